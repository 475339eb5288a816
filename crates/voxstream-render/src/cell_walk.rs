//! The trilinear cells a ray crosses inside one brick, in order: a 3-D DDA (Amanatides & Woo) over the brick's
//! voxel lattice, handing each cell's eight corners and the ray's entry and exit in it to a visitor.
//!
//! This is the level Knoll et al. intersect at (seed 002 §3, "Ray–cell intersection"): the trilinear interpolant
//! is exact inside a cell, so a cell is the unit of exact intersection; [`crate::isosurface`] walks cells here.

use std::ops::ControlFlow;

use voxstream_core::{Dequantize, PoolVoxels, Voxel, BLOCK_CELLS, VOXEL_MAX};

use crate::integrand::BrickSpan;

/// One cell along a ray.
#[derive(Clone, Copy, Debug)]
pub struct CellVisit<'v> {
    /// Corner values in 16-bit units (`[0, 65535]`; the stored integers of 16-bit voxels), x fastest: `v000, v100, v010, v110, v001, …`.
    pub corners: [f32; 8],
    /// Where the ray enters and leaves the cell (clipped to the span).
    pub t_in: f64,
    /// See `t_in`.
    pub t_out: f64,
    /// Cell-local units per world unit of `t` (the span's rate).
    pub rate: [f32; 3],
    /// The ray's cell-local position at `t = 0`, and the rate in `f64` (for [`CellVisit::start`]).
    offset: [f64; 3],
    rate_f64: [f64; 3],
    /// The brick, its stored voxels per axis, and the cell's coordinates in it (for gradients wider than the cell).
    voxels: PoolVoxels<'v>,
    /// Stored units to 16-bit units (`wide = stored · scale + offset`; 1 and 0 for 16-bit voxels).
    to_wide: (f32, f32),
    stored: usize,
    cell: [usize; 3],
}

impl CellVisit<'_> {
    /// The ray's position in the cell (cell-local, `[0, 1]³`) at `t_in`; computed only for the cells that need it
    /// (most are dismissed by their corners alone).
    #[inline(always)]
    pub fn start(&self) -> [f32; 3] {
        std::array::from_fn(|a| (self.offset[a] + self.t_in * self.rate_f64[a]) as f32)
    }

    /// The ray's position in the cell (cell-local) at distance `t`, from `t` alone: the same bits for the same `t`
    /// whatever the cell's entry was computed from.
    #[inline(always)]
    pub fn at(&self, t: f64) -> [f32; 3] {
        std::array::from_fn(|a| (self.offset[a] + t * self.rate_f64[a]) as f32)
    }

    /// The gradient at cell-local `p` from central differences at the cell's eight corners, interpolated
    /// trilinearly (smoother than the cell's own analytic gradient, which jumps between cells; Knoll et al. §3). At
    /// the brick's outer voxels the differences are one-sided.
    #[inline]
    pub fn central_gradient(&self, p: [f32; 3]) -> [f32; 3] {
        let b = self.stored;
        let at = |x: usize, y: usize, z: usize| self.voxels.stored((z * b + y) * b + x) * self.to_wide.0;
        let [fx, fy, fz] = p.map(|v| v.clamp(0.0, 1.0));
        let mut g = [0.0f32; 3];
        for corner in 0..8 {
            let c = [corner & 1, (corner >> 1) & 1, corner >> 2];
            let ijk: [usize; 3] = std::array::from_fn(|a| self.cell[a] + c[a]);
            let w = [fx, fy, fz].iter().zip(c).map(|(&f, side)| if side == 1 { f } else { 1.0 - f }).product::<f32>();
            for (a, component) in g.iter_mut().enumerate() {
                let (mut lo, mut hi) = (ijk, ijk);
                lo[a] = ijk[a].saturating_sub(1);
                hi[a] = (ijk[a] + 1).min(b - 1);
                let span = (hi[a] - lo[a]) as f32;
                *component += w * (at(hi[0], hi[1], hi[2]) - at(lo[0], lo[1], lo[2])) / span;
            }
        }
        g
    }
}

