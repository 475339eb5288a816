//! A pinhole camera in world space: eye, target, up and vertical field of view (right-handed, like `vtkCamera`).
//!
//! Each pixel's ray stands for the cone through the pixel (GigaVoxels [P09] §6, "Cone tracing"): its footprint at
//! distance `t` is `t · 2·tan(fov/2) / height`, which picks the tree level to sample.

use glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::error::RenderError;

/// A perspective camera.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    /// Position of the eye, world units.
    pub eye: [f64; 3],
    /// Point looked at, world units.
    pub target: [f64; 3],
    /// Up direction (need not be orthogonal to the view direction).
    pub up: [f64; 3],
    /// Vertical field of view, degrees.
    #[serde(default = "default_fov")]
    pub fov: f64,
}

fn default_fov() -> f64 {
    Camera::DEFAULT_FOV
}

/// The camera's orthonormal frame, ready to generate rays.
#[derive(Clone, Copy, Debug)]
pub struct CameraFrame {
    /// Eye position, world.
    pub eye: DVec3,
    /// Unit view direction.
    pub forward: DVec3,
    /// Unit right vector, scaled by the half-width of the image plane at distance 1.
    pub right: DVec3,
    /// Unit up vector, scaled by the half-height of the image plane at distance 1.
    pub up: DVec3,
    /// Angle subtended by one pixel (radians, small-angle): the cone's spread per unit distance.
    pub pixel_spread: f64,
}

impl Camera {
    /// Vertical field of view, degrees, when none is given.
    pub const DEFAULT_FOV: f64 = 40.0;
    /// Largest magnitude of an eye, target or up coordinate: squares of differences stay finite in `f64`.
    pub const MAX_COORDINATE: f64 = 1e150;
    /// Smallest distance from the eye to the target, as a fraction of the positions' largest coordinate: the view
    /// direction is then known to about 1e-7 radians.
    pub const MIN_RELATIVE_DISTANCE: f64 = 1e-9;
    /// Checks the camera and builds its frame for a `width × height` image.
    pub fn frame(&self, width: u32, height: u32) -> Result<CameraFrame, RenderError> {
        let eye = DVec3::from(self.eye);
        let target = DVec3::from(self.target);
        let up = DVec3::from(self.up);
        if !(eye.is_finite() && target.is_finite() && up.is_finite() && self.fov.is_finite()) {
            return Err(RenderError::DegenerateCamera("eye, target, up and fov must be finite numbers".into()));
        }
        if !(self.fov > 0.0 && self.fov < 180.0) {
            return Err(RenderError::DegenerateCamera(format!("fov must be in (0, 180) degrees, got {}", self.fov)));
        }
        // Each check names the cause: lengths are squared, so vectors past the bound overflow and would otherwise
        // show up as a zero view direction ("up is parallel") instead.
        for (name, vector) in [("eye", self.eye), ("target", self.target), ("up", self.up)] {
            if vector.iter().any(|v| v.abs() > Self::MAX_COORDINATE) {
                return Err(RenderError::DegenerateCamera(format!(
                    "{name} {vector:?} lies beyond ±{:e}, where distances overflow",
                    Self::MAX_COORDINATE
                )));
            }
        }
        let view = target - eye;
        let distance = view.length();
        // The view direction is known to `MIN_RELATIVE_DISTANCE` only if the eye is that far from the target,
        // relative to the positions' magnitude (f64 rounds them to about 1e-16 of it).
        let magnitude = eye.abs().max_element().max(target.abs().max_element());
        if distance <= 1e-300 {
            return Err(RenderError::DegenerateCamera("eye and target are the same point".into()));
        }
        if distance < Self::MIN_RELATIVE_DISTANCE * magnitude {
            return Err(RenderError::DegenerateCamera(format!(
                "the eye is only {distance:e} from the target, too close for positions of magnitude {magnitude:e} to \
                 give the view direction (move the eye at least {:e} away)",
                Self::MIN_RELATIVE_DISTANCE * magnitude
            )));
        }
        if up.length() == 0.0 {
            return Err(RenderError::DegenerateCamera("up is zero".into()));
        }
        let forward = view.normalize();
        let side = forward.cross(up);
        if side.length() <= 1e-9 * up.length() {
            return Err(RenderError::DegenerateCamera(format!(
                "up {:?} is parallel to the view direction (eye to target {:?}); give an up across it",
                self.up,
                view.to_array()
            )));
        }
        if width == 0 || height == 0 {
            return Err(RenderError::InvalidSetting(format!("image size must be positive, got {width}x{height}")));
        }
        let half_height = (self.fov.to_radians() * 0.5).tan();
        let half_width = half_height * width as f64 / height as f64;
        let right = side.normalize();
        let true_up = right.cross(forward);
        Ok(CameraFrame {
            eye,
            forward,
            right: right * half_width,
            up: true_up * half_height,
            pixel_spread: 2.0 * half_height / height as f64,
        })
    }
}

