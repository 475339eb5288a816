//! Rudin–Osher–Fatemi smoothing of the depth image with Chambolle's dual iteration and the depth-adaptive λ of
//! Reichl §6.5.3 (Eq. 6.3, 6.4, 6.8; Chambolle 2004).
//!
//! # The iteration
//!
//! ROF (Eq. 6.2) finds the `u` minimising `TV(u) + Σ (u − v)² / (2λ)`; Chambolle's dual fixed point iterates on
//! two dual variables `p` per pixel, from `p⁰ = 0`, and reads the result off as `u = v − λ div p` (Eq. 6.4).
//! With one λ, Eq. 6.3's step direction is `∇(div p − v/λ) = ∇(λ div p − v)/λ = −∇u/λ`. With the per-pixel
//! λ of Eq. 6.8 this is evaluated in the last form, per link (a pixel and its right or lower neighbour):
//!
//! ```text
//! λⁿ⁺¹ = λ0 / (uⁿ + ε)                            Eq. 6.8, uⁿ = v − λⁿ div pⁿ (u⁰ = v)
//! g    = −∇uⁿ / λ̄ⁿ⁺¹                              forward differences; λ̄ = the larger λ of the link's pixels
//! pⁿ⁺¹ = (pⁿ + τ g) / (1 + τ |g|)                  Eq. 6.3
//! uⁿ⁺¹ = v − λⁿ⁺¹ div pⁿ⁺¹                         div by backward differences (= −∇ᵀ); after the last: Eq. 6.4
//! ```
//!
//! This is the (diagonally preconditioned) projected-gradient step of the dual of ROF with weights λ_ij, so its
//! fixed point is the weighted-ROF minimiser; with a constant λ it is exactly Chambolle's iteration. `−∇u/λ` is
//! dimensionless, so the depth unit does not matter (scaling depths by s, λ0 by s² and ε by s scales the result
//! by s). Taking `∇(v/λ_ij)` literally instead (Chambolle on `v/λ_ij`, scaled back by λ_ij) differentiates the
//! noise in λ_ij = λ0/z_ij too; where the noise is a few % of the depth it amplified it (measured: 4.5× worse
//! than the input at depth 1 with ±0.05 noise), so it is not used.
//!
//! # The domain
//!
//! The domain Ω is the foreground mask. Its boundary conditions are Neumann, imposed exactly: the gradient
//! component along a link is 0 unless both pixels are foreground, so the dual variable on that link stays 0 and
//! `div` never reads outside Ω (`div = −∇ᵀ` on the graph of links: for constant λ the mean over each connected
//! part is kept). The thesis extrudes the depth one pixel (3×3, from valid neighbours) instead, so that a GPU
//! stencil reading past the mask finds values there; here nothing reads past the mask, so nothing is extruded.
//!
//! A link is also dropped where its two input depths differ by more than [`RofSettings::max_jump`]: a near sphere
//! in front of a far surface, or two fluid layers, become separate parts of the domain, each smoothed on its own
//! and never blended (TV alone keeps such a jump, but still moves a small near region towards the far one by
//! λ·perimeter/area; the cut removes that). Only neighbours are compared, so a steep but continuous surface
//! (whose per-pixel depth step stays below `max_jump`) remains one part.
//!
//! Like any ROF filter it loses contrast at extremes: a slope is flattened over a few pixels where it meets the
//! domain's boundary (the silhouette), and a peak is lowered (by 2λ/R for a plateau of radius R pixels).
//!
//! # Cost
//!
//! Per iteration two row-parallel passes over four `f32` buffers allocated once (`v`, `u`, `p₁`, `p₂`) and one
//! byte of link flags per pixel; λ is recomputed from `u` where needed (the thesis keeps it in a fourth texture,
//! with `div p`). About 41 bytes of memory traffic per pixel and iteration, which bounds the speed.

use rayon::prelude::*;

use super::DepthImage;

