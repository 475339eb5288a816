//! One frame: rays over image tiles in parallel (rayon), feedback gathered per tile.
//!
//! The renderer reads the tree through an immutable [`TreeView`] and writes only the [`FeedbackBuffer`]; it never
//! calls the cache manager or a producer (the one-way data flow of `docs/ARCHITECTURE.md`). Every pixel's result
//! depends only on its own ray, so the image is identical whatever the number of threads.

use rayon::prelude::*;
use voxstream_core::{FeedbackBuffer, Request, TreeView};

use crate::camera::{Camera, CameraFrame};
use crate::error::RenderError;
use crate::image::Image;
use crate::isosurface::SurfaceSettings;
use crate::projection::{Projection, ProjectionCaster};
use crate::ray_caster::RayCaster;
use crate::sampler::LANES;
use crate::settings::RenderSettings;
use crate::slice_in_volume::SliceInVolume;
use crate::surface_caster::SurfaceCaster;
use crate::transfer_function::TransferLut;
use crate::traversal::{DescentPath, RayStats};

/// What traces one pixel's ray: a volume ray ([`RayCaster`]) or an isosurface ray ([`SurfaceCaster`]), each the
/// one traversal paired with its integrand.
pub trait PixelTracer: Sync {
    /// The tree view it reads.
    fn view(&self) -> TreeView<'_>;

    /// Traces one ray given in volume space with `t` in world units (`origin` in volume units, `direction` = the
    /// unit world direction divided by the placement's scale); returns premultiplied `[r, g, b]` and opacity.
    /// Appends at most `max_requests_per_ray` requests per traversal to `requests`.
    fn trace(
        &self,
        origin: glam::DVec3,
        direction: glam::DVec3,
        spread: f64,
        stats: &mut RayStats,
        requests: &mut Vec<Request>,
        path: &mut DescentPath,
    ) -> ([f32; 3], f32);

    /// Traces the rays `(id, direction)` from `origin` and hands each one's `(id, colour, opacity, made requests)`
    /// to `emit`, in any order (a tracer may trace several side by side). One after another by default.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn trace_rays(
        &self,
        origin: glam::DVec3,
        rays: impl Iterator<Item = (usize, glam::DVec3)>,
        spread: f64,
        stats: &mut RayStats,
        requests: &mut Vec<Request>,
        paths: &mut [DescentPath; LANES],
        emit: impl FnMut(usize, [f32; 3], f32, bool),
    ) {
        trace_one_by_one(self, origin, rays, spread, stats, requests, &mut paths[0], emit);
    }
}

/// [`PixelTracer::trace_rays`] one ray after another, each with [`PixelTracer::trace`] (the default, and the
/// reference the tracers that trace rays side by side are tested against).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub fn trace_one_by_one<T: PixelTracer + ?Sized>(
    tracer: &T,
    origin: glam::DVec3,
    rays: impl Iterator<Item = (usize, glam::DVec3)>,
    spread: f64,
    stats: &mut RayStats,
    requests: &mut Vec<Request>,
    path: &mut DescentPath,
    mut emit: impl FnMut(usize, [f32; 3], f32, bool),
) {
    for (id, direction) in rays {
        let before = requests.len();
        let (color, alpha) = tracer.trace(origin, direction, spread, stats, requests, path);
        emit(id, color, alpha, requests.len() > before);
    }
}

/// Edge of the square image tiles handed to worker threads (in a sparse pass, this times its pixel stride).
pub const IMAGE_TILE: u32 = 16;

/// Bytes one pixel costs while a frame is rendered and written, counted in the memory budget: the progressive
/// image (16 bytes of RGBA f32 and 1 pending flag), the pass's per-tile results (an `Option<[f32; 4]>` of 20 bytes
/// and 1 flag), and, once rendering is done, the 8-bit copy and the PNG encoder's filtered rows (3 + 3 bytes),
/// rounded up.
pub const FRAME_BYTES_PER_PIXEL: u64 = 40;

