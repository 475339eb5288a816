//! [`GpuRenderer`]: one pass of the frame loop on the GPU, behind the same [`FrameRenderer`] interface as the CPU
//! ray caster, so the same [`Session`](voxstream_engine::Session) (cache manager, producers, budget) drives it.
//!
//! A pass (GigaVoxels [P09] §5–6): upload the node tiles and bricks that changed ([`crate::pools`]) and the frame's
//! uniforms; run `ray_caster.wgsl`, one invocation per pending pixel; read back the pixels, each pixel's "missed
//! data" flag, the usage flags and the request list; hand the usage and the requests to the CPU's
//! [`FeedbackBuffer`], which the cache manager serves exactly as it serves the CPU renderer's.

use std::sync::mpsc;

use voxstream_core::{BrickSlot, FeedbackBuffer, Request, TileId, TreeView};
use voxstream_engine::FrameRenderer;
use voxstream_layout::{
    BrickBlend, FeedbackCounters, RayCounters, RayFrame, RequestRecord, SurfaceRecord, TransferTableEntry,
    RAY_FRAME_BLENDING, RAY_FRAME_CENTRAL_NORMALS, RAY_FRAME_COLOUR_BY_LEVEL, RAY_FRAME_PHONG, RAY_FRAME_SHADOWS,
    RAY_FRAME_SKIP_EMPTY_SPACE, RAY_FRAME_STEPS_IGNORE_STAND_INS, RAY_FRAME_SURFACES_IN_VOLUME,
};
use voxstream_render::transfer_function::LUT_SIZE;
use voxstream_render::{
    Camera, PassInputs, ProgressiveImage, RayStats, RenderError, RenderSettings, Shading, SurfaceNormals,
    SurfaceSettings, TransferLut,
};
use wgpu::util::DeviceExt;

use crate::brick_filtering::BrickFiltering;
use crate::context::GpuContext;
use crate::error::GpuError;
use crate::pools::{GpuPools, UploadStats};

/// The ray caster's WGSL: the shared records of `voxstream-layout`, then the shader. The brick atlas's declaration
/// and reads ([`BrickFiltering::wgsl`]) go between them.
pub const RAY_CASTER_WGSL: [&str; 2] =
    [include_str!("../../voxstream-layout/src/layout.wgsl"), include_str!("ray_caster.wgsl")];

/// The whole shader for bricks filtered as `filtering` says.
pub fn ray_caster_source(filtering: BrickFiltering) -> String {
    [RAY_CASTER_WGSL[0], filtering.wgsl(), RAY_CASTER_WGSL[1]].concat()
}

/// Storage buffers the ray caster binds (nodes, table, pixels, flags, feedback, usage, ranges, surfaces, blends).
const STORAGE_BUFFERS: u32 = 9;
/// Edge of a workgroup's square of pixels (`@workgroup_size(8, 8, 1)` in the shader).
const WORKGROUP_EDGE: u32 = 8;
/// Most request records one pass keeps (more are counted as dropped; their rays stay pending and ask again).
const MAX_REQUEST_RECORDS: u64 = 1 << 18;
/// A ray may not cross more segments than this (the CPU's bound).
const MAX_SEGMENTS: u32 = 1 << 20;
/// Bytes before the request records in the feedback buffer: the request counters and the ray counters.
const FEEDBACK_HEADER_BYTES: u64 = (size_of::<FeedbackCounters>() + size_of::<RayCounters>()) as u64;

/// The GPU renderer: a device, the compiled ray caster, and the pools on the GPU.
pub struct GpuRenderer {
    context: GpuContext,
    /// The ray caster compiled for volumes (emission–absorption).
    pipeline: wgpu::ComputePipeline,
    /// The ray caster compiled for isosurfaces (`ISOSURFACES`).
    surface_pipeline: wgpu::ComputePipeline,
    bind_group_layout: wgpu::BindGroupLayout,
    filtering: BrickFiltering,
    /// The atlas's sampler (trilinear, clamped), bound with hardware filtering.
    sampler: wgpu::Sampler,
    pools: Option<GpuPools>,
    table: Option<(Vec<TransferTableEntry>, wgpu::Buffer)>,
    last_upload: UploadStats,
    total_upload: UploadStats,
    passes: u64,
}