/// The settings of [`smooth_rof`]. Build them with [`RofSettings::for_radius`] from the particle radius and the
/// camera, then adjust.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RofSettings {
    /// Number of Chambolle iterations (thesis: 75).
    pub iterations: u32,
    /// λ0 of Eq. 6.8: the smoothing strength; λ_ij = λ0 / (z_ij + ε), stronger near the camera. Unit: depth unit
    /// × depth unit (so λ = λ0/z is in depth units); 0 turns smoothing off. See [`RofSettings::for_radius`].
    pub lambda0: f32,
    /// ε of Eq. 6.8 in depth units: keeps λ finite at depth 0. (Estimated depths below 0 count as 0, and z + ε
    /// as at least 1e-6 of the farthest input depth.)
    pub epsilon: f32,
    /// Chambolle's step τ: 0.25 converges best in practice (Chambolle proves convergence for τ ≤ 1/8).
    pub tau: f32,
    /// Neighbours whose input depths differ by more than this (depth units) are not coupled: the domain's
    /// boundary runs between them (see the module docs). `f32::INFINITY` couples all foreground neighbours.
    pub max_jump: f32,
}

impl RofSettings {
    /// The thesis' iteration count.
    pub const THESIS_ITERATIONS: u32 = 75;
    /// Chambolle's τ.
    pub const CHAMBOLLE_TAU: f32 = 0.25;
    /// [`Self::for_radius`]'s `max_jump`, in particle radii: two touching spheres differ by at most one radius in
    /// depth, a tilted sheet of spheres by a few; a larger jump is a different layer.
    pub const MAX_JUMP_RADII: f32 = 4.0;
    /// [`Self::for_radius`]'s ε, in particle radii.
    pub const EPSILON_RADII: f32 = 1e-3;
    /// [`Self::for_radius`]'s λ(z) in units of `σ · r(z)` (see there), calibrated on a carpet of spheres at 2–6
    /// pixels per radius (see the tests): its bumps are flattened to under a tenth of their spread, while a wave
    /// of 5 radii amplitude and 20 radii wavelength under them keeps over 95 % of its amplitude (half of it leaves
    /// about 1.3× more bump near the camera; twice it loses 7 % of the wave at 2 pixels per radius).
    pub const LAMBDA_SCALE: f32 = 2.0;

    /// The `pixels_per_unit_at_depth_1` of [`Self::for_radius`] for a perspective camera: `h / (2 tan(θ/2))`
    /// with `h` the image height in pixels and θ the vertical field of view (Eq. 6.6).
    pub fn pixels_per_unit_at_depth_1(image_height: usize, fov_y_radians: f32) -> f32 {
        image_height as f32 / (2.0 * (0.5 * fov_y_radians).tan())
    }

    /// Settings for spheres of object-space radius `r_obj` (depth units) seen by a camera with
    /// `pixels_per_unit_at_depth_1` = h / (2 tan(θ/2)) ([`Self::pixels_per_unit_at_depth_1`]).
    ///
    /// A sphere of radius `r_obj` seen from the front leaves depth noise of standard deviation σ = r/√18 over
    /// its disc (Eq. 6.5, `r` in depth units: σ does not depend on `z`), and covers a disc of screen radius
    /// `r(z) = r_obj · pixels_per_unit_at_depth_1 / z` pixels (Eq. 6.6). ROF flattens a bump of height `a` and
    /// radius `R` pixels once λ ≳ a·R/2 (a disc's level moves by λ·perimeter/area = 2λ/R), so λ should be a
    /// multiple of σ · r(z):
    ///
    /// ```text
    /// λ(z) = LAMBDA_SCALE · σ · r(z) = λ0 / z,   λ0 = LAMBDA_SCALE · r_obj² · pixels_per_unit_at_depth_1 / √18
    /// ```
    ///
    /// which is Eq. 6.8's λ0 with the constants of Eq. 6.7 fixed by calibration ([`Self::LAMBDA_SCALE`]).
    /// `max_jump` is [`Self::MAX_JUMP_RADII`] radii, ε [`Self::EPSILON_RADII`] radii, 75 iterations, τ = 0.25.
    pub fn for_radius(r_obj: f32, pixels_per_unit_at_depth_1: f32) -> Self {
        let sigma = r_obj / 18f32.sqrt();
        Self {
            iterations: Self::THESIS_ITERATIONS,
            lambda0: Self::LAMBDA_SCALE * sigma * r_obj * pixels_per_unit_at_depth_1,
            epsilon: Self::EPSILON_RADII * r_obj,
            tau: Self::CHAMBOLLE_TAU,
            max_jump: Self::MAX_JUMP_RADII * r_obj,
        }
    }
}

