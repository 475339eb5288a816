//! Importing a volume into a store, in bounded memory: the input is read in slabs of one brick of z slices; each
//! level keeps at most one slab of its own resolution, writes it as one row of shards, and passes the 2×2×2 average
//! to the next level. Reichl (seed 004, ch. 4) calls this building the data pool once, offline.
//!
//! Memory: one slab of `brick_size` z slices per level — level 0 in the input's sample type, coarser levels in f32
//! (`brick_size · X · Y · (s + 4/3)` bytes for `s`-byte samples), plus the shard being encoded on each core. For
//! 2048² u8 slices that is about 0.3 GiB, for 4096² u16 slices about 1.8 GiB, whatever the number of slices: the
//! bound grows with the slice area, not the volume. An import writes into `STORE.partial` and renames it to `STORE` only when complete, so an
//! interrupted import never leaves a store that looks complete; running it again restarts cleanly. `--overwrite`
//! swaps by renames (the old store aside, the new one in, then the old one deleted), never deleting file by file.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use rayon::prelude::*;
use zarrs::array::{Array, ArrayBuilder};
use zarrs::filesystem::FilesystemStore;
use zarrs::group::GroupBuilder;

use crate::error::StoreError;
use crate::formats::SampleConversion;
use crate::layout::PyramidLayout;
use crate::metadata::{ome_multiscales, StoreAttributes, MINMAX_GROUP};
use crate::non_finite;
use crate::store_lock::ImportLock;
use crate::value_histogram::ValueHistogram;
use crate::volume::{DType, VolumeSource};
use crate::wavelet_codec::WaveletCodec;

/// Choices of an import.
#[derive(Clone, Debug, PartialEq)]
pub struct ImportOptions {
    /// Brick (inner chunk) edge in samples.
    pub brick_size: u64,
    /// Bricks per shard along x and y (a shard is one brick deep in z, so a slab writes whole shards).
    pub shard_bricks: u64,
    /// zstd level.
    pub zstd_level: i32,
    /// Replace an existing store.
    pub overwrite: bool,
    /// Replaces NaN and ±inf samples; `None` refuses them (see [`crate::non_finite`]).
    pub nan_as: Option<f32>,
    /// Follow each brick's zstd frame with the Zarr v3 `crc32c` codec (verified on read); `false` writes the codec
    /// chain of stores made before checksums, which readers still accept.
    pub brick_checksums: bool,
    /// How bricks are compressed.
    pub codec: BrickCodec,
}

/// How an import compresses its bricks.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "name", rename_all = "lowercase")]
pub enum BrickCodec {
    /// zstd (lossless): the store opens in every Zarr v3 reader.
    #[default]
    Zstd,
    /// The wavelet codec ([`crate::wavelet_codec`]): lossless when `max_error` is 0, otherwise every sample within
    /// `max_error` of its value; a Zarr v3 extension codec only voxstream reads.
    Wavelet {
        /// The guaranteed per-sample bound, in the data's units (0: lossless).
        max_error: f64,
    },
}

impl BrickCodec {
    /// The codec a front end's choice names: `zstd` or `wavelet`, and a max error (wavelet only; absent or 0 is
    /// lossless). The error is one line naming the problem.
    pub fn from_choice(name: &str, max_error: Option<f64>) -> Result<BrickCodec, String> {
        match (name, max_error) {
            ("zstd", None) => Ok(BrickCodec::Zstd),
            ("zstd", Some(_)) => Err("a max error applies to the wavelet codec; zstd is lossless".into()),
            ("wavelet", e) => {
                let max_error = e.unwrap_or(0.0);
                if !(max_error.is_finite() && max_error >= 0.0) {
                    return Err(format!("the max error must be a finite number ≥ 0 (0 is lossless), got {max_error}"));
                }
                Ok(BrickCodec::Wavelet { max_error })
            }
            (other, _) => Err(format!("unknown brick codec '{other}': zstd or wavelet")),
        }
    }

    /// The largest difference between a stored and a decoded sample (0 for lossless codecs).
    pub fn max_error(self) -> f64 {
        match self {
            BrickCodec::Zstd => 0.0,
            BrickCodec::Wavelet { max_error } => max_error,
        }
    }

