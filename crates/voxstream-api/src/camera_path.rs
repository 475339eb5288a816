//! Camera paths: a JSON list of cameras rendered as a sequence that reuses the cache, as a user flying through would.
//!
//! Format: `[{"eye": [x,y,z], "target": [x,y,z], "up": [x,y,z], "fov": 40}, ...]` or `{"cameras": [...]}`.

use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use serde_json::Value;
use voxstream_core::json_limits::read_json_file;
use voxstream_render::Camera;

/// Reads and validates a camera path.
pub fn read_camera_path(path: &Path) -> Result<Vec<Camera>> {
    let text = read_json_file(path, "camera path")?;
    parse_camera_path(&text).with_context(|| format!("invalid camera path {}", path.display()))
}

/// Reads one camera (`render --camera`, as `voxstream view` saves it): an object `{"eye": …, "target": …, "up": …,
/// "fov": …}`, or a path holding exactly one camera.
pub fn read_camera_file(path: &Path) -> Result<Camera> {
    let text = read_json_file(path, "camera")?;
    parse_camera_file(&text).with_context(|| format!("invalid camera {}", path.display()))
}

/// Parses one camera: an object, or a path of one camera.
pub fn parse_camera_file(text: &str) -> Result<Camera> {
    let value: Value = serde_json::from_str(text).map_err(|e| {
        anyhow!(r#"not valid JSON ({e}): expected {{"eye": [x,y,z], "target": [x,y,z], "up": [x,y,z], "fov": 40}}"#)
    })?;
    if let Value::Object(object) = &value {
        if !object.contains_key("cameras") {
            let camera = parse_camera(&value)?;
            camera.frame(2, 2)?;
            return Ok(camera);
        }
    }
    match parse_camera_path(text)?.as_slice() {
        [one] => Ok(*one),
        many => bail!("{} cameras given; --camera takes one (use --path for a sequence)", many.len()),
    }
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

/// A camera path generated around a view: what `--path rest:N`, `orbit:N`, `zoom:N` and `fly:N` name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PathKind {
    /// The view itself, N times: a camera at rest (from a cold cache, the data arriving is all that changes).
    Rest,
    /// A quarter turn around the target at the view's distance and elevation.
    Orbit,
    /// Straight towards the target, the distance shrinking geometrically to a thousandth: from the whole volume
    /// down to single voxels of a 512³ volume.
    Zoom,
    /// Through the volume: from the eye past the target to 80% of the way to the other side, looking ahead.
    Fly,
}

impl PathKind {
    /// The kinds, in the order the benchmarks report them.
    pub const ALL: [PathKind; 4] = [PathKind::Rest, PathKind::Orbit, PathKind::Zoom, PathKind::Fly];

    /// The name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            PathKind::Rest => "rest",
            PathKind::Orbit => "orbit",
            PathKind::Zoom => "zoom",
            PathKind::Fly => "fly",
        }
    }
}

/// Most cameras a generated path may have.
pub const MAX_GENERATED_FRAMES: usize = 100_000;

/// Parses `orbit:N`, `zoom:N` or `fly:N`; `None` if `text` is not of that form, an error if `N` is not a count.
pub fn parse_generated_path(text: &str) -> Option<Result<(PathKind, usize)>> {
    Some(parse_generated(text)?.map(|(kind, frames, _)| (kind, frames)))
}

/// Parses `KIND:N`, or `orbit:N:DEGREES` (an orbit of that many degrees; `orbit:N` is a quarter turn); `None` if
/// `text` is not of that form, an error if `N` is not a count or the degrees not a number.
pub fn parse_generated(text: &str) -> Option<Result<(PathKind, usize, Option<f64>)>> {
    let mut parts = text.split(':');
    let name = parts.next()?;
    let kind = PathKind::ALL.into_iter().find(|k| k.name() == name)?;
    let frames = parts.next()?;
    let degrees = parts.next();
    if parts.next().is_some() {
        return Some(Err(anyhow!("--path {text}: expected {}:N{}", kind.name(), orbit_suffix(kind))));
    }
    let frames = match frames.parse::<usize>() {
        Ok(n) if (2..=MAX_GENERATED_FRAMES).contains(&n) => n,
        _ => {
            return Some(Err(anyhow!(
                "--path {text}: the frame count must be a whole number from 2 to {MAX_GENERATED_FRAMES} (e.g. {}:60)",
                kind.name()
            )))
        }
    };
    let degrees = match degrees {
        None => None,
        Some(_) if kind != PathKind::Orbit => {
            return Some(Err(anyhow!(
                "--path {text}: only orbit takes degrees (orbit:N:360); {}:N takes none",
                kind.name()
            )))
        }
        Some(d) => match d.parse::<f64>() {
            Ok(v) if v.is_finite() && v != 0.0 && v.abs() <= 3600.0 => Some(v),
            _ => {
                return Some(Err(anyhow!(
                    "--path {text}: the orbit's degrees must be a non-zero number up to 3600, e.g. orbit:120:360"
                )))
            }
        },
    };
    Some(Ok((kind, frames, degrees)))
}

fn orbit_suffix(kind: PathKind) -> &'static str {
    if kind == PathKind::Orbit {
        " or orbit:N:DEGREES"
    } else {
        ""
    }
}

/// The cameras `--path` asks for around the view `view`: a generated path (`orbit:N`, … when no file of that name
/// exists), a camera path file, or `view` alone without `--path`.
pub fn path_cameras(path: Option<&Path>, view: &Camera) -> Result<Vec<Camera>> {
    Ok(match path {
        Some(path) => match path.to_str().filter(|_| !path.exists()).and_then(parse_generated) {
            Some(generated) => match generated? {
                (PathKind::Orbit, frames, Some(degrees)) => orbit_path(frames, degrees, view),
                (kind, frames, _) => generated_path(kind, frames, view),
            },
            None => read_camera_path(path)?,
        },
        None => vec![*view],
    })
}

