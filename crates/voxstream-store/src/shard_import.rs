//! A distributed import: the store [`crate::import`] writes, built by many processes (Dask workers, issue 50), one
//! shard per task, byte for byte the same. Reichl (seed 004, ch. 4) builds the data pool once, offline; this is that
//! step spread over a cluster.
//!
//! Why shards: a shard is one file holding many bricks, and two writers of one shard corrupt it (zarr-python issues
//! 3514 and 3682), so a task owns whole shards. Why this order: a level's samples are a pure function of the level
//! below (2×2×2 averages of its unrounded values, [`crate::import::downsample`]), and a shard's samples halve into
//! one octant of a coarser shard, because shard edges are even. So the task of shard `s` at level `m`:
//! - gets its samples: level 0's from the source, a coarser level's as the halves that the tasks of its (up to 8)
//!   child shards at level `m − 1` returned ([`ShardInput`]);
//! - writes the shard, measures each brick's min/max of its unrounded samples, and returns its own halves
//!   ([`ShardOutput::coarse`]) for its parent's task and a small [`ShardSummary`] (ranges; at level 0 the value
//!   range and histogram) for the client.
//!
//! The client holds a [`ShardImport`]: the import lock from `begin` to `finish`, `STORE.partial` with every level's
//! metadata, and, at `finish`, the summaries merged into what a single-process import writes last (hierarchical
//! min/max, percentiles, attributes), then the same rename into place. Tasks need only the [`ShardSpec`], a few
//! hundred bytes of JSON, validated where it is read. Data moved between tasks: the halves, an eighth of each
//! level's samples as f32.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::{Deserialize, Serialize};
use zarrs::filesystem::FilesystemStore;
use zarrs::storage::store::MemoryStore;
use zarrs::storage::ReadableStorageTraits;

use crate::error::StoreError;
use crate::import::{build_level_array, downsample, finish_store, partial_path, prepare_partial};
use crate::import::{store_shard, stored_brick_ranges, BrickCodec};
use crate::import::{BrickCounts, Samples};
use crate::import::{ImportOptions, ImportReport};
use crate::layout::PyramidLayout;
use crate::store_lock::ImportLock;
use crate::value_histogram::{HistogramParts, ValueHistogram};
use crate::volume::{DType, VolumeInfo};

/// What a task needs to write any shard of one import.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShardSpec {
    /// The store being written (`STORE.partial`).
    pub partial: PathBuf,
    /// Samples per axis (x, y, z) of level 0.
    pub dims: [u64; 3],
    /// Sample type name (`uint8`, `uint16`, `int16`, `float32`).
    pub dtype: String,
    /// Brick edge in samples.
    pub brick_size: u64,
    /// Bricks per shard along x and y (a shard is one brick deep).
    pub shard_bricks: u64,
    /// Replacement for NaN and ±inf samples; `None` refuses them.
    pub nan_as: Option<f32>,
    /// zstd level of the bricks.
    pub zstd_level: i32,
    /// Each brick followed by its CRC32C.
    pub brick_checksums: bool,
    /// How bricks are compressed (absent in specs from before the wavelet codec: zstd).
    #[serde(default)]
    pub codec: BrickCodec,
}

/// A shard's samples: level 0's from the source (x fastest, the shard's region only), or a coarser level's as the
/// halves its child shards' tasks returned, each with the child's index (x, y, z).
#[derive(Debug)]
pub enum ShardInput {
    Samples(Vec<f32>),
    Pieces(Vec<([u64; 3], Vec<f32>)>),
}

/// What a shard's task reports to the client.
#[derive(Clone, Debug, PartialEq)]
pub struct ShardSummary {
    pub level: usize,
    /// The shard's index (x, y, z) in its level's shard grid.
    pub shard: [u64; 3],
    /// Indices (x fastest) of the shard's bricks in the level, and each one's min and max.
    pub bricks: Vec<u64>,
    pub ranges: Vec<[f32; 2]>,
    /// Level 0 only: the smallest and largest sample (±inf when none) and the samples' histogram.
    pub value_range: [f64; 2],
    pub histogram: Option<HistogramParts>,
}

