//! The 1-D transfer function: value → colour and opacity, piecewise linear, with VTK's opacity convention.
//!
//! File format (JSON): `{"points": [[value, r, g, b, alpha], ...], "unit_distance": 0.01}`. Values must increase.
//! `alpha` is the opacity accumulated over `unit_distance` world units (VTK's `ScalarOpacityUnitDistance`); when the
//! key is absent it defaults to one finest voxel of the scene. Colours are linear and composited without gamma.
//!
//! For rendering, the function is tabulated as colour and extinction `σ = −ln(1 − alpha) / unit_distance`, so the
//! opacity of any step `Δt` is `1 − exp(−σ·Δt)` (the opacity correction of GigaVoxels [P09] §6 / [R08] §5).

use std::sync::OnceLock;

use serde::Deserialize;

use crate::adaptive_step::StepVariation;
use crate::preintegration::PreIntegration;

use crate::error::RenderError;
use crate::sampler::floor_index;
use crate::step_table::{StepLength, StepTable, StepTables};

/// A parsed, validated transfer function.
#[derive(Clone, Debug, PartialEq)]
pub struct TransferFunction {
    /// Control points `[value, r, g, b, alpha]`, values strictly increasing.
    pub points: Vec<[f64; 5]>,
    /// World distance over which `alpha` is reached; `None` = one finest voxel.
    pub unit_distance: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TransferFunctionFile {
    points: Vec<Vec<f64>>,
    #[serde(default)]
    unit_distance: Option<f64>,
}

/// Largest opacity kept finite when converted to extinction.
const MAX_ALPHA: f64 = 1.0 - 1e-6;

impl TransferFunction {
    /// Builds and validates a transfer function.
    pub fn new(points: Vec<[f64; 5]>, unit_distance: Option<f64>) -> Result<TransferFunction, RenderError> {
        let bad = |m: String| Err(RenderError::InvalidTransferFunction(m));
        if points.is_empty() {
            return bad("no points".into());
        }
        for (i, p) in points.iter().enumerate() {
            if p.iter().any(|v| !v.is_finite()) {
                return bad(format!("point {i} has a non-finite number"));
            }
            if p[1..].iter().any(|v| !(0.0..=1.0).contains(v)) {
                return bad(format!("point {i}: r, g, b and alpha must be in [0, 1]"));
            }
        }
        if let Some(i) = points.windows(2).position(|w| w[1][0] <= w[0][0]) {
            return bad(format!(
                "values must increase strictly: point {} ({}) follows {}",
                i + 1,
                points[i + 1][0],
                points[i][0]
            ));
        }
        if let Some(u) = unit_distance {
            if !(u.is_finite() && u > 0.0) {
                return bad(format!("unit_distance must be a positive number, got {u}"));
            }
        }
        Ok(TransferFunction { points, unit_distance })
    }

    /// Parses the JSON format described in the module docs.
    pub fn from_json(text: &str) -> Result<TransferFunction, RenderError> {
        let file: TransferFunctionFile = serde_json::from_str(text)
            .map_err(|e| RenderError::InvalidTransferFunction(format!("malformed JSON: {e}")))?;
        let mut points = Vec::with_capacity(file.points.len());
        for (i, p) in file.points.iter().enumerate() {
            let Ok(array) = <[f64; 5]>::try_from(p.as_slice()) else {
                return Err(RenderError::InvalidTransferFunction(format!(
                    "point {i} has {} numbers, expected 5 (value, r, g, b, alpha)",
                    p.len()
                )));
            };
            points.push(array);
        }
        TransferFunction::new(points, file.unit_distance)
    }

    /// Parses either this crate's JSON format or a ParaView colour-map preset (rescaled onto `value_range`, see
    /// [`crate::paraview_colormap`]).
    pub fn from_json_or_paraview(text: &str, value_range: [f64; 2]) -> Result<TransferFunction, RenderError> {
        let looks_like_paraview = serde_json::from_str::<serde_json::Value>(text).is_ok_and(|value| match &value {
            serde_json::Value::Object(object) => object.contains_key("RGBPoints"),
            serde_json::Value::Array(list) => list.iter().any(|v| v.get("RGBPoints").is_some()),
            _ => false,
        });
        if looks_like_paraview {
            crate::paraview_colormap::from_paraview_json(text, value_range)
        } else {
            TransferFunction::from_json(text)
        }
    }

