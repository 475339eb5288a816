//! What the viewer saves and loads: screenshots (PNG), the camera (the JSON `voxstream render --camera` reads) and
//! the transfer function (the JSON `voxstream render --tf` reads). Files are written to a temporary name beside the
//! target and renamed into place, so a failed save never leaves a half-written file over a good one; a FIFO or
//! `/dev/null` gets the bytes directly, and a folder is refused (`voxstream_engine::output_file`).

use std::path::Path;

use voxstream_core::json_limits::read_json_file;
use voxstream_render::{Camera, TransferFunction};

/// Writes `bytes` to `path` ([`voxstream_engine::OutputFile`]): through a temporary file beside a regular file,
/// straight into a FIFO or character device, never over a folder or a disk.
pub fn write_output(path: &Path, bytes: &[u8]) -> Result<(), String> {
    voxstream_engine::write_output(path, bytes).map_err(|e| e.to_string())
}

/// Saves an RGB image as PNG.
pub fn save_png(path: &Path, size: [u32; 2], rgb: &[u8]) -> Result<(), String> {
    let mut bytes = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut bytes, size[0], size[1]);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().map_err(|e| format!("cannot encode {}: {e}", path.display()))?;
        writer.write_image_data(rgb).map_err(|e| format!("cannot encode {}: {e}", path.display()))?;
    }
    write_output(path, &bytes)
}

/// The camera as `{"eye": …, "target": …, "up": …, "fov": …}`.
pub fn camera_json(camera: &Camera) -> String {
    let value = serde_json::json!({
        "eye": camera.eye, "target": camera.target, "up": camera.up, "fov": camera.fov,
    });
    format!("{value:#}\n")
}

/// The transfer function as `{"points": […], "unit_distance": …}` (no `unit_distance` when it is the default).
pub fn transfer_function_json(transfer_function: &TransferFunction) -> String {
    let mut value = serde_json::json!({ "points": transfer_function.points });
    if let Some(unit) = transfer_function.unit_distance {
        value["unit_distance"] = serde_json::json!(unit);
    }
    format!("{value:#}\n")
}

/// Reads a transfer-function file, with a message naming the file and the problem.
pub fn load_transfer_function(path: &Path, value_range: [f64; 2]) -> Result<TransferFunction, String> {
    let text = read_json_file(path, "transfer function").map_err(|e| e.to_string())?;
    TransferFunction::from_json_or_paraview(&text, value_range).map_err(|e| format!("{}: {e}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn saved_json_reads_back_as_the_same_function_and_camera() {
        let tf = TransferFunction::new(vec![[0.0, 0.1, 0.2, 0.3, 0.0], [2.5, 1.0, 0.5, 0.0, 0.7]], Some(0.01)).unwrap();
        assert_eq!(TransferFunction::from_json(&transfer_function_json(&tf)).unwrap(), tf);
        let default_unit = TransferFunction::new(tf.points.clone(), None).unwrap();
        assert_eq!(TransferFunction::from_json(&transfer_function_json(&default_unit)).unwrap(), default_unit);
        let camera = Camera { eye: [1.0, 2.0, 3.0], target: [0.5, 0.25, 0.125], up: [0.0, 0.0, 1.0], fov: 33.0 };
        let back: Camera = serde_json::from_str(&camera_json(&camera)).unwrap();
        assert_eq!(back, camera);
    }

    #[test]
    fn a_failed_save_leaves_no_partial_file_and_keeps_the_old_one() {
        let dir = std::env::temp_dir().join(format!("voxstream-viewer-files-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let target = dir.join("a.json");
        write_output(&target, b"old").unwrap();
        assert!(write_output(&dir.join("missing/b.json"), b"x").is_err());
        assert_eq!(std::fs::read(&target).unwrap(), b"old");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