/// The eight corners of the cell whose first voxel is `base` (x fastest: `v000, v100, v010, v110, v001, …`).
#[inline(always)]
fn cell_corners<V: Voxel>(voxels: &[V], base: usize, row: usize, slab: usize) -> [f32; 8] {
    let v = &voxels[base..base + slab + row + 2];
    [
        v[0].stored(),
        v[1].stored(),
        v[row].stored(),
        v[row + 1].stored(),
        v[slab].stored(),
        v[slab + 1].stored(),
        v[slab + row].stored(),
        v[slab + row + 1].stored(),
    ]
}

/// The corners (16-bit units) of the cell of `span`'s brick that holds stored-index coordinates `x` (clamped to
/// the brick), and `x` in that cell's local coordinates: for points of the ray just outside the span, which the
/// volume renderer samples from the same brick.
pub(crate) fn corners_at(span: &BrickSpan<'_>, x: [f64; 3]) -> ([f32; 8], [f32; 3]) {
    let b = span.stored;
    let last_cell = (b - 2) as f64;
    let cell = x.map(|v| v.floor().clamp(0.0, last_cell));
    let base = ((cell[2] as usize * b + cell[1] as usize) * b) + cell[0] as usize;
    let corners = match span.voxels {
        PoolVoxels::Wide(v) => cell_corners(v, base, b, b * b),
        PoolVoxels::Narrow(v) => {
            let Dequantize { scale, offset } = span.dequantize;
            cell_corners(v, base, b, b * b).map(|c| c * (scale * VOXEL_MAX as f32) + offset * VOXEL_MAX as f32)
        }
    };
    (corners, std::array::from_fn(|a| (x[a] - cell[a]) as f32))
}

/// Cells visited (or blocks skipped) by one span at most (a ray crosses at most `3·B` cells of a `B³` lattice; the
/// cap only guards against a numerical stall).
fn max_cells(stored: usize) -> usize {
    3 * stored + 3
}

/// Occupancy blocks one run of rejected blocks crosses at most (a ray crosses at most `3·blocks` of a `blocks³`
/// lattice; the cap only guards against a numerical stall).
fn max_blocks(blocks: usize) -> usize {
    3 * blocks + 3
}

/// The DDA's state at one cell: the cell, and per axis the `t` of the next lattice plane.
struct Lattice {
    cell: [i64; 3],
    next: [f64; 3],
}

impl Lattice {
    /// The state at distance `t`, in the cell holding `x(t)` (clamped to the brick), or where the ray enters an
    /// occupancy block across a plane: `entered = (axis, cell, block)` gives the cell on that axis (the one just
    /// across the plane, which rounding of `x(t)` might not give) and keeps the others inside the block (which
    /// rounding of `x(t)` might leave where the plane meets another block's edge).
    #[inline(always)]
    fn at(span: &BrickSpan<'_>, inverse_rate: &[f64; 3], t: f64, entered: Option<(usize, i64, [i64; 3])>) -> Lattice {
        let last_cell = (span.stored - 2) as i64;
        // Truncation, not floor: the two differ only below 0, which the clamp sends to 0 either way.
        let mut cell: [i64; 3] =
            std::array::from_fn(|a| ((span.origin[a] + t * span.rate[a]) as i64).clamp(0, last_cell));
        if let Some((axis, c, block)) = entered {
            for (a, cell) in cell.iter_mut().enumerate() {
                let first = block[a] * BLOCK_CELLS as i64;
                *cell = (*cell).clamp(first, (first + BLOCK_CELLS as i64 - 1).min(last_cell));
            }
            cell[axis] = c;
        }
        let next = std::array::from_fn(|a| {
            let plane = cell[a] as f64 + if span.rate[a] > 0.0 { 1.0 } else { 0.0 };
            // Infinite (never the nearest) along an axis the ray does not move on.
            if span.rate[a] != 0.0 {
                (plane - span.origin[a]) * inverse_rate[a]
            } else {
                f64::INFINITY
            }
        });
        Lattice { cell, next }
    }
}

