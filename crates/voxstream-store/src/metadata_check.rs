//! Validating a store's metadata once, on open: every attribute is checked before anything is sized from it, and a
//! bad one is refused with one error naming the store and the field (`docs/STORE_FORMAT.md` §9).
//!
//! After these checks the geometry is known to be small enough to lay out (dims ≤ 2^20 per axis, so at most 20
//! levels), the brick edge is one the importer writes, and the value range maps onto `f32` without overflow, so
//! the per-sample loops downstream need no checks of their own.

use std::path::Path;

use serde_json::Value;

use crate::error::StoreError;
use crate::layout::{PyramidLayout, MAX_BRICK_SIZE, MIN_BRICK_SIZE};
use crate::metadata::{StoreAttributes, FORMAT_VERSION};
use crate::orientation::Orientation;
use crate::space_unit::SpaceUnit;
use crate::volume::{DType, VolumeInfo};
use crate::world_extent::check_world_extent;

/// Largest samples per axis a store may have.
pub const MAX_DIM: u64 = 1 << 20;

/// Largest chunk (or shard, or inner chunk) a level array may declare, in samples: decoding one allocates that
/// much (2^27 samples are 512 MiB as `f32`).
pub const MAX_CHUNK_SAMPLES: u64 = 1 << 27;

/// The smallest and largest value a sample of `dtype` can hold.
pub fn dtype_range(dtype: DType) -> [f64; 2] {
    match dtype {
        DType::U8 => [0.0, u8::MAX as f64],
        DType::U16 => [0.0, u16::MAX as f64],
        DType::I16 => [i16::MIN as f64, i16::MAX as f64],
        DType::F32 => [-(f32::MAX as f64), f32::MAX as f64],
    }
}

/// Checks every attribute of a store at `path`; returns the volume and pyramid they describe.
pub fn validate_attributes(
    path: &Path,
    attributes: &StoreAttributes,
) -> Result<(VolumeInfo, PyramidLayout), StoreError> {
    let bad = |field: &str, problem: String| Err(StoreError::metadata(path, field, problem));
    if attributes.format_version > FORMAT_VERSION {
        return bad(
            "format_version",
            format!(
                "is {}: the store was written by a newer voxstream (this one reads version {FORMAT_VERSION}); \
                 upgrade voxstream",
                attributes.format_version
            ),
        );
    }
    if attributes.format_version == 0 {
        return bad("format_version", format!("is 0, expected {FORMAT_VERSION}"));
    }
    let Some(dtype) = attributes.dtype() else {
        return bad("dtype", format!("'{}' is not a sample type (u8, u16, i16, f32)", attributes.dtype));
    };
    let dims = attributes.dims;
    if dims.iter().any(|&d| d == 0 || d > MAX_DIM) {
        return bad("dims", format!("{dims:?} must be in 1..={MAX_DIM} per axis"));
    }
    if attributes.spacing.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
        return bad("spacing", format!("{:?} must be finite and positive", attributes.spacing));
    }
    if attributes.origin.iter().any(|o| !o.is_finite()) {
        return bad("origin", format!("{:?} must be finite", attributes.origin));
    }
    if let Err((field, problem)) = check_world_extent(dims, attributes.spacing, attributes.origin) {
        return bad(field, problem);
    }
    let brick_size = attributes.brick_size;
    if !(MIN_BRICK_SIZE..=MAX_BRICK_SIZE).contains(&brick_size) || !brick_size.is_multiple_of(2) {
        return bad(
            "brick_size",
            format!("is {brick_size}, expected an even size in {MIN_BRICK_SIZE}..={MAX_BRICK_SIZE}"),
        );
    }
    let layout =
        PyramidLayout::new(dims, brick_size).map_err(|e| StoreError::metadata(path, "brick_size", e.to_string()))?;
    if attributes.levels != layout.levels() {
        return bad(
            "levels",
            format!(
                "is {}, but dims {dims:?} with brick_size {brick_size} give {}",
                attributes.levels,
                layout.levels()
            ),
        );
    }
    if let Some(codec) = attributes.brick_codec {
        let e = codec.max_error();
        if !(e.is_finite() && e >= 0.0) {
            return bad("brick_codec", format!("max_error {e} must be a finite number ≥ 0"));
        }
    }
    let [lo, hi] = attributes.value_range;
    let [type_lo, type_hi] = dtype_range(dtype);
    if !(lo.is_finite() && hi.is_finite()) {
        return bad("value_range", format!("{:?} must be finite", attributes.value_range));
    }
    if lo > hi {
        return bad("value_range", format!("{:?} is reversed (min above max)", attributes.value_range));
    }
    if lo < type_lo || hi > type_hi {
        return bad(
            "value_range",
            format!(
                "{:?} lies outside what {} samples hold ({type_lo} to {type_hi})",
                attributes.value_range,
                dtype.name()
            ),
        );
    }
    if !((hi - lo) as f32).is_finite() {
        return bad("value_range", format!("{:?} spans more than an f32 holds", attributes.value_range));
    }
    if let Some(percentiles) = &attributes.value_percentiles {
        let in_range = |[percent, value]: [f64; 2]| (0.0..=100.0).contains(&percent) && value >= lo && value <= hi;
        let increasing = percentiles.windows(2).all(|w| w[0][0] < w[1][0] && w[0][1] <= w[1][1]);
        if !(percentiles.iter().all(|&p| in_range(p)) && increasing) {
            return bad(
                "value_percentiles",
                format!(
                    "must be [percent, value] pairs with percents in 0..=100 increasing and values within \
                     value_range {:?}, non-decreasing",
                    attributes.value_range
                ),
            );
        }
    }
    let unit = match attributes.unit.as_deref().map(SpaceUnit::parse) {
        None => None,
        Some(Ok(unit)) => Some(unit),
        Some(Err(problem)) => return bad("unit", problem),
    };
    let orientation = match attributes.orientation.as_deref().map(Orientation::parse) {
        None => None,
        Some(Ok(orientation)) => Some(orientation),
        Some(Err(problem)) => return bad("orientation", problem),
    };
    let info = VolumeInfo { dims, dtype, spacing: attributes.spacing, origin: attributes.origin, unit, orientation };
    Ok((info, layout))
}

