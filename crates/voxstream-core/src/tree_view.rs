//! The read-only view of the tree that renderers receive for one frame.
//!
//! NanoVDB-style: flat arrays and integer links, nothing else, so the CPU ray caster and a GPU backend read the
//! same layout. The view borrows the pools immutably: while a frame renders, the borrow checker guarantees that the
//! cache manager cannot change them.

use voxstream_layout::{BrickBlend, TreeHeader};

use crate::brick_pool::dequantize;
use crate::key::{TreeShape, BLOCK_CELLS};
use crate::node::{BrickSlot, Node, NodeId, TileId};
use crate::voxel_format::{PoolVoxels, VoxelFormat};

/// Flat, immutable view of the node pool and the brick pool.
#[derive(Clone, Copy, Debug)]
pub struct TreeView<'a> {
    /// N, brick size, deepest level.
    pub shape: TreeShape,
    /// The node pool, tile after tile; node 0 is the root.
    pub nodes: &'a [Node],
    /// The brick pool, brick after brick, `(M+2)³` voxels each.
    pub voxels: PoolVoxels<'a>,
    /// How `voxels` stand for values.
    pub voxel_format: VoxelFormat,
    /// `[min, max]` voxel of each brick slot (border included).
    pub brick_ranges: &'a [[u16; 2]],
    /// `[min, max]` voxel of each occupancy block, [`TreeShape::blocks_per_brick`] per slot.
    pub block_ranges: &'a [[u16; 2]],
    /// Per brick slot, the caps on its weight against its parent at its corners (Thiele et al.'s blending,
    /// [`crate::level_blending`]); empty when nothing is blended this frame.
    pub brick_blends: &'a [BrickBlend],
    /// The most node tiles and brick slots the pools will ever hold (fixed by the memory budget; `nodes` and
    /// `voxels` grow up to them with use): what a renderer with memory of its own (a GPU) allocates once.
    pub capacity: PoolCapacity,
}

/// The most node tiles and brick slots the pools hold.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PoolCapacity {
    /// Node tiles.
    pub tiles: u32,
    /// Brick slots.
    pub bricks: u32,
}

impl<'a> TreeView<'a> {
    /// The tree's shape and the pools' lengths as a GPU reads them (the uniform beside the node and brick buffers).
    pub fn header(&self) -> TreeHeader {
        let voxels_per_brick = self.shape.voxels_per_brick();
        TreeHeader {
            n: self.shape.n,
            nodes_per_tile: self.shape.nodes_per_tile(),
            brick_size: self.shape.brick_size,
            stored_brick_size: self.shape.stored_brick_size(),
            max_level: self.shape.max_level,
            blocks_per_axis: self.shape.blocks_per_axis() as u32,
            block_cells: BLOCK_CELLS as u32,
            voxels_per_brick: voxels_per_brick as u32,
            node_count: self.nodes.len() as u32,
            brick_count: (self.voxels.len() / voxels_per_brick) as u32,
            padding0: 0,
            padding1: 0,
        }
    }

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
    pub fn brick(&self, slot: BrickSlot) -> PoolVoxels<'a> {
        let per_brick = self.shape.voxels_per_brick();
        let start = slot.0 as usize * per_brick;
        self.voxels.slice(start..start + per_brick)
    }

    /// `[min, max]` of a brick's voxels, normalised to `[0, 1]`; for a brick with children whose producer knows it,
    /// widened to bound the whole subtree ([`crate::Producer::subtree_range`]).
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
    pub fn voxel(&self, brick: PoolVoxels<'_>, i: usize, j: usize, k: usize) -> f32 {
        let b = self.shape.stored_brick_size() as usize;
        self.voxel_format.dequantize().value(brick.stored((k * b + j) * b + i))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_describes_the_shape_and_the_pools() {
        let shape = TreeShape::new(3, 16, 5).unwrap();
        let nodes = vec![Node::MISSING; 2 * 27];
        let voxels = vec![0u16; 3 * shape.voxels_per_brick()];
        let ranges = vec![[0u16, 0]; 3];
        let blocks = vec![[0u16, 0]; 3 * shape.blocks_per_brick()];
        let view = TreeView {
            shape,
            nodes: &nodes,
            voxels: PoolVoxels::Wide(&voxels),
            voxel_format: VoxelFormat::Wide,
            brick_ranges: &ranges,
            block_ranges: &blocks,
            brick_blends: &[],
            capacity: PoolCapacity { tiles: 2, bricks: 3 },
        };
        let header = view.header();
        assert_eq!((header.n, header.nodes_per_tile, header.brick_size, header.stored_brick_size), (3, 27, 16, 18));
        // 17 cells between the 18 stored voxels, in blocks of 8: three blocks per axis, the last one smaller.
        assert_eq!((header.max_level, header.blocks_per_axis, header.block_cells), (5, 3, 8));
        assert_eq!(header.voxels_per_brick, 18 * 18 * 18);
        assert_eq!((header.node_count, header.brick_count), (54, 3));
    }
}
