//! Reading OME-Zarr images that voxstream did not write: Zarr v3 (OME-Zarr 0.5, `attributes.ome.multiscales`) and
//! Zarr v2 (OME-Zarr ≤ 0.4, `multiscales` in `.zattrs`).
//!
//! The last three axes are read as z, y, x (of leading axes, time and channel, the index chosen: [`crate::image_planes`]); `axes`
//! metadata saying otherwise, and `scale` or `translation` that are not one number per axis, are refused
//! ([`crate::foreign_axes`]), as are arrays whose chunk files do not follow their declared key separator
//! ([`crate::chunk_keys`]). Level 0 is the first dataset; spacing and origin come from its `scale` and `translation`. voxstream's own pyramid (each level
//! halving level 0, rounding up, down to one 32³ brick) is mapped onto the datasets whose shapes match within one
//! sample per axis (pyramids that round down); levels with no such dataset are averaged from the level below when a
//! brick is read. Per-brick min/max are unknown: the oracle never claims a region constant, and the brick pool
//! computes each brick's range when it arrives (for empty-space skipping). The value range used to normalise bricks
//! and for the default transfer function is the exact range of level 0, streamed once at open
//! ([`crate::value_range`]), unless the caller gives one ([`ForeignOptions::value_range`]); samples beyond a given
//! range saturate, and the reader counts them ([`crate::StoreReader::clipped_samples`]).
//!
//! Everything read from the metadata is checked before it sizes anything: dimensions, spacing and origin as for a
//! voxstream store, and every dataset's declared chunks against [`crate::metadata_check::MAX_CHUNK_SAMPLES`].

use std::path::Path;
use std::sync::Arc;

use serde_json::Value;
use zarrs::array::Array;
use zarrs::storage::ReadableStorageTraits;

use crate::chunk_keys::{stored_chunks_in, ChunkSource};
use crate::error::StoreError;
use crate::foreign_axes::{anatomical_orientation, check_axes, space_unit, transform_xyz};
use crate::image_planes::{choose_planes, leading_index, omero_channel, ImagePlanes, LeadingKind, PlaneChoice};
use crate::layout::PyramidLayout;
use crate::level_source::LevelSource;
use crate::metadata::StoreAttributes;
use crate::metadata_check::{check_chunk_sizes, dtype_range, validate_attributes};
use crate::value_range::ScanProgress;
use crate::volume::DType;

/// Brick edge used for foreign stores.
pub const FOREIGN_BRICK_SIZE: u64 = 32;

/// How to open a foreign image.
#[derive(Clone, Copy, Default)]
pub struct ForeignOptions<'a> {
    /// The value range to normalise by (`[lo, hi]`), instead of level 0's, which is then not scanned.
    pub value_range: Option<[f64; 2]>,
    /// Told `(chunks done, chunks in all)` while level 0 is scanned for its value range.
    pub progress: Option<ScanProgress<'a>>,
    /// The most samples the value-range scan at open reads ([`MAX_SCAN_SAMPLES`] when `None`): the finest level
    /// whose stored chunks hold no more is scanned (level 0 unless the image is large).
    pub max_scan_samples: Option<u64>,
    /// How a remote store (a URL) is read: timeouts, retries, the disk cache (defaults when `None`). Applies to
    /// voxstream's own stores too.
    pub remote: Option<&'a crate::remote_access::RemoteAccess>,
    /// The channel and time point of a 4-D/5-D image (0 when `None`).
    pub planes: PlaneChoice,
}

/// Default bound of the value-range scan at open: 2^28 samples (about a second of decoding here). A larger level 0
/// is not read whole when the image is opened (a terabyte on object storage would take hours): the finest level
/// within the bound is scanned instead, its range used, and samples beyond it are counted as clipped when read.
pub const MAX_SCAN_SAMPLES: u64 = 1 << 28;

fn multiscales(attributes: &serde_json::Map<String, Value>) -> Option<&Value> {
    attributes
        .get("ome")
        .and_then(|ome| ome.get("multiscales"))
        .or_else(|| attributes.get("multiscales"))
        .and_then(|m| m.get(0))
}

/// A level and its chunks as stored on disk (their indices), to be scanned for the value range.
pub(crate) type StoredChunks = (usize, Vec<Vec<u64>>);

/// What [`open_foreign`] finds: voxstream's attributes for the image, where each level's bricks come from, the level
/// to scan for the value range (unless given), and the leading axes and `omero` metadata.
pub(crate) type OpenedForeign = (StoreAttributes, Vec<LevelSource>, Option<StoredChunks>, ImagePlanes);

