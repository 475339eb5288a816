//! # voxstream-gpu: the GPU renderer, on wgpu
//!
//! GigaVoxels is a GPU system (seeds 000/001, `shared/notes/gigavoxels.md`): the node and brick pools live in GPU
//! memory, rays run in shaders and write the feedback that drives loading, and the CPU serves requests. This crate
//! is that renderer behind the frame loop's [`FrameRenderer`](voxstream_engine::FrameRenderer) interface:
//! [`GpuRenderer`] draws the passes of the same [`Session`](voxstream_engine::Session), cache manager and producers
//! as the CPU ray caster, whose image is its reference (every GPU stage has a CPU twin; the numbers they share and
//! the cell solver are checked against the CPU's directly: `tests/shader_interface.rs`, `tests/cell_cubic_twin/`).
//!
//! - [`context`]: the headless Vulkan device (Mesa's lavapipe in CI) and its description;
//! - [`brick_filtering`]: bricks filtered exactly in the shader or by the texture units;
//! - [`pools`]: the node pool as a storage buffer and the brick pool as a 3D texture atlas, updated by changed tiles
//!   and bricks only;
//! - [`renderer`]: one pass: uniforms, the ray caster's compute shader, readback, feedback to the CPU;
//! - [`shader`]: that shader's WGSL, in files along the CPU traversal's seams (`src/shader/`), joined into one module;
//! - [`shader_interface`]: what the host and the shader share by number (bindings, pixel flags, workgroup, range
//!   packing), named once;
//! - [`shader_records`]: the frame's uniform, isosurface records and value ranges as the shader reads them.
//!
//! The shader reads the `#[repr(C)]` records of `voxstream-layout` (nodes, tree header, transfer-table entries,
//! feedback records, the frame's [`RayFrame`](voxstream_layout::RayFrame)) through their WGSL mirror
//! `layout.wgsl`, which is prepended to it.
//!
//! The CPU renderer's integrands run on the GPU: emission–absorption, Knoll et al.'s exact isosurfaces (with
//! culling, translucent nested surfaces and shadows) and those surfaces inside the volume rendering, and Thiele et
//! al.'s level blending of interactive frames.
//! Not yet on the GPU (listed in `docs/ARCHITECTURE.md`): request compaction and focus weighting.
//! Positions are f32 in an anchor frame near the eye, so deep zooms keep the CPU's precision (see
//! `voxstream_layout::ray_frame`).

pub mod brick_filtering;
pub mod context;
pub mod error;
pub mod pools;
pub mod renderer;
pub mod shader;
pub mod shader_interface;
pub mod shader_records;

pub use brick_filtering::BrickFiltering;
pub use context::GpuContext;
pub use error::GpuError;
pub use pools::UploadStats;
pub use renderer::GpuRenderer;
