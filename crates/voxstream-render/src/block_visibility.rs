//! Which occupancy blocks of each resident brick an integrand can use: one bit per block, computed once per brick
//! and pass, so that the traversal finds the samples worth taking by reading bits, eight samples at a time.
//!
//! Empty-space skipping inside a brick (GigaVoxels [P09] §6; Knoll et al.'s min/max hierarchy, seed 002 §3) asks,
//! for each occupancy block a ray enters, whether any value in the block's `[min, max]` can contribute. Asked block
//! by block, each answer is a chain of dependent steps (locate the block, load its range, two transfer-function
//! table lookups, the block's exit, the first sample past it) that the next block waits for: taking the checks away
//! saves about a fifth of a frame on the MNI head (BENCHMARKS.md, "sixth round"). The answer depends only on the
//! block and the integrand's configuration (the transfer function), both fixed for a pass, so a brick's answers are
//! computed once, the first time a ray needs them; the traversal then locates the blocks of eight consecutive samples
//! at once, with the same arithmetic as the samples themselves, and reads their bits
//! ([`Traversal`](crate::Traversal)).
//!
//! The bits are exactly the integrand's [`Integrand::can_contribute`](crate::Integrand::can_contribute) of each
//! block's range. A sample is taken when the block holding its cell can contribute, which takes every sample the
//! range tests take that can change the image (they may also take a few samples just past a block's exit, which add
//! nothing). The bits are valid for one integrand configuration and one tree view: an integrand hands them to the
//! traversal ([`Integrand::block_visibility`](crate::Integrand::block_visibility)) only when it was made for both (the
//! volume renderer's [`RayCaster`](crate::RayCaster) makes one per pass).
//!
//! Rays of a pass run on several threads: each brick's bits are filled by the first ray that needs them (two rays
//! racing fill the same bits), then published by a flag with release/acquire ordering; no lock.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use voxstream_core::{BrickSlot, TreeView};

/// Per resident brick, one bit per occupancy block: whether an integrand can use the block's values.
pub struct BlockVisibility {
    /// 64-bit words per brick slot (`⌈blocks per brick / 64⌉`).
    words_per_slot: usize,
    /// The bits, `words_per_slot` words per slot, block `b` in bit `b % 64` of word `b / 64`.
    words: Vec<AtomicU64>,
    /// Per slot, whether its words are filled (release after the words, acquire before reading them).
    filled: Vec<AtomicBool>,
}

impl BlockVisibility {
    /// Room for every brick slot of `view`, nothing filled yet.
    pub fn new(view: &TreeView<'_>) -> BlockVisibility {
        let slots = view.brick_ranges.len();
        let words_per_slot = view.shape.blocks_per_brick().div_ceil(64);
        BlockVisibility {
            words_per_slot,
            words: (0..slots * words_per_slot).map(|_| AtomicU64::new(0)).collect(),
            filled: (0..slots).map(|_| AtomicBool::new(false)).collect(),
        }
    }

    /// The bits of the brick in `slot`, filled first if no ray has needed them yet, from `can_contribute` of each
    /// block's range (the integrand's own test, which the bits then equal).
    #[inline(always)]
    pub fn of_brick(
        &self,
        view: &TreeView<'_>,
        slot: BrickSlot,
        can_contribute: impl Fn(f32, f32) -> bool,
    ) -> BrickBlocks<'_> {
        let s = slot.0 as usize;
        let words = &self.words[s * self.words_per_slot..(s + 1) * self.words_per_slot];
        if !self.filled[s].load(Ordering::Acquire) {
            self.fill(view, slot, words, can_contribute);
        }
        BrickBlocks { words }
    }

    /// Fills one brick's words (kept out of line: once per brick and pass).
    #[inline(never)]
    fn fill(
        &self,
        view: &TreeView<'_>,
        slot: BrickSlot,
        words: &[AtomicU64],
        can_contribute: impl Fn(f32, f32) -> bool,
    ) {
        let blocks = view.shape.blocks_per_brick();
        for (w, word) in words.iter().enumerate() {
            let mut bits = 0u64;
            for bit in 0..64 {
                let block = w * 64 + bit;
                if block < blocks {
                    let [lo, hi] = view.block_range(slot, block);
                    bits |= u64::from(can_contribute(lo, hi)) << bit;
                }
            }
            word.store(bits, Ordering::Relaxed);
        }
        self.filled[slot.0 as usize].store(true, Ordering::Release);
    }
}

/// One brick's bits (see [`BlockVisibility`]).
#[derive(Clone, Copy)]
pub struct BrickBlocks<'m> {
    words: &'m [AtomicU64],
}

impl BrickBlocks<'_> {
    /// Whether the integrand can use the values of occupancy block `block` (x fastest).
    #[inline(always)]
    pub fn contributes(&self, block: usize) -> bool {
        self.words[block / 64].load(Ordering::Relaxed) >> (block % 64) & 1 != 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxstream_core::{BrickBlend, Node, PoolCapacity, PoolVoxels, TreeShape, VoxelFormat};

    #[test]
    fn the_bits_equal_the_test_of_each_block_range() {
        // Two slots of a shape with 5³ = 125 blocks per brick (two words), ranges varied per block.
        let shape = TreeShape::new(2, 32, 3).unwrap();
        let blocks = shape.blocks_per_brick();
        assert_eq!(blocks, 125);
        let ranges: Vec<[u16; 2]> =
            (0..2 * blocks).map(|i| [(i * 409 % 65_536) as u16, ((i * 409 + 3_000) % 65_536) as u16]).collect();
        let nodes = [Node::default()];
        let brick_ranges = [[0u16, 65_535]; 2];
        let voxels = vec![0u16; 2 * shape.voxels_per_brick()];
        let view = TreeView {
            shape,
            nodes: &nodes,
            voxels: PoolVoxels::Wide(&voxels),
            voxel_format: VoxelFormat::default(),
            brick_ranges: &brick_ranges,
            block_ranges: &ranges,
            brick_blends: &[] as &[BrickBlend],
            capacity: PoolCapacity::default(),
        };
        let test = |lo: f32, hi: f32| lo < 0.3 && hi > 0.2 || lo > 0.9;
        let visibility = BlockVisibility::new(&view);
        for slot in [BrickSlot(1), BrickSlot(0)] {
            let bits = visibility.of_brick(&view, slot, test);
            let mut seen = [0usize; 2];
            for block in 0..blocks {
                let [lo, hi] = view.block_range(slot, block);
                assert_eq!(bits.contributes(block), test(lo, hi), "slot {slot:?} block {block}");
                seen[usize::from(test(lo, hi))] += 1;
            }
            assert!(seen[0] > 0 && seen[1] > 0, "the ranges exercise both answers: {seen:?}");
            // Read again: filled once, the same bits (a different test now would not be asked).
            let again = visibility.of_brick(&view, slot, |_, _| unreachable!("filled already"));
            assert!((0..blocks).all(|b| again.contributes(b) == bits.contributes(b)));
        }
    }
}
