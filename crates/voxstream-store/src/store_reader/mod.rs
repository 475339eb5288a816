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
//!
//! # Modules
//! - `opening`: opening a local or remote store and validating its metadata and per-brick min/max once.
//! - `brick_reads`: regions assembled from bricks, each read once through the brick cache and checked.
//! - `background`: fetching ahead (prefetch, and the non-blocking frames of a remote session).
//! - `shard_indexes`: a remote store's coarse shard indexes, fetched at open; bricks' byte ranges from the indexes.
//! - `value_range_scan`: a foreign store's value range, scanned at open, and the samples it clips.

mod background;
mod brick_reads;
mod decoded_brick;
mod opening;
mod shard_indexes;
mod value_range_scan;

use std::num::NonZeroUsize;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use lru::LruCache;
use zarrs::storage::storage_adapter::performance_metrics::PerformanceMetricsStorageAdapter;

use voxstream_remote::RemoteStore;

use crate::checked_store::CheckedStore;
use crate::chunk_cache::ChunkCache;
use crate::error::StoreError;
use crate::layout::PyramidLayout;
use crate::level_source::LevelSource;
use crate::metadata::StoreAttributes;
use crate::metadata_check::validate_attributes;
use crate::volume::VolumeInfo;

use background::Background;
use decoded_brick::DecodedBrick;

/// Default size of the host-side brick cache.
pub const DEFAULT_CACHE_BYTES: u64 = 64 << 20;

/// The host-side caches of a store ([`StoreReader::host_caches`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct HostCaches {
    /// The decoded-brick cache's budget.
    pub decoded_bytes: u64,
    /// The compressed-brick cache, where there is one.
    pub compressed: Option<crate::checked_store::CompressedCacheStats>,
}

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
    brick_cache: Mutex<LruCache<(usize, [u64; 3]), Arc<DecodedBrick>>>,
    /// Decoded chunks of foreign arrays whose chunks do not tile the bricks (a share of the host cache).
    chunk_cache: ChunkCache,
    /// Counts the bytes the level arrays read from the storage.
    metrics: Option<Arc<PerformanceMetricsStorageAdapter<CheckedStore>>>,
    /// The storage a native store's bricks are read through (it holds the compressed-brick cache).
    bricks_store: Option<Arc<CheckedStore>>,
    /// Per level, its bricks per shard and the length of a shard's index where `shard_indexes` can read them.
    shard_geometries: std::sync::OnceLock<Vec<Option<([u64; 3], u64)>>>,
    /// Bytes the decoded-brick cache may hold.
    decoded_cache_bytes: u64,
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
    /// A foreign 4-D/5-D image's leading axes, the indices read, and the channel's `omero` metadata.
    planes: crate::image_planes::ImagePlanes,
}

impl StoreReader {
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
        // The cache holds at most `brick_cache_bytes` of decoded bricks, at least one: each at most brick_size³
        // samples in the store's type (`DecodedBrick`), or f32 where a level is averaged from the level below.
        let kept_sample_bytes =
            if levels.iter().any(|l| matches!(l, LevelSource::Synthesized)) { 4 } else { info.dtype.size() as u64 };
        let brick_bytes = attributes.brick_size.pow(3) * kept_sample_bytes;
        let capacity = NonZeroUsize::new((brick_cache_bytes / brick_bytes) as usize).unwrap_or(NonZeroUsize::MIN);
        let brick_cache = Mutex::new(LruCache::new(capacity));
        Ok(StoreReader {
            path: path.into(),
            attributes,
            info,
            layout,
            levels,
            brick_cache,
            chunk_cache,
            metrics: None,
            bricks_store: None,
            shard_geometries: Default::default(),
            decoded_cache_bytes: capacity.get() as u64 * brick_bytes,
            clipped: std::sync::atomic::AtomicU64::new(0),
            value_range_level: 0,
            prefetching: std::sync::atomic::AtomicBool::new(false),
            minmax,
            remote: None,
            reading: crate::single_flight::SingleFlight::new(),
            background: Background::default(),
            planes: Default::default(),
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

    /// A foreign 4-D or 5-D image's axes before z, y, x (time, channel) with the index read along each, and the
    /// chosen channel's `omero` display metadata; empty for 3-D images and voxstream's stores.
    pub fn image_planes(&self) -> &crate::image_planes::ImagePlanes {
        &self.planes
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

    /// The host caches: decoded bricks (f32) and bricks as stored (compressed), their budgets and what the
    /// compressed one holds and served. Foreign stores have no compressed-brick cache.
    pub fn host_caches(&self) -> HostCaches {
        HostCaches {
            decoded_bytes: self.decoded_cache_bytes,
            compressed: self.bricks_store.as_ref().and_then(|s| s.compressed_cache()),
        }
    }

    /// Bytes the level arrays have read from the storage since the store was opened (chunk and shard bytes, as
    /// stored: compressed).
    pub fn storage_bytes_read(&self) -> u64 {
        self.metrics.as_ref().map_or(0, |m| m.bytes_read() as u64)
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