    /// Whether decoded samples may differ from the samples written.
    pub fn is_lossy(self) -> bool {
        self.max_error() > 0.0
    }
}

impl Default for ImportOptions {
    fn default() -> Self {
        ImportOptions {
            brick_size: 32,
            shard_bricks: 8,
            zstd_level: 3,
            overwrite: false,
            nan_as: None,
            brick_checksums: true,
            codec: BrickCodec::Zstd,
        }
    }
}

/// What an import did.
#[derive(Clone, Debug, PartialEq)]
pub struct ImportReport {
    /// Levels written.
    pub levels: usize,
    /// Smallest and largest value.
    pub value_range: [f64; 2],
    /// `[percent, value]` pairs of the level-0 samples (see [`crate::value_histogram`]).
    pub value_percentiles: Vec<[f64; 2]>,
    /// Bricks per level that hold data (written).
    pub bricks_written: Vec<u64>,
    /// Bricks per level skipped because all their samples are 0 (the fill value).
    pub bricks_empty: Vec<u64>,
    /// What converting the input's samples did, when the store keeps another type than the input's (see
    /// [`crate::formats::sample_type`]); displayed, it is the note a front end prints.
    pub conversion: Option<SampleConversion>,
}

/// Imports `source` into a new store at `out`. `progress(done, total)` is called with input bytes. On failure the
/// partial store is removed and an existing store at `out` is left untouched. One import per store at a time: the
/// store's [`ImportLock`] is taken before anything is written and held until the new store is in place; while
/// another import holds it this one fails with [`StoreError::Busy`], touching nothing.
pub fn import_volume(
    source: &mut dyn VolumeSource,
    out: &Path,
    options: &ImportOptions,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<ImportReport, StoreError> {
    let lock = ImportLock::acquire(out)?;
    let result = import_into_partial(source, out, options, progress);
    if result.is_err() {
        let _ = std::fs::remove_dir_all(partial_path(out));
    }
    drop(lock);
    result
}

fn import_into_partial(
    source: &mut dyn VolumeSource,
    out: &Path,
    options: &ImportOptions,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<ImportReport, StoreError> {
    let info = source.info().clone();
    let (store, partial, layout) = prepare_partial(out, &info, options)?;
    let zarr = |e: &dyn std::fmt::Display| StoreError::store(&partial, e.to_string());

    let mut levels: Vec<LevelWriter> = Vec::new();
    for level in 0..layout.levels() {
        // The metadata is in place (prepare_partial wrote it).
        let array = build_level_array(&store, &layout, level, info.dtype, options).map_err(|e| zarr(&e))?;
        levels.push(LevelWriter::new(array, &layout, level, info.dtype, options.codec));
    }

    let brick = options.brick_size as usize;
    let total = info.byte_len();
    let slice_bytes = info.slice_len() as u64 * info.dtype.size() as u64;
    let mut value_range = [f64::INFINITY, f64::NEG_INFINITY];
    let mut histogram = ValueHistogram::new(info.dtype);
    let mut z = 0u64;
    let mut slice = Vec::with_capacity(info.slice_len());
    while z < info.dims[2] {
        let count = (info.dims[2] - z).min(brick as u64) as usize;
        // Read slice by slice into level 0's slab, which keeps the input's own sample type (1 byte per u8 sample).
        for k in 0..count {
            slice.clear();
            source.read_slices(1, &mut slice)?;
            non_finite::check_slice(&mut slice, info.dims[0], z + k as u64, options.nan_as)?;
            let (lo, hi) = slice.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| (lo.min(v), hi.max(v)));
            value_range[0] = value_range[0].min(lo as f64);
            value_range[1] = value_range[1].max(hi as f64);
            histogram.add(&slice);
            levels[0].buffer.extend_from_f32(&slice);
        }
        push_planes(&mut levels, 0, &[], count, false).map_err(|e| zarr(&e))?;
        z += count as u64;
        progress(z * slice_bytes, total);
    }
    // Flush what the coarser levels still hold.
    for level in 0..levels.len() {
        if levels[level].planes > 0 {
            push_planes(&mut levels, level, &[], 0, true).map_err(|e| zarr(&e))?;
        }
    }
    let minmax: Vec<Vec<[f32; 2]>> = levels.iter_mut().map(|l| std::mem::take(&mut l.minmax)).collect();
    let counts = BrickCounts {
        written: levels.iter().map(|l| l.written).collect(),
        empty: levels.iter().map(|l| l.empty).collect(),
    };
    drop(levels);
    let report =
        finish_store(&store, &partial, out, &info, &layout, minmax, value_range, &histogram, counts, options.codec)?;
    Ok(ImportReport { conversion: source.conversion(), ..report })
}

/// Checks an import's choices, clears what killed imports left, and creates `STORE.partial` with every level's
/// array metadata (no chunks yet). The caller holds the import lock.
pub(crate) fn prepare_partial(
    out: &Path,
    info: &crate::volume::VolumeInfo,
    options: &ImportOptions,
) -> Result<(Arc<FilesystemStore>, PathBuf, PyramidLayout), StoreError> {
    if !(4..=256).contains(&options.brick_size) || options.brick_size % 2 != 0 {
        return Err(StoreError::store(
            out,
            format!("brick size must be even and in 4..=256, got {}", options.brick_size),
        ));
    }
    if options.nan_as.is_some_and(|v| !v.is_finite()) {
        return Err(StoreError::store(out, "the replacement for NaN and ±inf must itself be finite"));
    }
    if out.exists() && !options.overwrite {
        return Err(StoreError::store(out, "already exists (use --overwrite to replace it)"));
    }
    // This import holds the lock, so aside folders beside a store in place are leftovers of killed imports (with
    // the store missing, one of them is its only whole copy: kept until the new store is in place).
    if out.is_dir() {
        remove_asides(out, &aside_paths(out))?;
    }
    let layout =
        PyramidLayout::new(info.dims, options.brick_size).map_err(|e| StoreError::store(out, e.to_string()))?;
    let partial = partial_path(out);
    if partial.exists() {
        std::fs::remove_dir_all(&partial).map_err(|e| StoreError::io(&partial, e))?;
    }
    std::fs::create_dir_all(&partial).map_err(|e| StoreError::io(&partial, e))?;
    let store = Arc::new(FilesystemStore::new(&partial).map_err(|e| StoreError::store(&partial, e.to_string()))?);
    let zarr = |e: &dyn std::fmt::Display| StoreError::store(&partial, e.to_string());

    for level in 0..layout.levels() {
        let array = build_level_array(&store, &layout, level, info.dtype, options).map_err(|e| zarr(&e))?;
        array.store_metadata().map_err(|e| zarr(&e))?;
    }
    Ok((store, partial, layout))
}

/// Bricks per level that hold data and that are empty (all 0).
pub(crate) struct BrickCounts {
    pub written: Vec<u64>,
    pub empty: Vec<u64>,
}

/// Everything after the bricks, the same for a single-process and a distributed import
/// ([`crate::shard_import`]): per-brick min/max made hierarchical and written, the group's attributes, and the
/// partial store renamed into place. `minmax` holds each level's per-brick ranges of its own samples (x fastest).
#[allow(clippy::too_many_arguments)]
pub(crate) fn finish_store(
    store: &Arc<FilesystemStore>,
    partial: &Path,
    out: &Path,
    info: &crate::volume::VolumeInfo,
    layout: &PyramidLayout,
    mut minmax: Vec<Vec<[f32; 2]>>,
    mut value_range: [f64; 2],
    histogram: &ValueHistogram,
    counts: BrickCounts,
    codec: BrickCodec,
) -> Result<ImportReport, StoreError> {
    let zarr = |e: &dyn std::fmt::Display| StoreError::store(partial, e.to_string());
    if !value_range[0].is_finite() {
        value_range = [0.0, 0.0];
    }
    // Per-brick min/max, hierarchical: a coarse brick's range covers every full-resolution sample below it.
    for level in 1..minmax.len() {
        let (finer, coarser) = minmax.split_at_mut(level);
        aggregate_minmax(&mut coarser[0], layout.bricks(level), &finer[level - 1], layout.bricks(level - 1));
    }
    for (level, ranges) in minmax.iter().enumerate() {
        write_minmax(store, layout, level, ranges).map_err(|e| zarr(&e))?;
    }
    GroupBuilder::new()
        .build(store.clone(), &format!("/{MINMAX_GROUP}"))
        .map_err(|e| zarr(&e))?
        .store_metadata()
        .map_err(|e| zarr(&e))?;

    let report = ImportReport {
        levels: layout.levels(),
        value_range,
        value_percentiles: histogram.stored_percentiles(),
        bricks_written: counts.written,
        bricks_empty: counts.empty,
        conversion: None,
    };
    let name = out.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let mut attributes = StoreAttributes::new(info, layout, value_range, true);
    attributes.value_percentiles = Some(histogram.stored_percentiles());
    attributes.brick_codec = Some(codec).filter(|c| *c != BrickCodec::Zstd);
    let mut group = GroupBuilder::new().build(store.clone(), "/").map_err(|e| zarr(&e))?;
    group.attributes_mut().insert("ome".into(), ome_multiscales(&name, info, layout));
    group.attributes_mut().insert("voxstream".into(), serde_json::to_value(&attributes).map_err(|e| zarr(&e))?);
    group.store_metadata().map_err(|e| zarr(&e))?;
    commit(partial, out)?;
    Ok(report)
}

/// Merges the ranges of a finer level's bricks (`finer`, `fb` bricks per axis) into their parents' (`coarse`).
fn aggregate_minmax(coarse: &mut [[f32; 2]], cb: [u64; 3], finer: &[[f32; 2]], fb: [u64; 3]) {
    for z in 0..fb[2] {
        for y in 0..fb[1] {
            for x in 0..fb[0] {
                let child = finer[((z * fb[1] + y) * fb[0] + x) as usize];
                let entry = &mut coarse[((z / 2 * cb[1] + y / 2) * cb[0] + x / 2) as usize];
                entry[0] = entry[0].min(child[0]);
                entry[1] = entry[1].max(child[1]);
            }
        }
    }
}

/// Puts the complete store `partial` at `out`. An existing store is first renamed aside (`STORE.old-<pid>`), the
/// new one renamed in, then the old one deleted: at every instant either `out` is a complete store, or (killed
/// between the two renames) the old store is whole in the aside folder, which `StoreReader::open` names. Aside
/// folders left by interrupted swaps are deleted once a new store is in place. The caller holds the import lock.
fn commit(partial: &Path, out: &Path) -> Result<(), StoreError> {
    if out.exists() {
        let aside = aside_path(out, std::process::id());
        std::fs::rename(out, &aside).map_err(|e| StoreError::io(out, e))?;
        if let Err(error) = std::fs::rename(partial, out) {
            // Put the old store back; the new one stays in STORE.partial for the caller to delete.
            let _ = std::fs::rename(&aside, out);
            return Err(StoreError::io(out, error));
        }
    } else {
        std::fs::rename(partial, out).map_err(|e| StoreError::io(out, e))?;
    }
    remove_asides(out, &aside_paths(out))
}

/// Deletes aside folders of `out` (under the import lock: none of them belongs to a running import).
pub(crate) fn remove_asides(out: &Path, asides: &[PathBuf]) -> Result<(), StoreError> {
    for stale in asides {
        std::fs::remove_dir_all(stale).map_err(|e| {
            StoreError::store(
                out,
                format!(
                    "the previous store {} could not be deleted ({}): delete it by hand",
                    stale.display(),
                    crate::error::describe_io(&e)
                ),
            )
        })?;
    }
    Ok(())
}

/// Where `import --overwrite` run by process `pid` moves the store it replaces.
pub fn aside_path(out: &Path, pid: u32) -> PathBuf {
    let mut name = out.file_name().map(|n| n.to_os_string()).unwrap_or_default();
    name.push(format!(".old-{pid}"));
    out.with_file_name(name)
}

/// Folders `STORE.old-<pid>` next to `out`: previous stores that an interrupted `--overwrite` moved aside.
pub fn aside_paths(out: &Path) -> Vec<PathBuf> {
    let Some(name) = out.file_name().map(|n| n.to_string_lossy().into_owned()) else {
        return Vec::new();
    };
    let prefix = format!("{name}.old-");
    let parent = match out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let mut found: Vec<PathBuf> = std::fs::read_dir(&parent)
        .map(|entries| {
            entries
                .flatten()
                .filter(|e| {
                    let n = e.file_name().to_string_lossy().into_owned();
                    n.strip_prefix(&prefix)
                        .is_some_and(|pid| !pid.is_empty() && pid.bytes().all(|b| b.is_ascii_digit()))
                })
                .map(|e| out.with_file_name(e.file_name()))
                .collect()
        })
        .unwrap_or_default();
    found.sort();
    found
}

/// Where an import in progress writes.
pub fn partial_path(out: &Path) -> PathBuf {
    let mut name = out.file_name().map(|n| n.to_os_string()).unwrap_or_default();
    name.push(".partial");
    out.with_file_name(name)
}

pub(crate) fn build_level_array<S: ?Sized>(
    store: &Arc<S>,
    layout: &PyramidLayout,
    level: usize,
    dtype: DType,
    options: &ImportOptions,
) -> Result<Array<S>, Box<dyn std::error::Error>> {
    use zarrs::array::codec::array_to_bytes::sharding::{
        ShardingCodecBuilder, ShardingCodecOptions, SubchunkWriteOrder,
    };
    use zarrs::array::codec::ZstdCodec;
    let [x, y, z] = layout.level_dims[level];
    let b = layout.brick_size;
    let shard = vec![b, b * options.shard_bricks, b * options.shard_bricks];
    let edge = std::num::NonZeroU64::new(b).ok_or("brick size must be positive")?;
    let mut sharding = ShardingCodecBuilder::new(vec![edge; 3], &dtype.zarr_data_type());
    let mut brick_codecs: Vec<Arc<dyn zarrs::array::codec::api::BytesToBytesCodecTraits>> = Vec::new();
    match options.codec {
        BrickCodec::Zstd => brick_codecs.push(Arc::new(ZstdCodec::new(options.zstd_level, false))),
        BrickCodec::Wavelet { max_error } => {
            sharding.array_to_bytes_codec(Arc::new(WaveletCodec::new(max_error)?));
        }
    }
    if options.brick_checksums {
        brick_codecs.push(Arc::new(zarrs::array::codec::Crc32cCodec::new()));
    }
    sharding.bytes_to_bytes_codecs(brick_codecs);
    let fill = match dtype {
        DType::U8 => zarrs::array::FillValue::from(0u8),
        DType::U16 => zarrs::array::FillValue::from(0u16),
        DType::I16 => zarrs::array::FillValue::from(0i16),
        DType::F32 => zarrs::array::FillValue::from(0f32),
    };
    // Bricks in C order within a shard (zarrs' default is the order their parallel encoders finish in): the same
    // input gives the same bytes, run after run and task by task (`crate::shard_import`).
    let ordered = ShardingCodecOptions::default().with_subchunk_write_order(SubchunkWriteOrder::C);
    let array = ArrayBuilder::new(vec![z, y, x], shard, dtype.zarr_data_type(), fill)
        .array_to_bytes_codec(Arc::new(sharding.build().with_options(ordered)))
        .dimension_names(["z", "y", "x"].into())
        .build(store.clone(), &format!("/{level}"))?;
    Ok(array)
}

/// One level being written: a slab of up to one brick of z planes.
struct LevelWriter {
    array: Array<FilesystemStore>,
    /// The bricks' codec (a lossy one's ranges are read back from the bricks as written).
    codec: BrickCodec,
    dims: [u64; 3],
    bricks: [u64; 3],
    brick: u64,
    dtype: DType,
    /// Planes held (x fastest), `planes` of them: level 0 in the input's type, coarser levels in f32.
    buffer: Samples,
    planes: usize,
    /// Next z row of bricks to write.
    row: u64,
    /// Per brick (x fastest, then y, then z): `[min, max]`.
    minmax: Vec<[f32; 2]>,
    written: u64,
    empty: u64,
}

impl LevelWriter {
    fn new(
        array: Array<FilesystemStore>,
        layout: &PyramidLayout,
        level: usize,
        dtype: DType,
        codec: BrickCodec,
    ) -> LevelWriter {
        let bricks = layout.bricks(level);
        let buffer = if level == 0 { Samples::new(dtype) } else { Samples::new(DType::F32) };
        LevelWriter {
            array,
            codec,
            dims: layout.level_dims[level],
            bricks,
            brick: layout.brick_size,
            dtype,
            buffer,
            planes: 0,
            row: 0,
            minmax: vec![[f32::INFINITY, f32::NEG_INFINITY]; bricks.iter().product::<u64>() as usize],
            written: 0,
            empty: 0,
        }
    }

    /// Writes the held planes as one row of shards; returns the 2×2×2-averaged planes for the next level.
    fn flush(&mut self) -> Result<(Vec<f32>, usize), Box<dyn std::error::Error + Send + Sync>> {
        let [nx, ny, _] = self.dims;
        let b = self.brick;
        let planes = self.planes;
        let shard_xy = self.array.chunk_grid_shape()[1..].to_vec();
        let shard_edge = self.array.chunk_shape(&[self.row, 0, 0])?.iter().map(|d| d.get()).collect::<Vec<_>>();
        let (shard_y, shard_x) = (shard_edge[1], shard_edge[2]);
        let shards: Vec<(u64, u64)> =
            (0..shard_xy[0]).flat_map(|sy| (0..shard_xy[1]).map(move |sx| (sy, sx))).collect();
        let buffer = &self.buffer;
        let dtype = self.dtype;
        let array = &self.array;
        let row = self.row;
        let codec = self.codec;
        // Encode and write the shards of this row in parallel.
        let results: Vec<Result<Vec<(u64, [f32; 2], bool)>, String>> = shards
            .par_iter()
            .map(|&(sy, sx)| {
                let mut elements = vec![0f32; (b * shard_y * shard_x) as usize];
                let mut brick_ranges: Vec<(u64, [f32; 2], bool)> = Vec::new();
                for z in 0..planes as u64 {
                    for y in 0..shard_y {
                        let gy = sy * shard_y + y;
                        if gy >= ny {
                            break;
                        }
                        let start = ((z * ny + gy) * nx + sx * shard_x) as usize;
                        let len = (shard_x).min(nx.saturating_sub(sx * shard_x)) as usize;
                        let dst = ((z * shard_y + y) * shard_x) as usize;
                        buffer.copy_to_f32(start, &mut elements[dst..dst + len]);
                    }
                }
                let valid = [shard_x.min(nx - sx * shard_x), shard_y.min(ny - sy * shard_y), planes as u64];
                store_shard(array, &[row, sy, sx], &elements, dtype).map_err(|e| e.to_string())?;
                let ranges =
                    stored_brick_ranges(array, &[row, sy, sx], &elements, [shard_x, shard_y], valid, b, dtype, codec)
                        .map_err(|e| e.to_string())?;
                for ([bx, by], range) in ranges {
                    let (gbx, gby) = (sx * shard_x / b + bx, sy * shard_y / b + by);
                    brick_ranges.push((gby * (nx.div_ceil(b)) + gbx, range, range == [0.0, 0.0]));
                }
                Ok(brick_ranges)
            })
            .collect();
        for result in results {
            for (index_in_row, range, is_empty) in
                result.map_err(|e| -> Box<dyn std::error::Error + Send + Sync> { e.into() })?
            {
                let index = (row * self.bricks[0] * self.bricks[1] + index_in_row) as usize;
                self.minmax[index] = range;
                if is_empty {
                    self.empty += 1;
                } else {
                    self.written += 1;
                }
            }
        }
        let coarse = downsample(&self.buffer, [nx, ny, planes as u64]);
        self.buffer.clear();
        self.planes = 0;
        self.row += 1;
        Ok((coarse, planes.div_ceil(2)))
    }
}

/// Each brick of a shard (x, y within it) with its `[min, max]`.
pub(crate) type BrickRanges = Vec<([u64; 2], [f32; 2])>;

/// Min and max of the samples of each brick of one shard that lie in the volume: `elements` is the whole shard (x
/// fastest, `edge` samples along x and y), `valid` its samples inside the volume along x, y, z. Bricks (x, y within
/// the shard, y outer) with no valid sample are left out.
pub(crate) fn shard_brick_ranges(elements: &[f32], edge: [u64; 2], valid: [u64; 3], b: u64) -> BrickRanges {
    let [vx, vy, vz] = valid;
    let mut ranges = Vec::new();
    for by in 0..vy.div_ceil(b) {
        for bx in 0..vx.div_ceil(b) {
            let mut range = [f32::INFINITY, f32::NEG_INFINITY];
            for z in 0..vz {
                for y in by * b..((by + 1) * b).min(vy) {
                    let row = ((z * edge[1] + y) * edge[0]) as usize;
                    for &v in &elements[row + (bx * b) as usize..row + ((bx + 1) * b).min(vx) as usize] {
                        range[0] = range[0].min(v);
                        range[1] = range[1].max(v);
                    }
                }
            }
            ranges.push(([bx, by], range));
        }
    }
    ranges
}

/// Each brick's `[min, max]` as the shard just written at `indices` holds it (ranges of the samples that lie in the
/// volume, as [`shard_brick_ranges`]; `[0, 0]` for a brick that reads as zeros, as empty ones do). For a lossless codec
/// that is `elements`' own ranges; a lossy codec's bricks are read back and their decoded samples' ranges taken, so
/// that each range is exactly what a reader decodes (tight for empty-space skipping, and never culling a brick whose
/// decoded samples reach a value).
#[allow(clippy::too_many_arguments)]
pub(crate) fn stored_brick_ranges<S: ?Sized + zarrs::storage::ReadableStorageTraits + 'static>(
    array: &Array<S>,
    indices: &[u64],
    elements: &[f32],
    edge: [u64; 2],
    valid: [u64; 3],
    b: u64,
    dtype: DType,
    codec: BrickCodec,
) -> Result<BrickRanges, Box<dyn std::error::Error>> {
    if !codec.is_lossy() {
        return Ok(shard_brick_ranges(elements, edge, valid, b));
    }
    let decoded: Vec<f32> = match dtype {
        DType::U8 => array.retrieve_chunk::<Vec<u8>>(indices)?.into_iter().map(f32::from).collect(),
        DType::U16 => array.retrieve_chunk::<Vec<u16>>(indices)?.into_iter().map(f32::from).collect(),
        DType::I16 => array.retrieve_chunk::<Vec<i16>>(indices)?.into_iter().map(f32::from).collect(),
        DType::F32 => array.retrieve_chunk::<Vec<f32>>(indices)?,
    };
    Ok(shard_brick_ranges(&decoded, edge, valid, b))
}

