//! Spatial binning, the fluid preview's only preprocess (Reichl §6.4, §6.4.2).
//!
//! One pass over the particles (a run at a time, so files larger than memory stream through) finds their bounds
//! and estimates their spacing; a second pass quantises every particle to its level-0 cell and bins it into the
//! brick holding it, in parallel over each run (each thread into lists of its own, appended a brick at a time;
//! sorting the keys instead took a third of a 100-million particle binning).
//! What is kept is a brick's occupied cells, 18 bits each in a `u32` (the thesis' 8 bits per axis, here 6: a brick
//! is 64³), duplicates removed: a few bytes per particle, the particles' positions are not held. Bits are made
//! from these lists only when a ray asks for a brick ([`crate::bit_brick`]).

use rustc_hash::{FxHashMap as HashMap, FxHashSet as HashSet};

use rayon::prelude::*;
use voxstream_geometry::particles::check_particles;
use voxstream_geometry::{ParticleChunks, RawParticles};

use crate::coarse_grid::{dense_levels, DenseLevel};
use crate::grid::{BrickKey, FluidGrid, BRICK, BRICK_SHIFT};
use crate::FluidError;

/// How the grid is chosen.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FluidSettings {
    /// Sphere radius, world units (`None`: 0.6 × the particles' estimated spacing, so that neighbours' spheres
    /// overlap into a surface).
    pub radius: Option<f64>,
    /// Level-0 cell edge, world units (`None`: the radius, a sphere two cells across).
    pub cell: Option<f64>,
}

/// The particles of one time step, binned.
#[derive(Debug)]
pub struct FluidBins {
    /// The cell grid.
    pub grid: FluidGrid,
    /// Sphere radius, world units.
    pub radius: f64,
    /// Particles read.
    pub particles: u64,
    /// Their typical spacing, estimated from a sample (0: unknown, a single particle).
    pub spacing: f64,
    /// Particles' bounds, world units.
    pub bounds: ([f64; 3], [f64; 3]),
    /// Occupied cells of each non-empty level-0 brick (by [`BrickKey::packed`]), packed by [`pack_cell`], sorted.
    leaf: HashMap<u64, Box<[u32]>>,
    /// Non-empty bricks of each level (level 0 included), by [`BrickKey::packed`].
    occupied: Vec<HashSet<u64>>,
    /// Bricks of each level that are non-empty or next to one (a sphere may reach into them).
    reached: Vec<HashSet<u64>>,
    /// The coarser levels' bits where they are small ([`crate::coarse_grid`]), finest first.
    dense: Vec<DenseLevel>,
}

/// A brick-local cell packed into 18 bits: x, then y, then z, 6 bits each.
#[inline]
pub fn pack_cell(local: [u32; 3]) -> u32 {
    local[0] | (local[1] << BRICK_SHIFT) | (local[2] << (2 * BRICK_SHIFT))
}

/// The brick-local cell of [`pack_cell`].
#[inline]
pub fn unpack_cell(packed: u32) -> [u32; 3] {
    let mask = BRICK as u32 - 1;
    [packed & mask, (packed >> BRICK_SHIFT) & mask, (packed >> (2 * BRICK_SHIFT)) & mask]
}

/// What the first pass learns.
struct Survey {
    lower: [f64; 3],
    upper: [f64; 3],
    count: u64,
    spacing: f64,
}

/// Most particles the spacing estimate looks at.
const SPACING_SAMPLE: usize = 1 << 20;

/// The particles' typical spacing: at a cell size where the occupied cells hold a few particles each, the cube root
/// of the volume per particle in occupied cells. Looks at the first [`SPACING_SAMPLE`] particles only; a sample of
/// a region of the fluid gives its spacing as well as the whole.
fn estimate_spacing(sample: &[[f64; 3]]) -> f64 {
    let mut lower = [f64::INFINITY; 3];
    let mut upper = [f64::NEG_INFINITY; 3];
    for p in sample {
        for a in 0..3 {
            lower[a] = lower[a].min(p[a]);
            upper[a] = upper[a].max(p[a]);
        }
    }
    let extent = (0..3).map(|a| upper[a] - lower[a]).fold(0.0, f64::max);
    if sample.len() < 2 || extent <= 0.0 {
        return 0.0;
    }
    // From coarse cells down: the finest cells that still hold several particles each give the spacing (cells
    // finer than the spacing hold one each and say nothing).
    let mut cell = extent / 4.0;
    let mut spacing = extent / (sample.len() as f64).cbrt();
    for _ in 0..24 {
        let mut cells = HashSet::with_capacity_and_hasher(sample.len(), Default::default());
        for p in sample {
            cells.insert([0, 1, 2].map(|a| ((p[a] - lower[a]) / cell).floor() as i64));
        }
        let per_cell = sample.len() as f64 / cells.len() as f64;
        if per_cell < 8.0 {
            break;
        }
        spacing = cell / per_cell.cbrt();
        cell /= 2.0;
    }
    spacing
}