impl GpuRenderer {
    /// Opens the GPU ([`GpuContext::new`]) and compiles the ray caster, with hardware-filtered bricks where the
    /// adapter can filter them ([`BrickFiltering::best_for`]).
    pub fn new() -> Result<GpuRenderer, GpuError> {
        GpuRenderer::with_filtering(None)
    }

    /// Opens the GPU with bricks filtered as `filtering` says (`None`: the best the adapter can do); an error where
    /// the adapter cannot do what was asked.
    pub fn with_filtering(filtering: Option<BrickFiltering>) -> Result<GpuRenderer, GpuError> {
        let context = GpuContext::new()?;
        let filtering = match filtering {
            Some(asked) => asked.check(context.filters_16bit_norm, &context.info.name)?,
            None => BrickFiltering::best_for(context.filters_16bit_norm),
        };
        GpuRenderer::with_context(context, filtering)
    }

    /// The ray caster on an already open device that can filter as `filtering` says ([`BrickFiltering::check`]).
    pub fn with_context(context: GpuContext, filtering: BrickFiltering) -> Result<GpuRenderer, GpuError> {
        let filtering = filtering.check(context.filters_16bit_norm, &context.info.name)?;
        let device = &context.device;
        // Bindings 2 and 4–11: one more than WebGPU's default limit of 8, which most Vulkan adapters exceed.
        let allowed = context.limits.max_storage_buffers_per_shader_stage;
        if allowed < STORAGE_BUFFERS {
            return Err(GpuError::Device {
                adapter: context.info.name.clone(),
                reason: format!("the ray caster binds {STORAGE_BUFFERS} storage buffers, the adapter allows {allowed}"),
            });
        }
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let source = ray_caster_source(filtering);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("ray_caster.wgsl"),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
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
            uniform(0),
            uniform(1),
            storage(2, true),
            wgpu::BindGroupLayoutEntry {
                binding: 3,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: wgpu::BindingType::Texture {
                    sample_type: filtering.sample_type(),
                    view_dimension: wgpu::TextureViewDimension::D3,
                    multisampled: false,
                },
                count: None,
            },
            storage(4, true),
            storage(5, false),
            storage(6, false),
            storage(7, false),
            storage(8, false),
            storage(9, true),
            storage(10, true),
            storage(11, true),
        ];
        if filtering == BrickFiltering::Hardware {
            entries.push(wgpu::BindGroupLayoutEntry {
                binding: 12,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                count: None,
            });
        }
        let bind_group_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("ray caster"),
            entries: &entries,
        });
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("brick atlas"),
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            ..Default::default()
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("ray caster"),
            bind_group_layouts: &[Some(&bind_group_layout)],
            immediate_size: 0,
        });
        // Both variants at start: an isosurface frame then never compiles inside a pass, and a driver that cannot
        // compile either fails here, once, with the reason.
        let pipeline = compile(device, &module, &layout, false);
        let surface_pipeline = compile(device, &module, &layout, true);
        if let Some(error) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Validation(error.to_string()));
        }
        Ok(GpuRenderer {
            context,
            pipeline,
            surface_pipeline,
            bind_group_layout,
            filtering,
            sampler,
            pools: None,
            table: None,
            last_upload: UploadStats::default(),
            total_upload: UploadStats::default(),
            passes: 0,
        })
    }

    /// The adapter, in one line ([`GpuContext::describe`]).
    pub fn adapter(&self) -> String {
        self.context.describe()
    }

    /// How the bricks are filtered.
    pub fn filtering(&self) -> BrickFiltering {
        self.filtering
    }

    /// What the last pass uploaded.
    pub fn last_upload(&self) -> UploadStats {
        self.last_upload
    }

    /// What every pass so far uploaded.
    pub fn total_upload(&self) -> UploadStats {
        self.total_upload
    }

    /// Passes rendered so far.
    pub fn passes(&self) -> u64 {
        self.passes
    }

    /// GPU memory the pools occupy, bytes (`None` before the first pass).
    pub fn pool_bytes(&self) -> Option<u64> {
        self.pools.as_ref().map(GpuPools::bytes)
    }

    fn pass(
        &mut self,
        inputs: PassInputs<'_>,
        progressive: &mut ProgressiveImage,
    ) -> Result<(RayStats, usize), RenderError> {
        let PassInputs { view, feedback, camera, lut, settings } = inputs;
        settings.validate()?;
        let (width, height) = (settings.width, settings.height);
        if progressive.image.width != width || progressive.image.height != height {
            return Err(RenderError::InvalidSetting("progressive image size differs from the settings".into()));
        }
        let frame = camera.frame(width, height)?;
        let pixel_count = width as u64 * height as u64;
        let max_storage = self.context.max_storage_bytes();
        let range_bytes = (LUT_SIZE as u64 + 1 + view.brick_ranges.len() as u64 + view.block_ranges.len() as u64) * 4;
        let readback_bytes =
            pixel_count * 20 + FEEDBACK_HEADER_BYTES + MAX_REQUEST_RECORDS * 8 + usage_count(&view) * 4;
        for (what, bytes) in [
            ("image", pixel_count * 16),
            ("tile and brick usage list", usage_count(&view) * 4),
            ("brick and block range list", range_bytes),
            ("brick blend list", view.brick_blends.len() as u64 * size_of::<BrickBlend>() as u64),
            ("readback of the image and the feedback", readback_bytes),
        ] {
            if bytes > max_storage {
                return Err(GpuError::TooLarge { what, bytes, limit: max_storage }.into());
            }
        }
        let device = &self.context.device;
        let queue = &self.context.queue;
        // Out of memory is an answer, not a crash: captured like validation errors (popped in reverse order).
        let memory_scope = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let pipeline = if settings.surfaces.is_empty() { &self.pipeline } else { &self.surface_pipeline };

        // The pools: allocated at the capacity the budget gives (again when the budget changes), then only what
        // changed is written.
        if !self.pools.as_ref().is_some_and(|pools| pools.fits(&view)) {
            // The old pools go first: never both on the GPU at once.
            self.pools = None;
            self.pools = Some(GpuPools::new(device, &view, &self.context.limits, self.filtering)?);
        }
        let Some(pools) = self.pools.as_mut() else { unreachable!("pools were just made") };
        self.last_upload = pools.update(queue, &view);
        self.total_upload.add(&self.last_upload);

        // The transfer function's table (extinction per world unit), re-uploaded only when it changed.
        let entries: Vec<TransferTableEntry> = lut
            .entries()
            .iter()
            .map(|e| TransferTableEntry { r: e.color[0], g: e.color[1], b: e.color[2], a: e.sigma })
            .collect();
        if self.table.as_ref().is_none_or(|(uploaded, _)| *uploaded != entries) {
            let buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("transfer table"),
                contents: bytemuck::cast_slice(&entries),
                usage: wgpu::BufferUsages::STORAGE,
            });
            self.table = Some((entries, buffer));
        }
        let Some((_, table)) = self.table.as_ref() else { unreachable!("the table was just made") };

        let request_capacity =
            (pixel_count * settings.max_requests_per_ray.max(1) as u64).clamp(1, MAX_REQUEST_RECORDS) as u32;
        let mut ray_frame = ray_frame(&frame, settings, view.shape.n, view.shape.max_level, request_capacity);
        [ray_frame.atlas_bricks_x, ray_frame.atlas_bricks_y] = [pools.atlas[0], pools.atlas[1]];
        // Isosurfaces (Knoll et al.): the same settings the CPU's surface caster derives.
        let surfaces = SurfaceSettings::new(settings, |value| lut.normalise(value));
        let surface_records = surface_records(&surfaces);
        ray_frame.surface_count = surfaces.count() as u32;
        ray_frame.finest_voxel = (settings.placement.mean_scale() * view.shape.voxel_size(view.shape.max_level)) as f32;
        // Thiele et al.'s level blending, when the frame loop blends (interactive frames): one record per brick slot.
        if !view.brick_blends.is_empty() {
            ray_frame.flags |= RAY_FRAME_BLENDING;
        }
        let brick_atlas = pools.bricks.create_view(&wgpu::TextureViewDescriptor::default());
        let header = view.header();
        let init = |label, contents: &[u8], usage| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: Some(label), contents, usage })
        };
        let copy_src = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC;
        // Brick and block ranges (4 bytes per brick and per block: a few % of the bricks' bytes) change with every
        // brick produced: written whole each pass.
        let ranges = init("ranges", bytemuck::cast_slice(&range_words(lut, &view)), wgpu::BufferUsages::STORAGE);
        let surface_buffer = init("surfaces", bytemuck::cast_slice(&surface_records), wgpu::BufferUsages::STORAGE);
        // Written whole each pass while blending (the caps change every frame of a transition).
        let unused = [BrickBlend::FULL];
        let blend_records = if view.brick_blends.is_empty() { &unused[..] } else { view.brick_blends };
        let blend_buffer = init("brick blends", bytemuck::cast_slice(blend_records), wgpu::BufferUsages::STORAGE);
        let tree_uniform = init("tree header", bytemuck::bytes_of(&header), wgpu::BufferUsages::UNIFORM);
        let frame_uniform = init("ray frame", bytemuck::bytes_of(&ray_frame), wgpu::BufferUsages::UNIFORM);
        let pixels = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("pixels"),
            size: pixel_count * 16,
            usage: copy_src,
            mapped_at_creation: false,
        });
        let flags: Vec<u32> = progressive.pending.iter().map(|&p| p as u32).collect();
        let pixel_flags = init("pixel flags", bytemuck::cast_slice(&flags), copy_src);
        let mut feedback_header = [0u32; (FEEDBACK_HEADER_BYTES / 4) as usize];
        feedback_header[1] = request_capacity;
        let feedback_bytes = FEEDBACK_HEADER_BYTES + request_capacity as u64 * size_of::<RequestRecord>() as u64;
        let feedback_buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("feedback"),
            size: feedback_bytes,
            usage: copy_src | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        queue.write_buffer(&feedback_buffer, 0, bytemuck::cast_slice(&feedback_header));
        let usage_bytes = usage_count(&view).max(1) * 4;
        let usage = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("usage"),
            size: usage_bytes,
            usage: copy_src,
            mapped_at_creation: false,
        });
        let mut entries = vec![
            entry(0, &tree_uniform),
            entry(1, &frame_uniform),
            entry(2, &pools.nodes),
            wgpu::BindGroupEntry { binding: 3, resource: wgpu::BindingResource::TextureView(&brick_atlas) },
            entry(4, table),
            entry(5, &pixels),
            entry(6, &pixel_flags),
            entry(7, &feedback_buffer),
            entry(8, &usage),
            entry(9, &ranges),
            entry(10, &surface_buffer),
            entry(11, &blend_buffer),
        ];
        if self.filtering == BrickFiltering::Hardware {
            entries.push(wgpu::BindGroupEntry { binding: 12, resource: wgpu::BindingResource::Sampler(&self.sampler) });
        }
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("ray caster"),
            layout: &self.bind_group_layout,
            entries: &entries,
        });

        // One readback buffer: pixels, flags, feedback, usage, one after another.
        let sizes = [pixel_count * 16, pixel_count * 4, feedback_bytes, usage_bytes];
        let offsets = [0, sizes[0], sizes[0] + sizes[1], sizes[0] + sizes[1] + sizes[2]];
        let readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: sizes.iter().sum(),
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("pass") });
        {
            let mut compute = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor::default());
            compute.set_pipeline(pipeline);
            compute.set_bind_group(0, &bind_group, &[]);
            compute.dispatch_workgroups(width.div_ceil(WORKGROUP_EDGE), height.div_ceil(WORKGROUP_EDGE), 1);
        }
        for (source, (&offset, &size)) in
            [&pixels, &pixel_flags, &feedback_buffer, &usage].iter().zip(offsets.iter().zip(&sizes))
        {
            encoder.copy_buffer_to_buffer(source, 0, &readback, offset, size);
        }
        queue.submit([encoder.finish()]);
        let (sender, receiver) = mpsc::channel();
        readback.map_async(wgpu::MapMode::Read, .., move |result| {
            let _ = sender.send(result);
        });
        device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| GpuError::Readback(e.to_string()))?;
        if let Some(error) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Validation(error.to_string()).into());
        }
        if let Some(error) = pollster::block_on(memory_scope.pop()) {
            return Err(GpuError::OutOfMemory(error.to_string()).into());
        }
        receiver
            .recv()
            .map_err(|e| GpuError::Readback(e.to_string()))?
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        let mapped = readback.get_mapped_range(..).map_err(|e| GpuError::Readback(e.to_string()))?;
        let bytes: &[u8] = &mapped;
        let section = |i: usize| &bytes[offsets[i] as usize..(offsets[i] + sizes[i]) as usize];
        let traced_pixels: &[[f32; 4]] = bytemuck::cast_slice(section(0));
        let traced_flags: &[u32] = bytemuck::cast_slice(section(1));
        for (index, (&flag, pixel)) in traced_flags.iter().zip(traced_pixels).enumerate() {
            if flag != 0 {
                progressive.image.pixels[index] = *pixel;
                progressive.pending[index] = flag == 2;
            }
        }
        let feedback_section = section(2);
        let counters: FeedbackCounters =
            bytemuck::pod_read_unaligned(&feedback_section[..size_of::<FeedbackCounters>()]);
        let rays: RayCounters = bytemuck::pod_read_unaligned(
            &feedback_section[size_of::<FeedbackCounters>()..FEEDBACK_HEADER_BYTES as usize],
        );
        let kept = counters.request_count.min(request_capacity) as usize;
        let records: &[RequestRecord] = bytemuck::cast_slice(
            &feedback_section[FEEDBACK_HEADER_BYTES as usize..][..kept * size_of::<RequestRecord>()],
        );
        let mut requests: Vec<Request> = records.iter().filter_map(|&r| Request::from_record(r)).collect();
        requests.sort_unstable();
        requests.dedup();
        feedback.push_requests(&requests);
        let usage_flags: &[u32] = bytemuck::cast_slice(section(3));
        let tiles = view.nodes.len() / view.shape.nodes_per_tile() as usize;
        for (index, &used) in usage_flags.iter().enumerate() {
            if used != 0 {
                if index < tiles {
                    feedback.mark_tile(TileId(index as u32));
                } else {
                    feedback.mark_brick(BrickSlot((index - tiles) as u32));
                }
            }
        }
        drop(mapped);
        readback.unmap();
        self.passes += 1;
        let stats = RayStats {
            rays: rays.rays as u64,
            samples: rays.samples as u64,
            descents: rays.descents as u64,
            ..RayStats::default()
        };
        Ok((stats, counters.request_count as usize))
    }
}

