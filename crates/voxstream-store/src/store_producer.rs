//! The streaming producer: bricks with their one-voxel borders, read from a store on the cache manager's worker
//! threads (GigaVoxels' producer reading from disk; Reichl's streaming supplier, seed 004 ch. 4).
//!
//! Tree level `d` reads store level `L − d`, brick `ijk` = chunk `ijk`; the border comes from the neighbouring
//! chunks (clamped at the volume's edge). Values are normalised by the volume's value range. The oracle answers
//! from the per-brick min/max, which covers every full-resolution sample below a brick, so a brick with `min = max`
//! is constant at every finer level too; bricks outside the volume are empty.

use std::path::Path;
use std::sync::Arc;

use voxstream_core::{quantize, NodeContent, NodeKey, ProduceError, Produced, Producer, TreeShape, VoxelFormat};

use crate::error::StoreError;
use crate::layout::PyramidLayout;
use crate::store_reader::StoreReader;
use crate::volume::DType;

/// Where a [`StoreProducer`] reads samples: the store on disk, or the same pyramid held in RAM.
pub trait BrickSource: Send + Sync {
    /// Name for error messages.
    fn path(&self) -> &Path;
    /// Levels and bricks.
    fn layout(&self) -> &PyramidLayout;
    /// Smallest and largest value at level 0.
    fn value_range(&self) -> [f64; 2];
    /// `[min, max]` of the full-resolution samples below brick `ijk` of `level`; `None` outside the grid.
    fn brick_range(&self, level: usize, ijk: [u64; 3]) -> Option<[f32; 2]>;
    /// Samples `[lower, lower + size)` (x, y, z) of `level`, x fastest.
    fn read_region(&self, level: usize, lower: [u64; 3], size: [u64; 3]) -> Result<Vec<f32>, StoreError>;

    /// Whether every sample of every level is an integer in `[0, 255]` (a `u8` volume), so that the brick pool may
    /// keep 8 bits per voxel ([`VoxelFormat`]). The default says no.
    fn samples_are_bytes(&self) -> bool {
        false
    }

    /// Starts reading these bricks `(level, ijk)` into a cache in the background; the default does nothing.
    fn prefetch(self: &Arc<Self>, bricks: Vec<(usize, [u64; 3])>) {
        let _ = bricks;
    }

    /// Reads to keep in flight at once (see [`Producer::concurrency`]); 0 for local sources.
    fn concurrency(&self) -> usize {
        0
    }

    /// Reads what these regions `(level, lower, size)` need into a cache, many reads in flight at once, and returns
    /// when they are there (see [`Producer::fetch`]); failures are left to `read_region`. The default: nothing.
    fn fetch_regions(&self, regions: &[(usize, [u64; 3], [u64; 3])]) {
        let _ = regions;
    }

    /// Whether `[lower, lower + size)` of `level` can be read without waiting on slow storage; if not, its reading
    /// starts in the background (see [`Producer::ready`]). The default: always.
    fn region_ready(self: &Arc<Self>, level: usize, lower: [u64; 3], size: [u64; 3]) -> bool {
        let _ = (level, lower, size);
        true
    }
}

impl BrickSource for StoreReader {
    fn path(&self) -> &Path {
        StoreReader::path(self)
    }
    fn layout(&self) -> &PyramidLayout {
        StoreReader::layout(self)
    }
    fn value_range(&self) -> [f64; 2] {
        self.attributes().value_range
    }
    fn brick_range(&self, level: usize, ijk: [u64; 3]) -> Option<[f32; 2]> {
        StoreReader::brick_range(self, level, ijk)
    }
    fn read_region(&self, level: usize, lower: [u64; 3], size: [u64; 3]) -> Result<Vec<f32>, StoreError> {
        StoreReader::read_region(self, level, lower, size)
    }
    fn samples_are_bytes(&self) -> bool {
        // Levels a foreign store lacks are averaged here (fractions): not bytes.
        self.info().dtype == DType::U8 && !self.has_synthesized_levels()
    }
    fn prefetch(self: &Arc<Self>, bricks: Vec<(usize, [u64; 3])>) {
        StoreReader::prefetch(self, bricks);
    }
    fn concurrency(&self) -> usize {
        StoreReader::remote(self).map_or(0, |remote| remote.concurrency())
    }
    fn fetch_regions(&self, regions: &[(usize, [u64; 3], [u64; 3])]) {
        StoreReader::fetch_regions(self, regions);
    }
    fn region_ready(self: &Arc<Self>, level: usize, lower: [u64; 3], size: [u64; 3]) -> bool {
        StoreReader::region_ready(self, level, lower, size)
    }
}

