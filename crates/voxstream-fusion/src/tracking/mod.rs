//! Camera tracking: the pose of each new depth frame, estimated by ICP against the surface fused so far.
//!
//! Seed 004 §8.2: "the current camera pose is estimated using ICP … and the new, noisy depth image is aligned with
//! the rendered output of the fused surface". As in KinectFusion's frame-to-model tracking (Newcombe et al. 2011,
//! "KinectFusion: real-time dense surface mapping and tracking", §3.5), the model is what the fusion ray-casts (and
//! smooths in screen space) from the previous pose, a [`ModelView`] of world-space vertices and normals per pixel;
//! the frame is a depth image in a 3-level pyramid; correspondences come from projective data association (a frame
//! vertex, moved by the current estimate, is projected into the model's reference camera and paired with the model
//! vertex at that pixel, unless they lie too far apart or their normals disagree); each iteration minimises the
//! linearised point-to-plane distance `Σ (n_model · (T p_frame − p_model))²` over a small rotation and translation,
//! solving 6×6 normal equations accumulated in parallel over image rows. Coarse levels pull in a larger motion
//! cheaply, fine levels make it exact.
//!
//! When the data cannot determine the pose, [`track`] says so ([`TrackingLost`]) instead of returning a guess: too
//! few correspondences, a scene that lets the camera slide (a single plane: the equations' conditioning is checked
//! before they are solved), or surfaces that still do not meet after the last iteration.
//!
//! [`ate_rmse`] and [`relative_pose_error`] measure a tracked trajectory against ground truth as the TUM RGB-D
//! benchmark does (Sturm et al. 2012).

mod linalg;
mod model;
mod trajectory;

#[cfg(test)]
mod tests;

use glam::{DAffine3, DMat3, DQuat, DVec3};
use rayon::prelude::*;

use crate::camera::{Intrinsics, Pose};
use linalg::{cholesky_solve, symmetric_eigen};
use model::{downsample, vertex_normal_maps};

pub use model::{ModelView, MODEL_DEPTH_JUMP};
pub use trajectory::{ate_rmse, relative_pose_error, RelativePoseError};

/// A raw sensor frame's depth made fit for tracking, as KinectFusion does before it computes normals: a depth-aware
/// bilateral filter (σ 2 pixels, 3 cm in depth; layers further apart are not blended; missing pixels stay
/// missing). Without it, Kinect noise of a few millimetres between neighbouring pixels turns the frame's normals
/// random, the normal test rejects most pairs, and ICP stays where it started (measured by
/// `examples/track_check.rs`: 24 mm error for a 25 mm step with raw depth).
pub fn prepare_frame(depth: &[f32], intrinsics: &Intrinsics) -> Vec<f32> {
    use voxstream_fluid::screen_space::{smooth_bilateral, DepthImage};
    let image = DepthImage::new(
        intrinsics.width as usize,
        intrinsics.height as usize,
        depth.iter().map(|&d| if d > 0.0 && d.is_finite() { d } else { f32::INFINITY }).collect(),
    );
    smooth_bilateral(&image, 2.0, 0.03).depth.into_iter().map(|d| if d.is_finite() { d } else { 0.0 }).collect()
}

/// The levels of the frame's depth pyramid: full, half and quarter resolution.
pub const PYRAMID_LEVELS: usize = 3;

/// The knobs of [`track`]; [`Default`] follows KinectFusion where it says, and otherwise suits a Kinect at 0.5–4 m.
#[derive(Clone, Debug, PartialEq)]
pub struct TrackingSettings {
    /// ICP iterations per pyramid level, finest first (KinectFusion: 10, 5, 4); levels run coarsest first, and a
    /// level with 0 iterations is skipped.
    pub iterations: [usize; PYRAMID_LEVELS],
    /// The farthest a frame vertex may lie from its model vertex to be paired at the finest level (metres); it
    /// doubles with each coarser level, whose pixels are twice as large and whose pose is still rough.
    pub max_distance: f64,
    /// The largest angle between a frame normal and its model normal to be paired (radians).
    pub max_normal_angle: f64,
    /// The largest depth step between neighbouring frame pixels, relative to depth, across which a normal is still
    /// estimated and a pyramid block still averaged.
    pub max_depth_jump: f64,
    /// The fewest correspondences, as a fraction of the level's frame vertices that have a normal, for the pose to
    /// count as tracked.
    pub min_inlier_fraction: f64,
    /// The smallest ratio of the least to the largest eigenvalue of the normal equations (rotations scaled by the
    /// scene's extent, so the ratio has no unit) below which the scene does not fix all six degrees of freedom.
    pub min_conditioning: f64,
    /// The largest root-mean-square point-to-plane residual at the finest level after the last iteration (metres).
    pub max_rms_residual: f64,
    /// A level stops iterating once an update rotates by less than this many radians and moves by less than this
    /// many metres.
    pub min_update: f64,
}