/// What a shard's task returns.
#[derive(Debug)]
pub struct ShardOutput {
    /// The shard's samples averaged 2×2×2 (x fastest; [`ShardSpec::coarse_extent`]): its parent's input. Empty at
    /// the last level.
    pub coarse: Vec<f32>,
    pub summary: ShardSummary,
}

impl ShardSpec {
    /// Parses and checks a spec that crossed a process boundary.
    pub fn from_json(text: &str) -> Result<ShardSpec, StoreError> {
        let spec: ShardSpec = serde_json::from_str(text)
            .map_err(|e| StoreError::store(Path::new("the shard spec"), format!("is not a shard spec: {e}")))?;
        spec.layout()?;
        spec.sample_type()?;
        if spec.shard_bricks == 0 || spec.shard_bricks > 1024 {
            return Err(spec.error(format!("{} bricks per shard is out of range", spec.shard_bricks)));
        }
        if !(-7..=22).contains(&spec.zstd_level) {
            return Err(spec.error(format!("zstd level {} is out of range", spec.zstd_level)));
        }
        if spec.nan_as.is_some_and(|v| !v.is_finite()) {
            return Err(spec.error("the replacement for NaN and ±inf must itself be finite"));
        }
        Ok(spec)
    }

    /// The spec as JSON, for tasks.
    pub fn to_json(&self) -> String {
        serde_json::to_string(self).expect("a shard spec serialises")
    }

    fn error(&self, message: impl Into<String>) -> StoreError {
        StoreError::store(&self.partial, message.into())
    }

    fn sample_type(&self) -> Result<DType, StoreError> {
        DType::from_name(&self.dtype).ok_or_else(|| self.error(format!("unknown sample type {:?}", self.dtype)))
    }

    /// The pyramid's levels.
    pub fn layout(&self) -> Result<PyramidLayout, StoreError> {
        if !(4..=256).contains(&self.brick_size) || !self.brick_size.is_multiple_of(2) {
            return Err(self.error(format!("brick size must be even and in 4..=256, got {}", self.brick_size)));
        }
        PyramidLayout::new(self.dims, self.brick_size).map_err(|e| self.error(e.to_string()))
    }

    /// Shard edge in samples (x, y, z).
    fn shard_edge(&self) -> [u64; 3] {
        let b = self.brick_size;
        [b * self.shard_bricks, b * self.shard_bricks, b]
    }

    /// Shards per axis (x, y, z) at `level` of `layout`.
    pub fn shards(&self, layout: &PyramidLayout, level: usize) -> [u64; 3] {
        let edge = self.shard_edge();
        let dims = layout.level_dims[level];
        [0, 1, 2].map(|a| dims[a].div_ceil(edge[a]))
    }

    /// Origin and extent (x, y, z, in samples of `level`) of a shard, or an error naming a shard outside the grid.
    pub fn region(
        &self,
        layout: &PyramidLayout,
        level: usize,
        shard: [u64; 3],
    ) -> Result<([u64; 3], [u64; 3]), StoreError> {
        if level >= layout.levels() {
            return Err(self.error(format!("level {level} does not exist ({} levels)", layout.levels())));
        }
        let grid = self.shards(layout, level);
        if (0..3).any(|a| shard[a] >= grid[a]) {
            return Err(self.error(format!("shard {shard:?} of level {level} is outside its grid {grid:?}")));
        }
        let edge = self.shard_edge();
        let dims = layout.level_dims[level];
        let origin = [0, 1, 2].map(|a| shard[a] * edge[a]);
        Ok((origin, [0, 1, 2].map(|a| edge[a].min(dims[a] - origin[a]))))
    }

