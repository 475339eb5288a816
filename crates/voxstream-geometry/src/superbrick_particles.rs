//! The out-of-core particle producer: particle sets larger than memory, binned once on disk into superbricks.
//!
//! Reichl (seed 004, ch. 5) renders SPH runs of billions of particles by sorting them, out of core, into
//! *superbricks* (a coarse grid of spatial bins) and resampling each brick from the superbricks its kernels reach.
//! This producer makes the same bricks as the in-memory [`crate::ParticleProducer`], holding only a bounded set of
//! superbricks in memory:
//!
//! 1. **Three streaming passes over the file** ([`ParticleChunks`]: a binary PLY read a few MB at a time, or columns
//!    of text a line at a time): the
//!    bounds, count and smoothing-length range (every chunk validated as the in-memory set is); the particles per
//!    superbrick; then each particle written, in unit-cube units, to its superbrick's run of a spill file (an
//!    external counting sort: 24 bytes per particle, in an unnamed temporary file deleted when the producer drops).
//! 2. **Superbricks:** `S³` bins, `S` the smallest power of two (at most [`MAX_SUPERBRICKS_PER_AXIS`]) that puts
//!    at most a 216th of the memory budget in a superbrick on average (a neighbourhood of 27 fits eight times over:
//!    small superbricks keep the cache's working set close to what the rays ask for, and each load cheap), and
//!    kernels reaching at most half a superbrick's width (all but the widest thousandth), so that a node's kernels
//!    come from its superbrick and at most its 26 neighbours. Each superbrick records its particles' bounds and widest
//!    kernel (its extent): a brick loads only the superbricks whose kernels reach it, and the few widest kernels are
//!    found through their superbricks' extents without shrinking the rest. Each superbrick's run is rewritten once
//!    in its index's order, so a load sorts sorted keys. At most 2³² particles per superbrick.
//! 3. **Smoothing lengths** where the file has none: the in-memory rule (`h = 2·` the 8th neighbour's distance,
//!    capped at 4× the median) with one more cap, half a superbrick's width (the in-memory one is a tenth of the
//!    cube): a k-d tree per superbrick over it and the neighbours' particles within a quarter of its width finds
//!    every `h` up to that cap exactly. The median is taken from a fine histogram.
//! 4. **One pass over the superbricks**, each with the neighbours' particles whose kernels reach it: the density
//!    probe (largest and median density at the particles, probed as in memory: every particle of the two narrowest
//!    support classes present, one in 64 of the others), the oracle's counts per support class, and the aggregated
//!    particles of the coarse levels.
//! 5. **Levels at or below the superbricks' size** (a node inside one superbrick): resampled exactly as in memory
//!    from the particles of the superbricks its kernels reach, loaded on demand into an LRU cache of indices
//!    ([`crate::particle_index`]) that holds at most the budget's particles (plus those in use by bricks being made;
//!    a thread needing a superbrick another is loading waits for it). Not counted in the budget: the build
//!    passes' neighbourhoods (a superbrick and the kernels reaching it) and the coarse levels' aggregates.
//! 6. **Coarser levels** (a node spanning superbricks): from particles aggregated per voxel of the level (mass
//!    summed, placed at the centre of mass, mass-weighted mean smoothing length; kernels of different widths kept
//!    apart) on cells half a voxel wide, built bottom-up and held in memory: at most `(brick·S)³` aggregates for
//!    the finest of them, far fewer where space is empty. The mass, hence the integral of the density, is exact;
//!    the profile is approximated (within 1.1% of the density scale on the tests' cloud; the kernel there is two
//!    voxels wide).
//!
//! 7. **The attribute** ([`ParticleTreeSettings::attribute`]): the probe pass computes the density at every particle
//!    and stores each particle's weight `mⱼ/ρⱼ·Aⱼ` in the spill file; one more pass over the superbricks evaluates the
//!    interpolant at every particle for its range, as the in-memory producer does.

use std::collections::HashMap;
use std::os::unix::fs::FileExt;
use std::path::Path;
use std::sync::{Arc, Mutex};

use glam::DVec3;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;
use voxstream_core::{NodeKey, ProduceError, Produced, Producer, TreeShape};

use crate::error::GeometryError;
use crate::formats::ply::PlyPointStream;
use crate::formats::xyz::TextPointStream;
use crate::mesh_distance::UnitCubeFit;
use crate::particle_index::{class_of, oracle_cells, GridCounts, ParticleGrid, ParticleIndex, MAX_CLASSES};
use crate::particle_producer::{
    FieldScale, MAX_SUPPORT_OVER_MEDIAN, MIN_SUPPORT_VOXELS, SMOOTHING_NEIGHBOURS, SMOOTHING_SCALE_RANGE,
};
use crate::particles::{check_particles, ParticleSet, RawParticles};
use crate::ParticleTreeSettings;

/// A particle set read in passes, a run of particles at a time.
pub trait ParticleChunks: Sync {
    /// Whether the particles carry smoothing lengths, masses and values.
    fn columns(&self) -> [bool; 3];
    /// Calls `f` with consecutive runs of the particles and the index of each run's first.
    fn for_each_chunk(
        &self,
        f: &mut dyn FnMut(u64, &RawParticles) -> Result<(), GeometryError>,
    ) -> Result<(), GeometryError>;
}

impl ParticleChunks for PlyPointStream {
    fn columns(&self) -> [bool; 3] {
        PlyPointStream::columns(self)
    }

    fn for_each_chunk(
        &self,
        f: &mut dyn FnMut(u64, &RawParticles) -> Result<(), GeometryError>,
    ) -> Result<(), GeometryError> {
        PlyPointStream::for_each_chunk(self, f)
    }
}

/// A set in memory, in runs of 65,536 (for tests, and to compare with the in-memory producer).
impl ParticleChunks for TextPointStream {
    fn columns(&self) -> [bool; 3] {
        TextPointStream::columns(self)
    }

    fn for_each_chunk(
        &self,
        f: &mut dyn FnMut(u64, &RawParticles) -> Result<(), GeometryError>,
    ) -> Result<(), GeometryError> {
        TextPointStream::for_each_chunk(self, f)
    }
}

impl ParticleChunks for ParticleSet {
    fn columns(&self) -> [bool; 3] {
        [!self.smoothing().is_empty(), !self.masses().is_empty(), !self.values().0.is_empty()]
    }

    fn for_each_chunk(
        &self,
        f: &mut dyn FnMut(u64, &RawParticles) -> Result<(), GeometryError>,
    ) -> Result<(), GeometryError> {
        const RUN: usize = 1 << 16;
        let column = |c: &[f32], from: usize, to: usize| if c.is_empty() { Vec::new() } else { c[from..to].to_vec() };
        for from in (0..self.len()).step_by(RUN) {
            let to = (from + RUN).min(self.len());
            let run = RawParticles {
                positions: self.positions()[from..to].to_vec(),
                smoothing: column(self.smoothing(), from, to),
                masses: column(self.masses(), from, to),
                values: column(self.values().0, from, to),
                value_name: self.values().1.to_string(),
            };
            f(from as u64, &run)?;
        }
        Ok(())
    }
}

/// Most superbricks per axis (`32³` = 32,768 bins; the coarse levels' aggregates grow with it).
pub const MAX_SUPERBRICKS_PER_AXIS: u64 = 32;

/// Bytes a particle takes while its superbrick is loaded (index entry, sorting and gathering temporaries): what the
/// memory budget is divided by.
pub const BYTES_PER_LOADED_PARTICLE: u64 = 64;