/// What walks the cells: it takes each cell, and says which occupancy blocks it can skip.
pub trait CellVisitor {
    /// Whether some value in `[lower, upper]` (stored units) can matter; `false` skips the block.
    fn block_can_contribute(&self, lower: u16, upper: u16) -> bool;
    /// One cell; `Break` ends the walk.
    fn visit(&mut self, cell: &CellVisit<'_>) -> ControlFlow<()>;
}

/// Visits the cells of `span` in ray order until the span ends or the visitor breaks; returns the cells visited.
/// Where the span allows culling, an occupancy block the visitor rejects is crossed without visiting its cells.
#[inline(always)]
pub fn walk_cells<V: CellVisitor>(span: &BrickSpan<'_>, visitor: &mut V) -> (ControlFlow<()>, u64) {
    let b = span.stored;
    let last_cell = (b - 2) as i64;
    let inverse_rate = span.rate.map(|r| 1.0 / r);
    let delta = inverse_rate.map(f64::abs);
    let step = span.rate.map(|r| {
        if r > 0.0 {
            1i64
        } else if r < 0.0 {
            -1
        } else {
            0
        }
    });
    let Lattice { mut cell, mut next } = Lattice::at(span, &inverse_rate, span.from, None);
    let rate = span.rate.map(|r| r as f32);
    // Corners in 16-bit units, what visitors compare: 8-bit voxels scaled (`Dequantize` times 65535).
    let to_wide = match span.voxels {
        PoolVoxels::Wide(_) => (1.0, 0.0),
        PoolVoxels::Narrow(_) => {
            let Dequantize { scale, offset } = span.dequantize;
            (scale * VOXEL_MAX as f32, offset * VOXEL_MAX as f32)
        }
    };
    let mut t = span.from;
    let mut visited = 0u64;
    // The block last checked, as one integer (cells are in [0, B−2], so their block coordinates fit 16 bits each).
    let mut checked_block = u64::MAX;
    let shift = BLOCK_CELLS.trailing_zeros();
    // Occupancy blocks are numbered x fastest, `span.blocks` per axis.
    let block_index =
        |block: [i64; 3]| ((block[2] * span.blocks as i64 + block[1]) * span.blocks as i64 + block[0]) as usize;
    for _ in 0..max_cells(b) {
        if span.cull_blocks {
            let key = |c: i64| (c as u64) >> shift;
            let block_key = key(cell[0]) | key(cell[1]) << 16 | key(cell[2]) << 32;
            if block_key != checked_block {
                checked_block = block_key;
                let block = cell.map(|c| c >> shift);
                let [lo, hi] = span.block_ranges[block_index(block)];
                if !visitor.block_can_contribute(lo, hi) {
                    // Cross the run of blocks the visitor rejects block by block (a DDA over blocks: each exit is
                    // the nearest of the block's exit planes), and set up the cells only where the run ends.
                    let mut block = block;
                    let mut entered = None;
                    for _ in 0..max_blocks(span.blocks) {
                        let mut exit = (f64::INFINITY, 0usize, 0i64);
                        for a in 0..3 {
                            let across = match step[a] {
                                1 => ((block[a] + 1) * BLOCK_CELLS as i64).min(last_cell + 1),
                                -1 => block[a] * BLOCK_CELLS as i64 - 1,
                                _ => continue,
                            };
                            let plane = if step[a] > 0 { across } else { across + 1 };
                            let t_plane = (plane as f64 - span.origin[a]) * inverse_rate[a];
                            if t_plane < exit.0 {
                                exit = (t_plane, a, across);
                            }
                        }
                        let (t_exit, axis, across) = exit;
                        if t_exit >= span.to || across < 0 || across > last_cell {
                            break;
                        }
                        t = t_exit.max(t);
                        block[axis] = across >> shift;
                        let [lo, hi] = span.block_ranges[block_index(block)];
                        if visitor.block_can_contribute(lo, hi) {
                            entered = Some((axis, across, block));
                            break;
                        }
                    }
                    let Some(entered) = entered else { break };
                    // The cells resume in the block just checked: rounding of the ray's other coordinates where it
                    // crosses near a block's edge could otherwise put them in a neighbour, rejected, whose exit
                    // leads back (a bounce that ends only at the cap, and loses the accepted block's cells).
                    Lattice { cell, next } = Lattice::at(span, &inverse_rate, t, Some(entered));
                    checked_block = key(cell[0]) | key(cell[1]) << 16 | key(cell[2]) << 32;
                    continue;
                }
            }
        }
        let axis = if next[0] <= next[1] && next[0] <= next[2] {
            0
        } else if next[1] <= next[2] {
            1
        } else {
            2
        };
        let t_out = next[axis].min(span.to).max(t);
        let base = ((cell[2] as usize * b + cell[1] as usize) * b) + cell[0] as usize;
        let (row, slab) = (b, b * b);
        let corners = match span.voxels {
            PoolVoxels::Wide(v) => cell_corners(v, base, row, slab),
            PoolVoxels::Narrow(v) => cell_corners(v, base, row, slab).map(|c| c * to_wide.0 + to_wide.1),
        };
        let offset = std::array::from_fn(|a| span.origin[a] - cell[a] as f64);
        visited += 1;
        let visit = CellVisit {
            corners,
            t_in: t,
            t_out,
            rate,
            offset,
            rate_f64: span.rate,
            voxels: span.voxels,
            to_wide,
            stored: b,
            cell: cell.map(|c| c as usize),
        };
        if visitor.visit(&visit).is_break() {
            return (ControlFlow::Break(()), visited);
        }
        if next[axis] >= span.to {
            break;
        }
        cell[axis] += step[axis];
        if cell[axis] < 0 || cell[axis] > last_cell {
            break;
        }
        t = t_out;
        next[axis] += delta[axis];
    }
    (ControlFlow::Continue(()), visited)
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxstream_core::VoxelFormat;

    /// Records cells; skips blocks whose lower bound is in `skip` (`u16::MAX..=u16::MAX`: none here).
    struct Recorder<F: FnMut(&CellVisit<'_>)> {
        skip: std::ops::RangeInclusive<u16>,
        record: F,
    }

    impl<F: FnMut(&CellVisit<'_>)> CellVisitor for Recorder<F> {
        fn block_can_contribute(&self, lower: u16, _upper: u16) -> bool {
            !self.skip.contains(&lower)
        }
        fn visit(&mut self, cell: &CellVisit<'_>) -> ControlFlow<()> {
            (self.record)(cell);
            ControlFlow::Continue(())
        }
    }

    #[test]
    fn cells_tile_the_span_in_order() {
        let b = 6;
        let voxels: Vec<u16> = (0..b * b * b).map(|i| i as u16).collect();
        let span = BrickSpan {
            voxels: PoolVoxels::Wide(&voxels),
            dequantize: VoxelFormat::Wide.dequantize(),
            stored: b,
            origin: [0.6, 1.2, 4.9],
            rate: [1.3, 0.7, -0.9],
            from: 0.0,
            to: 3.0,
            block_ranges: &[],
            blocks: 1,
            cull_blocks: false,
            step: 1.0,
        };
        let mut last_out = 0.0;
        let mut cells = Vec::new();
        let record = |c: &CellVisit<'_>| {
            assert_eq!(c.t_in, last_out, "no gap or overlap between cells");
            assert!(c.t_out >= c.t_in);
            // The start lies in the cell, and the corner v000 is the voxel at the cell's base.
            let start = c.start();
            assert!(start.iter().all(|&s| (-1e-5..=1.0 + 1e-5).contains(&s)), "{start:?}");
            last_out = c.t_out;
            cells.push(c.corners[0] as usize);
        };
        let (_, n) = walk_cells(&span, &mut Recorder { skip: u16::MAX..=u16::MAX, record });
        assert_eq!(last_out, 3.0);
        assert_eq!(n as usize, cells.len());
        // x from 0.6 to 4.5, y from 1.2 to 3.3, z from 4.9 to 2.2: 4 + 2 + 2 plane crossings, 9 cells.
        assert_eq!(cells.len(), 9, "{cells:?}");
        assert_eq!(cells[0], (4 * b + 1) * b, "first cell (0, 1, 4)");
    }

