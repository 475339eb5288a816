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
//!    The *dense* superbricks (more than an eighth of the budget's particles) merge their particles closer than the
//!    finest voxels tell apart on the way ([`merge`]), so that no superbrick is read whole while binning however much
//!    of the file one place holds (10⁷ points in one place took 877 MB in 64 MiB; now 33 MB); a region denser than
//!    that, whose distinct particles one superbrick cannot hold within the budget, is refused naming the
//!    `--particle-memory` it needs.
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
//!    every `h` up to that cap exactly, each record counted with the particles it stands for
//!    ([`crate::neighbour_spacing`]: over distinct positions, so copies do not stall the tree). The median is taken
//!    from a fine histogram.
//! 4. **One pass over the superbricks**, each with the neighbours' particles whose kernels reach it: the density
//!    probe (largest and median density at the particles, probed as in memory: every particle of the two narrowest
//!    support classes present, one in 64 of the others), the oracle's counts per support class, and the aggregated
//!    particles of the coarse levels.
//! 5. **Levels at or below the superbricks' size** (a node inside one superbrick): resampled exactly as in memory
//!    from the particles of the superbricks its kernels reach, loaded on demand into an LRU cache of indices
//!    ([`crate::particle_index`]) that holds at most the budget's particles (plus those in use by bricks being made;
//!    a thread needing a superbrick another is loading waits for it). Not counted in the budget: the build
//!    passes' neighbourhoods (a superbrick and the kernels reaching it) and the coarse levels' aggregates.
//! 6. **Coarser levels** (a node spanning superbricks): the coarsest from particles aggregated per voxel of the
//!    level (mass summed, placed at the centre of mass, mass-weighted mean smoothing length; kernels of different
//!    widths kept apart) on cells half a voxel wide, built bottom-up and held in memory. A level of `c` cells per
//!    axis holds at most `min(c³, particles)` aggregates: only the levels whose aggregates fit a quarter of the
//!    memory budget are held ([`BYTES_PER_AGGREGATE`] each while built; 20 million particles in 64 MiB took
//!    2 GiB when every level was), and those between them and the superbricks' are resampled from the superbricks
//!    like the finer levels (exact; a node there loads each superbrick it spans in turn, through the cache). The
//!    aggregates' mass, hence the integral of the density, is exact; the profile is approximated (within 1.1% of
//!    the density scale on the tests' cloud; the kernel there is two voxels wide).
//!
//! 7. **The attribute** ([`ParticleTreeSettings::attribute`]): the probe pass computes the density at every particle
//!    and stores each particle's weight `mⱼ/ρⱼ·Aⱼ` in the spill file; one more pass over the superbricks evaluates the
//!    interpolant at every particle for its range, as the in-memory producer does.
//!
//! The build (steps 1 to 4 and 7) is `build`'s, one step function a pass; serving bricks (5 and 6) is `serve`'s,
//! over the `spill` file and the `coarse` levels.

mod build;
mod chunks;
mod coarse;
mod merge;
mod serve;
mod spill;
#[cfg(test)]
mod tests;

use std::path::Path;
use std::sync::Mutex;

use glam::DVec3;

pub use chunks::ParticleChunks;

use crate::error::GeometryError;
use crate::formats::ply::PlyPointStream;
use crate::formats::xyz::TextPointStream;
use crate::mesh_distance::UnitCubeFit;
use crate::particle_index::{ParticleGrid, ParticleIndex};
use crate::particle_producer::FieldScale;
use crate::ParticleTreeSettings;
use serve::SuperbrickCache;
use voxstream_core::TreeShape;

/// Most superbricks per axis (`32³` = 32,768 bins; the coarse levels' aggregates grow with it).
pub const MAX_SUPERBRICKS_PER_AXIS: u64 = 32;

/// Bytes a particle takes while its superbrick is loaded (index entry, sorting and gathering temporaries): what the
/// memory budget is divided by.
pub const BYTES_PER_LOADED_PARTICLE: u64 = 64;

/// Bytes an aggregated particle of the coarse levels takes at its most (while it is summed in a hash map, listed and
/// indexed; 28 once held).
pub const BYTES_PER_AGGREGATE: u64 = 256;

/// The coarse levels' aggregates may take a `1/AGGREGATE_SHARE` of the memory budget while they are built.
pub const AGGREGATE_SHARE: u64 = 4;

/// The smallest memory budget: room for 27 superbricks of a few thousand particles.
pub const MIN_MEMORY_BYTES: u64 = 8 << 20;

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
    /// Particles in the spill file: fewer where particles closer than a 64th of the finest voxel merged.
    pub spilled_particles: u64,
    /// Superbricks per axis.
    pub superbricks_per_axis: u64,
    /// The tree level whose nodes are superbricks (coarser levels use aggregated particles).
    pub superbrick_level: u32,
    /// Particles in the fullest superbrick.
    pub largest_superbrick: u64,
    /// Most records read from one superbrick at once, while binning or for bricks: what binning holds of a region
    /// however dense the file makes it (dense superbricks merge while they are binned).
    pub largest_read: u64,
    /// The cache's budget, particles.
    pub budget_particles: u64,
    /// Most particles the cache held at once.
    pub peak_cached_particles: u64,
    /// Superbricks loaded from the spill file for bricks (cache misses).
    pub loads: u64,
    /// Aggregated particles held for the coarse levels.
    pub coarse_particles: u64,
    /// Levels held as aggregates (the coarsest; those between them and the superbricks' are resampled from the
    /// superbricks).
    pub coarse_levels_held: u32,
    /// Bytes of the spill file.
    pub spill_bytes: u64,
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
    /// Aggregated particles of the coarsest levels (`coarse_held` of them; the levels between are resampled from
    /// the superbricks).
    coarse: Vec<ParticleIndex>,
    coarse_held: u32,
    /// The oracle: per support class, its largest support and its counts.
    oracle: Vec<(f64, ParticleGrid)>,
    max_support: f64,
    cache: Mutex<SuperbrickCache>,
    /// The most records [`SuperbrickParticleProducer::read`] read at once.
    largest_read: std::sync::atomic::AtomicU64,
    /// Signalled when a load ends.
    loaded_signal: std::sync::Condvar,
    budget_particles: u64,
    total_mass: f64,
    /// Particles in the file (the spill file holds fewer where close ones merged).
    count: u64,
    scale: FieldScale,
}

/// Where a superbrick's kernels reach: its particles' bounds and their largest support (unit-cube units).
#[derive(Clone, Copy, Debug)]
pub(super) struct SuperbrickExtent {
    lower: DVec3,
    upper: DVec3,
    max_support: f64,
}

impl SuperbrickExtent {
    /// Whether a kernel of this superbrick, widened to `min_support`, may reach the box `lower..upper`.
    pub(super) fn reaches(&self, lower: DVec3, upper: DVec3, min_support: f64) -> bool {
        let reach = DVec3::splat(self.max_support.max(min_support));
        (self.lower - reach).cmple(upper).all() && (self.upper + reach).cmpge(lower).all()
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
