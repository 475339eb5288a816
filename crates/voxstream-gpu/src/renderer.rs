//! [`GpuRenderer`]: one pass of the frame loop on the GPU, behind the same [`FrameRenderer`] interface as the CPU
//! ray caster, so the same [`Session`](voxstream_engine::Session) (cache manager, producers, budget) drives it.
//!
//! A pass (GigaVoxels [P09] §5–6): upload the node tiles and bricks that changed ([`crate::pools`]) and the frame's
//! uniforms; run the ray caster's shader ([`crate::shader`]), one invocation per pending pixel; read back the pixels, each pixel's "missed
//! data" flag, the usage flags and the request list; hand the usage and the requests to the CPU's
//! [`FeedbackBuffer`], which the cache manager serves exactly as it serves the CPU renderer's.

use std::sync::mpsc;

use voxstream_core::{BrickSlot, FeedbackBuffer, Request, TileId, TreeView};
use voxstream_engine::FrameRenderer;
use voxstream_layout::{
    BrickBlend, FeedbackCounters, RayCounters, RayFrame, RequestRecord, SurfaceRecord, TransferTableEntry,
    RAY_FRAME_ADAPTIVE_STEP, RAY_FRAME_BLENDING,
};
use voxstream_render::transfer_function::LUT_SIZE;
use voxstream_render::{
    Camera, CameraFrame, PassInputs, ProgressiveImage, RayStats, RenderError, RenderSettings, SurfaceSettings,
    TransferLut,
};
use wgpu::util::DeviceExt;

use crate::brick_filtering::BrickFiltering;
use crate::context::GpuContext;
use crate::error::GpuError;
use crate::pools::{GpuPools, UploadStats};
use crate::shader::ray_caster_source;
use crate::shader_interface::{
    binding, layout_entries, storage_buffers, GROUP, PIXEL_MISSED, PIXEL_PENDING, PIXEL_UNTRACED, WORKGROUP_EDGE,
};
pub use crate::shader_records::anchor;
use crate::shader_records::{range_words, ray_frame, surface_records};

/// Most request records one pass keeps (more are counted as dropped; their rays stay pending and ask again).
const MAX_REQUEST_RECORDS: u64 = 1 << 18;
/// Bytes before the request records in the feedback buffer: the request counters and the ray counters.
const FEEDBACK_HEADER_BYTES: u64 = (size_of::<FeedbackCounters>() + size_of::<RayCounters>()) as u64;

