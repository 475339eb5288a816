//! Reading OME-Zarr images that voxstream did not write: Zarr v3 (OME-Zarr 0.5, `attributes.ome.multiscales`) and
//! Zarr v2 (OME-Zarr ≤ 0.4, `multiscales` in `.zattrs`).
//!
//! The last three axes are taken as z, y, x (leading axes such as time or channel are read at index 0). Level 0 is
//! the first dataset; spacing and origin come from its `scale` and `translation`. voxstream's own pyramid (each level
//! halving level 0, rounding up, down to one 32³ brick) is mapped onto the datasets whose shapes match within one
//! sample per axis (pyramids that round down); levels with no such dataset are averaged from the level below when a
//! brick is read. Per-brick min/max are unknown: the oracle never claims a region constant, and the brick pool
//! computes each brick's range when it arrives (for empty-space skipping). The value range used to normalise bricks
//! and for the default transfer function is that of the coarsest dataset (of a central block of at most
//! [`VALUE_RANGE_WINDOW`]³ samples when it is larger), widened by a quarter of its span on each side (clamped to the
//! type's range); samples beyond it saturate.
//!
//! Everything read from the metadata is checked before it sizes anything: dimensions, spacing and origin as for a
//! voxstream store, and every dataset's declared chunks against [`crate::metadata_check::MAX_CHUNK_SAMPLES`].

use std::path::Path;
use std::sync::Arc;

use serde_json::Value;
use zarrs::array::{Array, ArraySubset};
use zarrs::filesystem::FilesystemStore;
use zarrs::storage::ReadableStorageTraits;

use crate::error::StoreError;
use crate::layout::PyramidLayout;
use crate::level_source::{retrieve_f32, LevelSource};
use crate::metadata::StoreAttributes;
use crate::metadata_check::{check_chunk_sizes, dtype_range, validate_attributes};
use crate::volume::DType;

/// Brick edge used for foreign stores.
pub const FOREIGN_BRICK_SIZE: u64 = 32;

/// Edge of the largest block of the coarsest dataset read to estimate the value range.
pub const VALUE_RANGE_WINDOW: u64 = 256;

fn multiscales(attributes: &serde_json::Map<String, Value>) -> Option<&Value> {
    attributes
        .get("ome")
        .and_then(|ome| ome.get("multiscales"))
        .or_else(|| attributes.get("multiscales"))
        .and_then(|m| m.get(0))
}

fn transform(dataset: &Value, kind: &str) -> Option<Vec<f64>> {
    dataset
        .get("coordinateTransformations")?
        .as_array()?
        .iter()
        .find(|t| t.get("type").and_then(Value::as_str) == Some(kind))
        .and_then(|t| {
            t.get(if kind == "scale" { "scale" } else { "translation" })?
                .as_array()?
                .iter()
                .map(Value::as_f64)
                .collect()
        })
}

