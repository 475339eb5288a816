//! The mesh producer: bricks of a triangle mesh's signed distance, made when a ray asks for them.
//!
//! Reichl (seed 004, ch. 7) turns huge meshes into sample-based bricks; GigaVoxels ([R08] §7, the "furry bunny")
//! amplifies a mesh's distance field with noise into a hypertexture. Here each brick is produced on demand at its
//! level's resolution from [`MeshDistance`] (a BVH over the triangles): no preprocessing pass beyond building the
//! hierarchy, no resolution fixed in advance.
//!
//! Voxel values encode the signed distance `D` (plus `k·fbm`, when amplified) in a band around the surface:
//! `v = clamp(½ − D / band, 0, 1)` with `band = band_voxels` voxels of the brick's level, so the surface is the
//! isosurface `v = ½`, inside reads 1 and outside 0 — a volume renderer sees a solid, an isosurface renderer the
//! exact zero set, and every level is the same field band-limited to its voxels (the band widens with the voxel;
//! noise octaves shorter than two voxels are dropped). Inside the band, `D = (½ − v)·band` recovers the distance.
//!
//! The oracle answers from one bounded distance query at the node's centre: a node whose centre is farther from the
//! surface than its half-diagonal plus half the band (plus the noise bound) is wholly outside (empty) or inside
//! (solid), the side given by the whole mesh's winding number along rays ([`MeshDistance::is_inside`]), never by the
//! nearest feature's pseudo-normal, which a fold in the mesh can turn (issue 42: solid boxes beyond the cow's tail).
//! Within a brick, each voxel searches only within the band (plus the noise bound, and at least a voxel): beyond it
//! the value is 0 or 1 and only the side matters, which is the same for each 6-connected group of such far voxels
//! (the distance is 1-Lipschitz), so one winding test per group decides it.

use std::sync::Arc;

use glam::DVec3;
use voxstream_core::noise::{fbm, fbm_bound};
use voxstream_core::{quantize, NodeContent, NodeKey, ProduceError, Produced, Producer, TreeShape};

use crate::error::GeometryError;
use crate::mesh_distance::{MeshDistance, UnitCubeFit};
use crate::triangle_mesh::TriangleMesh;

/// Multi-octave noise added to the distance field (GigaVoxels' hypertexture).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Amplification {
    /// Noise amplitude `k`, unit-cube units.
    pub amplitude: f64,
    /// Frequency of the first octave, per unit-cube unit.
    pub base_frequency: f64,
    /// Number of octaves.
    pub octaves: u32,
    /// Amplitude ratio between octaves.
    pub gain: f64,
    /// Noise seed.
    pub seed: u64,
}

impl Amplification {
    /// Noise of amplitude `amplitude` (unit-cube units) with GigaVoxels' defaults: 12 octaves from a wavelength of a
    /// tenth of the cube, gain ½.
    pub fn with_amplitude(amplitude: f64) -> Amplification {
        Amplification { amplitude, base_frequency: 10.0, octaves: 12, gain: 0.5, seed: 2008 }
    }
}

/// How a mesh becomes a tree.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeshTreeSettings {
    /// Voxels per brick edge (without border).
    pub brick_size: u32,
    /// Width of the distance ramp, in voxels of each level.
    pub band_voxels: f64,
    /// Virtual resolution of the finest level per axis (`None`: about four voxels per median triangle edge,
    /// between 512 and 16384; ×16 deeper when amplified, since noise has detail at every scale).
    pub resolution: Option<u64>,
    /// Noise, if any.
    pub amplify: Option<Amplification>,
    /// Fraction of the cube's edge the mesh's largest side takes.
    pub fill: f64,
}

impl Default for MeshTreeSettings {
    fn default() -> Self {
        MeshTreeSettings { brick_size: 8, band_voxels: 3.0, resolution: None, amplify: None, fill: 0.8 }
    }
}

/// The mesh producer (N = 2).
#[derive(Clone, Debug)]
pub struct MeshProducer {
    shape: TreeShape,
    field: Arc<MeshDistance>,
    settings: MeshTreeSettings,
    fit: UnitCubeFit,
}

