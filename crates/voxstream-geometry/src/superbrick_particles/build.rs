//! Building the out-of-core producer (the module's steps 1 to 4 and 7): the three streaming passes that bin the
//! particles into superbricks in the spill file, the adaptive smoothing lengths, the superbricks' extents, the probe
//! and the oracle, and the coarse levels' aggregates (Reichl, seed 004, ch. 5). Each pass is one step function;
//! [`SuperbrickParticleProducer::new`] runs them in order.

use std::os::unix::fs::FileExt;
use std::sync::Mutex;

use glam::DVec3;
use rayon::prelude::*;
use voxstream_core::TreeShape;

use super::coarse::{aggregate_into, coarse_levels, Aggregates};
use super::merge::{compact, merge_records, multiplicity, Merging, SpillMerger, BYTES_PER_MERGED_CELL, DENSE_SHARE};
use super::spill::{encode, index_input, Record, MASS, RECORD_BYTES, WEIGHT};
use super::{
    OutOfCoreSettings, ParticleChunks, SuperbrickCache, SuperbrickExtent, SuperbrickParticleProducer, AGGREGATE_SHARE,
    BYTES_PER_AGGREGATE, BYTES_PER_LOADED_PARTICLE, MAX_SUPERBRICKS_PER_AXIS, MIN_MEMORY_BYTES,
};
use crate::error::GeometryError;
use crate::mesh_distance::UnitCubeFit;
use crate::neighbour_spacing::DistinctPositions;
use crate::particle_index::{class_of, oracle_cells, GridCounts, ParticleGrid, ParticleIndex, MAX_CLASSES};
use crate::particle_producer::{
    FieldScale, MAX_SUPPORT_OVER_MEDIAN, MERGE_CELLS_PER_VOXEL, SMOOTHING_NEIGHBOURS, SMOOTHING_SCALE_RANGE,
};
use crate::particles::check_particles;
use crate::ParticleTreeSettings;

fn invalid(message: String) -> GeometryError {
    GeometryError::Invalid { message }
}

