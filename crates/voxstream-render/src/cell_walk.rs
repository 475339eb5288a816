//! The trilinear cells a ray crosses inside one brick, in order: a 3-D DDA (Amanatides & Woo) over the brick's
//! voxel lattice, handing each cell's eight corners and the ray's entry and exit in it to a visitor.
//!
//! This is the level Knoll et al. intersect at (seed 002 §3, "Ray–cell intersection"): the trilinear interpolant
//! is exact inside a cell, so a cell is the unit of exact intersection; [`crate::isosurface`] walks cells here.

use std::ops::ControlFlow;

use crate::integrand::BrickSpan;

/// One cell along a ray.
#[derive(Clone, Copy, Debug)]
pub struct CellVisit {
    /// Corner values as stored (integers in `[0, 65535]`), x fastest: `v000, v100, v010, v110, v001, …`.
    pub corners: [f32; 8],
    /// Where the ray enters and leaves the cell (clipped to the span).
    pub t_in: f64,
    /// See `t_in`.
    pub t_out: f64,
    /// The ray's position in the cell (cell-local, `[0, 1]³`) at `t_in`.
    pub start: [f32; 3],
    /// Cell-local units per world unit of `t` (the span's rate).
    pub rate: [f32; 3],
}

/// Cells visited by one span at most (a ray crosses at most `3·B` cells of a `B³` lattice; the cap only guards
/// against a numerical stall).
fn max_cells(stored: usize) -> usize {
    3 * stored + 3
}

/// Visits the cells of `span` in ray order until the span ends or `visit` breaks; returns the cells visited.
#[inline(always)]
pub fn walk_cells(span: &BrickSpan<'_>, mut visit: impl FnMut(&CellVisit) -> ControlFlow<()>) -> (ControlFlow<()>, u64) {
    let b = span.stored;
    let last_cell = (b - 2) as i64;
    let x0: [f64; 3] = std::array::from_fn(|a| span.origin[a] + span.from * span.rate[a]);
    let mut cell: [i64; 3] = x0.map(|x| (x.floor() as i64).clamp(0, last_cell));
    // Per axis: the t of the next lattice plane, the t between planes, and the step.
    let mut next = [f64::INFINITY; 3];
    let mut delta = [f64::INFINITY; 3];
    let mut step = [0i64; 3];
    for a in 0..3 {
        let rate = span.rate[a];
        if rate > 0.0 {
            next[a] = (cell[a] as f64 + 1.0 - span.origin[a]) / rate;
            delta[a] = 1.0 / rate;
            step[a] = 1;
        } else if rate < 0.0 {
            next[a] = (cell[a] as f64 - span.origin[a]) / rate;
            delta[a] = -1.0 / rate;
            step[a] = -1;
        }
    }
    let rate = span.rate.map(|r| r as f32);
    let mut t = span.from;
    let mut visited = 0u64;
    for _ in 0..max_cells(b) {
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
        let v = &span.voxels[base..base + slab + row + 2];
        let corners = [
            v[0] as f32,
            v[1] as f32,
            v[row] as f32,
            v[row + 1] as f32,
            v[slab] as f32,
            v[slab + 1] as f32,
            v[slab + row] as f32,
            v[slab + row + 1] as f32,
        ];
        let start = std::array::from_fn(|a| (span.origin[a] + t * span.rate[a] - cell[a] as f64) as f32);
        visited += 1;
        if visit(&CellVisit { corners, t_in: t, t_out, start, rate }).is_break() {
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

    #[test]
    fn cells_tile_the_span_in_order() {
        let b = 6;
        let voxels: Vec<u16> = (0..b * b * b).map(|i| i as u16).collect();
        let span = BrickSpan {
            voxels: &voxels,
            stored: b,
            origin: [0.6, 1.2, 4.9],
            rate: [1.3, 0.7, -0.9],
            from: 0.0,
            to: 3.0,
            level: 0,
        };
        let mut last_out = 0.0;
        let mut cells = Vec::new();
        let (_, n) = walk_cells(&span, |c| {
            assert_eq!(c.t_in, last_out, "no gap or overlap between cells");
            assert!(c.t_out >= c.t_in);
            // The start lies in the cell, and the corner v000 is the voxel at the cell's base.
            assert!(c.start.iter().all(|&s| (-1e-5..=1.0 + 1e-5).contains(&s)), "{:?}", c.start);
            last_out = c.t_out;
            cells.push(c.corners[0] as usize);
            ControlFlow::Continue(())
        });
        assert_eq!(last_out, 3.0);
        assert_eq!(n as usize, cells.len());
        // x from 0.6 to 4.5, y from 1.2 to 3.3, z from 4.9 to 2.2: 4 + 2 + 2 plane crossings, 9 cells.
        assert_eq!(cells.len(), 9, "{cells:?}");
        assert_eq!(cells[0], (4 * b + 1) * b, "first cell (0, 1, 4)");
    }
}
