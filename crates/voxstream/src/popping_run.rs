//! Recording an interactive sequence and measuring its popping and seams against the converged images at the same
//! cameras ([`voxstream_engine::popping`]), for `render --stats` and `bench --popping`.

use std::path::Path;

use anyhow::Result;
use voxstream_core::Producer;
use voxstream_engine::{FrameRenderer, Mode, PoppingSummary, Rgb8, Session};
use voxstream_render::{Camera, Image};

use crate::png_output::write_rgb8_png;

/// Most bytes of 8-bit frames kept for the measurement.
pub const MAX_RECORDED_BYTES: u64 = 1 << 30;

/// The frames of an interactive sequence as written (8-bit RGB), with their cameras.
pub struct FrameRecorder {
    width: u32,
    height: u32,
    frames: Vec<(Camera, Vec<u8>)>,
}

impl FrameRecorder {
    /// A recorder for up to `frames` frames of `width × height`, or the reason it would hold too much.
    pub fn new(width: u32, height: u32, frames: u64) -> std::result::Result<FrameRecorder, String> {
        let bytes = frames.saturating_mul(width as u64 * height as u64 * 3);
        if bytes > MAX_RECORDED_BYTES {
            return Err(format!(
                "popping is not measured: {frames} frames of {width}x{height} would keep {} MiB of images (at most {} \
                 MiB; use fewer frames or a smaller image)",
                bytes >> 20,
                MAX_RECORDED_BYTES >> 20
            ));
        }
        Ok(FrameRecorder { width, height, frames: Vec::new() })
    }

    /// Keeps `image`, drawn from `camera`.
    pub fn record(&mut self, camera: &Camera, image: &Image) {
        self.frames.push((*camera, image.to_rgb8()));
    }

    /// The recorded frames, in order.
    pub fn frames(&self) -> impl Iterator<Item = &[u8]> {
        self.frames.iter().map(|(_, bytes)| bytes.as_slice())
    }

    /// The converged image at every recorded camera, drawn by `session` (consecutive equal cameras once).
    pub fn exact_images<P: Producer, R: FrameRenderer>(&self, session: &mut Session<P, R>) -> Result<Vec<Vec<u8>>> {
        let mut exact: Vec<Vec<u8>> = Vec::with_capacity(self.frames.len());
        for (index, (camera, _)) in self.frames.iter().enumerate() {
            let repeat = index > 0 && self.frames[index - 1].0 == *camera;
            let image = match exact.last() {
                Some(previous) if repeat => previous.clone(),
                _ => session.render(camera, Mode::Converged)?.image.to_rgb8(),
            };
            exact.push(image);
        }
        Ok(exact)
    }

    /// The recorded sequence measured against `exact` (one image per recorded frame).
    pub fn summary(&self, exact: &[Vec<u8>]) -> PoppingSummary {
        let frames: Vec<Rgb8<'_>> = self.frames().map(|b| self.rgb8(b)).collect();
        let references: Vec<Rgb8<'_>> = exact.iter().map(|b| self.rgb8(b)).collect();
        PoppingSummary::measure(&frames, &references)
    }

    /// Renders the converged images with `session` and measures the recorded sequence against them.
    pub fn measure<P: Producer, R: FrameRenderer>(&self, session: &mut Session<P, R>) -> Result<PoppingSummary> {
        let exact = self.exact_images(session)?;
        Ok(self.summary(&exact))
    }

    fn rgb8<'a>(&self, bytes: &'a [u8]) -> Rgb8<'a> {
        Rgb8 { width: self.width, height: self.height, bytes }
    }
}

/// Writes rows of 8-bit RGB frames of `width × height` side by side as one PNG (each row left to right, rows top
/// to bottom; a missing frame stays black).
pub fn write_strip(rows: &[Vec<&[u8]>], width: u32, height: u32, path: &Path) -> Result<()> {
    let columns = rows.iter().map(Vec::len).max().unwrap_or(0);
    let (strip_width, strip_height) = (width as usize * columns, height as usize * rows.len());
    let mut pixels = vec![0u8; strip_width * strip_height * 3];
    for (r, row) in rows.iter().enumerate() {
        for (c, frame) in row.iter().enumerate() {
            for y in 0..height as usize {
                let source = &frame[y * width as usize * 3..(y + 1) * width as usize * 3];
                let start = ((r * height as usize + y) * strip_width + c * width as usize) * 3;
                pixels[start..start + source.len()].copy_from_slice(source);
            }
        }
    }
    write_rgb8_png(&pixels, strip_width as u32, strip_height as u32, path)
}
