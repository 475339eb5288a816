//! Opening a store: validating its metadata once, then reading regions of any level and per-brick min/max.
//!
//! Stores written by voxstream carry `attributes.voxstream` (see [`crate::metadata`]). An import that did not finish
//! leaves only `STORE.partial`, never a `STORE` that opens.
//!
//! Reads go brick by brick (one inner chunk of a shard: the shard index, then only that chunk's bytes) through a
//! host-side LRU cache of decoded bricks (Reichl's host cache, seed 004 ch. 4). A brick's one-voxel border comes from
//! up to 26 neighbours, which the rays usually need next anyway, so the cache turns border reads into hits. The
//! cache's size is part of the memory budget (see `voxstream render --budget-mb`). Foreign images whose chunks do
//! not tile the bricks also keep decoded chunks ([`crate::chunk_cache`]) and chunks as stored
//! ([`crate::encoded_cache`]) within the same bytes, and get their value range from level 0 at open
//! ([`crate::value_range`]).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use std::num::NonZeroUsize;
use std::sync::Mutex;

use lru::LruCache;
use zarrs::array::{Array, ArraySubset};
use zarrs::group::Group;
use zarrs::storage::storage_adapter::performance_metrics::PerformanceMetricsStorageAdapter;
use zarrs::storage::ReadableStorageTraits;

use voxstream_remote::{DiskCache, RemoteLocation, RemoteStore};

use crate::checked_store::{zstd_encoded_bound, CheckedStore};
use crate::chunk_cache::ChunkCache;
use crate::chunk_keys::ChunkSource;
use crate::encoded_cache::EncodedCache;
use crate::error::StoreError;
use crate::foreign::ForeignOptions;
use crate::import::{aside_paths, partial_path};
use crate::layout::PyramidLayout;
use crate::level_probe::check_level_dtype;
use crate::level_source::{retrieve_f32, LevelSource};
use crate::metadata::{StoreAttributes, MINMAX_GROUP};
use crate::metadata_check::{check_chunk_sizes, validate_attributes};
use crate::metadata_files::check_node_metadata;
use crate::remote_access::RemoteAccess;
use crate::value_range::{bricks_over_stored_chunks, fold_samples, unwritten_fill_value, ScanProgress, EMPTY_RANGE};
use crate::volume::VolumeInfo;

/// Extends `data` (dims `have`, x fastest) to dims `want` by repeating its last samples.
fn pad_to(data: &[f32], have: [u64; 3], want: [u64; 3]) -> Vec<f32> {
    if have == want {
        return data.to_vec();
    }
    let mut out = Vec::with_capacity((want[0] * want[1] * want[2]) as usize);
    for z in 0..want[2] {
        for y in 0..want[1] {
            for x in 0..want[0] {
                let (sx, sy, sz) = (x.min(have[0] - 1), y.min(have[1] - 1), z.min(have[2] - 1));
                out.push(data[((sz * have[1] + sy) * have[0] + sx) as usize]);
            }
        }
    }
    out
}

