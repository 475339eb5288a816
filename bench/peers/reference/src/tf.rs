//! Transfer function: piecewise-linear colour and opacity in the scalar value, VTK-style. Opacity `alpha` is the
//! opacity accumulated over `unit_distance` world units, converted to an extinction coefficient only after
//! interpolation. Also answers "can alpha be non-zero anywhere on [lo, hi]?" for the empty-space skip, exactly
//! in the sense that a `false` answer guarantees `alpha(v) == 0.0` for every `v` in the range.

use anyhow::{bail, Result};

/// Alpha is clamped below 1 so the extinction stays finite.
const MAX_ALPHA: f64 = 1.0 - 1e-6;

#[derive(Debug, Clone)]
pub struct TransferFunction {
    values: Vec<f64>,
    rgba: Vec<[f64; 4]>,
    unit_distance: f64,
}

impl TransferFunction {
    /// `points` are `[value, r, g, b, alpha]`, strictly increasing in value.
    pub fn new(points: &[[f64; 5]], unit_distance: f64) -> Result<Self> {
        if points.is_empty() {
            bail!("tf.points must not be empty");
        }
        if !(unit_distance.is_finite() && unit_distance > 0.0) {
            bail!("tf.unit_distance must be finite and > 0 (got {unit_distance})");
        }
        for (i, p) in points.iter().enumerate() {
            if !p.iter().all(|x| x.is_finite()) {
                bail!("tf.points[{i}] has a non-finite entry");
            }
            if p[1..].iter().any(|&x| !(0.0..=1.0).contains(&x)) {
                bail!("tf.points[{i}]: r, g, b and alpha must be in [0, 1]");
            }
            if i > 0 && p[0] <= points[i - 1][0] {
                bail!(
                    "tf.points must be strictly increasing in value (point {i}: {} after {})",
                    p[0],
                    points[i - 1][0]
                );
            }
        }
        Ok(TransferFunction {
            values: points.iter().map(|p| p[0]).collect(),
            rgba: points.iter().map(|p| [p[1], p[2], p[3], p[4]]).collect(),
            unit_distance,
        })
    }

    /// Piecewise-linear `[r, g, b, alpha]` at `v`, clamped to the end points outside their range.
    #[inline]
    pub fn rgba(&self, v: f64) -> [f64; 4] {
        let n = self.values.len();
        if v.is_nan() || v <= self.values[0] {
            return self.rgba[0];
        }
        if v >= self.values[n - 1] {
            return self.rgba[n - 1];
        }
        // values[k] <= v < values[k + 1]
        let k = self.values.partition_point(|&x| x <= v).saturating_sub(1).min(n - 2);
        let t = (v - self.values[k]) / (self.values[k + 1] - self.values[k]);
        let (a, b) = (self.rgba[k], self.rgba[k + 1]);
        [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), a[2] + t * (b[2] - a[2]), a[3] + t * (b[3] - a[3])]
    }

    #[inline]
    pub fn alpha(&self, v: f64) -> f64 {
        self.rgba(v)[3]
    }

    /// Extinction per world unit for an (already interpolated) alpha.
    #[inline]
    pub fn sigma_from_alpha(&self, alpha: f64) -> f64 {
        -(1.0 - alpha.min(MAX_ALPHA)).ln() / self.unit_distance
    }

    /// Extinction per world unit at `v`: alpha interpolated first, then converted.
    #[cfg(test)]
    pub fn sigma(&self, v: f64) -> f64 {
        self.sigma_from_alpha(self.alpha(v))
    }

    /// `false` only if `alpha(v) == 0.0` for every `v` in `[lo, hi]` (as computed by [`Self::alpha`]).
    ///
    /// Conservative version of "max of alpha over the control points inside the range and at the interpolated
    /// end points": a segment with a non-zero end point that overlaps the range in more than one point is
    /// treated as non-zero there (its interpolant is positive on its interior), and a single-point contact is
    /// decided by evaluating alpha at that point, so no rounding can make a skipped sample visible.
    pub fn may_be_visible(&self, lo: f64, hi: f64) -> bool {
        let n = self.values.len();
        let a = |k: usize| self.rgba[k][3];
        if lo <= self.values[0] && a(0) > 0.0 {
            return true;
        }
        if hi >= self.values[n - 1] && a(n - 1) > 0.0 {
            return true;
        }
        for k in 0..n.saturating_sub(1) {
            let s_lo = lo.max(self.values[k]);
            let s_hi = hi.min(self.values[k + 1]);
            if s_lo > s_hi || (a(k) == 0.0 && a(k + 1) == 0.0) {
                continue;
            }
            if s_lo < s_hi || self.alpha(s_lo) > 0.0 {
                return true;
            }
        }
        false
    }
}
