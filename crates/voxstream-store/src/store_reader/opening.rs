//! Opening a store, local or remote: its folder or URL, its metadata validated once (voxstream's attributes, each
//! level's array, the per-brick min/max of every level), foreign stores handed to [`crate::foreign`].

use std::path::{Path, PathBuf};
use std::sync::Arc;

use zarrs::array::Array;
use zarrs::group::Group;
use zarrs::storage::storage_adapter::performance_metrics::PerformanceMetricsStorageAdapter;
use zarrs::storage::{ReadableStorageTraits, StoreKey};

use voxstream_remote::{DiskCache, RemoteLocation, RemoteStore};

use crate::checked_store::{zstd_encoded_bound, CheckedStore};
use crate::chunk_keys::ChunkSource;
use crate::encoded_cache::EncodedCache;
use crate::error::StoreError;
use crate::foreign::ForeignOptions;
use crate::import::{aside_paths, partial_path};
use crate::layout::PyramidLayout;
use crate::level_probe::check_level_dtype;
use crate::level_source::LevelSource;
use crate::metadata::{StoreAttributes, MINMAX_GROUP};
use crate::metadata_check::{check_chunk_sizes, validate_attributes};
use crate::metadata_files::check_node_metadata;
use crate::remote_access::RemoteAccess;

use super::{StoreReader, DEFAULT_CACHE_BYTES};

/// The first attribute that is, or holds, a JSON null.
fn null_field(attributes: &serde_json::Value) -> Option<String> {
    let object = attributes.as_object()?;
    object
        .iter()
        .find(|(_, v)| v.is_null() || v.as_array().is_some_and(|items| items.iter().any(serde_json::Value::is_null)))
        .map(|(k, _)| k.clone())
}

/// An array's `zarr.json` as JSON (for the checks zarrs does not make).
fn metadata_json(array: &Array<dyn ReadableStorageTraits>) -> serde_json::Value {
    serde_json::to_value(array.metadata()).unwrap_or(serde_json::Value::Null)
}

/// Reads and checks the per-brick `[min, max]` of `level`: the array must be there, its one chunk file must hold
/// exactly `8 ·` bricks bytes (checked before reading, so a forged brick count allocates nothing; over a network the
/// bytes are fetched with the metadata, held to the remote store's cap on whole values, and checked the same way
/// before they are decoded), and every entry
/// must be finite with `min ≤ max`. The chunk may be absent only when the whole volume is 0 (the Zarr fill value):
/// otherwise a missing file would read as empty space.
fn read_minmax(
    path: &Path,
    store: &Arc<CheckedStore>,
    layout: &PyramidLayout,
    level: usize,
    volume_is_zero: bool,
    remote: bool,
) -> Result<Vec<[f32; 2]>, StoreError> {
    let name = format!("{MINMAX_GROUP}/{level}");
    let bad = |problem: String| StoreError::store(path, format!("min/max of level {level} ({name}): {problem}"));
    // Over a network the one chunk (where voxstream writes it) is fetched while the array's metadata is, one round
    // trip instead of three (metadata, size, bytes); its size and bytes are then checked as if read after it.
    let guessed = if remote { StoreKey::new(format!("{name}/c/0/0/0/0")).ok() } else { None };
    let [bx, by, bz] = layout.bricks(level);
    let expected_bytes = bx * by * bz * 8;
    let ranges = std::thread::scope(|scope| {
        if let Some(key) = &guessed {
            scope.spawn(move || {
                // A failure (a value longer than the levels' bricks need, too) is left to the reads below, which
                // fetch and check again and report it.
                let _ = store.read_ahead(key, expected_bytes);
            });
        }
        Array::open(store.clone(), &format!("/{name}"))
    });
    let result = ranges
        .map_err(|e| bad(e.to_string()))
        .and_then(|ranges| check_minmax(&ranges, store, [bx, by, bz], volume_is_zero, &bad));
    if let Some(key) = &guessed {
        store.forget_ahead(key);
    }
    result
}

