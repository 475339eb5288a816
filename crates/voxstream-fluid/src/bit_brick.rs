//! A brick as one bit per cell, made from a brick's binned particles when a ray asks for it (Reichl §6.4.1), with
//! the brick processors of §6.5.1 and §6.5.5 applied as it is made: foam classification and the acceleration mask.
//!
//! Layout: the thesis packs 4×4×8 cells into four 32-bit words, one texel of a GPU texture; on a CPU the natural
//! word is a row of the brick along x, so a 64³ brick is 64 × 64 `u64` rows (row `y + 64·z`), and a cell's
//! neighbourhood of `2k + 1` cells per axis is `(2k + 1)²` masked words. The same bits, another order.
//!
//! - **Coarser levels** are the finer bits OR-ed (the thesis' binary mipmap): a cell of level `L` is set when any
//!   particle lies in its `2^L`-cube, which makes every coarse level conservative. They are made here straight from
//!   the level-0 cell lists under the brick.
//! - **Foam** (§6.5.5): an occupied cell whose neighbourhood (`FOAM_REACH` cells a side) holds less than a fraction
//!   of the cells the fluid's interior would is isolated spray: its bit moves from the surface bits to the foam
//!   count of its 4³ block (one byte per block, as the thesis keeps), drawn as a translucent volume.
//! - **The acceleration mask** (§6.5.1's mipmap skip, at cell resolution): `near` holds every cell a sphere can
//!   reach, so a ray tests spheres only in those cells, with 4³ and 16³ block summaries skipped whole. Neighbours'
//!   spheres reach in too: across a face at level 0 exactly (from the neighbour's cells near the face), across edges
//!   and corners and at coarser levels conservatively (every cell within reach of the shared face, edge or corner);
//!   the neighbours read are recorded, so that they are made with the brick.

use crate::binning::{unpack_cell, FluidBins};
use crate::coarse_grid::DenseLevel;
use crate::grid::{BrickKey, BRICK};

/// Words of a brick's bits.
pub const ROWS: usize = BRICK * BRICK;

/// Cells a side of the foam neighbourhood (a cube of `2·FOAM_REACH + 1`).
pub const FOAM_REACH: i32 = 2;

/// Edge of the blocks a ray skips whole when no sphere reaches them (measured: 4 steps a splash's rays through
/// 1.7× fewer cells than 8); also the foam count's block, so foam is accumulated a block at a time.
pub const SKIP_BLOCK: usize = 4;

/// Edge of the coarse blocks a ray skips first (neither a sphere nor foam reaches them).
pub const COARSE_BLOCK: usize = 16;

/// Coarse blocks per axis of a brick.
pub const COARSE_BLOCKS: usize = BRICK / COARSE_BLOCK;

/// Skip blocks per axis of a brick.
pub const SKIP_BLOCKS: usize = BRICK / SKIP_BLOCK;

/// Blocks of the foam count per axis ([`SKIP_BLOCK`]³ cells each).
pub const FOAM_BLOCKS: usize = SKIP_BLOCKS;

/// One brick of one level, as bits.
#[derive(Clone, Debug)]
pub struct BitBrick {
    /// Which brick.
    pub key: BrickKey,
    /// Surface particles: bit `x` of row `y + 64·z`.
    pub surface: Box<[u64]>,
    /// Cells a surface sphere can reach (the traversal's skip mask; foam is crossed a block at a time).
    pub near: Box<[u64]>,
    /// Blocks of [`SKIP_BLOCK`]³ cells holding any `near` cell: bit `bx + 16·(by + 16·bz)` (the coarse level of
    /// the skip).
    pub near_blocks: [u64; 64],
    /// Coarse blocks of [`COARSE_BLOCK`]³ cells holding any `near` cell or foam: bit `bx + 4·(by + 4·bz)`.
    pub coarse_blocks: u64,
    /// Foam cells per 4³ block (0..=64), block `bx + 16·(by + 16·bz)`; empty when the brick has no foam.
    pub foam: Box<[u8]>,
    /// Surface cells set.
    pub surface_cells: u32,
    /// Foam cells.
    pub foam_cells: u32,
    /// The neighbouring bricks whose bits rays in this brick read (their spheres reach in): bit
    /// `(dx + 1) + 3·(dy + 1) + 9·(dz + 1)`. Made with this brick, they spare a frame a pass.
    pub neighbours_read: u32,
}

