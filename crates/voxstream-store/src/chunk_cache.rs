//! Decoded chunks of foreign arrays whose chunks do not tile voxstream's 32³ bricks (64³ chunks, say), so that each
//! chunk is read and decoded once rather than once per brick that overlaps it (a 64³-chunk store read 364 MB for
//! 6.7 MB on disk).
//!
//! The unit kept is the array's read granularity: an inner chunk of a shard, else a whole chunk, at index 0 of the
//! leading axes. Arrays whose units divide the brick edge (voxstream's own stores, 16³ or 32³ chunks) skip it: each
//! brick reads whole units, once. A unit larger than a quarter of the cache is read straight through, as before.
//! Entries are evicted least recently used first to stay within the cache's bytes, which are part of the store's
//! host cache and so of `--budget-mb`.

use std::num::NonZeroU64;
use std::sync::{Arc, Mutex};

use lru::LruCache;
use zarrs::array::{Array, ArrayError, ArrayShardedExt, ArraySubset};
use zarrs::storage::ReadableStorageTraits;

use crate::level_source::{retrieve_f32, LevelSource};
use crate::volume::DType;

type Key = (usize, [u64; 3]);

/// The LRU of decoded units and the bytes it holds.
struct Entries {
    lru: LruCache<Key, Arc<Vec<f32>>>,
    bytes: u64,
}

/// A byte-bounded LRU cache of decoded chunks, shared by every level of one store.
pub(crate) struct ChunkCache {
    /// Per level, the unit (x, y, z) its array is read in when it goes through the cache.
    units: Vec<Option<[u64; 3]>>,
    capacity_bytes: u64,
    entries: Mutex<Entries>,
}

/// The read unit (x, y, z) of `array`: an inner chunk of a shard, else a chunk; `None` for chunk grids that are
/// not regular.
fn read_unit(array: &Array<dyn ReadableStorageTraits>) -> Option<[u64; 3]> {
    let metadata = serde_json::to_value(array.metadata()).ok()?;
    let regular = metadata
        .get("chunk_grid")
        .is_none_or(|grid| grid.get("name").and_then(serde_json::Value::as_str) == Some("regular"));
    if !regular {
        return None;
    }
    let zeros = vec![0; array.dimensionality()];
    let shape: Vec<NonZeroU64> = match array.effective_subchunk_shape() {
        Some(inner) => inner.to_vec(),
        None => array.chunk_shape(&zeros).ok()?.to_vec(),
    };
    let n = shape.len();
    (n >= 3).then(|| [shape[n - 1].get(), shape[n - 2].get(), shape[n - 3].get()])
}

impl ChunkCache {
    /// A cache of at most `capacity_bytes` for the levels that need one (units that do not divide `brick_size`).
    pub fn new(levels: &[LevelSource], brick_size: u64, capacity_bytes: u64) -> ChunkCache {
        let units = levels
            .iter()
            .map(|level| match level {
                LevelSource::Array { array, .. } => read_unit(array).filter(|unit| {
                    let bytes = unit.iter().fold(4u64, |n, &d| n.saturating_mul(d));
                    unit.iter().any(|&d| !brick_size.is_multiple_of(d)) && bytes <= capacity_bytes / 4
                }),
                LevelSource::Synthesized => None,
            })
            .collect();
        ChunkCache { units, capacity_bytes, entries: Mutex::new(Entries { lru: LruCache::unbounded(), bytes: 0 }) }
    }

    /// Whether any level is read through the cache.
    pub fn is_used(&self) -> bool {
        self.units.iter().any(Option::is_some)
    }

    /// Whether `level` is read through the cache.
    pub fn caches(&self, level: usize) -> bool {
        self.units.get(level).is_some_and(Option::is_some)
    }

    /// Samples `[lower, upper)` (x, y, z; within `shape`, the array's last three axes reversed) of `level`, x
    /// fastest, assembled from cached units (each read from `array` when missing). Levels not cached are read
    /// straight from `array`.
    #[allow(clippy::too_many_arguments)]
    pub fn read(
        &self,
        level: usize,
        array: &Array<dyn ReadableStorageTraits>,
        leading: &crate::image_planes::LeadingIndex,
        shape: [u64; 3],
        dtype: DType,
        lower: [u64; 3],
        upper: [u64; 3],
    ) -> Result<Vec<f32>, ArrayError> {
        let Some(unit) = self.units.get(level).copied().flatten() else {
            let mut ranges = leading.ranges();
            ranges.extend([2, 1, 0].map(|a| lower[a]..upper[a]));
            return retrieve_f32(array, &ArraySubset::new_with_ranges(&ranges), dtype);
        };
        let size = [0, 1, 2].map(|a| upper[a] - lower[a]);
        let mut out = vec![0f32; (size[0] * size[1] * size[2]) as usize];
        let first = [0, 1, 2].map(|a| lower[a] / unit[a]);
        let last = [0, 1, 2].map(|a| (upper[a] - 1) / unit[a]);
        for uz in first[2]..=last[2] {
            for uy in first[1]..=last[1] {
                for ux in first[0]..=last[0] {
                    let index = [ux, uy, uz];
                    let origin = [0, 1, 2].map(|a| index[a] * unit[a]);
                    let extent = [0, 1, 2].map(|a| (origin[a] + unit[a]).min(shape[a]) - origin[a]);
                    let samples = self.unit(level, index, || {
                        let mut ranges = leading.ranges();
                        ranges.extend([2, 1, 0].map(|a| origin[a]..origin[a] + extent[a]));
                        retrieve_f32(array, &ArraySubset::new_with_ranges(&ranges), dtype)
                    })?;
                    let from = [0, 1, 2].map(|a| origin[a].max(lower[a]));
                    let to = [0, 1, 2].map(|a| (origin[a] + extent[a]).min(upper[a]));
                    let run = (to[0] - from[0]) as usize;
                    for z in from[2]..to[2] {
                        for y in from[1]..to[1] {
                            let src = (((z - origin[2]) * extent[1] + (y - origin[1])) * extent[0]
                                + (from[0] - origin[0])) as usize;
                            let dst =
                                (((z - lower[2]) * size[1] + (y - lower[1])) * size[0] + (from[0] - lower[0])) as usize;
                            out[dst..dst + run].copy_from_slice(&samples[src..src + run]);
                        }
                    }
                }
            }
        }
        Ok(out)
    }

    /// Unit `index` of `level`, from the cache or `load` (then kept, evicting the least recently used units).
    fn unit(
        &self,
        level: usize,
        index: [u64; 3],
        load: impl FnOnce() -> Result<Vec<f32>, ArrayError>,
    ) -> Result<Arc<Vec<f32>>, ArrayError> {
        let key = (level, index);
        if let Some(samples) = self.entries.lock().unwrap_or_else(|p| p.into_inner()).lru.get(&key) {
            return Ok(samples.clone());
        }
        let samples = Arc::new(load()?);
        let mut entries = self.entries.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(old) = entries.lru.put(key, samples.clone()) {
            entries.bytes -= old.len() as u64 * 4;
        }
        entries.bytes += samples.len() as u64 * 4;
        while entries.bytes > self.capacity_bytes {
            match entries.lru.pop_lru() {
                Some((_, evicted)) => entries.bytes -= evicted.len() as u64 * 4,
                None => break,
            }
        }
        Ok(samples)
    }
}
