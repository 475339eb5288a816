//! Writing frames as PNG through [`crate::output_file`]: a uniquely named temporary file then renamed, so an
//! interrupted run never leaves a truncated image under the final name; a FIFO or `/dev/null` gets the bytes directly.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use voxstream_render::Image;

use crate::output_file::write_output;

/// Writes `image` as 8-bit RGB PNG at `path`.
pub fn write_png(image: &Image, path: &Path) -> Result<()> {
    write_rgb8_png(&image.to_rgb8(), image.width, image.height, path)
}

/// Writes `width × height` 8-bit RGB pixels (row-major, top row first) as a PNG at `path`.
pub fn write_rgb8_png(pixels: &[u8], width: u32, height: u32, path: &Path) -> Result<()> {
    write_output(path, |file| {
        let mut encoder = png::Encoder::new(file, width, height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().with_context(|| format!("cannot write {}", path.display()))?;
        writer.write_image_data(pixels).with_context(|| format!("cannot write {}", path.display()))?;
        writer.finish().with_context(|| format!("cannot write {}", path.display()))
    })
}

/// `frame.png` → `frame_0007.png` for the 8th frame of a sequence.
pub fn numbered_path(path: &Path, index: usize) -> PathBuf {
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "frame".into());
    let extension = path.extension().map(|e| e.to_string_lossy().into_owned()).unwrap_or_else(|| "png".into());
    path.with_file_name(format!("{stem}_{index:04}.{extension}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbering_keeps_folder_and_extension() {
        assert_eq!(numbered_path(Path::new("out/f.png"), 7), PathBuf::from("out/f_0007.png"));
    }
}
