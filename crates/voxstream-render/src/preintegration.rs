//! Pre-integrated transfer functions (Engel, Kraus and Ertl 2001; Reichl's brick traverser, seed 004 §5.6): the
//! colour and opacity of a whole ray segment between two samples, with the field taken as linear between their
//! values, so that a transfer-function feature the field crosses between two samples is integrated instead of
//! missed.
//!
//! Engel et al. tabulate the segment's colour and opacity in a 2-D table per segment length. Here the table is the
//! 1-D *integral function* of their §4: prefix integrals over the normalised value `s` of the extinction,
//! `T(s) = ∫₀ˢ σ`, and of the extinction-weighted colour, `K(s) = ∫₀ˢ σ·c`. For a segment of length `d` whose
//! value runs linearly from `s_f` to `s_b`:
//!
//! - optical depth `τ = d · (T(s_b) − T(s_f)) / (s_b − s_f)` (exact for a linear field), opacity `α = 1 − e^(−τ)`;
//! - premultiplied colour `α · (K(s_b) − K(s_f)) / (T(s_b) − T(s_f))`: the extinction-weighted mean colour over the
//!   segment times its opacity. Exact when the colour is constant over the segment; it neglects only the
//!   self-attenuation of the colour *within* one segment (where Engel's integral-function formula also drops the
//!   `α` factor, this keeps it, so an opaque segment never emits more than its colour).
//!
//! Any segment length works from the same table (no table per step), and a lookup costs two interpolated reads, a
//! division and one `exp`. Where `s_b ≈ s_f` the segment is the point value's, as an ordinary sample.

use glam::Vec4;

use crate::sampler::floor_index;
use crate::transfer_function::{LutEntry, LUT_SIZE};

/// Below this many table entries between the two values, a segment is taken as constant (the point value at their
/// mean): the division by `s_b − s_f` would only add rounding.
const CONSTANT_BELOW_ENTRIES: f32 = 1e-2;

/// The integral functions of one transfer-function table.
#[derive(Clone, Debug)]
pub struct PreIntegration {
    /// `prefix[i]` = `[Kr, Kg, Kb, T]` integrated from entry 0 to entry `i`, in units of entries (trapezoids of the
    /// table's linear pieces).
    prefix: Box<[Vec4]>,
    /// The table itself as `[σr, σg, σb, σ]` (for segments too short to divide by).
    point: Box<[Vec4]>,
}

impl PreIntegration {
    /// The integral functions of the extinction table `lut` ([`LUT_SIZE`] entries over normalised `[0, 1]`).
    pub fn new(lut: &[LutEntry]) -> PreIntegration {
        let point: Box<[Vec4]> = lut
            .iter()
            .map(|e| {
                let [r, g, b] = e.color;
                Vec4::new(r * e.sigma, g * e.sigma, b * e.sigma, e.sigma)
            })
            .collect();
        // Accumulated in f64: 4096 entries of sums would otherwise lose the small end's digits.
        let mut sum = [0f64; 4];
        let mut prefix = Vec::with_capacity(point.len());
        prefix.push(Vec4::ZERO);
        for pair in point.windows(2) {
            let (a, b) = (pair[0].to_array(), pair[1].to_array());
            for c in 0..4 {
                sum[c] += 0.5 * (a[c] as f64 + b[c] as f64);
            }
            prefix.push(Vec4::from_array(sum.map(|s| s as f32)));
        }
        PreIntegration { prefix: prefix.into_boxed_slice(), point }
    }

    /// Premultiplied `[r·α, g·α, b·α, α]` of a segment of `length` world units over which the normalised value
    /// runs linearly from `front` to `back`.
    #[inline(always)]
    pub fn segment(&self, front: f32, back: f32, length: f32) -> Vec4 {
        let last = (LUT_SIZE - 1) as f32;
        let xf = (front * last).clamp(0.0, last);
        let xb = (back * last).clamp(0.0, last);
        let span = xb - xf;
        // Mean extinction and extinction-weighted colour over the segment.
        let (mean_weighted, mean_sigma) = if span.abs() < CONSTANT_BELOW_ENTRIES {
            let p = interpolate(&self.point, 0.5 * (xf + xb));
            (p, p.w)
        } else {
            let difference = (interpolate(&self.prefix, xb) - interpolate(&self.prefix, xf)) / span;
            (difference, difference.w)
        };
        if mean_sigma <= 0.0 {
            return Vec4::ZERO;
        }
        let alpha = one_minus_exp_neg(mean_sigma * length);
        let colour = mean_weighted.truncate() * (alpha / mean_sigma);
        colour.extend(alpha)
    }
}