    /// The shards of `level − 1` whose halves make up `shard` of `level` (x fastest).
    pub fn children(&self, layout: &PyramidLayout, level: usize, shard: [u64; 3]) -> Vec<[u64; 3]> {
        if level == 0 {
            return Vec::new();
        }
        let grid = self.shards(layout, level - 1);
        let mut children = Vec::new();
        for z in 2 * shard[2]..(2 * shard[2] + 2).min(grid[2]) {
            for y in 2 * shard[1]..(2 * shard[1] + 2).min(grid[1]) {
                for x in 2 * shard[0]..(2 * shard[0] + 2).min(grid[0]) {
                    children.push([x, y, z]);
                }
            }
        }
        children
    }

    /// Samples per axis of a region's 2×2×2 averages.
    pub fn coarse_extent(extent: [u64; 3]) -> [u64; 3] {
        extent.map(|e| e.div_ceil(2))
    }

    /// Writes one shard (the task's work; see the module's documentation).
    pub fn write_shard(&self, level: usize, shard: [u64; 3], input: ShardInput) -> Result<ShardOutput, StoreError> {
        let layout = self.layout()?;
        let dtype = self.sample_type()?;
        let (origin, extent) = self.region(&layout, level, shard)?;
        let [ex, ey, ez] = extent;
        let mut value_range = [f64::INFINITY, f64::NEG_INFINITY];
        let mut histogram = None;
        let values = match (level, input) {
            (0, ShardInput::Samples(mut values)) => {
                if values.len() as u64 != ex * ey * ez {
                    return Err(self.error(format!(
                        "shard {shard:?} of level 0 holds {ex}×{ey}×{ez} samples, {} were given",
                        values.len()
                    )));
                }
                // Through the sample type, as the single-process import's level-0 slab holds them.
                let mut typed = Samples::new(dtype);
                typed.extend_from_f32(&values);
                typed.copy_to_f32(0, &mut values);
                for (k, plane) in values.chunks_mut((ex * ey) as usize).enumerate() {
                    crate::non_finite::check_slice(plane, ex, origin[2] + k as u64, self.nan_as).map_err(|e| {
                        match e {
                            // Positions in the volume, not in the shard.
                            StoreError::NonFinite { value, position: [x, y, z] } => {
                                StoreError::NonFinite { value, position: [x + origin[0], y + origin[1], z] }
                            }
                            other => other,
                        }
                    })?;
                }
                let (lo, hi) =
                    values.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| (lo.min(v), hi.max(v)));
                value_range = [f64::from(lo), f64::from(hi)];
                let mut counted = ValueHistogram::new(dtype);
                counted.add(&values);
                histogram = Some(counted.parts());
                values
            }
            (0, ShardInput::Pieces(_)) => return Err(self.error("level 0's shards are read from the source")),
            (_, ShardInput::Samples(_)) => {
                return Err(self.error(format!("shard {shard:?} of level {level} is made from its children's halves")))
            }
            (_, ShardInput::Pieces(pieces)) => self.assemble(&layout, level, shard, origin, extent, pieces)?,
        };

