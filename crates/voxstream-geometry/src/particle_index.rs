//! The particles binned for gathering: what the particle producers search when they make a brick.
//!
//! Reichl (seed 004, ch. 5) bins SPH particles once so that resampling a brick visits only the particles whose
//! kernels reach it. Here the particles are grouped in support classes (powers of two of the smallest support), each
//! sorted by its cells on a grid no finer than its widest kernel, so gathering around a point visits about as many
//! particles as reach it whatever the spread of `h`. Each class also counts its particles on a coarse grid (a
//! summed-area table) for the oracle's O(1) emptiness test.
//!
//! The in-memory producer ([`crate::ParticleProducer`]) holds one index over every particle; the out-of-core one
//! ([`crate::SuperbrickParticleProducer`]) one per superbrick it has loaded, and one per coarse level.

use glam::{DVec3, Vec3};
use rayon::prelude::*;

/// The normalised cubic spline kernel with support `h`.
#[inline]
pub fn cubic_spline(r: f64, h: f64) -> f64 {
    let q = r / h;
    let sigma = 8.0 / (std::f64::consts::PI * h * h * h);
    if q <= 0.5 {
        sigma * (1.0 - 6.0 * q * q + 6.0 * q * q * q)
    } else if q <= 1.0 {
        let t = 1.0 - q;
        sigma * 2.0 * t * t * t
    } else {
        0.0
    }
}

/// [`cubic_spline`] of one support, times a particle's weight, with its constants computed once.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SplineKernel {
    h_squared: f64,
    inverse_h: f64,
    /// The weight times the normalisation `8 / (π h³)`.
    scale: f64,
}

impl SplineKernel {
    fn new(h: f64, weight: f64) -> SplineKernel {
        SplineKernel { h_squared: h * h, inverse_h: 1.0 / h, scale: weight * 8.0 / (std::f64::consts::PI * h * h * h) }
    }

    /// `weight · cubic_spline(r, h)`.
    #[inline]
    fn weighted_at(&self, r: f64) -> f64 {
        let q = r * self.inverse_h;
        if q <= 0.5 {
            self.scale * (1.0 - 6.0 * q * q + 6.0 * q * q * q)
        } else if q <= 1.0 {
            let t = 1.0 - q;
            self.scale * 2.0 * t * t * t
        } else {
            0.0
        }
    }
}

/// Particle counts on a coarse uniform grid (at most 64³ cells) as a summed-area table: the oracle's O(1) test.
#[derive(Clone, Debug)]
pub(crate) struct ParticleGrid {
    /// Cells per axis.
    cells: usize,
    /// Summed-area table, `(cells + 1)³`.
    prefix: Vec<u64>,
}

/// Particle counts being gathered for a [`ParticleGrid`].
#[derive(Clone, Debug)]
pub(crate) struct GridCounts {
    cells: usize,
    counts: Vec<u32>,
}

impl GridCounts {
    /// Counts one particle at unit point `p`.
    pub(crate) fn add(&mut self, p: DVec3) {
        let scale = self.cells as f64;
        let c = [0, 1, 2].map(|a| ((p[a] * scale).floor().max(0.0) as usize).min(self.cells - 1));
        let cell = &mut self.counts[(c[2] * self.cells + c[1]) * self.cells + c[0]];
        *cell = cell.saturating_add(1);
    }

    /// The summed-area table.
    pub(crate) fn finish(self) -> ParticleGrid {
        ParticleGrid::from_counts(self.cells, &self.counts)
    }
}

/// The particles' cells on a fine grid (cell ≥ the largest support, up to 2²⁰ per axis), as sorted keys
/// `(z·cells + y)·cells + x`: the particles of a box are found by binary searches per row of cells, so memory is one
/// key per particle whatever the grid's size.
#[derive(Clone, Debug)]
pub(crate) struct SortedCells {
    cells: u64,
    keys: Vec<u64>,
}

/// The particles whose supports lie within a factor of two: a contiguous run of the sorted particles, on cells no
/// smaller than their largest support, so that gathering around a point visits about as many particles as reach it.
#[derive(Clone, Debug)]
struct SupportClass {
    /// Index of the class's first particle.
    first: usize,
    max_support: f64,
    cells: SortedCells,
    /// The class's counts for the oracle (when built with them).
    counts: Option<ParticleGrid>,
}

/// Rows of cells searched one by one below this; above, whole slabs (the particles' own distance tests then skip
/// the extra ones).
const MAX_ROWS: u64 = 4096;

