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
use crate::ray_caster::{RayCaster, RayStats};
use crate::settings::RenderSettings;
use crate::transfer_function::TransferLut;

/// Edge of the square image tiles handed to worker threads.
pub const IMAGE_TILE: u32 = 16;

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

/// Renders one frame of `view` from `camera`, writing usage and requests into `feedback`.
pub fn render_frame(
    view: TreeView<'_>,
    feedback: &FeedbackBuffer,
    camera: &Camera,
    lut: &TransferLut,
    settings: &RenderSettings,
) -> Result<RenderedFrame, RenderError> {
    settings.validate()?;
    let (width, height) = (settings.width, settings.height);
    let frame = camera.frame(width, height)?;
    let caster = RayCaster::new(view, feedback, lut, settings);
    let tiles_x = width.div_ceil(IMAGE_TILE);
    let tiles_y = height.div_ceil(IMAGE_TILE);
    let results: Vec<(Vec<[f32; 4]>, RayStats, usize)> = (0..tiles_x * tiles_y)
        .into_par_iter()
        .map(|tile| render_tile(&caster, &frame, settings, tile % tiles_x, tile / tiles_x, feedback))
        .collect();
    let mut image = Image::new(width, height);
    let mut stats = RayStats::default();
    let mut raw_requests = 0;
    for (tile, (pixels, tile_stats, requests)) in results.into_iter().enumerate() {
        let (x0, y0) = ((tile as u32 % tiles_x) * IMAGE_TILE, (tile as u32 / tiles_x) * IMAGE_TILE);
        let tile_width = IMAGE_TILE.min(width - x0) as usize;
        for (row, chunk) in pixels.chunks(tile_width).enumerate() {
            let start = (y0 as usize + row) * width as usize + x0 as usize;
            image.pixels[start..start + tile_width].copy_from_slice(chunk);
        }
        stats.add(&tile_stats);
        raw_requests += requests;
    }
    Ok(RenderedFrame { image, stats, raw_requests })
}

fn render_tile(
    caster: &RayCaster<'_>,
    frame: &CameraFrame,
    settings: &RenderSettings,
    tile_x: u32,
    tile_y: u32,
    feedback: &FeedbackBuffer,
) -> (Vec<[f32; 4]>, RayStats, usize) {
    let (width, height) = (settings.width, settings.height);
    let x0 = tile_x * IMAGE_TILE;
    let y0 = tile_y * IMAGE_TILE;
    let x1 = (x0 + IMAGE_TILE).min(width);
    let y1 = (y0 + IMAGE_TILE).min(height);
    let placement = &settings.placement;
    let origin = (frame.eye - glam::DVec3::from(placement.origin)) / placement.size;
    let mut pixels = Vec::with_capacity(((x1 - x0) * (y1 - y0)) as usize);
    let mut stats = RayStats::default();
    let mut requests: Vec<Request> = Vec::new();
    let background = settings.background;
    for y in y0..y1 {
        for x in x0..x1 {
            let direction = frame.direction(x, y, width, height);
            let mut request = None;
            let (color, alpha) = caster.trace(origin, direction, frame.pixel_spread, &mut stats, &mut request);
            requests.extend(request);
            let t = 1.0 - alpha;
            pixels.push([
                color[0] + t * background[0],
                color[1] + t * background[1],
                color[2] + t * background[2],
                alpha,
            ]);
        }
    }
    feedback.push_requests(&requests);
    (pixels, stats, requests.len())
}
