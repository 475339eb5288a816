//! A Kinect v1 depth noise model for synthetic sequences (seed 004 §8.2, which cites Nguyen, Izadi and Lovell,
//! "Modeling Kinect sensor noise for improved 3D reconstruction and tracking", 3DIMPVT 2012, as [NIL12]).
//!
//! Given the exact depth of every pixel (and, where known, the angle θ between the pixel's ray and the surface
//! normal), [`NoiseModel::apply`] makes what a Kinect would have measured:
//!
//! 1. **Lateral noise**: the depth is taken from a pixel displaced by a normal jitter of
//!    σ_L = 0.8 + 0.035·θ/(π/2 − θ) pixels ([NIL12] eq. 2 in pixels), rounded to the nearest pixel.
//! 2. **Holes**: no depth outside `[min_depth, max_depth]`, at grazing angles (θ above `grazing_degrees`), and, with
//!    probability `edge_dropout`, next to a depth discontinuity (a 4-neighbour whose true depth differs by more than
//!    `edge_jump`, or which saw nothing), where the structured-light pattern is shadowed.
//! 3. **Axial noise**: a normal error of σ_z(z, θ) = 0.0012 + 0.0019·(z − 0.4)² + 0.0001/√z · θ²/(π/2 − θ)² metres
//!    ([NIL12] eq. 1).
//! 4. **Quantisation**: the Kinect measures disparity in integer steps, d = 1/(q·z), so depths fall on a grid whose
//!    step is ≈ q·z² (q = 2.85·10⁻³ /m: 2.9 mm at 1 m, 7 cm at 5 m; Khoshelham and Elberink 2012).
//!
//! [NIL12] measured σ_z on real (already quantised) depth, so adding quantisation overstates the spread slightly;
//! [`NoiseModel::total_sigma`] is the spread this model produces, √(σ_z² + step²/12) (Sheppard's correction).
//! Every random number comes from a hash of the seed and the pixel, so a frame is the same whatever the thread count.

use rayon::prelude::*;

use super::SplitMix;
use crate::camera::Intrinsics;
use crate::FusionError;

use std::f64::consts::FRAC_PI_2;

/// The parameters of the noise; [`NoiseModel::KINECT_V1`] and [`NoiseModel::NONE`] are the two presets.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoiseModel {
    /// σ_z's constant term, metres (0.0012).
    pub axial_base: f64,
    /// σ_z's quadratic term, metres per square metre (0.0019).
    pub axial_quadratic: f64,
    /// The depth at which σ_z is least, metres (0.4).
    pub axial_offset: f64,
    /// σ_z's angular term, metres·√metre (0.0001).
    pub axial_angle: f64,
    /// σ_L at normal incidence, pixels (0.8).
    pub lateral_pixels: f64,
    /// σ_L's angular term, pixels (0.035).
    pub lateral_angle: f64,
    /// The disparity quantisation q: depth steps are ≈ q·z² (2.85·10⁻³ per metre); 0 = none.
    pub quantisation: f64,
    /// Nearest depth measured, metres (0.4).
    pub min_depth: f64,
    /// Farthest depth measured, metres (5).
    pub max_depth: f64,
    /// Angles between ray and normal above this give no depth, degrees (75; 90 = never).
    pub grazing_degrees: f64,
    /// A neighbour's true depth differing by more than this makes a discontinuity, metres (0.04).
    pub edge_jump: f64,
    /// The probability that a sample next to a discontinuity is dropped (0.5).
    pub edge_dropout: f64,
}

impl NoiseModel {
    /// The Kinect v1 of [NIL12], with the sensor's range and disparity quantisation.
    pub const KINECT_V1: NoiseModel = NoiseModel {
        axial_base: 0.0012,
        axial_quadratic: 0.0019,
        axial_offset: 0.4,
        axial_angle: 0.0001,
        lateral_pixels: 0.8,
        lateral_angle: 0.035,
        quantisation: 2.85e-3,
        min_depth: 0.4,
        max_depth: 5.0,
        grazing_degrees: 75.0,
        edge_jump: 0.04,
        edge_dropout: 0.5,
    };