impl SortedCells {
    fn cell_of(&self, p: DVec3) -> [u64; 3] {
        let scale = self.cells as f64;
        [0, 1, 2].map(|a| ((p[a] * scale).floor().max(0.0) as u64).min(self.cells - 1))
    }

    fn key(&self, [x, y, z]: [u64; 3]) -> u64 {
        (z * self.cells + y) * self.cells + x
    }

    /// Calls `f` with index ranges (into the sorted particles) covering every particle in the cells overlapping the
    /// box `lower..upper`, and perhaps others.
    fn for_each_range(&self, lower: DVec3, upper: DVec3, mut f: impl FnMut(std::ops::Range<usize>)) {
        let [x0, y0, z0] = self.cell_of(lower);
        let [x1, y1, z1] = self.cell_of(upper);
        let mut span = |from: u64, to: u64| {
            let a = self.keys.partition_point(|&k| k < from);
            let b = self.keys.partition_point(|&k| k <= to);
            if a < b {
                f(a..b);
            }
        };
        let last = self.cells - 1;
        if (y1 - y0 + 1) * (z1 - z0 + 1) <= MAX_ROWS {
            for z in z0..=z1 {
                for y in y0..=y1 {
                    span(self.key([x0, y, z]), self.key([x1, y, z]));
                }
            }
        } else if z1 - z0 < MAX_ROWS {
            for z in z0..=z1 {
                span(self.key([0, y0, z]), self.key([last, y1, z]));
            }
        } else {
            span(self.key([0, 0, z0]), self.key([last, last, z1]));
        }
    }
}

impl ParticleGrid {
    /// An empty count on `cells`³ cells, to [`GridCounts::add`] to and [`GridCounts::finish`].
    pub(crate) fn counting(cells: usize) -> GridCounts {
        GridCounts { cells, counts: vec![0; cells * cells * cells] }
    }

    /// The summed-area table of `counts` on `cells`³ cells.
    fn from_counts(cells: usize, counts: &[u32]) -> ParticleGrid {
        let n = cells + 1;
        let mut prefix = vec![0u64; n * n * n];
        let at = |x: usize, y: usize, z: usize| (z * n + y) * n + x;
        for z in 0..cells {
            for y in 0..cells {
                for x in 0..cells {
                    let value = counts[(z * cells + y) * cells + x] as i64
                        + prefix[at(x, y + 1, z + 1)] as i64
                        + prefix[at(x + 1, y, z + 1)] as i64
                        + prefix[at(x + 1, y + 1, z)] as i64
                        - prefix[at(x, y, z + 1)] as i64
                        - prefix[at(x, y + 1, z)] as i64
                        - prefix[at(x + 1, y, z)] as i64
                        + prefix[at(x, y, z)] as i64;
                    prefix[at(x + 1, y + 1, z + 1)] = value as u64;
                }
            }
        }
        ParticleGrid { cells, prefix }
    }

    fn cell_of(&self, p: DVec3) -> [usize; 3] {
        let scale = self.cells as f64;
        [0, 1, 2].map(|a| ((p[a] * scale).floor().max(0.0) as usize).min(self.cells - 1))
    }

    /// Bytes held.
    pub(crate) fn heap_bytes(&self) -> u64 {
        self.prefix.len() as u64 * 8
    }

    /// Whether any particle lies within `reach` of the node box `lower..lower + size`.
    pub(crate) fn any_near(&self, node_lower: DVec3, size: f64, reach: f64) -> bool {
        let lower = node_lower - DVec3::splat(reach);
        let upper = node_lower + DVec3::splat(size + reach);
        if upper.min_element() < 0.0 || lower.max_element() > 1.0 {
            return false;
        }
        let (from, to) = self.cell_range(lower, upper);
        self.count(from, to) > 0
    }

    /// Cell ranges (inclusive) covering the box `lower..upper` (unit units).
    fn cell_range(&self, lower: DVec3, upper: DVec3) -> ([usize; 3], [usize; 3]) {
        (self.cell_of(lower), self.cell_of(upper))
    }

    /// Particles in the cells `from..=to`.
    fn count(&self, from: [usize; 3], to: [usize; 3]) -> u64 {
        let n = self.cells + 1;
        let at = |x: usize, y: usize, z: usize| self.prefix[(z * n + y) * n + x];
        let [x0, y0, z0] = from;
        let [x1, y1, z1] = to.map(|v| v + 1);
        // Inclusion–exclusion over the eight corners (as i64: intermediate sums may go below zero).
        let sum = at(x1, y1, z1) as i64 - at(x0, y1, z1) as i64 - at(x1, y0, z1) as i64 - at(x1, y1, z0) as i64
            + at(x0, y0, z1) as i64
            + at(x0, y1, z0) as i64
            + at(x1, y0, z0) as i64
            - at(x0, y0, z0) as i64;
        sum.max(0) as u64
    }
}