/// The checks of [`read_minmax`] once its array is open.
fn check_minmax(
    ranges: &Array<CheckedStore>,
    store: &Arc<CheckedStore>,
    [bx, by, bz]: [u64; 3],
    volume_is_zero: bool,
    bad: &dyn Fn(String) -> StoreError,
) -> Result<Vec<[f32; 2]>, StoreError> {
    if ranges.shape() != [bz, by, bx, 2] {
        return Err(bad(format!("shape {:?}, expected {:?}", ranges.shape(), [bz, by, bx, 2])));
    }
    if ranges.chunk_grid_shape() != [1, 1, 1, 1] {
        return Err(bad("expected one chunk holding the whole array".into()));
    }
    let expected_bytes = bx * by * bz * 8;
    let key = ranges.chunk_key(&[0, 0, 0, 0]);
    match store.size_key(&key).map_err(|e| bad(e.to_string()))? {
        Some(bytes) if bytes != expected_bytes => {
            return Err(bad(format!("{key} holds {bytes} bytes, expected {expected_bytes} (truncated or corrupt)")));
        }
        Some(_) => {}
        None if volume_is_zero => {}
        None => return Err(bad(format!("{key} is missing; import the volume again"))),
    }
    let flat: Vec<f32> = ranges.retrieve_array_subset(&ranges.subset_all()).map_err(|e| bad(e.to_string()))?;
    let entries: Vec<[f32; 2]> = flat.chunks_exact(2).map(|c| [c[0], c[1]]).collect();
    if let Some(index) = entries.iter().position(|[min, max]| !(min.is_finite() && max.is_finite() && min <= max)) {
        return Err(bad(format!("entry {index} is {:?}, expected finite min ≤ max", entries[index])));
    }
    Ok(entries)
}

/// Bytes of the CRC32C that follows each brick's zstd frame (stores written before it have none).
const BRICK_CHECKSUM_BYTES: u64 = 4;

/// Opens the remote store at `location`, with `access`'s timeouts, retries and disk cache.
fn open_remote(location: RemoteLocation, access: Option<&RemoteAccess>) -> Result<Arc<RemoteStore>, StoreError> {
    let shown = PathBuf::from(location.shown());
    let access = access.cloned().unwrap_or_default();
    let cache = match &access.cache_dir {
        Some(dir) => {
            Some(DiskCache::open(dir, access.cache_limit_bytes).map_err(|e| StoreError::store(&shown, e.to_string()))?)
        }
        None => None,
    };
    let store =
        RemoteStore::open(location, access.options, cache).map_err(|e| StoreError::store(&shown, e.to_string()))?;
    Ok(Arc::new(store))
}

/// Checks that the local `path` is a store's folder, naming an interrupted import or swap where there was one.
fn check_local_folder(path: &Path) -> Result<(), StoreError> {
    if path.is_dir() {
        return Ok(());
    }
    if let Some(aside) = aside_paths(path).first() {
        return Err(StoreError::store(
            path,
            format!(
                "missing: an `import --overwrite` was interrupted while swapping stores; the previous store is whole \
                 at {} (rename it back), or run the import again",
                aside.display()
            ),
        ));
    }
    if partial_path(path).is_dir() {
        return Err(StoreError::store(path, "incomplete store: its import was interrupted; run the import again"));
    }
    Err(StoreError::store(path, "no such store (expected a folder holding zarr.json)"))
}

impl StoreReader {
    /// Opens and validates the store at `path`, with a host-side cache of [`DEFAULT_CACHE_BYTES`].
    pub fn open(path: &Path) -> Result<StoreReader, StoreError> {
        StoreReader::open_with_cache(path, DEFAULT_CACHE_BYTES)
    }

    /// Opens and validates the store at `path`; bricks read from disk are kept decoded in RAM up to `cache_bytes`,
    /// least recently used first out.
    pub fn open_with_cache(path: &Path, cache_bytes: u64) -> Result<StoreReader, StoreError> {
        StoreReader::open_with_options(path, cache_bytes, &ForeignOptions::default())
    }

