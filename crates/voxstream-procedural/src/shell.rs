//! An analytic spherical shell, `ρ(x) = exp(−((|x − c| − R)/σ)²)`: a smooth closed-form field, the test reference.
//!
//! Its bricks are point samples of the closed form. The field is smooth at the scale of σ, so the tree stops at
//! 256³ (level 4 of 16³ bricks, σ ≈ 15 voxels): finer levels would add nothing, which is the producer's "lower
//! resolution is enough" answer of GigaVoxels [R08] §4. So a converged render can be compared with a brute-force ray march of the same formula. The oracle marks
//! as empty every node farther than `4.5σ` from the shell, where `ρ < 2·10⁻⁹` quantises to 0 anyway.

use glam::DVec3;
use voxstream_core::{NodeContent, NodeKey, ProduceError, Produced, Producer, TreeShape};

use crate::brick_fill::fill_brick;

/// Distance from the shell (in σ) beyond which the density is treated as 0.
const CUTOFF_SIGMAS: f64 = 4.5;

/// The analytic shell producer.
#[derive(Clone, Copy, Debug)]
pub struct Shell {
    shape: TreeShape,
    /// Centre, volume units.
    pub centre: DVec3,
    /// Radius of the shell's crest.
    pub radius: f64,
    /// Thickness parameter σ.
    pub thickness: f64,
}

impl Default for Shell {
    fn default() -> Self {
        Shell {
            shape: TreeShape { n: 2, brick_size: 16, max_level: 4 },
            centre: DVec3::splat(0.5),
            radius: 0.3,
            thickness: 0.06,
        }
    }
}

impl Shell {
    /// The default shell with another brick size and depth.
    pub fn with_shape(brick_size: u32, max_level: u32) -> Result<Shell, voxstream_core::CoreError> {
        Ok(Shell { shape: TreeShape::new(2, brick_size, max_level)?, ..Shell::default() })
    }

    /// The closed-form density at `p` (volume units).
    #[inline]
    pub fn density(&self, p: DVec3) -> f64 {
        let r = ((p - self.centre).length() - self.radius) / self.thickness;
        if r.abs() > CUTOFF_SIGMAS {
            0.0
        } else {
            (-r * r).exp()
        }
    }
}

impl Producer for Shell {
    fn shape(&self) -> TreeShape {
        self.shape
    }

    fn oracle(&self, key: NodeKey) -> Option<f32> {
        let (lower, size) = key.bounds(&self.shape);
        let half_diagonal = size * 3f64.sqrt() * 0.5;
        let distance = (DVec3::from(lower) + DVec3::splat(size * 0.5) - self.centre).length();
        // Every point of the node is at least this far from the crest, plus one voxel of border.
        let margin = half_diagonal + size / self.shape.brick_size as f64;
        ((distance - self.radius).abs() > CUTOFF_SIGMAS * self.thickness + margin).then_some(0.0)
    }

    fn produce(&self, key: NodeKey, voxels: &mut [u16]) -> Result<Produced, ProduceError> {
        fill_brick(&self.shape, &key, voxels, |p| self.density(p));
        Ok(Produced { content: NodeContent::Brick, is_terminal: key.level >= self.shape.max_level })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn density_peaks_on_the_crest() {
        let shell = Shell::default();
        assert!((shell.density(DVec3::new(0.8, 0.5, 0.5)) - 1.0).abs() < 1e-12);
        assert_eq!(shell.density(DVec3::splat(0.5)), 0.0);
    }

    #[test]
    fn oracle_is_conservative() {
        let shell = Shell::default();
        let shape = shell.shape();
        let mut voxels = vec![0u16; shape.voxels_per_brick()];
        for level in 1..4u32 {
            let per_axis = 1u64 << level;
            for index in 0..per_axis.pow(3) {
                let key = NodeKey {
                    level,
                    ijk: [index % per_axis, (index / per_axis) % per_axis, index / per_axis / per_axis],
                };
                if shell.oracle(key).is_some() {
                    shell.produce(key, &mut voxels).unwrap();
                    assert!(voxels.iter().all(|&v| v == 0), "oracle called {key:?} empty");
                }
            }
        }
    }
}