pub(crate) fn store_shard<S: ?Sized + zarrs::storage::ReadableWritableStorageTraits + 'static>(
    array: &Array<S>,
    indices: &[u64],
    elements: &[f32],
    dtype: DType,
) -> Result<(), Box<dyn std::error::Error>> {
    match dtype {
        // Round half up: `(v + 0.5).floor()` compiles to one instruction, `round()` to a libm call.
        DType::U8 => {
            array.store_chunk(indices, &elements.iter().map(|&v| (v + 0.5).floor() as u8).collect::<Vec<_>>())?
        }
        DType::U16 => {
            array.store_chunk(indices, &elements.iter().map(|&v| (v + 0.5).floor() as u16).collect::<Vec<_>>())?
        }
        DType::I16 => {
            array.store_chunk(indices, &elements.iter().map(|&v| (v + 0.5).floor() as i16).collect::<Vec<_>>())?
        }
        DType::F32 => array.store_chunk(indices, elements)?,
    }
    Ok(())
}

/// Appends `count` planes to `level`; writes a row when a brick's worth is held (or `finish`), cascading down.
fn push_planes(
    levels: &mut [LevelWriter],
    level: usize,
    planes: &[f32],
    count: usize,
    finish: bool,
) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
    let writer = &mut levels[level];
    writer.buffer.extend_from_f32(planes);
    writer.planes += count;
    if writer.planes as u64 >= writer.brick || (finish && writer.planes > 0) {
        let (coarse, coarse_planes) = writer.flush()?;
        if level + 1 < levels.len() {
            push_planes(levels, level + 1, &coarse, coarse_planes, false)?;
        }
    }
    Ok(())
}

