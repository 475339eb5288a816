//! The store's geometry: pyramid levels, bricks per level, and how tree nodes map to store chunks.
//!
//! Level 0 is the full resolution; level `l + 1` halves every axis (rounding up) by averaging 2×2×2 blocks; the
//! last level fits in one brick. Tree level `d` (root 0) reads store level `L − d`, brick `ijk` = chunk `ijk`.

/// Geometry of a multiscale brick store.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PyramidLayout {
    /// Samples per axis (x, y, z) at each level, level 0 first.
    pub level_dims: Vec<[u64; 3]>,
    /// Brick (chunk) edge in samples.
    pub brick_size: u64,
}

impl PyramidLayout {
    /// Levels for a volume of `dims` with bricks of `brick_size`, down to one brick.
    pub fn new(dims: [u64; 3], brick_size: u64) -> PyramidLayout {
        let mut level_dims = vec![dims];
        while level_dims.last().is_some_and(|d| d.iter().any(|&v| v > brick_size)) {
            let d = *level_dims.last().unwrap_or(&dims);
            level_dims.push(d.map(|v| v.div_ceil(2)));
        }
        PyramidLayout { level_dims, brick_size }
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
        let layout = PyramidLayout::new([197, 233, 189], 32);
        assert_eq!(layout.levels(), 4);
        assert_eq!(layout.level_dims[3], [25, 30, 24]);
        assert_eq!(layout.bricks(0), [7, 8, 6]);
        assert_eq!(layout.bricks(3), [1, 1, 1]);
        let extent = layout.extent();
        assert!((extent[1] - 233.0 / 256.0).abs() < 1e-12);
        assert_eq!(PyramidLayout::new([10, 10, 10], 32).levels(), 1);
    }
}
