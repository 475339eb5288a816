//! Deferred integration of one brick from a set of cached frames (seed 004 §8.3.2, §8.4.3, eq. 8.1–8.2).
//!
//! Every voxel centre is projected into every frame of the set; each frame that saw the surface near it gives a
//! projective signed distance `D_i` (positive in front of the surface) with weight `W_i`: 1 in front, falling
//! linearly to 0 at `σ` behind, and nothing deeper (the voxel is hidden there). Distances in front are truncated to
//! `σ`, as every TSDF integration does, so free space carves away what an earlier window put there. The thesis
//! prints the weight behind the surface as `1 − (σ + D)/σ`, which would grow with depth; we read it as
//! `(σ + D)/σ`, the usual linear fall-off. A voxel already confident contributes its earlier result as a prior
//! `Φ` (the distance to the nearest confident sign change found by sweeping a few voxels along the axes) with weight
//! `Ψ`, larger for bricks of smaller error; without a sign change nearby `Ψ = 0`. Only the sign of the average is
//! kept; the voxel is confident when the frames' weights add up to the confidence weight, and a confident voxel is
//! replaced only by a confident one from samples no less accurate than those that set it (§8.3.4). Surface voxels
//! (average within `voxel/√2` of the surface) get the weighted average colour (§8.5).
//!
//! **Surface offsets** (our addition, [`crate::brick`]) are kept beside the bits and never change them: every voxel
//! a window sees with the confidence weight averages the frames' truncated distances with equal weights (the
//! thesis' fall-off behind the surface would bias a mean towards the front wherever the noise is a sizeable share
//! of the band) into its kept offset, weighted by the frames it was averaged over, as a TSDF averages, up to
//! [`MAX_OFFSET_WEIGHT`]. Voxels farther than [`OFFSET_RANGE`] voxels from the surface keep none.

use glam::{IVec3, Mat3, Vec3};

use crate::brick::{voxel_index, BinaryBrick, BRICK, BRICK_VOXELS, MAX_OFFSET_WEIGHT, OFFSET_RANGE};
use crate::brick_map::BrickMap;
use crate::camera::{Intrinsics, Pose};

/// How far (voxels) the prior's sweep looks for a confident sign change.
const PRIOR_SWEEP: i32 = 3;

/// The fusion's noise and weighting choices.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IntegrationSettings {
    /// Voxel edge, metres.
    pub voxel: f64,
    /// `σ` is this many times the sensor's depth uncertainty at the sample's depth…
    pub sigma_factor: f32,
    /// …but at least this many voxels.
    pub min_band_voxels: f32,
    /// Summed frame weight that makes a voxel confident.
    pub confidence_weight: f32,
    /// Weight of a confident voxel's earlier result, for a brick whose error equals the voxel size.
    pub prior_weight: f32,
    /// Keep the averaged distance of voxels within [`OFFSET_RANGE`] voxels of the surface (a byte, and a byte of
    /// weight), not only the sign: the surface then lies between voxel centres, not on voxel faces.
    pub surface_offsets: bool,
}

impl IntegrationSettings {
    /// The Kinect v1 axial uncertainty at depth `z` (Nguyen, Izadi and Lovell 2012, the thesis' [NIL12]).
    pub fn sensor_sigma(z: f32) -> f32 {
        0.0012 + 0.0019 * (z - 0.4) * (z - 0.4)
    }

    /// The band `σ` of a sample at depth `z`: the truncation distance of eq. 8.2.
    pub fn band(&self, z: f32) -> f32 {
        (self.sigma_factor * Self::sensor_sigma(z)).max(self.min_band_voxels * self.voxel as f32)
    }
}

/// The unit of cached depths, metres: the TUM benchmark's 1/5000 m.
pub const DEPTH_UNIT: f32 = 1.0 / 5000.0;
/// The farthest depth a cached frame keeps, metres (65535 units).
pub const MAX_DEPTH: f32 = 65535.0 * DEPTH_UNIT;

/// A frame in the cache: its images, pose, and the bricks it touched. The ring holds 2n of them, so they are
/// kept small: 2 bytes of depth and 3 of colour a pixel.
#[derive(Clone, Debug)]
pub struct CachedFrame {
    pub intrinsics: Intrinsics,
    /// Depth in units of [`DEPTH_UNIT`] (the TUM benchmark's 1/5000 m, so its PNGs are kept exactly); 0 = none.
    pub depth: Vec<u16>,
    pub colour: Vec<[u8; 3]>,
    pub pose: Pose,
    /// World to camera, in f32 (voxel centres are projected millions of times per window).
    rotation: Mat3,
    translation: Vec3,
    /// The bricks this frame's samples allocated or touched.
    pub bricks: Vec<IVec3>,
}

impl CachedFrame {
    /// A cached frame of `depth` in metres (0 = none; depths beyond [`MAX_DEPTH`] are dropped).
    pub fn new(intrinsics: Intrinsics, depth: &[f32], colour: Vec<[u8; 3]>, pose: Pose) -> Self {
        let depth = depth
            .iter()
            .map(|&d| if d > 0.0 && d <= MAX_DEPTH { (d / DEPTH_UNIT).round() as u16 } else { 0 })
            .collect();
        let inverse = pose.inverse();
        CachedFrame {
            intrinsics,
            depth,
            colour,
            pose,
            rotation: inverse.matrix3.as_mat3(),
            translation: inverse.translation.as_vec3(),
            bricks: Vec::new(),
        }
    }