/// Samples of a slab, in the input's type at level 0 (so a u8 slab takes 1 byte per sample) or in f32.
pub(crate) enum Samples {
    U8(Vec<u8>),
    U16(Vec<u16>),
    I16(Vec<i16>),
    F32(Vec<f32>),
}

impl Samples {
    pub(crate) fn new(dtype: DType) -> Samples {
        match dtype {
            DType::U8 => Samples::U8(Vec::new()),
            DType::U16 => Samples::U16(Vec::new()),
            DType::I16 => Samples::I16(Vec::new()),
            DType::F32 => Samples::F32(Vec::new()),
        }
    }

    /// Appends values that are exact in this type (the importers' f32 holds integer inputs exactly).
    pub(crate) fn extend_from_f32(&mut self, values: &[f32]) {
        match self {
            // Integer inputs are exact in f32: a cast (no rounding call) restores them.
            Samples::U8(v) => v.extend(values.iter().map(|&x| x as u8)),
            Samples::U16(v) => v.extend(values.iter().map(|&x| x as u16)),
            Samples::I16(v) => v.extend(values.iter().map(|&x| x as i16)),
            Samples::F32(v) => v.extend_from_slice(values),
        }
    }

    pub(crate) fn copy_to_f32(&self, start: usize, out: &mut [f32]) {
        let n = out.len();
        match self {
            Samples::U8(v) => out.iter_mut().zip(&v[start..start + n]).for_each(|(o, &x)| *o = x as f32),
            Samples::U16(v) => out.iter_mut().zip(&v[start..start + n]).for_each(|(o, &x)| *o = x as f32),
            Samples::I16(v) => out.iter_mut().zip(&v[start..start + n]).for_each(|(o, &x)| *o = x as f32),
            Samples::F32(v) => out.copy_from_slice(&v[start..start + n]),
        }
    }

