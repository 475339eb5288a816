//! Writing the rendered image: 8-bit RGB PNG (`round(clamp(c, 0, 1) * 255)`, linear, no gamma) and, optionally,
//! the raw float image (little-endian `f32`, row-major, 3 per pixel, top row first).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use anyhow::{Context, Result};

use crate::integrate::Image;

/// Linear float to 8-bit, no gamma.
pub fn to_u8(c: f32) -> u8 {
    (c.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// Creates (truncates) an output file; called before rendering so a bad path fails fast.
pub fn create(path: &Path) -> Result<File> {
    File::create(path).with_context(|| format!("cannot create {}", path.display()))
}

/// Writes `image` as 8-bit RGB PNG to `file`, which was created for `path`.
pub fn write_png(image: &Image, file: File, path: &Path) -> Result<()> {
    let fail = || format!("cannot write PNG {}", path.display());
    let width = u32::try_from(image.width).with_context(fail)?;
    let height = u32::try_from(image.height).with_context(fail)?;
    let mut encoder = png::Encoder::new(BufWriter::new(file), width, height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    let mut writer = encoder.write_header().with_context(fail)?;
    let bytes: Vec<u8> = image.rgb.iter().map(|&c| to_u8(c)).collect();
    writer.write_image_data(&bytes).with_context(fail)?;
    writer.finish().with_context(fail)
}

/// Writes the float RGB image to `file`, which was created for `path`.
pub fn write_f32(image: &Image, file: File, path: &Path) -> Result<()> {
    let fail = || format!("cannot write float image {}", path.display());
    let mut out = BufWriter::new(file);
    for c in &image.rgb {
        out.write_all(&c.to_le_bytes()).with_context(fail)?;
    }
    out.flush().with_context(fail)
}
