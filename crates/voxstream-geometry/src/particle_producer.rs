//! The particle producer: SPH density bricks resampled from particles when a ray asks for them.
//!
//! Reichl (seed 004, ch. 5) renders huge SPH runs by resampling the particles into multiresolution bricks with the
//! SPH kernel. Here each brick is made on demand: the particles whose kernels reach the brick are found through a
//! index built once (support classes on sorted cells), and each adds `m·W(|x − xⱼ|, h)` to the voxels within its support.
//!
//! - **Kernel:** the cubic B-spline (Monaghan's M4) with compact support `h`, normalised in 3-D so that its
//!   integral is 1: `W(r, h) = 8/(πh³)·(1 − 6q² + 6q³)` for `q = r/h ≤ ½`, `16/(πh³)·(1 − q)³` for `½ < q ≤ 1`,
//!   0 beyond. The density field therefore integrates to the total mass.
//! - **Levels:** level `L` uses `h' = max(h, 2·voxel_L)`: each level is the same density smoothed to what its voxels
//!   can hold, so it still integrates to the total mass and the finer levels refine it; a coarse level is never
//!   built from its children (Reichl averages them bottom-up), which is what lets any node be produced first.
//! - **Values:** voxels hold `ρ / ρ_max` with `ρ_max` the largest density found at the particles when opening (at
//!   every particle of the two narrowest support classes, where the density peaks, and one in 64 of the others),
//!   clamped at 1 where the density exceeds it (between particles, or at a peak the probe missed). The scale's top is
//!   at most [`DENSITY_RANGE`] times the median density at the particles: 16-bit voxels cannot hold the 10⁸ between a
//!   cluster's core and its halo, so the densest cores saturate rather than the halo vanishing below one step. The value range is
//!   `[0, ρ_max]` in the file's mass per file volume unit.
//! - **Smoothing lengths:** the file's, or, where it has none, `h = 2·(distance to the 8th nearest neighbour)` per
//!   particle (a k-d tree, `kiddo`): narrow kernels in dense clusters, wide ones in sparse outskirts.
//! - **Index:** a [`crate::particle_index`] over every particle: support classes (powers of two of the smallest
//!   `h`), each sorted by its cells on a grid no finer than its widest kernel, so gathering around a point visits
//!   about as many particles as reach it, whatever the spread of `h`.
//! - **Oracle:** a node is empty when no particle of any class lies within its box widened by that class's support,
//!   counted with each class's summed-area table: empty space is never produced.
//!
//! The index is built in memory; particle sets larger than memory go to the out-of-core
//! [`crate::SuperbrickParticleProducer`] (Reichl's superbricks), which makes the same bricks.
//! - **Attribute:** with [`ParticleTreeSettings::attribute`], the particles' scalar attribute is resampled instead,
//!   with the standard SPH interpolant `A(x) = Σ mⱼ/ρⱼ·Aⱼ·W(|x − xⱼ|, h)` (ρⱼ the density at particle j): it
//!   reproduces the attribute inside the particle set and fades to 0 outside it (not Shepard-normalised, so it
//!   overshoots somewhat at the set's boundary, where Σ mⱼ/ρⱼ·W is not 1). Voxel values map its range, which
//!   includes 0 (empty space), to 0…1.

use glam::DVec3;

use crate::neighbour_spacing::DistinctPositions;
use rayon::prelude::*;
use voxstream_core::{quantize, NodeContent, NodeKey, ProduceError, Produced, Producer, TreeShape};

use crate::error::GeometryError;
use crate::mesh_distance::UnitCubeFit;
pub use crate::particle_index::cubic_spline;
use crate::particle_index::ParticleIndex;
use crate::particles::ParticleSet;

/// The top of the density scale, in median densities at the particles (see [`ParticleProducer::value_range`]).
pub const DENSITY_RANGE: f64 = 1000.0;

/// The factors [`ParticleTreeSettings::smoothing_scale`] may take: beyond them a file's smoothing lengths are in other
/// units, which belongs fixed at the source rather than by a factor (and a huge reach would merge every particle).
pub const SMOOTHING_SCALE_RANGE: std::ops::RangeInclusive<f64> = 0.01..=100.0;

/// The kernel's support, in voxels of a level, below which a level widens the kernel.
pub const MIN_SUPPORT_VOXELS: f64 = 2.0;

/// How particles become a tree.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParticleTreeSettings {
    /// Voxels per brick edge (without border).
    pub brick_size: u32,
    /// Virtual resolution of the finest level per axis (`None`: four voxels across the smallest smoothing length,
    /// between 256 and 8192).
    pub resolution: Option<u64>,
    /// Fraction of the cube's edge the particles' bounds take (the rest is margin for the kernels).
    pub fill: f64,
    /// Factor applied to the file's smoothing lengths (molecular files give atomic radii: 2 makes an atom's
    /// density fall to zero at twice its radius).
    pub smoothing_scale: f64,
    /// Resample the particles' scalar attribute `A` instead of the density: `A(x) = Σ mⱼ/ρⱼ·Aⱼ·W(|x − xⱼ|, h)`,
    /// the SPH interpolant, with `ρⱼ` the density at particle j.
    pub attribute: bool,
}