impl Default for TrackingSettings {
    fn default() -> Self {
        TrackingSettings {
            iterations: [10, 5, 4],
            max_distance: 0.1,
            max_normal_angle: 30f64.to_radians(),
            max_depth_jump: 0.1,
            min_inlier_fraction: 0.25,
            min_conditioning: 1e-3,
            max_rms_residual: 0.03,
            min_update: 1e-7,
        }
    }
}

/// A tracked pose and how well the frame met the model there.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackResult {
    /// The frame's camera to world.
    pub pose: Pose,
    /// The root-mean-square point-to-plane distance of the finest level's correspondences at `pose` (metres).
    pub rms_residual: f64,
    /// The finest level's correspondences at `pose`.
    pub inliers: usize,
    /// ICP iterations run, all levels together.
    pub iterations: usize,
}

/// Why [`track`] gave no pose.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum TrackingLost {
    /// Too few frame vertices found a model vertex close enough with a similar normal.
    #[error(
        "tracking lost: {inliers} of {candidates} frame points at pyramid level {level} met the model, \
         fewer than the {required} needed (the camera moved too far, or the frame or model is empty)"
    )]
    TooFewInliers { level: usize, inliers: usize, candidates: usize, required: usize },
    /// The correspondences do not fix all six degrees of freedom (a single plane lets the camera slide).
    #[error(
        "tracking lost: the scene does not fix the pose at pyramid level {level} (conditioning {conditioning:.2e} \
         below {min:.2e}: too little structure, such as a single plane)"
    )]
    IllConditioned { level: usize, conditioning: f64, min: f64 },
    /// After the last iteration the frame still lies too far from the model.
    #[error("tracking lost: the frame lies {rms:.4} m (rms) from the model after ICP, more than {max} m")]
    ResidualTooLarge { rms: f64, max: f64 },
    /// The depth image or the model does not have the size its intrinsics say.
    #[error("tracking impossible: the {what} holds {actual} pixels, its intrinsics say {expected}")]
    SizeMismatch { what: &'static str, expected: usize, actual: usize },
}

/// One level of the frame's pyramid: camera-space vertices and normals.
struct Level {
    /// 0 for the finest.
    index: usize,
    vertices: Vec<Option<DVec3>>,
    normals: Vec<Option<DVec3>>,
    width: usize,
    /// The vertices that have a normal: the candidates for correspondences.
    candidates: usize,
    /// Their mean, the pivot of the rotation updates (keeps rotation and translation apart in the equations).
    centroid: DVec3,
}

impl Level {
    fn new(index: usize, depth: &[f32], k: &Intrinsics, max_jump: f64) -> Level {
        let (vertices, normals) = vertex_normal_maps(depth, k, max_jump);
        let (sum, candidates) = vertices
            .iter()
            .zip(&normals)
            .filter_map(|(p, n)| p.filter(|_| n.is_some()))
            .fold((DVec3::ZERO, 0), |(s, c), p| (s + p, c + 1));
        let centroid = if candidates > 0 { sum / candidates as f64 } else { DVec3::ZERO };
        Level { index, vertices, normals, width: k.width as usize, candidates, centroid }
    }
}

/// The point-to-plane normal equations of one iteration, summed over correspondences. The unknowns are a small
/// rotation `ω` about `pivot` and a translation `t` of the frame's world-space points: `q ↦ q + ω × (q − pivot) + t`.
#[derive(Clone, Copy)]
struct Equations {
    /// `Σ J Jᵀ` with `J = ((q − pivot) × n, n)`.
    jtj: [[f64; 6]; 6],
    /// `Σ J r` with the residual `r = n · (q − p_model)`.
    jtr: [f64; 6],
    /// `Σ r²`.
    r2: f64,
    /// `Σ |q − pivot|²`, the scene's extent around the pivot.
    spread2: f64,
    count: usize,
}