/// Bytes a `width`×`height` frame costs ([`FRAME_BYTES_PER_PIXEL`] per pixel).
pub fn frame_buffer_bytes(width: u32, height: u32) -> u64 {
    width as u64 * height as u64 * FRAME_BYTES_PER_PIXEL
}

/// A rendered frame and its counters.
#[derive(Clone, Debug)]
pub struct RenderedFrame {
    /// The image.
    pub image: Image,
    /// Ray counters.
    pub stats: RayStats,
    /// Requests the rays made (before deduplication).
    pub raw_requests: usize,
}

/// An image being completed over several passes ([R08] §6, "interrupt and resume"): after each pass only the
/// rays that reported a miss are traced again; the others already used exactly the data they needed.
#[derive(Clone, Debug)]
pub struct ProgressiveImage {
    /// The image so far.
    pub image: Image,
    /// Per pixel: whether its ray must be traced again.
    pub pending: Vec<bool>,
}

impl ProgressiveImage {
    /// A new image where every ray is pending.
    pub fn new(width: u32, height: u32) -> ProgressiveImage {
        ProgressiveImage { image: Image::new(width, height), pending: vec![true; width as usize * height as usize] }
    }

    /// Pixels still pending.
    pub fn pending_count(&self) -> usize {
        self.pending.iter().filter(|&&p| p).count()
    }
}

/// Renders one frame of `view` from `camera`, writing usage and requests into `feedback`.
pub fn render_frame(
    view: TreeView<'_>,
    feedback: &FeedbackBuffer,
    camera: &Camera,
    lut: &TransferLut,
    settings: &RenderSettings,
) -> Result<RenderedFrame, RenderError> {
    let mut progressive = ProgressiveImage::new(settings.width, settings.height);
    let inputs = PassInputs { view, feedback, camera, lut, settings };
    let (stats, raw_requests) = render_pass(inputs, &mut progressive)?;
    Ok(RenderedFrame { image: progressive.image, stats, raw_requests })
}

/// What one pass reads: the tree, the camera, the transfer function and the settings, and the feedback buffer its
/// rays write their usage and requests into. The image the pass completes is handed beside it
/// ([`render_pass`], `FrameRenderer::render_pass` of `voxstream-engine`).
#[derive(Clone, Copy, Debug)]
pub struct PassInputs<'a> {
    /// The tree the rays read.
    pub view: TreeView<'a>,
    /// Where the rays record what they used and what they missed.
    pub feedback: &'a FeedbackBuffer,
    /// Where the rays start.
    pub camera: &'a Camera,
    /// The transfer function's table.
    pub lut: &'a TransferLut,
    /// Image size, sampling and shading.
    pub settings: &'a RenderSettings,
}

/// Traces the pending rays of `progressive`, updating their pixels and marking which still miss data.
/// Returns the ray counters and the number of raw requests.
pub fn render_pass(
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
    // A sparse pass traces one pixel in stride²: its tiles grow with the stride, so that each holds as many rays
    // as a dense tile (the lanes of a tile with few rays mostly wait for its last ones).
    let edge = IMAGE_TILE * settings.pixel_stride.clamp(1, 8);
    let tiles_x = width.div_ceil(edge);
    let tiles_y = height.div_ceil(edge);
    let pending = &progressive.pending;
    let grid = TileGrid { tiles_x, tiles_y, edge };
    let results = if let Some(slab) = settings.volume_slice.filter(|_| settings.surfaces.is_empty()) {
        let caster = SliceInVolume::new(view, feedback, lut, settings, slab, camera.eye);
        trace_tiles(&caster, grid, &frame, settings, feedback, pending)
    } else if settings.projection != Projection::Composite {
        let caster = ProjectionCaster::new(view, feedback, lut, settings);
        trace_tiles(&caster, grid, &frame, settings, feedback, pending)
    } else if settings.surfaces.is_empty() {
        let caster = RayCaster::new(view, feedback, lut, settings);
        trace_tiles(&caster, grid, &frame, settings, feedback, pending)
    } else {
        let surfaces = SurfaceSettings::new(settings, |value| lut.normalise(value));
        let caster = SurfaceCaster::new(view, feedback, &surfaces, lut, settings);
        trace_tiles(&caster, grid, &frame, settings, feedback, pending)
    };
    let mut stats = RayStats::default();
    let mut raw_requests = 0;
    for (tile, result) in results.into_iter().enumerate() {
        let (x0, y0) = ((tile as u32 % tiles_x) * edge, (tile as u32 / tiles_x) * edge);
        let tile_width = edge.min(width - x0) as usize;
        for (row, (chunk, flags)) in result.pixels.chunks(tile_width).zip(result.pending.chunks(tile_width)).enumerate()
        {
            let start = (y0 as usize + row) * width as usize + x0 as usize;
            for (offset, (pixel, still_pending)) in chunk.iter().zip(flags).enumerate() {
                if let Some(pixel) = pixel {
                    progressive.image.pixels[start + offset] = *pixel;
                    progressive.pending[start + offset] = *still_pending;
                }
            }
        }
        stats.add(&result.stats);
        raw_requests += result.raw_requests;
    }
    Ok((stats, raw_requests))
}