    /// Bytes of the images.
    pub fn bytes(&self) -> usize {
        self.depth.len() * 2 + self.colour.len() * 3 + self.bricks.len() * 12
    }

    /// Whether any point of the sphere at world `centre` with `radius` may project into the image (a conservative
    /// test: `false` only where none can).
    #[inline]
    fn may_see(&self, centre: Vec3, radius: f32) -> bool {
        let c = self.rotation * centre + self.translation;
        if c.z + radius <= 0.0 {
            return false;
        }
        let near = c.z - radius;
        if near <= 1e-3 {
            return true;
        }
        let k = &self.intrinsics;
        // x/z over the sphere's box lies between these (z from near to far, x from c.x − r to c.x + r).
        let far = c.z + radius;
        let (x_lo, x_hi) = (
            (c.x - radius) / if c.x - radius < 0.0 { near } else { far },
            (c.x + radius) / if c.x + radius > 0.0 { near } else { far },
        );
        let (y_lo, y_hi) = (
            (c.y - radius) / if c.y - radius < 0.0 { near } else { far },
            (c.y + radius) / if c.y + radius > 0.0 { near } else { far },
        );
        let (u_lo, u_hi) = (k.fx as f32 * x_lo + k.cx as f32, k.fx as f32 * x_hi + k.cx as f32);
        let (v_lo, v_hi) = (k.fy as f32 * y_lo + k.cy as f32, k.fy as f32 * y_hi + k.cy as f32);
        u_hi >= -0.5 && v_hi >= -0.5 && u_lo < k.width as f32 - 0.5 && v_lo < k.height as f32 - 0.5
    }

    /// The depth and colour of the pixel that world point `p` projects to, with `p`'s own depth.
    #[inline]
    fn sample(&self, p: Vec3) -> Option<(f32, f32, [u8; 3])> {
        let c = self.rotation * p + self.translation;
        if c.z <= 0.0 {
            return None;
        }
        let k = &self.intrinsics;
        let u = (k.fx as f32 * c.x / c.z + k.cx as f32).round();
        let v = (k.fy as f32 * c.y / c.z + k.cy as f32).round();
        if u < 0.0 || v < 0.0 || u >= k.width as f32 || v >= k.height as f32 {
            return None;
        }
        let i = v as usize * k.width as usize + u as usize;
        let d = self.depth[i];
        (d > 0).then(|| (f32::from(d) * DEPTH_UNIT, c.z, self.colour.get(i).copied().unwrap_or([0; 3])))
    }
}

/// Whether a brick is processed by a window of the cache or by the sub-cache.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pass {
    /// A window of the ring buffer: confident voxels may be set.
    Window,
    /// The most recent few frames, for immediate feedback: nothing is confident (§8.3.3).
    SubCache,
}

/// The signed distance (metres, positive outside) from voxel `v` to the nearest confident sign change within
/// [`PRIOR_SWEEP`] voxels along the axes, if `v` is confident and there is one.
fn prior_distance(map: &BrickMap, v: IVec3, inside: bool, voxel: f64) -> Option<f32> {
    let mut nearest = None;
    for axis in [IVec3::X, IVec3::Y, IVec3::Z, -IVec3::X, -IVec3::Y, -IVec3::Z] {
        for step in 1..=PRIOR_SWEEP {
            if nearest.is_some_and(|n| n <= step) {
                break;
            }
            let w = v + axis * step;
            let (key, local) = BrickMap::split(w);
            let Some(brick) = map.brick(key) else { break };
            let i = voxel_index(local.x, local.y, local.z);
            if !brick.confident.get(i) {
                break;
            }
            if brick.inside.get(i) != inside {
                nearest = Some(step);
                break;
            }
        }
    }
    let steps = nearest?;
    let distance = (steps as f32 - 0.5) * voxel as f32;
    Some(if inside { -distance } else { distance })
}