impl Equations {
    const ZERO: Equations = Equations { jtj: [[0.0; 6]; 6], jtr: [0.0; 6], r2: 0.0, spread2: 0.0, count: 0 };

    fn add(&mut self, arm: DVec3, n: DVec3, r: f64) {
        let a = arm.cross(n);
        let j = [a.x, a.y, a.z, n.x, n.y, n.z];
        for (row, ji) in self.jtj.iter_mut().zip(j) {
            for (x, jk) in row.iter_mut().zip(j) {
                *x += ji * jk;
            }
        }
        for (x, ji) in self.jtr.iter_mut().zip(j) {
            *x += ji * r;
        }
        self.r2 += r * r;
        self.spread2 += arm.length_squared();
        self.count += 1;
    }

    fn merge(mut self, other: Equations) -> Equations {
        for (row, o) in self.jtj.iter_mut().zip(other.jtj) {
            for (x, y) in row.iter_mut().zip(o) {
                *x += y;
            }
        }
        for (x, y) in self.jtr.iter_mut().zip(other.jtr) {
            *x += y;
        }
        self.r2 += other.r2;
        self.spread2 += other.spread2;
        self.count += other.count;
        self
    }

    fn rms(&self) -> f64 {
        if self.count == 0 {
            0.0
        } else {
            (self.r2 / self.count as f64).sqrt()
        }
    }
}

/// Pairs the level's vertices, moved by `pose`, with the model by projective data association and sums the
/// equations of the pairs that pass the distance and normal tests.
fn associate(level: &Level, model: &ModelView, pose: &Pose, pivot: DVec3, settings: &TrackingSettings) -> Equations {
    let model_from_world = model.pose.inverse();
    let max_distance = settings.max_distance * (1 << level.index) as f64;
    let (max_d2, min_cos) = (max_distance * max_distance, settings.max_normal_angle.cos());
    let mw = model.intrinsics.width as usize;
    level
        .vertices
        .par_chunks(level.width.max(1))
        .zip(level.normals.par_chunks(level.width.max(1)))
        .fold(
            || Equations::ZERO,
            |mut eq, (vertices, normals)| {
                for (p, n) in vertices.iter().zip(normals) {
                    let (Some(p), Some(n)) = (p, n) else { continue };
                    let q = pose.transform_point3(*p);
                    let Some((mu, mv)) = model.intrinsics.pixel_of(model_from_world.transform_point3(q)) else {
                        continue;
                    };
                    let i = mv as usize * mw + mu as usize;
                    let (Some(q_model), Some(n_model)) = (model.vertices[i], model.normals[i]) else { continue };
                    let d = q - q_model;
                    if d.length_squared() > max_d2 || pose.transform_vector3(*n).dot(n_model) < min_cos {
                        continue;
                    }
                    eq.add(q - pivot, n_model, n_model.dot(d));
                }
                eq
            },
        )
        .reduce(|| Equations::ZERO, Equations::merge)
}

/// The update `(ω, t)` that minimises the linearised residuals, or the conditioning that was too poor to trust one.
fn solve(eq: &Equations, min_conditioning: f64) -> Result<(DVec3, DVec3), f64> {
    // Scale the rotation unknowns by the scene's extent `s` (ω' = s ω), so all six columns are lengths per unit
    // normal and the eigenvalue ratio below compares like with like; divide by the count for O(1) entries.
    let s = (eq.spread2 / eq.count.max(1) as f64).sqrt().max(1e-9);
    let scale = |i: usize| if i < 3 { 1.0 / s } else { 1.0 };
    let n = eq.count.max(1) as f64;
    let a: [[f64; 6]; 6] = std::array::from_fn(|i| std::array::from_fn(|k| eq.jtj[i][k] * scale(i) * scale(k) / n));
    let b: [f64; 6] = std::array::from_fn(|i| -eq.jtr[i] * scale(i) / n);
    let (values, _) = symmetric_eigen(a);
    let largest = values.iter().copied().fold(0.0, f64::max);
    let least = values.iter().copied().fold(f64::INFINITY, f64::min);
    let conditioning = if largest > 0.0 { least / largest } else { 0.0 };
    if conditioning.is_nan() || conditioning < min_conditioning {
        return Err(conditioning);
    }
    let x = cholesky_solve(&a, &b).ok_or(conditioning)?;
    Ok((DVec3::new(x[0], x[1], x[2]) / s, DVec3::new(x[3], x[4], x[5])))
}