    #[inline]
    fn get(&self, i: usize) -> f32 {
        match self {
            Samples::U8(v) => v[i] as f32,
            Samples::U16(v) => v[i] as f32,
            Samples::I16(v) => v[i] as f32,
            Samples::F32(v) => v[i],
        }
    }

    fn clear(&mut self) {
        match self {
            Samples::U8(v) => v.clear(),
            Samples::U16(v) => v.clear(),
            Samples::I16(v) => v.clear(),
            Samples::F32(v) => v.clear(),
        }
    }
}

/// Averages 2×2×2 blocks of `planes` (dims x, y, z); odd edges average the samples that exist.
pub(crate) fn downsample(planes: &Samples, dims: [u64; 3]) -> Vec<f32> {
    let [nx, ny, nz] = dims.map(|d| d as usize);
    let [ox, oy, oz] = [nx.div_ceil(2), ny.div_ceil(2), nz.div_ceil(2)];
    let mut out = vec![0f32; ox * oy * oz];
    for z in 0..oz {
        for y in 0..oy {
            for x in 0..ox {
                let (mut sum, mut n) = (0f64, 0u32);
                for dz in 0..2 {
                    for dy in 0..2 {
                        for dx in 0..2 {
                            let (sx, sy, sz) = (2 * x + dx, 2 * y + dy, 2 * z + dz);
                            if sx < nx && sy < ny && sz < nz {
                                sum += planes.get((sz * ny + sy) * nx + sx) as f64;
                                n += 1;
                            }
                        }
                    }
                }
                out[(z * oy + y) * ox + x] = (sum / n as f64) as f32;
            }
        }
    }
    out
}