/// 2×2×2 means of `data` (dims `size`, x fastest); odd edges average the samples that exist.
fn average_2x(data: &[f32], size: [u64; 3]) -> Vec<f32> {
    let [nx, ny, nz] = size.map(|v| v as usize);
    let [ox, oy, oz] = [nx.div_ceil(2), ny.div_ceil(2), nz.div_ceil(2)];
    let mut out = Vec::with_capacity(ox * oy * oz);
    for z in 0..oz {
        for y in 0..oy {
            for x in 0..ox {
                let (mut sum, mut n) = (0f64, 0u32);
                for (dx, dy, dz) in
                    [(0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0), (0, 0, 1), (1, 0, 1), (0, 1, 1), (1, 1, 1)]
                {
                    let (sx, sy, sz) = (2 * x + dx, 2 * y + dy, 2 * z + dz);
                    if sx < nx && sy < ny && sz < nz {
                        sum += data[(sz * ny + sy) * nx + sx] as f64;
                        n += 1;
                    }
                }
                out.push((sum / n as f64) as f32);
            }
        }
    }
    out
}

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
/// exactly `8 ·` bricks bytes (checked before reading, so a forged brick count allocates nothing), and every entry
/// must be finite with `min ≤ max`. The chunk may be absent only when the whole volume is 0 (the Zarr fill value):
/// otherwise a missing file would read as empty space.
fn read_minmax(
    path: &Path,
    store: &Arc<CheckedStore>,
    layout: &PyramidLayout,
    level: usize,
    volume_is_zero: bool,
) -> Result<Vec<[f32; 2]>, StoreError> {
    let name = format!("{MINMAX_GROUP}/{level}");
    let bad = |problem: String| StoreError::store(path, format!("min/max of level {level} ({name}): {problem}"));
    let ranges = Array::open(store.clone(), &format!("/{name}")).map_err(|e| bad(e.to_string()))?;
    let [bx, by, bz] = layout.bricks(level);
    if ranges.shape() != [bz, by, bx, 2] {
        return Err(bad(format!("shape {:?}, expected {:?}", ranges.shape(), [bz, by, bx, 2])));
    }
    if ranges.chunk_grid_shape() != [1, 1, 1, 1] {
        return Err(bad("expected one chunk holding the whole array".into()));
    }
    let expected_bytes = bx * by * bz * 8;
    let key = ranges.chunk_key(&[0, 0, 0, 0]);
    let stored_bytes = store.size_key(&key).map_err(|e| bad(e.to_string()))?;
    match stored_bytes {
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

/// Default size of the host-side brick cache.
pub const DEFAULT_CACHE_BYTES: u64 = 64 << 20;

/// An open store.
pub struct StoreReader {
    path: PathBuf,
    attributes: StoreAttributes,
    info: VolumeInfo,
    layout: PyramidLayout,
    /// Per level, where its bricks come from: an array of the store, or (foreign stores whose pyramid lacks the
    /// level) the 2×2×2 average of the level below.
    levels: Vec<LevelSource>,
    /// Decoded bricks (inner chunks) by level and brick index, least recently used first out.
    brick_cache: Mutex<LruCache<(usize, [u64; 3]), Arc<Vec<f32>>>>,
    cache_bytes: u64,
    /// Decoded chunks of foreign arrays whose chunks do not tile the bricks (a share of `cache_bytes`).
    chunk_cache: ChunkCache,
    /// Counts the bytes the level arrays read from the storage.
    metrics: Option<Arc<PerformanceMetricsStorageAdapter<CheckedStore>>>,
    /// Samples read from a foreign store that lay outside its value range (they saturate).
    clipped: std::sync::atomic::AtomicU64,
    /// The level scanned for a foreign store's value range (see [`StoreReader::value_range_level`]).
    value_range_level: usize,
    /// A background prefetch is running.
    prefetching: std::sync::atomic::AtomicBool,
    /// Per level, per brick (x fastest): `[min, max]` of the full-resolution samples below it; `None` for foreign
    /// stores, whose bricks' ranges are unknown until read (the brick pool computes them on upload).
    minmax: Option<Vec<Vec<[f32; 2]>>>,
    /// The remote store the bricks come from, `None` for a local folder.
    remote: Option<Arc<RemoteStore>>,
    /// Bricks being read now, so that a brick wanted by several threads is read once.
    reading: crate::single_flight::SingleFlight<(usize, [u64; 3])>,
    /// Background fetching for frames that must not wait (see [`StoreReader::set_nonblocking`]).
    background: Background,
}

/// Bricks fetched behind the frames of an interactive session over a remote store.
#[derive(Default)]
struct Background {
    /// Whether [`StoreReader::region_ready`] fetches in the background instead of answering "ready".
    on: std::sync::atomic::AtomicBool,
    /// Threads fetching (as many as the remote store's concurrency).
    pool: std::sync::OnceLock<Option<rayon::ThreadPool>>,
    /// Bricks being fetched.
    fetching: Mutex<std::collections::HashSet<(usize, [u64; 3])>>,
    /// Bricks whose background fetch failed: produced in the foreground, which reports the failure.
    failed: Mutex<std::collections::HashSet<(usize, [u64; 3])>>,
}

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
                let (attributes, levels, scan) =
                    crate::foreign::open_foreign(path, encoded, group.attributes(), foreign, &chunk_source)?;
                let mut reader = StoreReader::assemble(path, attributes, levels, None, cache_bytes - cache_bytes / 4)?;
                reader.cache_bytes = cache_bytes;
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
        // A brick read from a shard is at most one zstd frame of brick_size³ samples and its CRC32C.
        let brick_bytes = layout.brick_size.pow(3) * info.dtype.size() as u64;
        // A remote store keeps a quarter of the host cache for bricks as fetched (compressed: many more fit), so
        // that a border brick the decoded cache let go is not fetched again.
        let range_cache_bytes = if remote.is_some() { cache_bytes / 4 } else { 0 };
        let bricks_store = Arc::new(
            checked(zstd_encoded_bound(brick_bytes, BRICK_CHECKSUM_BYTES))?.with_range_cache(range_cache_bytes),
        );
        let metrics = Arc::new(PerformanceMetricsStorageAdapter::new(bricks_store));
        let open_level = |level: usize| -> Result<(LevelSource, Vec<[f32; 2]>), StoreError> {
            let readable: Arc<dyn ReadableStorageTraits> = metrics.clone();
            for node in [level.to_string(), MINMAX_GROUP.to_string(), format!("{MINMAX_GROUP}/{level}")] {
                check_metadata(&node)?;
            }
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
            let ranges = read_minmax(path, &store, &layout, level, attributes.value_range == [0.0, 0.0])?;
            Ok((LevelSource::Array { array, leading: 0, shape: [x, y, z] }, ranges))
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
        if root != [lo as f32, hi as f32] {
            return Err(StoreError::metadata(
                path,
                "value_range",
                format!(
                    "{:?} disagrees with the per-brick min/max of the whole volume {root:?}",
                    attributes.value_range
                ),
            ));
        }
        let mut reader =
            StoreReader::assemble(path, attributes, levels, Some(minmax), cache_bytes - range_cache_bytes)?;
        reader.cache_bytes = cache_bytes;
        reader.metrics = Some(metrics);
        reader.remote = remote;
        reader.probe_levels()?;
        Ok(reader)
    }

    /// A reader over validated parts; `minmax` is `None` when the store has no per-brick ranges (foreign stores).
    pub(crate) fn assemble(
        path: &Path,
        attributes: StoreAttributes,
        levels: Vec<LevelSource>,
        minmax: Option<Vec<Vec<[f32; 2]>>>,
        cache_bytes: u64,
    ) -> Result<StoreReader, StoreError> {
        let (info, layout) = validate_attributes(path, &attributes)?;
        // Foreign chunks that do not tile the bricks take half of `cache_bytes` for decoded chunks.
        let chunk_cache = ChunkCache::new(&levels, attributes.brick_size, cache_bytes / 2);
        let brick_cache_bytes = if chunk_cache.is_used() { cache_bytes - cache_bytes / 2 } else { cache_bytes };
        let chunk_cache =
            if chunk_cache.is_used() { chunk_cache } else { ChunkCache::new(&[], attributes.brick_size, 0) };
        // The cache holds at most `brick_cache_bytes` of decoded bricks (each at most brick_size³ f32), at least one.
        let brick_bytes = attributes.brick_size.pow(3) * 4;
        let capacity = NonZeroUsize::new((brick_cache_bytes / brick_bytes) as usize).unwrap_or(NonZeroUsize::MIN);
        let brick_cache = Mutex::new(LruCache::new(capacity));
        Ok(StoreReader {
            path: path.into(),
            attributes,
            info,
            layout,
            levels,
            brick_cache,
            cache_bytes,
            chunk_cache,
            metrics: None,
            clipped: std::sync::atomic::AtomicU64::new(0),
            value_range_level: 0,
            prefetching: std::sync::atomic::AtomicBool::new(false),
            minmax,
            remote: None,
            reading: crate::single_flight::SingleFlight::new(),
            background: Background::default(),
        })
    }

    /// The store's folder.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// voxstream's attributes.
    pub fn attributes(&self) -> &StoreAttributes {
        &self.attributes
    }

    /// Geometry and type of level 0.
    pub fn info(&self) -> &VolumeInfo {
        &self.info
    }

    /// Levels and bricks.
    pub fn layout(&self) -> &PyramidLayout {
        &self.layout
    }

    /// `[min, max]` of brick `ijk` of `level` (`[-∞, +∞]` when unknown), or `None` outside the grid.
    pub fn brick_range(&self, level: usize, ijk: [u64; 3]) -> Option<[f32; 2]> {
        let b = self.layout.bricks(level);
        if (0..3).any(|a| ijk[a] >= b[a]) {
            return None;
        }
        Some(match &self.minmax {
            Some(minmax) => minmax[level][((ijk[2] * b[1] + ijk[1]) * b[0] + ijk[0]) as usize],
            None => [f32::NEG_INFINITY, f32::INFINITY],
        })
    }

    /// Whether the store was written by voxstream (it has per-brick ranges and exact pyramid levels).
    pub fn is_native(&self) -> bool {
        self.minmax.is_some()
    }

    /// Reads samples `[lower, lower + size)` (x, y, z) of `level` as `f32`, x fastest, assembled from the bricks
    /// that overlap it (each read once from disk, then from the brick cache).
    pub fn read_region(&self, level: usize, lower: [u64; 3], size: [u64; 3]) -> Result<Vec<f32>, StoreError> {
        let b = self.layout.brick_size;
        let dims = self.layout.level_dims[level];
        let upper = [0, 1, 2].map(|a| lower[a] + size[a]);
        if (0..3).any(|a| upper[a] > dims[a] || size[a] == 0) {
            return Err(StoreError::store(&self.path, format!("region {lower:?}+{size:?} outside level {level}")));
        }
        let mut out = vec![0f32; (size[0] * size[1] * size[2]) as usize];
        let first = lower.map(|v| v / b);
        let last = [0, 1, 2].map(|a| (upper[a] - 1) / b);
        let mut ijks = Vec::new();
        for bz in first[2]..=last[2] {
            for by in first[1]..=last[1] {
                for bx in first[0]..=last[0] {
                    ijks.push([bx, by, bz]);
                }
            }
        }
        // A remote store's bricks (a node's and its neighbours', for the border) are fetched at once, each a round
        // trip; a local folder's one after another.
        let bricks: Vec<Arc<Vec<f32>>> = if self.remote.is_some() && ijks.len() > 1 {
            use rayon::prelude::*;
            ijks.par_iter().map(|&ijk| self.brick(level, ijk)).collect::<Result<_, _>>()?
        } else {
            ijks.iter().map(|&ijk| self.brick(level, ijk)).collect::<Result<_, _>>()?
        };
        for (&ijk, brick) in ijks.iter().zip(&bricks) {
            {
                {
                    let origin = ijk.map(|v| v * b);
                    let extent = [0, 1, 2].map(|a| (origin[a] + b).min(dims[a]) - origin[a]);
                    let from = [0, 1, 2].map(|a| origin[a].max(lower[a]));
                    let to = [0, 1, 2].map(|a| (origin[a] + extent[a]).min(upper[a]));
                    let run = (to[0] - from[0]) as usize;
                    for z in from[2]..to[2] {
                        for y in from[1]..to[1] {
                            let src = (((z - origin[2]) * extent[1] + (y - origin[1])) * extent[0]
                                + (from[0] - origin[0])) as usize;
                            let dst =
                                (((z - lower[2]) * size[1] + (y - lower[1])) * size[0] + (from[0] - lower[0])) as usize;
                            out[dst..dst + run].copy_from_slice(&brick[src..src + run]);
                        }
                    }
                }
            }
        }
        Ok(out)
    }

    /// Sessions over a remote store: with `on`, [`StoreReader::region_ready`] starts fetching what is missing in
    /// the background and answers "not yet", so that interactive frames never wait on the network (converged
    /// frames do not ask: `ServeOptions::wait_for_data`). No effect on local stores.
    pub fn set_nonblocking(&self, on: bool) {
        self.background.on.store(on && self.remote.is_some(), std::sync::atomic::Ordering::Relaxed);
    }

    /// Whether the bricks of `[lower, lower + size)` of `level` can be read without waiting on the network: always
    /// for local stores and unless [`StoreReader::set_nonblocking`] is on; otherwise whether they are all in the
    /// cache (or known to hold only 0), the missing ones being fetched in the background when not.
    pub fn region_ready(self: &Arc<Self>, level: usize, lower: [u64; 3], size: [u64; 3]) -> bool {
        use std::sync::atomic::Ordering;
        if !self.background.on.load(Ordering::Relaxed) {
            return true;
        }
        let b = self.layout.brick_size;
        let first = lower.map(|v| v / b);
        let last = [0, 1, 2].map(|a| (lower[a] + size[a]).saturating_sub(1) / b);
        let mut missing = Vec::new();
        {
            let cache = self.brick_cache.lock().unwrap_or_else(|p| p.into_inner());
            for z in first[2]..=last[2] {
                for y in first[1]..=last[1] {
                    for x in first[0]..=last[0] {
                        let ijk = [x, y, z];
                        if !cache.contains(&(level, ijk)) && !self.holds_only_zero(level, ijk) {
                            missing.push(ijk);
                        }
                    }
                }
            }
        }
        if missing.is_empty() {
            return true;
        }
        let failed = self.background.failed.lock().unwrap_or_else(|p| p.into_inner());
        if missing.iter().any(|&ijk| failed.contains(&(level, ijk))) {
            return true;
        }
        drop(failed);
        // A region is fetched whole or not yet: started in the rays' order, regions complete one after another,
        // rather than every region of the frame getting a few of its bricks, which the cache would let go before the
        // rest arrive.
        let keys: Vec<(usize, [u64; 3])> = missing.into_iter().map(|ijk| (level, ijk)).collect();
        self.fetch_in_background(keys, true);
        false
    }

    /// Starts reading `bricks` on the remote store's fetch threads (each at most once at a time), so that no worker
    /// of the shared pool, which draws the frames, waits on the network; with `whole`, all of them or (when they
    /// would not fit under the bound of bricks in flight) none. Failures are remembered (see
    /// [`StoreReader::region_ready`]). Returns `false` when no thread could be made (nothing started).
    fn fetch_in_background(self: &Arc<Self>, bricks: Vec<(usize, [u64; 3])>, whole: bool) -> bool {
        let threads = self.remote.as_ref().map_or(1, |r| r.concurrency()).max(1);
        let pool = self.background.pool.get_or_init(|| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .thread_name(|i| format!("voxstream-prefetch-{i}"))
                .build()
                .ok()
        });
        let Some(pool) = pool.as_ref() else {
            return false;
        };
        // At most a quarter of the brick cache is fetched at a time: bricks fetched faster than frames use them
        // would push one another out of the cache before they are drawn.
        let capacity = self.brick_cache.lock().unwrap_or_else(|p| p.into_inner()).cap().get();
        let limit = (capacity / 4).max(1);
        let mut fetching = self.background.fetching.lock().unwrap_or_else(|p| p.into_inner());
        let new = bricks.iter().filter(|key| !fetching.contains(key)).count();
        if whole && !fetching.is_empty() && fetching.len() + new > limit {
            return true;
        }
        for key in bricks {
            if fetching.len() >= limit {
                break;
            }
            if fetching.insert(key) {
                let reader = Arc::clone(self);
                pool.spawn(move || {
                    if reader.brick(key.0, key.1).is_err() {
                        reader.background.failed.lock().unwrap_or_else(|p| p.into_inner()).insert(key);
                    }
                    reader.background.fetching.lock().unwrap_or_else(|p| p.into_inner()).remove(&key);
                });
            }
        }
        true
    }

    /// Whether brick `ijk` of `level` holds only 0 by its min/max (nothing to read).
    fn holds_only_zero(&self, level: usize, ijk: [u64; 3]) -> bool {
        let Some(minmax) = &self.minmax else { return false };
        let b = self.layout.bricks(level);
        (0..3).all(|a| ijk[a] < b[a])
            && minmax[level][((ijk[2] * b[1] + ijk[1]) * b[0] + ijk[0]) as usize] == [0.0, 0.0]
    }

    /// The samples of brick `ijk` of `level` (clipped to the level), x fastest, from the cache or the disk.
    fn brick(&self, level: usize, ijk: [u64; 3]) -> Result<Arc<Vec<f32>>, StoreError> {
        let key = (level, ijk);
        if let Some(brick) = self.brick_cache.lock().unwrap_or_else(|p| p.into_inner()).get(&key) {
            return Ok(brick.clone());
        }
        // Threads after the same brick wait for one read (see `single_flight`).
        self.reading.run(&key, || {
            if let Some(brick) = self.brick_cache.lock().unwrap_or_else(|p| p.into_inner()).get(&key) {
                return Ok(brick.clone());
            }
            self.read_brick(level, ijk)
        })
    }

    /// Reads brick `ijk` of `level` from the store into the brick cache.
    fn read_brick(&self, level: usize, ijk: [u64; 3]) -> Result<Arc<Vec<f32>>, StoreError> {
        let key = (level, ijk);
        // A brick whose min/max is [0, 0] holds only the fill value: nothing to read (its shard may not exist).
        if let Some(minmax) = &self.minmax {
            let b = self.layout.bricks(level);
            if (0..3).all(|a| ijk[a] < b[a])
                && minmax[level][((ijk[2] * b[1] + ijk[1]) * b[0] + ijk[0]) as usize] == [0.0, 0.0]
            {
                let dims = self.layout.level_dims[level];
                let size = self.layout.brick_size;
                let extent: u64 = (0..3).map(|a| (ijk[a] * size + size).min(dims[a]) - ijk[a] * size).product();
                let brick = Arc::new(vec![0.0; extent as usize]);
                self.brick_cache.lock().unwrap_or_else(|p| p.into_inner()).put(key, brick.clone());
                return Ok(brick);
            }
        }
        let b = self.layout.brick_size;
        let dims = self.layout.level_dims[level];
        let lower = ijk.map(|v| v * b);
        let upper = [0, 1, 2].map(|a| (lower[a] + b).min(dims[a]));
        let samples = match &self.levels[level] {
            LevelSource::Array { array, leading, shape } => {
                let read_upper = [0, 1, 2].map(|a| upper[a].min(shape[a]));
                if (0..3).any(|a| read_upper[a] <= lower[a]) {
                    // The foreign level is one sample short here: repeat its last samples.
                    let inner = [0, 1, 2].map(|a| lower[a].min(shape[a] - 1));
                    let got = self.read_array(level, array, *leading, inner, [0, 1, 2].map(|a| inner[a] + 1))?;
                    vec![got[0]; ((upper[0] - lower[0]) * (upper[1] - lower[1]) * (upper[2] - lower[2])) as usize]
                } else {
                    let got = if self.chunk_cache.caches(level) {
                        let corrupt = |e: zarrs::array::ArrayError| {
                            StoreError::store(
                                &self.path,
                                format!("level {level}, samples {lower:?}..{read_upper:?}: {e}"),
                            )
                        };
                        let dtype = self.info.dtype;
                        self.chunk_cache
                            .read(level, array, *leading, *shape, dtype, lower, read_upper)
                            .map_err(corrupt)?
                    } else {
                        self.read_array(level, array, *leading, lower, read_upper)?
                    };
                    self.check_brick(level, ijk, array, &got)?;
                    self.count_clipped(&got);
                    pad_to(&got, [0, 1, 2].map(|a| read_upper[a] - lower[a]), [0, 1, 2].map(|a| upper[a] - lower[a]))
                }
            }
            LevelSource::Synthesized => {
                let finer = self.layout.level_dims[level - 1];
                let f_lower = lower.map(|v| 2 * v);
                let f_upper = [0, 1, 2].map(|a| (2 * upper[a]).min(finer[a]));
                let size = [0, 1, 2].map(|a| f_upper[a] - f_lower[a]);
                let fine = self.read_region(level - 1, f_lower, size)?;
                average_2x(&fine, size)
            }
        };
        let brick = Arc::new(samples);
        self.brick_cache.lock().unwrap_or_else(|p| p.into_inner()).put(key, brick.clone());
        Ok(brick)
    }

    /// Where the samples of `level` come from (`None` past the coarsest level).
    pub(crate) fn level_source(&self, level: usize) -> Option<&LevelSource> {
        self.levels.get(level)
    }

    /// Whether some level is averaged from the finer one when read (a foreign store that lacks it), so that its
    /// samples may be fractions even for an integer sample type.
    pub fn has_synthesized_levels(&self) -> bool {
        self.levels.iter().any(|level| matches!(level, LevelSource::Synthesized))
    }

    /// Native stores: a brick read from disk must agree with its min/max, else it is a failure, never empty space.
    /// A brick whose min/max says it holds data needs its shard file (zarrs would read a missing one as zeros); at
    /// level 0 the samples' range must equal the recorded one exactly (it was computed from these very samples), at
    /// coarser levels lie within it (a mean stays within what it averages).
    fn check_brick(
        &self,
        level: usize,
        ijk: [u64; 3],
        array: &Array<dyn ReadableStorageTraits>,
        samples: &[f32],
    ) -> Result<(), StoreError> {
        let Some(minmax) = &self.minmax else {
            return Ok(());
        };
        let b = self.layout.bricks(level);
        let [min, max] = minmax[level][((ijk[2] * b[1] + ijk[1]) * b[0] + ijk[0]) as usize];
        let failure =
            |problem: String| StoreError::store(&self.path, format!("level {level}, brick {ijk:?}: {problem}"));
        let (lo, hi) = samples.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| (lo.min(v), hi.max(v)));
        // A missing shard reads as the fill value, 0, throughout: only a brick that read as all 0 while its min/max
        // says otherwise needs its shard looked for (a size request, a round trip on a remote store).
        if [min, max] != [0.0, 0.0] && [lo, hi] == [0.0, 0.0] {
            let lower = ijk.map(|v| v * self.layout.brick_size);
            let shard = array.chunk_shape(&[0, 0, 0]).map_err(|e| failure(e.to_string()))?;
            let indices = [lower[2] / shard[0].get(), lower[1] / shard[1].get(), lower[0] / shard[2].get()];
            let key = array.chunk_key(&indices);
            match array.storage().size_key(&key) {
                Ok(Some(_)) => {}
                Ok(None) => {
                    return Err(failure(format!(
                        "shard {key} is missing, but the brick's min/max says it holds values {min} to {max}"
                    )))
                }
                Err(e) => return Err(failure(e.to_string())),
            }
        }
        let agrees = if level == 0 { lo == min && hi == max } else { lo >= min && hi <= max };
        if !agrees {
            return Err(failure(format!(
                "reads as values {lo} to {hi}, but its min/max says {min} to {max}: the shard is corrupt"
            )));
        }
        Ok(())
    }

    fn read_array(
        &self,
        level: usize,
        array: &Array<dyn ReadableStorageTraits>,
        leading: usize,
        lower: [u64; 3],
        upper: [u64; 3],
    ) -> Result<Vec<f32>, StoreError> {
        let mut ranges: Vec<std::ops::Range<u64>> = vec![0..1; leading];
        ranges.extend([lower[2]..upper[2], lower[1]..upper[1], lower[0]..upper[0]]);
        let subset = ArraySubset::new_with_ranges(&ranges);
        let corrupt = |e: zarrs::array::ArrayError| {
            use zarrs::array::{codec::api::CodecError, ArrayError};
            let problem = match e {
                ArrayError::CodecError(CodecError::InvalidChecksum) => {
                    "a brick's CRC32C does not match its bytes: the shard is corrupt; import the volume again".into()
                }
                e => e.to_string(),
            };
            StoreError::store(&self.path, format!("level {level}, samples {lower:?}..{upper:?}: {problem}"))
        };
        retrieve_f32(array, &subset, self.info.dtype).map_err(corrupt)
    }

    /// Reads `bricks` into the brick cache on a background worker (skipping those already cached or outside the
    /// level), at most one prefetch batch at a time; errors are left for `produce` to report.
    pub fn prefetch(self: &Arc<Self>, bricks: Vec<(usize, [u64; 3])>) {
        use std::sync::atomic::Ordering;
        // A remote store's bricks are fetched on its own threads, many at once: a worker of the shared pool waiting
        // on the network would hold up the frames drawn on it.
        if self.remote.is_some() {
            let cache = self.brick_cache.lock().unwrap_or_else(|p| p.into_inner());
            let wanted: Vec<(usize, [u64; 3])> = bricks
                .into_iter()
                .filter(|&(level, ijk)| {
                    let b = self.layout.bricks(level);
                    (0..3).all(|a| ijk[a] < b[a]) && !cache.contains(&(level, ijk)) && !self.holds_only_zero(level, ijk)
                })
                .collect();
            drop(cache);
            self.fetch_in_background(wanted, false);
            return;
        }
        if self.prefetching.swap(true, Ordering::AcqRel) {
            return;
        }
        let reader = Arc::clone(self);
        rayon::spawn(move || {
            for (level, ijk) in bricks {
                let b = reader.layout.bricks(level);
                let cached = reader.brick_cache.lock().unwrap_or_else(|p| p.into_inner()).contains(&(level, ijk));
                if !cached && (0..3).all(|a| ijk[a] < b[a]) {
                    let _ = reader.brick(level, ijk);
                }
            }
            reader.prefetching.store(false, Ordering::Release);
        });
    }

    /// Foreign stores: sets the value range to that of `level` (level 0 unless it holds more than the scan's bound,
    /// [`crate::foreign::MAX_SCAN_SAMPLES`]), read brick by brick over its `stored` chunks, chunk by chunk (through
    /// the caches, which keep what they can for the first frames), plus the fill value where a chunk was never
    /// written; bricks that cannot be read are left out. A level with no finite sample gets `[0, 1]`.
    fn scan_value_range(
        &mut self,
        level: usize,
        stored: &[Vec<u64>],
        progress: ScanProgress,
    ) -> Result<(), StoreError> {
        let LevelSource::Array { array, leading, .. } = &self.levels[level] else {
            return Err(StoreError::store(&self.path, format!("level {level} has no array")));
        };
        self.value_range_level = level;
        let failed = |e: zarrs::array::ArrayError| StoreError::store(&self.path, format!("level {level}: {e}"));
        let leading = *leading;
        let bricks = bricks_over_stored_chunks(array, leading, stored, self.layout.brick_size).map_err(failed)?;
        let mut range = EMPTY_RANGE;
        if let Some(fill) = unwritten_fill_value(array, leading, self.info.dtype, stored) {
            range = [fill, fill];
        }
        let total = bricks.len() as u64;
        for (done, ijk) in bricks.into_iter().enumerate() {
            // A brick that cannot be read is left out here: reading it fails again when it is wanted, and is
            // reported then (its ancestor stands in), as for any unreadable brick.
            if let Ok(samples) = self.brick(level, ijk) {
                fold_samples(&samples, &mut range);
            }
            progress(done as u64 + 1, total);
        }
        self.attributes.value_range = if range[0] <= range[1] { range } else { [0.0, 1.0] };
        validate_attributes(&self.path, &self.attributes)?;
        // The bricks were read against the placeholder range.
        self.clipped.store(0, std::sync::atomic::Ordering::Relaxed);
        Ok(())
    }

    /// Foreign stores: counts the samples outside the value range (they saturate when normalised).
    fn count_clipped(&self, samples: &[f32]) {
        if self.minmax.is_some() {
            return;
        }
        let [lo, hi] = self.attributes.value_range.map(|v| v as f32);
        let outside = samples.iter().filter(|&&v| v < lo || v > hi).count() as u64;
        if outside > 0 {
            self.clipped.fetch_add(outside, std::sync::atomic::Ordering::Relaxed);
        }
    }

    /// The level whose stored samples gave a foreign store's value range at open (0 unless level 0 holds more than
    /// the scan's bound; see [`crate::foreign::MAX_SCAN_SAMPLES`]; also 0 for native stores and `--value-range`).
    pub fn value_range_level(&self) -> usize {
        self.value_range_level
    }

    /// Samples read so far from a foreign store that lay outside its value range, so that they saturate (0 for a
    /// range taken from level 0; more where `--value-range` or a coarse level written by another tool exceeds it).
    pub fn clipped_samples(&self) -> u64 {
        self.clipped.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// Bytes the level arrays have read from the storage since the store was opened (chunk and shard bytes, as
    /// stored: compressed).
    pub fn storage_bytes_read(&self) -> u64 {
        self.metrics.as_ref().map_or(0, |m| m.bytes_read() as u64)
    }

    /// Bytes of decoded foreign chunks held now (part of the host cache).
    pub fn cached_chunk_bytes(&self) -> u64 {
        self.chunk_cache.bytes()
    }

    /// Capacity of the host-side brick cache, bytes.
    pub fn cache_capacity_bytes(&self) -> u64 {
        self.cache_bytes
    }

    /// Bricks cached now.
    pub fn cached_bricks(&self) -> usize {
        self.brick_cache.lock().unwrap_or_else(|p| p.into_inner()).len()
    }

    /// The remote store the bricks come from (its counts of requests, bytes and retries), `None` for a folder.
    pub fn remote(&self) -> Option<&Arc<RemoteStore>> {
        self.remote.as_ref()
    }

    /// Bytes the store occupies on disk (0 for a remote store).
    pub fn bytes_on_disk(&self) -> u64 {
        if self.remote.is_some() {
            return 0;
        }
        fn walk(path: &Path) -> u64 {
            std::fs::read_dir(path)
                .map(|entries| {
                    entries
                        .flatten()
                        .map(|e| {
                            let p = e.path();
                            if p.is_dir() {
                                walk(&p)
                            } else {
                                e.metadata().map(|m| m.len()).unwrap_or(0)
                            }
                        })
                        .sum()
                })
                .unwrap_or(0)
        }
        walk(&self.path)
    }
}