/// The rigid motion `q ↦ R(ω) (q − pivot) + pivot + t` of world points.
fn increment(omega: DVec3, t: DVec3, pivot: DVec3) -> DAffine3 {
    let rotation = DMat3::from_quat(DQuat::from_scaled_axis(omega));
    DAffine3::from_mat3_translation(rotation, pivot + t - rotation * pivot)
}

/// The pose of a depth frame (metres along the optical axis, 0 or non-finite = missing; `intrinsics` its camera),
/// found by point-to-plane ICP against `model`, starting from `initial` (usually the previous frame's pose, from
/// which `model` was rendered).
///
/// Works coarse to fine over a [`PYRAMID_LEVELS`]-level pyramid of the frame with
/// [`iterations`](TrackingSettings::iterations) per level, stopping a level early once the update is below
/// [`min_update`](TrackingSettings::min_update); see [`TrackingSettings`] for the tests that pair points and decide
/// the pose is lost.
pub fn track(
    frame_depth: &[f32],
    intrinsics: &Intrinsics,
    model: &ModelView,
    initial: Pose,
    settings: &TrackingSettings,
) -> Result<TrackResult, TrackingLost> {
    let model_pixels = model.intrinsics.pixel_count();
    for (what, expected, actual) in [
        ("frame's depth image", intrinsics.pixel_count(), frame_depth.len()),
        ("model's vertex map", model_pixels, model.vertices.len()),
        ("model's normal map", model_pixels, model.normals.len()),
    ] {
        if expected != actual {
            return Err(TrackingLost::SizeMismatch { what, expected, actual });
        }
    }

    // The pyramid, finest first.
    let mut levels = Vec::with_capacity(PYRAMID_LEVELS);
    let (mut depth, mut k) = (frame_depth.to_vec(), *intrinsics);
    for l in 0..PYRAMID_LEVELS {
        levels.push(Level::new(l, &depth, &k, settings.max_depth_jump));
        if l + 1 < PYRAMID_LEVELS {
            (depth, k) = downsample(&depth, &k, settings.max_depth_jump);
        }
    }
    let required = |level: &Level| ((settings.min_inlier_fraction * level.candidates as f64).ceil() as usize).max(6);

    let mut pose = initial;
    let mut iterations = 0;
    for (l, level) in levels.iter().enumerate().rev() {
        for _ in 0..settings.iterations[l] {
            let pivot = pose.transform_point3(level.centroid);
            let eq = associate(level, model, &pose, pivot, settings);
            iterations += 1;
            if eq.count < required(level) {
                return Err(TrackingLost::TooFewInliers {
                    level: l,
                    inliers: eq.count,
                    candidates: level.candidates,
                    required: required(level),
                });
            }
            let (omega, t) = solve(&eq, settings.min_conditioning).map_err(|conditioning| {
                TrackingLost::IllConditioned { level: l, conditioning, min: settings.min_conditioning }
            })?;
            pose = increment(omega, t, pivot) * pose;
            if omega.length() < settings.min_update && t.length() < settings.min_update {
                break;
            }
        }
    }

    // How well the frame meets the model at the final pose, at full resolution.
    let finest = &levels[0];
    let eq = associate(finest, model, &pose, pose.transform_point3(finest.centroid), settings);
    if eq.count < required(finest) {
        return Err(TrackingLost::TooFewInliers {
            level: 0,
            inliers: eq.count,
            candidates: finest.candidates,
            required: required(finest),
        });
    }
    if eq.rms() > settings.max_rms_residual {
        return Err(TrackingLost::ResidualTooLarge { rms: eq.rms(), max: settings.max_rms_residual });
    }
    Ok(TrackResult { pose, rms_residual: eq.rms(), inliers: eq.count, iterations })
}
