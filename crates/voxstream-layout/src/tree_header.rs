//! The tree header: the one uniform a GPU traversal needs besides the node and brick buffers.
//!
//! GigaVoxels [P09] §4 walks an N³-tree of node tiles and samples bricks of `M³` voxels plus a one-voxel border from
//! a brick pool. The header carries the numbers that walk depends on, so a shader never hard-codes N or M, and the
//! pools' current lengths, so it can bound every index it follows. The CPU side fills it from its `TreeView`
//! (`voxstream_core::TreeView::header`).
//!
//! | offset | bytes | field | meaning |
//! |---|---|---|---|
//! | 0 | 4 | [`n`](TreeHeader::n) | children per axis of a node (N; 2 = octree) |
//! | 4 | 4 | [`nodes_per_tile`](TreeHeader::nodes_per_tile) | N³: nodes in one tile of siblings |
//! | 8 | 4 | [`brick_size`](TreeHeader::brick_size) | M: voxels per brick edge, border excluded |
//! | 12 | 4 | [`stored_brick_size`](TreeHeader::stored_brick_size) | M + 2: voxels per brick edge as stored |
//! | 16 | 4 | [`max_level`](TreeHeader::max_level) | deepest level (the root is level 0) |
//! | 20 | 4 | [`blocks_per_axis`](TreeHeader::blocks_per_axis) | occupancy blocks per brick edge: the M + 1 cells between stored voxels, in blocks of `block_cells` (the last may be smaller) |
//! | 24 | 4 | [`block_cells`](TreeHeader::block_cells) | voxel cells per occupancy-block edge |
//! | 28 | 4 | [`voxels_per_brick`](TreeHeader::voxels_per_brick) | (M + 2)³: stride between bricks in the brick buffer |
//! | 32 | 4 | [`node_count`](TreeHeader::node_count) | nodes in the node buffer (tiles · N³) |
//! | 36 | 4 | [`brick_count`](TreeHeader::brick_count) | brick slots in the brick buffer |
//! | 40 | 8 | padding | zero; rounds the header up to 48 bytes (a multiple of 16, as uniforms need) |

use bytemuck::{Pod, Zeroable};

/// The shape of the tree and the sizes of its pools, as a GPU reads them (see the module docs for the offsets).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct TreeHeader {
    /// Children per axis of a node (N).
    pub n: u32,
    /// Nodes in one tile of siblings (N³).
    pub nodes_per_tile: u32,
    /// Voxels per brick edge, border excluded (M).
    pub brick_size: u32,
    /// Voxels per brick edge as stored, border included (M + 2).
    pub stored_brick_size: u32,
    /// Deepest level of the tree (the root is level 0).
    pub max_level: u32,
    /// Occupancy blocks per brick edge: the M + 1 cells between stored voxels, in blocks of `block_cells`.
    pub blocks_per_axis: u32,
    /// Voxel cells per occupancy-block edge.
    pub block_cells: u32,
    /// Voxels of one stored brick ((M + 2)³): the stride between bricks in the brick buffer.
    pub voxels_per_brick: u32,
    /// Nodes in the node buffer (tiles · N³); node 0 is the root.
    pub node_count: u32,
    /// Brick slots in the brick buffer.
    pub brick_count: u32,
    /// Zero; pads the header to a multiple of 16 bytes.
    pub padding0: u32,
    /// Zero; pads the header to a multiple of 16 bytes.
    pub padding1: u32,
}

/// Bytes of a [`TreeHeader`].
pub const TREE_HEADER_BYTES: usize = core::mem::size_of::<TreeHeader>();

#[cfg(test)]
mod tests {
    use super::*;
    use core::mem::{align_of, offset_of, size_of};

    #[test]
    fn offsets_are_as_documented() {
        assert_eq!(size_of::<TreeHeader>(), 48);
        assert_eq!(TREE_HEADER_BYTES % 16, 0);
        assert_eq!(align_of::<TreeHeader>(), 4);
        assert_eq!(offset_of!(TreeHeader, n), 0);
        assert_eq!(offset_of!(TreeHeader, nodes_per_tile), 4);
        assert_eq!(offset_of!(TreeHeader, brick_size), 8);
        assert_eq!(offset_of!(TreeHeader, stored_brick_size), 12);
        assert_eq!(offset_of!(TreeHeader, max_level), 16);
        assert_eq!(offset_of!(TreeHeader, blocks_per_axis), 20);
        assert_eq!(offset_of!(TreeHeader, block_cells), 24);
        assert_eq!(offset_of!(TreeHeader, voxels_per_brick), 28);
        assert_eq!(offset_of!(TreeHeader, node_count), 32);
        assert_eq!(offset_of!(TreeHeader, brick_count), 36);
        assert_eq!(offset_of!(TreeHeader, padding0), 40);
        assert_eq!(offset_of!(TreeHeader, padding1), 44);
    }

    #[test]
    fn bytes_are_little_endian_words_in_field_order() {
        let header = TreeHeader { n: 2, brick_size: 16, brick_count: 0x0102_0304, ..TreeHeader::default() };
        let bytes = bytemuck::bytes_of(&header);
        assert_eq!(&bytes[0..4], &[2, 0, 0, 0]);
        assert_eq!(&bytes[8..12], &[16, 0, 0, 0]);
        assert_eq!(&bytes[36..40], &[4, 3, 2, 1]);
    }
}