/// The smallest memory budget: room for 27 superbricks of a few thousand particles.
pub const MIN_MEMORY_BYTES: u64 = 8 << 20;

/// Bytes of a particle in the spill file: unit-cube position, support, mass, weight (`f32` little-endian each).
const RECORD_BYTES: usize = 24;

/// A particle as the spill file holds it: `[x, y, z, support, mass, weight]`, unit-cube units (support 0: not yet
/// known). The weight is what the particle adds times its kernel: its mass (density), or `mⱼ/ρⱼ·Aⱼ` (attribute; the
/// value `Aⱼ` until the probe knows `ρⱼ`).
type Record = [f32; 6];

/// Where a record keeps its mass, and its weight.
const MASS: usize = 4;
const WEIGHT: usize = 5;

/// How the out-of-core producer holds the particles.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct OutOfCoreSettings {
    /// Memory for loaded superbricks, bytes (at least [`MIN_MEMORY_BYTES`]).
    pub memory_bytes: u64,
    /// Directory of the spill file (24 bytes per particle).
    pub spill_directory: std::path::PathBuf,
}

/// What the out-of-core producer did and holds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SuperbrickStatistics {
    /// Particles in the set.
    pub particles: u64,
    /// Superbricks per axis.
    pub superbricks_per_axis: u64,
    /// The tree level whose nodes are superbricks (coarser levels use aggregated particles).
    pub superbrick_level: u32,
    /// Particles in the fullest superbrick.
    pub largest_superbrick: u64,
    /// The cache's budget, particles.
    pub budget_particles: u64,
    /// Most particles the cache held at once.
    pub peak_cached_particles: u64,
    /// Superbricks loaded from the spill file for bricks (cache misses).
    pub loads: u64,
    /// Aggregated particles held for the coarse levels.
    pub coarse_particles: u64,
    /// Bytes of the spill file.
    pub spill_bytes: u64,
}

/// Loaded superbricks, least recently used evicted first.
#[derive(Debug, Default)]
struct SuperbrickCache {
    loaded: HashMap<u32, (Arc<ParticleIndex>, u64)>,
    /// Superbricks a thread is loading: others wait for it rather than load them twice.
    loading: std::collections::HashSet<u32>,
    particles: u64,
    peak: u64,
    clock: u64,
    loads: u64,
}

/// The out-of-core particle producer (N = 2).
#[derive(Debug)]
pub struct SuperbrickParticleProducer {
    shape: TreeShape,
    fit: UnitCubeFit,
    /// The positions' bounds, file units.
    bounds: ([f64; 3], [f64; 3]),
    /// Superbricks per axis, and the level whose nodes they are.
    per_axis: u64,
    superbrick_level: u32,
    spill: std::fs::File,
    /// Particle offsets of each superbrick's run in the spill file (`S³ + 1`).
    starts: Vec<u64>,
    /// Per superbrick, the bounds of its particles and their largest support: a brick needs the superbricks whose
    /// kernels reach it, usually one, not every superbrick within the set's widest kernel.
    extents: Vec<SuperbrickExtent>,
    /// The adaptive smoothing lengths' cap (infinite where the file gives them).
    support_cap: f32,
    /// Aggregated particles of each level coarser than the superbricks.
    coarse: Vec<ParticleIndex>,
    /// The oracle: per support class, its largest support and its counts.
    oracle: Vec<(f64, ParticleGrid)>,
    max_support: f64,
    cache: Mutex<SuperbrickCache>,
    /// Signalled when a load ends.
    loaded_signal: std::sync::Condvar,
    budget_particles: u64,
    total_mass: f64,
    scale: FieldScale,
}

/// Where a superbrick's kernels reach: its particles' bounds and their largest support (unit-cube units).
#[derive(Clone, Copy, Debug)]
struct SuperbrickExtent {
    lower: DVec3,
    upper: DVec3,
    max_support: f64,
}

impl SuperbrickExtent {
    /// Whether a kernel of this superbrick, widened to `min_support`, may reach the box `lower..upper`.
    fn reaches(&self, lower: DVec3, upper: DVec3, min_support: f64) -> bool {
        let reach = DVec3::splat(self.max_support.max(min_support));
        (self.lower - reach).cmple(upper).all() && (self.upper + reach).cmpge(lower).all()
    }
}

/// A histogram of `log₂` values, 64 bins per octave over 2⁻¹²⁸…2¹²⁸: medians within 1.1% without holding the values.
struct LogHistogram {
    bins: Vec<u64>,
    count: u64,
}

impl LogHistogram {
    const PER_OCTAVE: f64 = 64.0;
    const LOWEST: f64 = -128.0;

    fn new() -> LogHistogram {
        LogHistogram { bins: vec![0; (256.0 * Self::PER_OCTAVE) as usize], count: 0 }
    }

    fn add(&mut self, value: f64) {
        if value > 0.0 {
            let bin = ((value.log2() - Self::LOWEST) * Self::PER_OCTAVE).floor().max(0.0) as usize;
            let last = self.bins.len() - 1;
            self.bins[bin.min(last)] += 1;
            self.count += 1;
        }
    }

    /// The median's bin centre (`None`: empty).
    fn median(&self) -> Option<f64> {
        self.quantile(0.5)
    }

    /// The bin centre of the `q`-quantile (`None`: empty).
    fn quantile(&self, q: f64) -> Option<f64> {
        let wanted = ((self.count as f64 * q).ceil() as u64).clamp(1, self.count.max(1));
        let mut seen = 0;
        for (bin, &n) in self.bins.iter().enumerate() {
            seen += n;
            if seen >= wanted {
                return Some(2f64.powf((bin as f64 + 0.5) / Self::PER_OCTAVE + Self::LOWEST));
            }
        }
        None
    }
}

/// Particles aggregated per half voxel of a coarse level: mass, mass-weighted position and support, summed weight.
#[derive(Clone, Copy, Debug, Default)]
struct Aggregate {
    mass: f64,
    weighted_position: DVec3,
    weighted_support: f64,
    weight: f64,
}

/// Aggregates per (cell, width class) of one coarse level.
type Aggregates = HashMap<(u64, u8), Aggregate>;

/// Aggregation cells per voxel edge of a coarse level.
const AGGREGATE_CELLS_PER_VOXEL: f64 = 2.0;

fn aggregate_into(aggregates: &mut Aggregates, shape: &TreeShape, level: u32, p: DVec3, h: f64, m: f64, w: f64) {
    let voxel = shape.voxel_size(level);
    let cell_size = voxel / AGGREGATE_CELLS_PER_VOXEL;
    let cells = (1.0 / cell_size).round() as u64;
    let cell = [0, 1, 2].map(|a| ((p[a] / cell_size).floor().max(0.0) as u64).min(cells - 1));
    let key = (cell[2] * cells + cell[1]) * cells + cell[0];
    // Kernels no wider than the level's own (two voxels) all become that; wider ones are kept apart by octave.
    let width = (h / (MIN_SUPPORT_VOXELS * voxel)).log2().floor().clamp(0.0, 63.0) as u8;
    let entry = aggregates.entry((key, width)).or_default();
    entry.mass += m;
    entry.weighted_position += p * m;
    entry.weighted_support += h * m;
    entry.weight += w;
}