/// `table` at continuous position `x ∈ [0, LUT_SIZE − 1]`, linear between entries.
#[inline(always)]
fn interpolate(table: &[Vec4], x: f32) -> Vec4 {
    let (i, floor) = floor_index(x, LUT_SIZE as u32 - 2);
    let i = i as usize;
    let (a, b) = (table[i], table[i + 1]);
    a + (b - a) * (x - floor)
}

/// `1 − e^(−x)` for `x ≥ 0`, to within 2·10⁻⁶ (far below an 8-bit level; relative to the result for thin segments),
/// without a call: a series for thin segments (where `1 − exp` would cancel), else `2^y` split into exponent bits
/// and a polynomial in the fraction. Written by hand: it sits in the per-sample loop, where `expm1f` was a fifth of a pre-integrated
/// sample's time.
#[inline(always)]
pub fn one_minus_exp_neg(x: f32) -> f32 {
    if x < 0.125 {
        // x − x²/2 + x³/6 − x⁴/24 + x⁵/120 − x⁶/720: the next term is below x⁷/5040 < 10⁻⁹·x.
        x * (1.0 - x * (0.5 - x * (1.0 / 6.0 - x * (1.0 / 24.0 - x * (1.0 / 120.0 - x * (1.0 / 720.0))))))
    } else {
        1.0 - exp2_negative(-x * std::f32::consts::LOG2_E)
    }
}