/// A pass's square tiles: `tiles_x` × `tiles_y` of `edge` pixels.
#[derive(Clone, Copy)]
struct TileGrid {
    tiles_x: u32,
    tiles_y: u32,
    edge: u32,
}

/// Traces every tile of a pass with `caster`, in parallel (rayon), each worker reusing its descent paths over its
/// share of the tiles; the results in tile order.
fn trace_tiles<T: PixelTracer>(
    caster: &T,
    TileGrid { tiles_x, tiles_y, edge }: TileGrid,
    frame: &CameraFrame,
    settings: &RenderSettings,
    feedback: &FeedbackBuffer,
    pending: &[bool],
) -> Vec<TileResult> {
    (0..tiles_x * tiles_y)
        .into_par_iter()
        .map_init(
            || descent_paths(caster, settings.shared_descents),
            |paths, tile| {
                let corner = ((tile % tiles_x) * edge, (tile / tiles_x) * edge);
                render_tile(caster, frame, settings, corner, edge, feedback, pending, paths)
            },
        )
        .collect()
}

struct TileResult {
    /// `None` where the pixel was not traced this pass.
    pixels: Vec<Option<[f32; 4]>>,
    pending: Vec<bool>,
    stats: RayStats,
    raw_requests: usize,
}

/// The lanes' descent paths, made once per worker's share of a pass's tiles rather than once per tile (each is a few
/// KiB). With [`RenderSettings::shared_descents`] each is kept from ray to ray within the pass
/// ([`DescentPath::for_rays_of_one_view`]): a ray's first descent starts from the nodes of the first descent of its
/// lane's last ray, mostly a neighbour's.
fn descent_paths<T: PixelTracer>(caster: &T, shared: bool) -> Box<[DescentPath; LANES]> {
    let path = |view| if shared { DescentPath::for_rays_of_one_view(view) } else { DescentPath::new(view) };
    Box::new(std::array::from_fn(|_| path(caster.view())))
}

#[allow(clippy::too_many_arguments)]
fn render_tile<T: PixelTracer>(
    caster: &T,
    frame: &CameraFrame,
    settings: &RenderSettings,
    (x0, y0): (u32, u32),
    edge: u32,
    feedback: &FeedbackBuffer,
    pending: &[bool],
    paths: &mut [DescentPath; LANES],
) -> TileResult {
    let (width, height) = (settings.width, settings.height);
    let x1 = (x0 + edge).min(width);
    let y1 = (y0 + edge).min(height);
    let placement = &settings.placement;
    let scale = glam::DVec3::from(placement.scale);
    let origin = (frame.eye - glam::DVec3::from(placement.origin)) / scale;
    let count = ((x1 - x0) * (y1 - y0)) as usize;
    let mut result = TileResult {
        pixels: Vec::with_capacity(count),
        pending: Vec::with_capacity(count),
        stats: RayStats::default(),
        raw_requests: 0,
    };
    let mut requests: Vec<Request> = Vec::new();
    // The loop and what it inlines (the whole traversal) are compiled for each instruction set; one is picked here.
    settings.instruction_set.arch().dispatch(TileLoop {
        caster,
        frame,
        pixels: (x0..x1, y0..y1),
        width,
        height,
        origin,
        scale,
        background: settings.background,
        pending,
        stride: settings.pixel_stride.max(1),
        result: &mut result,
        requests: &mut requests,
        paths,
    });
    // Neighbouring rays miss the same nodes: merge them here so the frame's request list stays small.
    result.raw_requests = requests.len();
    requests.sort_unstable();
    requests.dedup();
    // Tiles near the focus vote more than once (the order of loading only).
    for _ in 0..crate::settings::focus_weight(settings.focus, [x0, y0, x1, y1], width, height) {
        feedback.push_requests(&requests);
    }
    result
}

