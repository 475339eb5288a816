//! The brick pool: a flat array of fixed-size bricks of `(M+2)³` voxels, each with a one-voxel border.
//!
//! GigaVoxels [P09] §4 ("Brick pool"): bricks live in one big pool, addressed by slot; the border duplicates the
//! neighbours' voxels so trilinear filtering never reads outside a brick. voxstream stores the pool brick after
//! brick (slot `s` occupies voxels `[s·B³, (s+1)·B³)`, x fastest), which the CPU reads with perfect locality and a GPU
//! binds as one storage buffer (or copies slot by slot into a 3D atlas).
//!
//! Voxels are `u16`, the value normalised to `[0, 1]` (`value = voxel / 65535`), or `u8` for sources of 8-bit
//! samples ([`crate::voxel_format`]).

use crate::key::{TreeShape, BLOCK_CELLS};
use crate::lru::{Allocation, LruSlots};
use crate::node::{BrickSlot, NodeId};
use crate::voxel_format::{Narrowing, PoolVoxels, VoxelFormat};

/// The pool's voxels, owned.
#[derive(Debug, Clone)]
enum StoredVoxels {
    Wide(Vec<u16>),
    Narrow(Vec<u8>),
}

impl StoredVoxels {
    fn len(&self) -> usize {
        match self {
            StoredVoxels::Wide(v) => v.len(),
            StoredVoxels::Narrow(v) => v.len(),
        }
    }

    /// The voxels of one brick in `format`: kept as they are, or narrowed to bytes.
    fn of_brick(voxels: &[u16], format: VoxelFormat) -> StoredVoxels {
        match format {
            VoxelFormat::Wide => StoredVoxels::Wide(voxels.to_vec()),
            VoxelFormat::Narrow { scale, offset } => {
                let narrowing = Narrowing::new(scale, offset);
                StoredVoxels::Narrow(voxels.iter().map(|&v| narrowing.byte(v)).collect())
            }
        }
    }

    /// Copies one brick of the same format in at `start` (appending when `start` is the end).
    fn write(&mut self, start: usize, brick: &StoredVoxels) {
        fn put<T: Copy>(pool: &mut Vec<T>, start: usize, brick: &[T]) {
            if start >= pool.len() {
                pool.extend_from_slice(brick);
            } else {
                pool[start..start + brick.len()].copy_from_slice(brick);
            }
        }
        match (self, brick) {
            (StoredVoxels::Wide(pool), StoredVoxels::Wide(brick)) => put(pool, start, brick),
            (StoredVoxels::Narrow(pool), StoredVoxels::Narrow(brick)) => put(pool, start, brick),
            _ => unreachable!("a prepared brick has its pool's format"),
        }
    }
}

/// A brick ready for the pool: its voxels in the pool's format, and the value ranges renderers skip by, computed from
/// the stored voxels. Preparing is the per-voxel work of an insert, so production workers do it in parallel
/// ([`PreparedBrick::new`]) and the insert, which runs on one thread, only copies.
#[derive(Debug, Clone)]
pub struct PreparedBrick {
    /// The format it was prepared for (a pool of another format refuses it).
    format: VoxelFormat,
    voxels: StoredVoxels,
    /// `[min, max]` of the brick, in 16-bit units.
    range: [u16; 2],
    /// `[min, max]` of each occupancy block, in 16-bit units.
    block_ranges: Vec<[u16; 2]>,
}

impl PreparedBrick {
    /// Prepares one brick of 16-bit voxels (`shape.voxels_per_brick()` of them) for a pool of `format`.
    pub fn new(shape: &TreeShape, format: VoxelFormat, voxels: &[u16]) -> PreparedBrick {
        assert_eq!(voxels.len(), shape.voxels_per_brick(), "a brick has the shape's voxels");
        let stored = StoredVoxels::of_brick(voxels, format);
        let mut block_ranges = vec![[0u16; 2]; shape.blocks_per_brick()];
        // Ranges of what is stored (for 8-bit voxels, the bytes' values, which differ from the 16-bit voxels' by up
        // to half a step), so that skipping by them stays exact.
        let range = match &stored {
            StoredVoxels::Wide(brick) => brick_ranges(shape, brick, &mut block_ranges),
            StoredVoxels::Narrow(brick) => brick_ranges(shape, brick, &mut block_ranges),
        };
        for range in &mut block_ranges {
            *range = format.wide_bounds(*range);
        }
        PreparedBrick { format, voxels: stored, range: format.wide_bounds(range), block_ranges }
    }
}