/// Opens a foreign OME-Zarr image: voxstream's attributes for it, and where each level's bricks come from.
pub(crate) fn open_foreign(
    path: &Path,
    store: &Arc<FilesystemStore>,
    attributes: &serde_json::Map<String, Value>,
) -> Result<(StoreAttributes, Vec<LevelSource>), StoreError> {
    let bad = |m: String| StoreError::store(path, m);
    let ms = multiscales(attributes).ok_or_else(|| {
        bad("neither a voxstream store nor an OME-Zarr image (no 'voxstream' or 'multiscales' attributes)".into())
    })?;
    let datasets = ms
        .get("datasets")
        .and_then(Value::as_array)
        .filter(|d| !d.is_empty())
        .ok_or_else(|| bad("multiscales has no datasets".into()))?;
    let readable: Arc<dyn ReadableStorageTraits> = store.clone();
    let mut arrays = Vec::new();
    for dataset in datasets {
        let name = dataset.get("path").and_then(Value::as_str).ok_or_else(|| bad("a dataset has no path".into()))?;
        crate::metadata_files::check_node_metadata(path, name)?;
        let array = Array::open(readable.clone(), &format!("/{}", name.trim_start_matches('/')))
            .map_err(|e| bad(format!("dataset '{name}': {e}")))?;
        let shape = array.shape().to_vec();
        if shape.len() < 3 || shape[..shape.len() - 3].iter().any(|&d| d == 0) {
            return Err(StoreError::Unsupported {
                path: path.into(),
                message: format!("dataset '{name}' has shape {shape:?} (needs ≥ 3 axes)"),
            });
        }
        let metadata = serde_json::to_value(array.metadata()).unwrap_or(Value::Null);
        check_chunk_sizes(path, name, &metadata)?;
        arrays.push((name.to_string(), array));
    }
    let (_, first) = &arrays[0];
    let data_type = first.data_type().clone();
    let dtype = [
        (zarrs::array::data_type::uint8(), DType::U8),
        (zarrs::array::data_type::uint16(), DType::U16),
        (zarrs::array::data_type::int16(), DType::I16),
        (zarrs::array::data_type::float32(), DType::F32),
    ]
    .into_iter()
    .find(|(t, _)| *t == data_type)
    .map(|(_, d)| d)
    .ok_or_else(|| StoreError::Unsupported {
        path: path.into(),
        message: "sample type (uint8, uint16, int16, float32 only)".into(),
    })?;
    for (name, array) in &arrays {
        crate::level_probe::check_level_dtype(path, name, array, dtype)?;
    }
    let last3 = |shape: &[u64]| -> [u64; 3] {
        let n = shape.len();
        [shape[n - 1], shape[n - 2], shape[n - 3]]
    };
    let dims = last3(first.shape());
    let tail3 = |v: Option<Vec<f64>>, default: f64| -> [f64; 3] {
        match v {
            Some(v) if v.len() >= 3 => {
                let n = v.len();
                [v[n - 1], v[n - 2], v[n - 3]]
            }
            _ => [default; 3],
        }
    };
    let spacing = tail3(transform(&datasets[0], "scale"), 1.0);
    let origin = tail3(transform(&datasets[0], "translation"), 0.0);

    let info = crate::volume::VolumeInfo { dims, dtype, spacing, origin };
    info.validate(path)?;
    let layout = PyramidLayout::new(dims, FOREIGN_BRICK_SIZE).map_err(|e| bad(e.to_string()))?;
    let mut levels = Vec::new();
    let mut used = vec![false; arrays.len()];
    for level in 0..layout.levels() {
        let want = layout.level_dims[level];
        let found = arrays.iter().enumerate().find(|(i, (_, a))| {
            let have = last3(a.shape());
            !used[*i] && (0..3).all(|k| have[k].abs_diff(want[k]) <= 1) && (level == 0 || *i > 0)
        });
        match found {
            Some((i, (_, array))) => {
                used[i] = true;
                let leading = array.shape().len() - 3;
                levels.push(LevelSource::Array {
                    array: Array::open(readable.clone(), array.path().as_str()).map_err(|e| bad(e.to_string()))?,
                    leading,
                    shape: last3(array.shape()),
                });
            }
            None if level == 0 => return Err(bad("level 0 does not match its own shape".into())),
            None => levels.push(LevelSource::Synthesized),
        }
    }
    crate::synthesis_limit::check_synthesis(path, &layout, &levels)?;

    // The value range, from the coarsest dataset (read whole when small, else a central block of it).
    let samples_of =
        |a: &Array<dyn ReadableStorageTraits>| last3(a.shape()).iter().fold(1u64, |n, &d| n.saturating_mul(d));
    let (_, coarsest) = arrays.iter().min_by_key(|(_, a)| samples_of(a)).unwrap_or(&arrays[0]);
    let shape = coarsest.shape().to_vec();
    let mut ranges: Vec<std::ops::Range<u64>> = shape[..shape.len() - 3].iter().map(|_| 0..1).collect();
    ranges.extend(shape[shape.len() - 3..].iter().map(|&d| {
        let take = d.min(VALUE_RANGE_WINDOW);
        let start = (d - take) / 2;
        start..start + take
    }));
    let subset = ArraySubset::new_with_ranges(&ranges);
    let read_err = |e: zarrs::array::ArrayError| bad(format!("coarsest dataset: {e}"));
    let values = retrieve_f32(coarsest, &subset, dtype).map_err(read_err)?;
    let (lo, hi) = values
        .iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| (lo.min(v as f64), hi.max(v as f64)));
    let (lo, hi) = if lo.is_finite() { (lo, hi) } else { (0.0, 1.0) };
    let margin = (hi - lo).max(1e-6) * 0.25;
    let [type_lo, type_hi] = dtype_range(dtype);
    let value_range = [(lo - margin).max(type_lo), (hi + margin).min(type_hi)];
    let attributes = StoreAttributes::new(&info, &layout, value_range, true);
    validate_attributes(path, &attributes)?;
    Ok((attributes, levels))
}