/// The rays of one tile, as a [`pulp::WithSimd`] operation: `with_simd` is monomorphised per instruction set and
/// always inlined into pulp's `#[target_feature]` entry point, and the traversal is always inlined into it, so each
/// version of the whole ray loop is compiled for its instruction set. (A closure would be compiled once, for the
/// baseline.)
struct TileLoop<'t, T> {
    caster: &'t T,
    frame: &'t CameraFrame,
    pixels: (std::ops::Range<u32>, std::ops::Range<u32>),
    width: u32,
    height: u32,
    origin: glam::DVec3,
    scale: glam::DVec3,
    background: [f32; 3],
    pending: &'t [bool],
    stride: u32,
    result: &'t mut TileResult,
    requests: &'t mut Vec<Request>,
    paths: &'t mut [DescentPath; LANES],
}

/// The rays of a tile's pixels traced this pass (pending, on the pass's stride), row by row, as `(index in the
/// tile, direction in volume space with t still in world units)`. An iterator of its own rather than adapters and
/// closures, so that its `next` is inlined into the tile loop (and compiled for its instruction set).
struct TileRays<'t> {
    frame: &'t CameraFrame,
    columns: std::ops::Range<u32>,
    rows: std::ops::Range<u32>,
    x: u32,
    y: u32,
    index: usize,
    width: u32,
    height: u32,
    scale: glam::DVec3,
    pending: &'t [bool],
    stride: u32,
}

impl Iterator for TileRays<'_> {
    type Item = (usize, glam::DVec3);

    #[inline(always)]
    fn next(&mut self) -> Option<(usize, glam::DVec3)> {
        while self.y < self.rows.end && !self.columns.is_empty() {
            let (x, y, index) = (self.x, self.y, self.index);
            self.index += 1;
            self.x += 1;
            if self.x == self.columns.end {
                self.x = self.columns.start;
                self.y += 1;
            }
            if self.pending[(y * self.width + x) as usize] && x % self.stride == 0 && y % self.stride == 0 {
                return Some((index, self.frame.direction(x, y, self.width, self.height) / self.scale));
            }
        }
        None
    }
}

impl<T: PixelTracer> pulp::WithSimd for TileLoop<'_, T> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        let TileLoop {
            caster,
            frame,
            pixels,
            width,
            height,
            origin,
            scale,
            background,
            pending,
            stride,
            result,
            requests,
            paths,
        } = self;
        let (columns, rows) = pixels;
        let tile_width = columns.len();
        let count = tile_width * rows.len();
        // Pixels not traced this pass keep their value and their pending flag.
        result.pixels.resize(count, None);
        result.pending.resize(count, false);
        let rays = TileRays {
            frame,
            x: columns.start,
            y: rows.start,
            columns,
            rows,
            index: 0,
            width,
            height,
            scale,
            pending,
            stride,
        };
        let (pixels, flags) = (&mut result.pixels, &mut result.pending);
        caster.trace_rays(
            origin,
            rays,
            frame.pixel_spread,
            &mut result.stats,
            requests,
            paths,
            |index, color, alpha, requested| {
                flags[index] = requested;
                let t = 1.0 - alpha;
                pixels[index] = Some([
                    color[0] + t * background[0],
                    color[1] + t * background[1],
                    color[2] + t * background[2],
                    alpha,
                ]);
            },
        );
    }
}