/// Integrates brick `key` from `frames`, starting from its current state in `map` (absent: all outside).
pub fn integrate_brick(
    map: &BrickMap,
    key: IVec3,
    frames: &[&CachedFrame],
    settings: &IntegrationSettings,
    pass: Pass,
) -> BinaryBrick {
    let old = map.brick(key).cloned().unwrap_or_default();
    let voxel = settings.voxel;
    let prior_scale =
        if old.error.is_finite() && old.error > 0.0 { (voxel as f32 / old.error).clamp(0.5, 4.0) } else { 0.0 };
    let mut out = BinaryBrick { colours: Vec::new(), offsets: Vec::new(), ..old.clone() };
    let mut error_sum = 0.0f64;
    let mut error_weight = 0.0f64;
    let origin = key * BRICK;
    // Voxel centres, then frames outer and voxels inner: a frame's constants stay in registers and its depth rows
    // in cache, and a frame that cannot see the brick is skipped whole. Each voxel still sums its frames in order.
    let centres: Vec<Vec3> = (0..BRICK_VOXELS as i32)
        .map(|i| map.centre(origin + IVec3::new(i % BRICK, (i / BRICK) % BRICK, i / (BRICK * BRICK))).as_vec3())
        .collect();
    let brick_centre = map.centre(origin + IVec3::splat(BRICK / 2)).as_vec3() - Vec3::splat(0.5 * voxel as f32);
    let brick_radius = 0.5 * 3f32.sqrt() * (voxel as f32) * BRICK as f32;
    let mut w_sums = [0.0f32; BRICK_VOXELS];
    let mut wd_sums = [0.0f32; BRICK_VOXELS];
    let mut sigma_sums = [0.0f32; BRICK_VOXELS];
    let mut colours = [[0.0f32; 4]; BRICK_VOXELS];
    // Equal-weight sums for the surface offsets: frames, and their truncated distances.
    let mut n_sums = [0.0f32; BRICK_VOXELS];
    let mut d_sums = [0.0f32; BRICK_VOXELS];
    for frame in frames {
        if !frame.may_see(brick_centre, brick_radius) {
            continue;
        }
        for (i, p) in centres.iter().enumerate() {
            let Some((d, z_voxel, rgb)) = frame.sample(*p) else { continue };
            let distance = d - z_voxel;
            let band = settings.band(d);
            if distance <= -band {
                continue;
            }
            let w = if distance > 0.0 { 1.0 } else { (band + distance) / band };
            w_sums[i] += w;
            wd_sums[i] += w * distance.min(band);
            n_sums[i] += 1.0;
            d_sums[i] += distance.min(band);
            sigma_sums[i] += w * IntegrationSettings::sensor_sigma(d);
            if distance.abs() < band {
                let colour = &mut colours[i];
                for c in 0..3 {
                    colour[c] += w * f32::from(rgb[c]);
                }
                colour[3] += w;
            }
        }
    }
    for i in 0..BRICK_VOXELS {
        if w_sums[i] > 0.0 {
            error_sum += f64::from(sigma_sums[i]);
            error_weight += f64::from(w_sums[i]);
        }
    }
    let new_error = if error_weight > 0.0 { (error_sum / error_weight) as f32 } else { f32::INFINITY };
    let may_replace_confident = pass == Pass::Window && new_error <= old.error * 1.05;
    let mut changed_confident = false;
    for i in 0..BRICK_VOXELS {
        let (w_sum, wd_sum, colour) = (w_sums[i], wd_sums[i], colours[i]);
        let local = IVec3::new(i as i32 % BRICK, (i as i32 / BRICK) % BRICK, i as i32 / (BRICK * BRICK));
        let v = origin + local;
        let was_inside = old.inside.get(i);
        let was_confident = old.confident.get(i);
        if settings.surface_offsets {
            let kept = old.offset_and_weight(local.x, local.y, local.z);
            if pass == Pass::Window && n_sums[i] >= settings.confidence_weight {
                let (d0, w0) = kept.unwrap_or((0.0, 0.0));
                let d = (w0 * d0 + d_sums[i] / voxel as f32) / (w0 + n_sums[i]);
                if d.abs() < OFFSET_RANGE {
                    out.set_offset(local.x, local.y, local.z, d, (w0 + n_sums[i]).min(MAX_OFFSET_WEIGHT));
                }
            } else if let Some((d0, w0)) = kept {
                out.set_offset(local.x, local.y, local.z, d0, w0);
            }
        }
        let (prior, psi) = match (was_confident, prior_scale > 0.0) {
            (true, true) => match prior_distance(map, v, was_inside, voxel) {
                Some(phi) => (phi, settings.prior_weight * prior_scale),
                None => (0.0, 0.0),
            },
            _ => (0.0, 0.0),
        };
        if w_sum + psi <= 0.0 {
            // Unseen: keeps its state (and colour).
            out.keep_colour(&old, local.x, local.y, local.z);
            continue;
        }
        let average = (psi * prior + wd_sum) / (psi + w_sum);
        let inside = average < 0.0;
        let confident = pass == Pass::Window && w_sum >= settings.confidence_weight;
        if was_confident && !(confident && may_replace_confident) {
            out.keep_colour(&old, local.x, local.y, local.z);
            continue;
        }
        changed_confident |= confident;
        out.inside.set(i, inside);
        out.confident.set(i, confident);
        let surface = average.abs() <= voxel as f32 * std::f32::consts::FRAC_1_SQRT_2;
        if confident && surface && colour[3] > 0.0 {
            let rgb = [0, 1, 2].map(|c| (colour[c] / colour[3]).round().clamp(0.0, 255.0) as u8);
            out.set_colour(local.x, local.y, local.z, rgb);
        }
    }
    match pass {
        Pass::Window => {
            out.integrated = true;
            if changed_confident {
                out.error = new_error.min(old.error);
            }
        }
        // The sub-cache leaves `integrated` and the error as they were (`out` started as a copy of `old`).
        Pass::SubCache => {}
    }
    out
}
