//! The store's geometry: pyramid levels, bricks per level, and how tree nodes map to store chunks.
//!
//! Level 0 is the full resolution; level `l + 1` halves every axis (rounding up) by averaging 2×2×2 blocks; the
//! last level fits in one brick. Tree level `d` (root 0) reads store level `L − d`, brick `ijk` = chunk `ijk`.

use thiserror::Error;

/// Smallest brick edge a store may have (the importer's rule, `docs/STORE_FORMAT.md` §3.2).
pub const MIN_BRICK_SIZE: u64 = 4;

/// Largest brick edge a store may have.
pub const MAX_BRICK_SIZE: u64 = 256;

/// Why a pyramid cannot be laid out.
#[derive(Clone, Debug, Error, PartialEq, Eq)]
pub enum LayoutError {
    /// A brick edge below 2 would never reach one brick (0) or is degenerate (1).
    #[error("brick size must be at least 2, got {0}")]
    BrickSize(u64),
    /// Some axis has no samples.
    #[error("dimensions must be positive, got {0:?}")]
    Dims([u64; 3]),
}

/// Geometry of a multiscale brick store.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PyramidLayout {
    /// Samples per axis (x, y, z) at each level, level 0 first.
    pub level_dims: Vec<[u64; 3]>,
    /// Brick (chunk) edge in samples.
    pub brick_size: u64,
}

impl PyramidLayout {
    /// Levels for a volume of `dims` with bricks of `brick_size`, down to one brick. Each level halves the largest
    /// axis, so there are at most 64 levels whatever the input; a brick size below 2 or an empty axis is refused.
    pub fn new(dims: [u64; 3], brick_size: u64) -> Result<PyramidLayout, LayoutError> {
        if brick_size < 2 {
            return Err(LayoutError::BrickSize(brick_size));
        }
        if dims.contains(&0) {
            return Err(LayoutError::Dims(dims));
        }
        let mut level_dims = vec![dims];
        let mut last = dims;
        while last.iter().any(|&v| v > brick_size) {
            last = last.map(|v| v.div_ceil(2));
            level_dims.push(last);
        }
        Ok(PyramidLayout { level_dims, brick_size })
    }

    /// Number of levels.
    pub fn levels(&self) -> usize {
        self.level_dims.len()
    }

    /// Bricks per axis at `level`.
    pub fn bricks(&self, level: usize) -> [u64; 3] {
        self.level_dims[level].map(|v| v.div_ceil(self.brick_size))
    }

    /// Deepest tree level (the root is one brick at store level `levels − 1`).
    pub fn max_tree_level(&self) -> u32 {
        (self.levels() - 1) as u32
    }

    /// Fraction of the tree's unit cube the volume fills per axis (the tree spans `brick_size · 2^L` samples).
    pub fn extent(&self) -> [f64; 3] {
        let span = (self.brick_size << self.max_tree_level()) as f64;
        self.level_dims[0].map(|v| v as f64 / span)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pyramid_ends_in_one_brick() {
        let layout = PyramidLayout::new([197, 233, 189], 32).unwrap();
        assert_eq!(layout.levels(), 4);
        assert_eq!(layout.level_dims[3], [25, 30, 24]);
        assert_eq!(layout.bricks(0), [7, 8, 6]);
        assert_eq!(layout.bricks(3), [1, 1, 1]);
        let extent = layout.extent();
        assert!((extent[1] - 233.0 / 256.0).abs() < 1e-12);
        assert_eq!(PyramidLayout::new([10, 10, 10], 32).unwrap().levels(), 1);
    }

    #[test]
    fn degenerate_input_is_refused_not_looped_on() {
        // Regression (issue 9): brick size 0 used to loop forever, growing memory.
        assert_eq!(PyramidLayout::new([10, 10, 10], 0), Err(LayoutError::BrickSize(0)));
        assert_eq!(PyramidLayout::new([10, 10, 10], 1), Err(LayoutError::BrickSize(1)));
        assert_eq!(PyramidLayout::new([0, 10, 10], 32), Err(LayoutError::Dims([0, 10, 10])));
        assert_eq!(PyramidLayout::new([u64::MAX; 3], 2).unwrap().levels(), 64);
    }
}