/// How bricks are made.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BrickSettings {
    /// Sphere reach in cells at this level: a ray in cell `c` tests the spheres of cells within `reach` per axis.
    pub reach: i32,
    /// A cell is foam when its neighbourhood holds fewer occupied cells than this (0: no foam).
    pub foam_below: u32,
}

#[inline]
fn row(y: usize, z: usize) -> usize {
    y + BRICK * z
}

/// Bits `from..=to` (clamped to the row) set.
#[inline]
pub fn span_mask(from: i32, to: i32) -> u64 {
    let from = from.max(0);
    let to = to.min(BRICK as i32 - 1);
    if from > to {
        return 0;
    }
    let width = (to - from + 1) as u32;
    let ones = if width == 64 { u64::MAX } else { (1u64 << width) - 1 };
    ones << from
}

impl BitBrick {
    /// Makes brick `key` from the binned particles under it.
    pub fn build(bins: &FluidBins, key: BrickKey, settings: BrickSettings) -> BitBrick {
        let surface = match bins.dense(key.level) {
            Some(dense) => surface_from_dense(dense, key),
            None => surface_from_lists(bins, key),
        };
        let mut brick = BitBrick {
            key,
            near: vec![0u64; ROWS].into_boxed_slice(),
            near_blocks: [0; 64],
            coarse_blocks: 0,
            foam: Box::new([]),
            surface_cells: surface.iter().map(|r| r.count_ones()).sum(),
            foam_cells: 0,
            neighbours_read: 0,
            surface,
        };
        if settings.foam_below > 0 {
            brick.classify_foam(settings.foam_below);
        }
        brick.make_near(bins, settings.reach);
        brick
    }

    /// Whether cell `(x, y, z)` (within the brick) holds a surface particle.
    #[inline]
    pub fn is_set(&self, x: usize, y: usize, z: usize) -> bool {
        self.surface[row(y, z)] >> x & 1 == 1
    }

    /// Whether a sphere or foam can reach cell `(x, y, z)`.
    #[inline]
    pub fn is_near(&self, x: usize, y: usize, z: usize) -> bool {
        self.near[row(y, z)] >> x & 1 == 1
    }

    /// Whether the skip block `(bx, by, bz)` (block coordinates, 0..16) holds any `near` cell.
    #[inline]
    pub fn is_block_near(&self, bx: usize, by: usize, bz: usize) -> bool {
        let b = bx + SKIP_BLOCKS * (by + SKIP_BLOCKS * bz);
        self.near_blocks[b / 64] >> (b % 64) & 1 == 1
    }

    /// Whether the coarse block `(bx, by, bz)` (0..4) holds a `near` cell or foam.
    #[inline]
    pub fn is_coarse_block_busy(&self, bx: usize, by: usize, bz: usize) -> bool {
        self.coarse_blocks >> (bx + COARSE_BLOCKS * (by + COARSE_BLOCKS * bz)) & 1 == 1
    }

    /// Foam cells in the 4³ block holding cell `(x, y, z)` (0..=64).
    #[inline]
    pub fn foam_at(&self, x: usize, y: usize, z: usize) -> u8 {
        self.foam_in_block(x / SKIP_BLOCK, y / SKIP_BLOCK, z / SKIP_BLOCK)
    }

    /// Foam cells in block `(bx, by, bz)` (0..=64).
    #[inline]
    pub fn foam_in_block(&self, bx: usize, by: usize, bz: usize) -> u8 {
        if self.foam.is_empty() {
            return 0;
        }
        self.foam[bx + FOAM_BLOCKS * (by + FOAM_BLOCKS * bz)]
    }

    /// Occupied cells within `reach` of `(x, y, z)` per axis, inside this brick.
    fn neighbours(&self, x: i32, y: i32, z: i32, reach: i32) -> u32 {
        let mask = span_mask(x - reach, x + reach);
        let mut count = 0;
        for zz in (z - reach).max(0)..=(z + reach).min(BRICK as i32 - 1) {
            for yy in (y - reach).max(0)..=(y + reach).min(BRICK as i32 - 1) {
                count += (self.surface[row(yy as usize, zz as usize)] & mask).count_ones();
            }
        }
        count
    }

