//! Polygons into triangles, for the mesh readers (OBJ, OFF, PLY).
//!
//! A polygon of up to [`FAN_CORNERS`] corners is fanned, `(0, i, i+1)`, as before. A larger one is split in
//! balanced halves: the triangle `(first, middle, last)` of its corner chain, then each half-chain the same way, so
//! that every triangle spans a run of neighbouring corners. A fan of a 200,000-corner face made 200,000 slivers all
//! meeting at one corner, whose boxes all overlap there, and every distance query near that corner visited them all
//! (issue 41: a 1.1 MB OBJ took 203 s); the balanced split's boxes nest like a tree's. Both make `corners − 2`
//! triangles in the polygon's orientation, and neither needs the polygon to be planar or convex (neither is correct
//! for a non-convex one: readers take faces as given).

/// Corners up to which a polygon is fanned.
pub const FAN_CORNERS: usize = 16;

/// Appends the triangles of the polygon `corners` (vertex indices in order) to `triangles`: nothing for fewer than
/// three corners.
pub fn triangulate(corners: &[u32], triangles: &mut Vec<[u32; 3]>) {
    let n = corners.len();
    if n < 3 {
        return;
    }
    if n <= FAN_CORNERS {
        triangles.extend((1..n - 1).map(|i| [corners[0], corners[i], corners[i + 1]]));
        return;
    }
    triangles.reserve(n - 2);
    // Chains `lo..=hi` of corners, closed by the chord hi → lo; the stack holds at most one pending chain per level.
    let mut chains = vec![(0, n - 1)];
    while let Some((lo, hi)) = chains.pop() {
        if hi - lo < 2 {
            continue;
        }
        let middle = lo + (hi - lo) / 2;
        triangles.push([corners[lo], corners[middle], corners[hi]]);
        chains.push((middle, hi));
        chains.push((lo, middle));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_polygons_are_fanned() {
        let mut triangles = Vec::new();
        triangulate(&[7, 8, 9, 10], &mut triangles);
        assert_eq!(triangles, vec![[7, 8, 9], [7, 9, 10]]);
        triangulate(&[1, 2], &mut triangles);
        assert_eq!(triangles.len(), 2, "fewer than three corners make nothing");
    }

    #[test]
    fn large_polygons_split_into_neighbouring_runs_with_every_corner_and_one_orientation() {
        for n in [FAN_CORNERS + 1, 100, 4097] {
            let corners: Vec<u32> = (0..n as u32).collect();
            let mut triangles = Vec::new();
            triangulate(&corners, &mut triangles);
            assert_eq!(triangles.len(), n - 2);
            // The polygon's orientation (increasing corner order, as a fan keeps it) and every corner used.
            let mut used = vec![false; n];
            for t in &triangles {
                assert!(t[0] < t[1] && t[1] < t[2], "{t:?}");
                t.iter().for_each(|&c| used[c as usize] = true);
            }
            assert!(used.iter().all(|&u| u));
            // A triangulation of a convex polygon: the areas of the triangles add up to the polygon's.
            let point = |c: u32| {
                let angle = std::f64::consts::TAU * f64::from(c) / n as f64;
                (angle.cos(), angle.sin())
            };
            let area = |a: (f64, f64), b: (f64, f64), c: (f64, f64)| {
                0.5 * ((b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0))
            };
            let sum: f64 = triangles.iter().map(|t| area(point(t[0]), point(t[1]), point(t[2]))).sum();
            let polygon = 0.5 * n as f64 * (std::f64::consts::TAU / n as f64).sin();
            assert!((sum - polygon).abs() < 1e-9 * polygon, "{sum} vs {polygon}");
            // No sliver fan: the corner most used is in O(log n) triangles, not n − 2.
            let mut uses = vec![0usize; n];
            triangles.iter().flatten().for_each(|&c| uses[c as usize] += 1);
            let most = *uses.iter().max().unwrap();
            assert!(most <= 2 * (usize::BITS - n.leading_zeros()) as usize, "{most} triangles meet at one corner");
        }
    }
}