/// Bytes of the per-slot records (the owning node, the brick's value range, its blocks' ranges and its blending
/// caps), counted in the budget.
pub fn brick_record_bytes(shape: &TreeShape) -> usize {
    4 + 4 + 4 * shape.blocks_per_brick() + crate::level_blending::BLEND_BYTES_PER_BRICK
}

/// Largest voxel value; stands for 1.0.
pub const VOXEL_MAX: u16 = u16::MAX;

/// Quantises a value in `[0, 1]` to a voxel (clamped).
#[inline]
#[allow(clippy::manual_clamp)] // `clamp` keeps NaN; `max` then `min` turn it into 0, as the cast does.
pub fn quantize(value: f32) -> u16 {
    // `(value.clamp(0.0, 1.0) · 65535 + 0.5) as u16` (NaN to 0), written so that it vectorises: the integer part,
    // below 2²³, converted by adding 2²³ and taking the float's low mantissa bits.
    let rounded = (value.max(0.0).min(1.0) * VOXEL_MAX as f32 + 0.5).floor();
    (rounded + 8_388_608.0).to_bits() as u16
}

/// The value a voxel stands for.
#[inline]
pub fn dequantize(voxel: u16) -> f32 {
    voxel as f32 * (1.0 / VOXEL_MAX as f32)
}

/// Fixed-capacity pool of bricks with LRU slot management.
#[derive(Debug, Clone)]
pub struct BrickPool {
    voxels_per_brick: usize,
    voxels: StoredVoxels,
    format: VoxelFormat,
    owners: Vec<u32>,
    /// Per slot, `[min, max]` of its voxels: renderers skip bricks the transfer function makes invisible.
    ranges: Vec<[u16; 2]>,
    /// Per slot, `[min, max]` of each occupancy block ([`TreeShape::blocks_per_brick`] per slot, x fastest):
    /// renderers skip the invisible parts of a visible brick ([`crate::key::BLOCK_CELLS`]).
    block_ranges: Vec<[u16; 2]>,
    shape: TreeShape,
    lru: LruSlots,
}

impl BrickPool {
    /// An empty pool of at most `capacity` bricks of 16-bit voxels. Memory grows with use.
    pub fn new(shape: &TreeShape, capacity: u32) -> BrickPool {
        BrickPool::with_format(shape, capacity, VoxelFormat::Wide)
    }

    /// An empty pool of at most `capacity` bricks stored as `format` says. Memory grows with use.
    pub fn with_format(shape: &TreeShape, capacity: u32, format: VoxelFormat) -> BrickPool {
        let voxels_per_brick = shape.voxels_per_brick();
        BrickPool {
            voxels_per_brick,
            voxels: match format {
                VoxelFormat::Wide => StoredVoxels::Wide(Vec::new()),
                VoxelFormat::Narrow { .. } => StoredVoxels::Narrow(Vec::new()),
            },
            format,
            owners: Vec::new(),
            ranges: Vec::new(),
            block_ranges: Vec::new(),
            shape: *shape,
            lru: LruSlots::new(capacity),
        }
    }