impl FrameRenderer for GpuRenderer {
    fn render_pass(
        &mut self,
        inputs: PassInputs<'_>,
        progressive: &mut ProgressiveImage,
    ) -> Result<(RayStats, usize), RenderError> {
        self.pass(inputs, progressive)
    }

    fn describe(&self) -> String {
        format!("gpu: {}, {}", self.adapter(), self.filtering.describe())
    }

    fn bytes_uploaded(&self) -> u64 {
        self.total_upload.bytes()
    }

    /// The atlas holds 16-bit texels whatever the pool holds.
    fn needs_sixteen_bit_bricks(&self) -> bool {
        true
    }
}

/// The ray caster's pipeline, for isosurfaces or for volumes (the shader's `ISOSURFACES` constant).
fn compile(
    device: &wgpu::Device,
    module: &wgpu::ShaderModule,
    layout: &wgpu::PipelineLayout,
    isosurfaces: bool,
) -> wgpu::ComputePipeline {
    let constants = [("ISOSURFACES", if isosurfaces { 1.0 } else { 0.0 })];
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(if isosurfaces { "ray caster (isosurfaces)" } else { "ray caster (volumes)" }),
        layout: Some(layout),
        module,
        entry_point: Some("main"),
        compilation_options: wgpu::PipelineCompilationOptions { constants: &constants, ..Default::default() },
        cache: None,
    })
}

