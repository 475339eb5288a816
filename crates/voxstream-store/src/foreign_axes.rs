//! A foreign OME-Zarr image's axes and coordinate transformations, checked before they are used: voxstream reads the
//! last three array axes as z, y, x, so the `axes` metadata must say exactly that (leading axes being time or
//! channel), and a `scale` or `translation` must hold one number per axis. Anything else is refused with one line
//! naming what was found, never guessed (axes listed x, y, z were read transposed; a scale of strings became 1).

use serde_json::Value;

use crate::orientation::{Orientation, Towards};
use crate::space_unit::SpaceUnit;

/// An axis' name from OME-NGFF 0.4+ (`{"name": "z", "type": "space"}`) or 0.3 (`"z"`), lower case.
fn axis_name(axis: &Value) -> Option<String> {
    axis.as_str().or_else(|| axis.get("name").and_then(Value::as_str)).map(str::to_ascii_lowercase)
}

/// Refuses `axes` (a multiscales entry's) unless they are `dimensions` axes, the last three z, y, x in that order and
/// of type space (when typed), no leading one a space axis. Images without `axes` (OME-NGFF ≤ 0.2) read as before.
pub(crate) fn check_axes(multiscale: &Value, dimensions: usize) -> Result<(), String> {
    let Some(axes) = multiscale.get("axes") else {
        return Ok(());
    };
    let Some(axes) = axes.as_array() else {
        return Err(format!("multiscales 'axes' is {axes}, expected a list of axes"));
    };
    let names: Vec<String> = axes.iter().map(|a| axis_name(a).unwrap_or_else(|| format!("{a}"))).collect::<Vec<_>>();
    let listed = names.join(", ");
    if axes.len() != dimensions {
        return Err(format!("multiscales axes [{listed}] are {} axes, but the arrays have {dimensions}", axes.len()));
    }
    let is_space = |a: &Value| a.get("type").and_then(Value::as_str).is_none_or(|t| t == "space");
    let split = dimensions - 3;
    let spatial_tail = names[split..] == ["z", "y", "x"] && axes[split..].iter().all(is_space);
    let leading_space = names[..split].iter().zip(&axes[..split]).any(|(name, a)| {
        ["x", "y", "z"].contains(&name.as_str()) || a.get("type").and_then(Value::as_str) == Some("space")
    });
    if !spatial_tail || leading_space {
        return Err(format!(
            "axes are [{listed}]: voxstream reads images whose last three axes are the space axes z, y, x in that \
             order (leading axes time or channel); write the image with axes ordered z, y, x"
        ));
    }
    Ok(())
}

/// The unit of the last three (space) axes, when all three name the same OME-Zarr unit; otherwise none (an image
/// is read whatever units it gives, as before units were shown).
pub(crate) fn space_unit(multiscale: &Value) -> Option<SpaceUnit> {
    let axes = multiscale.get("axes")?.as_array()?;
    let units: Vec<Option<SpaceUnit>> = axes
        .iter()
        .rev()
        .take(3)
        .map(|a| a.get("unit").and_then(Value::as_str).and_then(SpaceUnit::from_name))
        .collect();
    let first = *units.first()?;
    (units.len() == 3 && units.iter().all(|u| *u == first)).then_some(first).flatten()
}

/// The anatomical orientation of the last three (space) axes, when each says one of the human body's six directions
/// (OME-NGFF RFC-4: `"orientation": {"type": "anatomical", "value": "left-to-right"}`) and together they name three
/// different body axes; otherwise none (the image is read as before, with the index-axes default view).
pub(crate) fn anatomical_orientation(multiscale: &Value) -> Option<Orientation> {
    let axes = multiscale.get("axes")?.as_array()?;
    if axes.len() < 3 {
        return None;
    }
    let towards = |axis: &Value| {
        let orientation = axis.get("orientation")?;
        (orientation.get("type").and_then(Value::as_str) == Some("anatomical")).then_some(())?;
        Towards::from_rfc4_value(orientation.get("value")?.as_str()?)
    };
    // Axes are listed z, y, x: the last is x.
    let n = axes.len();
    Orientation::new([towards(&axes[n - 1])?, towards(&axes[n - 2])?, towards(&axes[n - 3])?]).ok()
}

