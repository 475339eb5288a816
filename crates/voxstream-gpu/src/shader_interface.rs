//! What the host and the ray caster's WGSL share by number, named once on the Rust side: the bindings of
//! `bindings.wgsl` (group, number and kind of each), the pixel flags, the workgroup's edge and the packing of the
//! value ranges. [`crate::renderer`] builds its bind group layout ([`layout_entries`]) and bind groups from these
//! names, never from literals.
//!
//! The WGSL cannot import Rust, so it repeats each value; `tests/shader_interface.rs` parses the joined shader and
//! checks every `const` that has a Rust twin (these, `voxstream_layout`'s, and the CPU renderer's that the shader
//! mirrors) and every `@group(g) @binding(b) var` against [`BINDINGS`] and [`layout_entries`]: a binding added to
//! the WGSL fails that test until it is added here.

use crate::brick_filtering::BrickFiltering;

/// The ray caster's one bind group.
pub const GROUP: u32 = 0;

/// The ray caster's binding numbers, by the name of the WGSL variable bound there.
pub mod binding {
    /// `tree`: the [`TreeHeader`](voxstream_layout::TreeHeader) uniform.
    pub const TREE: u32 = 0;
    /// `frame`: the [`RayFrame`](voxstream_layout::RayFrame) uniform.
    pub const FRAME: u32 = 1;
    /// `nodes`: the node pool.
    pub const NODES: u32 = 2;
    /// `bricks`: the brick atlas, a 3D texture (declared by [`BrickFiltering::wgsl`](crate::BrickFiltering::wgsl)).
    pub const BRICKS: u32 = 3;
    /// `table`: the transfer function's entries.
    pub const TABLE: u32 = 4;
    /// `pixels`: the traced pixels, written.
    pub const PIXELS: u32 = 5;
    /// `pixel_flags`: per pixel, pending in, [`PIXEL_DONE`](super::PIXEL_DONE) or
    /// [`PIXEL_MISSED`](super::PIXEL_MISSED) out.
    pub const PIXEL_FLAGS: u32 = 6;
    /// `feedback`: the request counters, the ray counters and the request records.
    pub const FEEDBACK: u32 = 7;
    /// `usage`: one flag per node tile, then one per brick slot.
    pub const USAGE: u32 = 8;
    /// `ranges`: what empty-space skipping reads ([`crate::shader_records`]'s `range_words`).
    pub const RANGES: u32 = 9;
    /// `surfaces`: the frame's isosurfaces.
    pub const SURFACES: u32 = 10;
    /// `blends`: per brick slot, its level-blending caps.
    pub const BLENDS: u32 = 11;
    /// `brick_sampler`: the atlas's sampler, with hardware filtering only.
    pub const BRICK_SAMPLER: u32 = 12;
}

/// Every binding of the ray caster (group [`GROUP`]): the WGSL variable's name and its number. The sampler is bound
/// with [`BrickFiltering::Hardware`] only.
pub const BINDINGS: [(&str, u32); 13] = [
    ("tree", binding::TREE),
    ("frame", binding::FRAME),
    ("nodes", binding::NODES),
    ("bricks", binding::BRICKS),
    ("table", binding::TABLE),
    ("pixels", binding::PIXELS),
    ("pixel_flags", binding::PIXEL_FLAGS),
    ("feedback", binding::FEEDBACK),
    ("usage", binding::USAGE),
    ("ranges", binding::RANGES),
    ("surfaces", binding::SURFACES),
    ("blends", binding::BLENDS),
    ("brick_sampler", binding::BRICK_SAMPLER),
];

/// `pixel_flags` out: the pixel was not traced this pass (in: not pending).
pub const PIXEL_UNTRACED: u32 = 0;
/// `pixel_flags` in: trace this pixel's ray this pass.
pub const PIXEL_PENDING: u32 = 1;
/// `pixel_flags` out: traced, and complete.
pub const PIXEL_DONE: u32 = 1;
/// `pixel_flags` out: traced, but it missed data (trace it again next pass).
pub const PIXEL_MISSED: u32 = 2;

/// Edge of a workgroup's square of pixels (`@workgroup_size(WORKGROUP_EDGE, WORKGROUP_EDGE, 1)`).
pub const WORKGROUP_EDGE: u32 = 8;

/// A packed value range (`ranges`, two 16-bit voxels): the maximum above this shift …
pub const RANGE_HIGH_SHIFT: u32 = 16;
/// … the minimum below it.
pub const RANGE_LOW_MASK: u32 = (1 << RANGE_HIGH_SHIFT) - 1;

/// The bind group layout's entries for bricks filtered as `filtering` says: every binding of [`BINDINGS`] the
/// shader declares with that filtering, of the kind its WGSL declaration has.
pub fn layout_entries(filtering: BrickFiltering) -> Vec<wgpu::BindGroupLayoutEntry> {
    let storage = |binding, read_only| wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    };
    let uniform = |binding| wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    };
    let mut entries = vec![
        uniform(binding::TREE),
        uniform(binding::FRAME),
        storage(binding::NODES, true),
        wgpu::BindGroupLayoutEntry {
            binding: binding::BRICKS,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Texture {
                sample_type: filtering.sample_type(),
                view_dimension: wgpu::TextureViewDimension::D3,
                multisampled: false,
            },
            count: None,
        },
        storage(binding::TABLE, true),
        storage(binding::PIXELS, false),
        storage(binding::PIXEL_FLAGS, false),
        storage(binding::FEEDBACK, false),
        storage(binding::USAGE, false),
        storage(binding::RANGES, true),
        storage(binding::SURFACES, true),
        storage(binding::BLENDS, true),
    ];
    if filtering == BrickFiltering::Hardware {
        entries.push(wgpu::BindGroupLayoutEntry {
            binding: binding::BRICK_SAMPLER,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
            count: None,
        });
    }
    entries
}

/// Storage buffers among `entries` (what the adapter's `max_storage_buffers_per_shader_stage` must allow).
pub fn storage_buffers(entries: &[wgpu::BindGroupLayoutEntry]) -> u32 {
    let is_storage = |e: &&wgpu::BindGroupLayoutEntry| {
        matches!(e.ty, wgpu::BindingType::Buffer { ty: wgpu::BufferBindingType::Storage { .. }, .. })
    };
    entries.iter().filter(is_storage).count() as u32
}