impl Default for ParticleTreeSettings {
    fn default() -> Self {
        ParticleTreeSettings { brick_size: 8, resolution: None, fill: 0.8, smoothing_scale: 1.0, attribute: false }
    }
}

/// What the voxel values 0 and 1 stand for, and the densities found at the particles when opening: the scale both
/// particle producers (in memory and out of core) quantise their fields with.
#[derive(Clone, Copy, Debug)]
pub(crate) struct FieldScale {
    /// Largest density at a particle, unit-cube units.
    pub(crate) max_density: f64,
    /// Median density at the probed particles, unit-cube units.
    pub(crate) typical_density: f64,
    /// The field values the voxel values 0 and 1 stand for (unit-cube units for the density).
    pub(crate) lower: f64,
    pub(crate) upper: f64,
    pub(crate) attribute: bool,
}

impl FieldScale {
    /// The density scale from the largest and the median density probed (unit-cube units; 0: none found): 16-bit
    /// voxels cannot span the density range of clustered particles (10⁸ between a cluster's core and its halo is
    /// common), so the top of the scale is at most [`DENSITY_RANGE`] times the median, and denser voxels saturate.
    pub(crate) fn of_densities(max_density: f64, typical_density: f64, attribute: bool) -> FieldScale {
        let max_density = if max_density > 0.0 { max_density } else { 1.0 };
        let upper = max_density.min(DENSITY_RANGE * typical_density.max(f64::MIN_POSITIVE));
        FieldScale { max_density, typical_density, lower: 0.0, upper, attribute }
    }

    /// The attribute's scale: its range at the particles, which includes 0 (where no particle reaches).
    pub(crate) fn set_attribute_range(&mut self, lower: f64, upper: f64) {
        self.lower = lower;
        self.upper = if upper > lower { upper } else { lower + 1.0 };
    }

    /// `[0, ρ_top]` in file mass per file volume, or the attribute's range.
    pub(crate) fn value_range(&self, fit: &UnitCubeFit) -> [f64; 2] {
        if self.attribute {
            [self.lower, self.upper]
        } else {
            [0.0, self.upper / fit.size.powi(3)]
        }
    }

    /// The median density in file mass per file volume.
    pub(crate) fn typical_density(&self, fit: &UnitCubeFit) -> f64 {
        self.typical_density / fit.size.powi(3)
    }

    /// The voxel value (0 to 1) where no particle reaches.
    pub(crate) fn empty_value(&self) -> f32 {
        quantize((-self.lower / (self.upper - self.lower)) as f32) as f32 / 65535.0
    }

    /// A brick from the field summed at its voxels (`reached`: whether any kernel reached it), as `produce` returns it.
    pub(crate) fn brick(&self, reached: bool, field: &[f64], voxels: &mut [u16], is_finest: bool) -> Produced {
        if !reached {
            let content = match self.empty_value() {
                0.0 => NodeContent::Empty,
                value => NodeContent::Constant(value),
            };
            return Produced { content, is_terminal: true };
        }
        let scale = 1.0 / (self.upper - self.lower);
        for (voxel, value) in voxels.iter_mut().zip(field) {
            *voxel = quantize(((value - self.lower) * scale).clamp(0.0, 1.0) as f32);
        }
        Produced { content: NodeContent::Brick, is_terminal: is_finest }
    }
}

/// The particle producer (N = 2).
#[derive(Clone, Debug)]
pub struct ParticleProducer {
    shape: TreeShape,
    fit: UnitCubeFit,
    /// Every particle, binned (unit-cube units).
    index: ParticleIndex,
    /// Attribute mode: what each particle adds, times its kernel, `mⱼ/ρⱼ·Aⱼ` (index order). Density mode: `None`,
    /// the masses.
    attribute_weights: Option<Vec<f64>>,
    total_mass: f64,
    scale: FieldScale,
}

