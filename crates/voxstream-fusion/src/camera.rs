//! Pinhole intrinsics and camera poses, in the TUM RGB-D benchmark's conventions (seed 004 §8.2): the camera looks
//! along +z, x to the right, y down; a pose maps camera coordinates to world coordinates (metres).

use glam::{DAffine3, DVec2, DVec3};

/// A camera-to-world rigid transform.
pub type Pose = DAffine3;

/// Pinhole intrinsics of a depth (and registered colour) image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Intrinsics {
    pub width: u32,
    pub height: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
}

impl Intrinsics {
    /// The TUM RGB-D benchmark's default (ROS) intrinsics of a 640×480 Kinect image, which its documentation tells
    /// users to assume for the registered depth images.
    pub const TUM_DEFAULT: Intrinsics =
        Intrinsics { width: 640, height: 480, fx: 525.0, fy: 525.0, cx: 319.5, cy: 239.5 };

    /// The camera-space point at pixel centre `(u, v)` (pixel coordinates, `(0.5, 0.5)`… conventions of the
    /// benchmark: integer coordinates are pixel centres) at depth `z` along the optical axis.
    pub fn unproject(&self, u: f64, v: f64, z: f64) -> DVec3 {
        DVec3::new((u - self.cx) * z / self.fx, (v - self.cy) * z / self.fy, z)
    }

    /// The pixel coordinates of camera-space point `p` (integer = pixel centre), or `None` behind the camera.
    pub fn project(&self, p: DVec3) -> Option<DVec2> {
        if p.z <= 0.0 {
            return None;
        }
        Some(DVec2::new(self.fx * p.x / p.z + self.cx, self.fy * p.y / p.z + self.cy))
    }

    /// The pixel index of camera-space point `p`, rounded to the nearest pixel centre, or `None` outside the image.
    pub fn pixel_of(&self, p: DVec3) -> Option<(u32, u32)> {
        let uv = self.project(p)?;
        let (u, v) = (uv.x.round(), uv.y.round());
        if u < 0.0 || v < 0.0 || u >= self.width as f64 || v >= self.height as f64 {
            return None;
        }
        Some((u as u32, v as u32))
    }

    /// The pixels of the image.
    pub fn pixel_count(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// The side of one pixel's footprint at depth `z` (metres), the finest detail a sample can carry there.
    pub fn footprint(&self, z: f64) -> f64 {
        z / self.fx.max(self.fy)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn project_inverts_unproject() {
        let k = Intrinsics::TUM_DEFAULT;
        for (u, v, z) in [(0.0, 0.0, 0.5), (319.5, 239.5, 2.0), (639.0, 479.0, 4.25), (100.25, 37.5, 1.0)] {
            let p = k.unproject(u, v, z);
            assert!((p.z - z).abs() < 1e-12);
            let back = k.project(p).unwrap();
            assert!((back.x - u).abs() < 1e-9 && (back.y - v).abs() < 1e-9, "{u},{v} -> {back}");
        }
        assert_eq!(k.pixel_of(k.unproject(639.0, 479.0, 1.0)), Some((639, 479)));
        assert_eq!(k.pixel_of(k.unproject(640.0, 10.0, 1.0)), None);
        assert_eq!(k.project(DVec3::new(0.0, 0.0, -1.0)), None);
    }
}