    /// `[r, g, b, alpha]` at `value`, linear between points, clamped outside; NaN maps as the first point.
    pub fn evaluate(&self, value: f64) -> [f64; 4] {
        let first = &self.points[0];
        let last = &self.points[self.points.len() - 1];
        let pick = |p: &[f64; 5]| [p[1], p[2], p[3], p[4]];
        if value.is_nan() || value <= first[0] {
            return pick(first);
        }
        if value >= last[0] {
            return pick(last);
        }
        let i = self.points.partition_point(|p| p[0] <= value);
        let (a, b) = (&self.points[i - 1], &self.points[i]);
        let f = (value - a[0]) / (b[0] - a[0]);
        std::array::from_fn(|c| a[c + 1] + (b[c + 1] - a[c + 1]) * f)
    }
}

/// One entry of the tabulated transfer function.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LutEntry {
    /// Linear colour.
    pub color: [f32; 3],
    /// Extinction per world unit.
    pub sigma: f32,
}

/// The transfer function tabulated over the data's value range `[lower, upper]` for the per-sample loop; lookups take
/// normalised values (`0` = `lower`, `1` = `upper`), which is what bricks hold.
#[derive(Clone, Debug)]
pub struct TransferLut {
    entries: Vec<LutEntry>,
    /// `visible_before[i]`: entries with non-zero extinction among `entries[..i]` (O(1) range queries).
    visible_before: Vec<u32>,
    lower: f32,
    scale: f32,
    /// The data values that normalised 0 and 1 stand for.
    data_range: [f64; 2],
    /// The same table pre-corrected for each ray-march step used so far.
    step_tables: StepTables,
    /// Its integral functions, for pre-integrated segments (built on first use).
    preintegration: OnceLock<PreIntegration>,
    /// Its variation sums, for the adaptive step (built on first use).
    variation: OnceLock<StepVariation>,
}

/// Entries in the table.
pub const LUT_SIZE: usize = 4096;

impl TransferLut {
    /// Tabulates `tf` over data values `[lower, upper]`; `default_unit_distance` applies when the function names none.
    pub fn new(tf: &TransferFunction, lower: f32, upper: f32, default_unit_distance: f64) -> TransferLut {
        let unit = tf.unit_distance.unwrap_or(default_unit_distance);
        let entries: Vec<LutEntry> = (0..LUT_SIZE)
            .map(|i| {
                let value = lower as f64 + (upper - lower) as f64 * i as f64 / (LUT_SIZE - 1) as f64;
                let [r, g, b, alpha] = tf.evaluate(value);
                let sigma = -(1.0 - alpha.min(MAX_ALPHA)).ln() / unit;
                LutEntry { color: [r as f32, g as f32, b as f32], sigma: sigma as f32 }
            })
            .collect();
        let mut visible_before = Vec::with_capacity(LUT_SIZE + 1);
        visible_before.push(0u32);
        for entry in entries.iter() {
            let entry: &LutEntry = entry;
            let last = *visible_before.last().unwrap_or(&0);
            visible_before.push(last + (entry.sigma > 0.0) as u32);
        }
        TransferLut {
            entries,
            visible_before,
            lower: 0.0,
            scale: (LUT_SIZE - 1) as f32,
            data_range: [lower as f64, upper as f64],
            step_tables: StepTables::default(),
            preintegration: OnceLock::new(),
            variation: OnceLock::new(),
        }
    }

    /// The normalised value (what bricks hold) of data value `value`: 0 at the data's lower bound, 1 at its upper;
    /// 0 for a data range of zero width.
    pub fn normalise(&self, value: f64) -> f64 {
        let [lower, upper] = self.data_range;
        if upper > lower {
            (value - lower) / (upper - lower)
        } else {
            0.0
        }
    }

    /// The table of premultiplied colour and opacity for steps of `step` (built on first use, then shared).
    #[inline]
    pub fn step_table(&self, step: StepLength) -> &StepTable {
        self.step_tables.get(&self.entries, step)
    }

    /// The integral functions for pre-integrated segments ([`crate::preintegration`]; built on first use).
    #[inline]
    pub fn preintegration(&self) -> &PreIntegration {
        self.preintegration.get_or_init(|| PreIntegration::new(&self.entries))
    }

    /// The variation sums for the adaptive step ([`crate::adaptive_step`]; built on first use).
    #[inline]
    pub fn variation(&self) -> &StepVariation {
        self.variation.get_or_init(|| StepVariation::new(&self.entries))
    }