impl MeshProducer {
    /// Places `mesh` in the unit cube and builds its distance hierarchy.
    pub fn new(mesh: &TriangleMesh, settings: MeshTreeSettings) -> Result<MeshProducer, GeometryError> {
        let invalid = |message: String| GeometryError::Invalid { message };
        if !(settings.band_voxels.is_finite() && settings.band_voxels >= 1.0) {
            return Err(invalid(format!("band of {} voxels: it must be at least 1", settings.band_voxels)));
        }
        if let Some(a) = settings.amplify {
            if !(a.amplitude.is_finite() && a.amplitude >= 0.0 && a.base_frequency.is_finite() && a.gain.is_finite()) {
                return Err(invalid(format!("amplification {a:?} must be finite and non-negative")));
            }
        }
        // The brick size is checked before it divides anything.
        TreeShape::new(2, settings.brick_size, 0).map_err(|error| invalid(error.to_string()))?;
        let (lower, upper) = mesh.bounds();
        let fit = UnitCubeFit::checked_around(lower, upper, settings.fill)?;
        let field = MeshDistance::new(mesh, fit);
        let resolution = settings.resolution.unwrap_or_else(|| {
            let wanted = (4.0 / field.median_edge.max(1e-9)).clamp(512.0, 16384.0) as u64;
            if settings.amplify.is_some() {
                wanted * 16
            } else {
                wanted
            }
        });
        let bricks = resolution.div_ceil(u64::from(settings.brick_size)).max(1);
        let max_level = 64 - (bricks - 1).leading_zeros();
        let shape = TreeShape::new(2, settings.brick_size, max_level).map_err(|error| invalid(error.to_string()))?;
        Ok(MeshProducer { shape, field: Arc::new(field), settings, fit })
    }

    /// Where the mesh sits in the unit cube (file units ↔ tree units).
    pub fn fit(&self) -> UnitCubeFit {
        self.fit
    }

    /// The distance field (unit-cube units).
    pub fn field(&self) -> &MeshDistance {
        &self.field
    }

    /// Width of the distance ramp at `level`, unit-cube units.
    pub fn band(&self, level: u32) -> f64 {
        self.settings.band_voxels * self.shape.voxel_size(level)
    }

    /// How far beyond the mesh's bounds (unit-cube units) values can be non-zero: half the finest band plus the noise.
    pub fn margin(&self) -> f64 {
        self.band(self.shape.max_level) * 0.5 + self.noise_bound()
    }

    fn noise_bound(&self) -> f64 {
        self.settings.amplify.map_or(0.0, |a| a.amplitude * fbm_bound(a.octaves, a.gain))
    }

    /// The (amplified) distance at `p` as seen at `level`, given the mesh's signed distance there.
    fn displaced(&self, p: DVec3, distance: f64, level: u32) -> f64 {
        match self.settings.amplify {
            Some(a) => {
                let voxel = self.shape.voxel_size(level);
                distance + a.amplitude * fbm(p.to_array(), a.base_frequency, a.octaves, a.gain, voxel, a.seed)
            }
            None => distance,
        }
    }

    /// The voxel value at `p` as seen at `level` (the reference the bricks are made of).
    pub fn value(&self, p: DVec3, level: u32) -> f64 {
        let distance = self.field.signed_distance(p);
        let value = 0.5 - self.displaced(p, distance, level) / self.band(level);
        if value > 0.0 && value < 1.0 {
            value
        } else if self.field.is_inside(p) {
            1.0
        } else {
            0.0
        }
    }
}

impl Producer for MeshProducer {
    fn shape(&self) -> TreeShape {
        self.shape
    }

    fn oracle(&self, key: NodeKey) -> Option<f32> {
        let (lower, size) = key.bounds(&self.shape);
        let voxel = size / f64::from(self.shape.brick_size);
        let reach = (size * 0.5 + voxel) * 3f64.sqrt();
        let slack = self.band(key.level) * 0.5 + self.noise_bound();
        let centre = DVec3::from(lower) + DVec3::splat(size * 0.5);
        // The node lies in a ball around its centre that the surface does not enter: one side of it throughout, the
        // side the whole mesh's winding gives (the nearest feature's sign can be wrong far from a fold).
        if self.field.signed_distance_within(centre, reach + slack).is_some() {
            return None;
        }
        Some(if self.field.is_inside(centre) { 1.0 } else { 0.0 })
    }

