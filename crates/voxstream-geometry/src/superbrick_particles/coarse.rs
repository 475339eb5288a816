//! The coarse levels (the module's step 6): particles aggregated per half voxel of each level coarser than the
//! superbricks (mass summed, placed at the centre of mass, mass-weighted mean smoothing length, kernels of different
//! widths kept apart), built bottom-up and held in memory.

use std::collections::HashMap;

use glam::DVec3;
use voxstream_core::TreeShape;

use crate::particle_index::ParticleIndex;
use crate::particle_producer::MIN_SUPPORT_VOXELS;

/// Particles aggregated per half voxel of a coarse level: mass, mass-weighted position and support, summed weight.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Aggregate {
    mass: f64,
    weighted_position: DVec3,
    weighted_support: f64,
    weight: f64,
}

/// Aggregates per (cell, width class) of one coarse level.
pub(super) type Aggregates = HashMap<(u64, u8), Aggregate>;

/// Aggregation cells per voxel edge of a coarse level.
const AGGREGATE_CELLS_PER_VOXEL: f64 = 2.0;

pub(super) fn aggregate_into(
    aggregates: &mut Aggregates,
    shape: &TreeShape,
    level: u32,
    p: DVec3,
    h: f64,
    m: f64,
    w: f64,
) {
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

/// The coarse levels' indices, bottom-up from `aggregates` (the level above the superbricks'): each level from the
/// aggregates of the one below. Index `l` is level `l`.
pub(super) fn coarse_levels(
    mut aggregates: Aggregates,
    shape: &TreeShape,
    superbrick_level: u32,
) -> Vec<ParticleIndex> {
    let mut coarse = Vec::new();
    for level in (0..superbrick_level).rev() {
        let particles = aggregated_particles(&aggregates);
        let (positions, support): (Vec<DVec3>, Vec<f64>) = particles.iter().map(|a| (a.0, a.1)).unzip();
        let weights: Vec<f32> = particles.iter().map(|a| a.3 as f32).collect();
        let (index, _) = ParticleIndex::build(&positions, &support, &weights, false);
        if level > 0 {
            aggregates = Aggregates::new();
            for &(p, h, m, w) in &particles {
                aggregate_into(&mut aggregates, shape, level - 1, p, h, m, w);
            }
        }
        coarse.push(index);
    }
    coarse.reverse();
    coarse
}