/// The aggregates as particles: unit position (single precision), support, mass, weight.
fn aggregated_particles(aggregates: &Aggregates) -> Vec<(DVec3, f64, f64, f64)> {
    let mut entries: Vec<(&(u64, u8), &Aggregate)> = aggregates.iter().collect();
    // A fixed order (by cell and width) so that the same file gives the same bricks.
    entries.sort_unstable_by_key(|(key, _)| **key);
    let entries: Vec<&Aggregate> = entries.into_iter().map(|(_, a)| a).collect();
    entries
        .iter()
        .map(|a| {
            let p = (a.weighted_position / a.mass).as_vec3().as_dvec3();
            (p, f64::from((a.weighted_support / a.mass) as f32), a.mass, a.weight)
        })
        .collect()
}

impl SuperbrickParticleProducer {
    /// Bins the particles of `source` into superbricks in a spill file, and probes them (see the module's steps).
    pub fn new(
        source: &dyn ParticleChunks,
        settings: ParticleTreeSettings,
        out_of_core: &OutOfCoreSettings,
    ) -> Result<SuperbrickParticleProducer, GeometryError> {
        let invalid = |message: String| GeometryError::Invalid { message };
        let [has_smoothing, has_masses, has_values] = source.columns();
        if settings.attribute && !has_values {
            return Err(invalid(
                "the particles have no scalar attribute to render (a value column); render their density instead"
                    .into(),
            ));
        }
        if !SMOOTHING_SCALE_RANGE.contains(&settings.smoothing_scale) {
            return Err(invalid(format!(
                "smoothing scale {} must be between {} and {}",
                settings.smoothing_scale,
                SMOOTHING_SCALE_RANGE.start(),
                SMOOTHING_SCALE_RANGE.end()
            )));
        }
        if out_of_core.memory_bytes < MIN_MEMORY_BYTES {
            return Err(invalid(format!(
                "{} MiB of memory for particles is too little: give at least {} MiB",
                out_of_core.memory_bytes >> 20,
                MIN_MEMORY_BYTES >> 20
            )));
        }
        TreeShape::new(2, settings.brick_size, 0).map_err(|error| invalid(error.to_string()))?;

        // Pass 1: count, bounds, smoothing lengths, mass; every run validated.
        let mut count = 0u64;
        let (mut lower, mut upper) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        let (mut min_h, mut max_h) = (f64::INFINITY, 0.0f64);
        let mut file_supports = LogHistogram::new();
        let mut total_mass = 0.0;
        source.for_each_chunk(&mut |first, run| {
            check_particles(run, first)?;
            if run.smoothing.is_empty() == has_smoothing
                || run.masses.is_empty() == has_masses
                || run.values.is_empty() == has_values
            {
                return Err(invalid(format!("particle {first}: the columns change within the file")));
            }
            count += run.positions.len() as u64;
            for p in &run.positions {
                for a in 0..3 {
                    lower[a] = lower[a].min(p[a]);
                    upper[a] = upper[a].max(p[a]);
                }
            }
            for &h in &run.smoothing {
                min_h = min_h.min(f64::from(h));
                file_supports.add(f64::from(h));
                max_h = max_h.max(f64::from(h));
            }
            total_mass +=
                if has_masses { run.masses.iter().map(|&m| f64::from(m)).sum() } else { run.positions.len() as f64 };
            Ok(())
        })?;
        if count == 0 {
            return Err(invalid("the file holds no particles".into()));
        }
        let fit = UnitCubeFit::checked_around(lower, upper, settings.fill)?;
        let to_support = |h: f32| f64::from((f64::from(h) * settings.smoothing_scale / fit.size) as f32);

        // The finest level, where it is known before the smoothing lengths are (it bounds the superbricks' level).
        let resolution_for = |min_support: f64| {
            settings.resolution.unwrap_or_else(|| (4.0 / min_support.max(1e-9)).clamp(256.0, 8192.0) as u64)
        };
        let max_level_for = |resolution: u64| {
            let bricks = resolution.div_ceil(u64::from(settings.brick_size)).max(1);
            64 - (bricks - 1).leading_zeros()
        };
        let level_bound = match (settings.resolution, has_smoothing) {
            (Some(r), _) => max_level_for(r),
            (None, true) => max_level_for(resolution_for(to_support(min_h as f32))),
            (None, false) => max_level_for(256),
        };
        let budget_particles = out_of_core.memory_bytes / BYTES_PER_LOADED_PARTICLE;
        // A 216th of the budget per superbrick on average (measured on 8 million clustered particles at 64 and 256
        // MiB: a 27th, the neighbourhood's share, made superbricks the cache thrashed on, 1.4× slower).
        let target = (budget_particles / 216).max(1);
        let mut per_axis = 1u64;
        let most = MAX_SUPERBRICKS_PER_AXIS.min(1 << level_bound.min(5));
        while per_axis < most && count / per_axis.pow(3) > target {
            per_axis *= 2;
        }
        if has_smoothing {
            // Kernels reaching at most half a superbrick (all but the widest thousandth: a few huge kernels must
            // not make the whole set one superbrick; theirs are found through the superbricks' extents).
            let wide = to_support(file_supports.quantile(0.999).unwrap_or(max_h).min(max_h) as f32);
            while per_axis > 1 && per_axis as f64 * wide > 0.5 {
                per_axis /= 2;
            }
        }
        let superbrick_level = per_axis.trailing_zeros();
        let superbrick_of = |p: DVec3| -> usize {
            let c = [0, 1, 2].map(|a| ((p[a] * per_axis as f64).floor().max(0.0) as u64).min(per_axis - 1));
            ((c[2] * per_axis + c[1]) * per_axis + c[0]) as usize
        };
        let unit_of = |p: [f64; 3]| fit.to_unit(p).as_vec3().as_dvec3();

        // Pass 2: particles per superbrick.
        let bins = per_axis.pow(3) as usize;
        let mut starts = vec![0u64; bins + 1];
        source.for_each_chunk(&mut |_, run| {
            for p in &run.positions {
                starts[superbrick_of(unit_of(*p)) + 1] += 1;
            }
            Ok(())
        })?;
        for i in 0..bins {
            starts[i + 1] += starts[i];
        }
        if starts[bins] != count {
            return Err(invalid("the file changed while it was read".into()));
        }
        let largest = starts.windows(2).map(|w| w[1] - w[0]).max().unwrap_or(0);
        if largest > u64::from(u32::MAX) {
            return Err(invalid(format!(
                "{largest} particles in one superbrick of {per_axis}³: at most 2³² are read (split the file's densest \
                 region, or give more --particle-memory)"
            )));
        }

        // Pass 3: each particle to its superbrick's run of the spill file.
        let spill_io = |error| GeometryError::Io { path: out_of_core.spill_directory.clone(), error };
        let spill = tempfile::tempfile_in(&out_of_core.spill_directory).map_err(spill_io)?;
        spill.set_len(count * RECORD_BYTES as u64).map_err(spill_io)?;
        let mut cursor = starts.clone();
        let mut bytes = Vec::new();
        source.for_each_chunk(&mut |_, run| {
            let mut binned: Vec<(usize, Record)> = run
                .positions
                .iter()
                .enumerate()
                .map(|(i, p)| {
                    let unit = unit_of(*p);
                    let h = if has_smoothing { to_support(run.smoothing[i]) as f32 } else { 0.0 };
                    let m = if has_masses { run.masses[i] } else { 1.0 };
                    let w = if settings.attribute { run.values[i] } else { m };
                    (superbrick_of(unit), [unit.x as f32, unit.y as f32, unit.z as f32, h, m, w])
                })
                .collect();
            binned.sort_by_key(|&(bin, _)| bin);
            for group in binned.chunk_by(|a, b| a.0 == b.0) {
                let bin = group[0].0;
                if cursor[bin] + group.len() as u64 > starts[bin + 1] {
                    return Err(invalid("the file changed while it was read".into()));
                }
                encode(group.iter().map(|(_, r)| r), &mut bytes);
                spill.write_all_at(&bytes, cursor[bin] * RECORD_BYTES as u64).map_err(spill_io)?;
                cursor[bin] += group.len() as u64;
            }
            Ok(())
        })?;
        if cursor.iter().zip(&starts[1..]).any(|(written, end)| written != end) {
            return Err(invalid("the file changed while it was read".into()));
        }

        let mut producer = SuperbrickParticleProducer {
            shape: TreeShape::new(2, settings.brick_size, 0).map_err(|error| invalid(error.to_string()))?,
            fit,
            bounds: (lower, upper),
            per_axis,
            superbrick_level,
            spill,
            starts,
            extents: Vec::new(),
            support_cap: f32::INFINITY,
            coarse: Vec::new(),
            oracle: Vec::new(),
            max_support: 0.0,
            cache: Mutex::new(SuperbrickCache::default()),
            loaded_signal: std::sync::Condvar::new(),
            budget_particles,
            total_mass,
            scale: FieldScale::of_densities(1.0, 1.0, settings.attribute),
        };

        // Smoothing lengths where the file has none: per superbrick, over it and its neighbours' nearby particles.
        if !has_smoothing {
            let mut histogram = LogHistogram::new();
            let reach = 0.25 / per_axis as f64;
            let cap = (0.5 / per_axis as f64).min(0.1);
            for bin in 0..bins {
                let mut own = producer.read(bin).map_err(spill_io)?;
                if own.is_empty() {
                    continue;
                }
                let neighbours = producer.neighbourhood(bin, reach).map_err(spill_io)?;
                let points: Vec<[f64; 3]> = own
                    .iter()
                    .chain(&neighbours)
                    .map(|r| [f64::from(r[0]), f64::from(r[1]), f64::from(r[2])])
                    .collect();
                let h: Vec<f64> = if count < 2 {
                    vec![0.05f64.min(cap)]
                } else if points.len() <= SMOOTHING_NEIGHBOURS.min(count as usize - 1) {
                    // The 8th neighbour (or the set's farthest) lies beyond `reach`: its h is past the cap.
                    vec![cap; own.len()]
                } else {
                    let tree: ImmutableKdTree<f64, 3> = ImmutableKdTree::new_from_slice(&points);
                    let k = (SMOOTHING_NEIGHBOURS + 1).min(points.len());
                    let wanted = std::num::NonZero::new(k).unwrap_or(std::num::NonZero::<usize>::MIN);
                    points[..own.len()]
                        .par_iter()
                        .map(|p| {
                            let nearest = tree.nearest_n::<SquaredEuclidean>(p, wanted);
                            let farthest = nearest.iter().map(|n| n.distance).fold(0.0, f64::max);
                            (2.0 * farthest.sqrt()).clamp(1e-6, cap)
                        })
                        .collect()
                };
                for (record, h) in own.iter_mut().zip(&h) {
                    record[3] = *h as f32;
                    histogram.add(f64::from(record[3]));
                }
                encode(own.iter(), &mut bytes);
                producer.spill.write_all_at(&bytes, producer.starts[bin] * RECORD_BYTES as u64).map_err(spill_io)?;
            }
            let median = histogram.median().unwrap_or(cap);
            producer.support_cap = (MAX_SUPPORT_OVER_MEDIAN * median) as f32;
        }

        // The supports' range, now that every particle has one.
        let (mut min_support, mut max_support) = (f64::INFINITY, 0.0f64);
        let mut extents = Vec::with_capacity(bins);
        for bin in 0..bins {
            let mut extent = SuperbrickExtent { lower: DVec3::INFINITY, upper: DVec3::NEG_INFINITY, max_support: 0.0 };
            let records = producer.read(bin).map_err(spill_io)?;
            // Rewritten in the order its index sorts them (support class, cell), so that each later load of the
            // superbrick sorts sorted keys (a linear pass) instead of shuffled ones.
            let (positions, support, masses) = index_input(records.iter(), MASS);
            let (_, order) = ParticleIndex::build(&positions, &support, &masses, false);
            let records: Vec<Record> = order.iter().map(|&i| records[i as usize]).collect();
            encode(records.iter(), &mut bytes);
            producer.spill.write_all_at(&bytes, producer.starts[bin] * RECORD_BYTES as u64).map_err(spill_io)?;
            for record in records {
                let p = DVec3::new(f64::from(record[0]), f64::from(record[1]), f64::from(record[2]));
                extent.lower = extent.lower.min(p);
                extent.upper = extent.upper.max(p);
                extent.max_support = extent.max_support.max(f64::from(record[3]));
                min_support = min_support.min(f64::from(record[3]));
            }
            max_support = max_support.max(extent.max_support);
            extents.push(extent);
        }
        producer.extents = extents;
        producer.max_support = max_support;
        let max_level = max_level_for(resolution_for(min_support));
        producer.shape =
            TreeShape::new(2, settings.brick_size, max_level).map_err(|error| invalid(error.to_string()))?;
        debug_assert!(superbrick_level <= max_level);

        // The probe, the oracle's counts and the coarse levels' aggregates, a superbrick at a time.
        // The last class holds every wider kernel.
        let class_support = |c: usize| match c {
            c if c + 1 == MAX_CLASSES => max_support,
            c => (min_support * 2f64.powi(c as i32 + 1)).min(max_support),
        };
        // As in memory, every particle of the two narrowest classes present is probed (the density peaks there).
        let mut present = [false; MAX_CLASSES];
        for bin in 0..bins {
            for record in producer.read(bin).map_err(spill_io)? {
                present[class_of(f64::from(record[3]), min_support)] = true;
            }
        }
        let narrow_end = (0..MAX_CLASSES).filter(|&c| present[c]).nth(2).unwrap_or(MAX_CLASSES);
        let mut counts: Vec<Option<GridCounts>> = vec![None; MAX_CLASSES];
        let mut densities = LogHistogram::new();
        let mut max_density = 0.0f64;
        let mut aggregates = Aggregates::new();
        for bin in 0..bins {
            let mut own = producer.read(bin).map_err(spill_io)?;
            if own.is_empty() {
                continue;
            }
            let neighbours = producer.kernels_reaching(bin).map_err(spill_io)?;
            let (positions, support, masses) = index_input(own.iter().chain(&neighbours), MASS);
            let (index, _) = ParticleIndex::build(&positions, &support, &masses, false);
            let first = producer.starts[bin];
            // The attribute needs every particle's density.
            let probed: Vec<f64> = (0..own.len())
                .into_par_iter()
                .map(|i| {
                    let narrow = class_of(support[i], min_support) < narrow_end;
                    match settings.attribute || narrow || (first + i as u64).is_multiple_of(64) {
                        true => index.kernel_sum(|j| f64::from(index.masses[j]), positions[i], 0.0),
                        false => 0.0,
                    }
                })
                .collect();
            for &d in &probed {
                max_density = max_density.max(d);
                densities.add(d);
            }
            if settings.attribute {
                // Every particle's kernel is positive at its own centre, so ρⱼ > 0.
                for (record, rho) in own.iter_mut().zip(&probed) {
                    record[WEIGHT] = (f64::from(record[MASS]) / rho * f64::from(record[WEIGHT])) as f32;
                }
                encode(own.iter(), &mut bytes);
                producer.spill.write_all_at(&bytes, first * RECORD_BYTES as u64).map_err(spill_io)?;
            }
            for i in 0..own.len() {
                let class = class_of(support[i], min_support);
                counts[class].get_or_insert_with(|| ParticleGrid::counting(oracle_cells(class_support(class))));
                if let Some(grid) = &mut counts[class] {
                    grid.add(positions[i]);
                }
                if superbrick_level > 0 {
                    let level = superbrick_level - 1;
                    let weight = f64::from(own[i][WEIGHT]);
                    aggregate_into(
                        &mut aggregates,
                        &producer.shape,
                        level,
                        positions[i],
                        support[i],
                        f64::from(masses[i]),
                        weight,
                    );
                }
            }
        }
        producer.oracle = counts
            .into_iter()
            .enumerate()
            .filter_map(|(class, grid)| Some((class_support(class), grid?.finish())))
            .collect();
        let typical_density = densities.median().unwrap_or(max_density);
        producer.scale = FieldScale::of_densities(max_density, typical_density, settings.attribute);
        if settings.attribute {
            // The interpolant's range at every particle, as in memory: one more pass with the weights.
            let (mut lower, mut upper) = (0.0f64, 0.0f64);
            for bin in 0..bins {
                let own = producer.read(bin).map_err(spill_io)?;
                if own.is_empty() {
                    continue;
                }
                let neighbours = producer.kernels_reaching(bin).map_err(spill_io)?;
                let (positions, support, weights) = index_input(own.iter().chain(&neighbours), WEIGHT);
                let (index, _) = ParticleIndex::build(&positions, &support, &weights, false);
                let fields: Vec<f64> = (0..own.len())
                    .into_par_iter()
                    .map(|i| index.kernel_sum(|j| f64::from(index.masses[j]), positions[i], 0.0))
                    .collect();
                lower = fields.iter().copied().fold(lower, f64::min);
                upper = fields.iter().copied().fold(upper, f64::max);
            }
            producer.scale.set_attribute_range(lower, upper);
        }

        // Coarse levels, bottom-up: each from the aggregates of the one below.
        let mut coarse = Vec::new();
        for level in (0..superbrick_level).rev() {
            let particles = aggregated_particles(&aggregates);
            let (positions, support): (Vec<DVec3>, Vec<f64>) = particles.iter().map(|a| (a.0, a.1)).unzip();
            let weights: Vec<f32> = particles.iter().map(|a| a.3 as f32).collect();
            let (index, _) = ParticleIndex::build(&positions, &support, &weights, false);
            if level > 0 {
                aggregates = Aggregates::new();
                for &(p, h, m, w) in &particles {
                    aggregate_into(&mut aggregates, &producer.shape, level - 1, p, h, m, w);
                }
            }
            coarse.push(index);
        }
        coarse.reverse();
        producer.coarse = coarse;
        Ok(producer)
    }