/// The largest number of samples any `chunk_shape` (Zarr v3, including a sharding codec's inner chunks) or
/// `chunks` (Zarr v2) in an array's metadata declares.
pub fn largest_declared_chunk(metadata: &Value) -> u64 {
    match metadata {
        Value::Object(map) => map
            .iter()
            .map(|(key, value)| match (key.as_str(), value) {
                ("chunk_shape" | "chunks", Value::Array(shape)) if shape.iter().all(Value::is_u64) => {
                    shape.iter().filter_map(Value::as_u64).fold(1u64, |n, d| n.saturating_mul(d))
                }
                _ => largest_declared_chunk(value),
            })
            .max()
            .unwrap_or(0),
        Value::Array(items) => items.iter().map(largest_declared_chunk).max().unwrap_or(0),
        _ => 0,
    }
}

/// Refuses an array whose chunks (or shards, or inner chunks) would decode into more than [`MAX_CHUNK_SAMPLES`].
pub fn check_chunk_sizes(path: &Path, name: &str, metadata: &Value) -> Result<(), StoreError> {
    let largest = largest_declared_chunk(metadata);
    if largest > MAX_CHUNK_SAMPLES {
        return Err(StoreError::metadata(
            path,
            format!("{name}/zarr.json chunk_shape"),
            format!("declares chunks of {largest} samples, more than the {MAX_CHUNK_SAMPLES} voxstream reads"),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn good() -> StoreAttributes {
        StoreAttributes {
            format_version: 1,
            dims: [100, 80, 60],
            dtype: "u16".into(),
            spacing: [1.0, 1.0, 2.0],
            origin: [0.0; 3],
            unit: Some("millimeter".into()),
            orientation: Some("LPS".into()),
            brick_size: 32,
            levels: 3,
            value_range: [0.0, 4000.0],
            complete: true,
            value_percentiles: Some(vec![[0.5, 10.0], [99.5, 3900.0]]),
            brick_codec: None,
        }
    }

    fn field_of(attributes: &StoreAttributes) -> String {
        match validate_attributes(Path::new("s.zarr"), attributes) {
            Err(StoreError::Metadata { field, .. }) => field,
            other => panic!("expected a metadata error, got {other:?}"),
        }
    }

    #[test]
    fn each_bad_attribute_is_named() {
        assert!(validate_attributes(Path::new("s.zarr"), &good()).is_ok());
        type Edit = Box<dyn Fn(&mut StoreAttributes)>;
        let cases: Vec<(&str, Edit)> = vec![
            ("format_version", Box::new(|a| a.format_version = 99)),
            ("format_version", Box::new(|a| a.format_version = 0)),
            ("dtype", Box::new(|a| a.dtype = "u64".into())),
            ("dims", Box::new(|a| a.dims = [0, 1, 1])),
            ("dims", Box::new(|a| a.dims = [1 << 40, 1, 1])),
            ("spacing", Box::new(|a| a.spacing = [f64::NAN, 1.0, 1.0])),
            ("spacing", Box::new(|a| a.spacing = [0.0, 1.0, 1.0])),
            ("origin", Box::new(|a| a.origin = [f64::INFINITY, 0.0, 0.0])),
            ("unit", Box::new(|a| a.unit = Some("furlong".into()))),
            ("orientation", Box::new(|a| a.orientation = Some("RAR".into()))),
            ("orientation", Box::new(|a| a.orientation = Some("up".into()))),
            ("spacing", Box::new(|a| a.spacing = [1.0, 1e308, 1.0])),
            ("origin", Box::new(|a| a.origin = [0.0, 0.0, 1e308])),
            ("brick_size", Box::new(|a| a.brick_size = 0)),
            ("brick_size", Box::new(|a| a.brick_size = 7)),
            ("brick_size", Box::new(|a| a.brick_size = 1 << 40)),
            ("levels", Box::new(|a| a.levels = 1)),
            ("value_range", Box::new(|a| a.value_range = [4000.0, 0.0])),
            ("value_range", Box::new(|a| a.value_range = [-1e308, 1e308])),
            ("value_range", Box::new(|a| a.value_range = [0.0, 70000.0])),
            ("value_range", Box::new(|a| a.value_range = [f64::NAN, 1.0])),
            ("value_percentiles", Box::new(|a| a.value_percentiles = Some(vec![[0.5, 10.0], [99.5, 1e9]]))),
            ("value_percentiles", Box::new(|a| a.value_percentiles = Some(vec![[99.5, 3900.0], [0.5, 10.0]]))),
            ("value_percentiles", Box::new(|a| a.value_percentiles = Some(vec![[f64::NAN, 10.0]]))),
        ];
        for (field, edit) in cases {
            let mut attributes = good();
            edit(&mut attributes);
            assert_eq!(field_of(&attributes), field, "{attributes:?}");
        }
    }

    #[test]
    fn newer_format_says_so() {
        let mut attributes = good();
        attributes.format_version = 99;
        let message = validate_attributes(Path::new("s.zarr"), &attributes).unwrap_err().to_string();
        assert!(message.contains("newer voxstream") && message.contains("s.zarr"), "{message}");
    }

    #[test]
    fn chunk_shapes_are_found_at_any_depth() {
        let metadata = serde_json::json!({
            "chunk_grid": {"configuration": {"chunk_shape": [32, 256, 256]}},
            "codecs": [{"name": "sharding_indexed", "configuration": {"chunk_shape": [1024, 1024, 1024]}}]
        });
        assert_eq!(largest_declared_chunk(&metadata), 1 << 30);
        assert!(check_chunk_sizes(Path::new("s"), "0", &metadata).is_err());
        assert_eq!(largest_declared_chunk(&serde_json::json!({"chunks": [64, 64, 64]})), 1 << 18);
    }
}