    /// Exact depth: no noise, no holes, no range limit.
    pub const NONE: NoiseModel = NoiseModel {
        axial_base: 0.0,
        axial_quadratic: 0.0,
        axial_offset: 0.0,
        axial_angle: 0.0,
        lateral_pixels: 0.0,
        lateral_angle: 0.0,
        quantisation: 0.0,
        min_depth: 0.0,
        max_depth: f64::INFINITY,
        grazing_degrees: 90.0,
        edge_jump: f64::INFINITY,
        edge_dropout: 0.0,
    };

    /// Checks that every parameter is in range; the error names the field.
    pub fn validate(&self) -> Result<(), FusionError> {
        let finite_non_negative = [
            ("axial_base", self.axial_base),
            ("axial_quadratic", self.axial_quadratic),
            ("axial_offset", self.axial_offset),
            ("axial_angle", self.axial_angle),
            ("lateral_pixels", self.lateral_pixels),
            ("lateral_angle", self.lateral_angle),
            ("quantisation", self.quantisation),
            ("min_depth", self.min_depth),
        ];
        for (name, value) in finite_non_negative {
            if !(value.is_finite() && value >= 0.0) {
                return Err(FusionError::Settings(format!(
                    "noise {name} = {value} is out of range: give a finite value ≥ 0"
                )));
            }
        }
        if self.max_depth.is_nan() || self.max_depth <= self.min_depth {
            return Err(FusionError::Settings(format!(
                "noise max_depth = {} must exceed min_depth = {}",
                self.max_depth, self.min_depth
            )));
        }
        if !(self.grazing_degrees > 0.0 && self.grazing_degrees <= 90.0) {
            return Err(FusionError::Settings(format!(
                "noise grazing_degrees = {} is out of range: give (0, 90] degrees",
                self.grazing_degrees
            )));
        }
        if self.edge_jump.is_nan() || self.edge_jump <= 0.0 {
            return Err(FusionError::Settings(format!(
                "noise edge_jump = {} is out of range: give a depth step > 0 metres (∞ for none)",
                self.edge_jump
            )));
        }
        if !(0.0..=1.0).contains(&self.edge_dropout) {
            return Err(FusionError::Settings(format!(
                "noise edge_dropout = {} is out of range: give a probability in [0, 1]",
                self.edge_dropout
            )));
        }
        Ok(())
    }

    /// The axial standard deviation σ_z at depth `z` (metres) and incidence angle `theta` (radians) ([NIL12] eq. 1).
    pub fn axial_sigma(&self, z: f64, theta: f64) -> f64 {
        let d = z - self.axial_offset;
        let mut sigma = self.axial_base + self.axial_quadratic * d * d;
        if self.axial_angle > 0.0 && theta > 0.0 {
            let rest = (FRAC_PI_2 - theta).max(1e-3);
            sigma += self.axial_angle / z.max(1e-6).sqrt() * theta * theta / (rest * rest);
        }
        sigma
    }

    /// The lateral standard deviation σ_L at incidence angle `theta`, pixels ([NIL12] eq. 2).
    pub fn lateral_sigma(&self, theta: f64) -> f64 {
        let rest = (FRAC_PI_2 - theta).max(1e-3);
        self.lateral_pixels + self.lateral_angle * theta.max(0.0) / rest
    }

    /// The step between quantised depths near `z`, metres (0 without quantisation).
    pub fn quantisation_step(&self, z: f64) -> f64 {
        self.quantisation * z * z
    }

    /// The standard deviation of a measured depth at `z` and `theta` this model produces: σ_z with the
    /// quantisation's variance step²/12 added.
    pub fn total_sigma(&self, z: f64, theta: f64) -> f64 {
        let sigma = self.axial_sigma(z, theta);
        let step = self.quantisation_step(z);
        (sigma * sigma + step * step / 12.0).sqrt()
    }