    /// The particles of superbrick `bin` as the spill file holds them (the adaptive cap applied).
    fn read(&self, bin: usize) -> std::io::Result<Vec<Record>> {
        let (from, to) = (self.starts[bin], self.starts[bin + 1]);
        let mut bytes = vec![0u8; ((to - from) as usize) * RECORD_BYTES];
        self.spill.read_exact_at(&mut bytes, from * RECORD_BYTES as u64)?;
        Ok(bytes
            .chunks_exact(RECORD_BYTES)
            .map(|r| {
                let mut record: Record =
                    [0, 4, 8, 12, 16, 20].map(|o| f32::from_le_bytes([r[o], r[o + 1], r[o + 2], r[o + 3]]));
                record[3] = record[3].min(self.support_cap);
                record
            })
            .collect())
    }

    /// Superbrick `bin`'s box (unit-cube units).
    fn superbrick_box(&self, bin: usize) -> (DVec3, DVec3) {
        let s = self.per_axis;
        let ijk = [bin as u64 % s, bin as u64 / s % s, bin as u64 / s / s];
        let width = 1.0 / s as f64;
        let lower = DVec3::from(ijk.map(|c| c as f64 * width));
        (lower, lower + DVec3::splat(width))
    }

    /// The particles of the superbricks around `bin` (not `bin` itself) within `reach` of its box.
    fn neighbourhood(&self, bin: usize, reach: f64) -> std::io::Result<Vec<Record>> {
        let (lower, upper) = self.superbrick_box(bin);
        let (lower, upper) = (lower - DVec3::splat(reach), upper + DVec3::splat(reach));
        let mut records = Vec::new();
        for other in self.bins_overlapping(lower, upper) {
            if other == bin {
                continue;
            }
            records.extend(self.read(other)?.into_iter().filter(|r| {
                let p = DVec3::new(f64::from(r[0]), f64::from(r[1]), f64::from(r[2]));
                p.cmpge(lower).all() && p.cmple(upper).all()
            }));
        }
        Ok(records)
    }

