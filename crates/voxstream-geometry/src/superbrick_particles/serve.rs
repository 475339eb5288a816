//! Serving bricks (the module's steps 5 and 6): levels at or below the superbricks' size resampled from the
//! superbricks their kernels reach, loaded on demand into an LRU cache within the memory budget; the coarsest levels
//! from the aggregates held in memory, and any level between them and the superbricks' from the superbricks too. Also what the producer tells of itself (ranges, statistics, memory).

use std::collections::HashMap;
use std::sync::Arc;

use glam::DVec3;
use voxstream_core::{NodeKey, ProduceError, Produced, Producer, TreeShape};

use super::spill::{index_input, RECORD_BYTES, WEIGHT};
use super::{SuperbrickExtent, SuperbrickParticleProducer, SuperbrickStatistics, BYTES_PER_LOADED_PARTICLE};
use crate::mesh_distance::UnitCubeFit;
use crate::particle_index::ParticleIndex;
use crate::particle_producer::MIN_SUPPORT_VOXELS;

/// Loaded superbricks, least recently used evicted first.
#[derive(Debug, Default)]
pub(super) struct SuperbrickCache {
    loaded: HashMap<u32, (Arc<ParticleIndex>, u64)>,
    /// Superbricks a thread is loading: others wait for it rather than load them twice.
    loading: std::collections::HashSet<u32>,
    particles: u64,
    peak: u64,
    clock: u64,
    loads: u64,
}

impl SuperbrickParticleProducer {
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
            particles: self.count,
            spilled_particles: self.starts.last().copied().unwrap_or(0),
            superbricks_per_axis: self.per_axis,
            superbrick_level: self.superbrick_level,
            largest_superbrick: largest,
            largest_read: self.largest_read.load(std::sync::atomic::Ordering::Relaxed),
            budget_particles: self.budget_particles,
            peak_cached_particles: cache.peak,
            loads: cache.loads,
            coarse_particles: self.coarse.iter().map(|c| c.len() as u64).sum(),
            coarse_levels_held: self.coarse_held,
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
