//! The read-only view of the tree that renderers receive for one frame.
//!
//! NanoVDB-style: flat arrays and integer links, nothing else, so the CPU ray caster and a GPU backend read the
//! same layout. The view borrows the pools immutably: while a frame renders, the borrow checker guarantees that the
//! cache manager cannot change them.

use crate::brick_pool::dequantize;
use crate::key::TreeShape;
use crate::node::{BrickSlot, Node, NodeId, TileId};

/// Flat, immutable view of the node pool and the brick pool.
#[derive(Clone, Copy, Debug)]
pub struct TreeView<'a> {
    /// N, brick size, deepest level.
    pub shape: TreeShape,
    /// The node pool, tile after tile; node 0 is the root.
    pub nodes: &'a [Node],
    /// The brick pool, brick after brick, `(M+2)³` voxels each.
    pub voxels: &'a [u16],
    /// `[min, max]` voxel of each brick slot (border included).
    pub brick_ranges: &'a [[u16; 2]],
    /// `[min, max]` voxel of each occupancy block, [`TreeShape::blocks_per_brick`] per slot.
    pub block_ranges: &'a [[u16; 2]],
}

impl<'a> TreeView<'a> {
    /// The root node.
    #[inline]
    pub fn root(&self) -> Node {
        self.nodes[0]
    }

    /// Child `child_index` of the tile `tile`.
    #[inline]
    pub fn child(&self, tile: TileId, child_index: u32) -> (NodeId, Node) {
        let id = NodeId::new(tile, child_index, self.shape.nodes_per_tile());
        (id, self.nodes[id.0 as usize])
    }

    /// The voxels of one brick.
    #[inline]
    pub fn brick(&self, slot: BrickSlot) -> &'a [u16] {
        let per_brick = self.shape.voxels_per_brick();
        let start = slot.0 as usize * per_brick;
        &self.voxels[start..start + per_brick]
    }

    /// `[min, max]` of a brick's voxels, normalised to `[0, 1]`.
    #[inline]
    pub fn brick_range(&self, slot: BrickSlot) -> [f32; 2] {
        let [lo, hi] = self.brick_ranges[slot.0 as usize];
        [dequantize(lo), dequantize(hi)]
    }

    /// `[min, max]` of occupancy block `block` (x fastest) of a brick, normalised to `[0, 1]`.
    #[inline]
    pub fn block_range(&self, slot: BrickSlot, block: usize) -> [f32; 2] {
        let [lo, hi] = self.block_ranges[slot.0 as usize * self.shape.blocks_per_brick() + block];
        [dequantize(lo), dequantize(hi)]
    }

    /// Value of voxel `(i, j, k)` (border included, so indices run over `0..M+2`) of a brick.
    #[inline]
    pub fn voxel(&self, brick: &[u16], i: usize, j: usize, k: usize) -> f32 {
        let b = self.shape.stored_brick_size() as usize;
        dequantize(brick[(k * b + j) * b + i])
    }
}