    /// `z` rounded to the nearest depth of integer disparity 1/(q·z).
    pub fn quantise(&self, z: f64) -> f64 {
        if self.quantisation <= 0.0 || z <= 0.0 {
            return z;
        }
        let disparity = (1.0 / (self.quantisation * z)).round();
        if disparity < 1.0 {
            // Beyond the last disparity step: the sensor reports nothing.
            return 0.0;
        }
        1.0 / (self.quantisation * disparity)
    }

    /// The measured depth image of the exact depth image `depth` (metres, 0 = nothing there), `incidence` the angle
    /// (radians) between each pixel's ray and the surface normal there, or `None` to estimate it from the depth.
    /// Deterministic given `seed`; with [`NoiseModel::NONE`] the depth comes back unchanged.
    ///
    /// # Panics
    /// If `depth` (or `incidence`) does not hold one value per pixel of `intrinsics`.
    pub fn apply(&self, intrinsics: &Intrinsics, depth: &[f32], incidence: Option<&[f32]>, seed: u64) -> Vec<f32> {
        let (width, height) = (intrinsics.width as usize, intrinsics.height as usize);
        assert_eq!(depth.len(), width * height, "one depth per pixel");
        let estimated;
        let incidence = match incidence {
            Some(angles) => {
                assert_eq!(angles.len(), depth.len(), "one angle per pixel");
                angles
            }
            None => {
                estimated = incidence_from_depth(intrinsics, depth);
                &estimated
            }
        };
        let grazing = self.grazing_degrees.to_radians();
        let mut out = vec![0.0f32; depth.len()];
        out.par_chunks_mut(width).enumerate().for_each(|(v, row)| {
            for (u, measured) in row.iter_mut().enumerate() {
                let pixel = v * width + u;
                let mut random = SplitMix::new(seed, pixel as u64);
                // Lateral: the sample comes from a jittered pixel.
                let theta_here = f64::from(incidence[pixel]);
                let sigma_l = self.lateral_sigma(theta_here);
                let (mut su, mut sv) = (u, v);
                if sigma_l > 0.0 {
                    let du = (random.normal() * sigma_l).round();
                    let dv = (random.normal() * sigma_l).round();
                    su = (u as f64 + du).clamp(0.0, (width - 1) as f64) as usize;
                    sv = (v as f64 + dv).clamp(0.0, (height - 1) as f64) as usize;
                }
                let source = sv * width + su;
                let z = f64::from(depth[source]);
                let theta = f64::from(incidence[source]);
                if !(z > 0.0 && z.is_finite()) || z < self.min_depth || z > self.max_depth || theta > grazing {
                    continue;
                }
                if self.edge_dropout > 0.0 && at_discontinuity(depth, width, height, su, sv, self.edge_jump) {
                    let drop = random.uniform() < self.edge_dropout;
                    if drop {
                        continue;
                    }
                }
                let sigma = self.axial_sigma(z, theta);
                let noisy = if sigma > 0.0 { z + random.normal() * sigma } else { z };
                let noisy = self.quantise(noisy);
                if noisy >= self.min_depth && noisy <= self.max_depth && noisy > 0.0 {
                    *measured = noisy as f32;
                }
            }
        });
        out
    }
}

impl Default for NoiseModel {
    fn default() -> NoiseModel {
        NoiseModel::KINECT_V1
    }
}

/// Whether a 4-neighbour of `(u, v)` saw nothing or lies more than `jump` away in depth.
fn at_discontinuity(depth: &[f32], width: usize, height: usize, u: usize, v: usize, jump: f64) -> bool {
    let z = f64::from(depth[v * width + u]);
    let neighbours = [
        (u > 0).then(|| v * width + u - 1),
        (u + 1 < width).then(|| v * width + u + 1),
        (v > 0).then(|| (v - 1) * width + u),
        (v + 1 < height).then(|| (v + 1) * width + u),
    ];
    neighbours.into_iter().flatten().any(|n| {
        let other = f64::from(depth[n]);
        !(other > 0.0 && other.is_finite()) || (other - z).abs() > jump
    })
}

