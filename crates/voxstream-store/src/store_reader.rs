//! Opening a store: validating its metadata once, then reading regions of any level and per-brick min/max.
//!
//! Stores written by voxstream carry `attributes.voxstream` (see [`crate::metadata`]). An import that did not finish
//! leaves only `STORE.partial`, never a `STORE` that opens.
//!
//! Reads go through a host-side LRU cache of compressed shards (Reichl's host cache, seed 004 ch. 4): a shard read
//! for one brick keeps its neighbours in RAM, which is the read-ahead of siblings, and the cache's size is part of
//! the memory budget (see `voxstream render --budget-mb`).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use zarrs::array::chunk_cache::{ChunkCache, ChunkCacheLruSizeLimit, ChunkCacheTypeEncoded};
use zarrs::array::{Array, ArraySubset, CodecOptions};
use zarrs::filesystem::FilesystemStore;
use zarrs::group::Group;
use zarrs::storage::ReadableStorageTraits;

use crate::error::StoreError;
use crate::import::partial_path;
use crate::layout::PyramidLayout;
use crate::metadata::{StoreAttributes, MINMAX_GROUP};
use crate::volume::{DType, VolumeInfo};

/// Default size of the host-side cache of compressed shards.
pub const DEFAULT_CACHE_BYTES: u64 = 64 << 20;

/// An open store.
pub struct StoreReader {
    path: PathBuf,
    attributes: StoreAttributes,
    info: VolumeInfo,
    layout: PyramidLayout,
    /// Per level, the array behind an LRU cache of encoded (compressed) shards held in RAM.
    levels: Vec<ChunkCacheLruSizeLimit<ChunkCacheTypeEncoded>>,
    cache_bytes: u64,
    /// Per level, per brick (x fastest): `[min, max]` of the full-resolution samples below it.
    minmax: Vec<Vec<[f32; 2]>>,
}

impl StoreReader {
    /// Opens and validates the store at `path`, with a host-side cache of [`DEFAULT_CACHE_BYTES`].
    pub fn open(path: &Path) -> Result<StoreReader, StoreError> {
        StoreReader::open_with_cache(path, DEFAULT_CACHE_BYTES)
    }