/// Rudin–Osher–Fatemi total-variation smoothing of the foreground (finite) pixels, Chambolle's dual fixed-point
/// iteration (Eq. 6.3, 6.4) with the depth-adaptive λ of Eq. 6.8, on the odd-shaped domain: the foreground mask
/// with Neumann boundary conditions, cut also between neighbours more than `max_jump` apart (module docs).
/// Background pixels keep their non-finite values bit for bit. Settings with no effect (0 iterations,
/// λ0 ≤ 0, τ ≤ 0, or non-finite) return the image unchanged.
///
/// # Panics
/// If the image is inconsistent (see [`DepthImage::new`]).
pub fn smooth_rof(image: &DepthImage, settings: &RofSettings) -> DepthImage {
    image.assert_consistent();
    let (w, h) = (image.width, image.height);
    let RofSettings { iterations, lambda0, epsilon, tau, max_jump } = *settings;
    let is_active = iterations > 0 && lambda0 > 0.0 && lambda0.is_finite() && tau > 0.0 && tau.is_finite();
    let max_depth = image.depth.iter().filter(|z| z.is_finite()).map(|z| z.abs()).reduce(f32::max);
    let Some(max_depth) = max_depth.filter(|_| is_active) else {
        return image.clone();
    };
    let epsilon = if epsilon.is_finite() { epsilon.max(0.0) } else { 0.0 };
    // Estimated depths are clamped so that z + ε is at least this before λ = λ0 / (z + ε): a depth at or behind
    // the camera would make λ infinite. 1e-6 of the farthest depth is far below any the camera resolves; the
    // last term keeps λ finite when all depths are 0.
    let depth_lambda =
        DepthLambda { epsilon, min_denominator: (1e-6 * max_depth).max(epsilon).max(1e-20 * lambda0), lambda0 };

    // v: the input; the background holds a positive depth there instead (no link reaches a background pixel, so
    // its p and div p stay 0 and its u stays v: it only has to keep λ finite).
    let background_depth = max_depth.max(1.0);
    let v: Vec<f32> = image.depth.iter().map(|&z| if z.is_finite() { z } else { background_depth }).collect();
    let links = links(image, max_jump);
    let mut p1 = vec![0.0f32; w * h];
    let mut p2 = vec![0.0f32; w * h];
    let mut u = v.clone();
    let zero_row = vec![0.0f32; w];

    for _ in 0..iterations {
        // Eq. 6.3 with g = −∇u/λ̄ and λ from the current u (Eq. 6.8).
        p1.par_chunks_mut(w).zip(p2.par_chunks_mut(w)).enumerate().for_each(|(y, (p1_row, p2_row))| {
            let row = y * w..(y + 1) * w;
            let u_below = if y + 1 < h { &u[(y + 1) * w..(y + 2) * w] } else { &u[row.clone()] };
            let rows = PRow { u: &u[row.clone()], u_below, links: &links[row] };
            rows.update_p(p1_row, p2_row, tau, &depth_lambda);
        });
        // u = v − λ div p, div by backward differences, λ from the previous u (Eq. 6.8).
        u.par_chunks_mut(w).enumerate().for_each(|(y, u_row)| {
            let row = y * w..(y + 1) * w;
            let p2_above = if y > 0 { &p2[(y - 1) * w..y * w] } else { &zero_row[..] };
            update_u_row(u_row, &v[row.clone()], &p1[row.clone()], &p2[row], p2_above, &depth_lambda);
        });
    }

    // The foreground takes u; the background keeps its input bits.
    let mut depth = image.depth.clone();
    for (z, &smoothed) in depth.iter_mut().zip(&u) {
        if z.is_finite() {
            *z = smoothed;
        }
    }
    DepthImage { width: w, height: h, depth }
}

/// Eq. 6.8's λ = λ0 / (u + ε) with u + ε clamped to at least `min_denominator`.
struct DepthLambda {
    epsilon: f32,
    min_denominator: f32,
    lambda0: f32,
}