/// The angle between each pixel's ray and the surface normal estimated from its neighbours' unprojected points
/// (central differences where both neighbours saw something, one-sided otherwise; 0 where none did).
pub fn incidence_from_depth(intrinsics: &Intrinsics, depth: &[f32]) -> Vec<f32> {
    let (width, height) = (intrinsics.width as usize, intrinsics.height as usize);
    let point = |u: usize, v: usize| {
        let z = f64::from(depth[v * width + u]);
        (z > 0.0 && z.is_finite()).then(|| intrinsics.unproject(u as f64, v as f64, z))
    };
    let mut angles = vec![0.0f32; depth.len()];
    angles.par_chunks_mut(width).enumerate().for_each(|(v, row)| {
        for (u, angle) in row.iter_mut().enumerate() {
            let Some(centre) = point(u, v) else { continue };
            let difference = |a: Option<glam::DVec3>, b: Option<glam::DVec3>| match (a, b) {
                (Some(a), Some(b)) => Some(b - a),
                (None, Some(b)) => Some(b - centre),
                (Some(a), None) => Some(centre - a),
                (None, None) => None,
            };
            let left = (u > 0).then(|| point(u - 1, v)).flatten();
            let right = (u + 1 < width).then(|| point(u + 1, v)).flatten();
            let up = (v > 0).then(|| point(u, v - 1)).flatten();
            let down = (v + 1 < height).then(|| point(u, v + 1)).flatten();
            let (Some(du), Some(dv)) = (difference(left, right), difference(up, down)) else { continue };
            let normal = du.cross(dv);
            let (n, r) = (normal.length(), centre.length());
            if n > 0.0 && r > 0.0 {
                *angle = (normal.dot(centre).abs() / (n * r)).clamp(0.0, 1.0).acos() as f32;
            }
        }
    });
    angles
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small() -> Intrinsics {
        Intrinsics { width: 64, height: 48, fx: 52.5, fy: 52.5, cx: 31.5, cy: 23.5 }
    }

    /// The mean and standard deviation of the measured depths of a fronto-parallel plane at `z` over several seeds.
    fn plane_statistics(model: &NoiseModel, z: f32) -> (f64, f64, usize) {
        let k = small();
        let depth = vec![z; k.pixel_count()];
        let angles = vec![0.0f32; k.pixel_count()];
        let samples: Vec<f64> = (0..8)
            .flat_map(|seed| model.apply(&k, &depth, Some(&angles), seed))
            .filter(|&d| d > 0.0)
            .map(f64::from)
            .collect();
        let mean = samples.iter().sum::<f64>() / samples.len() as f64;
        let variance = samples.iter().map(|d| (d - mean) * (d - mean)).sum::<f64>() / (samples.len() - 1) as f64;
        (mean, variance.sqrt(), samples.len())
    }

    #[test]
    fn the_spread_of_a_plane_matches_the_model() {
        let model = NoiseModel::KINECT_V1;
        for z in [1.0f32, 3.0] {
            let (mean, sigma, count) = plane_statistics(&model, z);
            let expected = model.total_sigma(f64::from(z), 0.0);
            assert!(count > 20_000, "a plane in range has no holes: {count}");
            assert!((sigma / expected - 1.0).abs() < 0.1, "at {z} m: measured σ {sigma}, model {expected}");
            assert!((mean - f64::from(z)).abs() < 3.0 * expected / (count as f64).sqrt() + 2e-4, "unbiased: {mean}");
        }
        // The formula itself: 0.0012 + 0.0019·0.36 at 1 m, and the quantisation step 2.85 mm there.
        assert!((model.axial_sigma(1.0, 0.0) - 0.001884).abs() < 1e-12);
        assert!((model.quantisation_step(1.0) - 0.00285).abs() < 1e-12);
        // Quantised depths sit on the disparity grid.
        let q = model.quantise(1.0013);
        assert!((1.0 / (model.quantisation * q) - (1.0 / (model.quantisation * q)).round()).abs() < 1e-6);
        assert!((q - 1.0013).abs() <= model.quantisation_step(1.0013) * 0.51);
    }

    #[test]
    fn none_leaves_depth_exact_and_seeds_repeat() {
        let k = small();
        let depth: Vec<f32> =
            (0..k.pixel_count()).map(|i| if i % 7 == 0 { 0.0 } else { 0.1 + i as f32 * 0.003 }).collect();
        assert_eq!(NoiseModel::NONE.apply(&k, &depth, None, 5), depth);
        let a = NoiseModel::KINECT_V1.apply(&k, &depth, None, 5);
        assert_eq!(a, NoiseModel::KINECT_V1.apply(&k, &depth, None, 5), "deterministic");
        assert_ne!(a, NoiseModel::KINECT_V1.apply(&k, &depth, None, 6), "the seed matters");
        assert_ne!(a, depth);
    }

    #[test]
    fn holes_at_grazing_angles_out_of_range_and_at_edges() {
        let k = small();
        let model = NoiseModel::KINECT_V1;
        let depth = vec![1.5f32; k.pixel_count()];
        let count = |angle: f32| {
            let angles = vec![angle; k.pixel_count()];
            model.apply(&k, &depth, Some(&angles), 1).iter().filter(|&&d| d > 0.0).count()
        };
        assert_eq!(count(80f32.to_radians()), 0, "grazing: no depth");
        assert_eq!(count(60f32.to_radians()), k.pixel_count(), "steep but not grazing: all measured");
        // A plane tilted to 85° estimated from the depth itself: z grows along u fast enough.
        let tilted: Vec<f32> = (0..k.pixel_count()).map(|i| 1.0 + (i % 64) as f32 * 0.25).collect();
        let angles = incidence_from_depth(&k, &tilted);
        assert!(angles[10 * 64 + 5] > 75f32.to_radians(), "estimated angle {}", angles[10 * 64 + 5]);
        // Out of range.
        assert!(model.apply(&k, &vec![0.3; k.pixel_count()], None, 1).iter().all(|&d| d == 0.0), "too near");
        assert!(model.apply(&k, &vec![6.0; k.pixel_count()], None, 1).iter().all(|&d| d == 0.0), "too far");
        // A step from 1 m to 2 m down the middle: about half the samples along it dropped, none far from it.
        let step: Vec<f32> = (0..k.pixel_count()).map(|i| if i % 64 < 32 { 1.0 } else { 2.0 }).collect();
        let zero = vec![0.0f32; k.pixel_count()];
        let measured = model.apply(&k, &step, Some(&zero), 3);
        let near_edge = (0..48).flat_map(|v| [v * 64 + 31, v * 64 + 32]).filter(|&p| measured[p] == 0.0).count();
        let far_from_edge = (0..48).flat_map(|v| [v * 64 + 10, v * 64 + 50]).filter(|&p| measured[p] == 0.0).count();
        assert!((10..=86).contains(&near_edge), "dropped along the edge: {near_edge} of 96");
        assert_eq!(far_from_edge, 0);
    }

    #[test]
    fn validation_names_the_field() {
        let bad = NoiseModel { edge_dropout: 1.5, ..NoiseModel::KINECT_V1 };
        assert!(bad.validate().unwrap_err().to_string().contains("edge_dropout"));
        let bad = NoiseModel { axial_base: f64::NAN, ..NoiseModel::KINECT_V1 };
        assert!(bad.validate().unwrap_err().to_string().contains("axial_base"));
        assert!(NoiseModel::KINECT_V1.validate().is_ok() && NoiseModel::NONE.validate().is_ok());
    }
}