impl ParticleProducer {
    /// Places the particles in the unit cube, chooses smoothing lengths where the file has none, and bins them.
    pub fn new(particles: &ParticleSet, settings: ParticleTreeSettings) -> Result<ParticleProducer, GeometryError> {
        if settings.attribute && particles.values().0.is_empty() {
            return Err(GeometryError::Invalid {
                message: "the particles have no scalar attribute to render (a value column); render their density \
                          instead"
                    .into(),
            });
        }
        let (lower, upper) = particles.bounds();
        let fit = UnitCubeFit::checked_around(lower, upper, settings.fill)?;
        if !SMOOTHING_SCALE_RANGE.contains(&settings.smoothing_scale) {
            return Err(GeometryError::Invalid {
                message: format!(
                    "smoothing scale {} must be between {} and {}",
                    settings.smoothing_scale,
                    SMOOTHING_SCALE_RANGE.start(),
                    SMOOTHING_SCALE_RANGE.end()
                ),
            });
        }
        // The brick size is checked before it divides anything.
        TreeShape::new(2, settings.brick_size, 0)
            .map_err(|error| GeometryError::Invalid { message: error.to_string() })?;
        let count = particles.len();
        // Rounded to the single precision they are stored in, before anything is derived from them.
        let unit: Vec<DVec3> = particles.positions().iter().map(|p| fit.to_unit(*p).as_vec3().as_dvec3()).collect();
        let support: Vec<f64> = if particles.smoothing().is_empty() {
            adaptive_support(&unit)
        } else {
            particles.smoothing().iter().map(|&h| f64::from(h) * settings.smoothing_scale / fit.size).collect()
        };
        let support: Vec<f64> = support.into_iter().map(|h| f64::from(h as f32)).collect();
        // After the adaptive smoothing lengths, whose k-d tree is the build's peak.
        let masses: Vec<f32> =
            if particles.masses().is_empty() { vec![1.0; count] } else { particles.masses().to_vec() };
        let min_support = support.iter().copied().fold(f64::INFINITY, f64::min);
        let resolution =
            settings.resolution.unwrap_or_else(|| (4.0 / min_support.max(1e-9)).clamp(256.0, 8192.0) as u64);
        let bricks = resolution.div_ceil(u64::from(settings.brick_size)).max(1);
        let max_level = 64 - (bricks - 1).leading_zeros();
        let shape = TreeShape::new(2, settings.brick_size, max_level)
            .map_err(|error| GeometryError::Invalid { message: error.to_string() })?;

        // Particles at one position with one kernel add up to one particle of their summed mass: the density is the
        // same, and a pile of copies (a file of one point repeated) no longer makes every gather and every density
        // probe visit all of them (50,000 copies took a minute to open, a million hours). With an attribute, the
        // merged particle carries the values' mass-weighted mean: its `M/ρ·Ā` is the copies' `Σ mⱼ·Aⱼ/ρ`.
        // Particles closer than a 64th of the finest voxel (with kernels within 4.4%) merge the same way, at their
        // centre of mass: a cluster jittered far below the voxels (10⁶ points within 5·10⁻⁵ of one place, one 100
        // away) is a handful of particles, not a quadratic density probe (hours); the bricks, whose kernels are at
        // least two voxels wide, barely see the move.
        let merge_cell = shape.voxel_size(max_level) / MERGE_CELLS_PER_VOXEL;
        let values = settings.attribute.then(|| particles.values().0.to_vec());
        let (unit, support, masses, values) = merge_close(unit, support, masses, values, merge_cell);
        let count = unit.len();
        // Particles by support class (powers of two from the smallest), each class on a grid of cells no smaller
        // than its own largest support, sorted by (class, cell).
        let (index, order) = ParticleIndex::build(&unit, &support, &masses, true);
        // The index holds its own copies: the inputs go before the density probe allocates.
        drop((unit, support, masses));
        let order = if settings.attribute { order } else { Vec::new() };
        let total_mass = index.masses.iter().map(|&m| f64::from(m)).sum();
        let mut producer = ParticleProducer {
            shape,
            fit,
            index,
            attribute_weights: None,
            total_mass,
            scale: FieldScale::of_densities(1.0, 1.0, settings.attribute),
        };
        // The largest density is where the kernels are narrowest (the densest particles): exactly at every particle
        // of the two narrowest classes, and at one in 64 of the others (the attribute needs every particle's).
        let narrow_end = producer.index.class_start(2).unwrap_or(count);
        let probed = |i: &usize| settings.attribute || *i < narrow_end || i.is_multiple_of(64);
        let densities: Vec<f64> = (0..count)
            .into_par_iter()
            .map(|i| if probed(&i) { producer.density(producer.index.positions[i].as_dvec3(), 0.0) } else { 0.0 })
            .collect();
        let max_density = densities.iter().copied().fold(0.0, f64::max);
        let mut probed_densities: Vec<f64> = densities.iter().copied().filter(|&d| d > 0.0).collect();
        let middle = probed_densities.len() / 2;
        let typical_density = match probed_densities.is_empty() {
            true => max_density,
            false => *probed_densities.select_nth_unstable_by(middle, f64::total_cmp).1,
        };
        producer.scale = FieldScale::of_densities(max_density, typical_density, settings.attribute);
        if let Some(values) = values {
            // Every particle's kernel is positive at its own centre, so ρⱼ > 0.
            producer.attribute_weights = Some(
                order
                    .iter()
                    .zip(&densities)
                    .zip(&producer.index.masses)
                    .map(|((&i, rho), &m)| f64::from(m) / rho * f64::from(values[i as usize]))
                    .collect(),
            );
            let at_particles: Vec<f64> = (0..count)
                .into_par_iter()
                .map(|i| producer.field(producer.index.positions[i].as_dvec3(), 0.0))
                .collect();
            let lower = at_particles.iter().copied().fold(0.0, f64::min);
            let upper = at_particles.iter().copied().fold(0.0, f64::max);
            producer.scale.set_attribute_range(lower, upper);
        }
        Ok(producer)
    }

