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

    /// Writes a brick of 16-bit voxels at `start` (appending when `start` is the end), narrowed if the pool is.
    fn write(&mut self, start: usize, voxels: &[u16], format: VoxelFormat) {
        match (self, format) {
            (StoredVoxels::Wide(pool), _) => {
                if start >= pool.len() {
                    pool.extend_from_slice(voxels);
                } else {
                    pool[start..start + voxels.len()].copy_from_slice(voxels);
                }
            }
            (StoredVoxels::Narrow(pool), VoxelFormat::Narrow { scale, offset }) => {
                if start >= pool.len() {
                    pool.resize(start + voxels.len(), 0);
                }
                let narrowing = Narrowing::new(scale, offset);
                for (out, &v) in pool[start..start + voxels.len()].iter_mut().zip(voxels) {
                    *out = narrowing.byte(v);
                }
            }
            (StoredVoxels::Narrow(_), VoxelFormat::Wide) => unreachable!("a narrow pool has a narrow format"),
        }
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
pub fn quantize(value: f32) -> u16 {
    (value.clamp(0.0, 1.0) * VOXEL_MAX as f32 + 0.5) as u16
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
        self.insert_avoiding(owner, voxels, frame, |_| false).map(|(slot, evicted, _)| (slot, evicted))
    }

    /// As [`BrickPool::insert`], but a brick to evict is one whose owner `keep` lets go, if one of the oldest
    /// [`crate::lru::RECYCLE_SCAN`] is; else the oldest all the same, and the third value is `true`.
    pub fn insert_avoiding(
        &mut self,
        owner: NodeId,
        voxels: &[u16],
        frame: u32,
        mut keep: impl FnMut(NodeId) -> bool,
    ) -> Option<(BrickSlot, Option<NodeId>, bool)> {
        debug_assert_eq!(voxels.len(), self.voxels_per_brick);
        let owners = &self.owners;
        let (allocation, yielded) = self.lru.allocate_avoiding(frame, |slot| keep(NodeId(owners[slot as usize])))?;
        let slot = allocation.slot() as usize;
        let start = slot * self.voxels_per_brick;
        let blocks = self.shape.blocks_per_brick();
        let format = self.format;
        let fresh = start >= self.voxels.len();
        self.voxels.write(start, voxels, format);
        if fresh {
            self.owners.push(owner.0);
            self.ranges.push([0, 0]);
            self.block_ranges.resize(self.block_ranges.len() + blocks, [0, 0]);
        }
        // Ranges of what is stored (for 8-bit voxels, the bytes' values, which differ from the 16-bit voxels' by
        // up to half a step), so that skipping by them stays exact.
        let block_out = &mut self.block_ranges[slot * blocks..(slot + 1) * blocks];
        let range = match &self.voxels {
            StoredVoxels::Wide(pool) => brick_ranges(&self.shape, &pool[start..start + voxels.len()], block_out),
            StoredVoxels::Narrow(pool) => brick_ranges(&self.shape, &pool[start..start + voxels.len()], block_out),
        };
        self.ranges[slot] = format.wide_bounds(range);
        for range in block_out.iter_mut() {
            *range = format.wide_bounds(*range);
        }
        if fresh {
            return Some((BrickSlot(slot as u32), None, yielded));
        }
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

    /// Stores `voxels` for `owner` in a free slot, never evicting: `None` when [`BrickPool::free_slots`] is 0.
    pub fn insert_if_free(&mut self, owner: NodeId, voxels: &[u16], frame: u32) -> Option<BrickSlot> {
        if self.free_slots() == 0 {
            return None;
        }
        let (slot, evicted) = self.insert(owner, voxels, frame)?;
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
/// Returns the whole brick's `[min, max]`. Both in stored units.
fn brick_ranges<V: Copy + Into<u16>>(shape: &TreeShape, voxels: &[V], out: &mut [[u16; 2]]) -> [u16; 2] {
    let range = voxels.iter().fold([u16::MAX, 0], |[lo, hi], &v| [lo.min(v.into()), hi.max(v.into())]);
    let b = shape.stored_brick_size() as usize;
    let blocks = shape.blocks_per_axis();
    let span = |i: usize| i * BLOCK_CELLS..=((i + 1) * BLOCK_CELLS).min(b - 1);
    for (index, range) in out.iter_mut().take(blocks * blocks * blocks).enumerate() {
        let (bi, bj, bk) = (index % blocks, index / blocks % blocks, index / (blocks * blocks));
        let mut lo_hi = [u16::MAX, 0];
        for k in span(bk) {
            for j in span(bj) {
                let row = &voxels[(k * b + j) * b..(k * b + j) * b + b];
                for &v in &row[span(bi)] {
                    lo_hi = [lo_hi[0].min(v.into()), lo_hi[1].max(v.into())];
                }
            }
        }
        *range = lo_hi;
    }
    range
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