impl CameraFrame {
    /// Unit direction of the ray through the centre of pixel `(x, y)` (y down).
    #[inline(always)]
    pub fn direction(&self, x: u32, y: u32, width: u32, height: u32) -> DVec3 {
        let sx = 2.0 * (x as f64 + 0.5) / width as f64 - 1.0;
        let sy = 1.0 - 2.0 * (y as f64 + 0.5) / height as f64;
        (self.forward + self.right * sx + self.up * sy).normalize()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera() -> Camera {
        Camera { eye: [0.0, 0.0, 5.0], target: [0.0; 3], up: [0.0, 1.0, 0.0], fov: 90.0 }
    }

    #[test]
    fn centre_ray_looks_at_the_target_and_corners_spread() {
        let frame = camera().frame(2, 2).unwrap();
        let d = frame.direction(1, 0, 2, 2);
        // Pixel (1, 0) is right and up of centre.
        assert!(d.x > 0.0 && d.y > 0.0 && d.z < 0.0);
        let frame = camera().frame(1, 1).unwrap();
        assert!((frame.direction(0, 0, 1, 1) - DVec3::new(0.0, 0.0, -1.0)).length() < 1e-12);
        assert!((frame.pixel_spread - 2.0).abs() < 1e-12);
    }

    #[test]
    fn degenerate_cameras_are_rejected() {
        let mut c = camera();
        c.target = c.eye;
        assert!(c.frame(8, 8).is_err());
        let mut c = camera();
        c.up = [0.0, 0.0, 1.0];
        assert!(c.frame(8, 8).is_err());
        let mut c = camera();
        c.fov = 0.0;
        assert!(c.frame(8, 8).is_err());
        let mut c = camera();
        c.eye[0] = f64::NAN;
        assert!(c.frame(8, 8).is_err());
        assert!(camera().frame(0, 8).is_err());
    }

    /// Issue 41 item 10: a far eye (whose squared distance overflows) or an eye a hair from the target used to be
    /// reported as "up is zero or parallel to the view direction".
    #[test]
    fn each_degenerate_camera_names_its_cause() {
        let message = |edit: &dyn Fn(&mut Camera)| {
            let mut c = camera();
            edit(&mut c);
            c.frame(8, 8).unwrap_err().to_string()
        };
        let far = message(&|c| c.eye = [1e308, 0.0, 0.0]);
        assert!(far.contains("eye [1e308, 0.0, 0.0] lies beyond"), "{far}");
        let far_target = message(&|c| c.target = [0.0, -1e200, 0.0]);
        assert!(far_target.contains("target") && far_target.contains("beyond"), "{far_target}");
        let close = message(&|c| {
            c.target = [0.5, 0.5, 0.5];
            c.eye = [0.5, 0.5, 0.5 + 1e-10];
        });
        assert!(close.contains("too close") && close.contains("from the target"), "{close}");
        let parallel = message(&|c| c.up = [0.0, 0.0, 2.0]);
        assert!(parallel.contains("parallel") && parallel.contains("[0.0, 0.0, 2.0]"), "{parallel}");
        assert!(message(&|c| c.up = [0.0; 3]).ends_with("up is zero"));
        // Far but representable, and close but resolvable, are fine.
        let mut c = camera();
        c.eye = [1e100, 0.0, 0.0];
        assert!(c.frame(8, 8).is_ok());
        c.eye = [0.0, 0.0, 1e-6];
        assert!(c.frame(8, 8).is_ok());
    }
}