    fn produce(&self, key: NodeKey, voxels: &mut [u16]) -> Result<Produced, ProduceError> {
        let b = self.shape.stored_brick_size() as usize;
        let band = self.band(key.level);
        // Beyond the band's half (and the noise), values saturate; the search also reaches at least one voxel, so
        // that a voxel with nothing found and its neighbour are together farther from the surface than the step.
        let slack = (band * 0.5 + self.noise_bound()).max(self.shape.voxel_size(key.level) * (1.0 + 1e-9));
        // Each voxel searches only within `slack`. Inside it, the value comes from the distance and the nearest
        // feature's sign (a wrong sign there, at a fold, stays within the band). Beyond it the value is 0 or 1 and
        // only the side matters: two neighbouring voxels one of which is farther than `slack` (more than a voxel)
        // from the surface are on the same side of it (the distance is 1-Lipschitz), so each 6-connected group of
        // such far voxels lies on one side, which one test of the whole mesh (`is_inside`) decides. A near voxel's
        // pseudo-normal sign is never passed on to far ones.
        let mut far = vec![false; b * b * b];
        let mut index = 0;
        for k in 0..b {
            for j in 0..b {
                for i in 0..b {
                    let p = DVec3::from(key.voxel_centre(&self.shape, i as u32, j as u32, k as u32));
                    match self.field.signed_distance_within(p, slack) {
                        Some(distance) => {
                            let value = (0.5 - self.displaced(p, distance, key.level) / band).clamp(0.0, 1.0);
                            voxels[index] = quantize(value as f32);
                        }
                        None => far[index] = true,
                    }
                    index += 1;
                }
            }
        }
        let mut pending = Vec::new();
        for seed in 0..far.len() {
            if !far[seed] {
                continue;
            }
            let (i, j, k) = (seed % b, seed / b % b, seed / (b * b));
            let p = DVec3::from(key.voxel_centre(&self.shape, i as u32, j as u32, k as u32));
            let value = quantize(if self.field.is_inside(p) { 1.0 } else { 0.0 });
            // Flood the seed's group: each far voxel is written once and leaves the group.
            far[seed] = false;
            pending.push(seed);
            while let Some(n) = pending.pop() {
                voxels[n] = value;
                let (i, j, k) = (n % b, n / b % b, n / (b * b));
                let neighbours = [
                    (i > 0).then(|| n - 1),
                    (i + 1 < b).then(|| n + 1),
                    (j > 0).then(|| n - b),
                    (j + 1 < b).then(|| n + b),
                    (k > 0).then(|| n - b * b),
                    (k + 1 < b).then(|| n + b * b),
                ];
                for m in neighbours.into_iter().flatten() {
                    if far[m] {
                        far[m] = false;
                        pending.push(m);
                    }
                }
            }
        }
        Ok(Produced { content: NodeContent::Brick, is_terminal: key.level >= self.shape.max_level })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::triangle_mesh::RawMesh;

    /// An icosphere of `subdivisions` around the origin, radius 1 (vertices on the sphere).
    pub(crate) fn icosphere(subdivisions: u32) -> TriangleMesh {
        let t = (1.0 + 5f64.sqrt()) / 2.0;
        let mut positions: Vec<DVec3> = [
            [-1.0, t, 0.0],
            [1.0, t, 0.0],
            [-1.0, -t, 0.0],
            [1.0, -t, 0.0],
            [0.0, -1.0, t],
            [0.0, 1.0, t],
            [0.0, -1.0, -t],
            [0.0, 1.0, -t],
            [t, 0.0, -1.0],
            [t, 0.0, 1.0],
            [-t, 0.0, -1.0],
            [-t, 0.0, 1.0],
        ]
        .iter()
        .map(|p| DVec3::from(*p).normalize())
        .collect();
        let mut triangles: Vec<[u32; 3]> = vec![
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ];
        for _ in 0..subdivisions {
            let mut midpoints = std::collections::HashMap::new();
            let mut middle = |a: u32, b: u32, positions: &mut Vec<DVec3>| {
                *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
                    positions.push(((positions[a as usize] + positions[b as usize]) * 0.5).normalize());
                    positions.len() as u32 - 1
                })
            };
            let mut next = Vec::with_capacity(triangles.len() * 4);
            for [a, b, c] in triangles {
                let ab = middle(a, b, &mut positions);
                let bc = middle(b, c, &mut positions);
                let ca = middle(c, a, &mut positions);
                next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
            }
            triangles = next;
        }
        let positions = positions.iter().map(|p| p.as_vec3().to_array()).collect();
        TriangleMesh::new(RawMesh { positions, triangles }).unwrap()
    }

    #[test]
    fn sphere_bricks_hold_the_distance_within_half_a_voxel() {
        // A finely tessellated sphere: the mesh is within (1 − cos(θ/2)) ≈ 3e-4 of the true sphere.
        let mesh = icosphere(6);
        let settings = MeshTreeSettings { resolution: Some(256), ..MeshTreeSettings::default() };
        let producer = MeshProducer::new(&mesh, settings).unwrap();
        let fit = producer.fit();
        let radius = 1.0 / fit.size;
        let centre = fit.to_unit([0.0; 3]);
        let shape = producer.shape();
        let mut voxels = vec![0u16; shape.voxels_per_brick()];
        let mut checked = 0;
        for level in [3, shape.max_level] {
            let voxel = shape.voxel_size(level);
            let band = producer.band(level);
            let per_axis = shape.nodes_per_axis(level);
            for index in (0..per_axis.pow(3)).step_by(7) {
                let key = NodeKey {
                    level,
                    ijk: [index % per_axis, index / per_axis % per_axis, index / per_axis / per_axis],
                };
                let oracle = producer.oracle(key);
                if oracle.is_some() && index % 5 != 0 {
                    continue;
                }
                producer.produce(key, &mut voxels).unwrap();
                let b = shape.stored_brick_size();
                for (n, &v) in voxels.iter().enumerate() {
                    let (i, j, k) = (n as u32 % b, n as u32 / b % b, n as u32 / b / b);
                    let p = DVec3::from(key.voxel_centre(&shape, i, j, k));
                    let exact = (p - centre).length() - radius;
                    let value = f64::from(v) / 65535.0;
                    if let Some(constant) = oracle {
                        assert_eq!(value, f64::from(constant), "oracle wrong at {key:?}");
                    }
                    if value > 0.0 && value < 1.0 {
                        let decoded = (0.5 - value) * band;
                        assert!((decoded - exact).abs() <= 0.5 * voxel, "{key:?} {p}: {decoded} vs {exact}");
                        checked += 1;
                    } else {
                        // Outside the band: the right side of the surface.
                        assert!((value == 0.0) == (exact > 0.0) || exact.abs() < 0.5 * voxel, "{p}: {value} {exact}");
                    }
                }
            }
        }
        assert!(checked > 1000, "{checked} voxels in the band");
    }

    #[test]
    fn oracle_finds_the_empty_outside_and_the_solid_inside() {
        let producer = MeshProducer::new(&icosphere(3), MeshTreeSettings::default()).unwrap();
        let corner = NodeKey { level: 3, ijk: [0, 0, 0] };
        assert_eq!(producer.oracle(corner), Some(0.0));
        let middle = NodeKey { level: 3, ijk: [3, 3, 3] }; // touches the centre: deep inside
        assert_eq!(producer.oracle(middle), Some(1.0));
        let surface = NodeKey { level: 3, ijk: [0, 3, 3] }; // x ∈ [0, 1/8], the sphere reaches x = 0.1
        assert_eq!(producer.oracle(surface), None);
    }

    #[test]
    fn amplified_bricks_stay_within_the_noise_bound() {
        let mesh = icosphere(3);
        let amplify = Amplification::with_amplitude(0.01);
        let settings = MeshTreeSettings { amplify: Some(amplify), ..MeshTreeSettings::default() };
        let producer = MeshProducer::new(&mesh, settings).unwrap();
        assert!(producer.shape().virtual_resolution() >= 8192, "amplified trees go deeper");
        let plain = MeshProducer::new(&mesh, MeshTreeSettings::default()).unwrap();
        let level = 5;
        let shape = producer.shape();
        let mut differs = 0;
        for index in 0..200u64 {
            let p = DVec3::new((index % 10) as f64 / 10.0, (index / 10 % 5) as f64 / 5.0, (index / 50) as f64 / 4.0);
            let a = producer.value(p, level);
            let b = plain.value(p, level);
            if a != b {
                differs += 1;
            }
            let bound = producer.noise_bound() / producer.band(level);
            assert!((a - b).abs() <= bound + 1e-9, "noise moves values by at most its bound");
            let _ = shape;
        }
        assert!(differs > 0, "the noise changes the field");
    }
}