fn survey(chunks: &dyn ParticleChunks) -> Result<Survey, FluidError> {
    let mut lower = [f64::INFINITY; 3];
    let mut upper = [f64::NEG_INFINITY; 3];
    let mut count = 0u64;
    let mut sample: Vec<[f64; 3]> = Vec::new();
    chunks.for_each_chunk(&mut |first, run: &RawParticles| {
        check_particles(run, first)?;
        for p in &run.positions {
            for a in 0..3 {
                lower[a] = lower[a].min(p[a]);
                upper[a] = upper[a].max(p[a]);
            }
        }
        if sample.len() < SPACING_SAMPLE {
            let take = (SPACING_SAMPLE - sample.len()).min(run.positions.len());
            sample.extend_from_slice(&run.positions[..take]);
        }
        count += run.positions.len() as u64;
        Ok(())
    })?;
    if count == 0 {
        return Err(FluidError::Settings("the file holds no particles".into()));
    }
    let spacing = estimate_spacing(&sample);
    Ok(Survey { lower, upper, count, spacing })
}

impl FluidBins {
    /// Bins `chunks` (two passes over them). `progress` is called with the particles binned so far.
    pub fn build(
        chunks: &dyn ParticleChunks,
        settings: FluidSettings,
        progress: &mut dyn FnMut(u64),
    ) -> Result<FluidBins, FluidError> {
        let survey = survey(chunks)?;
        let extent = (0..3).map(|a| survey.upper[a] - survey.lower[a]).fold(0.0, f64::max);
        let radius = match settings.radius {
            Some(r) if !(r.is_finite() && r > 0.0) => {
                return Err(FluidError::Settings(format!("--particle-radius must be a positive number, got {r}")))
            }
            Some(r) => r,
            // A single particle, or all at one place: a sphere a hundredth of the set (or of a unit) across.
            None if survey.spacing > 0.0 => 0.6 * survey.spacing,
            None => 0.01 * extent.max(1.0),
        };
        let cell = settings.cell.unwrap_or(radius);
        // Spheres reach `radius` beyond their centres, jittered within their cells.
        let grid = FluidGrid::new(survey.lower, survey.upper, radius + cell, cell)?;
        let mut lists: HashMap<u64, Vec<u32>> = HashMap::default();
        let mut binned = 0u64;
        chunks.for_each_chunk(&mut |first, run: &RawParticles| {
            check_particles(run, first)?;
            // Each thread bins its share of the run into lists of its own (a hash lookup per particle, the last
            // brick remembered), appended brick by brick afterwards: no sort.
            let share = run.positions.len().div_ceil(rayon::current_num_threads().max(1)).max(1 << 12);
            let parts: Vec<HashMap<u64, Vec<u32>>> = run
                .positions
                .par_chunks(share)
                .map(|positions| {
                    let mut part: HashMap<u64, Vec<u32>> = HashMap::default();
                    let mut last: Option<(u64, Vec<u32>)> = None;
                    for &p in positions {
                        // Within the grid by construction (the bounds were measured on the same particles).
                        let cell = grid.cell_of(p).unwrap_or([0; 3]);
                        let key = BrickKey::of_cell(cell).packed();
                        let local = pack_cell(cell.map(|c| c & (BRICK as u32 - 1)));
                        match &mut last {
                            Some((k, list)) if *k == key => list.push(local),
                            _ => {
                                if let Some((k, list)) = last.take() {
                                    part.insert(k, list);
                                }
                                let mut list = part.remove(&key).unwrap_or_default();
                                list.push(local);
                                last = Some((key, list));
                            }
                        }
                    }
                    if let Some((k, list)) = last {
                        part.insert(k, list);
                    }
                    part
                })
                .collect();
            for part in parts {
                for (key, cells) in part {
                    match lists.get_mut(&key) {
                        Some(list) => list.extend_from_slice(&cells),
                        None => {
                            lists.insert(key, cells);
                        }
                    }
                }
            }
            binned += run.positions.len() as u64;
            progress(binned);
            Ok(())
        })?;
        if binned != survey.count {
            return Err(FluidError::Settings(format!(
                "the file changed while it was read ({} particles, then {binned})",
                survey.count
            )));
        }
        let leaf: HashMap<u64, Box<[u32]>> = lists
            .into_par_iter()
            .map(|(key, cells)| {
                // Sorted and without repeats through a bit per cell of the brick (linear, not a sort).
                let mut bits = vec![0u64; BRICK * BRICK * BRICK / 64];
                for &c in &cells {
                    bits[c as usize / 64] |= 1 << (c % 64);
                }
                drop(cells);
                let mut sorted = Vec::new();
                for (w, &word) in bits.iter().enumerate() {
                    let mut word = word;
                    while word != 0 {
                        sorted.push(w as u32 * 64 + word.trailing_zeros());
                        word &= word - 1;
                    }
                }
                (key, sorted.into_boxed_slice())
            })
            .collect();
        let mut occupied = vec![HashSet::default(); usize::from(grid.levels)];
        for &packed in leaf.keys() {
            let key = unpack_key(packed);
            for level in 0..grid.levels {
                occupied[usize::from(level)].insert(key.ancestor(level).packed());
            }
        }
        let reached = occupied
            .iter()
            .enumerate()
            .map(|(level, set)| {
                let bricks = grid.bricks(level as u8);
                let mut reached = HashSet::with_capacity_and_hasher(set.len() * 2, Default::default());
                for &packed in set {
                    let key = unpack_key(packed);
                    for d in NEIGHBOURHOOD {
                        let at: [i64; 3] = std::array::from_fn(|a| i64::from(key.at[a]) + d[a]);
                        if (0..3).all(|a| at[a] >= 0 && at[a] < i64::from(bricks[a])) {
                            reached.insert(BrickKey { level: key.level, at: at.map(|c| c as u32) }.packed());
                        }
                    }
                }
                reached
            })
            .collect();
        let leaves: Vec<(BrickKey, &[u32])> = leaf.iter().map(|(&k, cells)| (unpack_key(k), &cells[..])).collect();
        let dense = dense_levels(&grid, &leaves, unpack_cell);
        drop(leaves);
        Ok(FluidBins {
            grid,
            reached,
            dense,
            radius,
            particles: survey.count,
            spacing: survey.spacing,
            bounds: (survey.lower, survey.upper),
            leaf,
            occupied,
        })
    }