/// Every level of a store decoded into RAM: the "fully in memory" baseline the streaming producer is measured
/// against. It ignores the memory budget; use it only for volumes that fit.
pub struct InMemoryVolume {
    path: std::path::PathBuf,
    layout: PyramidLayout,
    value_range: [f64; 2],
    samples_are_bytes: bool,
    levels: Vec<Vec<f32>>,
    ranges: Vec<Vec<[f32; 2]>>,
}

impl InMemoryVolume {
    /// Reads every level of `reader`.
    pub fn load(reader: &StoreReader) -> Result<InMemoryVolume, StoreError> {
        let layout = reader.layout().clone();
        let mut levels = Vec::new();
        let mut ranges = Vec::new();
        for level in 0..layout.levels() {
            levels.push(reader.read_region(level, [0; 3], layout.level_dims[level])?);
            let b = layout.bricks(level);
            let mut r = Vec::new();
            for z in 0..b[2] {
                for y in 0..b[1] {
                    for x in 0..b[0] {
                        r.push(reader.brick_range(level, [x, y, z]).unwrap_or([0.0, 0.0]));
                    }
                }
            }
            ranges.push(r);
        }
        Ok(InMemoryVolume {
            path: reader.path().to_path_buf(),
            layout,
            value_range: reader.attributes().value_range,
            samples_are_bytes: reader.samples_are_bytes(),
            levels,
            ranges,
        })
    }
}

impl BrickSource for InMemoryVolume {
    fn path(&self) -> &Path {
        &self.path
    }
    fn layout(&self) -> &PyramidLayout {
        &self.layout
    }
    fn value_range(&self) -> [f64; 2] {
        self.value_range
    }
    fn samples_are_bytes(&self) -> bool {
        self.samples_are_bytes
    }
    fn brick_range(&self, level: usize, ijk: [u64; 3]) -> Option<[f32; 2]> {
        let b = self.layout.bricks(level);
        if (0..3).any(|a| ijk[a] >= b[a]) {
            return None;
        }
        Some(self.ranges[level][((ijk[2] * b[1] + ijk[1]) * b[0] + ijk[0]) as usize])
    }
    fn read_region(&self, level: usize, lower: [u64; 3], size: [u64; 3]) -> Result<Vec<f32>, StoreError> {
        let [nx, ny, _] = self.layout.level_dims[level];
        let data = &self.levels[level];
        let mut out = Vec::with_capacity((size[0] * size[1] * size[2]) as usize);
        for z in lower[2]..lower[2] + size[2] {
            for y in lower[1]..lower[1] + size[1] {
                let start = ((z * ny + y) * nx + lower[0]) as usize;
                out.extend_from_slice(&data[start..start + size[0] as usize]);
            }
        }
        Ok(out)
    }
}

/// Produces bricks from a store (or its in-memory copy).
pub struct StoreProducer<S: BrickSource = StoreReader> {
    reader: Arc<S>,
    shape: TreeShape,
    lower: f32,
    inverse_span: f32,
    voxel_format: VoxelFormat,
}

impl<S: BrickSource> Clone for StoreProducer<S> {
    fn clone(&self) -> Self {
        StoreProducer {
            reader: self.reader.clone(),
            shape: self.shape,
            lower: self.lower,
            inverse_span: self.inverse_span,
            voxel_format: self.voxel_format,
        }
    }
}

