//! ParaView colour-map presets as transfer functions, so that the maps users already have (ParaView's "Export
//! preset", or the presets shipped in its `ColorMaps.json`) load in `voxstream render --tf` and in the viewer.
//!
//! A preset is `{"Name": …, "RGBPoints": [x, r, g, b, x, r, g, b, …], "Points": [x, opacity, midpoint, sharpness,
//! …]}` (or a list of them; the first with `RGBPoints` is used). As ParaView does when a preset is applied, the map's
//! x range is rescaled onto the data's value range. `Points` (ParaView's opacity function) is rescaled the same way;
//! its midpoint and sharpness are ignored (linear between points). Without `Points`, opacity ramps linearly from 0
//! to [`DEFAULT_RAMP_OPACITY`] per unit distance (one finest voxel by default: ParaView's ramp to 1 would make any
//! thick volume opaque at once).

use serde_json::Value;

use crate::error::RenderError;
use crate::transfer_function::TransferFunction;

/// Opacity at the top of the value range when the preset has no opacity points.
pub const DEFAULT_RAMP_OPACITY: f64 = 0.1;

/// Most control points accepted from a preset.
pub const MAX_PRESET_POINTS: usize = 4096;

fn invalid(message: impl Into<String>) -> RenderError {
    RenderError::InvalidTransferFunction(message.into())
}

/// Parses a ParaView colour-map preset onto `value_range` (data values).
pub fn from_paraview_json(text: &str, value_range: [f64; 2]) -> Result<TransferFunction, RenderError> {
    let value: Value = serde_json::from_str(text).map_err(|e| invalid(format!("malformed JSON: {e}")))?;
    let preset = find_preset(&value).ok_or_else(|| invalid("no ParaView preset with \"RGBPoints\" found"))?;
    let colours = numbers(preset.get("RGBPoints"), "RGBPoints", 4)?;
    if colours.len() < 2 {
        return Err(invalid("RGBPoints needs at least two points (x, r, g, b each)"));
    }
    let opacities = match preset.get("Points") {
        Some(points) => Some(numbers(Some(points), "Points", 4)?),
        None => None,
    };
    let (x0, x1) = (colours[0][0], colours[colours.len() - 1][0]);
    if x1 <= x0 {
        return Err(invalid(format!("RGBPoints spans no range: first x {x0}, last x {x1}")));
    }
    let [lo, hi] = value_range;
    let (lo, hi) = if hi > lo && lo.is_finite() && hi.is_finite() { (lo, hi) } else { (0.0, 1.0) };
    if !(x1 - x0).is_finite() {
        return Err(invalid(format!("RGBPoints spans too wide a range: first x {x0}, last x {x1}")));
    }
    let rescale = |x: f64| lo + (x - x0) / (x1 - x0) * (hi - lo);
    let colour_points: Vec<(f64, [f64; 3])> = colours.iter().map(|p| (rescale(p[0]), [p[1], p[2], p[3]])).collect();
    let opacity_points: Vec<(f64, [f64; 1])> = match &opacities {
        Some(points) if !points.is_empty() => points.iter().map(|p| (rescale(p[0]), [p[1]])).collect(),
        _ => vec![(lo, [0.0]), (hi, [DEFAULT_RAMP_OPACITY])],
    };
    let mut xs: Vec<f64> = colour_points.iter().map(|p| p.0).chain(opacity_points.iter().map(|p| p.0)).collect();
    if xs.iter().any(|x| !x.is_finite()) {
        return Err(invalid("the points cannot be rescaled onto the data's range (x values too far apart)"));
    }
    xs.sort_by(f64::total_cmp);
    let tolerance = (hi - lo) * 1e-12;
    xs.dedup_by(|b, a| (*b - *a).abs() <= tolerance);
    if xs.len() > MAX_PRESET_POINTS {
        return Err(invalid(format!("{} control points; at most {MAX_PRESET_POINTS} are accepted", xs.len())));
    }
    let points = xs
        .iter()
        .map(|&x| {
            let [r, g, b] = piecewise_linear(&colour_points, x);
            let [alpha] = piecewise_linear(&opacity_points, x);
            [x, r.clamp(0.0, 1.0), g.clamp(0.0, 1.0), b.clamp(0.0, 1.0), alpha.clamp(0.0, 1.0)]
        })
        .collect();
    TransferFunction::new(points, None)
}

/// The first preset object with `RGBPoints`, in a list or alone.
fn find_preset(value: &Value) -> Option<&serde_json::Map<String, Value>> {
    match value {
        Value::Object(object) if object.contains_key("RGBPoints") => Some(object),
        Value::Array(list) => list.iter().find_map(|v| v.as_object().filter(|o| o.contains_key("RGBPoints"))),
        _ => None,
    }
}

