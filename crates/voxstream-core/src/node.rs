//! The node record of the N³-tree and the ids that address the pools.
//!
//! The record itself (two 32-bit words, GigaVoxels [P09] §4) is GPU-visible, so it is defined, with its layout and
//! its tests, in `voxstream-layout` ([`voxstream_layout::node`]); this module re-exports it so the core's paths
//! (`voxstream_core::node::Node`, `voxstream_core::Node`) stay as they were.

pub use voxstream_layout::node::{
    BrickSlot, Node, NodeData, NodeId, TileId, CHILD_MASK, CONSTANT_BIT, MAX_TILE_INDEX, TERMINAL_BIT,
};