impl<S: BrickSource> StoreProducer<S> {
    /// A producer over an open store.
    pub fn new(reader: Arc<S>) -> Result<StoreProducer<S>, StoreError> {
        let layout = reader.layout();
        let shape = TreeShape::new(2, layout.brick_size as u32, layout.max_tree_level())
            .map_err(|e| StoreError::store(reader.path(), e.to_string()))?;
        let [lower, upper] = reader.value_range();
        let span = (upper - lower) as f32;
        // 8-bit voxels where the samples are bytes and the normalisation maps them exactly (issue "a ray caster
        // faster than VTK's": native bricks).
        let voxel_format = if reader.samples_are_bytes() {
            VoxelFormat::for_bytes([lower, upper]).unwrap_or(VoxelFormat::Wide)
        } else {
            VoxelFormat::Wide
        };
        Ok(StoreProducer {
            reader,
            shape,
            lower: lower as f32,
            inverse_span: if span > 0.0 { 1.0 / span } else { 0.0 },
            voxel_format,
        })
    }

    /// The same producer with bricks kept as `format` says: `Some(VoxelFormat::Wide)` keeps 16 bits for any source
    /// (what `--brick-bits 16` asks for); `None`, or a narrow format, keeps what [`StoreProducer::new`] chose (8
    /// bits only where that is exact).
    pub fn with_voxel_format(mut self, format: Option<VoxelFormat>) -> StoreProducer<S> {
        if format == Some(VoxelFormat::Wide) {
            self.voxel_format = VoxelFormat::Wide;
        }
        self
    }

    /// How the brick pool keeps this producer's voxels.
    pub fn voxel_format(&self) -> VoxelFormat {
        self.voxel_format
    }

    /// The source.
    pub fn source(&self) -> &S {
        &self.reader
    }

    #[inline]
    fn normalise(&self, value: f32) -> f32 {
        (value - self.lower) * self.inverse_span
    }

    fn store_level(&self, key: &NodeKey) -> usize {
        (self.shape.max_level - key.level) as usize
    }

    /// The level and the region `[lower, lower + size)` of it that `key`'s brick and its one-voxel border read
    /// (clamped to the level); `None` for a node wholly outside the volume (empty).
    fn region(&self, key: &NodeKey) -> Option<(usize, [u64; 3], [u64; 3])> {
        let level = self.store_level(key);
        let dims = self.reader.layout().level_dims[level];
        let m = self.shape.brick_size as i64;
        let b = m + 2;
        let start = key.ijk.map(|v| v as i64 * m - 1);
        if (0..3).any(|a| start[a] + 1 >= dims[a] as i64) {
            return None;
        }
        let lower = [0, 1, 2].map(|a| start[a].max(0) as u64);
        let upper = [0, 1, 2].map(|a| ((start[a] + b) as u64).min(dims[a]));
        Some((level, lower, [0, 1, 2].map(|a| upper[a] - lower[a])))
    }
}

impl<S: BrickSource> Producer for StoreProducer<S> {
    fn shape(&self) -> TreeShape {
        self.shape
    }

    fn voxel_format(&self) -> VoxelFormat {
        self.voxel_format
    }

    fn oracle(&self, key: NodeKey) -> Option<f32> {
        match self.reader.brick_range(self.store_level(&key), key.ijk) {
            None => Some(0.0),
            Some([min, max]) if min == max => Some(self.normalise(min)),
            Some(_) => None,
        }
    }