    /// Moves isolated cells (fewer than `below` occupied cells in their neighbourhood, itself included) from the
    /// surface to the foam counts. The neighbourhood is clamped to the brick and the threshold scaled by the part
    /// of it inside, so that cells near a face are not taken for spray.
    fn classify_foam(&mut self, below: u32) {
        let full = (2 * FOAM_REACH + 1).pow(3) as u32;
        let mut foam_rows = vec![0u64; ROWS];
        let mut any = false;
        for z in 0..BRICK {
            for y in 0..BRICK {
                let mut bits = self.surface[row(y, z)];
                while bits != 0 {
                    let x = bits.trailing_zeros() as i32;
                    bits &= bits - 1;
                    let inside = |c: i32| ((c + FOAM_REACH).min(BRICK as i32 - 1) - (c - FOAM_REACH).max(0) + 1) as u32;
                    let examined = inside(x) * inside(y as i32) * inside(z as i32);
                    // Most cells are in the fluid: the 3³ around them already holds enough (9 words, not 25).
                    if self.neighbours(x, y as i32, z as i32, 1) >= below {
                        continue;
                    }
                    let count = self.neighbours(x, y as i32, z as i32, FOAM_REACH);
                    // count / examined < below / full, in integers.
                    if u64::from(count) * u64::from(full) < u64::from(below) * u64::from(examined) {
                        foam_rows[row(y, z)] |= 1 << x;
                        any = true;
                    }
                }
            }
        }
        if !any {
            return;
        }
        let mut foam = vec![0u8; FOAM_BLOCKS.pow(3)];
        let mut foam_cells = 0;
        for z in 0..BRICK {
            for y in 0..BRICK {
                let bits = foam_rows[row(y, z)];
                if bits == 0 {
                    continue;
                }
                self.surface[row(y, z)] &= !bits;
                foam_cells += bits.count_ones();
                for bx in 0..FOAM_BLOCKS {
                    let n = (bits >> (4 * bx) & 0xf).count_ones() as u8;
                    foam[bx + FOAM_BLOCKS * (y / 4 + FOAM_BLOCKS * (z / 4))] += n;
                }
            }
        }
        self.surface_cells -= foam_cells;
        self.foam_cells = foam_cells;
        self.foam = foam.into_boxed_slice();
    }

