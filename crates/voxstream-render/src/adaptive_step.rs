//! The error-bounded adaptive step: each brick segment's step chosen from how much the transfer function varies over
//! the brick's value range, so that smooth regions take steps of several voxels while sharp features keep fine ones
//! (issue 46; the brick-level choice of Reichl's traverser, seed 004 §5.6, with the bound below).
//!
//! The bound. A midpoint sum with step `h` of the optical depth `∫σ(v(t)) dt` along a stretch where the field `v`
//! is monotone errs by at most `h · V`, where `V` is the total variation of `σ` over the values the stretch crosses
//! (each step's error is at most `h` times the variation of `σ` over that step's values, and the steps' value
//! intervals do not overlap). The same holds for the emitted colour with `σ·c`. Every value of a brick lies in its
//! range `[lo, hi]`, so `V ≤ TV(lo, hi)`, the variation of the table between the two. A step of at most
//! `tolerance / TV(lo, hi)` keeps the error of each monotone stretch of a ray within `tolerance` (optical depth, or
//! premultiplied colour), whatever the field does inside the brick. The step never drops below the fixed step (the
//! cone's footprint times `--step`), and never grows past [`MAX_STEP_GROWTH`] times it: the bound says nothing of
//! what a trilinear field does between samples several voxels apart, and the cap keeps the field itself resolved.
//!
//! `TV(lo, hi)` is a difference of two prefix sums over the table: one subtraction per brick segment.

use crate::transfer_function::{LutEntry, LUT_SIZE};

/// The longest adaptive step, in fixed steps.
pub const MAX_STEP_GROWTH: f64 = 4.0;

/// The default tolerance: optical depth (and premultiplied colour) per monotone stretch of a ray.
pub const DEFAULT_TOLERANCE: f64 = 0.05;

/// Prefix sums of the table's variation.
#[derive(Clone, Debug)]
pub struct StepVariation {
    /// `before[i]`: the variation between entries 0 and `i`, the largest of `σ`'s and of each `σ·c`'s.
    before: Box<[f64]>,
}

impl StepVariation {
    /// The variation sums of the extinction table `lut` ([`LUT_SIZE`] entries over normalised `[0, 1]`).
    pub fn new(lut: &[LutEntry]) -> StepVariation {
        let weighted = |e: &LutEntry| {
            let [r, g, b] = e.color;
            [e.sigma as f64, (r * e.sigma) as f64, (g * e.sigma) as f64, (b * e.sigma) as f64]
        };
        let mut before = Vec::with_capacity(lut.len());
        let mut sum = 0.0;
        before.push(0.0);
        for pair in lut.windows(2) {
            let (a, b) = (weighted(&pair[0]), weighted(&pair[1]));
            sum += (0..4).map(|c| (b[c] - a[c]).abs()).fold(0.0, f64::max);
            before.push(sum);
        }
        StepVariation { before: before.into_boxed_slice() }
    }

    /// The prefix sums themselves, one per table entry (what a GPU uploads).
    pub fn prefix(&self) -> &[f64] {
        &self.before
    }

    /// The table's variation (per world unit) over the normalised values `[lower, upper]`, widened to whole entries.
    #[inline]
    pub fn over(&self, lower: f32, upper: f32) -> f64 {
        let last = (LUT_SIZE - 1) as f32;
        // NaN goes to the whole table (conservative).
        let a = (lower * last).floor().clamp(0.0, last);
        let b = (upper * last).ceil().clamp(0.0, last);
        let (a, b) = if a <= b { (a as usize, b as usize) } else { (0, LUT_SIZE - 1) };
        self.before[b] - self.before[a]
    }