    #[test]
    fn central_differences_of_a_linear_field_are_its_slope() {
        // v = 3x + 5y + 7z + 100 (exact in u16): central differences give (3, 5, 7) everywhere inside, and the
        // one-sided ones at the brick's faces too.
        let b = 6;
        let voxels: Vec<u16> =
            (0..b * b * b).map(|i| (3 * (i % b) + 5 * (i / b % b) + 7 * (i / (b * b)) + 100) as u16).collect();
        for origin in [[0.3, 2.6, 1.1], [4.7, 4.2, 0.1]] {
            let span = BrickSpan {
                voxels: PoolVoxels::Wide(&voxels),
                dequantize: VoxelFormat::Wide.dequantize(),
                stored: b,
                origin,
                rate: [0.0, 0.0, 0.0],
                from: 0.0,
                to: 0.0,
                block_ranges: &[],
                blocks: 1,
                cull_blocks: false,
                step: 1.0,
            };
            let mut gradients = Vec::new();
            let record = |c: &CellVisit<'_>| gradients.push(c.central_gradient(c.start()));
            let _ = walk_cells(&span, &mut Recorder { skip: u16::MAX..=u16::MAX, record });
            assert_eq!(gradients.len(), 1);
            for (g, slope) in gradients[0].iter().zip([3.0, 5.0, 7.0]) {
                assert!((g - slope).abs() < 1e-5, "{:?} at {origin:?}", gradients[0]);
            }
        }
    }