    /// The particles of the other superbricks whose kernels reach superbrick `bin`'s box (as far as each particle's
    /// own support: a few wide kernels do not bring in their superbricks' narrow ones).
    fn kernels_reaching(&self, bin: usize) -> std::io::Result<Vec<Record>> {
        let (lower, upper) = self.superbrick_box(bin);
        let reach = DVec3::splat(self.max_support);
        let mut records = Vec::new();
        for other in self.bins_overlapping(lower - reach, upper + reach) {
            if other == bin
                || self.starts[other] == self.starts[other + 1]
                || !self.extents[other].reaches(lower, upper, 0.0)
            {
                continue;
            }
            records.extend(self.read(other)?.into_iter().filter(|r| {
                let p = DVec3::new(f64::from(r[0]), f64::from(r[1]), f64::from(r[2]));
                (lower - p).max(p - upper).max(DVec3::ZERO).length() < f64::from(r[3])
            }));
        }
        Ok(records)
    }

    /// The superbricks overlapping the box `lower..upper`.
    fn bins_overlapping(&self, lower: DVec3, upper: DVec3) -> Vec<usize> {
        let s = self.per_axis;
        let cell = |v: f64| ((v * s as f64).floor().max(0.0) as u64).min(s - 1);
        let (from, to) = ([0, 1, 2].map(|a| cell(lower[a])), [0, 1, 2].map(|a| cell(upper[a])));
        let mut bins = Vec::new();
        for z in from[2]..=to[2] {
            for y in from[1]..=to[1] {
                for x in from[0]..=to[0] {
                    bins.push(((z * s + y) * s + x) as usize);
                }
            }
        }
        bins
    }