    /// All voxels, brick after brick: the array renderers read.
    #[inline]
    pub fn voxels(&self) -> PoolVoxels<'_> {
        match &self.voxels {
            StoredVoxels::Wide(v) => PoolVoxels::Wide(v),
            StoredVoxels::Narrow(v) => PoolVoxels::Narrow(v),
        }
    }

    /// How the voxels are stored.
    pub fn format(&self) -> VoxelFormat {
        self.format
    }

    /// Voxels per brick, borders included.
    pub fn voxels_per_brick(&self) -> usize {
        self.voxels_per_brick
    }

    /// `[min, max]` voxel of every slot, in slot order: the array renderers read for empty-space skipping.
    #[inline]
    pub fn ranges(&self) -> &[[u16; 2]] {
        &self.ranges
    }

    /// `[min, max]` of every occupancy block, slot after slot.
    #[inline]
    pub fn block_ranges(&self) -> &[[u16; 2]] {
        &self.block_ranges
    }

    /// The voxels of one brick.
    pub fn brick(&self, slot: BrickSlot) -> PoolVoxels<'_> {
        let start = slot.0 as usize * self.voxels_per_brick;
        self.voxels().slice(start..start + self.voxels_per_brick)
    }

    /// The node that owns `slot`.
    pub fn owner(&self, slot: BrickSlot) -> NodeId {
        NodeId(self.owners[slot.0 as usize])
    }

    /// Bricks in use.
    pub fn len(&self) -> u32 {
        self.lru.len()
    }

    /// Whether no brick is resident.
    pub fn is_empty(&self) -> bool {
        self.lru.is_empty()
    }

    /// Bricks ever allocated (memory actually touched).
    pub fn allocated(&self) -> u32 {
        self.lru.high_water()
    }

    /// Maximum bricks.
    pub fn capacity(&self) -> u32 {
        self.lru.capacity()
    }

    /// Whether `slot` holds a brick of the tree.
    pub fn is_in_use(&self, slot: BrickSlot) -> bool {
        self.lru.is_in_use(slot.0)
    }

    /// Marks `slot` used at `frame`.
    pub fn touch(&mut self, slot: BrickSlot, frame: u32) {
        self.lru.touch(slot.0, frame);
    }

    /// Stores `voxels` for `owner`. Returns the slot and, if a slot was recycled, the node that owned it (the caller
    /// must clear that node's brick pointer). `None` when every brick was used during `frame`.
    pub fn insert(&mut self, owner: NodeId, voxels: &[u16], frame: u32) -> Option<(BrickSlot, Option<NodeId>)> {
        let brick = self.prepare(voxels);
        self.insert_avoiding(owner, &brick, frame, |_| false).map(|(slot, evicted, _)| (slot, evicted))
    }

    /// `voxels` prepared for this pool ([`PreparedBrick::new`] with its shape and format).
    pub fn prepare(&self, voxels: &[u16]) -> PreparedBrick {
        PreparedBrick::new(&self.shape, self.format, voxels)
    }

    /// As [`BrickPool::insert`] for a prepared brick, where a brick to evict is one whose owner `keep` lets go, if
    /// one of the oldest [`crate::lru::RECYCLE_SCAN`] is; else the oldest all the same, and the third value is
    /// `true`.
    pub fn insert_avoiding(
        &mut self,
        owner: NodeId,
        brick: &PreparedBrick,
        frame: u32,
        mut keep: impl FnMut(NodeId) -> bool,
    ) -> Option<(BrickSlot, Option<NodeId>, bool)> {
        assert_eq!(brick.voxels.len(), self.voxels_per_brick, "a prepared brick has the pool's shape");
        assert_eq!(brick.format, self.format, "a prepared brick has the pool's voxel format");
        let owners = &self.owners;
        let (allocation, yielded) = self.lru.allocate_avoiding(frame, |slot| keep(NodeId(owners[slot as usize])))?;
        let slot = allocation.slot() as usize;
        let start = slot * self.voxels_per_brick;
        let blocks = self.shape.blocks_per_brick();
        let fresh = start >= self.voxels.len();
        self.voxels.write(start, &brick.voxels);
        if fresh {
            self.owners.push(owner.0);
            self.ranges.push(brick.range);
            self.block_ranges.extend_from_slice(&brick.block_ranges);
            return Some((BrickSlot(slot as u32), None, yielded));
        }
        self.ranges[slot] = brick.range;
        self.block_ranges[slot * blocks..(slot + 1) * blocks].copy_from_slice(&brick.block_ranges);
        let previous = std::mem::replace(&mut self.owners[slot], owner.0);
        let evicted = match allocation {
            Allocation::Recycled(_) => Some(NodeId(previous)),
            Allocation::Fresh(_) => None,
        };
        Some((BrickSlot(slot as u32), evicted, yielded))
    }

    /// Widens the value range of the brick in `slot` to include `[lower, upper]` (stored units): for a brick with
    /// children, the bounds of its whole subtree, so that one range check can skip the subtree unloaded. Its
    /// occupancy blocks keep their own ranges.
    pub fn widen_range(&mut self, slot: BrickSlot, [lower, upper]: [u16; 2]) {
        let range = &mut self.ranges[slot.0 as usize];
        *range = [range[0].min(lower), range[1].max(upper)];
    }

    /// Slots a brick can take without evicting one: never used, or released.
    pub fn free_slots(&self) -> u32 {
        self.capacity() - self.len()
    }

    /// Stores `brick` for `owner` in a free slot, never evicting: `None` when [`BrickPool::free_slots`] is 0.
    pub fn insert_if_free(&mut self, owner: NodeId, brick: &PreparedBrick, frame: u32) -> Option<BrickSlot> {
        if self.free_slots() == 0 {
            return None;
        }
        let (slot, evicted, _) = self.insert_avoiding(owner, brick, frame, |_| false)?;
        debug_assert!(evicted.is_none(), "a free slot was available, nothing may be evicted");
        Some(slot)
    }

    /// Frees `slot`.
    pub fn release(&mut self, slot: BrickSlot) {
        self.lru.release(slot.0);
    }
}