/// The first `kind` ("scale" or "translation") transform of `dataset` as (x, y, z), `None` when it has none; a
/// transform that is not `dimensions` numbers is refused.
pub(crate) fn transform_xyz(dataset: &Value, kind: &str, dimensions: usize) -> Result<Option<[f64; 3]>, String> {
    let Some(transforms) = dataset.get("coordinateTransformations") else {
        return Ok(None);
    };
    let Some(transform) = transforms
        .as_array()
        .and_then(|list| list.iter().find(|t| t.get("type").and_then(Value::as_str) == Some(kind)))
    else {
        return Ok(None);
    };
    let values = transform.get(kind);
    let numbers: Option<Vec<f64>> =
        values.and_then(Value::as_array).and_then(|v| v.iter().map(Value::as_f64).collect());
    match numbers {
        Some(v) if v.len() == dimensions => Ok(Some([v[dimensions - 1], v[dimensions - 2], v[dimensions - 3]])),
        _ => Err(format!(
            "coordinateTransformations {kind} is {}, expected {dimensions} numbers (one per axis)",
            values.map_or_else(|| "missing (a path to a file is not read)".to_string(), Value::to_string)
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn axes_must_end_in_z_y_x() {
        let ok = json!({"axes": [{"name": "c", "type": "channel"}, {"name": "z", "type": "space"},
                                  {"name": "y", "type": "space"}, {"name": "x", "type": "space"}]});
        assert_eq!(check_axes(&ok, 4), Ok(()));
        assert_eq!(check_axes(&json!({"axes": ["t", "c", "z", "y", "x"]}), 5), Ok(()));
        assert_eq!(check_axes(&json!({}), 3), Ok(()));
        let transposed = check_axes(&json!({"axes": ["x", "y", "z"]}), 3).unwrap_err();
        assert!(transposed.contains("[x, y, z]") && transposed.contains("z, y, x"), "{transposed}");
        assert!(check_axes(&json!({"axes": ["z", "y", "x"]}), 4).unwrap_err().contains("3 axes"));
    }

    #[test]
    fn rfc4_anatomical_orientations_are_read_from_the_space_axes() {
        let axis = |name: &str, value: &str| json!({"name": name, "type": "space", "orientation": {"type": "anatomical", "value": value}});
        let ras = json!({"axes": [{"name": "t", "type": "time"}, axis("z", "inferior-to-superior"),
                                  axis("y", "posterior-to-anterior"), axis("x", "left-to-right")]});
        assert_eq!(anatomical_orientation(&ras).map(|o| o.code()), Some("RAS".to_string()));
        // The Allen mouse atlas' PIR: x to the back, y down, z to the right.
        let pir = json!({"axes": [axis("z", "left-to-right"), axis("y", "superior-to-inferior"),
                                  axis("x", "anterior-to-posterior")]});
        assert_eq!(anatomical_orientation(&pir).map(|o| o.code()), Some("PIR".to_string()));
        // One axis without it, a value of another anatomy, one body axis twice: none.
        let partial = json!({"axes": [{"name": "z", "type": "space"}, axis("y", "posterior-to-anterior"),
                                      axis("x", "left-to-right")]});
        assert_eq!(anatomical_orientation(&partial), None);
        let dorsal = json!({"axes": [axis("z", "dorsal-to-ventral"), axis("y", "posterior-to-anterior"),
                                     axis("x", "left-to-right")]});
        assert_eq!(anatomical_orientation(&dorsal), None);
        let twice = json!({"axes": [axis("z", "right-to-left"), axis("y", "posterior-to-anterior"),
                                    axis("x", "left-to-right")]});
        assert_eq!(anatomical_orientation(&twice), None);
        assert_eq!(anatomical_orientation(&json!({"axes": ["z", "y", "x"]})), None);
    }

    #[test]
    fn the_unit_is_the_one_all_three_space_axes_share() {
        let axis = |name: &str, unit: &str| json!({"name": name, "type": "space", "unit": unit});
        let ms = json!({"axes": [{"name": "c", "type": "channel"}, axis("z", "micrometer"), axis("y", "micrometer"),
                                 axis("x", "micrometer")]});
        assert_eq!(space_unit(&ms).map(SpaceUnit::name), Some("micrometer"));
        let mixed = json!({"axes": [axis("z", "millimeter"), axis("y", "micrometer"), axis("x", "micrometer")]});
        assert_eq!(space_unit(&mixed), None);
        assert_eq!(space_unit(&json!({"axes": ["z", "y", "x"]})), None);
        assert!(check_axes(&json!({"axes": ["z", "c", "y", "x"]}), 4).is_err());
        assert!(check_axes(&json!({"axes": [{"name": "z", "type": "time"}, "y", "x"]}), 3).is_err());
    }

    #[test]
    fn transforms_are_numbers_one_per_axis() {
        let dataset = |scale: Value| json!({"coordinateTransformations": [{"type": "scale", "scale": scale}]});
        assert_eq!(transform_xyz(&dataset(json!([3.0, 2.0, 1.0])), "scale", 3), Ok(Some([1.0, 2.0, 3.0])));
        assert_eq!(transform_xyz(&dataset(json!([3.0, 2.0, 1.0])), "translation", 3), Ok(None));
        let strings = transform_xyz(&dataset(json!(["a", "b", "c"])), "scale", 3).unwrap_err();
        assert!(strings.contains("[\"a\",\"b\",\"c\"]") && strings.contains("3 numbers"), "{strings}");
        assert!(transform_xyz(&dataset(json!([1.0, 1.0])), "scale", 3).is_err());
    }
}