/// `frames` cameras turning `degrees` about the view's up direction through its target. A whole number of turns
/// (360, 720, …) leaves out the last camera, which would repeat the first: the frames then loop as a movie.
pub fn orbit_path(frames: usize, degrees: f64, from: &Camera) -> Vec<Camera> {
    let target = glam::DVec3::from(from.target);
    let up = glam::DVec3::from(from.up).normalize_or(glam::DVec3::Y);
    let offset = glam::DVec3::from(from.eye) - target;
    let whole_turns = (degrees / 360.0).fract() == 0.0;
    let last = if whole_turns { frames } else { frames.max(2) - 1 } as f64;
    (0..frames)
        .map(|i| {
            let rotation = glam::DQuat::from_axis_angle(up, (i as f64 / last * degrees).to_radians());
            Camera { eye: (target + rotation * offset).to_array(), ..*from }
        })
        .collect()
}

/// `frames` cameras of `kind` around the view `from`.
pub fn generated_path(kind: PathKind, frames: usize, from: &Camera) -> Vec<Camera> {
    let eye = glam::DVec3::from(from.eye);
    let target = glam::DVec3::from(from.target);
    let up = glam::DVec3::from(from.up).normalize_or(glam::DVec3::Y);
    let offset = eye - target;
    let last = (frames.max(2) - 1) as f64;
    (0..frames)
        .map(|i| {
            let s = i as f64 / last;
            let (eye, target) = match kind {
                PathKind::Rest => (eye, target),
                PathKind::Orbit => {
                    let rotation = glam::DQuat::from_axis_angle(up, s * std::f64::consts::FRAC_PI_2);
                    (target + rotation * offset, target)
                }
                PathKind::Zoom => (target + offset * 1e-3f64.powf(s), target),
                PathKind::Fly => {
                    let eye = eye - offset * (1.8 * s);
                    (eye, eye - offset)
                }
            };
            Camera { eye: eye.to_array(), target: target.to_array(), up: from.up, fov: from.fov }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn generated_paths_start_at_the_view_and_go_where_they_say() {
        let view = Camera { eye: [0.5, 0.5, 3.0], target: [0.5, 0.5, 0.5], up: [0.0, 1.0, 0.0], fov: 30.0 };
        let distance = |c: &Camera| glam::DVec3::from(c.eye).distance(glam::DVec3::from(c.target));
        for kind in PathKind::ALL {
            let path = generated_path(kind, 11, &view);
            assert_eq!(path.len(), 11);
            assert!(glam::DVec3::from(path[0].eye).distance(glam::DVec3::from(view.eye)) < 1e-12, "{kind:?}");
            assert!(path.iter().all(|c| c.frame(8, 8).is_ok()), "{kind:?}: every camera is valid");
        }
        assert!(generated_path(PathKind::Rest, 11, &view).iter().all(|c| *c == view));
        let orbit = generated_path(PathKind::Orbit, 11, &view);
        assert!(orbit.iter().all(|c| (distance(c) - 2.5).abs() < 1e-9));
        // A quarter turn about +y: from +z to +x.
        assert!((orbit[10].eye[0] - 3.0).abs() < 1e-9 && (orbit[10].eye[2] - 0.5).abs() < 1e-9);
        let zoom = generated_path(PathKind::Zoom, 11, &view);
        assert!((distance(&zoom[10]) - 2.5e-3).abs() < 1e-12);
        let fly = generated_path(PathKind::Fly, 11, &view);
        // 80% of the way beyond the target, still looking along -z.
        assert!((fly[10].eye[2] - (0.5 - 2.0)).abs() < 1e-9);
        assert!(fly[10].target[2] < fly[10].eye[2]);
        assert!(matches!(parse_generated_path("zoom:40"), Some(Ok((PathKind::Zoom, 40)))));
        assert!(parse_generated_path("path.json").is_none());
        assert!(parse_generated_path("spin:3").is_none());
        let error = parse_generated_path("fly:x").unwrap().unwrap_err().to_string();
        assert!(error.contains("fly:60"), "{error}");
        assert!(parse_generated_path("orbit:1").unwrap().is_err());
    }

    #[test]
    fn a_full_orbit_loops_without_repeating_its_first_camera() {
        let view = Camera { eye: [0.5, 0.5, 3.0], target: [0.5, 0.5, 0.5], up: [0.0, 1.0, 0.0], fov: 30.0 };
        assert!(matches!(parse_generated("orbit:8:360"), Some(Ok((PathKind::Orbit, 8, Some(d)))) if d == 360.0));
        assert!(matches!(parse_generated("orbit:8"), Some(Ok((PathKind::Orbit, 8, None)))));
        for bad in ["zoom:8:90", "orbit:8:x", "orbit:8:0", "orbit:8:90:1"] {
            assert!(parse_generated(bad).unwrap().is_err(), "{bad}");
        }
        let path = path_cameras(Some(Path::new("orbit:8:360")), &view).unwrap();
        assert_eq!(path.len(), 8);
        // 45° a frame: the fifth camera is opposite the first, and none repeats it.
        assert!((path[4].eye[2] - (0.5 - 2.5)).abs() < 1e-9, "{:?}", path[4].eye);
        assert!(path[1..].iter().all(|c| glam::DVec3::from(c.eye).distance(glam::DVec3::from(view.eye)) > 1.0));
        // Not a whole turn: the last camera is at the end of the arc.
        let half = orbit_path(5, 180.0, &view);
        assert!((half[4].eye[2] - (0.5 - 2.5)).abs() < 1e-9, "{:?}", half[4].eye);
    }

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