/// What empty-space skipping reads: per transfer-table index, the entries with non-zero extinction before it (one
/// more than the table's length), then per brick slot its `[min, max]` voxel as `min | max << 16`, then per slot
/// its occupancy blocks' ranges, packed the same way.
fn range_words(lut: &TransferLut, view: &TreeView<'_>) -> Vec<u32> {
    let entries = lut.entries();
    let mut words = Vec::with_capacity(entries.len() + 1 + view.brick_ranges.len());
    let mut visible = 0u32;
    words.push(0);
    for entry in entries {
        visible += (entry.sigma > 0.0) as u32;
        words.push(visible);
    }
    let pack = |&[lo, hi]: &[u16; 2]| lo as u32 | (hi as u32) << 16;
    words.extend(view.brick_ranges.iter().map(pack));
    words.extend(view.block_ranges.iter().map(pack));
    words
}

/// Usage flags of a pass: one per node tile, then one per brick slot.
fn usage_count(view: &TreeView<'_>) -> u64 {
    let header = view.header();
    (view.nodes.len() as u64 / header.nodes_per_tile.max(1) as u64) + header.brick_count as u64
}

fn entry(binding: u32, buffer: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry { binding, resource: buffer.as_entire_binding() }
}

/// The anchor of the shader's positions (see `voxstream_layout::ray_frame`): the deepest level whose node
/// coordinates fit in an `i32` (`N^level < 2³¹`, and no deeper than the tree), and the node there that holds `eye`
/// (clamped into the clip box and the unit cube). Returns the level, its scale `N^level` and the node's coordinates.
pub fn anchor(eye: [f64; 3], clip: [[f64; 3]; 2], n: u32, max_level: u32) -> (u32, f64, [u32; 3]) {
    let (mut level, mut scale) = (0u32, 1u64);
    while level < max_level && scale * n as u64 <= i32::MAX as u64 {
        level += 1;
        scale *= n as u64;
    }
    let coordinates = std::array::from_fn(|a| {
        let lower = clip[0][a].max(0.0);
        let upper = clip[1][a].min(1.0).max(lower);
        let inside = if eye[a].is_finite() { eye[a].clamp(lower, upper) } else { lower };
        ((inside * scale as f64).floor().max(0.0) as u64).min(scale - 1) as u32
    });
    (level, scale as f64, coordinates)
}