    /// The [`LUT_SIZE`] entries, evenly spaced over the normalised values `[0, 1]` (what a GPU uploads).
    pub fn entries(&self) -> &[LutEntry] {
        &self.entries
    }

    /// Colour and extinction at normalised `value` (linear between entries).
    #[inline(always)]
    pub fn lookup(&self, value: f32) -> LutEntry {
        let x = ((value - self.lower) * self.scale).clamp(0.0, (LUT_SIZE - 1) as f32);
        let i = (x as usize).min(LUT_SIZE - 2);
        let f = x - i as f32;
        let (a, b) = (self.entries[i], self.entries[i + 1]);
        LutEntry {
            color: std::array::from_fn(|c| a.color[c] + (b.color[c] - a.color[c]) * f),
            sigma: a.sigma + (b.sigma - a.sigma) * f,
        }
    }

    /// Whether some normalised value in `[lower, upper]` has non-zero extinction (conservative, for empty-space
    /// skipping).
    #[inline(always)]
    pub fn is_visible_in(&self, lower: f32, upper: f32) -> bool {
        // `lookup` reads entries ⌊x⌋ and ⌊x⌋+1, the latter with weight x − ⌊x⌋. A constant range is sampled exactly
        // (interpolating equal values returns them); otherwise allow samples a rounding error outside the range.
        let slack = if lower == upper { 0.0 } else { 1e-3 };
        // Float operations only (see `floor_index`); NaN goes to the whole table (conservative).
        let (a, _) = floor_index((self.entry_position(lower) - slack).max(0.0), LUT_SIZE as u32 - 1);
        let (b, _) = floor_index((self.entry_position(upper) + slack).ceil(), LUT_SIZE as u32 - 1);
        let (a, b) = (a as usize, b as usize);
        self.visible_before[b + 1] > self.visible_before[a]
    }

    /// The continuous table position of a normalised value, clamped to the table.
    #[inline(always)]
    fn entry_position(&self, value: f32) -> f32 {
        ((value - self.lower) * self.scale).clamp(0.0, (LUT_SIZE - 1) as f32)
    }

