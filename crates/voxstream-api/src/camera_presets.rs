//! Camera presets and turns: `--view +x|-x|+y|-y|+z|-z|iso` frames the volume looking along an axis (ParaView's
//! "set view direction" buttons), and `--azimuth`, `--elevation` and `--zoom` turn and move a camera around what
//! it looks at (VTK's `vtkCamera::Azimuth`, `Elevation` and `Dolly`), keeping its up direction instead of rolling.
//!
//! World axes are the data's: a store's x, y, z are its sample axes scaled by the spacing (NIfTI's i, j, k; an
//! OME-Zarr's x, y, z), so `+z` looks along the slices' normal, down the stack. Where a store knows its anatomical
//! orientation ([`Orientation`]), `--view anterior|posterior|left|right|superior|inferior` look at that side of the
//! patient (3D Slicer's A, P, L, R, S, I views): head up, or the front up from above and below.

use anyhow::{anyhow, bail, Result};
use glam::{DQuat, DVec3};
use voxstream_render::Camera;
use voxstream_store::Orientation;

use crate::defaults::frame_box_with_fov;

/// A direction the camera looks along, as `--view` names it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ViewDirection {
    /// Looking along +x (from the −x side), +z up.
    PlusX,
    /// Looking along −x, +z up.
    MinusX,
    /// Looking along +y, +z up.
    PlusY,
    /// Looking along −y, +z up.
    MinusY,
    /// Looking along +z (from below), +y up.
    PlusZ,
    /// Looking along −z (from above), +y up.
    MinusZ,
    /// A three-quarter view from the +x, −y, +z corner, +z up.
    Iso,
    /// The patient's front, from in front of it, head up (needs the anatomical orientation).
    Anterior,
    /// The patient's back, head up.
    Posterior,
    /// The patient's left side, head up.
    Left,
    /// The patient's right side, head up.
    Right,
    /// From above the head, the front up.
    Superior,
    /// From below the feet, the front up.
    Inferior,
}

impl ViewDirection {
    /// Every preset, in the order `--help` lists them.
    pub const ALL: [ViewDirection; 13] = [
        ViewDirection::PlusX,
        ViewDirection::MinusX,
        ViewDirection::PlusY,
        ViewDirection::MinusY,
        ViewDirection::PlusZ,
        ViewDirection::MinusZ,
        ViewDirection::Iso,
        ViewDirection::Anterior,
        ViewDirection::Posterior,
        ViewDirection::Left,
        ViewDirection::Right,
        ViewDirection::Superior,
        ViewDirection::Inferior,
    ];

    /// The name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            ViewDirection::PlusX => "+x",
            ViewDirection::MinusX => "-x",
            ViewDirection::PlusY => "+y",
            ViewDirection::MinusY => "-y",
            ViewDirection::PlusZ => "+z",
            ViewDirection::MinusZ => "-z",
            ViewDirection::Iso => "iso",
            ViewDirection::Anterior => "anterior",
            ViewDirection::Posterior => "posterior",
            ViewDirection::Left => "left",
            ViewDirection::Right => "right",
            ViewDirection::Superior => "superior",
            ViewDirection::Inferior => "inferior",
        }
    }

    /// The preset named `text`, with a message listing them otherwise.
    pub fn parse(text: &str) -> Result<ViewDirection> {
        let wanted = text.trim().to_ascii_lowercase();
        ViewDirection::ALL.into_iter().find(|v| v.name() == wanted).ok_or_else(|| {
            let names: Vec<&str> = ViewDirection::ALL.iter().map(|v| v.name()).collect();
            anyhow!("--view {text}: expected one of {}", names.join(", "))
        })
    }

    /// The direction the camera looks along (unit) and the up direction it keeps, in the volume's axes; an
    /// anatomical preset needs the volume's `orientation` (`name` is the volume's, for the message).
    pub fn axes(self, orientation: Option<Orientation>, name: &str) -> Result<(DVec3, DVec3)> {
        // The anatomical presets: the side of the patient looked at, in RAS, and the up direction kept.
        let (superior, anterior) = ([0.0, 0.0, 1.0], [0.0, 1.0, 0.0]);
        let (side, up) = match self {
            ViewDirection::PlusX => return Ok((DVec3::X, DVec3::Z)),
            ViewDirection::MinusX => return Ok((-DVec3::X, DVec3::Z)),
            ViewDirection::PlusY => return Ok((DVec3::Y, DVec3::Z)),
            ViewDirection::MinusY => return Ok((-DVec3::Y, DVec3::Z)),
            ViewDirection::PlusZ => return Ok((DVec3::Z, DVec3::Y)),
            ViewDirection::MinusZ => return Ok((-DVec3::Z, DVec3::Y)),
            ViewDirection::Iso => return Ok((DVec3::new(-1.0, 1.0, -1.0).normalize(), DVec3::Z)),
            ViewDirection::Anterior => ([0.0, 1.0, 0.0], superior),
            ViewDirection::Posterior => ([0.0, -1.0, 0.0], superior),
            ViewDirection::Left => ([-1.0, 0.0, 0.0], superior),
            ViewDirection::Right => ([1.0, 0.0, 0.0], superior),
            ViewDirection::Superior => ([0.0, 0.0, 1.0], anterior),
            ViewDirection::Inferior => ([0.0, 0.0, -1.0], anterior),
        };
        let orientation = orientation.ok_or_else(|| {
            anyhow!(
                "--view {}: {name} does not say its anatomical orientation (which way is the patient's front); \
                 import it again with --orientation RAS (or LPS, …), or look along its axes with --view +x, -y, …",
                self.name()
            )
        })?;
        let side = DVec3::from(orientation.volume_direction(side));
        Ok((-side, DVec3::from(orientation.volume_direction(up))))
    }
}