/// Particles binned in support classes on sorted cells (unit-cube units).
#[derive(Clone, Debug)]
pub(crate) struct ParticleIndex {
    /// Positions, sorted by (class, cell). Single precision (a 2⁻²⁴ step of the cube, far below the finest voxel).
    pub(crate) positions: Vec<Vec3>,
    /// Kernel support per particle (same order).
    pub(crate) support: Vec<f32>,
    /// Mass per particle (same order).
    pub(crate) masses: Vec<f32>,
    pub(crate) max_support: f64,
    classes: Vec<SupportClass>,
}

/// Most support classes (powers of two of the smallest support).
pub(crate) const MAX_CLASSES: usize = 24;

/// The support class of a kernel of support `h` when the smallest is `min_support`.
#[inline]
pub(crate) fn class_of(h: f64, min_support: f64) -> usize {
    ((h / min_support.max(1e-12)).log2().floor().max(0.0) as usize).min(MAX_CLASSES - 1)
}

/// Cells per axis of a class's oracle grid, for kernels up to `max_support`.
pub(crate) fn oracle_cells(max_support: f64) -> usize {
    ((1.0 / max_support).floor() as usize).clamp(1, 64)
}

impl ParticleIndex {
    /// Bins particles at `unit` (already rounded to single precision) with supports `support` and masses `masses`
    /// (same lengths). With `oracle_grids`, each class counts its particles for [`ParticleIndex::reaches`]. Returns
    /// the index and, for each of its particles, the input index it came from.
    pub(crate) fn build(
        unit: &[DVec3],
        support: &[f64],
        masses: &[f32],
        oracle_grids: bool,
    ) -> (ParticleIndex, Vec<u32>) {
        let max_support = support.iter().copied().fold(0.0, f64::max);
        let min_support = support.iter().copied().fold(f64::INFINITY, f64::min);
        let mut class_max = [0.0f64; MAX_CLASSES];
        for &h in support {
            let c = class_of(h, min_support);
            class_max[c] = class_max[c].max(h);
        }
        let class_cells = class_max.map(|h| if h > 0.0 { ((1.0 / h).floor() as u64).clamp(1, 1 << 20) } else { 1 });
        // (class, cell key, input index): 16 bytes a particle, the class as a byte (there are at most 24).
        let mut keyed: Vec<(u8, u64, u32)> = unit
            .par_iter()
            .zip(support)
            .enumerate()
            .map(|(i, (p, &h))| {
                let c = class_of(h, min_support);
                let cells = SortedCells { cells: class_cells[c], keys: Vec::new() };
                (c as u8, cells.key(cells.cell_of(*p)), i as u32)
            })
            .collect();
        keyed.par_sort_unstable();
        let order: Vec<u32> = keyed.iter().map(|&(_, _, i)| i).collect();
        let mut classes = Vec::new();
        for group in keyed.chunk_by(|a, b| a.0 == b.0) {
            let class = usize::from(group[0].0);
            let first = classes.last().map_or(0, |c: &SupportClass| c.first + c.cells.keys.len());
            let counts = oracle_grids.then(|| {
                let mut grid = ParticleGrid::counting(oracle_cells(class_max[class]));
                group.iter().for_each(|&(_, _, i)| grid.add(unit[i as usize]));
                grid.finish()
            });
            classes.push(SupportClass {
                first,
                max_support: class_max[class],
                cells: SortedCells { cells: class_cells[class], keys: group.iter().map(|&(_, k, _)| k).collect() },
                counts,
            });
        }
        let positions: Vec<Vec3> = order.iter().map(|&i| unit[i as usize].as_vec3()).collect();
        let support: Vec<f32> = order.iter().map(|&i| support[i as usize] as f32).collect();
        let masses: Vec<f32> = order.iter().map(|&i| masses[i as usize]).collect();
        (ParticleIndex { positions, support, masses, max_support, classes }, order)
    }

    /// Where the `n`-th support class present begins (its particles follow the narrower classes').
    pub(crate) fn class_start(&self, n: usize) -> Option<usize> {
        self.classes.get(n).map(|c| c.first)
    }

    /// Number of particles.
    pub(crate) fn len(&self) -> usize {
        self.positions.len()
    }