    /// The skip mask: surface cells dilated by `reach` (a box), and a shell of `reach` cells on each face whose
    /// side holds a non-empty neighbouring brick.
    fn make_near(&mut self, bins: &FluidBins, reach: i32) {
        let n = BRICK as i32;
        // Dilate along x, then y, then z.
        let mut a: Vec<u64> = self
            .surface
            .iter()
            .map(|&r| {
                let mut d = r;
                for s in 1..=reach {
                    d |= r << s | r >> s;
                }
                d
            })
            .collect();
        let mut b = vec![0u64; ROWS];
        for z in 0..n {
            for y in 0..n {
                let mut d = 0;
                for yy in (y - reach).max(0)..=(y + reach).min(n - 1) {
                    d |= a[row(yy as usize, z as usize)];
                }
                b[row(y as usize, z as usize)] = d;
            }
        }
        for z in 0..n {
            for y in 0..n {
                let mut d = 0;
                for zz in (z - reach).max(0)..=(z + reach).min(n - 1) {
                    d |= b[row(y as usize, zz as usize)];
                }
                a[row(y as usize, z as usize)] = d;
            }
        }
        // Spheres of neighbouring bricks reaching in. Across a face at level 0, exactly: the neighbour's cells
        // within `reach` of the face, each dilated into this brick. Otherwise (edges, corners, coarser levels,
        // whose cells would take a walk over many leaves), conservatively: every cell within `reach` of the
        // shared face, edge or corner.
        let bricks = bins.grid.bricks(self.key.level);
        for dz in -1i32..=1 {
            for dy in -1i32..=1 {
                for dx in -1i32..=1 {
                    let d = [dx, dy, dz];
                    if d == [0; 3] {
                        continue;
                    }
                    let at: [i64; 3] = std::array::from_fn(|i| i64::from(self.key.at[i]) + i64::from(d[i]));
                    if (0..3).any(|i| at[i] < 0 || at[i] >= i64::from(bricks[i])) {
                        continue;
                    }
                    let neighbour = BrickKey { level: self.key.level, at: at.map(|c| c as u32) };
                    if !bins.is_occupied(neighbour) {
                        continue;
                    }
                    let face = d.iter().filter(|&&v| v != 0).count() == 1;
                    let offset = ((d[0] + 1) + 3 * (d[1] + 1) + 9 * (d[2] + 1)) as u32;
                    if face && self.key.level == 0 {
                        for &packed in bins.leaf_cells(neighbour) {
                            // The neighbour's cell in this brick's coordinates.
                            let c = unpack_cell(packed);
                            let p: [i32; 3] = std::array::from_fn(|i| c[i] as i32 + d[i] * n);
                            if (0..3).all(|i| p[i] >= -reach && p[i] < n + reach) {
                                mark_box(&mut a, p, reach);
                                self.neighbours_read |= 1 << offset;
                            }
                        }
                    } else {
                        self.neighbours_read |= 1 << offset;
                        let span = |v: i32| match v {
                            -1 => (0, reach - 1),
                            1 => (n - reach, n - 1),
                            _ => (0, n - 1),
                        };
                        let ((x0, x1), (y0, y1), (z0, z1)) = (span(d[0]), span(d[1]), span(d[2]));
                        let mask = span_mask(x0, x1);
                        for z in z0..=z1 {
                            for y in y0..=y1 {
                                a[row(y as usize, z as usize)] |= mask;
                            }
                        }
                    }
                }
            }
        }
        let mut blocks = [0u64; 64];
        for z in 0..BRICK {
            for y in 0..BRICK {
                let r = a[row(y, z)];
                if r == 0 {
                    continue;
                }
                for bx in 0..SKIP_BLOCKS {
                    if r >> (SKIP_BLOCK * bx) & 0xf != 0 {
                        let b = bx + SKIP_BLOCKS * (y / SKIP_BLOCK + SKIP_BLOCKS * (z / SKIP_BLOCK));
                        blocks[b / 64] |= 1 << (b % 64);
                    }
                }
            }
        }
        self.near_blocks = blocks;
        let mut coarse = 0u64;
        let ratio = COARSE_BLOCK / SKIP_BLOCK;
        for bz in 0..SKIP_BLOCKS {
            for by in 0..SKIP_BLOCKS {
                for bx in 0..SKIP_BLOCKS {
                    if self.is_block_near(bx, by, bz) || self.foam_in_block(bx, by, bz) > 0 {
                        coarse |= 1 << (bx / ratio + COARSE_BLOCKS * (by / ratio + COARSE_BLOCKS * (bz / ratio)));
                    }
                }
            }
        }
        self.coarse_blocks = coarse;
        self.near = a.into_boxed_slice();
    }

    /// Bytes this brick holds.
    pub fn heap_bytes(&self) -> u64 {
        (8 * (self.surface.len() + self.near.len()) + self.foam.len()) as u64 + std::mem::size_of::<Self>() as u64
    }
}

/// The bits of `key` from the level-0 cell lists under it.
pub fn surface_from_lists(bins: &FluidBins, key: BrickKey) -> Box<[u64]> {
    let mut surface = vec![0u64; ROWS].into_boxed_slice();
    let level = u32::from(key.level);
    for_each_leaf_under(bins, key, &mut |leaf| {
        // Offset of the leaf brick within `key`, in level-`L` cells (0 when L ≥ 6: many leaves per cell).
        let offset: [u32; 3] = std::array::from_fn(|a| ((leaf.at[a] - (key.at[a] << level)) * BRICK as u32) >> level);
        for &packed in bins.leaf_cells(leaf) {
            let c = unpack_cell(packed);
            let [x, y, z] = std::array::from_fn(|a| ((c[a] >> level) + offset[a]) as usize);
            surface[row(y, z)] |= 1 << x;
        }
    });
    surface
}