/// A flat list of finite numbers cut into groups of `group`, x non-decreasing.
fn numbers(value: Option<&Value>, name: &str, group: usize) -> Result<Vec<Vec<f64>>, RenderError> {
    let list = value.and_then(Value::as_array).ok_or_else(|| invalid(format!("{name} must be a list of numbers")))?;
    if list.len() % group != 0 {
        return Err(invalid(format!("{name} holds {} numbers, not a multiple of {group}", list.len())));
    }
    if list.len() / group > MAX_PRESET_POINTS {
        return Err(invalid(format!("{name} holds {} points; at most {MAX_PRESET_POINTS}", list.len() / group)));
    }
    let flat: Vec<f64> = list
        .iter()
        .enumerate()
        .map(|(i, v)| {
            v.as_f64().filter(|f| f.is_finite()).ok_or_else(|| invalid(format!("{name}[{i}] is not a finite number")))
        })
        .collect::<Result<_, _>>()?;
    let groups: Vec<Vec<f64>> = flat.chunks(group).map(<[f64]>::to_vec).collect();
    if let Some(i) = groups.windows(2).position(|w| w[1][0] < w[0][0]) {
        return Err(invalid(format!(
            "{name}: x must not decrease (point {} at {} follows {})",
            i + 1,
            groups[i + 1][0],
            groups[i][0]
        )));
    }
    Ok(groups)
}

/// Linear between the points (x non-decreasing), clamped outside.
fn piecewise_linear<const C: usize>(points: &[(f64, [f64; C])], x: f64) -> [f64; C] {
    let first = points[0];
    let last = points[points.len() - 1];
    if x <= first.0 {
        return first.1;
    }
    if x >= last.0 {
        return last.1;
    }
    let i = points.partition_point(|p| p.0 <= x).clamp(1, points.len() - 1);
    let (a, b) = (points[i - 1], points[i]);
    if b.0 <= a.0 {
        return b.1;
    }
    let f = (x - a.0) / (b.0 - a.0);
    std::array::from_fn(|c| a.1[c] + (b.1[c] - a.1[c]) * f)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// ParaView's "Cool to Warm" as its ColorMaps.json ships it (three of its points).
    const COOL_TO_WARM: &str = r#"[{"ColorSpace": "Diverging", "Name": "Cool to Warm", "NanColor": [1, 1, 0],
        "RGBPoints": [0, 0.23137, 0.298039, 0.752941, 0.5, 0.865, 0.865, 0.865, 1, 0.705882, 0.0156863, 0.14902]}]"#;

    #[test]
    fn a_preset_is_rescaled_onto_the_data_range_with_a_default_ramp() {
        let tf = from_paraview_json(COOL_TO_WARM, [100.0, 300.0]).unwrap();
        assert_eq!(tf.points.len(), 3);
        assert_eq!(tf.points[0], [100.0, 0.23137, 0.298039, 0.752941, 0.0]);
        assert_eq!(tf.points[1][0], 200.0);
        assert!((tf.points[1][4] - DEFAULT_RAMP_OPACITY / 2.0).abs() < 1e-12);
        assert_eq!(tf.points[2][4], DEFAULT_RAMP_OPACITY);
    }

    #[test]
    fn opacity_points_merge_with_the_colour_points() {
        let text =
            r#"{"RGBPoints": [-1, 0, 0, 0, 1, 1, 1, 1], "Points": [-1, 0, 0.5, 0, 0, 0.5, 0.5, 0, 1, 0.2, 0.5, 0]}"#;
        let tf = from_paraview_json(text, [0.0, 10.0]).unwrap();
        assert_eq!(tf.points.iter().map(|p| p[0]).collect::<Vec<_>>(), vec![0.0, 5.0, 10.0]);
        assert_eq!(tf.points[1], [5.0, 0.5, 0.5, 0.5, 0.5]);
    }

    #[test]
    fn malformed_presets_are_refused_with_the_reason() {
        let message = |text: &str| from_paraview_json(text, [0.0, 1.0]).unwrap_err().to_string();
        assert!(message(r#"{"RGBPoints": [0, 0, 0]}"#).contains("not a multiple of 4"));
        assert!(message(r#"{"RGBPoints": [1, 0, 0, 0, 0, 1, 1, 1]}"#).contains("must not decrease"));
        assert!(message(r#"{"RGBPoints": [0, 0, 0, 0, 0, 1, 1, 1]}"#).contains("spans no range"));
        assert!(message(r#"{"RGBPoints": [0, 0, 0, 0]}"#).contains("at least two points"));
        assert!(message(r#"{"RGBPoints": [0, "a", 0, 0, 1, 1, 1, 1]}"#).contains("RGBPoints[1] is not a finite number"));
        assert!(message(r#"{"Name": "x"}"#).contains("no ParaView preset"));
        assert!(message("[1, 2").contains("malformed JSON"));
        assert!(message(r#"{"RGBPoints": [-1e308, 0, 0, 0, 1e308, 1, 1, 1]}"#).contains("too wide"));
        // A colour equal to its x, outside [0, 1], is clamped like any other.
        let tf = from_paraview_json(r#"{"RGBPoints": [0, 0, 0, 0, 1.5, 1.5, 1, 1]}"#, [0.0, 1.5]).unwrap();
        assert_eq!(tf.points[1][1], 1.0);
    }
}
