//! Camera paths: a JSON list of cameras rendered as a sequence that reuses the cache, as a user flying through would.
//!
//! Format: `[{"eye": [x,y,z], "target": [x,y,z], "up": [x,y,z], "fov": 40}, ...]` or `{"cameras": [...]}`.

use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use serde_json::Value;
use voxstream_render::Camera;

/// Reads and validates a camera path.
pub fn read_camera_path(path: &Path) -> Result<Vec<Camera>> {
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read camera path {}", path.display()))?;
    parse_camera_path(&text).with_context(|| format!("invalid camera path {}", path.display()))
}

/// Parses a camera path: each camera on its own, so that an error names the camera and the field.
pub fn parse_camera_path(text: &str) -> Result<Vec<Camera>> {
    const EXPECTED: &str = r#"expected a list of cameras [{"eye": [x,y,z], "target": [x,y,z], "up": [x,y,z], "fov": 40}, …] or {"cameras": [...]}"#;
    let file: Value = serde_json::from_str(text).map_err(|e| anyhow!("not valid JSON ({e}): {EXPECTED}"))?;
    let list = match file {
        Value::Array(list) => list,
        Value::Object(mut object) => match object.remove("cameras") {
            Some(Value::Array(list)) => list,
            _ => bail!("{EXPECTED}"),
        },
        _ => bail!("{EXPECTED}"),
    };
    let cameras = list
        .iter()
        .enumerate()
        .map(|(i, camera)| parse_camera(camera).with_context(|| format!("camera {i}")))
        .collect::<Result<Vec<Camera>>>()?;
    if cameras.is_empty() {
        bail!("the path holds no camera");
    }
    for (i, camera) in cameras.iter().enumerate() {
        camera.frame(2, 2).with_context(|| format!("camera {i}"))?;
    }
    Ok(cameras)
}

/// One camera object: `eye`, `target` and `up` required, `fov` optional, nothing else.
fn parse_camera(value: &Value) -> Result<Camera> {
    let Value::Object(fields) = value else {
        bail!("expected an object {{\"eye\": …, \"target\": …, \"up\": …}}")
    };
    if let Some(unknown) = fields.keys().find(|k| !["eye", "target", "up", "fov"].contains(&k.as_str())) {
        bail!("unknown field `{unknown}` (expected eye, target, up, fov)");
    }
    let vector = |name: &str| -> Result<[f64; 3]> {
        let value = fields.get(name).ok_or_else(|| anyhow!("missing field `{name}`"))?;
        let numbers: Option<Vec<f64>> = value.as_array().map(|a| a.iter().filter_map(Value::as_f64).collect());
        match numbers {
            Some(numbers) if numbers.len() == 3 && value.as_array().is_some_and(|a| a.len() == 3) => {
                Ok([numbers[0], numbers[1], numbers[2]])
            }
            _ => bail!("`{name}` must be three numbers [x, y, z], got {value}"),
        }
    };
    let fov = match fields.get("fov") {
        None => Camera::DEFAULT_FOV,
        Some(value) => value.as_f64().ok_or_else(|| anyhow!("`fov` must be a number of degrees, got {value}"))?,
    };
    Ok(Camera { eye: vector("eye")?, target: vector("target")?, up: vector("up")?, fov })
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
        let missing_up = r#"[{"eye":[0,0,3],"target":[0,0,0]}]"#;
        assert_eq!(format!("{:#}", parse_camera_path(missing_up).unwrap_err()), "camera 0: missing field `up`");
        let wrong_type = r#"{"cameras":[{"eye":[0,0,3],"target":[0,0,0],"up":[0,1,0]},{"eye":"x"}]}"#;
        let message = format!("{:#}", parse_camera_path(wrong_type).unwrap_err());
        assert_eq!(message, "camera 1: `eye` must be three numbers [x, y, z], got \"x\"");
        let extra = r#"[{"eye":[0,0,3],"target":[0,0,0],"up":[0,1,0],"fvo":3}]"#;
        assert_eq!(
            format!("{:#}", parse_camera_path(extra).unwrap_err()),
            "camera 0: unknown field `fvo` (expected eye, target, up, fov)"
        );
    }
}
