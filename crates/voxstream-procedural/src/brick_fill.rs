//! Filling a brick (border included) from a function of position: the common core of the analytic producers.
//!
//! Voxel `(i, j, k)` of a stored brick (`0..M+2` per axis, border included) is centred at
//! `lower + (i − ½)·voxel` (GigaVoxels [P09] §4: the border duplicates the neighbours' voxels).

use glam::DVec3;
use voxstream_core::{quantize, NodeKey, TreeShape};

/// Centre of stored voxel `(i, j, k)` of node `key`, volume units ([`NodeKey::voxel_centre`] as a vector).
#[inline]
pub fn voxel_centre(shape: &TreeShape, key: &NodeKey, i: u32, j: u32, k: u32) -> DVec3 {
    DVec3::from(key.voxel_centre(shape, i, j, k))
}

/// Writes `density(position)` (clamped to `[0, 1]`) at every stored voxel of `key`.
pub fn fill_brick(shape: &TreeShape, key: &NodeKey, voxels: &mut [u16], mut density: impl FnMut(DVec3) -> f64) {
    let b = shape.stored_brick_size();
    debug_assert_eq!(voxels.len(), (b as usize).pow(3));
    let mut index = 0;
    for k in 0..b {
        for j in 0..b {
            for i in 0..b {
                voxels[index] = quantize(density(voxel_centre(shape, key, i, j, k)) as f32);
                index += 1;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn border_voxels_straddle_the_node() {
        let shape = TreeShape::new(2, 4, 3).unwrap();
        let key = NodeKey { level: 1, ijk: [1, 0, 0] };
        let first = voxel_centre(&shape, &key, 0, 1, 1);
        let last = voxel_centre(&shape, &key, 5, 1, 1);
        // Node spans x ∈ [0.5, 1]; voxel edge 1/8.
        assert!((first.x - (0.5 - 0.0625)).abs() < 1e-12);
        assert!((last.x - (1.0 + 0.0625)).abs() < 1e-12);
    }
}