/// A camera looking along `direction` at the box `lower..upper` (of a volume whose anatomical orientation is
/// `orientation`, where known), far enough that the whole box shows in a `width × height` image with a vertical
/// field of view of `fov` degrees.
pub fn preset_camera(
    direction: ViewDirection,
    orientation: Option<Orientation>,
    name: &str,
    bounds: [[f64; 3]; 2],
    (width, height): (u32, u32),
    fov: f64,
) -> Result<Camera> {
    let [lower, upper] = bounds;
    let (forward, up) = direction.axes(orientation, name)?;
    Ok(frame_box_with_fov(lower, upper, width, height, (-forward).to_array(), up.to_array(), fov))
}

/// How a camera is turned and moved around its target: degrees about its up direction (`azimuth`, positive moves
/// the eye to its right, counter-clockwise seen from above, as VTK's), degrees towards its up direction (`elevation`), and a factor by which the
/// distance shrinks (`zoom`: 2 is twice as close).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CameraTurn {
    /// Degrees about the up direction through the target.
    pub azimuth: Option<f64>,
    /// Degrees towards the up direction (90 looks straight down on the target).
    pub elevation: Option<f64>,
    /// The distance to the target divided by this.
    pub zoom: Option<f64>,
}

impl CameraTurn {
    /// Whether it changes nothing.
    pub fn is_none(&self) -> bool {
        self.azimuth.is_none() && self.elevation.is_none() && self.zoom.is_none()
    }

    /// `camera` turned and moved. The up direction stays the camera's (no roll); an elevation that would look
    /// straight along it ends there, the image's top then towards where the eye came from.
    pub fn apply(&self, camera: Camera) -> Result<Camera> {
        for (flag, value) in [("--azimuth", self.azimuth), ("--elevation", self.elevation), ("--zoom", self.zoom)] {
            if value.is_some_and(|v| !v.is_finite()) {
                bail!("{flag} must be a finite number");
            }
        }
        if let Some(zoom) = self.zoom {
            if !(zoom > 0.0) {
                bail!("--zoom {zoom} must be positive (2 is twice as close, 0.5 twice as far)");
            }
        }
        let target = DVec3::from(camera.target);
        let mut offset = DVec3::from(camera.eye) - target;
        let mut up = DVec3::from(camera.up).normalize_or(DVec3::Z);
        if let Some(degrees) = self.azimuth {
            offset = DQuat::from_axis_angle(up, degrees.to_radians()) * offset;
        }
        if let Some(degrees) = self.elevation {
            // The eye's angle above the plane through the target normal to `up`.
            let distance = offset.length();
            let height = offset.dot(up);
            let level = offset - up * height;
            let above = (height / distance).clamp(-1.0, 1.0).asin().to_degrees();
            let wanted = above + degrees;
            if wanted.abs() > 90.0 + 1e-9 {
                bail!(
                    "--elevation {degrees}: the eye is {above:.1}° above the target's level and would pass over the \
                     pole ({wanted:.1}°): keep the sum within ±90°, or add --azimuth 180 to look from the other side"
                );
            }
            // A valid camera never looks exactly along its up direction, so `level` is not zero.
            let horizontal = level.normalize_or(up.any_orthonormal_vector());
            let angle = wanted.to_radians();
            offset = (horizontal * angle.cos() + up * angle.sin()) * distance;
            if (90.0 - wanted.abs()).abs() < 1e-6 {
                // Looking straight along `up`: the image's top points away from where the eye came from.
                up = -horizontal * wanted.signum();
            }
        }
        if let Some(zoom) = self.zoom {
            offset /= zoom;
        }
        Ok(Camera { eye: (target + offset).to_array(), target: camera.target, up: up.to_array(), fov: camera.fov })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: [f64; 3], b: [f64; 3]) -> bool {
        (DVec3::from(a) - DVec3::from(b)).length() < 1e-9
    }