    /// Superbrick `bin`'s index, from the cache or loaded into it (evicting the least recently used beyond the
    /// budget).
    fn superbrick(&self, bin: usize) -> std::io::Result<Arc<ParticleIndex>> {
        let key = bin as u32;
        {
            let mut cache = self.cache.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
            loop {
                cache.clock += 1;
                let clock = cache.clock;
                if let Some((index, used)) = cache.loaded.get_mut(&key) {
                    *used = clock;
                    return Ok(Arc::clone(index));
                }
                // Not cached: load it, unless another thread is (then wait for it and look again).
                if cache.loading.insert(key) {
                    break;
                }
                cache = self.loaded_signal.wait(cache).unwrap_or_else(|poisoned| poisoned.into_inner());
            }
        }
        let loaded = self.read(bin).map(|records| {
            let (positions, support, masses) = index_input(records.iter(), WEIGHT);
            Arc::new(ParticleIndex::build(&positions, &support, &masses, false).0)
        });
        let mut cache = self.cache.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        cache.loading.remove(&key);
        self.loaded_signal.notify_all();
        let index = loaded?;
        cache.clock += 1;
        let clock = cache.clock;
        cache.loads += 1;
        cache.particles += index.len() as u64;
        cache.loaded.insert(key, (Arc::clone(&index), clock));
        while cache.particles > self.budget_particles && cache.loaded.len() > 1 {
            let oldest = cache.loaded.iter().filter(|(b, _)| **b != key).min_by_key(|(_, (_, used))| *used);
            let Some((&oldest, _)) = oldest else { break };
            if let Some((evicted, _)) = cache.loaded.remove(&oldest) {
                cache.particles -= evicted.len() as u64;
            }
        }
        cache.peak = cache.peak.max(cache.particles);
        Ok(index)
    }

    /// Where the particles sit in the unit cube.
    pub fn fit(&self) -> UnitCubeFit {
        self.fit
    }

    /// Axis-aligned bounds of the positions, file units (lower, upper).
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        self.bounds
    }

    /// `[0, ρ_top]` in file mass per file volume, or the attribute's interpolated range (as
    /// [`crate::ParticleProducer::value_range`]).
    pub fn value_range(&self) -> [f64; 2] {
        self.scale.value_range(&self.fit)
    }

    /// The median density at the probed particles, file mass per file volume.
    pub fn typical_density(&self) -> f64 {
        self.scale.typical_density(&self.fit)
    }

    /// How far beyond the particles' bounds (unit-cube units) the finest level's density reaches.
    pub fn margin(&self) -> f64 {
        self.max_support.max(MIN_SUPPORT_VOXELS * self.shape.voxel_size(self.shape.max_level))
    }

    /// Total mass.
    pub fn total_mass(&self) -> f64 {
        self.total_mass
    }

    /// Largest density found at a particle, unit-cube units.
    pub fn max_density(&self) -> f64 {
        self.scale.max_density
    }

    /// The density the voxel value 1 stands for, unit-cube units.
    pub fn density_scale(&self) -> f64 {
        self.scale.upper
    }

    /// What was built and what the cache did.
    pub fn statistics(&self) -> SuperbrickStatistics {
        let cache = self.cache.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        let largest = self.starts.windows(2).map(|w| w[1] - w[0]).max().unwrap_or(0);
        SuperbrickStatistics {
            particles: self.starts.last().copied().unwrap_or(0),
            superbricks_per_axis: self.per_axis,
            superbrick_level: self.superbrick_level,
            largest_superbrick: largest,
            budget_particles: self.budget_particles,
            peak_cached_particles: cache.peak,
            loads: cache.loads,
            coarse_particles: self.coarse.iter().map(|c| c.len() as u64).sum(),
            spill_bytes: self.starts.last().copied().unwrap_or(0) * RECORD_BYTES as u64,
        }
    }

    /// Bytes held in memory: the superbricks' offsets, the oracle, the coarse levels and the cached superbricks.
    pub fn heap_bytes(&self) -> u64 {
        let cached = self.cache.lock().unwrap_or_else(|poisoned| poisoned.into_inner()).particles;
        let coarse: u64 = self.coarse.iter().map(|c| c.heap_bytes()).sum();
        let oracle: u64 = self.oracle.iter().map(|(_, grid)| grid.heap_bytes()).sum();
        let extents = self.extents.len() * std::mem::size_of::<SuperbrickExtent>();
        (self.starts.len() * 8 + extents) as u64 + coarse + oracle + cached * BYTES_PER_LOADED_PARTICLE
    }
}

/// Records as the index's input: unit positions, supports, and the `column` (mass or weight) as the index's masses.
fn index_input<'a>(records: impl Iterator<Item = &'a Record>, column: usize) -> (Vec<DVec3>, Vec<f64>, Vec<f32>) {
    let mut positions = Vec::new();
    let mut support = Vec::new();
    let mut masses = Vec::new();
    for r in records {
        positions.push(DVec3::new(f64::from(r[0]), f64::from(r[1]), f64::from(r[2])));
        support.push(f64::from(r[3]));
        masses.push(r[column]);
    }
    (positions, support, masses)
}