    /// Where the particles sit in the unit cube.
    pub fn fit(&self) -> UnitCubeFit {
        self.fit
    }

    /// The values the voxel values 0 and 1 stand for: `[0, ρ_top]` in file mass per file volume, `ρ_top` the peak
    /// density or [`DENSITY_RANGE`] times the median, whichever is lower (denser voxels saturate); or the attribute's
    /// interpolated range (including 0, its value where no particle reaches).
    pub fn value_range(&self) -> [f64; 2] {
        self.scale.value_range(&self.fit)
    }

    /// The median density at the particles (probed as for the peak), in file mass per file volume: where a default
    /// transfer function should put its ramp, the peak being often orders of magnitude above it.
    pub fn typical_density(&self) -> f64 {
        self.scale.typical_density(&self.fit)
    }

    /// How far beyond the particles' bounds (unit-cube units) the finest level's density reaches: the largest support.
    pub fn margin(&self) -> f64 {
        self.index.max_support.max(MIN_SUPPORT_VOXELS * self.shape.voxel_size(self.shape.max_level))
    }

    /// Total mass.
    pub fn total_mass(&self) -> f64 {
        self.total_mass
    }

    /// Largest density found at a particle, unit-cube units.
    pub fn max_density(&self) -> f64 {
        self.scale.max_density
    }

    /// The density the voxel value 1 stands for, unit-cube units (density mode).
    pub fn density_scale(&self) -> f64 {
        self.scale.upper
    }

    /// The density at unit point `p` with kernels no narrower than `min_support` (0: the particles' own).
    pub fn density(&self, p: DVec3, min_support: f64) -> f64 {
        self.index.kernel_sum(|i| f64::from(self.index.masses[i]), p, min_support)
    }

    /// The field rendered (density, or the attribute's interpolant) at unit point `p`.
    pub fn field(&self, p: DVec3, min_support: f64) -> f64 {
        self.index.kernel_sum(|i| self.weight(i), p, min_support)
    }

    /// What particle `i` adds, times its kernel: its mass (density), or `mⱼ/ρⱼ·Aⱼ` (attribute).
    #[inline]
    fn weight(&self, i: usize) -> f64 {
        match &self.attribute_weights {
            Some(weights) => weights[i],
            None => f64::from(self.index.masses[i]),
        }
    }

    /// Bytes held, for the memory budget: the index, and the attribute's weights.
    pub fn heap_bytes(&self) -> u64 {
        self.index.heap_bytes() + self.attribute_weights.as_ref().map_or(0, |w| w.len() as u64 * 8)
    }
}

/// Bytes per particle the in-memory producer holds while it renders (the index's position, support, class and
/// mass: [`ParticleProducer::heap_bytes`] without the coarse count tables and the attribute's weights), once built;
/// a file's count is checked before reading against the build's peak, [`BUILD_BYTES_PER_PARTICLE`].
pub const HELD_BYTES_PER_PARTICLE: u64 = 12 + 4 + 4 + 8;

/// Bytes per particle at the in-memory build's peak, the file's columns included: what a file's count is held to
/// before it is read. Measured as the slope of `voxstream render`'s largest resident set between 2·10⁵ and 2·10⁶
/// uniform points without smoothing lengths (the worst case: the adaptive lengths' k-d tree): 124 bytes (149 before
/// the build dropped its temporaries as it went and keyed the index in 16 bytes).
pub const BUILD_BYTES_PER_PARTICLE: u64 = 128;

/// Cells per finest voxel edge within which particles merge (see [`merge_close`]).
pub const MERGE_CELLS_PER_VOXEL: f64 = 64.0;