    #[test]
    fn culled_blocks_are_crossed_without_visiting_their_cells() {
        // A 34³ brick (32 cells per axis, blocks of 8 cells: 5 blocks per axis, the last one a single cell) whose
        // voxel value is its block's x index: a ray along x through every block, culling blocks 1 and 2.
        let b = 34;
        let voxels: Vec<u16> = (0..b * b * b).map(|i| ((i % b) / BLOCK_CELLS) as u16).collect();
        let blocks = 5;
        let block_ranges: Vec<[u16; 2]> = (0..blocks * blocks * blocks).map(|i| [(i % 5) as u16; 2]).collect();
        let span = BrickSpan {
            voxels: PoolVoxels::Wide(&voxels),
            dequantize: VoxelFormat::Wide.dequantize(),
            stored: b,
            origin: [0.5, 3.5, 3.5],
            rate: [1.0, 0.0, 0.0],
            from: 0.0,
            to: 32.4,
            block_ranges: &block_ranges,
            blocks,
            cull_blocks: true,
            step: 1.0,
        };
        let mut seen = Vec::new();
        let record = |c: &CellVisit<'_>| seen.push((c.corners[0] as u16, c.t_in));
        let (_, n) = walk_cells(&span, &mut Recorder { skip: 1..=2, record });
        // Cells 0..8 (block 0), then 24..=32 (blocks 3 and 4): the ray re-enters at x = 24, t = 23.5.
        assert_eq!(n, 8 + 9, "{seen:?}");
        assert_eq!(seen[8], (3, 23.5));
        assert!(seen.iter().all(|&(block, _)| !(1..=2).contains(&block)));
    }

    /// The index of the occupancy block holding the cell whose first voxel is `base` (a `b³` brick, `blocks` per
    /// axis).
    fn block_of_cell(base: usize, b: usize, blocks: usize) -> usize {
        let [x, y, z] = [base % b, base / b % b, base / (b * b)].map(|c| c / BLOCK_CELLS);
        (z * blocks + y) * blocks + x
    }

    /// Rejects the blocks whose index (their range's lower bound here) is set in a mask.
    struct MaskedBlocks {
        rejected: u128,
        cells: Vec<usize>,
    }

    impl CellVisitor for MaskedBlocks {
        fn block_can_contribute(&self, lower: u16, _upper: u16) -> bool {
            self.rejected & (1 << lower) == 0
        }
        fn visit(&mut self, cell: &CellVisit<'_>) -> ControlFlow<()> {
            self.cells.push(cell.corners[0] as usize);
            ControlFlow::Continue(())
        }
    }