impl DepthLambda {
    #[inline(always)]
    fn lambda(&self, u: f32) -> f32 {
        self.lambda0 / (u + self.epsilon).max(self.min_denominator)
    }

    /// 1/λ without a division.
    #[inline(always)]
    fn inverse_lambda(&self, u: f32, inverse_lambda0: f32) -> f32 {
        (u + self.epsilon).max(self.min_denominator) * inverse_lambda0
    }
}

/// Link flag: coupled to the right neighbour.
const LINK_RIGHT: u8 = 1;
/// Link flag: coupled to the lower neighbour.
const LINK_DOWN: u8 = 2;

/// Per pixel, [`LINK_RIGHT`] and [`LINK_DOWN`] where the pixel is coupled to that neighbour: both foreground,
/// input depths at most `max_jump` apart (a NaN `max_jump` couples all); never past the last column or row.
fn links(image: &DepthImage, max_jump: f32) -> Vec<u8> {
    let (w, h, z) = (image.width, image.height, &image.depth);
    let max_jump = if max_jump.is_nan() { f32::INFINITY } else { max_jump };
    let coupled = |a: f32, b: f32| a.is_finite() && b.is_finite() && (a - b).abs() <= max_jump;
    let mut links = vec![0u8; w * h];
    links.par_chunks_mut(w).enumerate().for_each(|(y, flags)| {
        let row = &z[y * w..(y + 1) * w];
        let below = (y + 1 < h).then(|| &z[(y + 1) * w..(y + 2) * w]);
        for (x, flag) in flags.iter_mut().enumerate() {
            let right = x + 1 < w && coupled(row[x], row[x + 1]);
            let down = below.is_some_and(|b| coupled(row[x], b[x]));
            *flag = if right { LINK_RIGHT } else { 0 } | if down { LINK_DOWN } else { 0 };
        }
    });
    links
}

/// The inputs of one row of Eq. 6.3: `u` of this row and the next (any row of the right length for the last
/// row, which has no [`LINK_DOWN`]), and the row's link flags.
struct PRow<'a> {
    u: &'a [f32],
    u_below: &'a [f32],
    links: &'a [u8],
}

impl PRow<'_> {
    /// One row of Eq. 6.3: p ← (p + τg) / (1 + τ|g|), g = −∇u/λ̄ (0 across dropped links), λ̄ the larger λ of
    /// the link's two pixels, i.e. the one at the smaller depth.
    fn update_p(&self, p1: &mut [f32], p2: &mut [f32], tau: f32, lambda: &DepthLambda) {
        let n = self.u.len();
        // Re-sliced to one length so the loops have no bounds checks and vectorise.
        let (p1, p2, u, u_below, links) = (&mut p1[..n], &mut p2[..n], self.u, &self.u_below[..n], &self.links[..n]);
        let inverse_lambda0 = 1.0 / lambda.lambda0;
        let difference = |a: f32, b: f32, is_linked: bool| {
            let g = (a - b) * lambda.inverse_lambda(a.min(b), inverse_lambda0);
            if is_linked {
                g
            } else {
                0.0
            }
        };
        let step = |p1: &mut f32, p2: &mut f32, gx: f32, gy: f32| {
            let scale = 1.0 / (1.0 + tau * (gx * gx + gy * gy).sqrt());
            *p1 = (*p1 + tau * gx) * scale;
            *p2 = (*p2 + tau * gy) * scale;
        };
        let last = n - 1;
        let u_right = &u[1..];
        for x in 0..last {
            let gx = difference(u[x], u_right[x], links[x] & LINK_RIGHT != 0);
            let gy = difference(u[x], u_below[x], links[x] & LINK_DOWN != 0);
            step(&mut p1[x], &mut p2[x], gx, gy);
        }
        let gy = difference(u[last], u_below[last], links[last] & LINK_DOWN != 0);
        step(&mut p1[last], &mut p2[last], 0.0, gy);
    }
}

