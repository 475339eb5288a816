//! A hypertextured torus, N = 2: a distance field amplified by 16 octaves of fBm (virtual resolution 131072³).
//!
//! GigaVoxels [R08] §7 / [P09] §8 ("Hypertexture"): opacity = f(d(X) + k·P(X)), with d a distance field and P a
//! multi-octave noise; the oracle knows the inner and outer shells. Here:
//!
//! - `D(X) = d_torus(X) + k · fbm(X)` with 16 octaves of aperiodic value noise;
//! - density `ρ = clamp(½ − D / band, 0, 1)`, where the band widens to 1.5 voxels at coarse levels and octaves
//!   shorter than two voxels are dropped: each level is a band-limited (mip) version of the finest one;
//! - oracle: a node is empty where `d_torus > k·B + band/2` on all of it and solid where `d_torus < −(k·B + band/2)`,
//!   with `B` the fBm bound and `d_torus` 1-Lipschitz.

use glam::{DVec2, DVec3};
use voxstream_core::{NodeContent, NodeKey, ProduceError, Produced, Producer, TreeShape};

use crate::brick_fill::fill_brick;
use crate::noise::{fbm, fbm_bound};

/// The hypertexture producer.
#[derive(Clone, Copy, Debug)]
pub struct Hypertexture {
    shape: TreeShape,
    /// Torus centre, volume units.
    pub centre: DVec3,
    /// Major radius (centre to tube axis).
    pub major_radius: f64,
    /// Minor radius (tube).
    pub minor_radius: f64,
    /// Noise amplitude `k`, volume units.
    pub amplitude: f64,
    /// Frequency of the first octave, per volume unit.
    pub base_frequency: f64,
    /// Number of octaves.
    pub octaves: u32,
    /// Amplitude ratio between octaves.
    pub gain: f64,
    /// Width of the density ramp at the finest level, volume units.
    pub finest_band: f64,
    /// Noise seed.
    pub seed: u64,
}

impl Default for Hypertexture {
    fn default() -> Self {
        Hypertexture {
            shape: TreeShape { n: 2, brick_size: 8, max_level: 14 },
            centre: DVec3::splat(0.5),
            major_radius: 0.28,
            minor_radius: 0.12,
            amplitude: 0.03,
            base_frequency: 6.0,
            octaves: 16,
            gain: 0.5,
            finest_band: 2e-5,
            seed: 2008,
        }
    }
}

impl Hypertexture {
    /// The default hypertexture with another brick size and depth.
    pub fn with_shape(brick_size: u32, max_level: u32) -> Result<Hypertexture, voxstream_core::CoreError> {
        Ok(Hypertexture { shape: TreeShape::new(2, brick_size, max_level)?, ..Hypertexture::default() })
    }

    /// Signed distance to the torus (axis along z), negative inside.
    #[inline]
    pub fn torus_distance(&self, p: DVec3) -> f64 {
        let q = p - self.centre;
        let ring = DVec2::new(DVec2::new(q.x, q.y).length() - self.major_radius, q.z);
        ring.length() - self.minor_radius
    }

    fn band(&self, level: u32) -> f64 {
        self.finest_band.max(1.5 * self.shape.voxel_size(level))
    }

    /// Density at `p` as seen at `level` (band-limited to that level's voxels).
    pub fn density(&self, p: DVec3, level: u32) -> f64 {
        let voxel = self.shape.voxel_size(level);
        let noise = fbm(p.to_array(), self.base_frequency, self.octaves, self.gain, voxel, self.seed);
        let displaced = self.torus_distance(p) + self.amplitude * noise;
        (0.5 - displaced / self.band(level)).clamp(0.0, 1.0)
    }
}

impl Producer for Hypertexture {
    fn shape(&self) -> TreeShape {
        self.shape
    }

    fn oracle(&self, key: NodeKey) -> Option<f32> {
        let (lower, size) = key.bounds(&self.shape);
        // Cover the border voxels too.
        let reach = size * 3f64.sqrt() * 0.5 + size / self.shape.brick_size as f64 * 3f64.sqrt();
        let distance = self.torus_distance(DVec3::from(lower) + DVec3::splat(size * 0.5));
        let slack = self.amplitude * fbm_bound(self.octaves, self.gain) + self.band(key.level) * 0.5;
        if distance - reach > slack {
            Some(0.0)
        } else if distance + reach < -slack {
            Some(1.0)
        } else {
            None
        }
    }

    fn produce(&self, key: NodeKey, voxels: &mut [u16]) -> Result<Produced, ProduceError> {
        fill_brick(&self.shape, &key, voxels, |p| self.density(p, key.level));
        Ok(Produced { content: NodeContent::Brick, is_terminal: key.level >= self.shape.max_level })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn virtual_resolution_is_at_least_16384() {
        assert!(Hypertexture::default().shape().virtual_resolution() >= 16384);
        assert!(Hypertexture::default().octaves >= 16);
    }

    #[test]
    fn oracle_agrees_with_production() {
        let h = Hypertexture::default();
        let shape = h.shape();
        let mut voxels = vec![0u16; shape.voxels_per_brick()];
        let (mut empty, mut solid) = (0, 0);
        for level in 2..4u32 {
            let per_axis = 1u64 << level;
            for index in 0..per_axis.pow(3) {
                let key = NodeKey {
                    level,
                    ijk: [index % per_axis, (index / per_axis) % per_axis, index / per_axis / per_axis],
                };
                if let Some(value) = h.oracle(key) {
                    h.produce(key, &mut voxels).unwrap();
                    let expected = voxstream_core::quantize(value);
                    assert!(voxels.iter().all(|&v| v == expected), "oracle wrong at {key:?}");
                    if value == 0.0 {
                        empty += 1
                    } else {
                        solid += 1
                    }
                }
            }
        }
        assert!(empty > 0, "the oracle finds the empty outside");
        let _ = solid; // The tube (radius 0.12) is thin; the solid core appears at deeper levels.
        let deep = NodeKey { level: 6, ijk: [32 + 18 - 1, 32, 32] }; // inside the tube, near its axis
        let (lower, size) = deep.bounds(&shape);
        let centre = DVec3::from(lower) + DVec3::splat(size / 2.0);
        assert!(h.torus_distance(centre) < -0.05);
        assert_eq!(h.oracle(deep), Some(1.0), "the solid core is constant");
    }
}
