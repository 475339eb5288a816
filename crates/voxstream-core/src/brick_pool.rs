//! The brick pool: a flat array of fixed-size bricks of `(M+2)³` voxels, each with a one-voxel border.
//!
//! GigaVoxels [P09] §4 ("Brick pool"): bricks live in one big pool, addressed by slot; the border duplicates the
//! neighbours' voxels so trilinear filtering never reads outside a brick. voxstream stores the pool brick after
//! brick (slot `s` occupies voxels `[s·B³, (s+1)·B³)`, x fastest), which the CPU reads with perfect locality and a GPU
//! binds as one storage buffer (or copies slot by slot into a 3D atlas).
//!
//! Voxels are `u16`, the value normalised to `[0, 1]` (`value = voxel / 65535`).

use crate::key::TreeShape;
use crate::lru::{Allocation, LruSlots};
use crate::node::{BrickSlot, NodeId};

/// Bytes of the per-slot records (the owning node, and the brick's value range), counted in the budget.
pub const BRICK_RECORD_BYTES: usize = 4 + 4;

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
    voxels: Vec<u16>,
    owners: Vec<u32>,
    /// Per slot, `[min, max]` of its voxels: renderers skip bricks the transfer function makes invisible.
    ranges: Vec<[u16; 2]>,
    lru: LruSlots,
}

impl BrickPool {
    /// An empty pool of at most `capacity` bricks. Memory grows with use.
    pub fn new(shape: &TreeShape, capacity: u32) -> BrickPool {
        let voxels_per_brick = shape.voxels_per_brick();
        BrickPool {
            voxels_per_brick,
            voxels: Vec::new(),
            owners: Vec::new(),
            ranges: Vec::new(),
            lru: LruSlots::new(capacity),
        }
    }

    /// All voxels, brick after brick: the array renderers read.
    #[inline]
    pub fn voxels(&self) -> &[u16] {
        &self.voxels
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

    /// The voxels of one brick.
    pub fn brick(&self, slot: BrickSlot) -> &[u16] {
        let start = slot.0 as usize * self.voxels_per_brick;
        &self.voxels[start..start + self.voxels_per_brick]
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
        debug_assert_eq!(voxels.len(), self.voxels_per_brick);
        let allocation = self.lru.allocate(frame)?;
        let slot = allocation.slot() as usize;
        let start = slot * self.voxels_per_brick;
        let range = voxels.iter().fold([u16::MAX, 0], |[lo, hi], &v| [lo.min(v), hi.max(v)]);
        if start >= self.voxels.len() {
            self.voxels.extend_from_slice(voxels);
            self.owners.push(owner.0);
            self.ranges.push(range);
            return Some((BrickSlot(slot as u32), None));
        }
        self.voxels[start..start + self.voxels_per_brick].copy_from_slice(voxels);
        self.ranges[slot] = range;
        let previous = std::mem::replace(&mut self.owners[slot], owner.0);
        let evicted = match allocation {
            Allocation::Recycled(_) => Some(NodeId(previous)),
            Allocation::Fresh(_) => None,
        };
        Some((BrickSlot(slot as u32), evicted))
    }

    /// Frees `slot`.
    pub fn release(&mut self, slot: BrickSlot) {
        self.lru.release(slot.0);
    }
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
        assert_eq!(pool.brick(slot)[0], 7);
    }
}