/// Opens a foreign OME-Zarr image: voxstream's attributes for it, where each level's bricks come from, and, unless
/// `options` gives the value range, the level to scan and its stored chunks (level 0's unless they hold more than
/// the scan's bound of samples), whose range the attributes' `value_range` (then
/// `[0, 1]`) must be replaced with.
pub(crate) fn open_foreign(
    path: &Path,
    readable: Arc<dyn ReadableStorageTraits>,
    attributes: &serde_json::Map<String, Value>,
    options: &ForeignOptions,
    chunk_source: &ChunkSource,
) -> Result<OpenedForeign, StoreError> {
    let bad = |m: String| StoreError::store(path, m);
    let attributes_json = attributes;
    let ms = multiscales(attributes).ok_or_else(|| {
        bad("neither a voxstream store nor an OME-Zarr image (no 'voxstream' or 'multiscales' attributes)".into())
    })?;
    let datasets = ms
        .get("datasets")
        .and_then(Value::as_array)
        .filter(|d| !d.is_empty())
        .ok_or_else(|| bad("multiscales has no datasets".into()))?;
    let mut arrays = Vec::new();
    let mut stored_per_dataset = Vec::new();
    for dataset in datasets {
        let name = dataset.get("path").and_then(Value::as_str).ok_or_else(|| bad("a dataset has no path".into()))?;
        if name.split(['/', '\\']).any(|part| part == "..") {
            return Err(bad(format!("dataset path '{name}' leaves the store (it holds '..')")));
        }
        if let ChunkSource::Folder(_) = chunk_source {
            crate::metadata_files::check_node_metadata(path, name)?;
        }
        let opened = Array::open(readable.clone(), &format!("/{}", name.trim_start_matches('/')))
            .map_err(|e| bad(format!("dataset '{name}': {e}")))?;
        // The metadata as written (a v2 array's own keys), before a blosc array is re-created from it as v3.
        let metadata = serde_json::to_value(opened.metadata()).unwrap_or(Value::Null);
        let array = crate::strict_codecs::with_strict_blosc(opened, readable.clone())
            .map_err(|e| bad(format!("dataset '{name}': {e}")))?;
        let shape = array.shape().to_vec();
        if shape.len() < 3 || shape[..shape.len() - 3].iter().any(|&d| d == 0) {
            return Err(StoreError::Unsupported {
                path: path.into(),
                message: format!("dataset '{name}' has shape {shape:?} (needs ≥ 3 axes)"),
            });
        }
        check_chunk_sizes(path, name, &metadata)?;
        check_axes(ms, shape.len()).map_err(|m| bad(format!("dataset '{name}': {m}")))?;
        let chunks = stored_chunks_in(chunk_source, name, &metadata, shape.len())
            .map_err(|m| bad(format!("dataset '{name}' {m}")))?;
        stored_per_dataset.push(chunks);
        arrays.push((name.to_string(), array));
    }
    let (_, first) = &arrays[0];
    let data_type = first.data_type().clone();
    let dtype = DType::from_zarr_data_type(&data_type).ok_or_else(|| StoreError::Unsupported {
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
    let dimensions = first.shape().len();
    let planes = choose_planes(ms, first.shape(), options.planes).map_err(bad)?;
    let leading = leading_index(&planes);
    let transform = |kind: &str| {
        transform_xyz(&datasets[0], kind, dimensions).map_err(|m| bad(format!("dataset '{}': {m}", arrays[0].0)))
    };
    let spacing = transform("scale")?.unwrap_or([1.0; 3]);
    let origin = transform("translation")?.unwrap_or([0.0; 3]);

    let info = crate::volume::VolumeInfo {
        dims,
        dtype,
        spacing,
        origin,
        unit: space_unit(ms),
        orientation: anatomical_orientation(ms),
    };
    info.validate(path)?;
    let layout = PyramidLayout::new(dims, FOREIGN_BRICK_SIZE).map_err(|e| bad(e.to_string()))?;
    let mut levels = Vec::new();
    let mut used = vec![false; arrays.len()];
    // Per level, the dataset read for it (None: synthesised).
    let mut level_datasets = Vec::new();
    for level in 0..layout.levels() {
        let want = layout.level_dims[level];
        let found = arrays.iter().enumerate().find(|(i, (_, a))| {
            let have = last3(a.shape());
            !used[*i] && (0..3).all(|k| have[k].abs_diff(want[k]) <= 1) && (level == 0 || *i > 0)
        });
        match found {
            Some((i, (_, array))) => {
                used[i] = true;
                level_datasets.push(Some(i));
                let extents = &array.shape()[..array.shape().len() - 3];
                if extents.len() != leading.len() || extents.iter().zip(&leading.0).any(|(&n, &i)| i >= n) {
                    return Err(bad(format!(
                        "dataset '{}' has shape {:?}: its leading axes differ from level 0's",
                        array.path(),
                        array.shape()
                    )));
                }
                levels.push(LevelSource::Array {
                    array: Array::open(readable.clone(), array.path().as_str())
                        .map_err(|e| e.to_string())
                        .and_then(|opened| crate::strict_codecs::with_strict_blosc(opened, readable.clone()))
                        .map_err(bad)?,
                    leading: leading.clone(),
                    shape: last3(array.shape()),
                });
            }
            None if level == 0 => return Err(bad("level 0 does not match its own shape".into())),
            None => {
                level_datasets.push(None);
                levels.push(LevelSource::Synthesized)
            }
        }
    }
    crate::synthesis_limit::check_synthesis(path, &layout, &levels)?;

    let (value_range, scan) = match options.value_range {
        Some([lo, hi]) if !(lo < hi && lo >= dtype_range(dtype)[0] && hi <= dtype_range(dtype)[1]) => {
            let [type_lo, type_hi] = dtype_range(dtype);
            return Err(StoreError::Unsupported {
                path: path.into(),
                message: format!(
                    "the value range given, {lo} to {hi}, is not an increasing range within what {} samples hold \
                     ({type_lo} to {type_hi})",
                    dtype.name()
                ),
            });
        }
        Some(range) => (range, None),
        None => {
            // The finest stored level whose chunks hold at most the bound (else the coarsest stored one).
            let bound = options.max_scan_samples.unwrap_or(MAX_SCAN_SAMPLES);
            // A store that cannot be listed (plain HTTP) counts every chunk of the grid as stored.
            let chunk_count = |i: usize| match &stored_per_dataset[i] {
                Some(chunks) => chunks.len() as u64,
                None => arrays[i].1.chunk_grid_shape().iter().fold(1u64, |n, &d| n.saturating_mul(d)),
            };
            let stored_samples = |i: usize| {
                let array = &arrays[i].1;
                let chunk = array.chunk_shape(&vec![0; array.dimensionality()]).ok();
                let per_chunk = chunk.map_or(u64::MAX, |c| c.iter().fold(1u64, |n, d| n.saturating_mul(d.get())));
                per_chunk.saturating_mul(chunk_count(i))
            };
            let stored: Vec<(usize, usize)> =
                level_datasets.iter().enumerate().filter_map(|(level, d)| d.map(|i| (level, i))).collect();
            let (level, i) = stored
                .iter()
                .copied()
                .find(|&(_, i)| stored_samples(i) <= bound)
                .or_else(|| stored.last().copied())
                .ok_or_else(|| bad("no level is stored".into()))?;
            let chunks = match stored_per_dataset[i].take() {
                Some(chunks) => chunks,
                None => every_chunk(&arrays[i].1).map_err(|m| bad(format!("dataset '{}': {m}", arrays[i].0)))?,
            };
            ([0.0, 1.0], Some((level, chunks)))
        }
    };
    let attributes = StoreAttributes::new(&info, &layout, value_range, true);
    validate_attributes(path, &attributes)?;
    let channel = planes.iter().find(|a| a.kind == LeadingKind::Channel).map_or(0, |a| a.index);
    let omero = omero_channel(attributes_json, channel);
    Ok((attributes, levels, scan, ImagePlanes { axes: planes, omero }))
}

/// Most chunks of a grid taken as stored when a remote store cannot be listed (the level scanned holds at most
/// [`MAX_SCAN_SAMPLES`] samples unless no level does; the coarsest level of a pyramid has a handful of chunks).
const MAX_GRID_CHUNKS: u64 = 1 << 22;

/// Every chunk index of `array`'s grid (for a store that cannot be listed: absent chunks read as the fill value).
fn every_chunk(array: &Array<dyn ReadableStorageTraits>) -> Result<Vec<Vec<u64>>, String> {
    let grid = array.chunk_grid_shape().to_vec();
    let count = grid.iter().fold(1u64, |n, &d| n.saturating_mul(d));
    if count > MAX_GRID_CHUNKS {
        return Err(format!(
            "{count} chunks and no level small enough to scan for the value range over a server that cannot list \
             them; give the range with --value-range LO,HI"
        ));
    }
    let mut all = vec![Vec::new()];
    for &extent in &grid {
        all = all.into_iter().flat_map(|prefix| (0..extent).map(move |i| [prefix.clone(), vec![i]].concat())).collect();
    }
    Ok(all)
}