    /// As [`StoreReader::open_with_cache`]; a foreign (not voxstream-written) store is opened with `foreign`.
    pub fn open_with_options(
        path: &Path,
        cache_bytes: u64,
        foreign: &ForeignOptions,
    ) -> Result<StoreReader, StoreError> {
        // A URL names a remote store: it is read through the same checks, its bytes fetched by ranges.
        let location = voxstream_remote::RemoteLocation::parse(path.to_str().unwrap_or(""))
            .map_err(|e| StoreError::store(voxstream_remote::redact(&path.to_string_lossy()), e.to_string()))?;
        let remote = match location {
            Some(location) => Some(open_remote(location, foreign.remote)?),
            None => {
                check_local_folder(path)?;
                None
            }
        };
        // From here on, `path` is what messages show: for a remote store its URL without credentials.
        let shown = remote.as_ref().map_or_else(|| path.to_path_buf(), |r| PathBuf::from(r.location().shown()));
        let path = shown.as_path();
        let check_metadata = |node: &str| match remote {
            // A remote store holds metadata reads to the JSON cap itself (see voxstream_remote::RemoteStore).
            Some(_) => Ok(()),
            None => check_node_metadata(path, node),
        };
        // Every read goes through checks of its byte range and file kind, and every decoder stops at the chunk's
        // size (see `checked_store` and `strict_codecs`): a forged shard index or a decompression bomb is an error.
        crate::strict_codecs::register();
        let checked = |max_range_bytes| match &remote {
            Some(remote) => Ok(CheckedStore::remote(remote.clone(), max_range_bytes)),
            None => CheckedStore::new(path, max_range_bytes).map_err(|e| StoreError::store(path, e.to_string())),
        };
        let store = Arc::new(checked(u64::MAX)?);
        check_metadata("")?;
        let group = Group::open(store.clone(), "/").map_err(|e| match (&remote, &e) {
            (Some(_), zarrs::group::GroupCreateError::MissingMetadata) => StoreError::store(
                path,
                "no zarr.json (nor .zattrs) there: check that the URL names the store's root folder, the one holding \
                 zarr.json",
            ),
            // A remote store's read failed (the network, the server, TLS): its message says why; the file may be fine.
            (Some(_), zarrs::group::GroupCreateError::StorageError(e)) => {
                StoreError::store(path, format!("cannot read zarr.json: {e}"))
            }
            _ => StoreError::store(path, format!("missing or corrupt zarr.json: {e}")),
        })?;
        let attributes: StoreAttributes = match group.attributes().get("voxstream") {
            Some(value) => serde_json::from_value(value.clone()).map_err(|e| match null_field(value) {
                // serde_json writes a non-finite number as null: name the field.
                Some(field) => {
                    StoreError::metadata(path, field, "is null (a non-finite number?); import the volume again")
                }
                None => StoreError::store(path, format!("corrupt voxstream attributes: {e}")),
            })?,
            None => {
                // A quarter of the host cache keeps chunks as stored, the rest decoded chunks and bricks.
                let metrics = Arc::new(PerformanceMetricsStorageAdapter::new(store.clone()));
                let encoded = Arc::new(EncodedCache::new(metrics.clone(), cache_bytes / 4));
                let chunk_source = match &remote {
                    Some(remote) => ChunkSource::Remote(remote),
                    None => ChunkSource::Folder(path),
                };
                let (attributes, levels, scan, planes) =
                    crate::foreign::open_foreign(path, encoded, group.attributes(), foreign, &chunk_source)?;
                let mut reader = StoreReader::assemble(path, attributes, levels, None, cache_bytes - cache_bytes / 4)?;
                reader.planes = planes;
                reader.metrics = Some(metrics);
                reader.remote = remote;
                if let Some((level, stored)) = scan {
                    reader.scan_value_range(level, &stored, foreign.progress.unwrap_or(&|_, _| {}))?;
                }
                reader.probe_levels()?;
                return Ok(reader);
            }
        };
        if !attributes.complete {
            return Err(StoreError::store(path, "incomplete store: its import was interrupted; run the import again"));
        }
        let (info, layout) = validate_attributes(path, &attributes)?;
        // A brick read from a shard is at most one zstd frame of brick_size³ samples and its CRC32C; a wavelet brick
        // at most that frame (of its byte-shuffled samples, its fallback) after its header.
        let brick_bytes = layout.brick_size.pow(3) * info.dtype.size() as u64;
        let header_bytes = match attributes.brick_codec {
            Some(crate::import::BrickCodec::Wavelet { .. }) => {
                voxstream_wavelet::header_len(voxstream_wavelet::DType::F32)
            }
            _ => 0,
        } as u64;
        // Half of the host cache keeps bricks as stored (compressed: several to tens of times more of the volume fit
        // than decoded, as f32), so that a brick the decoded cache let go is decoded again from memory, not read or
        // fetched again (Reichl's compressed host cache). A quarter was too little for a remote store: on the 2048³
        // store at `--budget-mb 512`, 3,460 ranges were fetched twice, 10,700 requests and 92 MB for a view that
        // needs 4,513 and 41 MB (BENCHMARKS.md, "Against tensorstore").
        // `--compressed-cache-mb` gives it a budget of its own, besides the host cache (then all decoded).
        let (range_cache_bytes, decoded_cache_bytes) =
            match foreign.remote.and_then(|access| access.compressed_cache_bytes) {
                Some(bytes) => (bytes, cache_bytes),
                None => (cache_bytes / 2, cache_bytes - cache_bytes / 2),
            };
        let bricks_store = Arc::new(
            checked(zstd_encoded_bound(brick_bytes, BRICK_CHECKSUM_BYTES + header_bytes))?
                .with_range_cache(range_cache_bytes),
        );
        let metrics = Arc::new(PerformanceMetricsStorageAdapter::new(bricks_store.clone()));
        let volume_is_zero = attributes.value_range == [0.0, 0.0];
        let open_array = |level: usize| -> Result<Array<dyn ReadableStorageTraits>, StoreError> {
            let readable: Arc<dyn ReadableStorageTraits> = metrics.clone();
            let array = Array::open(readable, &format!("/{level}"))
                .map_err(|e| StoreError::store(path, format!("level {level}: {e}")))?;
            let [x, y, z] = layout.level_dims[level];
            if array.shape() != [z, y, x] {
                return Err(StoreError::store(
                    path,
                    format!("level {level} has shape {:?}, expected {:?}", array.shape(), [z, y, x]),
                ));
            }
            check_chunk_sizes(path, &level.to_string(), &metadata_json(&array))?;
            check_level_dtype(path, &level.to_string(), &array, info.dtype)?;
            Ok(array)
        };
        let open_level = |level: usize| -> Result<(LevelSource, Vec<[f32; 2]>), StoreError> {
            for node in [level.to_string(), MINMAX_GROUP.to_string(), format!("{MINMAX_GROUP}/{level}")] {
                check_metadata(&node)?;
            }
            let minmax = || read_minmax(path, &store, &layout, level, volume_is_zero, remote.is_some());
            // Over a network the level's array and its min/max are read at once (their round trips overlap); the
            // level's error, if both fail, is the one reported.
            let (array, ranges) = if remote.is_some() {
                let (array, ranges) = std::thread::scope(|scope| {
                    let ranges = scope.spawn(minmax);
                    let array = open_array(level);
                    let ranges = ranges
                        .join()
                        .unwrap_or_else(|_| Err(StoreError::store(path, "reading a level's min/max panicked")));
                    (array, ranges)
                });
                (array?, ranges?)
            } else {
                (open_array(level)?, minmax()?)
            };
            let [x, y, z] = layout.level_dims[level];
            Ok((LevelSource::Array { array, leading: Default::default(), shape: [x, y, z] }, ranges))
        };
        // A remote store's levels are opened at once (each a few round trips); a folder's in turn. Either way the
        // first level that fails, in level order, is the one reported.
        let opened: Vec<Result<(LevelSource, Vec<[f32; 2]>), StoreError>> = if remote.is_some() {
            let open_level = &open_level;
            std::thread::scope(|scope| {
                let handles: Vec<_> =
                    (0..layout.levels()).map(|level| scope.spawn(move || open_level(level))).collect();
                handles
                    .into_iter()
                    .map(|h| h.join().unwrap_or_else(|_| Err(StoreError::store(path, "opening a level panicked"))))
                    .collect()
            })
        } else {
            (0..layout.levels()).map(open_level).collect()
        };
        let mut levels = Vec::new();
        let mut minmax = Vec::new();
        for result in opened {
            let (level, ranges) = result?;
            levels.push(level);
            minmax.push(ranges);
        }
        // The coarsest level's one brick covers every sample: its range is the volume's.
        let root = minmax.last().and_then(|m| m.first()).copied().unwrap_or([0.0, 0.0]);
        let [lo, hi] = attributes.value_range;
        let exact = [lo as f32, hi as f32];
        // A lossy codec's bricks decode within its bound of the values imported: so do their ranges.
        let agrees = match attributes.brick_codec.filter(|c| c.is_lossy()) {
            None => root == exact,
            Some(codec) => {
                let e = codec.max_error() as f32;
                let slack = e + (lo.abs().max(hi.abs()) as f32 + e) * 4.0 * f32::EPSILON;
                (root[0] - exact[0]).abs() <= slack && (root[1] - exact[1]).abs() <= slack && root[0] <= root[1]
            }
        };
        if !agrees {
            return Err(StoreError::metadata(
                path,
                "value_range",
                format!(
                    "{:?} disagrees with the per-brick min/max of the whole volume {root:?}",
                    attributes.value_range
                ),
            ));
        }
        let mut reader = StoreReader::assemble(path, attributes, levels, Some(minmax), decoded_cache_bytes)?;
        reader.metrics = Some(metrics);
        reader.remote = remote;
        reader.bricks_store = Some(bricks_store.clone());
        if reader.remote.is_some() {
            // The coarse levels' shard indexes are fetched while the levels are probed (see `shard_indexes`).
            let indexes = reader.shard_indexes_to_fetch();
            let reader = &reader;
            std::thread::scope(|scope| {
                scope.spawn(|| StoreReader::fetch_shard_indexes(&bricks_store, &indexes));
                reader.probe_levels()
            })?;
        } else {
            reader.probe_levels()?;
        }
        Ok(reader)
    }
}