/// Writes `[min, max]` of each occupancy block of `voxels` (one brick) into `out`: block `(i, j, k)` covers the cells
/// `i·E .. min((i+1)·E, B−1)` per axis, hence the voxels `i·E ..= min((i+1)·E, B−1)`, so every trilinear sample
/// taken in one of its cells lies within its range.
///
/// Returns the whole brick's `[min, max]` (the blocks cover every voxel). Both in stored units.
///
/// Separable, so that the work on each voxel vectorises: whole rows are reduced element by element over each block's
/// slices (z), then over its rows (y), and only the short rows left are reduced along x.
fn brick_ranges<V: Copy + Ord + Into<u16>>(shape: &TreeShape, voxels: &[V], out: &mut [[u16; 2]]) -> [u16; 2] {
    let b = shape.stored_brick_size() as usize;
    let blocks = shape.blocks_per_axis();
    let span = |i: usize| i * BLOCK_CELLS..=((i + 1) * BLOCK_CELLS).min(b - 1);
    let min_into = |acc: &mut [V], row: &[V]| acc.iter_mut().zip(row).for_each(|(a, &v)| *a = (*a).min(v));
    let max_into = |acc: &mut [V], row: &[V]| acc.iter_mut().zip(row).for_each(|(a, &v)| *a = (*a).max(v));
    let slice = b * b;
    let (mut slab_lo, mut slab_hi) = (voxels[..slice].to_vec(), voxels[..slice].to_vec());
    let (mut rows_lo, mut rows_hi) = (voxels[..b].to_vec(), voxels[..b].to_vec());
    let mut whole = [u16::MAX, 0];
    for bk in 0..blocks {
        // The block layer's slices reduced to one, element by element.
        let layer = span(bk);
        let first = &voxels[layer.start() * slice..(layer.start() + 1) * slice];
        slab_lo.copy_from_slice(first);
        slab_hi.copy_from_slice(first);
        for k in layer.skip(1) {
            min_into(&mut slab_lo, &voxels[k * slice..(k + 1) * slice]);
            max_into(&mut slab_hi, &voxels[k * slice..(k + 1) * slice]);
        }
        for bj in 0..blocks {
            // Then the block row's rows of that slice.
            let rows = span(bj);
            rows_lo.copy_from_slice(&slab_lo[rows.start() * b..(rows.start() + 1) * b]);
            rows_hi.copy_from_slice(&slab_hi[rows.start() * b..(rows.start() + 1) * b]);
            for j in rows.skip(1) {
                min_into(&mut rows_lo, &slab_lo[j * b..(j + 1) * b]);
                max_into(&mut rows_hi, &slab_hi[j * b..(j + 1) * b]);
            }
            // Then each block's stretch of the row left.
            for bi in 0..blocks {
                let lo = rows_lo[span(bi)].iter().copied().min().map_or(u16::MAX, Into::into);
                let hi = rows_hi[span(bi)].iter().copied().max().map_or(0, Into::into);
                out[(bk * blocks + bj) * blocks + bi] = [lo, hi];
                whole = [whole[0].min(lo), whole[1].max(hi)];
            }
        }
    }
    whole
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantisation_round_trips_within_half_a_step() {
        for i in 0..=100 {
            let v = i as f32 / 100.0;
            assert!((dequantize(quantize(v)) - v).abs() <= 0.5 / VOXEL_MAX as f32 + 1e-7);
        }
        assert_eq!(quantize(-1.0), 0);
        assert_eq!(quantize(2.0), VOXEL_MAX);
    }

    #[test]
    fn quantize_equals_the_saturating_cast() {
        let reference = |v: f32| (v.clamp(0.0, 1.0) * VOXEL_MAX as f32 + 0.5) as u16;
        // Every float bit pattern on a stride that is prime to 2³², and the edges.
        let mut bits = 0u32;
        for _ in 0..(1u32 << 22) {
            let v = f32::from_bits(bits);
            assert_eq!(quantize(v), reference(v), "{v:e} ({bits:#x})");
            bits = bits.wrapping_add(1021);
        }
        for v in [0.0, -0.0, 1.0, f32::MIN_POSITIVE, 0.5 / 65535.0, 1.0 - 0.5 / 65535.0, f32::INFINITY, f32::NAN] {
            assert_eq!(quantize(v), reference(v), "{v:e}");
            assert_eq!(quantize(-v), reference(-v), "{:e}", -v);
        }
        for voxel in 0..=VOXEL_MAX {
            let v = dequantize(voxel);
            assert_eq!(quantize(v), reference(v));
            assert_eq!(quantize(v + 0.5 / 65535.0), reference(v + 0.5 / 65535.0));
        }
    }

    /// The ranges as first written: every block's voxels visited one by one.
    fn brick_ranges_one_by_one(shape: &TreeShape, voxels: &[u16]) -> ([u16; 2], Vec<[u16; 2]>) {
        let whole = voxels.iter().fold([u16::MAX, 0], |[lo, hi], &v| [lo.min(v), hi.max(v)]);
        let b = shape.stored_brick_size() as usize;
        let blocks = shape.blocks_per_axis();
        let span = |i: usize| i * BLOCK_CELLS..=((i + 1) * BLOCK_CELLS).min(b - 1);
        let mut out = vec![[u16::MAX, 0]; shape.blocks_per_brick()];
        for (index, range) in out.iter_mut().enumerate() {
            let (bi, bj, bk) = (index % blocks, index / blocks % blocks, index / (blocks * blocks));
            for k in span(bk) {
                for j in span(bj) {
                    for &v in &voxels[(k * b + j) * b..][span(bi)] {
                        *range = [range[0].min(v), range[1].max(v)];
                    }
                }
            }
        }
        (whole, out)
    }

    proptest::proptest! {
        #[test]
        fn separable_ranges_equal_the_ranges_voxel_by_voxel(
            brick_size in proptest::sample::select(vec![4u32, 7, 8, 14, 16, 30, 32]),
            seed in 0u64..1_000_000,
            spread in 1u32..65_536,
        ) {
            let shape = TreeShape::new(2, brick_size, 3).unwrap();
            let mut state = seed | 1;
            let voxels: Vec<u16> = (0..shape.voxels_per_brick())
                .map(|_| {
                    state ^= state << 13;
                    state ^= state >> 7;
                    state ^= state << 17;
                    (state % spread as u64) as u16 + 17
                })
                .collect();
            let mut blocks = vec![[0u16; 2]; shape.blocks_per_brick()];
            let whole = brick_ranges(&shape, &voxels, &mut blocks);
            let (whole_reference, blocks_reference) = brick_ranges_one_by_one(&shape, &voxels);
            proptest::prop_assert_eq!(whole, whole_reference);
            proptest::prop_assert_eq!(blocks, blocks_reference);
        }
    }

    #[test]
    #[should_panic(expected = "the pool's voxel format")]
    fn a_brick_prepared_for_another_format_is_refused() {
        let shape = TreeShape::new(2, 8, 4).unwrap();
        let mut pool = BrickPool::with_format(&shape, 4, VoxelFormat::for_bytes([0.0, 255.0]).unwrap());
        let other = PreparedBrick::new(&shape, VoxelFormat::for_bytes([10.0, 40.0]).unwrap(), &vec![7u16; 1000]);
        pool.insert_avoiding(NodeId(1), &other, 1, |_| false);
    }

    #[test]
    fn recycling_reports_the_previous_owner() {
        let shape = TreeShape::new(2, 2, 4).unwrap();
        let mut pool = BrickPool::new(&shape, 1);
        let bricks = vec![7u16; shape.voxels_per_brick()];
        let (slot, evicted) = pool.insert(NodeId(3), &bricks, 1).unwrap();
        assert_eq!((slot, evicted), (BrickSlot(0), None));
        assert!(pool.insert(NodeId(4), &bricks, 1).is_none(), "brick used this frame cannot be recycled");
        let (_, evicted) = pool.insert(NodeId(4), &bricks, 2).unwrap();
        assert_eq!(evicted, Some(NodeId(3)));
        assert_eq!(pool.owner(slot), NodeId(4));
        assert_eq!(pool.brick(slot).stored(0), 7.0);
    }

    #[test]
    fn block_ranges_cover_their_cells_voxels() {
        // M = 14: B = 16 stored voxels, 15 cells, blocks of 8 and 7 cells.
        let shape = TreeShape::new(2, 14, 4).unwrap();
        assert_eq!(shape.blocks_per_axis(), 2);
        let b = shape.stored_brick_size() as usize;
        let mut voxels = vec![100u16; shape.voxels_per_brick()];
        // A voxel on the shared face x = 8 belongs to the cells of both x-blocks.
        voxels[(3 * b + 2) * b + 8] = 5;
        voxels[(15 * b + 15) * b + 15] = 900;
        let mut pool = BrickPool::new(&shape, 1);
        let (slot, _) = pool.insert(NodeId(1), &voxels, 1).unwrap();
        let ranges = &pool.block_ranges()[slot.0 as usize * 8..][..8];
        assert_eq!(ranges[0], [5, 100]);
        assert_eq!(ranges[1], [5, 100]);
        assert_eq!(ranges[7], [100, 900]);
        assert_eq!(ranges[2], [100, 100]);
    }

    #[test]
    fn a_narrow_pool_keeps_bytes_and_bounds_their_values() {
        let shape = TreeShape::new(2, 8, 4).unwrap();
        let format = VoxelFormat::for_bytes([10.0, 40.0]).unwrap();
        let VoxelFormat::Narrow { scale, offset } = format else { unreachable!() };
        let mut pool = BrickPool::with_format(&shape, 4, format);
        // What a store producer writes for the bytes 10..=40: their normalised values quantised to 16 bits.
        let bytes: Vec<u8> = (0..shape.voxels_per_brick()).map(|i| 10 + (i * 7 % 31) as u8).collect();
        let wide: Vec<u16> = bytes.iter().map(|&v| quantize((v as f32 - 10.0) / 30.0)).collect();
        let (slot, _) = pool.insert(NodeId(1), &wide, 1).unwrap();
        let PoolVoxels::Narrow(stored) = pool.brick(slot) else { panic!("a narrow pool stores bytes") };
        assert_eq!(stored, &bytes[..]);
        assert_eq!(pool.voxels().len(), shape.voxels_per_brick());
        // The ranges (16-bit units) bound every value the bytes stand for, as renderers compute it.
        let [lo, hi] = pool.ranges()[slot.0 as usize];
        for &v in &bytes {
            let value = v as f32 * scale + offset;
            assert!(dequantize(lo) <= value && value <= dequantize(hi), "{v}: {value} outside [{lo}, {hi}]");
        }
        let b = shape.stored_brick_size() as usize;
        for (block, &[lo, hi]) in pool.block_ranges()[..shape.blocks_per_brick()].iter().enumerate() {
            let blocks = shape.blocks_per_axis();
            let (bi, bj, bk) = (block % blocks, block / blocks % blocks, block / (blocks * blocks));
            let span = |i: usize| i * BLOCK_CELLS..=((i + 1) * BLOCK_CELLS).min(b - 1);
            for k in span(bk) {
                for j in span(bj) {
                    for i in span(bi) {
                        let value = bytes[(k * b + j) * b + i] as f32 * scale + offset;
                        assert!(dequantize(lo) <= value && value <= dequantize(hi));
                    }
                }
            }
        }
    }
}
