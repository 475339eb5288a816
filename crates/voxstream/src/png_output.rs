//! Writing frames as PNG: to a temporary file first, then renamed, so an interrupted run never leaves a truncated
//! image under the final name.

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use voxstream_render::Image;

/// Writes `image` as 8-bit RGB PNG at `path`.
pub fn write_png(image: &Image, path: &Path) -> Result<()> {
    let temporary = temporary_path(path);
    let result = (|| -> Result<()> {
        let file = File::create(&temporary).with_context(|| format!("cannot create {}", temporary.display()))?;
        let mut encoder = png::Encoder::new(BufWriter::new(file), image.width, image.height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().with_context(|| format!("cannot write {}", path.display()))?;
        writer.write_image_data(&image.to_rgb8()).with_context(|| format!("cannot write {}", path.display()))?;
        writer.finish().with_context(|| format!("cannot write {}", path.display()))?;
        std::fs::rename(&temporary, path).with_context(|| format!("cannot move the image to {}", path.display()))
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&temporary);
    }
    result
}

fn temporary_path(path: &Path) -> PathBuf {
    let mut name = path.file_name().map(|n| n.to_os_string()).unwrap_or_default();
    name.push(".partial");
    path.with_file_name(name)
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