/// One row of `u = v − λ div p` with λ from the previous `u` (Eq. 6.8) and `div p = p₁(x) − p₁(x−1) + p₂(x) −
/// p₂(x, y−1)` by backward differences, 0 before the first column and row (`p2_above` = zeros for the first
/// row). The dropped links hold p = 0, which makes this the adjoint −∇ᵀ of the masked forward difference.
fn update_u_row(u: &mut [f32], v: &[f32], p1: &[f32], p2: &[f32], p2_above: &[f32], lambda: &DepthLambda) {
    let n = u.len();
    let (v, p1, p2, p2_above) = (&v[..n], &p1[..n], &p2[..n], &p2_above[..n]);
    let update = |u: &mut f32, v: f32, divergence: f32| *u = v - lambda.lambda(*u) * divergence;
    update(&mut u[0], v[0], p1[0] + p2[0] - p2_above[0]);
    let p1_left = &p1[..n - 1];
    let (u, v, p1, p2, p2_above) = (&mut u[1..], &v[1..], &p1[1..], &p2[1..], &p2_above[1..]);
    for x in 0..n - 1 {
        update(&mut u[x], v[x], p1[x] - p1_left[x] + p2[x] - p2_above[x]);
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_images::{image, noise, noisy_plane, rms_error};
    use super::super::total_variation;
    use super::*;

    /// Fixed settings for the synthetic tests: λ = λ0/z, no jump cut unless a test sets one.
    fn settings(lambda0: f32) -> RofSettings {
        RofSettings { iterations: 75, lambda0, epsilon: 1e-4, tau: 0.25, max_jump: f32::INFINITY }
    }

    fn everywhere(_: usize, _: usize) -> bool {
        true
    }

    #[test]
    fn noisy_tilted_plane_gets_closer_to_the_plane() {
        let (noisy, truth) = noisy_plane(64, 64, 0.05, 1);
        // λ at depth ≈ 4: 0.1, about twice the noise amplitude.
        let smoothed = smooth_rof(&noisy, &settings(0.4));
        let (before, after) = (rms_error(&noisy, &truth, everywhere), rms_error(&smoothed, &truth, everywhere));
        // ROF flattens a slope where it meets the domain's boundary (its extremes lose contrast), so the error
        // is larger in the outer pixels; 4 pixels in, the plane is met much more closely.
        let inner = |x: usize, y: usize| (4..60).contains(&x) && (4..60).contains(&y);
        let after_inner = rms_error(&smoothed, &truth, inner);
        // Measured: 0.0288 → 0.0117 (2.5×) over the image, → 0.0064 (4.5×) 4 pixels in.
        assert!(after * 2.0 < before, "RMS error {before} → {after}");
        assert!(after_inner * 3.5 < before, "RMS error {before} → {after_inner} 4 pixels in");
        assert!(total_variation(&smoothed) * 2.0 < total_variation(&noisy));
    }

    #[test]
    fn step_edge_stays_a_step_by_tv_alone() {
        // Depth 2 left of x = 32, depth 3 right of it, ±0.05 noise; no jump cut, so only TV keeps the edge.
        let truth = |x: usize, _: usize| if x < 32 { 2.0 } else { 3.0 };
        let noisy = image(64, 64, |x, y| Some(truth(x, y) + 0.05 * noise(x, y, 2)));
        let smoothed = smooth_rof(&noisy, &settings(0.8));
        let far_from_edge = |x: usize, _: usize| !(29..35).contains(&x);
        let after = rms_error(&smoothed, truth, far_from_edge);
        // Measured: 0.0286 → 0.0114; at most 0.085 off anywhere, 0.05 three pixels from the edge.
        assert!(after < 0.5 * rms_error(&noisy, truth, far_from_edge), "RMS error {after}");
        for (i, &z) in smoothed.depth.iter().enumerate() {
            let (x, y) = (i % 64, i / 64);
            // No pixel ends between the sides (halfway would be 2.5).
            assert!((z - truth(x, y)).abs() < 0.2, "pixel ({x}, {y}) at {z}");
            if far_from_edge(x, y) {
                assert!((z - truth(x, y)).abs() < 0.05, "pixel ({x}, {y}) at {z}");
            }
        }
    }

    #[test]
    fn jump_cut_keeps_a_small_near_region_at_its_depth() {
        // A 4×4 near patch (depth 1) on a far plane (depth 3): TV alone pulls the patch towards the far plane by
        // about λ·perimeter/area = λ; with the jump cut it is its own domain and keeps its mean exactly.
        let near = |x: usize, y: usize| (30..34).contains(&x) && (30..34).contains(&y);
        let input = image(64, 64, |x, y| Some(if near(x, y) { 1.0 } else { 3.0 }));
        let strong = settings(0.4); // λ ≈ 0.4 on the patch
        let patch = |im: &DepthImage| im.depth[31 * 64 + 31];
        let uncut = smooth_rof(&input, &strong);
        // Measured: 1.28.
        assert!(patch(&uncut) > 1.2, "TV alone moves the patch: {}", patch(&uncut));
        let cut = smooth_rof(&input, &RofSettings { max_jump: 0.5, ..strong });
        assert_eq!(cut, input, "a piecewise-constant image with cut links is a fixed point");
    }

    #[test]
    fn background_untouched_and_disc_mean_kept() {
        let inside = |x: usize, y: usize| (x as f32 - 31.5).powi(2) + (y as f32 - 29.5).powi(2) < 20.0f32.powi(2);
        let mut noisy = image(64, 64, |x, y| inside(x, y).then(|| 5.0 + 0.1 * noise(x, y, 3)));
        // Background of several non-finite kinds, all to be kept bit for bit.
        noisy.depth[0] = f32::NAN;
        noisy.depth[1] = f32::NEG_INFINITY;
        let smoothed = smooth_rof(&noisy, &settings(2.0));
        let mean = |im: &DepthImage| {
            let fg: Vec<f64> = im.depth.iter().filter(|z| z.is_finite()).map(|&z| f64::from(z)).collect();
            fg.iter().sum::<f64>() / fg.len() as f64
        };
        for (a, b) in noisy.depth.iter().zip(&smoothed.depth) {
            assert_eq!(a.is_finite(), b.is_finite());
            if !a.is_finite() {
                assert_eq!(a.to_bits(), b.to_bits());
            }
        }
        // λ varies with depth only by ±2 %, so the mean is kept to far below the noise (0.058 RMS).
        assert!((mean(&smoothed) - mean(&noisy)).abs() < 1e-3, "{} vs {}", mean(&smoothed), mean(&noisy));
        let after = rms_error(&smoothed, |_, _| 5.0, everywhere);
        // Measured: 0.0576 → 0.0050, mean kept to 4e-6.
        assert!(after < 0.2 * rms_error(&noisy, |_, _| 5.0, everywhere), "RMS {after}");
    }

    #[test]
    fn stronger_smoothing_near_the_camera() {
        // The same ±0.05 noise on a flat surface at depth 1 and at depth 10, the same λ0: λ is 10× larger near.
        let relative_residual = |depth: f32| {
            let noisy = image(64, 64, |x, y| Some(depth + 0.05 * noise(x, y, 4)));
            let smoothed = smooth_rof(&noisy, &settings(0.1));
            let truth = |_: usize, _: usize| depth;
            rms_error(&smoothed, truth, everywhere) / rms_error(&noisy, truth, everywhere)
        };
        let (near, far) = (relative_residual(1.0), relative_residual(10.0));
        // Measured: near 0.05, far 0.47.
        assert!(near < 0.25 * far, "near {near}, far {far}");
    }

    #[test]
    fn constant_image_is_a_fixed_point() {
        for depth in [0.1f32, 3.0, 100.0] {
            // A constant disc on background, too: the mask's boundary must not create gradients.
            let flat = image(64, 64, |x, y| (x + y > 20).then_some(depth));
            let smoothed = smooth_rof(&flat, &settings(5.0 * depth * depth));
            for (a, b) in flat.depth.iter().zip(&smoothed.depth) {
                assert!(a.to_bits() == b.to_bits() || (a - b).abs() <= 1e-5 * depth, "{a} → {b}");
            }
        }
    }

    #[test]
    fn result_scales_with_the_depth_unit() {
        // Depths ×s, λ0 ×s², ε ×s, max_jump ×s: the same problem in another unit, so the result is ×s.
        let (noisy, _) = noisy_plane(48, 40, 0.05, 5);
        let base = RofSettings { max_jump: 0.12, ..settings(0.8) };
        let reference = smooth_rof(&noisy, &base);
        for s in [0.01f32, 37.0] {
            let scaled = DepthImage { depth: noisy.depth.iter().map(|z| z * s).collect(), ..noisy.clone() };
            let settings = RofSettings {
                lambda0: base.lambda0 * s * s,
                epsilon: base.epsilon * s,
                max_jump: base.max_jump * s,
                ..base
            };
            let result = smooth_rof(&scaled, &settings);
            for (a, b) in reference.depth.iter().zip(&result.depth) {
                assert!((a * s - b).abs() <= 1e-4 * (a * s).abs(), "{} vs {b} at scale {s}", a * s);
            }
        }
    }

    /// A carpet of spheres of radius `r_obj` facing the camera at depth `z + wave(x)`, one every `2r` on screen,
    /// as the sphere caster sees it (front-most hit, orthographic within a sphere).
    fn sphere_carpet(z: f32, r_obj: f32, f: f32, wave: impl Fn(usize) -> f32) -> DepthImage {
        let r_px = r_obj * f / z;
        image(128, 128, |x, y| {
            let cell = |c: usize| (c as f32 + 0.5) % (2.0 * r_px) - r_px;
            let rho = (cell(x).powi(2) + cell(y).powi(2)).sqrt() / r_px; // 0 at a centre, ≥ 1 at corners
            Some(z + wave(x) - r_obj * (1.0 - rho.min(1.0).powi(2)).sqrt())
        })
    }

    /// Spheres of radius 0.05 under a 60° camera at 720 px (f ≈ 624): 6.2 px per radius at depth 5, 2.1 at 15.
    const CARPET_RADIUS: f32 = 0.05;
    const CARPET_DEPTHS: [f32; 2] = [5.0, 15.0];

    fn carpet_settings() -> (RofSettings, f32) {
        let f = RofSettings::pixels_per_unit_at_depth_1(720, 60f32.to_radians());
        assert!((f - 623.54).abs() < 0.01);
        (RofSettings::for_radius(CARPET_RADIUS, f), f)
    }

    #[test]
    fn for_radius_flattens_sphere_carpets_at_every_depth() {
        let (settings, f) = carpet_settings();
        let spread = |image: &DepthImage| {
            let n = image.depth.len() as f64;
            let mean = image.depth.iter().map(|&z| f64::from(z)).sum::<f64>() / n;
            (image.depth.iter().map(|&z| (f64::from(z) - mean).powi(2)).sum::<f64>() / n).sqrt()
        };
        for z in CARPET_DEPTHS {
            let carpet = sphere_carpet(z, CARPET_RADIUS, f, |_| 0.0);
            let ratio = spread(&smooth_rof(&carpet, &settings)) / spread(&carpet);
            // Measured: 0.079 at depth 5, 0.042 at depth 15.
            assert!(ratio < 0.15, "bumps at depth {z} only reduced to {ratio}");
        }
    }

    #[test]
    fn for_radius_keeps_a_wave_larger_than_the_spheres() {
        // A wave of amplitude 5 radii and wavelength 20 radii (object space) under the sphere bumps.
        let (settings, f) = carpet_settings();
        for z in CARPET_DEPTHS {
            let wavelength_px = 20.0 * CARPET_RADIUS * f / z;
            let wave = |x: usize| 5.0 * CARPET_RADIUS * (std::f32::consts::TAU * x as f32 / wavelength_px).sin();
            let smoothed = smooth_rof(&sphere_carpet(z, CARPET_RADIUS, f, wave), &settings);
            // The wave's amplitude in the result, 8 pixels in: projection on the (zero-mean) wave after removing
            // the mean offset.
            let inner: Vec<usize> = (8..120).flat_map(|y| (8..120).map(move |x| y * 128 + x)).collect();
            let residual = |i: usize| f64::from(smoothed.depth[i] - z);
            let offset = inner.iter().map(|&i| residual(i)).sum::<f64>() / inner.len() as f64;
            let (mut dot, mut norm) = (0.0, 0.0);
            for &i in &inner {
                let s = f64::from(wave(i % 128));
                dot += (residual(i) - offset) * s;
                norm += s * s;
            }
            // Measured: 0.98 at depth 5, 0.96 at depth 15.
            assert!(dot / norm > 0.9, "wave at depth {z} kept to {}", dot / norm);
        }
    }
}