    /// The step for a brick whose normalised values lie in `[lower, upper]`: `tolerance / TV`, within `[base,
    /// MAX_STEP_GROWTH · base]` (world units of `t`, as `base`).
    #[inline]
    pub fn step(&self, lower: f32, upper: f32, base: f64, tolerance: f64) -> f64 {
        let variation = self.over(lower, upper);
        let longest = MAX_STEP_GROWTH * base;
        if variation * longest <= tolerance {
            longest
        } else {
            (tolerance / variation).max(base)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::transfer_function::{TransferFunction, TransferLut};

    fn variation(points: Vec<[f64; 5]>) -> (TransferLut, StepVariation) {
        let tf = TransferFunction::new(points, Some(1.0)).expect("valid");
        let lut = TransferLut::new(&tf, 0.0, 1.0, 1.0);
        let v = StepVariation::new(lut.entries());
        (lut, v)
    }

    #[test]
    fn flat_ranges_take_the_longest_step_and_sharp_ones_the_fixed_step() {
        // Constant below 0.5, a steep ramp 0.5..0.52, constant above.
        let (lut, v) =
            variation(vec![[0.0, 1.0, 1.0, 1.0, 0.1], [0.5, 1.0, 1.0, 1.0, 0.1], [0.52, 1.0, 1.0, 1.0, 0.9]]);
        let base = 0.25;
        assert_eq!(v.step(0.1, 0.45, base, 0.05), MAX_STEP_GROWTH * base);
        assert_eq!(v.step(0.6, 0.9, base, 0.05), MAX_STEP_GROWTH * base);
        assert_eq!(v.step(0.4, 0.6, base, 0.05), base, "crossing the ramp");
        // The variation across the ramp is σ's jump (colour white: σ·c varies as σ).
        let jump = (lut.lookup(0.6).sigma - lut.lookup(0.4).sigma) as f64;
        assert!((v.over(0.4, 0.6) - jump).abs() < 1e-4 * jump, "{} against {jump}", v.over(0.4, 0.6));
        // In between: the bound's own step.
        let tolerance = jump * 0.5;
        assert!((v.step(0.4, 0.6, base, tolerance) - 0.5).abs() < 1e-3);
    }

    #[test]
    fn the_bound_holds_for_a_monotone_stretch_of_any_shape() {
        // A wiggly transfer function; a monotone field crossing [lo, hi] in some nonlinear way: the midpoint sum at the
        // adaptive step errs by at most the tolerance.
        let points: Vec<[f64; 5]> = (0..=20)
            .map(|i| {
                let x = i as f64 / 20.0;
                [x, 1.0, 1.0, 1.0, 0.3 + 0.25 * (x * 31.0).sin()]
            })
            .collect();
        let (lut, v) = variation(points);
        let (lower, upper) = (0.2f32, 0.7f32);
        let tolerance = 0.05;
        let step = v.step(lower, upper, 1e-3, tolerance);
        let field = |t: f64| lower as f64 + (upper - lower) as f64 * (t / 3.0).powf(1.7);
        let exact: f64 = {
            let n = 300_000;
            (0..n)
                .map(|k| lut.lookup(field((k as f64 + 0.5) * 3.0 / n as f64) as f32).sigma as f64 * 3.0 / n as f64)
                .sum()
        };
        let samples = (3.0 / step).floor() as usize;
        let mut sum: f64 =
            (0..samples).map(|k| lut.lookup(field((k as f64 + 0.5) * step) as f32).sigma as f64 * step).sum();
        // The remainder of the stretch, as the traversal's last sample covers it.
        let rest = 3.0 - samples as f64 * step;
        sum += lut.lookup(field(3.0 - 0.5 * rest) as f32).sigma as f64 * rest;
        assert!((sum - exact).abs() <= tolerance, "error {} at step {step}", (sum - exact).abs());
        assert!(step > 1e-3, "the step grew: {step}");
    }

    #[test]
    fn nan_and_reversed_ranges_read_the_whole_table() {
        let (_, v) = variation(vec![[0.0, 1.0, 1.0, 1.0, 0.0], [1.0, 1.0, 1.0, 1.0, 0.5]]);
        let whole = v.over(0.0, 1.0);
        assert_eq!(v.over(f32::NAN, 0.5), whole);
        assert_eq!(v.over(0.8, 0.2), whole);
    }
}
