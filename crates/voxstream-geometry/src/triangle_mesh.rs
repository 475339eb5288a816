//! A validated triangle mesh: finite vertex positions and triangles that index them, degenerate and repeated
//! triangles dropped.
//!
//! Readers (`formats`) produce a [`RawMesh`] (polygons already fanned into triangles); [`TriangleMesh::new`] checks it
//! once, so that the distance queries of the mesh producer never meet a NaN or an out-of-range index.

use crate::error::GeometryError;

/// Vertices and triangles as a file holds them, not yet validated.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RawMesh {
    /// Vertex positions, file units.
    pub positions: Vec<[f32; 3]>,
    /// Triangles as vertex indices (polygons fanned: `(0, i, i+1)`).
    pub triangles: Vec<[u32; 3]>,
}

/// A mesh ready for distance queries.
#[derive(Clone, Debug)]
pub struct TriangleMesh {
    positions: Vec<[f32; 3]>,
    triangles: Vec<[u32; 3]>,
    /// Triangles dropped because their area is zero (repeated or collinear vertices).
    pub degenerate_dropped: usize,
    /// Triangles dropped because an earlier one has the same corners in the same turn.
    pub repeated_dropped: usize,
}

impl TriangleMesh {
    /// Validates `raw`: every position finite, every index in range, at least one triangle of non-zero area.
    pub fn new(raw: RawMesh) -> Result<TriangleMesh, GeometryError> {
        let RawMesh { positions, mut triangles } = raw;
        if let Some(index) = positions.iter().position(|p| p.iter().any(|c| !c.is_finite())) {
            return Err(GeometryError::Invalid {
                message: format!(
                    "vertex {index} has a non-finite coordinate {:?}: fix or remove it in the mesh file",
                    positions[index]
                ),
            });
        }
        let count = positions.len();
        if let Some(t) = triangles.iter().position(|t| t.iter().any(|&i| i as usize >= count)) {
            return Err(GeometryError::Invalid {
                message: format!(
                    "triangle {t} uses vertex {:?} but the mesh has {count} vertices",
                    triangles[t].iter().max().copied().unwrap_or(0)
                ),
            });
        }
        // Vertices at bit-identical positions become one (−0 counts as +0): the sign of the distance comes from
        // normals shared across edges and vertices, which a flat-shaded file (each face its own vertices) would
        // otherwise not share.
        let mut first_at: std::collections::HashMap<[u32; 3], u32> = std::collections::HashMap::new();
        let remap: Vec<u32> = positions
            .iter()
            .enumerate()
            .map(|(i, p)| *first_at.entry(p.map(|c| (c + 0.0).to_bits())).or_insert(i as u32))
            .collect();
        for t in &mut triangles {
            *t = t.map(|i| remap[i as usize]);
        }
        let before = triangles.len();
        triangles.retain(|t| {
            let [a, b, c] = t.map(|i| glam::DVec3::from(positions[i as usize].map(f64::from)));
            (b - a).cross(c - a).length_squared() > 0.0
        });
        let degenerate_dropped = before - triangles.len();
        // Repeated triangles (the same corners in the same turn) lie on each other: every distance query near them
        // would test them all, and no hierarchy can split them (a polygon listing its corners over and over made
        // 100,000 copies of two triangles). One copy stays; a copy turned the other way (a two-sided wall) stays too.
        let mut seen = std::collections::HashSet::with_capacity(triangles.len());
        let nondegenerate = triangles.len();
        triangles.retain(|&[a, b, c]| {
            // The rotation that starts at the smallest index names the turn.
            let turned = if a <= b && a <= c {
                [a, b, c]
            } else if b <= c {
                [b, c, a]
            } else {
                [c, a, b]
            };
            seen.insert(turned)
        });
        let repeated_dropped = nondegenerate - triangles.len();
        if triangles.is_empty() {
            return Err(GeometryError::Invalid {
                message: if before == 0 {
                    "the mesh has no triangles (a point cloud? render it as particles)".into()
                } else {
                    format!("all {before} triangles of the mesh have zero area")
                },
            });
        }
        Ok(TriangleMesh { positions, triangles, degenerate_dropped, repeated_dropped })
    }

    /// Vertex positions.
    pub fn positions(&self) -> &[[f32; 3]] {
        &self.positions
    }

    /// Triangles (vertex indices), none degenerate.
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// Axis-aligned bounds of the vertices used by triangles (lower, upper).
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let mut lower = [f64::INFINITY; 3];
        let mut upper = [f64::NEG_INFINITY; 3];
        for t in &self.triangles {
            for &i in t {
                let p = self.positions[i as usize];
                for a in 0..3 {
                    lower[a] = lower[a].min(f64::from(p[a]));
                    upper[a] = upper[a].max(f64::from(p[a]));
                }
            }
        }
        (lower, upper)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn raw(positions: Vec<[f32; 3]>, triangles: Vec<[u32; 3]>) -> RawMesh {
        RawMesh { positions, triangles }
    }

    #[test]
    fn validation_names_the_problem() {
        let good = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let mesh = TriangleMesh::new(raw(good.clone(), vec![[0, 1, 2], [0, 0, 1]])).unwrap();
        assert_eq!(mesh.triangles().len(), 1);
        assert_eq!(mesh.degenerate_dropped, 1);
        let nan = TriangleMesh::new(raw(vec![[0.0, f32::NAN, 0.0]], vec![])).unwrap_err().to_string();
        assert!(nan.contains("vertex 0 has a non-finite coordinate"), "{nan}");
        let range = TriangleMesh::new(raw(good.clone(), vec![[0, 1, 7]])).unwrap_err().to_string();
        assert!(range.contains("uses vertex 7 but the mesh has 3 vertices"), "{range}");
        let flat = TriangleMesh::new(raw(good, vec![[0, 0, 1]])).unwrap_err().to_string();
        assert!(flat.contains("zero area"), "{flat}");
    }

    #[test]
    fn repeated_triangles_are_dropped_but_not_turned_ones() {
        let positions = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let mut triangles = vec![[0, 1, 2]; 1000];
        triangles.extend([[1, 2, 0], [2, 0, 1], [0, 2, 1], [2, 1, 0]]);
        let mesh = TriangleMesh::new(raw(positions, triangles)).unwrap();
        assert_eq!(mesh.triangles(), &[[0, 1, 2], [0, 2, 1]]);
        assert_eq!(mesh.repeated_dropped, 1002);
        assert_eq!(mesh.degenerate_dropped, 0);
    }

    #[test]
    fn coincident_vertices_are_welded() {
        // Two triangles sharing an edge through duplicated vertices (and a −0).
        let positions =
            vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, -0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]];
        let mesh = TriangleMesh::new(raw(positions, vec![[0, 1, 2], [3, 5, 4]])).unwrap();
        assert_eq!(mesh.triangles(), &[[0, 1, 2], [1, 5, 2]]);
    }
}