    /// The per-brick ranges of the full-resolution level bound every coarser sample above them (levels are
    /// averages of aligned 2×2×2 blocks), so the union of the finest bricks under the node's box, grown by the reach
    /// of a trilinear sample near its faces at the node's own level (one of its voxels, rounded up to finest
    /// bricks), bounds every value the tree holds there. Foreign stores keep no ranges: unbounded. `None` for a node
    /// wholly outside the volume (it is empty).
    fn subtree_range(&self, key: NodeKey) -> Option<[f32; 2]> {
        let level = self.store_level(&key);
        // A source that keeps no ranges (a foreign store) reports each brick unbounded, and so is the subtree: say
        // so without visiting every finest brick below the node (3.5·10¹³ under the root of a 2^20³ image).
        if let Some([f32::NEG_INFINITY, f32::INFINITY]) = self.reader.brick_range(level, key.ijk) {
            return Some([self.normalise(f32::NEG_INFINITY), self.normalise(f32::INFINITY)]);
        }
        let m = self.shape.brick_size as u64;
        // Finest bricks per node edge, and the margin: one voxel of the node's level, 2^level finest voxels.
        let per_node = 1u64 << level;
        let margin = (1u64 << level).div_ceil(m) as i64;
        let finest = self.reader.layout().bricks(0);
        let lower: [i64; 3] = std::array::from_fn(|a| (key.ijk[a] * per_node) as i64 - margin);
        let upper: [i64; 3] =
            std::array::from_fn(|a| (((key.ijk[a] + 1) * per_node) as i64 + margin).min(finest[a] as i64));
        let mut range = [f32::INFINITY, f32::NEG_INFINITY];
        for z in lower[2].max(0)..upper[2] {
            for y in lower[1].max(0)..upper[1] {
                for x in lower[0].max(0)..upper[0] {
                    if let Some([lo, hi]) = self.reader.brick_range(0, [x as u64, y as u64, z as u64]) {
                        range = [range[0].min(lo), range[1].max(hi)];
                    }
                }
            }
        }
        (range[0] <= range[1]).then(|| [self.normalise(range[0]), self.normalise(range[1])])
    }

    fn prefetch(&self, keys: &[NodeKey]) {
        let bricks = keys.iter().map(|key| (self.store_level(key), key.ijk)).collect();
        self.reader.prefetch(bricks);
    }

    fn concurrency(&self) -> usize {
        self.reader.concurrency()
    }

    fn fetch(&self, keys: &[NodeKey]) {
        let regions: Vec<_> = keys.iter().filter_map(|key| self.region(key)).collect();
        self.reader.fetch_regions(&regions);
    }

    fn ready(&self, key: NodeKey) -> bool {
        match self.region(&key) {
            Some((level, lower, size)) => self.reader.region_ready(level, lower, size),
            None => true,
        }
    }

    fn produce(&self, key: NodeKey, voxels: &mut [u16]) -> Result<Produced, ProduceError> {
        let Some((level, lower, size)) = self.region(&key) else {
            return Ok(Produced { content: NodeContent::Empty, is_terminal: true });
        };
        let is_terminal = level == 0;
        let m = self.shape.brick_size as i64;
        let b = m as usize + 2;
        let start = key.ijk.map(|v| v as i64 * m - 1);
        let upper = [0, 1, 2].map(|a| lower[a] + size[a]);
        let samples = self.reader.read_region(level, lower, size).map_err(|e| ProduceError {
            level: key.level,
            ijk: key.ijk,
            message: e.to_string(),
        })?;
        let (sx, sy) = (size[0] as usize, size[1] as usize);
        // Where each voxel of a row comes from in the region (the border clamped to the level): one stretch of the
        // region's row unless the brick touches the level's x bounds.
        let clamped = |a: usize, i: usize| {
            (start[a] + i as i64).clamp(lower[a] as i64, upper[a] as i64 - 1) as usize - lower[a] as usize
        };
        let xs: Vec<usize> = (0..b).map(|i| clamped(0, i)).collect();
        let stretch = xs.windows(2).all(|w| w[1] == w[0] + 1);
        let convert = |sample: f32| quantize(self.normalise(sample));
        for (index, out) in voxels.chunks_exact_mut(b).take(b * b).enumerate() {
            let (k, j) = (index / b, index % b);
            let row = &samples[(clamped(2, k) * sy + clamped(1, j)) * sx..][..sx];
            if stretch {
                out.iter_mut().zip(&row[xs[0]..xs[0] + b]).for_each(|(voxel, &sample)| *voxel = convert(sample));
            } else {
                out.iter_mut().zip(&xs).for_each(|(voxel, &x)| *voxel = convert(row[x]));
            }
        }
        Ok(Produced { content: NodeContent::Brick, is_terminal })
    }
}