    /// Whether any particle lies in the brick.
    pub fn is_occupied(&self, key: BrickKey) -> bool {
        self.occupied.get(usize::from(key.level)).is_some_and(|set| set.contains(&key.packed()))
    }

    /// Whether a sphere may reach into the brick (it or a neighbour holds particles).
    pub fn is_reached(&self, key: BrickKey) -> bool {
        self.reached.get(usize::from(key.level)).is_some_and(|set| set.contains(&key.packed()))
    }

    /// The whole grid's bits at `level`, where they are kept dense.
    pub fn dense(&self, level: u8) -> Option<&DenseLevel> {
        self.dense.iter().find(|d| d.level == level)
    }

    /// The occupied cells of a level-0 brick ([`pack_cell`]), empty if none.
    pub fn leaf_cells(&self, key: BrickKey) -> &[u32] {
        debug_assert_eq!(key.level, 0);
        self.leaf.get(&key.packed()).map_or(&[], |cells| cells)
    }

    /// Number of non-empty bricks of `level`.
    pub fn occupied_bricks(&self, level: u8) -> usize {
        self.occupied.get(usize::from(level)).map_or(0, HashSet::len)
    }

    /// Occupied level-0 cells (distinct), all bricks.
    pub fn occupied_cells(&self) -> u64 {
        self.leaf.values().map(|c| c.len() as u64).sum()
    }

    /// Bytes this binning holds (cell lists, the brick sets and the dense coarse levels; what a time step costs
    /// before any brick is made).
    pub fn heap_bytes(&self) -> u64 {
        let lists: u64 = self.leaf.values().map(|c| 4 * c.len() as u64 + 32).sum();
        let sets: u64 = self.occupied.iter().chain(&self.reached).map(|s| 16 * s.capacity() as u64).sum();
        let dense: u64 = self.dense.iter().map(DenseLevel::bytes).sum();
        lists + sets + dense
    }
}