/// Particles in one cell of `cell` (unit units) whose supports lie within a sixteenth of an octave, merged into one
/// of their summed mass at their centre of mass (rounded to single precision) with their mass-weighted mean support
/// and, where given, value: exact copies of a point become one particle of the same density (and interpolated
/// attribute), and a cluster finer than the voxels a handful. Returned as given where nothing merges.
#[allow(clippy::type_complexity)]
fn merge_close(
    unit: Vec<DVec3>,
    support: Vec<f64>,
    masses: Vec<f32>,
    values: Option<Vec<f32>>,
    cell: f64,
) -> (Vec<DVec3>, Vec<f64>, Vec<f32>, Option<Vec<f32>>) {
    let key = |i: usize| {
        let c = unit[i].to_array().map(|v| (v / cell).floor() as i64);
        [c[0], c[1], c[2], (support[i].log2() * 16.0).floor() as i64]
    };
    let mut order: Vec<u32> = (0..unit.len() as u32).collect();
    order.par_sort_unstable_by_key(|&i| key(i as usize));
    if order.windows(2).all(|w| key(w[0] as usize) != key(w[1] as usize)) {
        return (unit, support, masses, values);
    }
    let (mut merged_unit, mut merged_support, mut merged_masses) = (Vec::new(), Vec::new(), Vec::new());
    let mut merged_values = values.as_ref().map(|_| Vec::new());
    let (mut mass, mut weight, mut position, mut reach, mut value) = (0.0f64, 0.0f64, DVec3::ZERO, 0.0f64, 0.0f64);
    for (n, &i) in order.iter().enumerate() {
        let i = i as usize;
        // Massless particles weigh a little in the mean, so a cell of them still has a position.
        let w = f64::from(masses[i]).max(1e-30);
        mass += f64::from(masses[i]);
        weight += w;
        position += unit[i] * w;
        reach += support[i] * w;
        value += values.as_ref().map_or(0.0, |v| f64::from(v[i])) * w;
        if n + 1 == order.len() || key(order[n + 1] as usize) != key(i) {
            merged_unit.push((position / weight).as_vec3().as_dvec3());
            merged_support.push(f64::from((reach / weight) as f32));
            merged_masses.push(mass as f32);
            if let Some(merged) = &mut merged_values {
                merged.push((value / weight) as f32);
            }
            (mass, weight, position, reach, value) = (0.0, 0.0, DVec3::ZERO, 0.0, 0.0);
        }
    }
    (merged_unit, merged_support, merged_masses, merged_values)
}

/// Neighbours the adaptive smoothing length reaches: `h = 2 · (distance to the 8th nearest other particle)`, about
/// 65 neighbours within the support in a uniform volume (SPH codes use 30 to 100).
pub const SMOOTHING_NEIGHBOURS: usize = 8;

/// Per-particle smoothing lengths for files that give none, adapted to the local spacing (a k-d tree's 8 nearest
/// neighbours), so that dense clusters get narrow kernels and sparse outskirts wide ones. Clamped to [1e-6, 0.1] of
/// the cube and to [`MAX_SUPPORT_OVER_MEDIAN`] times the median.
fn adaptive_support(unit: &[DVec3]) -> Vec<f64> {
    if unit.len() < 2 {
        return vec![0.05; unit.len()];
    }
    // Over distinct positions, each with its multiplicity (see [`crate::neighbour_spacing`]).
    let distinct = DistinctPositions::new(unit.len(), |i| unit[i].to_array(), |_| 1);
    // Held no longer than needed: this is the in-memory build's peak (see [`BUILD_BYTES_PER_PARTICLE`]).
    let queries: Vec<u32> = (0..distinct.positions.len() as u32).collect();
    let distinct_support: Vec<f64> =
        distinct.neighbour_reach(&queries).into_iter().map(|reach| reach.clamp(1e-6, 0.1)).collect();
    drop(queries);
    let DistinctPositions { positions, multiplicity, of: distinct_of } = distinct;
    // Isolated particles (outliers, a sparse halo) would get kernels spanning much of the volume: their density is
    // negligible, but every brick their kernel touches would have to be made. At most four times the median, the
    // particles' median taken over the distinct positions weighted by their multiplicities.
    let mut by_support: Vec<u32> = (0..positions.len() as u32).collect();
    drop(positions);
    by_support.par_sort_unstable_by(|&a, &b| distinct_support[a as usize].total_cmp(&distinct_support[b as usize]));
    let middle = (unit.len() / 2) as u64;
    let mut seen = 0u64;
    let median = by_support
        .iter()
        .find_map(|&d| {
            seen += multiplicity[d as usize];
            (seen > middle).then_some(distinct_support[d as usize])
        })
        .unwrap_or(0.1);
    drop((by_support, multiplicity));
    let cap = MAX_SUPPORT_OVER_MEDIAN * median;
    distinct_of.iter().map(|&d| distinct_support[d as usize].min(cap)).collect()
}

/// The adaptive smoothing length's cap, in median smoothing lengths.
pub const MAX_SUPPORT_OVER_MEDIAN: f64 = 4.0;

impl Producer for ParticleProducer {
    fn shape(&self) -> TreeShape {
        self.shape
    }

    fn oracle(&self, key: NodeKey) -> Option<f32> {
        let (lower, size) = key.bounds(&self.shape);
        let voxel = size / f64::from(self.shape.brick_size);
        match self.index.may_reach(DVec3::from(lower), size, MIN_SUPPORT_VOXELS * voxel, voxel) {
            true => None,
            false => Some(self.scale.empty_value()),
        }
    }