/// The frame's camera and settings as the shader reads them.
fn ray_frame(
    frame: &voxstream_render::CameraFrame,
    settings: &RenderSettings,
    n: u32,
    max_level: u32,
    request_capacity: u32,
) -> RayFrame {
    let placement = &settings.placement;
    let eye: [f64; 3] = std::array::from_fn(|a| (frame.eye[a] - placement.origin[a]) / placement.scale[a]);
    let (anchor_level, anchor_scale, anchor) = anchor(eye, [placement.clip_lower, placement.clip_upper], n, max_level);
    // Unit cube → anchor frame, in f64, rounded once.
    let to_anchor =
        |p: [f64; 3]| -> [f32; 3] { std::array::from_fn(|a| (p[a] * anchor_scale - anchor[a] as f64) as f32) };
    let (eye, clip_lower, clip_upper) =
        (to_anchor(eye), to_anchor(placement.clip_lower), to_anchor(placement.clip_upper));
    let light = settings.light_direction.map_or([0.0; 3], |l| {
        let length = (l[0] * l[0] + l[1] * l[1] + l[2] * l[2]).sqrt();
        if length > 0.0 {
            l.map(|c| (c / length) as f32)
        } else {
            [0.0; 3]
        }
    });
    let mut flags = 0;
    if settings.shading == Shading::Phong {
        flags |= RAY_FRAME_PHONG;
    }
    if settings.steps_ignore_stand_ins {
        flags |= RAY_FRAME_STEPS_IGNORE_STAND_INS;
    }
    if settings.colour_by_level {
        flags |= RAY_FRAME_COLOUR_BY_LEVEL;
    }
    if settings.skip_empty_space {
        flags |= RAY_FRAME_SKIP_EMPTY_SPACE;
    }
    if settings.surface_normals == SurfaceNormals::CentralDifferences {
        flags |= RAY_FRAME_CENTRAL_NORMALS;
    }
    if settings.surfaces_in_volume {
        flags |= RAY_FRAME_SURFACES_IN_VOLUME;
    }
    // As `SurfaceCaster`: shadows from a fixed light, with Phong shading.
    if settings.shadows && settings.shading == Shading::Phong && light != [0.0; 3] {
        flags |= RAY_FRAME_SHADOWS;
    }
    RayFrame {
        width: settings.width,
        height: settings.height,
        pixel_stride: settings.pixel_stride.max(1),
        max_requests_per_ray: settings.max_requests_per_ray,
        flags,
        stand_in_levels: if n <= 2 { 2 } else { 1 },
        request_capacity,
        max_segments: MAX_SEGMENTS,
        eye_x: eye[0],
        eye_y: eye[1],
        eye_z: eye[2],
        pixel_spread: frame.pixel_spread as f32,
        forward_x: frame.forward.x as f32,
        forward_y: frame.forward.y as f32,
        forward_z: frame.forward.z as f32,
        world_per_volume: placement.mean_scale() as f32,
        right_x: frame.right.x as f32,
        right_y: frame.right.y as f32,
        right_z: frame.right.z as f32,
        lod_bias: settings.lod_bias as f32,
        up_x: frame.up.x as f32,
        up_y: frame.up.y as f32,
        up_z: frame.up.z as f32,
        step_factor: settings.step_factor as f32,
        inverse_scale_x: (1.0 / placement.scale[0]) as f32,
        inverse_scale_y: (1.0 / placement.scale[1]) as f32,
        inverse_scale_z: (1.0 / placement.scale[2]) as f32,
        bias_scale: (-settings.lod_bias * (n as f64).ln()).exp() as f32,
        clip_lower_x: clip_lower[0],
        clip_lower_y: clip_lower[1],
        clip_lower_z: clip_lower[2],
        stop_below: 1.0 - settings.opacity_cutoff,
        clip_upper_x: clip_upper[0],
        clip_upper_y: clip_upper[1],
        clip_upper_z: clip_upper[2],
        ambient: settings.phong.ambient,
        background_r: settings.background[0],
        background_g: settings.background[1],
        background_b: settings.background[2],
        diffuse: settings.phong.diffuse,
        light_x: light[0],
        light_y: light[1],
        light_z: light[2],
        specular: settings.phong.specular,
        shininess: settings.phong.shininess,
        atlas_bricks_x: 1,
        atlas_bricks_y: 1,
        anchor_level,
        anchor_x: anchor[0],
        anchor_y: anchor[1],
        anchor_z: anchor[2],
        anchor_scale: anchor_scale as f32,
        surface_count: 0,
        finest_voxel: 0.0,
        reserved0: 0,
        reserved1: 0,
    }
}

