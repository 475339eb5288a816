//! # voxstream-layout: the records a GPU reads and writes, byte for byte
//!
//! The bottom of voxstream's crate graph (it depends on `bytemuck` only and is `#![no_std]`): every type here is
//! `#[repr(C)]` + [`bytemuck::Pod`], holds no pointers, and is uploaded or read back as raw bytes. The CPU ray
//! caster reads the very same records, so the CPU renderer stays the reference of a GPU backend
//! (GigaVoxels [P09] §4 "Node structure" for the node, §5 "Ray-guided data requests" for the feedback).
//!
//! | record | bytes | what it is for |
//! |---|---|---|
//! | [`Node`] | 8 | one node of the N³-tree: child tile + flags, brick slot or constant ([P09] §4) |
//! | [`TreeHeader`] | 48 | the shape of the tree and the pools' sizes: everything needed to walk [`Node`]s and find bricks |
//! | [`TransferTableHeader`] | 16 | how to read the transfer-function table |
//! | [`TransferTableEntry`] | 16 | one entry of the transfer-function table: r, g, b and extinction or step opacity |
//! | [`FeedbackCounters`] | 16 | the request list's fill level, written with atomics ([P09] §5) |
//! | [`UsageFlag`] | 4 | one tile or brick slot used by some ray this frame ([P09] §5) |
//! | [`RayCounters`] | 16 | what a pass's rays counted: rays, samples, descents |
//! | [`RayFrame`] | 224 | the frame's camera and ray settings, flattened: what a GPU ray caster reads beside the header |
//! | [`SurfaceRecord`] | 32 | one isosurface: isovalue, culling bounds, colour and opacity (Knoll et al.) |
//! | [`RequestRecord`] | 8 | one ray's request: a node to produce or to subdivide ([P09] §5) |
//! | [`BrickBlend`] | 36 | per brick slot: the cap on its weight against its parent at its corners (Thiele et al.'s blending) |
//!
//! Every struct is padded to a multiple of 16 bytes where a shader binds it as a uniform, and its WGSL mirror is
//! `src/layout.wgsl` (`tests/wgsl_mirror.rs` checks that both agree: field names, order, offsets and sizes). Each
//! module draws its record's offsets, as NanoVDB's `GridData` does; a change here is a change of the GPU interface.
//! The layout is little-endian, as on every GPU and CPU voxstream targets.
//!
//! ```
//! use voxstream_layout::{BrickSlot, Node, NodeData, TileId};
//!
//! let mut node = Node::MISSING;
//! node.set_brick(Some(BrickSlot(6)));
//! node.set_child_tile(Some(TileId(3)));
//! assert_eq!(node.data(), NodeData::Brick(BrickSlot(6)));
//! // What a shader reads: two little-endian words, the brick slot stored plus one.
//! assert_eq!(bytemuck::bytes_of(&node), &[3, 0, 0, 0, 7, 0, 0, 0]);
//! ```

#![cfg_attr(not(test), no_std)]

pub mod brick_blend;
pub mod feedback_records;
pub mod node;
pub mod ray_frame;
pub mod transfer_table;
pub mod tree_header;

pub use brick_blend::BrickBlend;
pub use feedback_records::{
    FeedbackCounters, RayCounters, RequestRecord, UsageFlag, REQUEST_DEFICIT_SHIFT, REQUEST_KIND_MASK,
    REQUEST_MAX_DEFICIT, REQUEST_PRODUCE, REQUEST_SUBDIVIDE,
};
pub use node::{BrickSlot, Node, NodeData, NodeId, TileId, CHILD_MASK, CONSTANT_BIT, MAX_TILE_INDEX, TERMINAL_BIT};
pub use ray_frame::{
    RayFrame, SurfaceRecord, RAY_FRAME_ADAPTIVE_STEP, RAY_FRAME_BLENDING, RAY_FRAME_BYTES, RAY_FRAME_CENTRAL_NORMALS,
    RAY_FRAME_COLOUR_BY_LEVEL, RAY_FRAME_PHONG, RAY_FRAME_SHADOWS, RAY_FRAME_SKIP_EMPTY_SPACE,
    RAY_FRAME_STEPS_IGNORE_STAND_INS, RAY_FRAME_SURFACES_IN_VOLUME,
};
pub use transfer_table::{TransferTableEntry, TransferTableHeader, TABLE_HOLDS_EXTINCTION, TABLE_HOLDS_STEP_OPACITY};
pub use tree_header::TreeHeader;