    /// Opens and validates the store at `path`; compressed shards read from disk are kept in RAM up to
    /// `cache_bytes` (split evenly between levels), least recently used first out.
    pub fn open_with_cache(path: &Path, cache_bytes: u64) -> Result<StoreReader, StoreError> {
        if !path.is_dir() {
            if partial_path(path).is_dir() {
                return Err(StoreError::store(path, "incomplete store: its import was interrupted; run the import again"));
            }
            return Err(StoreError::store(path, "no such store (expected a folder holding zarr.json)"));
        }
        let store = Arc::new(FilesystemStore::new(path).map_err(|e| StoreError::store(path, e.to_string()))?);
        let group = Group::open(store.clone(), "/")
            .map_err(|e| StoreError::store(path, format!("missing or corrupt zarr.json: {e}")))?;
        let attributes: StoreAttributes = match group.attributes().get("voxstream") {
            Some(value) => serde_json::from_value(value.clone())
                .map_err(|e| StoreError::store(path, format!("corrupt voxstream attributes: {e}")))?,
            None => {
                return Err(StoreError::store(
                    path,
                    "not a voxstream store (no 'voxstream' attributes); rendering foreign OME-Zarr stores is not \
                     supported yet: import the data with `voxstream import`",
                ))
            }
        };
        if !attributes.complete {
            return Err(StoreError::store(path, "incomplete store: its import was interrupted; run the import again"));
        }
        let dtype = attributes
            .dtype()
            .ok_or_else(|| StoreError::store(path, format!("unknown sample type '{}'", attributes.dtype)))?;
        let info = VolumeInfo { dims: attributes.dims, dtype, spacing: attributes.spacing, origin: attributes.origin };
        info.validate(path)?;
        let layout = PyramidLayout::new(attributes.dims, attributes.brick_size);
        if layout.levels() != attributes.levels {
            return Err(StoreError::store(
                path,
                format!("metadata names {} levels, the dimensions imply {}", attributes.levels, layout.levels()),
            ));
        }
        let mut levels = Vec::new();
        let mut minmax = Vec::new();
        for level in 0..layout.levels() {
            let readable: Arc<dyn ReadableStorageTraits> = store.clone();
            let array = Array::open(readable, &format!("/{level}"))
                .map_err(|e| StoreError::store(path, format!("level {level}: {e}")))?;
            let [x, y, z] = layout.level_dims[level];
            if array.shape() != [z, y, x] {
                return Err(StoreError::store(
                    path,
                    format!("level {level} has shape {:?}, expected {:?}", array.shape(), [z, y, x]),
                ));
            }
            let per_level = (cache_bytes / layout.levels() as u64).max(1);
            levels.push(ChunkCacheLruSizeLimit::new(Arc::new(array), per_level));
            let ranges = Array::open(store.clone(), &format!("/{MINMAX_GROUP}/{level}"))
                .map_err(|e| StoreError::store(path, format!("min/max of level {level}: {e}")))?;
            let flat: Vec<f32> = ranges
                .retrieve_array_subset(&ranges.subset_all())
                .map_err(|e| StoreError::store(path, format!("min/max of level {level}: {e}")))?;
            let expected = layout.bricks(level).iter().product::<u64>() as usize;
            if flat.len() != expected * 2 {
                return Err(StoreError::store(path, format!("min/max of level {level} has the wrong size")));
            }
            minmax.push(flat.chunks_exact(2).map(|c| [c[0], c[1]]).collect());
        }
        Ok(StoreReader { path: path.into(), attributes, info, layout, levels, cache_bytes, minmax })
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

    /// `[min, max]` of brick `ijk` of `level`, or `None` outside the grid.
    pub fn brick_range(&self, level: usize, ijk: [u64; 3]) -> Option<[f32; 2]> {
        let b = self.layout.bricks(level);
        if (0..3).any(|a| ijk[a] >= b[a]) {
            return None;
        }
        Some(self.minmax[level][((ijk[2] * b[1] + ijk[1]) * b[0] + ijk[0]) as usize])
    }

    /// Reads samples `[lower, lower + size)` (x, y, z) of `level` as `f32`, x fastest.
    pub fn read_region(&self, level: usize, lower: [u64; 3], size: [u64; 3]) -> Result<Vec<f32>, StoreError> {
        let subset = ArraySubset::new_with_ranges(&[
            lower[2]..lower[2] + size[2],
            lower[1]..lower[1] + size[1],
            lower[0]..lower[0] + size[0],
        ]);
        let cache = &self.levels[level];
        let corrupt = |e: zarrs::array::ArrayError| {
            StoreError::store(&self.path, format!("level {level}, samples {lower:?}+{size:?}: {e}"))
        };
        let options = CodecOptions::default();
        Ok(match self.info.dtype {
            DType::U8 => cache.retrieve_array_subset::<Vec<u8>>(&subset, &options).map_err(corrupt)?.into_iter().map(f32::from).collect(),
            DType::U16 => cache.retrieve_array_subset::<Vec<u16>>(&subset, &options).map_err(corrupt)?.into_iter().map(f32::from).collect(),
            DType::I16 => cache.retrieve_array_subset::<Vec<i16>>(&subset, &options).map_err(corrupt)?.into_iter().map(f32::from).collect(),
            DType::F32 => cache.retrieve_array_subset::<Vec<f32>>(&subset, &options).map_err(corrupt)?,
        })
    }

    /// Capacity of the host-side cache of compressed shards.
    pub fn cache_capacity_bytes(&self) -> u64 {
        self.cache_bytes
    }

    /// Compressed shards cached now.
    pub fn cached_shards(&self) -> usize {
        self.levels.iter().map(|c| c.len()).sum()
    }

    /// Bytes the store occupies on disk.
    pub fn bytes_on_disk(&self) -> u64 {
        fn walk(path: &Path) -> u64 {
            std::fs::read_dir(path)
                .map(|entries| {
                    entries
                        .flatten()
                        .map(|e| {
                            let p = e.path();
                            if p.is_dir() { walk(&p) } else { e.metadata().map(|m| m.len()).unwrap_or(0) }
                        })
                        .sum()
                })
                .unwrap_or(0)
        }
        walk(&self.path)
    }
}