/// A histogram of `log₂` values, 64 bins per octave over 2⁻¹²⁸…2¹²⁸: medians within 1.1% without holding the values.
pub(super) struct LogHistogram {
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
        self.add_n(value, 1);
    }

    /// Adds `value` `n` times.
    fn add_n(&mut self, value: f64, n: u64) {
        if value > 0.0 {
            let bin = ((value.log2() - Self::LOWEST) * Self::PER_OCTAVE).floor().max(0.0) as usize;
            let last = self.bins.len() - 1;
            self.bins[bin.min(last)] += n;
            self.count += n;
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

/// What the first pass finds: the count, the positions' bounds (file units), the smoothing lengths' range and
/// distribution, and the total mass.
struct Survey {
    count: u64,
    lower: [f64; 3],
    upper: [f64; 3],
    min_h: f64,
    max_h: f64,
    file_supports: LogHistogram,
    total_mass: f64,
}

/// Where a particle goes: the unit cube's fit and the superbricks per axis.
#[derive(Clone, Copy, Debug)]
struct Binning {
    fit: UnitCubeFit,
    per_axis: u64,
}

impl Binning {
    /// A file position in unit-cube units, rounded to single precision as the spill file holds it.
    fn unit_of(&self, p: [f64; 3]) -> DVec3 {
        self.fit.to_unit(p).as_vec3().as_dvec3()
    }

    /// The superbrick holding unit-cube position `p` (x fastest; clamped into the cube).
    fn superbrick_of(&self, p: DVec3) -> usize {
        let per_axis = self.per_axis;
        let c = [0, 1, 2].map(|a| ((p[a] * per_axis as f64).floor().max(0.0) as u64).min(per_axis - 1));
        ((c[2] * per_axis + c[1]) * per_axis + c[0]) as usize
    }
}

/// A file smoothing length `h` as a support in unit-cube units (single precision).
fn to_support(h: f32, settings: &ParticleTreeSettings, fit: &UnitCubeFit) -> f64 {
    f64::from((f64::from(h) * settings.smoothing_scale / fit.size) as f32)
}

/// The finest level's resolution, given or from the narrowest support.
fn resolution_for(settings: &ParticleTreeSettings, min_support: f64) -> u64 {
    settings
        .resolution
        .unwrap_or_else(|| (4.0 / min_support.max(1e-9)).clamp(256.0, MAX_DEFAULT_RESOLUTION as f64) as u64)
}

/// The finest level of a tree of `resolution` voxels per axis.
fn max_level_for(settings: &ParticleTreeSettings, resolution: u64) -> u32 {
    let bricks = resolution.div_ceil(u64::from(settings.brick_size)).max(1);
    64 - (bricks - 1).leading_zeros()
}

impl SuperbrickParticleProducer {
    /// Bins the particles of `source` into superbricks in a spill file, and probes them (see the module's steps).
    pub fn new(
        source: &dyn ParticleChunks,
        settings: ParticleTreeSettings,
        out_of_core: &OutOfCoreSettings,
    ) -> Result<SuperbrickParticleProducer, GeometryError> {
        let columns = source.columns();
        let [has_smoothing, _, _] = columns;
        check_settings(columns, &settings, out_of_core)?;
        let survey = survey(source, columns)?;
        let fit = UnitCubeFit::checked_around(survey.lower, survey.upper, settings.fill)?;
        let budget_particles = out_of_core.memory_bytes / BYTES_PER_LOADED_PARTICLE;
        let per_axis = superbricks_per_axis(&survey, &settings, &fit, has_smoothing, budget_particles);
        let superbrick_level = per_axis.trailing_zeros();
        let binning = Binning { fit, per_axis };
        // Particles closer than a 64th of the finest voxel merge, out of core as in memory (here the finest the
        // settings allow: the smallest support is not known yet); the dense superbricks already while binned.
        let merging =
            Merging { cell: finest_voxel_bound(&settings) / MERGE_CELLS_PER_VOXEL, attribute: settings.attribute };
        let counted = count_per_superbrick(source, &binning, survey.count)?;
        let binned = Spilling { binning, columns, merging, budget_particles, memory_bytes: out_of_core.memory_bytes };
        let (spill, starts) = binned.spill_records(source, &counted, &settings, out_of_core)?;
        check_largest_superbrick(&starts, per_axis, budget_particles, out_of_core.memory_bytes)?;
        let mut producer = SuperbrickParticleProducer {
            shape: TreeShape::new(2, settings.brick_size, 0).map_err(|error| invalid(error.to_string()))?,
            fit,
            bounds: (survey.lower, survey.upper),
            per_axis,
            superbrick_level,
            spill,
            starts,
            extents: Vec::new(),
            support_cap: f32::INFINITY,
            coarse: Vec::new(),
            coarse_held: 0,
            oracle: Vec::new(),
            max_support: 0.0,
            cache: Mutex::new(SuperbrickCache::default()),
            largest_read: Default::default(),
            loaded_signal: std::sync::Condvar::new(),
            budget_particles,
            total_mass: survey.total_mass,
            count: survey.count,
            scale: FieldScale::of_densities(1.0, 1.0, settings.attribute),
        };
        let spill_io = |error| GeometryError::Io { path: out_of_core.spill_directory.clone(), error };
        let adaptive = match has_smoothing {
            false => Some(producer.adaptive_smoothing(survey.count, &out_of_core.spill_directory).map_err(spill_io)?),
            true => None,
        };
        let min_support = producer.sort_and_measure(merging, adaptive.as_ref()).map_err(spill_io)?;
        let max_level = max_level_for(&settings, resolution_for(&settings, min_support));
        producer.shape =
            TreeShape::new(2, settings.brick_size, max_level).map_err(|error| invalid(error.to_string()))?;
        debug_assert!(superbrick_level <= max_level);
        producer.coarse_held =
            held_coarse_levels(survey.count, settings.brick_size, superbrick_level, out_of_core.memory_bytes);
        let aggregates = producer.probe(min_support, settings.attribute).map_err(spill_io)?;
        if settings.attribute {
            producer.attribute_range().map_err(spill_io)?;
        }
        producer.coarse = coarse_levels(aggregates, &producer.shape, producer.coarse_held);
        Ok(producer)
    }

    /// Smoothing lengths where the file has none: per superbrick, over it and its neighbours' nearby particles (the
    /// module's step 3), each record counted with the particles it stands for (merged while binned). Sets the
    /// adaptive cap from their median, and returns the lengths in a file of their own (a record's offset in the spill
    /// file, four bytes each): the neighbours' records must keep their counts until every superbrick is done.
    fn adaptive_smoothing(&mut self, count: u64, directory: &std::path::Path) -> std::io::Result<std::fs::File> {
        let per_axis = self.per_axis;
        let mut histogram = LogHistogram::new();
        let reach = 0.25 / per_axis as f64;
        let cap = (0.5 / per_axis as f64).min(0.1);
        let records = self.starts[self.starts.len() - 1];
        let lengths = tempfile::tempfile_in(directory)?;
        lengths.set_len(records * 4)?;
        let mut bytes = Vec::new();
        for bin in 0..self.starts.len() - 1 {
            let own = self.read(bin)?;
            if own.is_empty() {
                continue;
            }
            let neighbours = self.neighbourhood(bin, reach)?;
            let around: Vec<&Record> = own.iter().chain(&neighbours).collect();
            let particles: u64 = around.iter().map(|r| multiplicity(r)).sum();
            let h: Vec<f64> = if count < 2 {
                vec![0.05f64.min(cap); own.len()]
            } else if particles <= SMOOTHING_NEIGHBOURS.min(count as usize - 1) as u64 {
                // The 8th neighbour (or the set's farthest) lies beyond `reach`: its h is past the cap.
                vec![cap; own.len()]
            } else {
                let position = |i: usize| [0, 1, 2].map(|a| f64::from(around[i][a]));
                let distinct = DistinctPositions::new(around.len(), position, |i| multiplicity(around[i]));
                let mut queries = distinct.of[..own.len()].to_vec();
                queries.sort_unstable();
                queries.dedup();
                let reach = distinct.neighbour_reach(&queries);
                (0..own.len())
                    .map(|i| {
                        let q = queries.binary_search(&distinct.of[i]).unwrap_or(0);
                        reach[q].clamp(1e-6, cap)
                    })
                    .collect()
            };
            bytes.clear();
            for (record, h) in own.iter().zip(&h) {
                let h = *h as f32;
                histogram.add_n(f64::from(h), multiplicity(record));
                bytes.extend_from_slice(&h.to_le_bytes());
            }
            lengths.write_all_at(&bytes, self.starts[bin] * 4)?;
        }
        let median = histogram.median().unwrap_or(cap);
        self.support_cap = (MAX_SUPPORT_OVER_MEDIAN * median) as f32;
        Ok(lengths)
    }

    /// The supports' range, now that every particle has one (the `adaptive` smoothing lengths put in their records
    /// first, capped): each superbrick's extent, the largest support, and each superbrick's run rewritten in the
    /// order its index sorts them, its close particles merged first ([`merge_records`]; the runs compacted in place:
    /// a merged run ends no later than it did). Returns the smallest support.
    fn sort_and_measure(&mut self, merging: Merging, adaptive: Option<&std::fs::File>) -> std::io::Result<f64> {
        let bins = self.starts.len() - 1;
        let (mut min_support, mut max_support) = (f64::INFINITY, 0.0f64);
        let mut extents = Vec::with_capacity(bins);
        let mut compacted = vec![0u64; bins + 1];
        for bin in 0..bins {
            let mut extent = SuperbrickExtent { lower: DVec3::INFINITY, upper: DVec3::NEG_INFINITY, max_support: 0.0 };
            let mut records = self.read(bin)?;
            if let Some(lengths) = adaptive {
                let mut bytes = vec![0u8; records.len() * 4];
                lengths.read_exact_at(&mut bytes, self.starts[bin] * 4)?;
                for (record, h) in records.iter_mut().zip(bytes.chunks_exact(4)) {
                    record[3] = f32::from_le_bytes([h[0], h[1], h[2], h[3]]).min(self.support_cap);
                }
            }
            let records = merge_records(records, merging);
            compacted[bin + 1] = compacted[bin] + records.len() as u64;
            // Rewritten in the order its index sorts them (support class, cell), so that each later load of the
            // superbrick sorts sorted keys (a linear pass) instead of shuffled ones.
            let (positions, support, masses) = index_input(records.iter(), MASS);
            let (_, order) = ParticleIndex::build(&positions, &support, &masses, false);
            let records: Vec<Record> = order.iter().map(|&i| records[i as usize]).collect();
            self.write(compacted[bin], &records)?;
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
        self.extents = extents;
        self.max_support = max_support;
        if compacted[bins] < self.starts[bins] {
            self.spill.set_len(compacted[bins] * RECORD_BYTES as u64)?;
        }
        self.starts = compacted;
        Ok(min_support)
    }

    /// The probe, the oracle's counts and the coarse levels' aggregates, a superbrick at a time (the module's step
    /// 4): sets the oracle and the field's scale, stores the attribute's weights, and returns the aggregates of the
    /// level above the superbricks'.
    fn probe(&mut self, min_support: f64, attribute: bool) -> std::io::Result<Aggregates> {
        let bins = self.starts.len() - 1;
        let max_support = self.max_support;
        let coarse_held = self.coarse_held;
        // The last class holds every wider kernel.
        let class_support = |c: usize| match c {
            c if c + 1 == MAX_CLASSES => max_support,
            c => (min_support * 2f64.powi(c as i32 + 1)).min(max_support),
        };
        // As in memory, every particle of the two narrowest classes present is probed (the density peaks there).
        let mut present = [false; MAX_CLASSES];
        for bin in 0..bins {
            for record in self.read(bin)? {
                present[class_of(f64::from(record[3]), min_support)] = true;
            }
        }
        let narrow_end = (0..MAX_CLASSES).filter(|&c| present[c]).nth(2).unwrap_or(MAX_CLASSES);
        let mut counts: Vec<Option<GridCounts>> = vec![None; MAX_CLASSES];
        let mut densities = LogHistogram::new();
        let mut max_density = 0.0f64;
        let mut aggregates = Aggregates::new();
        for bin in 0..bins {
            let mut own = self.read(bin)?;
            if own.is_empty() {
                continue;
            }
            let neighbours = self.kernels_reaching(bin)?;
            let (positions, support, masses) = index_input(own.iter().chain(&neighbours), MASS);
            let (index, _) = ParticleIndex::build(&positions, &support, &masses, false);
            let first = self.starts[bin];
            // The attribute needs every particle's density.
            let probed: Vec<f64> = (0..own.len())
                .into_par_iter()
                .map(|i| {
                    let narrow = class_of(support[i], min_support) < narrow_end;
                    match attribute || narrow || (first + i as u64).is_multiple_of(64) {
                        true => index.kernel_sum(|j| f64::from(index.masses[j]), positions[i], 0.0),
                        false => 0.0,
                    }
                })
                .collect();
            for &d in &probed {
                max_density = max_density.max(d);
                densities.add(d);
            }
            if attribute {
                // Every particle's kernel is positive at its own centre, so ρⱼ > 0.
                for (record, rho) in own.iter_mut().zip(&probed) {
                    record[WEIGHT] = (f64::from(record[MASS]) / rho * f64::from(record[WEIGHT])) as f32;
                }
                self.write(first, &own)?;
            }
            for i in 0..own.len() {
                let class = class_of(support[i], min_support);
                counts[class].get_or_insert_with(|| ParticleGrid::counting(oracle_cells(class_support(class))));
                if let Some(grid) = &mut counts[class] {
                    grid.add(positions[i]);
                }
                if coarse_held > 0 {
                    let level = coarse_held - 1;
                    let weight = f64::from(own[i][WEIGHT]);
                    let mass = f64::from(masses[i]);
                    aggregate_into(&mut aggregates, &self.shape, level, positions[i], support[i], mass, weight);
                }
            }
        }
        self.oracle = counts
            .into_iter()
            .enumerate()
            .filter_map(|(class, grid)| Some((class_support(class), grid?.finish())))
            .collect();
        let typical_density = densities.median().unwrap_or(max_density);
        self.scale = FieldScale::of_densities(max_density, typical_density, attribute);
        Ok(aggregates)
    }

    /// The interpolant's range at every particle, as in memory: one more pass with the weights (the module's step
    /// 7).
    fn attribute_range(&mut self) -> std::io::Result<()> {
        let (mut lower, mut upper) = (0.0f64, 0.0f64);
        for bin in 0..self.starts.len() - 1 {
            let own = self.read(bin)?;
            if own.is_empty() {
                continue;
            }
            let neighbours = self.kernels_reaching(bin)?;
            let (positions, support, weights) = index_input(own.iter().chain(&neighbours), WEIGHT);
            let (index, _) = ParticleIndex::build(&positions, &support, &weights, false);
            let fields: Vec<f64> = (0..own.len())
                .into_par_iter()
                .map(|i| index.kernel_sum(|j| f64::from(index.masses[j]), positions[i], 0.0))
                .collect();
            lower = fields.iter().copied().fold(lower, f64::min);
            upper = fields.iter().copied().fold(upper, f64::max);
        }
        self.scale.set_attribute_range(lower, upper);
        Ok(())
    }
}

/// The settings and the file's columns, checked before the file is read.
fn check_settings(
    [_, _, has_values]: [bool; 3],
    settings: &ParticleTreeSettings,
    out_of_core: &OutOfCoreSettings,
) -> Result<(), GeometryError> {
    if settings.attribute && !has_values {
        return Err(invalid(
            "the particles have no scalar attribute to render (a value column); render their density instead".into(),
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
    Ok(())
}

/// How many of the levels coarser than the superbricks are held as aggregates (the module's step 6): those whose
/// aggregates fit [`AGGREGATE_SHARE`] of the memory budget at [`BYTES_PER_AGGREGATE`] each, counted at their most (a
/// level of `c` half-voxel cells per axis holds at most `c³` of them, and never more than the particles); the
/// finer ones are resampled from the superbricks like the levels below.
pub(super) fn held_coarse_levels(count: u64, brick_size: u32, superbrick_level: u32, memory_bytes: u64) -> u32 {
    let most = memory_bytes / AGGREGATE_SHARE / BYTES_PER_AGGREGATE;
    (0..superbrick_level)
        .take_while(|&level| {
            let cells = (2 * u64::from(brick_size)) << level;
            cells.saturating_pow(3).min(count) <= most
        })
        .count() as u32
}

/// The finest voxel the settings allow (the finest level's when `resolution` is given; else that of the largest
/// default resolution), unit-cube units.
fn finest_voxel_bound(settings: &ParticleTreeSettings) -> f64 {
    let level = max_level_for(settings, settings.resolution.unwrap_or(MAX_DEFAULT_RESOLUTION));
    1.0 / (f64::from(settings.brick_size) * 2f64.powi(level as i32))
}

/// The largest resolution [`resolution_for`] chooses by itself.
const MAX_DEFAULT_RESOLUTION: u64 = 8192;

/// Pass 1: count, bounds, smoothing lengths, mass; every run validated.
fn survey(source: &dyn ParticleChunks, columns: [bool; 3]) -> Result<Survey, GeometryError> {
    let [has_smoothing, has_masses, has_values] = columns;
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
    Ok(Survey { count, lower, upper, min_h, max_h, file_supports, total_mass })
}

/// The superbricks per axis (the module's step 2): the smallest power of two that puts at most a 216th of the
/// budget in a superbrick, within the finest level's bound, and halved while the file's kernels (all but the widest
/// thousandth) reach past half a superbrick.
fn superbricks_per_axis(
    survey: &Survey,
    settings: &ParticleTreeSettings,
    fit: &UnitCubeFit,
    has_smoothing: bool,
    budget_particles: u64,
) -> u64 {
    // The finest level, where it is known before the smoothing lengths are (it bounds the superbricks' level).
    let level_bound = match (settings.resolution, has_smoothing) {
        (Some(r), _) => max_level_for(settings, r),
        (None, true) => {
            max_level_for(settings, resolution_for(settings, to_support(survey.min_h as f32, settings, fit)))
        }
        (None, false) => max_level_for(settings, 256),
    };
    // A 216th of the budget per superbrick on average (measured on 8 million clustered particles at 64 and 256
    // MiB: a 27th, the neighbourhood's share, made superbricks the cache thrashed on, 1.4× slower).
    let target = (budget_particles / 216).max(1);
    let mut per_axis = 1u64;
    let most = MAX_SUPERBRICKS_PER_AXIS.min(1 << level_bound.min(5));
    while per_axis < most && survey.count / per_axis.pow(3) > target {
        per_axis *= 2;
    }
    if has_smoothing {
        // Kernels reaching at most half a superbrick (all but the widest thousandth: a few huge kernels must
        // not make the whole set one superbrick; theirs are found through the superbricks' extents).
        let wide = survey.file_supports.quantile(0.999).unwrap_or(survey.max_h).min(survey.max_h);
        let wide = to_support(wide as f32, settings, fit);
        while per_axis > 1 && per_axis as f64 * wide > 0.5 {
            per_axis /= 2;
        }
    }
    per_axis
}

/// Pass 2: particles per superbrick, as the offsets of each superbrick's run in the spill file (`S³ + 1`).
fn count_per_superbrick(source: &dyn ParticleChunks, binning: &Binning, count: u64) -> Result<Vec<u64>, GeometryError> {
    let bins = binning.per_axis.pow(3) as usize;
    let mut starts = vec![0u64; bins + 1];
    source.for_each_chunk(&mut |_, run| {
        for p in &run.positions {
            starts[binning.superbrick_of(binning.unit_of(*p)) + 1] += 1;
        }
        Ok(())
    })?;
    for i in 0..bins {
        starts[i + 1] += starts[i];
    }
    if starts[bins] != count {
        return Err(invalid("the file changed while it was read".into()));
    }
    Ok(starts)
}

/// Refuses a superbrick that, merged, still holds more particles than the memory budget (a region denser than the
/// superbricks can split: they are at most [`MAX_SUPERBRICKS_PER_AXIS`] a side), or than one index holds (2³²),
/// naming the `--particle-memory` that would hold it twice (it and its neighbours).
fn check_largest_superbrick(
    starts: &[u64],
    per_axis: u64,
    budget_particles: u64,
    memory_bytes: u64,
) -> Result<(), GeometryError> {
    let largest = starts.windows(2).map(|w| w[1] - w[0]).max().unwrap_or(0);
    if largest > budget_particles || largest > u64::from(u32::MAX) {
        let needed = (largest.saturating_mul(2 * BYTES_PER_LOADED_PARTICLE)).div_ceil(1 << 20);
        return Err(invalid(format!(
            "{largest} particles (after merging those closer than the finest voxels tell apart) lie in one \
             superbrick, 1/{per_axis} of the set's width a side: more than {} MiB of --particle-memory holds \
             ({budget_particles} at {BYTES_PER_LOADED_PARTICLE} bytes each); give --particle-memory {needed} or more{}",
            memory_bytes >> 20,
            if largest > u64::from(u32::MAX) {
                " (at most 2³² particles are read from one superbrick: split the file's densest region)"
            } else {
                ""
            }
        )));
    }
    Ok(())
}

/// How pass 3 writes the spill file.
struct Spilling {
    binning: Binning,
    columns: [bool; 3],
    merging: Merging,
    budget_particles: u64,
    memory_bytes: u64,
}

impl Spilling {
    /// Pass 3: each particle, in unit-cube units, to its superbrick's run of a new spill file (an external counting
    /// sort), the dense superbricks' records merged on the way (see [`super::merge`]). Returns the file and its runs'
    /// offsets (`S³ + 1`), compacted where merging left runs shorter than `counted`.
    fn spill_records(
        &self,
        source: &dyn ParticleChunks,
        counted: &[u64],
        settings: &ParticleTreeSettings,
        out_of_core: &OutOfCoreSettings,
    ) -> Result<(std::fs::File, Vec<u64>), GeometryError> {
        let Spilling { binning, columns: [has_smoothing, has_masses, _], .. } = *self;
        let count = counted[counted.len() - 1];
        let spill_io = |error| GeometryError::Io { path: out_of_core.spill_directory.clone(), error };
        let spill = tempfile::tempfile_in(&out_of_core.spill_directory).map_err(spill_io)?;
        spill.set_len(count * RECORD_BYTES as u64).map_err(spill_io)?;
        let dense_from = self.budget_particles / DENSE_SHARE;
        let dense = |bin: usize| counted[bin + 1] - counted[bin] > dense_from;
        let mut merger =
            SpillMerger::new(self.merging, (self.memory_bytes / AGGREGATE_SHARE / BYTES_PER_MERGED_CELL) as usize);
        let mut cursor = counted[..counted.len() - 1].to_vec();
        let mut seen = vec![0u64; cursor.len()];
        let mut bytes = Vec::new();
        source.for_each_chunk(&mut |_, run| {
            let mut binned: Vec<(usize, Record)> = run
                .positions
                .iter()
                .enumerate()
                .map(|(i, p)| {
                    let unit = binning.unit_of(*p);
                    // Before the adaptive smoothing lengths, minus the particles a record stands for.
                    let h = match has_smoothing {
                        true => to_support(run.smoothing[i], settings, &binning.fit) as f32,
                        false => -1.0,
                    };
                    let m = if has_masses { run.masses[i] } else { 1.0 };
                    let w = if settings.attribute { run.values[i] } else { m };
                    (binning.superbrick_of(unit), [unit.x as f32, unit.y as f32, unit.z as f32, h, m, w])
                })
                .collect();
            binned.sort_by_key(|&(bin, _)| bin);
            for group in binned.chunk_by(|a, b| a.0 == b.0) {
                let bin = group[0].0;
                seen[bin] += group.len() as u64;
                if counted[bin] + seen[bin] > counted[bin + 1] {
                    return Err(invalid("the file changed while it was read".into()));
                }
                if dense(bin) {
                    for (_, record) in group {
                        if merger.add(bin, record) {
                            merger.flush(&spill, &mut cursor).map_err(spill_io)?;
                        }
                    }
                    continue;
                }
                encode(group.iter().map(|(_, r)| r), &mut bytes);
                spill.write_all_at(&bytes, cursor[bin] * RECORD_BYTES as u64).map_err(spill_io)?;
                cursor[bin] += group.len() as u64;
            }
            Ok(())
        })?;
        merger.flush(&spill, &mut cursor).map_err(spill_io)?;
        if seen.iter().zip(counted.windows(2)).any(|(seen, run)| *seen != run[1] - run[0]) {
            return Err(invalid("the file changed while it was read".into()));
        }
        let starts = match cursor.iter().zip(&counted[1..]).all(|(written, end)| written == end) {
            true => counted.to_vec(),
            false => compact(&spill, counted, &cursor).map_err(spill_io)?,
        };
        Ok((spill, starts))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::particles::{ParticleSet, RawParticles};

    fn set(positions: Vec<[f64; 3]>, smoothing: Vec<f32>) -> ParticleSet {
        ParticleSet::new(RawParticles { positions, smoothing, ..RawParticles::default() }).unwrap()
    }

    /// Eight particles in the corners of a cube, and one at its centre.
    fn corners_and_centre() -> Vec<[f64; 3]> {
        let mut positions: Vec<[f64; 3]> =
            (0..8).map(|i| [(i & 1) as f64 * 10.0, ((i >> 1) & 1) as f64 * 10.0, (i >> 2) as f64 * 10.0]).collect();
        positions.push([5.1, 5.1, 5.1]);
        positions
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

    #[test]
    fn each_particle_lands_in_the_superbrick_around_it() {
        let positions = corners_and_centre();
        let source = set(positions.clone(), Vec::new());
        let survey = survey(&source, source.columns()).unwrap();
        assert_eq!((survey.count, survey.lower, survey.upper), (9, [0.0; 3], [10.0; 3]));
        let fit = UnitCubeFit::checked_around(survey.lower, survey.upper, 0.8).unwrap();
        let binning = Binning { fit, per_axis: 2 };
        // Corner i is superbrick i (x fastest, then y, then z); the centre, just past the middle, the far corner's.
        let bins: Vec<usize> = positions.iter().map(|&p| binning.superbrick_of(binning.unit_of(p))).collect();
        assert_eq!(bins, [0, 1, 2, 3, 4, 5, 6, 7, 7]);
        // Positions outside the cube are clamped to the nearest superbrick.
        assert_eq!(binning.superbrick_of(DVec3::splat(-1.0)), 0);
        assert_eq!(binning.superbrick_of(DVec3::splat(2.0)), 7);
        let starts = count_per_superbrick(&source, &binning, survey.count).unwrap();
        assert_eq!(starts, [0, 1, 2, 3, 4, 5, 6, 7, 9]);
        // A count that the second pass does not find is a file that changed.
        let error = count_per_superbrick(&source, &binning, 10).unwrap_err();
        assert!(error.to_string().contains("the file changed while it was read"), "{error}");
    }

    #[test]
    fn the_spill_file_holds_each_superbricks_run_in_unit_units() {
        let positions = corners_and_centre();
        let source = set(positions, vec![1.0; 9]);
        let fit = UnitCubeFit::checked_around([0.0; 3], [10.0; 3], 0.8).unwrap();
        let binning = Binning { fit, per_axis: 2 };
        let starts = count_per_superbrick(&source, &binning, 9).unwrap();
        let settings = ParticleTreeSettings::default();
        let out_of_core = OutOfCoreSettings { memory_bytes: MIN_MEMORY_BYTES, spill_directory: std::env::temp_dir() };
        let merging = Merging { cell: 1e-6, attribute: false };
        let budget_particles = MIN_MEMORY_BYTES / BYTES_PER_LOADED_PARTICLE;
        let spilling =
            Spilling { binning, columns: source.columns(), merging, budget_particles, memory_bytes: MIN_MEMORY_BYTES };
        let (spill, spilled) = spilling.spill_records(&source, &starts, &settings, &out_of_core).unwrap();
        assert_eq!(spilled, starts, "nothing dense, nothing merged");
        assert_eq!(spill.metadata().unwrap().len(), 9 * RECORD_BYTES as u64);
        let mut last = vec![0u8; 2 * RECORD_BYTES];
        spill.read_exact_at(&mut last, 7 * RECORD_BYTES as u64).unwrap();
        let records: Vec<f32> = last.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
        // Superbrick 7's run: its corner and the centre, in the order the file gives them; support in unit
        // units, mass 1, weight the mass.
        let support = to_support(1.0, &settings, &fit) as f32;
        for (record, file) in records.chunks_exact(6).zip([[10.0; 3], [5.1; 3]]) {
            let unit = binning.unit_of(file);
            assert_eq!(record, [unit.x as f32, unit.y as f32, unit.z as f32, support, 1.0, 1.0]);
        }
    }

    #[test]
    fn the_coarse_levels_held_fit_a_share_of_the_budget_whatever_the_count() {
        // 20 million particles in 64 MiB: the aggregates of level 4 (256³ half voxels of 8³ bricks) took 2 GiB;
        // now only the levels whose aggregates fit a quarter of the budget are held, the rest resampled from the
        // superbricks.
        let memory = 64u64 << 20;
        let held = held_coarse_levels(20_000_000, 8, 5, memory);
        assert!(held < 5, "{held}");
        let cells = (16u64 << held.saturating_sub(1)).pow(3);
        assert!(cells * BYTES_PER_AGGREGATE <= memory / AGGREGATE_SHARE, "{held} levels");
        // A file with fewer particles than fit is held whole, however fine its levels.
        assert_eq!(held_coarse_levels(1000, 8, 5, memory), 5);
        // Bricks whose coarsest level's aggregates would not fit: every level from the superbricks.
        assert_eq!(held_coarse_levels(u64::MAX, 64, 5, MIN_MEMORY_BYTES), 0);
    }

    #[test]
    fn superbricks_shrink_to_the_budget_and_grow_to_the_kernels() {
        let survey = |count: u64, h: f64| {
            let mut file_supports = LogHistogram::new();
            file_supports.add(h);
            Survey { count, lower: [0.0; 3], upper: [1.0; 3], min_h: h, max_h: h, file_supports, total_mass: 1.0 }
        };
        let fit = UnitCubeFit::checked_around([0.0; 3], [1.0; 3], 1.0).unwrap();
        let settings = ParticleTreeSettings { resolution: Some(1024), ..ParticleTreeSettings::default() };
        let budget = MIN_MEMORY_BYTES / BYTES_PER_LOADED_PARTICLE;
        // Few particles: one superbrick; many: more, up to the most per axis.
        assert_eq!(superbricks_per_axis(&survey(100, 0.0), &settings, &fit, false, budget), 1);
        let many = superbricks_per_axis(&survey(10_000_000, 0.0), &settings, &fit, false, budget);
        assert!(many > 1 && many <= MAX_SUPERBRICKS_PER_AXIS, "{many}");
        // Wide kernels (a quarter of the cube) allow at most two superbricks per axis.
        assert!(superbricks_per_axis(&survey(10_000_000, 0.25), &settings, &fit, true, budget) <= 2);
    }
}