    proptest::proptest! {
        /// Culling only removes cells: a walk that rejects some blocks visits, in order, exactly the cells of the
        /// walk without culling that lie in blocks it accepts, however long the runs of rejected blocks.
        #[test]
        fn culling_visits_the_unculled_walks_cells_in_accepted_blocks(
            origin in proptest::array::uniform3(0.0f64..33.0),
            rate in proptest::array::uniform3(-1.0f64..1.0),
            rejected: u128,
        ) {
            let b = 34;
            let blocks = 5;
            // Each voxel's value is its index (each cell is named by its first corner); each block's range names
            // the block.
            let voxels: Vec<u16> = (0..b * b * b).map(|i| i as u16).collect();
            let block_ranges: Vec<[u16; 2]> = (0..blocks * blocks * blocks).map(|i| [i as u16; 2]).collect();
            let length = rate.iter().map(|r| r * r).sum::<f64>().sqrt().max(1e-3);
            let span = |cull_blocks| BrickSpan {
                voxels: PoolVoxels::Wide(&voxels),
                dequantize: VoxelFormat::Wide.dequantize(),
                stored: b,
                origin,
                rate,
                from: 0.0,
                to: 60.0 / length,
                block_ranges: &block_ranges,
                blocks,
                cull_blocks,
                step: 1.0,
            };
            let mut all = MaskedBlocks { rejected, cells: Vec::new() };
            let _ = walk_cells(&span(false), &mut all);
            let mut culled = MaskedBlocks { rejected, cells: Vec::new() };
            let _ = walk_cells(&span(true), &mut culled);
            let expected: Vec<usize> =
                all.cells.iter().copied().filter(|&c| rejected & (1 << block_of_cell(c, b, blocks)) == 0).collect();
            proptest::prop_assert_eq!(culled.cells, expected);
        }
    }

    #[test]
    fn a_ray_through_a_block_corner_does_not_bounce_between_rejected_blocks() {
        // A ray along the diagonal of x and y, through the corner where blocks (0,1,2) and (1,0,2), both rejected,
        // meet block (0,0,2), accepted (a case found by review). x(t) rounds to 8 on the axis not crossed, so the
        // cells set up after each rejected block used to land in the other one, and the walk bounced between them
        // until its cap, losing block (0,0,2)'s cells.
        let b = 34;
        let blocks = 5;
        let voxels: Vec<u16> = (0..b * b * b).map(|i| i as u16).collect();
        let block_ranges: Vec<[u16; 2]> = (0..blocks * blocks * blocks).map(|i| [i as u16; 2]).collect();
        let span = |cull_blocks| BrickSpan {
            voxels: PoolVoxels::Wide(&voxels),
            dequantize: VoxelFormat::Wide.dequantize(),
            stored: b,
            origin: [19.138852055303165, 19.138852055303165, 20.321332063106475],
            rate: [-0.9598942193908013, -0.9598942193908013, 0.0],
            from: 0.0,
            to: 40.0,
            block_ranges: &block_ranges,
            blocks,
            cull_blocks,
            step: 1.0,
        };
        let rejected: u128 = 158656801145080388633616921682194150770;
        // Block (0, 0, 2) is index 50; (1, 0, 2) is 51 and (0, 1, 2) is 55.
        let in_block_0_0_2 = |base: usize| block_of_cell(base, b, blocks) == 50;
        assert_eq!(rejected >> 50 & 1, 0, "block (0,0,2) accepted");
        assert_eq!(rejected >> 51 & rejected >> 55 & 1, 1, "blocks (1,0,2) and (0,1,2) rejected");
        let mut all = MaskedBlocks { rejected: 0, cells: Vec::new() };
        let _ = walk_cells(&span(false), &mut all);
        let mut culled = MaskedBlocks { rejected, cells: Vec::new() };
        let _ = walk_cells(&span(true), &mut culled);
        let wanted: Vec<usize> = all.cells.iter().copied().filter(|&c| in_block_0_0_2(c)).collect();
        let got: Vec<usize> = culled.cells.iter().copied().filter(|&c| in_block_0_0_2(c)).collect();
        assert!(!wanted.is_empty());
        // The ray reaches the block's far corner cell (0, 0, 20) either way (the staircase along the diagonal may
        // start on either side of the corner it enters by).
        let corner = 20 * b * b;
        assert_eq!(wanted.last(), Some(&corner), "{wanted:?}");
        assert_eq!(got.last(), Some(&corner), "{got:?}");
        assert!(got.len() + 1 >= wanted.len(), "{got:?} against {wanted:?}");
    }
}