const _: () = assert!(GROUP == 0, "the pipeline layout lists the ray caster's group first");

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
        let entries = layout_entries(filtering);
        // Nine (nodes, table, pixels, flags, feedback, usage, ranges, surfaces, blends): one more than WebGPU's
        // default limit of 8, which most Vulkan adapters exceed.
        let (allowed, needed) = (context.limits.max_storage_buffers_per_shader_stage, storage_buffers(&entries));
        if allowed < needed {
            return Err(GpuError::Device {
                adapter: context.info.name.clone(),
                reason: format!("the ray caster binds {needed} storage buffers, the adapter allows {allowed}"),
            });
        }
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let source = ray_caster_source(filtering);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("ray caster (src/shader)"),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
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
            // The ray caster's only group, GROUP, is the first.
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

    /// One pass: checks, uploads, per-pass buffers, dispatch, readback, feedback, in that order.
    fn pass(
        &mut self,
        inputs: PassInputs<'_>,
        progressive: &mut ProgressiveImage,
    ) -> Result<(RayStats, usize), RenderError> {
        let PassInputs { view, feedback, camera, lut, settings } = inputs;
        let frame = self.check_pass(&view, camera, settings, progressive)?;
        let device = &self.context.device;
        // Out of memory is an answer, not a crash: captured like validation errors (popped in reverse order).
        let memory_scope = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        self.upload_pools(&view)?;
        self.upload_table(lut);
        let (ray_frame, request_capacity, surface_records) = self.ray_frame(&frame, &view, lut, settings);
        let buffers = self.pass_buffers(&view, lut, &ray_frame, &surface_records, request_capacity, progressive);
        let bind_group = self.bind_group(&buffers);
        let readback = self.dispatch(settings, &buffers, &bind_group);
        self.wait_for_readback(&readback, memory_scope, scope)?;
        let (counters, rays) = read_back(&readback, &view, feedback, request_capacity, progressive)?;
        self.passes += 1;
        let stats = RayStats {
            rays: rays.rays as u64,
            samples: rays.samples as u64,
            descents: rays.descents as u64,
            ..RayStats::default()
        };
        Ok((stats, counters.request_count as usize))
    }

    /// Checks the settings, the image's size and the camera, and that every buffer the pass needs fits the device's
    /// storage limit; returns the camera's frame.
    fn check_pass(
        &self,
        view: &TreeView<'_>,
        camera: &Camera,
        settings: &RenderSettings,
        progressive: &ProgressiveImage,
    ) -> Result<CameraFrame, RenderError> {
        settings.validate()?;
        // The CPU's volume-rendering option the shader does not mirror yet (issue 46): refused, never ignored.
        if (settings.surfaces.is_empty() || settings.surfaces_in_volume) && settings.preintegrated {
            let (what, instead) = ("pre-integration (--preintegrate)", "--backend cpu, or drop --preintegrate");
            return Err(GpuError::Unsupported { what, instead }.into());
        }
        // Nor projections and clipping planes (issue 42): refused, never ignored.
        if settings.projection != voxstream_render::Projection::Composite {
            let (what, instead) = ("intensity projections (--projection)", "--backend cpu, or drop --projection");
            return Err(GpuError::Unsupported { what, instead }.into());
        }
        if !settings.clip_planes.is_empty() {
            let (what, instead) = ("clipping planes (--clip-plane)", "--backend cpu, or --crop for a box");
            return Err(GpuError::Unsupported { what, instead }.into());
        }
        if settings.volume_slice.is_some() {
            let (what, instead) = ("slices drawn with the volume (--with-volume)", "--backend cpu");
            return Err(GpuError::Unsupported { what, instead }.into());
        }
        let (width, height) = (settings.width, settings.height);
        if progressive.image.width != width || progressive.image.height != height {
            return Err(RenderError::InvalidSetting("progressive image size differs from the settings".into()));
        }
        let frame = camera.frame(width, height)?;
        let pixel_count = width as u64 * height as u64;
        let max_storage = self.context.max_storage_bytes();
        let variation_words = if settings.adaptive_step.is_some() { LUT_SIZE as u64 } else { 0 };
        let range_bytes =
            (LUT_SIZE as u64 + 1 + view.brick_ranges.len() as u64 + view.block_ranges.len() as u64 + variation_words)
                * 4;
        let readback_bytes = pixel_count * 20 + FEEDBACK_HEADER_BYTES + MAX_REQUEST_RECORDS * 8 + usage_count(view) * 4;
        for (what, bytes) in [
            ("image", pixel_count * 16),
            ("tile and brick usage list", usage_count(view) * 4),
            ("brick and block range list", range_bytes),
            ("brick blend list", view.brick_blends.len() as u64 * size_of::<BrickBlend>() as u64),
            ("readback of the image and the feedback", readback_bytes),
        ] {
            if bytes > max_storage {
                return Err(GpuError::TooLarge { what, bytes, limit: max_storage }.into());
            }
        }
        Ok(frame)
    }

    /// The pools: allocated at the capacity the budget gives (again when the budget changes), then only what
    /// changed is written.
    fn upload_pools(&mut self, view: &TreeView<'_>) -> Result<(), RenderError> {
        let device = &self.context.device;
        if !self.pools.as_ref().is_some_and(|pools| pools.fits(view)) {
            // The old pools go first: never both on the GPU at once.
            self.pools = None;
            self.pools = Some(GpuPools::new(device, view, &self.context.limits, self.filtering)?);
        }
        let Some(pools) = self.pools.as_mut() else { unreachable!("pools were just made") };
        self.last_upload = pools.update(&self.context.queue, view);
        self.total_upload.add(&self.last_upload);
        Ok(())
    }

    /// The transfer function's table (extinction per world unit), re-uploaded only when it changed.
    fn upload_table(&mut self, lut: &TransferLut) {
        let entries: Vec<TransferTableEntry> = lut
            .entries()
            .iter()
            .map(|e| TransferTableEntry { r: e.color[0], g: e.color[1], b: e.color[2], a: e.sigma })
            .collect();
        if self.table.as_ref().is_none_or(|(uploaded, _)| *uploaded != entries) {
            let buffer = self.context.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("transfer table"),
                contents: bytemuck::cast_slice(&entries),
                usage: wgpu::BufferUsages::STORAGE,
            });
            self.table = Some((entries, buffer));
        }
    }

    /// The frame's uniforms: the ray frame (with the atlas's size, the surfaces and the blending flag), the number
    /// of request records the feedback buffer keeps, and the isosurfaces' records.
    fn ray_frame(
        &self,
        frame: &CameraFrame,
        view: &TreeView<'_>,
        lut: &TransferLut,
        settings: &RenderSettings,
    ) -> (RayFrame, u32, Vec<SurfaceRecord>) {
        let Some(pools) = self.pools.as_ref() else { unreachable!("the pools are uploaded first") };
        let pixel_count = settings.width as u64 * settings.height as u64;
        let request_capacity =
            (pixel_count * settings.max_requests_per_ray.max(1) as u64).clamp(1, MAX_REQUEST_RECORDS) as u32;
        let mut ray_frame = ray_frame(frame, settings, view.shape.n, view.shape.max_level, request_capacity);
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
        (ray_frame, request_capacity, surface_records)
    }

    /// The pass's own buffers, made and written: ranges, surfaces, blends, the two uniforms, the pixels and their
    /// pending flags, the feedback (its header written) and the usage flags.
    fn pass_buffers(
        &self,
        view: &TreeView<'_>,
        lut: &TransferLut,
        ray_frame: &RayFrame,
        surface_records: &[SurfaceRecord],
        request_capacity: u32,
        progressive: &ProgressiveImage,
    ) -> PassBuffers {
        let device = &self.context.device;
        let Some(pools) = self.pools.as_ref() else { unreachable!("the pools are uploaded first") };
        let pixel_count = progressive.image.width as u64 * progressive.image.height as u64;
        let brick_atlas = pools.bricks.create_view(&wgpu::TextureViewDescriptor::default());
        let header = view.header();
        let init = |label, contents: &[u8], usage| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: Some(label), contents, usage })
        };
        let copy_src = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC;
        // Brick and block ranges (4 bytes per brick and per block: a few % of the bricks' bytes) change with every
        // brick produced: written whole each pass.
        let adaptive = ray_frame.flags & RAY_FRAME_ADAPTIVE_STEP != 0;
        let ranges =
            init("ranges", bytemuck::cast_slice(&range_words(lut, view, adaptive)), wgpu::BufferUsages::STORAGE);
        let surfaces = init("surfaces", bytemuck::cast_slice(surface_records), wgpu::BufferUsages::STORAGE);
        // Written whole each pass while blending (the caps change every frame of a transition).
        let unused = [BrickBlend::FULL];
        let blend_records = if view.brick_blends.is_empty() { &unused[..] } else { view.brick_blends };
        let blends = init("brick blends", bytemuck::cast_slice(blend_records), wgpu::BufferUsages::STORAGE);
        let tree_uniform = init("tree header", bytemuck::bytes_of(&header), wgpu::BufferUsages::UNIFORM);
        let frame_uniform = init("ray frame", bytemuck::bytes_of(ray_frame), wgpu::BufferUsages::UNIFORM);
        let pixels = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("pixels"),
            size: pixel_count * 16,
            usage: copy_src,
            mapped_at_creation: false,
        });
        let flags: Vec<u32> =
            progressive.pending.iter().map(|&p| if p { PIXEL_PENDING } else { PIXEL_UNTRACED }).collect();
        let pixel_flags = init("pixel flags", bytemuck::cast_slice(&flags), copy_src);
        let mut feedback_header = [0u32; (FEEDBACK_HEADER_BYTES / 4) as usize];
        feedback_header[1] = request_capacity;
        let feedback_bytes = FEEDBACK_HEADER_BYTES + request_capacity as u64 * size_of::<RequestRecord>() as u64;
        let feedback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("feedback"),
            size: feedback_bytes,
            usage: copy_src | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        self.context.queue.write_buffer(&feedback, 0, bytemuck::cast_slice(&feedback_header));
        let usage_bytes = usage_count(view).max(1) * 4;
        let usage = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("usage"),
            size: usage_bytes,
            usage: copy_src,
            mapped_at_creation: false,
        });
        PassBuffers {
            brick_atlas,
            ranges,
            surfaces,
            blends,
            tree_uniform,
            frame_uniform,
            pixels,
            pixel_flags,
            feedback,
            usage,
            sizes: [pixel_count * 16, pixel_count * 4, feedback_bytes, usage_bytes],
        }
    }

    /// The ray caster's bind group: the pass's buffers, the pools, the table and (hardware filtering) the sampler.
    fn bind_group(&self, buffers: &PassBuffers) -> wgpu::BindGroup {
        let Some(pools) = self.pools.as_ref() else { unreachable!("the pools are uploaded first") };
        let Some((_, table)) = self.table.as_ref() else { unreachable!("the table is uploaded first") };
        let mut entries = vec![
            entry(binding::TREE, &buffers.tree_uniform),
            entry(binding::FRAME, &buffers.frame_uniform),
            entry(binding::NODES, &pools.nodes),
            wgpu::BindGroupEntry {
                binding: binding::BRICKS,
                resource: wgpu::BindingResource::TextureView(&buffers.brick_atlas),
            },
            entry(binding::TABLE, table),
            entry(binding::PIXELS, &buffers.pixels),
            entry(binding::PIXEL_FLAGS, &buffers.pixel_flags),
            entry(binding::FEEDBACK, &buffers.feedback),
            entry(binding::USAGE, &buffers.usage),
            entry(binding::RANGES, &buffers.ranges),
            entry(binding::SURFACES, &buffers.surfaces),
            entry(binding::BLENDS, &buffers.blends),
        ];
        if self.filtering == BrickFiltering::Hardware {
            entries.push(wgpu::BindGroupEntry {
                binding: binding::BRICK_SAMPLER,
                resource: wgpu::BindingResource::Sampler(&self.sampler),
            });
        }
        self.context.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("ray caster"),
            layout: &self.bind_group_layout,
            entries: &entries,
        })
    }

    /// Runs the ray caster (one invocation per pixel), copies pixels, flags, feedback and usage into one readback
    /// buffer, submits, and asks for the readback to be mapped.
    fn dispatch(&self, settings: &RenderSettings, buffers: &PassBuffers, bind_group: &wgpu::BindGroup) -> Readback {
        let device = &self.context.device;
        let pipeline = if settings.surfaces.is_empty() { &self.pipeline } else { &self.surface_pipeline };
        // One readback buffer: pixels, flags, feedback, usage, one after another.
        let sizes = buffers.sizes;
        let offsets = [0, sizes[0], sizes[0] + sizes[1], sizes[0] + sizes[1] + sizes[2]];
        let buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: sizes.iter().sum(),
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("pass") });
        {
            let mut compute = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor::default());
            compute.set_pipeline(pipeline);
            compute.set_bind_group(GROUP, bind_group, &[]);
            compute.dispatch_workgroups(
                settings.width.div_ceil(WORKGROUP_EDGE),
                settings.height.div_ceil(WORKGROUP_EDGE),
                1,
            );
        }
        let sources = [&buffers.pixels, &buffers.pixel_flags, &buffers.feedback, &buffers.usage];
        for (source, (&offset, &size)) in sources.iter().zip(offsets.iter().zip(&sizes)) {
            encoder.copy_buffer_to_buffer(source, 0, &buffer, offset, size);
        }
        self.context.queue.submit([encoder.finish()]);
        let (sender, receiver) = mpsc::channel();
        buffer.map_async(wgpu::MapMode::Read, .., move |result| {
            let _ = sender.send(result);
        });
        Readback { buffer, offsets, sizes, mapped: receiver }
    }

    /// Waits for the GPU, then turns what the error scopes caught (validation first, then out of memory) and a
    /// failed mapping into errors.
    fn wait_for_readback(
        &self,
        readback: &Readback,
        // In the order they were pushed: dropped unpopped (on an early error) in reverse, as a stack of scopes.
        memory_scope: wgpu::ErrorScopeGuard,
        scope: wgpu::ErrorScopeGuard,
    ) -> Result<(), RenderError> {
        let device = &self.context.device;
        device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| GpuError::Readback(e.to_string()))?;
        if let Some(error) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Validation(error.to_string()).into());
        }
        if let Some(error) = pollster::block_on(memory_scope.pop()) {
            return Err(GpuError::OutOfMemory(error.to_string()).into());
        }
        readback
            .mapped
            .recv()
            .map_err(|e| GpuError::Readback(e.to_string()))?
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        Ok(())
    }
}