/// Records as the spill file's bytes.
fn encode<'a>(records: impl Iterator<Item = &'a Record>, bytes: &mut Vec<u8>) {
    bytes.clear();
    for record in records {
        for v in record {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
}

impl Producer for SuperbrickParticleProducer {
    fn shape(&self) -> TreeShape {
        self.shape
    }

    fn oracle(&self, key: NodeKey) -> Option<f32> {
        let (lower, size) = key.bounds(&self.shape);
        let voxel = size / f64::from(self.shape.brick_size);
        let reaches = self.oracle.iter().any(|(max_support, grid)| {
            grid.any_near(DVec3::from(lower), size, max_support.max(MIN_SUPPORT_VOXELS * voxel) + voxel)
        });
        if reaches {
            None
        } else {
            Some(self.scale.empty_value())
        }
    }

    fn produce(&self, key: NodeKey, voxels: &mut [u16]) -> Result<Produced, ProduceError> {
        let b = self.shape.stored_brick_size() as usize;
        let (_, size) = key.bounds(&self.shape);
        let voxel = size / f64::from(self.shape.brick_size);
        let min_support = MIN_SUPPORT_VOXELS * voxel;
        let first = DVec3::from(key.voxel_centre(&self.shape, 0, 0, 0));
        let last = first + DVec3::splat((b - 1) as f64 * voxel);
        let mut density = vec![0.0f64; b * b * b];
        let mut reached = false;
        if let Some(coarse) = self.coarse.get(key.level as usize) {
            reached = coarse.splat(|i| f64::from(coarse.masses[i]), first, voxel, b, min_support, &mut density);
        } else {
            let reach = DVec3::splat(self.max_support.max(min_support));
            for bin in self.bins_overlapping(first - reach, last + reach) {
                if self.starts[bin] == self.starts[bin + 1] || !self.extents[bin].reaches(first, last, min_support) {
                    continue;
                }
                let index = self.superbrick(bin).map_err(|error| ProduceError {
                    level: key.level,
                    ijk: key.ijk,
                    message: format!("reading superbrick {bin} from the spill file: {error}"),
                })?;
                reached |= index.splat(|i| f64::from(index.masses[i]), first, voxel, b, min_support, &mut density);
            }
        }
        Ok(self.scale.brick(reached, &density, voxels, key.level >= self.shape.max_level))
    }
}

/// File-name endings [`open_out_of_core`] streams.
pub const STREAMED_FILE_ENDINGS: [&str; 4] = [".ply", ".xyz", ".csv", ".txt"];

/// Reads a particle file out of core: a binary PLY point file ([`PlyPointStream`]) or columns of text
/// ([`TextPointStream`]), by its name's ending. Returns the producer and the scalar attribute's name.
pub fn open_out_of_core(
    path: &Path,
    settings: ParticleTreeSettings,
    out_of_core: &OutOfCoreSettings,
) -> Result<(SuperbrickParticleProducer, String), GeometryError> {
    let name = path.to_string_lossy().to_lowercase();
    if name.ends_with(".ply") {
        let stream = PlyPointStream::open(path)?;
        Ok((SuperbrickParticleProducer::new(&stream, settings, out_of_core)?, stream.value_name().to_string()))
    } else if STREAMED_FILE_ENDINGS.iter().any(|e| name.ends_with(e)) {
        let stream = TextPointStream::open(path)?;
        Ok((SuperbrickParticleProducer::new(&stream, settings, out_of_core)?, stream.value_name().to_string()))
    } else {
        Err(GeometryError::Unsupported {
            path: path.to_path_buf(),
            message: format!(
                "out of core reads {} files; convert this one to a binary PLY (x y z [h] [mass] [value] vertex \
                 properties)",
                STREAMED_FILE_ENDINGS.join(", ")
            ),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{ParticleProducer, RawParticles};
    use voxstream_core::NodeContent;

    /// A ball with a denser core, in file units around (10, 20, 30) with radius 5.
    fn cloud(count: usize, seed: u64) -> Vec<[f64; 3]> {
        let mut state = seed;
        let mut next = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        (0..count)
            .map(|_| loop {
                let p = [next() * 2.0 - 1.0, next() * 2.0 - 1.0, next() * 2.0 - 1.0];
                let r2: f64 = p.iter().map(|v| v * v).sum();
                if r2 <= 1.0 && (r2 < 0.2 || next() < 0.5) {
                    return [10.0 + 5.0 * p[0], 20.0 + 5.0 * p[1], 30.0 + 5.0 * p[2]];
                }
            })
            .collect()
    }

    fn out_of_core(memory_bytes: u64) -> OutOfCoreSettings {
        OutOfCoreSettings { memory_bytes, spill_directory: std::env::temp_dir() }
    }

    /// The largest difference between the two producers' fields over the non-empty nodes of `level` (every
    /// `stride`-th), relative to the in-memory value range, and the number of nodes compared.
    fn largest_difference(
        memory: &ParticleProducer,
        streamed: &SuperbrickParticleProducer,
        level: u32,
        stride: u64,
    ) -> (f64, usize) {
        let shape = memory.shape();
        assert_eq!(shape, streamed.shape());
        let per_axis = shape.nodes_per_axis(level);
        let (mut a, mut b) = (vec![0u16; shape.voxels_per_brick()], vec![0u16; shape.voxels_per_brick()]);
        let (mut worst, mut compared) = (0.0f64, 0);
        for index in (0..per_axis.pow(3)).step_by(stride as usize) {
            let key =
                NodeKey { level, ijk: [index % per_axis, index / per_axis % per_axis, index / per_axis / per_axis] };
            let (oracle_a, oracle_b) = (memory.oracle(key), streamed.oracle(key));
            if oracle_a.is_some() && oracle_b.is_some() {
                continue;
            }
            let pa = memory.produce(key, &mut a).unwrap();
            let pb = streamed.produce(key, &mut b).unwrap();
            if pa.content == NodeContent::Brick || pb.content == NodeContent::Brick {
                compared += 1;
                let value = |v: &[u16], i: usize, p: &Produced, [lower, upper]: [f64; 2]| {
                    let unit = match p.content {
                        NodeContent::Brick => f64::from(v[i]) / 65535.0,
                        NodeContent::Constant(c) => f64::from(c),
                        NodeContent::Empty => 0.0,
                    };
                    lower + unit * (upper - lower)
                };
                let [lower, upper] = memory.value_range();
                for i in 0..a.len() {
                    let da = value(&a, i, &pa, memory.value_range());
                    let db = value(&b, i, &pb, streamed.value_range());
                    worst = worst.max((da - db).abs() / (upper - lower));
                }
            }
        }
        (worst, compared)
    }

    #[test]
    fn out_of_core_bricks_equal_the_in_memory_ones_within_a_budget() {
        let positions = cloud(400_000, 5);
        let count = positions.len();
        let masses: Vec<f32> = (0..count).map(|i| 0.5 + (i % 4) as f32 * 0.25).collect();
        let set = ParticleSet::new(RawParticles {
            smoothing: vec![0.6; count],
            masses,
            positions,
            ..RawParticles::default()
        })
        .unwrap();
        let settings = ParticleTreeSettings { resolution: Some(256), ..ParticleTreeSettings::default() };
        let memory = ParticleProducer::new(&set, settings).unwrap();
        let streamed = SuperbrickParticleProducer::new(&set, settings, &out_of_core(MIN_MEMORY_BYTES)).unwrap();
        let statistics = streamed.statistics();
        assert_eq!(statistics.particles, count as u64);
        assert!(statistics.superbricks_per_axis >= 4, "{statistics:?}");
        assert!((streamed.total_mass() / memory.total_mass() - 1.0).abs() < 1e-9);
        // Every particle probed in both (one support class): the same peak, the same scale.
        assert!((streamed.density_scale() / memory.density_scale() - 1.0).abs() < 1e-9);
        assert!((streamed.typical_density() / memory.typical_density() - 1.0).abs() < 0.012);
        // At and below the superbricks' level, the same sums of the same kernels (up to the order of the sum and
        // 16-bit quantisation).
        let finest = memory.shape().max_level;
        for (level, stride) in [(statistics.superbrick_level, 1), (finest, 37)] {
            let (worst, compared) = largest_difference(&memory, &streamed, level, stride);
            assert!(compared > 20, "level {level}: {compared} bricks");
            assert!(worst <= 1.0 / 65535.0, "level {level}: {worst}");
        }
        // Coarser levels come from aggregated particles: close, not equal (1.1% of the scale at most, measured).
        for level in 0..statistics.superbrick_level {
            let (worst, compared) = largest_difference(&memory, &streamed, level, 1);
            assert!(compared > 0);
            assert!(worst < 0.02, "level {level}: {worst} of the density scale");
        }
        // Only part of the set was ever in memory.
        let statistics = streamed.statistics();
        assert!(statistics.loads > 0);
        assert!(
            statistics.peak_cached_particles <= statistics.budget_particles + statistics.largest_superbrick,
            "{statistics:?}"
        );
        assert!(statistics.peak_cached_particles < count as u64 / 2, "{statistics:?}");
    }

    #[test]
    fn out_of_core_density_integrates_to_the_total_mass_at_every_level() {
        let positions = cloud(60_000, 9);
        let set = ParticleSet::new(RawParticles {
            smoothing: vec![0.4; positions.len()],
            positions,
            ..RawParticles::default()
        })
        .unwrap();
        let settings = ParticleTreeSettings { resolution: Some(128), ..ParticleTreeSettings::default() };
        let producer = SuperbrickParticleProducer::new(&set, settings, &out_of_core(MIN_MEMORY_BYTES)).unwrap();
        assert!(producer.statistics().superbrick_level >= 1, "{:?}", producer.statistics());
        let shape = producer.shape();
        let m = shape.brick_size as usize;
        let b = m + 2;
        let mut voxels = vec![0u16; shape.voxels_per_brick()];
        for level in 0..=shape.max_level {
            let per_axis = shape.nodes_per_axis(level);
            let mut sum = 0.0;
            for index in 0..per_axis.pow(3) {
                let key = NodeKey {
                    level,
                    ijk: [index % per_axis, index / per_axis % per_axis, index / per_axis / per_axis],
                };
                if producer.oracle(key).is_some() {
                    continue;
                }
                if producer.produce(key, &mut voxels).unwrap().content != NodeContent::Brick {
                    continue;
                }
                for k in 1..=m {
                    for j in 1..=m {
                        for i in 1..=m {
                            sum += f64::from(voxels[(k * b + j) * b + i]) / 65535.0;
                        }
                    }
                }
            }
            let integral = sum * producer.density_scale() * shape.voxel_size(level).powi(3);
            let total = producer.total_mass();
            assert!((integral / total - 1.0).abs() < 0.01, "level {level}: {integral} vs {total}");
        }
    }

    #[test]
    fn adaptive_smoothing_per_superbrick_matches_the_whole_set() {
        // No smoothing lengths in the file: the k-d trees per superbrick give each particle the h the whole set's
        // tree gives it (up to the cap's median, taken from a histogram).
        let set = ParticleSet::new(RawParticles { positions: cloud(150_000, 21), ..RawParticles::default() }).unwrap();
        let settings = ParticleTreeSettings { resolution: Some(256), ..ParticleTreeSettings::default() };
        let memory = ParticleProducer::new(&set, settings).unwrap();
        let streamed = SuperbrickParticleProducer::new(&set, settings, &out_of_core(MIN_MEMORY_BYTES)).unwrap();
        assert!(streamed.statistics().superbricks_per_axis >= 4, "{:?}", streamed.statistics());
        assert!((streamed.margin() / memory.margin() - 1.0).abs() < 0.02, "{} {}", streamed.margin(), memory.margin());
        let level = memory.shape().max_level;
        let (worst, compared) = largest_difference(&memory, &streamed, level, 53);
        assert!(compared > 20);
        assert!(worst < 0.01, "{worst}");
    }

    #[test]
    fn an_attribute_out_of_core_equals_the_in_memory_one() {
        // A temperature rising along x: the SPH interpolant with weights mⱼ/ρⱼ·Aⱼ, ρⱼ probed at every particle.
        let positions = cloud(20_000, 13);
        let values: Vec<f32> = positions.iter().map(|p| (p[0] - 10.0) as f32 * 3.0 + 1.0).collect();
        let set = ParticleSet::new(RawParticles {
            smoothing: vec![0.6; positions.len()],
            masses: (0..positions.len()).map(|i| 1.0 + (i % 2) as f32).collect(),
            positions,
            values,
            value_name: "temperature".into(),
        })
        .unwrap();
        let settings =
            ParticleTreeSettings { resolution: Some(128), attribute: true, ..ParticleTreeSettings::default() };
        let memory = ParticleProducer::new(&set, settings).unwrap();
        let streamed = SuperbrickParticleProducer::new(&set, settings, &out_of_core(MIN_MEMORY_BYTES)).unwrap();
        let statistics = streamed.statistics();
        assert!(statistics.superbricks_per_axis >= 4, "{statistics:?}");
        let ([a0, a1], [b0, b1]) = (memory.value_range(), streamed.value_range());
        assert!(a0 < -10.0 && a1 > 10.0, "the range covers the temperatures: {a0} {a1}");
        assert!((a0 - b0).abs() < 1e-4 * (a1 - a0) && (a1 - b1).abs() < 1e-4 * (a1 - a0), "{a0} {a1} / {b0} {b1}");
        // Empty space is the voxel value of 0 in both.
        let far = NodeKey { level: 1, ijk: [0, 0, 0] };
        assert_eq!(memory.oracle(far).is_some(), streamed.oracle(far).is_some());
        for level in statistics.superbrick_level..=memory.shape().max_level {
            let stride = if level == statistics.superbrick_level { 1 } else { 7 };
            let (worst, compared) = largest_difference(&memory, &streamed, level, stride);
            assert!(compared > 10, "level {level}: {compared}");
            assert!(worst <= 2.0 / 65535.0, "level {level}: {worst}");
        }
        for level in 0..statistics.superbrick_level {
            let (worst, _) = largest_difference(&memory, &streamed, level, 1);
            assert!(worst < 0.02, "level {level}: {worst}");
        }
    }

    #[test]
    fn isolated_and_widely_smoothed_particles_match_the_in_memory_producer() {
        // An isolated trio (fewer than 8 neighbours anywhere near: in memory their h hits the cap, and must out of
        // core too), and one particle whose kernel spans the cube (it must not make the whole set one superbrick).
        let mut positions = cloud(40_000, 17);
        positions.extend([[40.0, 20.0, 30.0], [40.01, 20.0, 30.0], [40.0, 20.01, 30.0]]);
        let adaptive =
            ParticleSet::new(RawParticles { positions: positions.clone(), ..RawParticles::default() }).unwrap();
        let settings = ParticleTreeSettings { resolution: Some(64), ..ParticleTreeSettings::default() };
        let memory = ParticleProducer::new(&adaptive, settings).unwrap();
        let streamed = SuperbrickParticleProducer::new(&adaptive, settings, &out_of_core(MIN_MEMORY_BYTES)).unwrap();
        assert!(streamed.statistics().superbricks_per_axis >= 4, "{:?}", streamed.statistics());
        for level in streamed.statistics().superbrick_level..=memory.shape().max_level {
            let (worst, compared) = largest_difference(&memory, &streamed, level, 1);
            assert!(compared > 10);
            assert!(worst < 0.01, "adaptive, level {level}: {worst}");
        }
        let mut smoothing = vec![0.5f32; positions.len()];
        smoothing[7] = 40.0;
        let wide = ParticleSet::new(RawParticles { positions, smoothing, ..RawParticles::default() }).unwrap();
        let memory = ParticleProducer::new(&wide, settings).unwrap();
        let streamed = SuperbrickParticleProducer::new(&wide, settings, &out_of_core(MIN_MEMORY_BYTES)).unwrap();
        assert!(streamed.statistics().superbricks_per_axis >= 4, "{:?}", streamed.statistics());
        for level in streamed.statistics().superbrick_level..=memory.shape().max_level {
            let (worst, compared) = largest_difference(&memory, &streamed, level, 1);
            assert!(compared > 10);
            assert!(worst <= 1.0 / 65535.0, "one wide kernel, level {level}: {worst}");
        }
    }

    #[test]
    fn bad_settings_are_named() {
        let set = ParticleSet::new(RawParticles { positions: cloud(10, 1), ..RawParticles::default() }).unwrap();
        let small = SuperbrickParticleProducer::new(&set, ParticleTreeSettings::default(), &out_of_core(1 << 20));
        assert!(small.unwrap_err().to_string().contains("give at least 8 MiB"));
        let attribute = ParticleTreeSettings { attribute: true, ..ParticleTreeSettings::default() };
        let error = SuperbrickParticleProducer::new(&set, attribute, &out_of_core(MIN_MEMORY_BYTES)).unwrap_err();
        assert!(error.to_string().contains("no scalar attribute"), "{error}");
        let missing = OutOfCoreSettings {
            memory_bytes: MIN_MEMORY_BYTES,
            spill_directory: "/nonexistent/voxstream-spill".into(),
        };
        let error = SuperbrickParticleProducer::new(&set, ParticleTreeSettings::default(), &missing).unwrap_err();
        assert!(error.to_string().contains("/nonexistent/voxstream-spill"), "{error}");
    }

    #[test]
    fn the_log_histogram_median_is_within_its_bin() {
        let mut histogram = LogHistogram::new();
        for i in 1..=1001 {
            histogram.add(f64::from(i) * 1e-3);
        }
        let median = histogram.median().unwrap();
        assert!((median / 0.501 - 1.0).abs() < 0.011, "{median}");
        assert_eq!(LogHistogram::new().median(), None);
    }
}
