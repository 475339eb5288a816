//! Node identity: the tree's shape and the `(level, ijk)` key of a node, kept apart from where it lives in a pool.
//!
//! GigaVoxels [P09] §4 ("Tiles"): the N³-tree subdivides the unit cube regularly, so a node is named by its level
//! and integer coordinates. Coordinates are `u64`, so an N = 3 tree can reach level 40 (3⁴⁰ ≈ 1.2·10¹⁹ < 2⁶⁴): deep
//! zooms are exact integers, never float positions.

use crate::error::CoreError;

/// Cells per edge of a brick's occupancy block: the granularity at which rays skip invisible space inside a brick.
pub const BLOCK_CELLS: usize = 8;

/// Shape of an N³-tree and its bricks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TreeShape {
    /// Subdivision factor per axis (2 = octree, 3 for the Menger sponge).
    pub n: u32,
    /// Brick edge in voxels, without the border.
    pub brick_size: u32,
    /// Deepest level the producer can reach (the root is level 0).
    pub max_level: u32,
}

/// The one-voxel border around every brick, duplicated from the neighbours (GigaVoxels [P09] §4).
pub const BRICK_BORDER: u32 = 1;

impl TreeShape {
    /// Checks the shape and returns it.
    pub fn new(n: u32, brick_size: u32, max_level: u32) -> Result<TreeShape, CoreError> {
        if !(2..=4).contains(&n) {
            return Err(CoreError::InvalidShape(format!("N must be 2, 3 or 4, got {n}")));
        }
        if !(2..=64).contains(&brick_size) {
            return Err(CoreError::InvalidShape(format!("brick size must be 2..=64 voxels, got {brick_size}")));
        }
        let levels_fitting_u64 = (64.0 / (n as f64).log2()).floor() as u32 - 1;
        if max_level > levels_fitting_u64 {
            return Err(CoreError::InvalidShape(format!(
                "max level {max_level} too deep for N={n} (at most {levels_fitting_u64})"
            )));
        }
        Ok(TreeShape { n, brick_size, max_level })
    }

    /// Nodes per tile: `N³`.
    #[inline]
    pub fn nodes_per_tile(&self) -> u32 {
        self.n * self.n * self.n
    }

    /// Brick edge including both borders: `M + 2`.
    #[inline]
    pub fn stored_brick_size(&self) -> u32 {
        self.brick_size + 2 * BRICK_BORDER
    }

    /// Occupancy blocks per brick axis: the `B − 1` cells between the `B = M + 2` stored voxels, in blocks of
    /// [`BLOCK_CELLS`] cells (the last block may be smaller).
    pub fn blocks_per_axis(&self) -> usize {
        (self.stored_brick_size() as usize - 1).div_ceil(BLOCK_CELLS)
    }

    /// Occupancy blocks per brick.
    pub fn blocks_per_brick(&self) -> usize {
        self.blocks_per_axis().pow(3)
    }

    /// Voxels stored per brick: `(M + 2)³`.
    #[inline]
    pub fn voxels_per_brick(&self) -> usize {
        (self.stored_brick_size() as usize).pow(3)
    }

    /// Nodes per axis at `level`: `N^level`.
    #[inline]
    pub fn nodes_per_axis(&self, level: u32) -> u64 {
        (self.n as u64).pow(level)
    }

    /// Edge of a voxel at `level`, in volume units (the root spans 1).
    #[inline]
    pub fn voxel_size(&self, level: u32) -> f64 {
        1.0 / (self.nodes_per_axis(level) as f64 * self.brick_size as f64)
    }

    /// Virtual resolution of the finest level, per axis (saturates at `u64::MAX`).
    pub fn virtual_resolution(&self) -> u64 {
        self.nodes_per_axis(self.max_level).saturating_mul(self.brick_size as u64)
    }
}

/// Identity of a node: level and integer coordinates at that level.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct NodeKey {
    /// Depth in the tree; the root is 0.
    pub level: u32,
    /// Coordinates in `[0, N^level)³`.
    pub ijk: [u64; 3],
}

impl NodeKey {
    /// The root node.
    pub const ROOT: NodeKey = NodeKey { level: 0, ijk: [0, 0, 0] };

    /// Child `child_index` (x fastest, then y, then z) of this node.
    #[inline]
    pub fn child(&self, child_index: u32, n: u32) -> NodeKey {
        let n64 = n as u64;
        let c = child_index as u64;
        NodeKey {
            level: self.level + 1,
            ijk: [
                self.ijk[0] * n64 + c % n64,
                self.ijk[1] * n64 + (c / n64) % n64,
                self.ijk[2] * n64 + c / (n64 * n64),
            ],
        }
    }

    /// Lower corner and edge of the node in volume units `[0, 1]³`.
    pub fn bounds(&self, shape: &TreeShape) -> ([f64; 3], f64) {
        let size = 1.0 / shape.nodes_per_axis(self.level) as f64;
        ([self.ijk[0] as f64 * size, self.ijk[1] as f64 * size, self.ijk[2] as f64 * size], size)
    }

    /// Centre of stored voxel `(i, j, k)` of this node's brick (border included: index 0 is the border voxel below
    /// the node), in volume units: what every producer samples its field at.
    #[inline]
    pub fn voxel_centre(&self, shape: &TreeShape, i: u32, j: u32, k: u32) -> [f64; 3] {
        let (lower, size) = self.bounds(shape);
        let voxel = size / shape.brick_size as f64;
        [lower[0] + (i as f64 - 0.5) * voxel, lower[1] + (j as f64 - 0.5) * voxel, lower[2] + (k as f64 - 0.5) * voxel]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn children_tile_the_parent() {
        let shape = TreeShape::new(3, 9, 20).unwrap();
        let parent = NodeKey { level: 2, ijk: [4, 5, 8] };
        let mut seen = std::collections::HashSet::new();
        for c in 0..27 {
            let child = parent.child(c, 3);
            assert_eq!(child.level, 3);
            for a in 0..3 {
                assert_eq!(child.ijk[a] / 3, parent.ijk[a]);
            }
            seen.insert(child.ijk);
        }
        assert_eq!(seen.len(), 27);
        let (lo, size) = parent.child(26, 3).bounds(&shape);
        assert!((lo[0] + size - 5.0 / 9.0).abs() < 1e-15);
    }

    #[test]
    fn shape_rejects_nonsense() {
        assert!(TreeShape::new(1, 8, 4).is_err());
        assert!(TreeShape::new(2, 0, 4).is_err());
        assert!(TreeShape::new(3, 9, 60).is_err());
        assert!(TreeShape::new(3, 9, 39).is_ok());
    }

    #[test]
    fn virtual_resolution_of_the_sponge_passes_float_limits() {
        let shape = TreeShape::new(3, 9, 25).unwrap();
        assert!(shape.virtual_resolution() > 1 << 40);
        assert_eq!(shape.voxels_per_brick(), 11 * 11 * 11);
    }
}