/// The bits of `key` copied from its level's dense grid.
pub fn surface_from_dense(dense: &DenseLevel, key: BrickKey) -> Box<[u64]> {
    let mut surface = vec![0u64; ROWS].into_boxed_slice();
    for z in 0..BRICK {
        for y in 0..BRICK {
            surface[row(y, z)] = dense.brick_row(key, y, z);
        }
    }
    surface
}

/// Sets the cells of `rows` within `reach` of `p` (per axis; `p` may lie outside the brick).
fn mark_box(rows: &mut [u64], p: [i32; 3], reach: i32) {
    let n = BRICK as i32;
    let mask = span_mask(p[0] - reach, p[0] + reach);
    if mask == 0 {
        return;
    }
    for z in (p[2] - reach).max(0)..=(p[2] + reach).min(n - 1) {
        for y in (p[1] - reach).max(0)..=(p[1] + reach).min(n - 1) {
            rows[row(y as usize, z as usize)] |= mask;
        }
    }
}

/// Calls `f` with every non-empty level-0 brick under `key`, descending only through non-empty bricks.
pub fn for_each_leaf_under(bins: &FluidBins, key: BrickKey, f: &mut dyn FnMut(BrickKey)) {
    if !bins.is_occupied(key) {
        return;
    }
    if key.level == 0 {
        f(key);
        return;
    }
    for dz in 0..2 {
        for dy in 0..2 {
            for dx in 0..2 {
                let child =
                    BrickKey { level: key.level - 1, at: [2 * key.at[0] + dx, 2 * key.at[1] + dy, 2 * key.at[2] + dz] };
                for_each_leaf_under(bins, child, f);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::binning::FluidSettings;
    use voxstream_geometry::{ParticleSet, RawParticles};

    fn bins(positions: Vec<[f64; 3]>, cell: f64) -> FluidBins {
        let set = ParticleSet::new(RawParticles { positions, ..Default::default() }).unwrap();
        FluidBins::build(&set, FluidSettings { radius: Some(cell), cell: Some(cell) }, &mut |_| {}).unwrap()
    }

    const PLAIN: BrickSettings = BrickSettings { reach: 1, foam_below: 0 };

    #[test]
    fn every_particle_sets_its_cell_at_every_level() {
        let positions: Vec<[f64; 3]> =
            (0..500).map(|i| [(i % 17) as f64 * 0.37, (i % 23) as f64 * 0.29, (i % 11) as f64 * 0.61]).collect();
        let bins = bins(positions.clone(), 0.05);
        for level in 0..bins.grid.levels {
            let mut made = std::collections::HashMap::new();
            for p in &positions {
                let cell = bins.grid.cell_of(*p).unwrap().map(|c| c >> level);
                let key = BrickKey { level, at: cell.map(|c| c / BRICK as u32) };
                let brick = made.entry(key).or_insert_with(|| BitBrick::build(&bins, key, PLAIN));
                let [x, y, z] = cell.map(|c| (c % BRICK as u32) as usize);
                assert!(brick.is_set(x, y, z), "level {level} {p:?}");
                assert!(brick.is_near(x, y, z));
            }
            // No more cells than particles at level 0; coarser levels hold fewer.
            let total: u32 = made.values().map(|b| b.surface_cells).sum();
            assert!(total as usize <= positions.len());
        }
    }

    #[test]
    fn coarse_bricks_copied_from_the_dense_levels_are_those_the_lists_make() {
        let positions: Vec<[f64; 3]> = (0..20_000)
            .map(|i| {
                let f = i as f64;
                [(f * 0.618_034).fract() * 90.0, (f * 0.414_214).fract() * 50.0, (f * 0.732_051).fract() * 70.0]
            })
            .collect();
        let bins = bins(positions, 0.1);
        assert!(bins.grid.levels >= 4);
        let mut dense_levels = 0;
        for level in 1..bins.grid.levels {
            let Some(dense) = bins.dense(level) else { continue };
            dense_levels += 1;
            let b = bins.grid.bricks(level);
            for z in 0..b[2] {
                for y in 0..b[1] {
                    for x in 0..b[0] {
                        let key = BrickKey { level, at: [x, y, z] };
                        assert!(surface_from_dense(dense, key) == surface_from_lists(&bins, key), "{key:?}");
                    }
                }
            }
        }
        assert_eq!(dense_levels, bins.grid.levels - 1, "every coarse level of a small grid is dense");
    }

    #[test]
    fn the_near_mask_is_the_surface_dilated_by_the_reach() {
        // One particle in the middle of the first brick, far from every face.
        let bins = bins(vec![[0.0; 3], [100.0, 100.0, 100.0]], 0.5);
        let cell = bins.grid.cell_of([0.0; 3]).unwrap();
        let key = BrickKey::of_cell(cell);
        let brick = BitBrick::build(&bins, key, BrickSettings { reach: 2, foam_below: 0 });
        let [cx, cy, cz] = cell.map(|c| (c % BRICK as u32) as i32);
        let mut near = 0;
        for z in 0..BRICK as i32 {
            for y in 0..BRICK as i32 {
                for x in 0..BRICK as i32 {
                    let inside = (x - cx).abs() <= 2 && (y - cy).abs() <= 2 && (z - cz).abs() <= 2;
                    let marked = brick.is_near(x as usize, y as usize, z as usize);
                    // No neighbouring brick holds particles, so no shell either.
                    assert_eq!(marked, inside, "{x} {y} {z}");
                    near += marked as u32;
                }
            }
        }
        assert_eq!(near, 125);
        // The blocks holding those cells, and no others.
        let b = SKIP_BLOCK;
        for bz in 0..SKIP_BLOCKS {
            for by in 0..SKIP_BLOCKS {
                for bx in 0..SKIP_BLOCKS {
                    let any = (0..b)
                        .any(|k| (0..b).any(|j| (0..b).any(|i| brick.is_near(b * bx + i, b * by + j, b * bz + k))));
                    assert_eq!(brick.is_block_near(bx, by, bz), any);
                }
            }
        }
    }

    #[test]
    fn cells_a_neighbours_sphere_reaches_are_marked_near() {
        // One particle in the first cell of the next brick along x (global cell 64: x = −1 + 64.5·0.5), and one
        // far inside this brick.
        let bins = bins(vec![[0.0; 3], [31.25, 0.0, 0.0]], 0.5);
        let key = BrickKey::of_cell(bins.grid.cell_of([0.0; 3]).unwrap());
        assert_eq!(bins.grid.cell_of([31.25, 0.0, 0.0]).unwrap(), [64, 2, 2]);
        let brick = BitBrick::build(&bins, key, BrickSettings { reach: 1, foam_below: 0 });
        for (y, z) in [(1, 1), (2, 2), (3, 3), (1, 3)] {
            assert!(brick.is_near(63, y, z), "{y} {z}");
        }
        assert!(!brick.is_near(63, 4, 2), "beyond the sphere's reach");
        assert!(!brick.is_near(62, 2, 2));
        assert!(!brick.is_near(63, 10, 50));
    }

    #[test]
    fn an_isolated_particle_is_foam_and_a_dense_block_is_not() {
        // A dense 10³ block of particles, one per cell, and one stray particle away from it.
        let mut positions = Vec::new();
        for k in 0..10 {
            for j in 0..10 {
                for i in 0..10 {
                    positions.push([i as f64 + 0.5, j as f64 + 0.5, k as f64 + 0.5]);
                }
            }
        }
        positions.push([20.5, 20.5, 20.5]);
        let bins = bins(positions, 1.0);
        let cell = bins.grid.cell_of([20.5; 3]).unwrap();
        let key = BrickKey::of_cell(cell);
        let brick = BitBrick::build(&bins, key, BrickSettings { reach: 1, foam_below: 25 });
        let [x, y, z] = cell.map(|c| (c % BRICK as u32) as usize);
        assert!(!brick.is_set(x, y, z), "the stray particle is not surface");
        assert_eq!(brick.foam_at(x, y, z), 1);
        assert!(!brick.is_near(x, y, z), "foam is crossed a block at a time, not tested for spheres");
        assert_eq!(brick.foam_cells, 1);
        // A corner of the block sees 3³ = 27 occupied cells of 125, well above 25 %.
        assert_eq!(brick.surface_cells, 1000);
    }
}
