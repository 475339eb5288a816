//! One RGB-D frame: depth in metres along the optical axis (0 where the sensor saw nothing) and a colour image
//! registered to it, with the time it was taken and, where known, its pose (seed 004 §8.3.2: every cached frame
//! keeps its pose estimate).

use crate::camera::{Intrinsics, Pose};

/// A depth image with its registered colour image.
#[derive(Clone, Debug, PartialEq)]
pub struct RgbdFrame {
    /// Seconds (the benchmark's timestamps).
    pub timestamp: f64,
    pub intrinsics: Intrinsics,
    /// `depth[v * width + u]`, metres; 0 = no measurement.
    pub depth: Vec<f32>,
    /// `colour[v * width + u]`, sRGB.
    pub colour: Vec<[u8; 3]>,
    /// Camera to world, where known (ground truth or tracked).
    pub pose: Option<Pose>,
}

impl RgbdFrame {
    /// The depth at pixel `(u, v)`, `None` where the sensor saw nothing.
    pub fn depth_at(&self, u: u32, v: u32) -> Option<f32> {
        let z = self.depth[(v * self.intrinsics.width + u) as usize];
        (z > 0.0 && z.is_finite()).then_some(z)
    }
}
