//! Pinhole camera with VTK's conventions: vertical field of view, `right = forward x up`, `true_up = right x
//! forward`, pixel rows counted downwards from the top of the image.

use anyhow::{bail, Result};

use crate::math::{add, cross, normalize, scale, sub, V3};
use crate::scene::CameraSpec;

#[derive(Debug, Clone)]
pub struct Camera {
    pub eye: V3,
    pub forward: V3,
    right: V3,
    up: V3,
    /// `tan(fov / 2)`.
    h: f64,
    width: f64,
    height: f64,
}

impl Camera {
    pub fn new(spec: &CameraSpec, width: usize, height: usize) -> Result<Camera> {
        let all = [spec.eye, spec.target, spec.up];
        if !all.iter().flatten().all(|v| v.is_finite()) {
            bail!("camera eye, target and up must be finite");
        }
        if !(spec.fov.is_finite() && spec.fov > 0.0 && spec.fov < 180.0) {
            bail!("camera fov must be in (0, 180) degrees (got {})", spec.fov);
        }
        let Some(forward) = normalize(sub(spec.target, spec.eye)) else {
            bail!("camera eye and target must differ");
        };
        let Some(right) = normalize(cross(forward, spec.up)) else {
            bail!("camera up must not be zero or parallel to the view direction");
        };
        let up = cross(right, forward);
        Ok(Camera {
            eye: spec.eye,
            forward,
            right,
            up,
            h: (spec.fov.to_radians() / 2.0).tan(),
            width: width as f64,
            height: height as f64,
        })
    }

    /// Unit ray direction through the sub-pixel position `(px, py)` in `[0, width) x [0, height)`, `y` down.
    #[inline]
    pub fn direction(&self, px: f64, py: f64) -> V3 {
        let sx = 2.0 * px / self.width - 1.0;
        let sy = 1.0 - 2.0 * py / self.height;
        let aspect = self.width / self.height;
        let d = add(add(self.forward, scale(self.right, sx * self.h * aspect)), scale(self.up, sy * self.h));
        // |d| >= |forward| = 1, so normalisation cannot fail.
        normalize(d).unwrap_or(self.forward)
    }
}