    fn produce(&self, key: NodeKey, voxels: &mut [u16]) -> Result<Produced, ProduceError> {
        let b = self.shape.stored_brick_size() as usize;
        let (_, size) = key.bounds(&self.shape);
        let voxel = size / f64::from(self.shape.brick_size);
        let min_support = MIN_SUPPORT_VOXELS * voxel;
        // Stored voxel (i, j, k) is centred at first + (i, j, k)·voxel.
        let first = DVec3::from(key.voxel_centre(&self.shape, 0, 0, 0));
        let mut density = vec![0.0f64; b * b * b];
        let reached = self.index.splat(|i| self.weight(i), first, voxel, b, min_support, &mut density);
        Ok(self.scale.brick(reached, &density, voxels, key.level >= self.shape.max_level))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::particles::RawParticles;

    fn particles(positions: Vec<[f64; 3]>, smoothing: Vec<f32>, masses: Vec<f32>) -> ParticleSet {
        ParticleSet::new(RawParticles { positions, smoothing, masses, ..RawParticles::default() }).unwrap()
    }

    fn random_cloud(count: usize, seed: u64) -> Vec<[f64; 3]> {
        let mut state = seed;
        let mut next = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        (0..count)
            .map(|_| {
                // A ball of radius 1 (rejection sampled) and a denser core.
                loop {
                    let p = [next() * 2.0 - 1.0, next() * 2.0 - 1.0, next() * 2.0 - 1.0];
                    let r2: f64 = p.iter().map(|v| v * v).sum();
                    if r2 <= 1.0 && (r2 < 0.2 || next() < 0.5) {
                        return p;
                    }
                }
            })
            .collect()
    }

    /// Issue 41: a file of one point repeated (100 M copies in a 600 KB `.ply.gz`) made every density probe and
    /// every gather visit every copy: opening 50,000 copies took a minute. Copies merge into one particle of their
    /// summed mass, with the same field.
    #[test]
    fn a_cluster_finer_than_a_voxel_merges_into_a_few_particles() {
        // 20,000 points jittered by 5·10⁻⁵ around the origin and one 100 units away (the cluster spans a 300th of a
        // voxel, yet its points differ in single precision): none were copies, every kernel reached every point,
        // and the density probe visited all 20,000 from each of them (quadratic: 3 s here, about two hours for 10⁶).
        // Within a 64th of a voxel they are a few particles of the same mass.
        let mut state = 11u64;
        let mut next = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut positions: Vec<[f64; 3]> = (0..20_000).map(|_| [next() * 5e-5, next() * 5e-5, next() * 5e-5]).collect();
        positions.push([100.0; 3]);
        let producer =
            ParticleProducer::new(&particles(positions, Vec::new(), Vec::new()), ParticleTreeSettings::default())
                .unwrap();
        let held = producer.index.positions.len();
        assert!(held <= 9, "{held} particles held for a cluster within a voxel and one outlier");
        assert_eq!(producer.total_mass(), 20_001.0);
    }

    #[test]
    fn copies_of_one_point_merge_into_one_particle_with_the_same_density() {
        let copies = 20_000;
        let mut positions = vec![[0.25, 0.5, 0.5]; copies];
        positions.extend([[0.75, 0.5, 0.5], [0.5, 0.25, 0.5]]);
        let count = positions.len();
        let set = ParticleSet::new(RawParticles {
            positions,
            smoothing: vec![0.1; count],
            masses: vec![1.0; count],
            ..RawParticles::default()
        })
        .unwrap();
        let producer = ParticleProducer::new(&set, ParticleTreeSettings::default()).unwrap();
        assert_eq!(producer.index.positions.len(), 3, "the copies are one particle");
        assert_eq!(producer.total_mass(), count as f64);
        // The density at the copies: all their kernels at distance zero (h = 0.1 file units).
        let fit = producer.fit();
        let at = fit.to_unit([0.25, 0.5, 0.5]);
        let h = 0.1 / fit.size;
        let expected = copies as f64 * cubic_spline(0.0, h);
        let density = producer.density(at, 0.0);
        assert!((density - expected).abs() < 1e-5 * expected, "{density} vs {expected}");
        // With an attribute, copies merge too (they kept every particle before), carrying their values'
        // mass-weighted mean: the interpolant at them, Σ mⱼ/ρ·Aⱼ·W(0) with ρ = Σ mⱼ·W(0), is that mean either way.
        let copies = ParticleSet::new(RawParticles {
            positions: vec![[0.0, 0.0, 0.0]; 4],
            smoothing: vec![0.1; 4],
            masses: vec![1.0, 1.0, 1.0, 3.0],
            values: vec![1.0, 2.0, 3.0, 4.0],
            value_name: "v".into(),
        })
        .unwrap();
        let settings = ParticleTreeSettings { attribute: true, ..ParticleTreeSettings::default() };
        let producer = ParticleProducer::new(&copies, settings).unwrap();
        assert_eq!(producer.index.positions.len(), 1);
        let mean = (1.0 + 2.0 + 3.0 + 3.0 * 4.0) / 6.0;
        let at = producer.fit().to_unit([0.0; 3]);
        let field = producer.field(at, 0.0);
        assert!((field - mean).abs() < 1e-5, "{field} vs {mean}");
        assert!((producer.value_range()[1] - mean).abs() < 1e-5, "{:?}", producer.value_range());
    }

    #[test]
    fn kernel_integrates_to_one() {
        let h = 0.7;
        // ∫ W 4πr² dr by the midpoint rule.
        let steps = 20000;
        let integral: f64 = (0..steps)
            .map(|i| {
                let r = (i as f64 + 0.5) / steps as f64 * h;
                cubic_spline(r, h) * 4.0 * std::f64::consts::PI * r * r * h / steps as f64
            })
            .sum();
        assert!((integral - 1.0).abs() < 1e-6, "{integral}");
        assert_eq!(cubic_spline(h * 1.01, h), 0.0);
    }

    /// Sums every voxel's density of `level` (bricks from the producer, border excluded) times the voxel volume.
    fn integrate(producer: &ParticleProducer, level: u32) -> f64 {
        let shape = producer.shape();
        let m = shape.brick_size as usize;
        let b = m + 2;
        let per_axis = shape.nodes_per_axis(level);
        let voxel = shape.voxel_size(level);
        let mut voxels = vec![0u16; shape.voxels_per_brick()];
        let mut sum = 0.0;
        for index in 0..per_axis.pow(3) {
            let key =
                NodeKey { level, ijk: [index % per_axis, index / per_axis % per_axis, index / per_axis / per_axis] };
            if producer.oracle(key).is_some() {
                continue;
            }
            let produced = producer.produce(key, &mut voxels).unwrap();
            if produced.content == NodeContent::Empty {
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
        sum * producer.density_scale() * voxel.powi(3)
    }

    #[test]
    fn density_integrates_to_the_total_mass_at_every_level() {
        let cloud = random_cloud(3000, 11);
        let masses: Vec<f32> = (0..cloud.len()).map(|i| 0.5 + (i % 3) as f32).collect();
        let set = particles(cloud, vec![0.15; 3000], masses);
        let settings = ParticleTreeSettings { resolution: Some(128), ..ParticleTreeSettings::default() };
        let producer = ParticleProducer::new(&set, settings).unwrap();
        let total = producer.total_mass();
        for level in 0..=producer.shape().max_level {
            let integral = integrate(&producer, level);
            // Quantisation to 16 bits and clamping at ρ_max cost a little; the kernel sums must hold the mass.
            assert!((integral / total - 1.0).abs() < 0.01, "level {level}: {integral} vs {total}");
        }
    }

    #[test]
    fn a_single_particle_profile_is_the_kernel() {
        let set = particles(vec![[0.0; 3]], vec![1.0], vec![2.0]);
        let producer = ParticleProducer::new(&set, ParticleTreeSettings::default()).unwrap();
        let centre = producer.fit().to_unit([0.0; 3]);
        let h = 1.0 / producer.fit().size;
        for step in 0..20 {
            let r = step as f64 / 20.0 * h * 1.1;
            let p = centre + DVec3::new(r, 0.0, 0.0);
            let expected = 2.0 * cubic_spline(r, h);
            assert!((producer.density(p, 0.0) - expected).abs() <= 1e-9 * expected.max(1.0));
        }
        // Bricks of the finest level sample the same profile (within 16-bit quantisation).
        let shape = producer.shape();
        let level = shape.max_level;
        let voxel = shape.voxel_size(level);
        assert!(MIN_SUPPORT_VOXELS * voxel < h, "the finest level keeps the particle's own kernel");
        let per_axis = shape.nodes_per_axis(level);
        let key_of = |p: DVec3| NodeKey { level, ijk: [0, 1, 2].map(|a| (p[a] * per_axis as f64) as u64) };
        let key = key_of(centre + DVec3::new(0.3 * h, 0.1 * h, 0.0));
        let mut voxels = vec![0u16; shape.voxels_per_brick()];
        producer.produce(key, &mut voxels).unwrap();
        let b = shape.stored_brick_size();
        for (n, &v) in voxels.iter().enumerate() {
            let p = DVec3::from(key.voxel_centre(&shape, n as u32 % b, n as u32 / b % b, n as u32 / b / b));
            let expected = 2.0 * cubic_spline((p - centre).length(), h) / producer.density_scale();
            assert!((f64::from(v) / 65535.0 - expected.min(1.0)).abs() < 2.0 / 65535.0, "{p}");
        }
        assert_eq!(producer.value_range()[1], producer.density_scale() / producer.fit().size.powi(3));
        assert_eq!(producer.density_scale(), producer.max_density(), "one particle: the peak is the median");
        assert!((producer.max_density() - 2.0 * cubic_spline(0.0, h)).abs() < 1e-9);
    }

    #[test]
    fn an_attribute_is_interpolated_where_particles_are() {
        // A lattice of particles carrying A = 7 (and −2 on one side): inside, the SPH interpolant Σ mⱼ/ρⱼ·Aⱼ·W
        // reproduces the values; outside the particles it is 0.
        let mut positions = Vec::new();
        let mut values = Vec::new();
        for k in 0..16 {
            for j in 0..16 {
                for i in 0..16 {
                    positions.push([i as f64, j as f64, k as f64]);
                    values.push(if i < 8 { 7.0 } else { -2.0 });
                }
            }
        }
        // A lone particle far away leaves empty space between.
        positions.push([200.0; 3]);
        values.push(7.0);
        let set = ParticleSet::new(RawParticles {
            smoothing: vec![3.0; positions.len()],
            positions,
            values,
            value_name: "temperature".into(),
            ..RawParticles::default()
        })
        .unwrap();
        let settings = ParticleTreeSettings { attribute: true, ..ParticleTreeSettings::default() };
        let producer = ParticleProducer::new(&set, settings).unwrap();
        let [lower, upper] = producer.value_range();
        // The range covers the values; at the lattice's corners the plain SPH interpolant overshoots (a particle there
        // has few neighbours, so Σ mⱼ/ρⱼ·W is not 1): a known property of the estimator, not normalised away here.
        assert!(lower < -1.9 && lower > -3.0 && upper > 6.9 && upper < 10.0, "{lower} {upper}");
        let at = |x: f64| producer.field(producer.fit().to_unit([x, 7.5, 7.5]), 0.0);
        assert!((at(3.5) - 7.0).abs() < 0.1, "{}", at(3.5));
        assert!((at(11.5) + 2.0).abs() < 0.05, "{}", at(11.5));
        assert_eq!(at(-5.0), 0.0);
        // Empty space is the voxel value of 0, not 0: the oracle and the bricks say so.
        let empty = producer.oracle(NodeKey { level: 3, ijk: [4, 4, 4] }).unwrap();
        assert!((f64::from(empty) - (-lower / (upper - lower))).abs() < 1e-4);
        let no_attribute = particles(vec![[0.0; 3]], vec![], vec![]);
        let error = ParticleProducer::new(&no_attribute, settings).unwrap_err().to_string();
        assert!(error.contains("no scalar attribute"), "{error}");
    }

    #[test]
    fn adaptive_smoothing_follows_the_local_spacing() {
        // Two lattices, spacing 0.01 and 0.03: inside each, the 8th neighbour is a face diagonal away (6 at s, then
        // 12 at s·√2), so h = 2·√2·s.
        let mut unit = Vec::new();
        for (origin, spacing) in [(0.1, 0.01), (0.5, 0.03)] {
            for k in 0..8 {
                for j in 0..8 {
                    for i in 0..8 {
                        unit.push(DVec3::new(i as f64, j as f64, k as f64) * spacing + DVec3::splat(origin));
                    }
                }
            }
        }
        let h = adaptive_support(&unit);
        let interior = |i: usize| {
            (i % 8).clamp(1, 6) == i % 8
                && (i / 8 % 8).clamp(1, 6) == i / 8 % 8
                && (i / 64 % 8).clamp(1, 6) == i / 64 % 8
        };
        for (i, h) in h.iter().enumerate().filter(|(i, _)| interior(*i)) {
            let spacing = if i < 512 { 0.01 } else { 0.03 };
            assert!((h - 2.0 * 2f64.sqrt() * spacing).abs() < 1e-9, "particle {i}: {h}");
        }
    }

    #[test]
    fn oracle_never_hides_density() {
        let cloud: Vec<[f64; 3]> = random_cloud(500, 3).into_iter().map(|p| [p[0] * 0.3, p[1], p[2] * 0.3]).collect();
        let set = particles(cloud, vec![], vec![]);
        let producer = ParticleProducer::new(&set, ParticleTreeSettings::default()).unwrap();
        let shape = producer.shape();
        let mut voxels = vec![0u16; shape.voxels_per_brick()];
        let mut empty = 0;
        for level in 1..4u32 {
            let per_axis = shape.nodes_per_axis(level);
            for index in 0..per_axis.pow(3) {
                let key = NodeKey {
                    level,
                    ijk: [index % per_axis, index / per_axis % per_axis, index / per_axis / per_axis],
                };
                if producer.oracle(key) == Some(0.0) {
                    empty += 1;
                    let produced = producer.produce(key, &mut voxels).unwrap();
                    assert!(
                        produced.content == NodeContent::Empty || voxels.iter().all(|&v| v == 0),
                        "the oracle called {key:?} empty"
                    );
                }
            }
        }
        assert!(empty > 10, "the slab leaves empty space the oracle finds: {empty}");
    }
}