/// The buffers one pass makes besides the pools and the transfer table.
struct PassBuffers {
    /// The brick atlas, as the shader binds it.
    brick_atlas: wgpu::TextureView,
    ranges: wgpu::Buffer,
    surfaces: wgpu::Buffer,
    blends: wgpu::Buffer,
    tree_uniform: wgpu::Buffer,
    frame_uniform: wgpu::Buffer,
    pixels: wgpu::Buffer,
    pixel_flags: wgpu::Buffer,
    feedback: wgpu::Buffer,
    usage: wgpu::Buffer,
    /// Bytes of the pixels, their flags, the feedback and the usage: the readback's sections.
    sizes: [u64; 4],
}

/// The readback buffer of one pass, its sections (pixels, flags, feedback, usage) and the answer of its mapping.
struct Readback {
    buffer: wgpu::Buffer,
    offsets: [u64; 4],
    sizes: [u64; 4],
    mapped: mpsc::Receiver<Result<(), wgpu::BufferAsyncError>>,
}

/// Reads the mapped readback: the traced pixels into `progressive`, the requests (sorted, deduplicated) and the
/// usage flags into `feedback`; returns the request and ray counters.
fn read_back(
    readback: &Readback,
    view: &TreeView<'_>,
    feedback: &FeedbackBuffer,
    request_capacity: u32,
    progressive: &mut ProgressiveImage,
) -> Result<(FeedbackCounters, RayCounters), RenderError> {
    let Readback { buffer, offsets, sizes, .. } = readback;
    let mapped = buffer.get_mapped_range(..).map_err(|e| GpuError::Readback(e.to_string()))?;
    let bytes: &[u8] = &mapped;
    let section = |i: usize| &bytes[offsets[i] as usize..(offsets[i] + sizes[i]) as usize];
    let traced_pixels: &[[f32; 4]] = bytemuck::cast_slice(section(0));
    let traced_flags: &[u32] = bytemuck::cast_slice(section(1));
    for (index, (&flag, pixel)) in traced_flags.iter().zip(traced_pixels).enumerate() {
        if flag != PIXEL_UNTRACED {
            progressive.image.pixels[index] = *pixel;
            progressive.pending[index] = flag == PIXEL_MISSED;
        }
    }
    let feedback_section = section(2);
    let counters: FeedbackCounters = bytemuck::pod_read_unaligned(&feedback_section[..size_of::<FeedbackCounters>()]);
    let rays: RayCounters =
        bytemuck::pod_read_unaligned(&feedback_section[size_of::<FeedbackCounters>()..FEEDBACK_HEADER_BYTES as usize]);
    let kept = counters.request_count.min(request_capacity) as usize;
    let records: &[RequestRecord] =
        bytemuck::cast_slice(&feedback_section[FEEDBACK_HEADER_BYTES as usize..][..kept * size_of::<RequestRecord>()]);
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
    buffer.unmap();
    Ok((counters, rays))
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

    fn device_warning(&self) -> Option<String> {
        self.context.cpu_emulation_warning()
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

/// Usage flags of a pass: one per node tile, then one per brick slot.
fn usage_count(view: &TreeView<'_>) -> u64 {
    let header = view.header();
    (view.nodes.len() as u64 / header.nodes_per_tile.max(1) as u64) + header.brick_count as u64
}

fn entry(binding: u32, buffer: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry { binding, resource: buffer.as_entire_binding() }
}