fn write_minmax(
    store: &Arc<FilesystemStore>,
    layout: &PyramidLayout,
    level: usize,
    minmax: &[[f32; 2]],
) -> Result<(), Box<dyn std::error::Error>> {
    let [bx, by, bz] = layout.bricks(level);
    let array = ArrayBuilder::new(
        vec![bz, by, bx, 2],
        vec![bz, by, bx, 2],
        zarrs::array::data_type::float32(),
        zarrs::array::FillValue::from(0f32),
    )
    .dimension_names(["z", "y", "x", "minmax"].into())
    .build(store.clone(), &format!("/{MINMAX_GROUP}/{level}"))?;
    array.store_metadata()?;
    let flat: Vec<f32> = minmax.iter().flat_map(|r| if r[0] > r[1] { [0.0, 0.0] } else { *r }).collect();
    array.store_chunk(&[0, 0, 0, 0], &flat)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn downsampling_averages_blocks_and_edges() {
        // 3×1×1 → 2×1×1: (a+b)/2 and c.
        assert_eq!(downsample(&Samples::F32(vec![1.0, 3.0, 10.0]), [3, 1, 1]), vec![2.0, 10.0]);
        let cube: Vec<u8> = (0..8).collect();
        assert_eq!(downsample(&Samples::U8(cube), [2, 2, 2]), vec![3.5]);
    }
}