/// The frame's isosurfaces as the shader reads them; one unused record where there are none (a binding may not be
/// empty).
fn surface_records(surfaces: &SurfaceSettings) -> Vec<SurfaceRecord> {
    let mut records: Vec<SurfaceRecord> = (0..surfaces.count())
        .map(|i| {
            let s = surfaces.surface(i);
            SurfaceRecord {
                iso: s.iso,
                lower: s.lower,
                upper: s.upper,
                opacity: s.opacity,
                r: s.color[0],
                g: s.color[1],
                b: s.color[2],
                reserved: 0,
            }
        })
        .collect();
    if records.is_empty() {
        records.push(SurfaceRecord::default());
    }
    records
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_anchor_is_the_deepest_node_holding_the_eye_that_an_i32_can_name() {
        let clip = [[0.0; 3], [1.0; 3]];
        // N = 3: 3^19 < 2^31 < 3^20.
        let (level, scale, node) = anchor([0.5, 0.25, 1.0 + 1e-9], clip, 3, 25);
        assert_eq!((level, scale), (19, 3f64.powi(19)));
        assert_eq!(node[0] as f64, (0.5 * scale).floor());
        assert_eq!(node[1] as f64, (0.25 * scale).floor());
        assert_eq!(node[2] as f64, scale - 1.0, "an eye outside is clamped to the last node");
        // N = 2: 2^30; a shallow tree stops at its deepest level.
        assert_eq!(anchor([0.5; 3], clip, 2, 40).0, 30);
        assert_eq!(anchor([0.5; 3], clip, 2, 7), (7, 128.0, [64; 3]));
        // Far outside, below the clip box, or not finite: the nearest node inside.
        assert_eq!(anchor([-5.0, f64::NAN, 0.3], [[0.25; 3], [0.75; 3]], 2, 2).2, [1, 1, 1]);
    }
}
