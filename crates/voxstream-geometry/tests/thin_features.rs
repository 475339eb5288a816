//! Inside and outside of meshes with thin features, against an exact reference: every voxel the mesh producer
//! makes (or its oracle answers for a whole node) away from the surface must lie on the side the mesh's winding
//! number gives (Van Oosterom and Strackee's solid angle, summed over every triangle: independent of the BVH, the
//! pseudo-normals and the rays the producer uses).
//!
//! Regression (issue 42, item 3): CGAL's `cow.off` has a fold at its tail's tip (two triangles crossed through each
//! other), whose crease's pseudo-normal points inwards; every point whose nearest feature was that crease, a cone
//! reaching far beyond the tail, read inside, and whole nodes there were solid boxes at any resolution.

use glam::DVec3;
use voxstream_core::{NodeKey, Producer};
use voxstream_geometry::triangle_bvh::closest_on_triangle;
use voxstream_geometry::{MeshProducer, MeshTreeSettings, RawMesh, TriangleMesh};

/// The winding number of the triangles around `p` (1 inside a closed outward-facing mesh, 0 outside).
fn winding_number(positions: &[DVec3], triangles: &[[u32; 3]], p: DVec3) -> f64 {
    let mut solid_angle = 0.0;
    for t in triangles {
        let [a, b, c] = t.map(|i| positions[i as usize] - p);
        let (la, lb, lc) = (a.length(), b.length(), c.length());
        let numerator = a.dot(b.cross(c));
        let denominator = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
        solid_angle += 2.0 * numerator.atan2(denominator);
    }
    solid_angle / (4.0 * std::f64::consts::PI)
}

/// Distance from `p` to the nearest triangle, by brute force.
fn distance(positions: &[DVec3], triangles: &[[u32; 3]], p: DVec3) -> f64 {
    triangles
        .iter()
        .map(|t| t.map(|i| positions[i as usize]))
        .map(|[a, b, c]| (closest_on_triangle(p, a, b, c).0 - p).length())
        .fold(f64::INFINITY, f64::min)
}

/// A closed needle along +x: a tube of `sides` sides and radius `radius` from x = 0 to 1, a flat back cap, and a
/// tip cone to `tip` (a tip pulled off the axis folds the cone's triangles through the tube's wall).
fn needle(sides: u32, radius: f32, tip: [f32; 3]) -> TriangleMesh {
    let mut positions = Vec::new();
    for x in [0.0f32, 1.0] {
        for s in 0..sides {
            let angle = std::f32::consts::TAU * s as f32 / sides as f32;
            positions.push([x, radius * angle.cos(), radius * angle.sin()]);
        }
    }
    let (back, front) = (2 * sides, 2 * sides + 1);
    positions.push([0.0, 0.0, 0.0]);
    positions.push(tip);
    let mut triangles = Vec::new();
    for s in 0..sides {
        let next = (s + 1) % sides;
        // Tube (outward: counter-clockwise seen from outside), back cap facing −x, tip cone facing +x.
        triangles.push([s, next, sides + next]);
        triangles.push([s, sides + next, sides + s]);
        triangles.push([back, next, s]);
        triangles.push([front, sides + s, sides + next]);
    }
    TriangleMesh::new(RawMesh { positions, triangles }).unwrap()
}

/// Walks the producer's tree as a renderer would (oracle, then bricks and their children where it does not know)
/// and returns the samples checked and the disagreements with the winding number beyond `band/2 + voxel` of the
/// surface.
fn disagreements(mesh: &TriangleMesh, resolution: u64) -> (usize, Vec<String>) {
    let settings = MeshTreeSettings { resolution: Some(resolution), ..MeshTreeSettings::default() };
    let producer = MeshProducer::new(mesh, settings).unwrap();
    let fit = producer.fit();
    let positions: Vec<DVec3> = mesh.positions().iter().map(|p| fit.to_unit(p.map(f64::from))).collect();
    let triangles = mesh.triangles();
    let shape = producer.shape();
    let b = shape.stored_brick_size();
    let mut voxels = vec![0u16; shape.voxels_per_brick()];
    let (mut checked, mut wrong) = (0, Vec::new());
    let mut check = |p: DVec3, inside: bool, level: u32, what: &str| {
        let tolerance = producer.band(level) * 0.5 + shape.voxel_size(level);
        if distance(&positions, triangles, p) <= tolerance {
            return;
        }
        checked += 1;
        let reference = winding_number(&positions, triangles, p) > 0.5;
        if inside != reference {
            wrong.push(format!("{what} at {p} (file {}): inside {inside}", DVec3::from(fit.origin) + p * fit.size));
        }
    };
    let mut pending = vec![NodeKey::ROOT];
    while let Some(key) = pending.pop() {
        if let Some(value) = producer.oracle(key) {
            // A constant node: its corners (a hair inside) and centre.
            let (lower, size) = key.bounds(&shape);
            for corner in 0..9u32 {
                let offset = if corner == 8 {
                    DVec3::splat(0.5)
                } else {
                    DVec3::new((corner & 1) as f64, (corner >> 1 & 1) as f64, (corner >> 2) as f64) * 0.98 + 0.01
                };
                check(DVec3::from(lower) + offset * size, value > 0.5, key.level, &format!("oracle {key:?}"));
            }
            continue;
        }
        producer.produce(key, &mut voxels).unwrap();
        for (n, &v) in voxels.iter().enumerate() {
            let (i, j, k) = (n as u32 % b, n as u32 / b % b, n as u32 / b / b);
            let p = DVec3::from(key.voxel_centre(&shape, i, j, k));
            check(p, v > u16::MAX / 2, key.level, &format!("brick {key:?}"));
        }
        if key.level < shape.max_level {
            pending.extend((0..8).map(|c| key.child(c, 2)));
        }
    }
    (checked, wrong)
}

#[test]
fn a_plain_needle_is_inside_exactly_where_its_winding_number_says() {
    let (checked, wrong) = disagreements(&needle(8, 0.01, [1.05, 0.0, 0.0]), 256);
    assert!(checked > 10_000, "{checked} samples away from the surface");
    assert!(
        wrong.is_empty(),
        "{} of {checked} samples on the wrong side, e.g. {:?}",
        wrong.len(),
        &wrong[..3.min(wrong.len())]
    );
}

#[test]
fn a_needle_with_a_folded_tip_has_no_solid_outside_it() {
    // The tip pulled back and off the axis: the tip cone's triangles fold through the tube's wall (as at the cow's
    // tail), and on main whole nodes beyond the tip read solid (4499 and 8466 samples on the wrong side).
    for tip in [[0.98, 0.03, 0.0], [0.97, -0.02, 0.01]] {
        let (checked, wrong) = disagreements(&needle(8, 0.01, tip), 256);
        assert!(checked > 10_000, "{checked} samples away from the surface");
        assert!(
            wrong.is_empty(),
            "tip {tip:?}: {} of {checked} samples on the wrong side, e.g. {:?}",
            wrong.len(),
            &wrong[..3.min(wrong.len())]
        );
    }
}