    #[test]
    fn presets_look_along_their_axis_and_frame_the_box() {
        let bounds = [[0.0, 0.0, 0.0], [2.0, 1.0, 4.0]];
        let lps = Orientation::parse("LPS").ok();
        for direction in ViewDirection::ALL {
            let camera = preset_camera(direction, lps, "v.zarr", bounds, (64, 48), 30.0).unwrap();
            let forward = (DVec3::from(camera.target) - DVec3::from(camera.eye)).normalize();
            let (expected, _) = direction.axes(lps, "v.zarr").unwrap();
            assert!((forward - expected).length() < 1e-9, "{direction:?}: looks along {forward}");
            assert!(close(camera.target, [1.0, 0.5, 2.0]), "{direction:?}: aims at the centre");
            // Every corner inside the image.
            let frame = camera.frame(64, 48).expect("valid camera");
            for corner in 0..8 {
                let p = DVec3::new(bounds[corner & 1][0], bounds[corner >> 1 & 1][1], bounds[corner >> 2 & 1][2]);
                let r = p - frame.eye;
                let depth = r.dot(frame.forward);
                let (x, y) = (r.dot(frame.right) / depth, r.dot(frame.up) / depth);
                let half = (camera.fov.to_radians() / 2.0).tan();
                assert!(y.abs() <= half && x.abs() <= half * 64.0 / 48.0, "{direction:?}: corner {corner} outside");
            }
        }
        assert_eq!(ViewDirection::parse("-Z").unwrap(), ViewDirection::MinusZ);
        assert_eq!(ViewDirection::parse("Anterior").unwrap(), ViewDirection::Anterior);
        let error = ViewDirection::parse("top").unwrap_err().to_string();
        assert!(error.contains("+x, -x, +y, -y, +z, -z, iso, anterior, posterior, left, right"), "{error}");
    }

    #[test]
    fn anatomical_presets_look_at_the_patients_side_whatever_the_axes() {
        let close_to = |a: DVec3, b: [f64; 3]| (a - DVec3::from(b)).length() < 1e-12;
        // RAS (MNI): the front is +y; LPS (DICOM): the front is −y; PIR (Allen atlas): the front is −x, up is −y.
        for (code, front, up) in [
            ("RAS", [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]),
            ("LPS", [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]),
            ("PIR", [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]),
        ] {
            let orientation = Orientation::parse(code).ok();
            let (forward, kept_up) = ViewDirection::Anterior.axes(orientation, "v").unwrap();
            assert!(close_to(-forward, front), "{code}: the eye is in front: {forward}");
            assert!(close_to(kept_up, up), "{code}: head up: {kept_up}");
            let (forward, kept_up) = ViewDirection::Superior.axes(orientation, "v").unwrap();
            assert!(close_to(-forward, up), "{code}: from above: {forward}");
            assert!(close_to(kept_up, front), "{code}: the front up: {kept_up}");
        }
        // The patient's left is −x in RAS: the eye there looks along +x.
        let (forward, _) = ViewDirection::Left.axes(Some(Orientation::RAS), "v").unwrap();
        assert!(close_to(forward, [1.0, 0.0, 0.0]), "{forward}");
        // The data-axes presets need no orientation; the anatomical ones say how to give it.
        assert!(ViewDirection::PlusX.axes(None, "v").is_ok());
        let error = ViewDirection::Anterior.axes(None, "scan.zarr").unwrap_err().to_string();
        assert!(error.contains("scan.zarr does not say its anatomical orientation") && error.contains("--orientation"));
    }

    #[test]
    fn turns_keep_the_distance_and_the_up_direction_and_zoom_moves_in() {
        let camera = Camera { eye: [0.0, -4.0, 0.0], target: [0.0; 3], up: [0.0, 0.0, 1.0], fov: 30.0 };
        let turned = CameraTurn { azimuth: Some(90.0), ..Default::default() }.apply(camera).unwrap();
        assert!(close(turned.eye, [4.0, 0.0, 0.0]), "{:?}", turned.eye);
        assert!(close(turned.up, [0.0, 0.0, 1.0]));
        let raised = CameraTurn { elevation: Some(30.0), ..Default::default() }.apply(camera).unwrap();
        assert!(close(raised.eye, [0.0, -4.0 * 30f64.to_radians().cos(), 2.0]), "{:?}", raised.eye);
        assert!(close(raised.up, [0.0, 0.0, 1.0]), "no roll: {:?}", raised.up);
        // Straight down: the image's top is +y, where the eye looked.
        let top = CameraTurn { elevation: Some(90.0), ..Default::default() }.apply(camera).unwrap();
        assert!(close(top.eye, [0.0, 0.0, 4.0]), "{:?}", top.eye);
        assert!(close(top.up, [0.0, 1.0, 0.0]), "{:?}", top.up);
        assert!(top.frame(8, 8).is_ok());
        let zoomed = CameraTurn { zoom: Some(2.0), azimuth: Some(-90.0), ..Default::default() }.apply(camera).unwrap();
        assert!(close(zoomed.eye, [-2.0, 0.0, 0.0]), "{:?}", zoomed.eye);
        let error = CameraTurn { elevation: Some(120.0), ..Default::default() }.apply(camera).unwrap_err();
        assert!(error.to_string().contains("pass over the pole"), "{error}");
        assert!(CameraTurn { zoom: Some(0.0), ..Default::default() }.apply(camera).is_err());
        assert!(CameraTurn::default().is_none());
    }
}