        // The whole shard as the array stores it, zeros past the volume's edge, as `LevelWriter::flush` fills it.
        let edge = self.shard_edge();
        let mut elements = vec![0f32; (edge[0] * edge[1] * edge[2]) as usize];
        for z in 0..ez {
            for y in 0..ey {
                let from = ((z * ey + y) * ex) as usize;
                let to = ((z * edge[1] + y) * edge[0]) as usize;
                elements[to..to + ex as usize].copy_from_slice(&values[from..from + ex as usize]);
            }
        }
        let b = self.brick_size;
        let bricks_per_axis = layout.bricks(level);
        // Encoded in memory with the codecs the import built (not read back from its metadata: the same codecs
        // with the same options), then written into the level's folder by `write_shard_file`.
        let options = ImportOptions {
            brick_size: b,
            shard_bricks: self.shard_bricks,
            zstd_level: self.zstd_level,
            nan_as: self.nan_as,
            brick_checksums: self.brick_checksums,
            overwrite: false,
            codec: self.codec,
        };
        let zarr = |e: &dyn std::fmt::Display| StoreError::store(&self.partial, e.to_string());
        let memory = Arc::new(MemoryStore::new());
        let array = build_level_array(&memory, &layout, level, dtype, &options).map_err(|e| zarr(&e))?;
        let indices = [shard[2], shard[1], shard[0]];
        store_shard(&array, &indices, &elements, dtype).map_err(|e| zarr(&e))?;
        let stored = stored_brick_ranges(&array, &indices, &elements, [edge[0], edge[1]], extent, b, dtype, self.codec)
            .map_err(|e| zarr(&e))?;
        let (bricks, ranges) = stored
            .into_iter()
            .map(|([bx, by], range)| {
                let [gx, gy, gz] = [origin[0] / b + bx, origin[1] / b + by, origin[2] / b];
                ((gz * bricks_per_axis[1] + gy) * bricks_per_axis[0] + gx, range)
            })
            .unzip();
        let key = array.chunk_key(&indices);
        // A shard of zeros only is not stored (as zarrs does not store it in a single-process import).
        if let Some(bytes) = memory.get(&key).map_err(|e| zarr(&e))? {
            self.write_shard_file(level, key.as_str(), &bytes)?;
        }
        let coarse = if level + 1 < layout.levels() { downsample(&Samples::F32(values), extent) } else { Vec::new() };
        Ok(ShardOutput { coarse, summary: ShardSummary { level, shard, bricks, ranges, value_range, histogram } })
    }

    /// Writes a shard's bytes at `key` under the level's folder, which must exist: folders below it are made one by
    /// one, never the level's own, so a task still running after its import was aborted (the partial store
    /// deleted) fails instead of making a new one. The file appears whole (written aside, then renamed), and a task
    /// that runs twice writes the same bytes twice.
    fn write_shard_file(&self, level: usize, key: &str, bytes: &[u8]) -> Result<(), StoreError> {
        let level_dir = self.partial.join(level.to_string());
        let relative = key.strip_prefix(&format!("{level}/")).ok_or_else(|| self.error(format!("shard key {key}")))?;
        let path = level_dir.join(relative);
        if !level_dir.join("zarr.json").is_file() {
            return Err(self.error(format!(
                "level {level} is gone from the partial store: the import was aborted or finished elsewhere"
            )));
        }
        let mut dir = level_dir.clone();
        let parents: Vec<&str> = relative.split('/').collect();
        for part in &parents[..parents.len() - 1] {
            dir.push(part);
            match std::fs::create_dir(&dir) {
                Ok(()) => {}
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
                Err(e) => return Err(StoreError::io(&dir, e)),
            }
        }
        let mut aside = path.clone().into_os_string();
        aside.push(format!(".writing-{}-{:?}", std::process::id(), std::thread::current().id()));
        let aside = PathBuf::from(aside);
        std::fs::write(&aside, bytes).map_err(|e| StoreError::io(&aside, e))?;
        std::fs::rename(&aside, &path).map_err(|e| {
            let _ = std::fs::remove_file(&aside);
            StoreError::io(&path, e)
        })
    }

    /// A coarser shard's samples from its children's halves, each checked against the child it claims to be.
    fn assemble(
        &self,
        layout: &PyramidLayout,
        level: usize,
        shard: [u64; 3],
        origin: [u64; 3],
        extent: [u64; 3],
        pieces: Vec<([u64; 3], Vec<f32>)>,
    ) -> Result<Vec<f32>, StoreError> {
        let children = self.children(layout, level, shard);
        let mut seen = vec![false; children.len()];
        let [ex, ey, ez] = extent;
        let mut values = vec![0f32; (ex * ey * ez) as usize];
        for (child, piece) in pieces {
            let Some(slot) = children.iter().position(|&c| c == child) else {
                return Err(self.error(format!("shard {child:?} of level {} is not a child of {shard:?}", level - 1)));
            };
            if std::mem::replace(&mut seen[slot], true) {
                return Err(self.error(format!("shard {child:?} of level {} was given twice", level - 1)));
            }
            let (child_origin, child_extent) = self.region(layout, level - 1, child)?;
            let [cx, cy, cz] = Self::coarse_extent(child_extent);
            if piece.len() as u64 != cx * cy * cz {
                return Err(self.error(format!(
                    "the halves of shard {child:?} of level {} hold {} samples, not {cx}×{cy}×{cz}",
                    level - 1,
                    piece.len()
                )));
            }
            let offset = [0, 1, 2].map(|a| child_origin[a] / 2 - origin[a]);
            for z in 0..cz {
                for y in 0..cy {
                    let from = ((z * cy + y) * cx) as usize;
                    let to = (((z + offset[2]) * ey + y + offset[1]) * ex + offset[0]) as usize;
                    values[to..to + cx as usize].copy_from_slice(&piece[from..from + cx as usize]);
                }
            }
        }
        if let Some(missing) = seen.iter().position(|&s| !s) {
            return Err(self.error(format!(
                "shard {shard:?} of level {level} lacks the halves of shard {:?} of level {}",
                children[missing],
                level - 1
            )));
        }
        Ok(values)
    }
}