    /// Calls `f` with index ranges covering every particle whose kernel (no narrower than `min_support`) can reach the
    /// box `lower..upper`, and perhaps others (each caller tests the distance).
    pub(crate) fn gather(
        &self,
        lower: DVec3,
        upper: DVec3,
        min_support: f64,
        mut f: impl FnMut(std::ops::Range<usize>),
    ) {
        for class in &self.classes {
            let reach = DVec3::splat(class.max_support.max(min_support));
            class.cells.for_each_range(lower - reach, upper + reach, |range| {
                f(class.first + range.start..class.first + range.end)
            });
        }
    }

    /// `Σ weight(j)·W(|p − xⱼ|, max(hⱼ, min_support))` at unit point `p`.
    pub(crate) fn kernel_sum(&self, weight: impl Fn(usize) -> f64, p: DVec3, min_support: f64) -> f64 {
        let mut sum = 0.0;
        self.gather(p, p, min_support, |range| {
            for i in range {
                let h = f64::from(self.support[i]).max(min_support);
                sum += weight(i) * cubic_spline((self.positions[i].as_dvec3() - p).length(), h);
            }
        });
        sum
    }

    /// Adds `weight(j)·W(|x − xⱼ|, max(hⱼ, min_support))` to `density`, a `b³` block of voxels centred at
    /// `first + (i, j, k)·voxel`. Returns whether any kernel reached the block.
    pub(crate) fn splat(
        &self,
        weight: impl Fn(usize) -> f64,
        first: DVec3,
        voxel: f64,
        b: usize,
        min_support: f64,
        density: &mut [f64],
    ) -> bool {
        let last = first + DVec3::splat((b - 1) as f64 * voxel);
        let mut reached = false;
        self.gather(first, last, min_support, |range| {
            for i in range {
                let p = self.positions[i].as_dvec3();
                let h = f64::from(self.support[i]).max(min_support);
                // Does the kernel reach the box of the stored voxel centres (which holds every finer level's
                // voxel centres too)? Finer levels use kernels no wider, so if none does, none will.
                let outside = (first - p).max(p - last).max(DVec3::ZERO);
                if outside.length() >= h {
                    continue;
                }
                reached = true;
                // Voxel index range within the kernel's support.
                let low = ((p - DVec3::splat(h) - first) / voxel).ceil();
                let high = ((p + DVec3::splat(h) - first) / voxel).floor();
                if high.min_element() < 0.0 || low.max_element() > (b - 1) as f64 {
                    continue;
                }
                let low = low.max(DVec3::ZERO).as_uvec3();
                let high = high.min(DVec3::splat((b - 1) as f64)).as_uvec3();
                // The kernel's sphere, not its bounding cube: per row, only the chord inside the support (about
                // half the cube's voxels), with the kernel's constants taken out of the loop.
                let kernel = SplineKernel::new(h, weight(i));
                for vz in low.z..=high.z {
                    let dz = first.z + f64::from(vz) * voxel - p.z;
                    for vy in low.y..=high.y {
                        let dy = first.y + f64::from(vy) * voxel - p.y;
                        let chord_squared = kernel.h_squared - (dy * dy + dz * dz);
                        if chord_squared <= 0.0 {
                            continue;
                        }
                        let half_chord = chord_squared.sqrt();
                        let from = ((p.x - half_chord - first.x) / voxel).ceil().max(f64::from(low.x));
                        let to = ((p.x + half_chord - first.x) / voxel).floor().min(f64::from(high.x));
                        if from > to {
                            continue;
                        }
                        let row = (vz as usize * b + vy as usize) * b;
                        let yz_squared = dy * dy + dz * dz;
                        for vx in from as u32..=to as u32 {
                            let dx = first.x + f64::from(vx) * voxel - p.x;
                            density[row + vx as usize] += kernel.weighted_at((dx * dx + yz_squared).sqrt());
                        }
                    }
                }
            }
        });
        reached
    }

    /// Whether any particle's kernel (widened to `min_support`) may reach the node box `lower..lower + size` (built
    /// with oracle grids; without, always true).
    pub(crate) fn may_reach(&self, node_lower: DVec3, size: f64, min_support: f64, margin: f64) -> bool {
        self.classes.iter().any(|class| {
            let Some(counts) = &class.counts else { return true };
            counts.any_near(node_lower, size, class.max_support.max(min_support) + margin)
        })
    }

    /// Bytes held: position, support, mass and sorted cell key per particle, and the oracle grids.
    pub(crate) fn heap_bytes(&self) -> u64 {
        let counts: usize = self.classes.iter().filter_map(|c| c.counts.as_ref()).map(|c| c.prefix.len() * 8).sum();
        (self.positions.len() * (12 + 4 + 4 + 8) + counts) as u64
    }
}