/// The 27 offsets of a brick's neighbourhood, itself included.
const NEIGHBOURHOOD: [[i64; 3]; 27] = {
    let mut out = [[0i64; 3]; 27];
    let mut i = 0;
    while i < 27 {
        out[i] = [(i % 3) as i64 - 1, (i / 3 % 3) as i64 - 1, (i / 9) as i64 - 1];
        i += 1;
    }
    out
};

/// The key of [`BrickKey::packed`].
pub fn unpack_key(packed: u64) -> BrickKey {
    let mask = (1u64 << 19) - 1;
    BrickKey {
        level: (packed >> 57) as u8,
        at: [(packed & mask) as u32, ((packed >> 19) & mask) as u32, ((packed >> 38) & mask) as u32],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxstream_geometry::ParticleSet;

    fn set(positions: Vec<[f64; 3]>) -> ParticleSet {
        ParticleSet::new(RawParticles { positions, ..Default::default() }).unwrap()
    }

    /// A jittered lattice of spacing `h` filling `n³` sites.
    pub(crate) fn lattice(n: usize, h: f64) -> Vec<[f64; 3]> {
        let mut out = Vec::new();
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    let wobble = |s: usize| ((s * 2_654_435_761) % 1000) as f64 / 1000.0 * 0.2 - 0.1;
                    let s = i + n * (j + n * k);
                    out.push([
                        (i as f64 + wobble(s)) * h,
                        (j as f64 + wobble(s + 7)) * h,
                        (k as f64 + wobble(s + 13)) * h,
                    ]);
                }
            }
        }
        out
    }

    #[test]
    fn the_spacing_of_a_lattice_is_estimated_within_a_tenth() {
        let points = lattice(40, 0.25);
        let spacing = estimate_spacing(&points);
        assert!((spacing - 0.25).abs() < 0.025, "{spacing}");
    }

    #[test]
    fn every_particle_lands_in_its_cell_and_coarse_levels_know_where_particles_are() {
        let points = lattice(30, 0.1);
        let particles = set(points.clone());
        let bins =
            FluidBins::build(&particles, FluidSettings { radius: Some(0.05), cell: Some(0.02) }, &mut |_| {}).unwrap();
        assert_eq!(bins.particles, points.len() as u64);
        assert_eq!(bins.radius, 0.05);
        // 2.9 + 2·0.07 → 152 cells → 3 bricks a side.
        assert_eq!(bins.grid.bricks(0), [3, 3, 3]);
        for p in &points {
            let cell = bins.grid.cell_of(*p).unwrap();
            let key = BrickKey::of_cell(cell);
            let local = pack_cell(cell.map(|c| c % BRICK as u32));
            assert!(bins.leaf_cells(key).binary_search(&local).is_ok(), "{p:?}");
            for level in 0..bins.grid.levels {
                assert!(bins.is_occupied(key.ancestor(level)));
            }
        }
        // Spacing 0.1, cells 0.02: every particle has a cell of its own.
        assert_eq!(bins.occupied_cells(), points.len() as u64);
        assert_eq!(bins.occupied_bricks(bins.grid.levels - 1), 1);
        assert!(!bins.is_occupied(BrickKey { level: 0, at: [7, 0, 0] }));
    }

    #[test]
    fn the_default_radius_follows_the_spacing_and_bad_radii_are_refused() {
        let particles = set(lattice(20, 0.5));
        let bins = FluidBins::build(&particles, FluidSettings::default(), &mut |_| {}).unwrap();
        assert!((bins.radius - 0.3).abs() < 0.03, "{}", bins.radius);
        assert_eq!(bins.grid.cell, bins.radius);
        for bad in [0.0, -1.0, f64::NAN] {
            let error = FluidBins::build(&particles, FluidSettings { radius: Some(bad), cell: None }, &mut |_| {})
                .unwrap_err()
                .to_string();
            assert!(error.contains("--particle-radius"), "{error}");
        }
    }

    #[test]
    fn keys_and_cells_unpack_to_what_was_packed() {
        let key = BrickKey { level: 3, at: [5, 300_000, 17] };
        assert_eq!(unpack_key(key.packed()), key);
        assert_eq!(unpack_cell(pack_cell([63, 0, 41])), [63, 0, 41]);
    }
}