/// A distributed import in progress, held by the client: the lock, `STORE.partial` with its levels' metadata, and
/// what `finish` needs. Dropped without `finish`, it removes the partial store (an existing store at `out` is left
/// as it was).
pub struct ShardImport {
    spec: ShardSpec,
    layout: PyramidLayout,
    info: VolumeInfo,
    out: PathBuf,
    _lock: ImportLock,
    finished: bool,
}

impl ShardImport {
    /// Takes the import lock of `out` and creates `STORE.partial` with every level's metadata, checking `options`
    /// as `import_volume` does (an existing store needs `overwrite`).
    pub fn begin(info: VolumeInfo, out: &Path, options: &ImportOptions) -> Result<ShardImport, StoreError> {
        // Tasks write shard files into `out` from every worker: a URL would become a local folder named `s3:` (a
        // store the caller believes is in the bucket), so it is refused before anything is written.
        let text = out.to_string_lossy();
        match voxstream_remote::RemoteLocation::parse(&text) {
            Ok(None) => {}
            Ok(Some(location)) => {
                return Err(StoreError::store(
                    location.shown(),
                    "a distributed import writes into a folder every worker sees, not into an object store: import \
                     into a shared folder and copy it to the bucket (its root zarr.json last), or import an array \
                     that fits in memory with import_volume(numpy_array, URL)",
                ))
            }
            Err(e) => return Err(StoreError::store(voxstream_remote::redact(&text), e.to_string())),
        }
        let lock = ImportLock::acquire(out)?;
        let (_, partial, layout) = match prepare_partial(out, &info, options) {
            Ok(prepared) => prepared,
            Err(error) => {
                let _ = std::fs::remove_dir_all(partial_path(out));
                return Err(error);
            }
        };
        let spec = ShardSpec {
            partial,
            dims: info.dims,
            dtype: info.dtype.name().into(),
            brick_size: options.brick_size,
            shard_bricks: options.shard_bricks,
            nan_as: options.nan_as,
            zstd_level: options.zstd_level,
            brick_checksums: options.brick_checksums,
            codec: options.codec,
        };
        Ok(ShardImport { spec, layout, info, out: out.to_path_buf(), _lock: lock, finished: false })
    }

    /// What tasks need.
    pub fn spec(&self) -> &ShardSpec {
        &self.spec
    }

    /// Where the store goes.
    pub fn out(&self) -> &Path {
        &self.out
    }

    /// The pyramid being written.
    pub fn layout(&self) -> &PyramidLayout {
        &self.layout
    }