    /// Whether every entry that a normalised value in `[lower, upper]` reads has non-zero extinction. Then
    /// [`TransferLut::is_visible_in`] holds for every range inside `[lower, upper]`: the entries such a range reads
    /// (a superset, widened by its slack) always overlap these.
    #[inline(always)]
    pub fn is_visible_throughout(&self, lower: f32, upper: f32) -> bool {
        let (first, _) = floor_index(self.entry_position(lower).max(0.0), LUT_SIZE as u32 - 1);
        let (last, _) = floor_index(self.entry_position(upper).ceil().max(0.0), LUT_SIZE as u32 - 1);
        let (first, last) = (first as usize, last as usize);
        first <= last && (self.visible_before[last + 1] - self.visible_before[first]) as usize == last + 1 - first
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn visible_throughout_a_range_means_visible_in_every_range_inside_it() {
        // Invisible below 0.3 and in a notch around 0.6; values far outside the table's range too.
        let tf = TransferFunction::new(
            vec![
                [0.0, 1.0, 1.0, 1.0, 0.0],
                [0.3, 1.0, 1.0, 1.0, 0.0],
                [0.31, 1.0, 1.0, 1.0, 0.5],
                [0.59, 1.0, 1.0, 1.0, 0.5],
                [0.6, 1.0, 1.0, 1.0, 0.0],
                [0.61, 1.0, 1.0, 1.0, 0.5],
                [1.0, 1.0, 1.0, 1.0, 0.5],
            ],
            Some(1.0),
        )
        .expect("valid function");
        let lut = TransferLut::new(&tf, 0.0, 1.0, 1.0);
        assert!(lut.is_visible_throughout(0.35, 0.55));
        assert!(!lut.is_visible_throughout(0.35, 0.65), "the notch");
        assert!(!lut.is_visible_throughout(0.1, 0.2));
        let grid: Vec<f32> = (0..=200).map(|i| i as f32 / 200.0).collect();
        let mut throughout = 0;
        for (i, &lower) in grid.iter().enumerate() {
            for &upper in &grid[i..] {
                if !lut.is_visible_throughout(lower, upper) {
                    continue;
                }
                throughout += 1;
                for (k, &a) in grid.iter().enumerate().filter(|&(_, &a)| a >= lower && a <= upper) {
                    for &b in grid[k..].iter().filter(|&&b| b <= upper) {
                        assert!(lut.is_visible_in(a, b), "[{a}, {b}] inside [{lower}, {upper}]");
                    }
                }
            }
        }
        assert!(throughout > 100, "only {throughout} ranges visible throughout");
    }

    #[test]
    fn parses_and_interpolates() {
        let tf = TransferFunction::from_json(r#"{"points": [[0, 0,0,0, 0], [1, 1,0.5,0, 0.5]], "unit_distance": 2}"#)
            .unwrap();
        assert_eq!(tf.evaluate(0.5), [0.5, 0.25, 0.0, 0.25]);
        assert_eq!(tf.evaluate(-3.0), [0.0; 4]);
        assert_eq!(tf.evaluate(f64::NAN), [0.0; 4]);
        let lut = TransferLut::new(&tf, 0.0, 1.0, 1.0);
        let e = lut.lookup(1.0);
        // alpha 0.5 over 2 units: sigma = ln 2 / 2.
        assert!((e.sigma as f64 - std::f64::consts::LN_2 / 2.0).abs() < 1e-6);
        assert!(lut.is_visible_in(0.0, 0.01));
        // A block of zeros is invisible when the opacity only starts rising at zero (a fog's transfer function).
        assert!(!lut.is_visible_in(0.0, 0.0));
        assert!(lut.is_visible_in(0.0, 1e-6));
        let gated = TransferFunction::new(
            vec![[0.0, 0.0, 0.0, 0.0, 0.0], [0.5, 0.0, 0.0, 0.0, 0.0], [1.0, 1.0, 1.0, 1.0, 1.0]],
            None,
        )
        .unwrap();
        let lut = TransferLut::new(&gated, 0.0, 1.0, 1.0);
        assert!(!lut.is_visible_in(0.0, 0.45));
        assert!(lut.is_visible_in(0.3, 0.6));
        // Data range 100..300: normalised 0.5 is the value 200.
        let ranged =
            TransferFunction::new(vec![[100.0, 0.0, 0.0, 0.0, 0.0], [300.0, 1.0, 1.0, 1.0, 0.5]], Some(1.0)).unwrap();
        let lut = TransferLut::new(&ranged, 100.0, 300.0, 1.0);
        assert!((lut.lookup(0.5).color[0] - 0.5).abs() < 1e-3);
    }

    #[test]
    fn invisible_ranges_hold_no_visible_sample() {
        let tf = TransferFunction::new(
            vec![
                [0.0, 1.0, 1.0, 1.0, 0.0],
                [0.3, 1.0, 1.0, 1.0, 0.0],
                [0.31, 1.0, 1.0, 1.0, 0.2],
                [1.0, 1.0, 1.0, 1.0, 0.0],
            ],
            Some(1.0),
        )
        .unwrap();
        let lut = TransferLut::new(&tf, 0.0, 1.0, 1.0);
        let mut state = 12345u64;
        let mut random = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut invisible = 0;
        for _ in 0..20000 {
            let (a, b) = (random(), random());
            let (lo, hi) = if random() < 0.2 { (a, a) } else { (a.min(b), a.max(b)) };
            if lut.is_visible_in(lo, hi) {
                continue;
            }
            invisible += 1;
            for i in 0..=16 {
                // Interpolated samples, as trilinear filtering computes them.
                let v = lo + (hi - lo) * (i as f32 / 16.0);
                assert_eq!(lut.lookup(v).sigma, 0.0, "value {v} in the invisible range [{lo}, {hi}]");
            }
        }
        assert!(invisible > 1000);
    }

    #[test]
    fn rejects_bad_functions() {
        for text in [
            "not json",
            r#"{"points": []}"#,
            r#"{"points": [[0, 0, 0, 0]]}"#,
            r#"{"points": [[0.5, 0,0,0,0], [0.2, 1,1,1,1]]}"#,
            r#"{"points": [[0.5, 0,0,0,0], [0.5, 1,1,1,1]]}"#,
            r#"{"points": [[0, 0,0,0, 2]]}"#,
            r#"{"points": [[0, 0,0,0, 1]], "unit_distance": 0}"#,
            r#"{"points": [[0, 0,0,0, 1]], "colour": 1}"#,
        ] {
            assert!(TransferFunction::from_json(text).is_err(), "accepted {text}");
        }
    }
}