/// `2^y` for `y ≤ 0` (0 below 2⁻¹²⁶): the integer part into the exponent bits, the fraction by its Taylor
/// polynomial of degree 7 (relative error below 1.4·10⁻⁶ on `[0, 1)`).
#[inline(always)]
fn exp2_negative(y: f32) -> f32 {
    if y < -126.0 {
        return 0.0;
    }
    let whole = y.floor();
    let f = y - whole;
    // The fitted polynomial's first coefficient is ln 2 to f32 precision (the Taylor term); kept as fitted.
    #[allow(clippy::approx_constant)]
    const C: [f32; 7] =
        [0.693_147_2, 0.240_226_5, 0.055_504_11, 0.009_618_129, 0.001_333_356, 1.540_353e-4, 1.525_273e-5];
    let p = 1.0 + f * (C[0] + f * (C[1] + f * (C[2] + f * (C[3] + f * (C[4] + f * (C[5] + f * C[6]))))));
    p * f32::from_bits(((whole as i32 + 127) as u32) << 23)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::transfer_function::{TransferFunction, TransferLut};

    fn table(points: Vec<[f64; 5]>) -> (TransferLut, PreIntegration) {
        let tf = TransferFunction::new(points, Some(1.0)).expect("valid");
        let lut = TransferLut::new(&tf, 0.0, 1.0, 1.0);
        let pre = PreIntegration::new(lut.entries());
        (lut, pre)
    }

    /// The segment by brute force: many point samples of the linear ramp, composited front to back.
    fn brute_force(lut: &TransferLut, front: f32, back: f32, length: f64) -> Vec4 {
        let n = 20_000;
        let dt = length / n as f64;
        let (mut colour, mut transmittance) = ([0f64; 3], 1f64);
        for k in 0..n {
            let s = front as f64 + (back - front) as f64 * (k as f64 + 0.5) / n as f64;
            let e = lut.lookup(s as f32);
            let alpha = 1.0 - (-(e.sigma as f64) * dt).exp();
            for c in 0..3 {
                colour[c] += transmittance * alpha * e.color[c] as f64;
            }
            transmittance *= 1.0 - alpha;
        }
        Vec4::new(colour[0] as f32, colour[1] as f32, colour[2] as f32, (1.0 - transmittance) as f32)
    }

    #[test]
    fn a_narrow_peak_between_two_samples_is_integrated_not_missed() {
        // Transparent except a 1%-wide opaque-ish peak at 0.5, crossed between two samples at 0.3 and 0.7.
        let (lut, pre) = table(vec![
            [0.0, 1.0, 0.5, 0.2, 0.0],
            [0.495, 1.0, 0.5, 0.2, 0.0],
            [0.5, 1.0, 0.5, 0.2, 0.9],
            [0.505, 1.0, 0.5, 0.2, 0.0],
            [1.0, 1.0, 0.5, 0.2, 0.0],
        ]);
        for (front, back) in [(0.3f32, 0.7f32), (0.7, 0.3)] {
            let got = pre.segment(front, back, 2.0);
            let want = brute_force(&lut, front, back, 2.0);
            assert!(got.w > 0.01, "the peak is seen: {got}");
            // Thin: self-attenuation inside the segment is negligible, so the formula is exact up to the table.
            assert!((got - want).abs().max_element() < 2e-4, "{front}->{back}: {got} against {want}");
        }
        // Point samples at either end see nothing.
        assert_eq!(lut.lookup(0.3).sigma, 0.0);
        assert_eq!(lut.lookup(0.7).sigma, 0.0);
    }

    #[test]
    fn a_constant_segment_is_the_point_samples_opacity_and_colour() {
        let (lut, pre) = table(vec![[0.0, 0.2, 0.4, 0.8, 0.1], [1.0, 0.9, 0.3, 0.1, 0.8]]);
        for value in [0.0f32, 0.25, 0.6, 1.0] {
            for length in [0.01f32, 0.5, 3.0] {
                let e = lut.lookup(value);
                let alpha = 1.0 - (-(e.sigma as f64) * length as f64).exp();
                let want = Vec4::new(e.color[0], e.color[1], e.color[2], 1.0) * alpha as f32;
                let got = pre.segment(value, value, length);
                assert!((got - want).abs().max_element() < 1e-5, "{value} over {length}: {got} against {want}");
                // A hair apart (the divided branch): the same within the table's rounding.
                let near = pre.segment(value.min(0.999), value.min(0.999) + 1e-3, length);
                let e = lut.lookup(value.min(0.999) + 5e-4);
                let alpha = 1.0 - (-(e.sigma as f64) * length as f64).exp();
                assert!((near.w - alpha as f32).abs() < 1e-4, "{value} over {length}: {} against {alpha}", near.w);
            }
        }
    }

    #[test]
    fn segments_compose_like_the_brute_force_integral_on_ramps() {
        // A ramp of opacity and colour: the mean-colour formula's only error is self-attenuation within a
        // segment, which is second order in its optical depth.
        let (lut, pre) = table(vec![[0.0, 1.0, 0.0, 0.0, 0.0], [0.4, 0.0, 1.0, 0.0, 0.3], [1.0, 0.0, 0.0, 1.0, 0.6]]);
        for (front, back, length) in [(0.1f32, 0.9f32, 0.5f64), (0.9, 0.2, 0.25), (0.35, 0.45, 1.0)] {
            let got = pre.segment(front, back, length as f32);
            let want = brute_force(&lut, front, back, length);
            assert!((got.w - want.w).abs() < 1e-4, "opacity {front}->{back}: {got} against {want}");
            assert!((got - want).abs().max_element() < 0.02 * want.w.max(1e-3), "{front}->{back}: {got} vs {want}");
        }
    }

    #[test]
    fn one_minus_exp_neg_is_within_its_stated_error_everywhere() {
        let mut worst = 0f64;
        let mut x = 0f32;
        while x < 200.0 {
            let want = -(-(x as f64)).exp_m1();
            let got = one_minus_exp_neg(x) as f64;
            let error = (got - want).abs();
            let thin = x < 0.125;
            assert!(error <= 2e-6 && (!thin || error <= 1e-6 * want), "{x}: {got} against {want}");
            worst = worst.max(error);
            x = if x < 1e-3 { x + 1e-6 } else { x * 1.0007 + 1e-6 };
        }
        assert!(worst > 0.0, "the approximation was compared");
    }
}
