//! The cell grid of a fluid time step: where its cells and bricks are, and their levels of detail (Reichl §6.4.1).
//!
//! The domain (the particles' bounds, widened by a sphere's reach) is cut into cubic cells of a user-chosen size —
//! the balance between speed and how exactly a sphere sits — and the cells into bricks of [`BRICK`]³. Level 0 is
//! the finest; a cell of level `L` is `2^L` cells of level 0 per axis, a brick of level `L` covers `2^L` bricks of
//! level 0 per axis, and the coarsest level is one brick. Bricks are named by a [`BrickKey`].

use crate::FluidError;

/// Cells per axis of a brick (the thesis' 64³, which it measured as the best balance of rendering time, conversion
/// time and memory, §6.6.2). One row of a brick along x is one `u64`.
pub const BRICK: usize = 64;

/// log2 of [`BRICK`].
pub const BRICK_SHIFT: u32 = 6;

/// Most cells per axis of level 0 (2^20: a brick coordinate fits 14 bits, a key 64).
pub const MAX_CELLS_PER_AXIS: u64 = 1 << 20;

/// A brick: its level and integer coordinates among that level's bricks.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct BrickKey {
    /// Level of detail, 0 = finest.
    pub level: u8,
    /// Brick coordinates at that level.
    pub at: [u32; 3],
}

impl BrickKey {
    /// The brick of level 0 holding cell `cell` of level 0.
    pub fn of_cell(cell: [u32; 3]) -> BrickKey {
        BrickKey { level: 0, at: cell.map(|c| c >> BRICK_SHIFT) }
    }

    /// The brick one level coarser that covers this one.
    pub fn parent(self) -> BrickKey {
        BrickKey { level: self.level + 1, at: self.at.map(|c| c >> 1) }
    }

    /// The brick at level `level` (≥ this one's) covering this one.
    pub fn ancestor(self, level: u8) -> BrickKey {
        let up = u32::from(level - self.level);
        BrickKey { level, at: self.at.map(|c| c >> up) }
    }

    /// Packed into 64 bits (level in the top 6 bits, then z, y, x in 19 bits each): a total order by level, then
    /// by z, y, x.
    pub fn packed(self) -> u64 {
        (u64::from(self.level) << 57)
            | (u64::from(self.at[2]) << 38)
            | (u64::from(self.at[1]) << 19)
            | u64::from(self.at[0])
    }
}

/// The cell grid of one time step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FluidGrid {
    /// World position of the corner of cell (0, 0, 0).
    pub origin: [f64; 3],
    /// Edge of a level-0 cell, world units.
    pub cell: f64,
    /// Level-0 cells per axis (a multiple of [`BRICK`]).
    pub cells: [u32; 3],
    /// Number of levels (the coarsest, `levels − 1`, is one brick).
    pub levels: u8,
}

impl FluidGrid {
    /// The grid of `cell`-sized cells over the box `lower..upper` widened by `margin` on every side.
    pub fn new(lower: [f64; 3], upper: [f64; 3], margin: f64, cell: f64) -> Result<FluidGrid, FluidError> {
        if !(cell.is_finite() && cell > 0.0) {
            return Err(FluidError::Settings(format!("the cell size must be a positive number, got {cell}")));
        }
        let mut origin = [0.0; 3];
        let mut cells = [0u32; 3];
        for a in 0..3 {
            origin[a] = lower[a] - margin;
            let extent = upper[a] + margin - origin[a];
            let n = (extent / cell).ceil().max(1.0);
            if !(n.is_finite() && n <= MAX_CELLS_PER_AXIS as f64) {
                return Err(FluidError::Settings(format!(
                    "{} cells of {cell} along axis {a} exceed the {MAX_CELLS_PER_AXIS} a grid can hold: give a \
                     larger --particle-radius or --fluid-cell",
                    n
                )));
            }
            // Whole bricks.
            cells[a] = ((n as u32).div_ceil(BRICK as u32)) * BRICK as u32;
        }
        let bricks = cells.iter().map(|&c| c / BRICK as u32).max().unwrap_or(1);
        let levels = (bricks.next_power_of_two().trailing_zeros() + 1) as u8;
        Ok(FluidGrid { origin, cell, cells, levels })
    }

    /// Bricks per axis at `level`.
    pub fn bricks(&self, level: u8) -> [u32; 3] {
        self.cells.map(|c| (c >> BRICK_SHIFT).div_ceil(1 << level))
    }

    /// Edge of a cell of `level`, world units.
    pub fn cell_size(&self, level: u8) -> f64 {
        self.cell * f64::from(1u32 << level)
    }

    /// World box of a brick.
    pub fn brick_box(&self, key: BrickKey) -> ([f64; 3], [f64; 3]) {
        let edge = self.cell_size(key.level) * BRICK as f64;
        let lower = std::array::from_fn(|a| self.origin[a] + f64::from(key.at[a]) * edge);
        let upper = std::array::from_fn(|a| lower[a] + edge);
        (lower, upper)
    }

    /// The level-0 cell holding a world position, `None` outside the grid.
    #[inline]
    pub fn cell_of(&self, p: [f64; 3]) -> Option<[u32; 3]> {
        let mut out = [0u32; 3];
        for a in 0..3 {
            let c = ((p[a] - self.origin[a]) / self.cell).floor();
            if !(c >= 0.0 && c < f64::from(self.cells[a])) {
                return None;
            }
            out[a] = c as u32;
        }
        Some(out)
    }

    /// World box of the whole grid.
    pub fn world_box(&self) -> ([f64; 3], [f64; 3]) {
        let upper = std::array::from_fn(|a| self.origin[a] + f64::from(self.cells[a]) * self.cell);
        (self.origin, upper)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_grid_is_whole_bricks_and_its_coarsest_level_is_one_brick() {
        let grid = FluidGrid::new([0.0; 3], [10.0, 3.0, 1.0], 0.5, 0.05).unwrap();
        // 11 / 0.05 = 220 cells → 4 bricks of 64; 4 / 0.05 = 80 → 2; 2 / 0.05 = 40 → 1.
        assert_eq!(grid.cells, [256, 128, 64]);
        assert_eq!(grid.bricks(0), [4, 2, 1]);
        assert_eq!(grid.bricks(grid.levels - 1), [1, 1, 1]);
        assert_eq!(grid.bricks(grid.levels - 2), [2, 1, 1]);
        assert_eq!(grid.cell_of([-0.5, -0.5, -0.5]), Some([0, 0, 0]));
        assert_eq!(grid.cell_of([-0.6, 0.0, 0.0]), None);
        let cell = grid.cell_of([3.0, 1.0, 0.2]).unwrap();
        assert_eq!(BrickKey::of_cell(cell), BrickKey { level: 0, at: [1, 0, 0] });
    }

    #[test]
    fn a_grid_too_fine_is_refused_with_the_flag_to_change() {
        let error = FluidGrid::new([0.0; 3], [1.0; 3], 0.0, 1e-7).unwrap_err().to_string();
        assert!(error.contains("--particle-radius"), "{error}");
        assert!(FluidGrid::new([0.0; 3], [1.0; 3], 0.0, f64::NAN).is_err());
    }

    #[test]
    fn keys_pack_in_order_and_ancestors_cover_their_descendants() {
        let a = BrickKey { level: 0, at: [5, 3, 1] };
        let b = BrickKey { level: 0, at: [0, 0, 2] };
        assert!(a.packed() < b.packed());
        assert!(b.packed() < a.parent().packed());
        assert_eq!(a.ancestor(2), a.parent().parent());
        assert_eq!(a.ancestor(2).at, [1, 0, 0]);
    }
}