    /// Merges the tasks' summaries (every shard of every level exactly once) into what a single-process import
    /// writes after its bricks, and renames the store into place.
    pub fn finish(mut self, summaries: Vec<ShardSummary>) -> Result<ImportReport, StoreError> {
        let result = self.finish_inner(summaries);
        self.finished = result.is_ok();
        result
    }

    fn finish_inner(&self, summaries: Vec<ShardSummary>) -> Result<ImportReport, StoreError> {
        let layout = &self.layout;
        let error = |message: String| StoreError::store(&self.spec.partial, message);
        let levels = layout.levels();
        let mut seen: Vec<Vec<bool>> =
            (0..levels).map(|l| vec![false; self.spec.shards(layout, l).iter().product::<u64>() as usize]).collect();
        let mut minmax: Vec<Vec<[f32; 2]>> = (0..levels)
            .map(|l| vec![[f32::INFINITY, f32::NEG_INFINITY]; layout.bricks(l).iter().product::<u64>() as usize])
            .collect();
        let mut counts = BrickCounts { written: vec![0; levels], empty: vec![0; levels] };
        let mut value_range = [f64::INFINITY, f64::NEG_INFINITY];
        let mut histogram = ValueHistogram::new(self.info.dtype);
        for summary in summaries {
            let level = summary.level;
            self.spec.region(layout, level, summary.shard)?;
            let grid = self.spec.shards(layout, level);
            let index = ((summary.shard[2] * grid[1] + summary.shard[1]) * grid[0] + summary.shard[0]) as usize;
            if std::mem::replace(&mut seen[level][index], true) {
                return Err(error(format!("shard {:?} of level {level} was reported twice", summary.shard)));
            }
            if summary.bricks.len() != summary.ranges.len() {
                return Err(error(format!("shard {:?} of level {level}: bricks and ranges differ", summary.shard)));
            }
            for (&brick, &range) in summary.bricks.iter().zip(&summary.ranges) {
                let slot = minmax[level]
                    .get_mut(brick as usize)
                    .ok_or_else(|| error(format!("brick {brick} of level {level} does not exist")))?;
                *slot = range;
                if range == [0.0, 0.0] {
                    counts.empty[level] += 1;
                } else {
                    counts.written[level] += 1;
                }
            }
            if level == 0 {
                value_range[0] = value_range[0].min(summary.value_range[0]);
                value_range[1] = value_range[1].max(summary.value_range[1]);
                let parts =
                    summary.histogram.as_ref().ok_or_else(|| error("a level-0 shard has no histogram".into()))?;
                histogram.merge(parts).map_err(|e| error(format!("shard {:?}'s histogram: {e}", summary.shard)))?;
            }
        }
        for (level, seen) in seen.iter().enumerate() {
            if let Some(missing) = seen.iter().position(|&s| !s) {
                return Err(error(format!(
                    "{} shards of level {level} were not reported (the first: number {missing})",
                    seen.iter().filter(|&&s| !s).count()
                )));
            }
        }
        let store = Arc::new(
            FilesystemStore::new(&self.spec.partial)
                .map_err(|e| StoreError::store(&self.spec.partial, e.to_string()))?,
        );
        finish_store(
            &store,
            &self.spec.partial,
            &self.out,
            &self.info,
            layout,
            minmax,
            value_range,
            &histogram,
            counts,
            self.spec.codec,
        )
    }
}

impl Drop for ShardImport {
    fn drop(&mut self) {
        if !self.finished {
            // A task still running may add a folder while this deletes (the deletion then fails): try again. Once
            // a level's folder is gone, tasks refuse to write ([`ShardSpec::write_shard_file`]).
            for _ in 0..5 {
                if std::fs::remove_dir_all(&self.spec.partial).is_ok() || !self.spec.partial.exists() {
                    break;
                }
                std::thread::sleep(std::time::Duration::from_millis(20));
            }
        }
    }
}

#[cfg(test)]
mod tests;
