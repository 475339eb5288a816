//! Camera paths: a JSON list of cameras rendered as a sequence that reuses the cache, as a user flying through would.
//!
//! Format: `[{"eye": [x,y,z], "target": [x,y,z], "up": [x,y,z], "fov": 40}, ...]` or `{"cameras": [...]}`.

use std::path::Path;

use anyhow::{bail, Context, Result};
use serde::Deserialize;
use voxstream_render::Camera;

#[derive(Deserialize)]
#[serde(untagged)]
enum PathFile {
    List(Vec<Camera>),
    Object { cameras: Vec<Camera> },
}

/// Reads and validates a camera path.
pub fn read_camera_path(path: &Path) -> Result<Vec<Camera>> {
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read camera path {}", path.display()))?;
    parse_camera_path(&text).with_context(|| format!("invalid camera path {}", path.display()))
}

/// Parses a camera path.
pub fn parse_camera_path(text: &str) -> Result<Vec<Camera>> {
    let file: PathFile = serde_json::from_str(text)
        .map_err(|e| anyhow::anyhow!("expected a list of {{eye, target, up, fov}} cameras ({e})"))?;
    let cameras = match file {
        PathFile::List(c) | PathFile::Object { cameras: c } => c,
    };
    if cameras.is_empty() {
        bail!("the path holds no camera");
    }
    for (i, camera) in cameras.iter().enumerate() {
        camera.frame(2, 2).with_context(|| format!("camera {i}"))?;
    }
    Ok(cameras)
}

/// An orbit of `frames` cameras around `target` at `distance`, `elevation` above the horizontal plane.
pub fn orbit(frames: usize, target: [f64; 3], distance: f64, elevation: f64, fov: f64) -> Vec<Camera> {
    (0..frames)
        .map(|i| {
            let angle = i as f64 / frames as f64 * std::f64::consts::TAU * 0.25 + 0.6;
            let eye = [
                target[0] + distance * angle.sin() * elevation.cos(),
                target[1] + distance * elevation.sin(),
                target[2] + distance * angle.cos() * elevation.cos(),
            ];
            Camera { eye, target, up: [0.0, 1.0, 0.0], fov }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_both_forms_and_rejects_bad_cameras() {
        let one = r#"{"eye":[0,0,3],"target":[0,0,0],"up":[0,1,0],"fov":30}"#;
        assert_eq!(parse_camera_path(&format!("[{one},{one}]")).unwrap().len(), 2);
        assert_eq!(parse_camera_path(&format!("{{\"cameras\":[{one}]}}")).unwrap().len(), 1);
        assert!(parse_camera_path("[]").is_err());
        assert!(parse_camera_path(r#"[{"eye":[0,0,0],"target":[0,0,0],"up":[0,1,0]}]"#).is_err());
        assert!(parse_camera_path("{").is_err());
    }
}
