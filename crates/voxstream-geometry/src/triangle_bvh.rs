//! A bounding-volume hierarchy over a mesh's triangles, and the closest-point query the mesh producer's signed
//! distance is built on.
//!
//! Built once when the mesh is opened (binned surface-area-heuristic splits of the triangle centroids along the widest
//! axis, median splits below [`MAX_DEPTH`], leaves of up to [`LEAF_TRIANGLES`]), queried for every voxel a brick
//! needs. The query is a depth-first search that visits the
//! nearer child first and prunes boxes farther than the best distance so far; callers pass an upper bound on the
//! distance (a neighbouring voxel's distance plus the step, the distance field being 1-Lipschitz), which prunes
//! almost everything at once. (Gathering the leaves near a brick once and searching only those per voxel was tried:
//! no faster on the Stanford dragon, where a voxel's band already holds dozens of triangles.) Reichl (seed 004, ch. 7) voxelises triangles into bricks the same on-demand way; the
//! closest-point-in-triangle test with feature classification is Ericson, *Real-Time Collision Detection* §5.1.5.

use glam::DVec3;
use rayon::prelude::*;

/// Most triangles in a leaf.
pub const LEAF_TRIANGLES: usize = 4;

/// One node: a box and either two children (`count == 0`: left is the next node, right is `first`) or a leaf
/// (`count` triangles of the reordered list from `first`).
#[derive(Clone, Copy, Debug)]
struct BvhNode {
    lower: [f32; 3],
    upper: [f32; 3],
    first: u32,
    count: u32,
}

/// Which part of a triangle a closest point lies on: its inside, an edge (0: ab, 1: bc, 2: ca) or a vertex (0: a,
/// 1: b, 2: c). The sign of the distance comes from the pseudo-normal of that feature.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TriangleFeature {
    /// Inside the triangle.
    Face,
    /// On edge `0`: ab, `1`: bc, `2`: ca.
    Edge(u8),
    /// At vertex `0`: a, `1`: b, `2`: c.
    Vertex(u8),
}

/// The closest point of a triangle to a query point.
#[derive(Clone, Copy, Debug)]
pub struct ClosestPoint {
    /// The point.
    pub point: DVec3,
    /// Squared distance to the query point.
    pub distance_squared: f64,
    /// Index of the triangle (in the mesh's order).
    pub triangle: u32,
    /// The feature of the triangle it lies on.
    pub feature: TriangleFeature,
}

/// The hierarchy over triangles given by their corners.
#[derive(Clone, Debug)]
pub struct TriangleBvh {
    nodes: Vec<BvhNode>,
    /// Triangle indices in leaf order.
    order: Vec<u32>,
}

fn widen(bound: f64, down: bool) -> f32 {
    // f32 boxes must contain the f64 triangles: round outward by more than f32's rounding.
    let value = bound as f32;
    let slack = value.abs().max(1e-6) * 4.0 * f32::EPSILON;
    if down {
        value - slack
    } else {
        value + slack
    }
}

impl TriangleBvh {
    /// Builds the hierarchy over the triangles (depth at most [`MAX_DEPTH`]); subtrees of more than
    /// [`PARALLEL_TRIANGLES`] are built on the worker threads.
    pub fn build(positions: &[DVec3], triangles: &[[u32; 3]]) -> TriangleBvh {
        let centroids: Vec<DVec3> =
            triangles.par_iter().map(|t| t.map(|i| positions[i as usize]).iter().sum::<DVec3>() / 3.0).collect();
        let mut order: Vec<u32> = (0..triangles.len() as u32).collect();
        let builder = Builder { positions, triangles, centroids: &centroids };
        let nodes = builder.subtree(&mut order, 0, 0);
        TriangleBvh { nodes, order }
    }

    /// The closest point of any triangle to `p` strictly within `max_distance`, or `None` if no triangle comes that
    /// close. `positions` and `triangles` must be those the hierarchy was built over.
    pub fn closest_point(
        &self,
        positions: &[DVec3],
        triangles: &[[u32; 3]],
        p: DVec3,
        max_distance: f64,
    ) -> Option<ClosestPoint> {
        let mut best: Option<ClosestPoint> = None;
        let mut best_squared = max_distance * max_distance;
        // Pending nodes with their box distances. Each level of the tree leaves at most one pending sibling, and the
        // build bounds the depth by MAX_DEPTH.
        let mut stack = [(0u32, 0.0f64); MAX_DEPTH + 2];
        stack[0] = (0, box_distance_squared(&self.nodes[0], p));
        let mut depth = 1;
        while depth > 0 {
            depth -= 1;
            let (index, distance) = stack[depth];
            if distance >= best_squared {
                continue;
            }
            let node = &self.nodes[index as usize];
            if node.count > 0 {
                let first = node.first as usize;
                for &t in &self.order[first..first + node.count as usize] {
                    let [a, b, c] = triangles[t as usize].map(|i| positions[i as usize]);
                    let (point, feature) = closest_on_triangle(p, a, b, c);
                    let distance_squared = (point - p).length_squared();
                    if distance_squared < best_squared {
                        best_squared = distance_squared;
                        best = Some(ClosestPoint { point, distance_squared, triangle: t, feature });
                    }
                }
                continue;
            }
            let left = index + 1;
            let right = node.first;
            let left_distance = box_distance_squared(&self.nodes[left as usize], p);
            let right_distance = box_distance_squared(&self.nodes[right as usize], p);
            // The farther child below the nearer one, so the nearer is searched first; a child already beyond the
            // best distance is not pushed.
            let (near, far) = if left_distance <= right_distance {
                ((left, left_distance), (right, right_distance))
            } else {
                ((right, right_distance), (left, left_distance))
            };
            if far.1 < best_squared {
                stack[depth] = far;
                depth += 1;
            }
            if near.1 < best_squared {
                stack[depth] = near;
                depth += 1;
            }
        }
        best
    }

    /// The winding number of the mesh around `origin` counted along the ray `origin + t·direction`, `t > 0`: each
    /// triangle the ray crosses adds +1 where it leaves through the triangle's front (the ray along its normal) and
    /// −1 where it enters. For a closed, consistently oriented mesh this is the winding number whatever the
    /// direction: 1 inside, 0 outside (2 where two closed parts overlap). A ray through an edge or a vertex may count
    /// a crossing twice or not at all, and through a hole it misses the surface: callers compare several directions.
    pub fn ray_winding(&self, positions: &[DVec3], triangles: &[[u32; 3]], origin: DVec3, direction: DVec3) -> i64 {
        let inverse = direction.recip();
        let mut winding = 0;
        // Both children of a hit node are pushed: at most one pending sibling per level, as in `closest_point`.
        let mut stack = [0u32; MAX_DEPTH + 2];
        let mut depth = usize::from(ray_hits_box(&self.nodes[0], origin, inverse));
        while depth > 0 {
            depth -= 1;
            let node = &self.nodes[stack[depth] as usize];
            if node.count > 0 {
                let first = node.first as usize;
                for &t in &self.order[first..first + node.count as usize] {
                    let [a, b, c] = triangles[t as usize].map(|i| positions[i as usize]);
                    winding += ray_crossing(origin, direction, a, b, c);
                }
                continue;
            }
            for child in [stack[depth] + 1, node.first] {
                if ray_hits_box(&self.nodes[child as usize], origin, inverse) {
                    stack[depth] = child;
                    depth += 1;
                }
            }
        }
        winding
    }

    /// The nearest triangle the ray `origin + t·direction` meets with `0 < t < t_max`: its `t` (in units of
    /// `direction`'s length, so an unnormalised direction with a camera-space z of 1 gives depth along the optical
    /// axis) and its index, or `None`. Both faces count (Möller and Trumbore 1997). The search visits the nearer
    /// child box first and skips boxes that start beyond the nearest hit so far.
    pub fn first_hit(
        &self,
        positions: &[DVec3],
        triangles: &[[u32; 3]],
        origin: DVec3,
        direction: DVec3,
        t_max: f64,
    ) -> Option<(f64, u32)> {
        let inverse = direction.recip();
        let mut best: Option<(f64, u32)> = None;
        let mut limit = t_max;
        // Pending nodes with the ray's entry into their boxes; at most one pending sibling per level.
        let mut stack = [(0u32, 0.0f64); MAX_DEPTH + 2];
        let mut depth = 0;
        if let Some(near) = ray_box_entry(&self.nodes[0], origin, inverse, limit) {
            stack[0] = (0, near);
            depth = 1;
        }
        while depth > 0 {
            depth -= 1;
            let (index, near) = stack[depth];
            if near >= limit {
                continue;
            }
            let node = &self.nodes[index as usize];
            if node.count > 0 {
                let first = node.first as usize;
                for &t in &self.order[first..first + node.count as usize] {
                    let [a, b, c] = triangles[t as usize].map(|i| positions[i as usize]);
                    if let Some(hit) = ray_triangle(origin, direction, a, b, c) {
                        if hit < limit {
                            limit = hit;
                            best = Some((hit, t));
                        }
                    }
                }
                continue;
            }
            let left = index + 1;
            let right = node.first;
            let left_near = ray_box_entry(&self.nodes[left as usize], origin, inverse, limit);
            let right_near = ray_box_entry(&self.nodes[right as usize], origin, inverse, limit);
            let (near, far) = match (left_near, right_near) {
                (Some(l), Some(r)) if l <= r => (Some((left, l)), Some((right, r))),
                (Some(l), Some(r)) => (Some((right, r)), Some((left, l))),
                (Some(l), None) => (Some((left, l)), None),
                (None, r) => (r.map(|r| (right, r)), None),
            };
            for entry in [far, near].into_iter().flatten() {
                stack[depth] = entry;
                depth += 1;
            }
        }
        best
    }

    /// Depth of the hierarchy (root = 1).
    pub fn depth(&self) -> usize {
        fn depth_of(nodes: &[BvhNode], index: usize) -> usize {
            let node = &nodes[index];
            if node.count > 0 {
                1
            } else {
                1 + depth_of(nodes, index + 1).max(depth_of(nodes, node.first as usize))
            }
        }
        depth_of(&self.nodes, 0)
    }
}

/// Subtrees larger than this are built in parallel (rayon::join).
pub const PARALLEL_TRIANGLES: usize = 1 << 14;

/// Deepest the surface-area split may go before the build falls back to median splits (which halve the triangles),
/// so that the tree's depth, and the query's stack, stay bounded whatever the mesh.
pub const MAX_DEPTH: usize = 96;

/// Bins of the surface-area heuristic along the split axis.
const SAH_BINS: usize = 16;

struct Builder<'a> {
    positions: &'a [DVec3],
    triangles: &'a [[u32; 3]],
    centroids: &'a [DVec3],
}

impl Builder<'_> {
    /// The subtree over `order` (which starts at `offset` of the whole list), its nodes numbered from 0 in depth-first
    /// order (left child next to its parent, `first` of an inner node the right child's index).
    fn subtree(&self, order: &mut [u32], offset: usize, depth: usize) -> Vec<BvhNode> {
        let mut lower = DVec3::splat(f64::INFINITY);
        let mut upper = DVec3::splat(f64::NEG_INFINITY);
        let mut centre_lower = lower;
        let mut centre_upper = upper;
        for &t in order.iter() {
            for &i in &self.triangles[t as usize] {
                lower = lower.min(self.positions[i as usize]);
                upper = upper.max(self.positions[i as usize]);
            }
            centre_lower = centre_lower.min(self.centroids[t as usize]);
            centre_upper = centre_upper.max(self.centroids[t as usize]);
        }
        let root = BvhNode {
            lower: lower.to_array().map(|v| widen(v, true)),
            upper: upper.to_array().map(|v| widen(v, false)),
            first: offset as u32,
            count: order.len() as u32,
        };
        let extent = centre_upper - centre_lower;
        if order.len() <= LEAF_TRIANGLES || extent.max_element() <= 0.0 {
            return vec![root];
        }
        let axis = if extent.x >= extent.y && extent.x >= extent.z {
            0
        } else if extent.y >= extent.z {
            1
        } else {
            2
        };
        let centroids = self.centroids;
        let middle = match self.surface_area_split(order, axis, centre_lower[axis], extent[axis]) {
            // Past MAX_DEPTH − log₂(triangles), only median splits: the depth stays below MAX_DEPTH.
            Some(middle) if depth + (usize::BITS - order.len().leading_zeros()) as usize + 1 < MAX_DEPTH => middle,
            _ => {
                let middle = order.len() / 2;
                order.select_nth_unstable_by(middle, |&a, &b| {
                    centroids[a as usize][axis].total_cmp(&centroids[b as usize][axis])
                });
                middle
            }
        };
        let (left_order, right_order) = order.split_at_mut(middle);
        let (left, right) = if left_order.len() + right_order.len() > PARALLEL_TRIANGLES {
            rayon::join(
                || self.subtree(left_order, offset, depth + 1),
                || self.subtree(right_order, offset + middle, depth + 1),
            )
        } else {
            (self.subtree(left_order, offset, depth + 1), self.subtree(right_order, offset + middle, depth + 1))
        };
        let mut nodes = Vec::with_capacity(1 + left.len() + right.len());
        let right_index = 1 + left.len();
        nodes.push(BvhNode { first: right_index as u32, count: 0, ..root });
        for (shift, part) in [(1, left), (right_index, right)] {
            nodes.extend(part.into_iter().map(|node| {
                if node.count == 0 {
                    BvhNode { first: node.first + shift as u32, ..node }
                } else {
                    node
                }
            }));
        }
        nodes
    }
}

impl Builder<'_> {
    /// Partitions `order` at the binned surface-area-heuristic split along `axis` (centroids from `lower` over
    /// `extent`) and returns the split index, or `None` when every split leaves one side empty.
    fn surface_area_split(&self, order: &mut [u32], axis: usize, lower: f64, extent: f64) -> Option<usize> {
        let bin_of = |t: u32| {
            let f = (self.centroids[t as usize][axis] - lower) / extent;
            ((f * SAH_BINS as f64) as usize).min(SAH_BINS - 1)
        };
        let mut counts = [0usize; SAH_BINS];
        let mut boxes = [(DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)); SAH_BINS];
        for &t in order.iter() {
            let bin = bin_of(t);
            counts[bin] += 1;
            for &i in &self.triangles[t as usize] {
                boxes[bin].0 = boxes[bin].0.min(self.positions[i as usize]);
                boxes[bin].1 = boxes[bin].1.max(self.positions[i as usize]);
            }
        }
        let area = |(lo, hi): (DVec3, DVec3)| {
            let d = (hi - lo).max(DVec3::ZERO);
            d.x * d.y + d.y * d.z + d.z * d.x
        };
        let merge = |a: (DVec3, DVec3), b: (DVec3, DVec3)| (a.0.min(b.0), a.1.max(b.1));
        // Cost of splitting after bin k: area(left) · count(left) + area(right) · count(right).
        let mut right_cost = [0.0f64; SAH_BINS];
        let mut accumulated = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        let mut count = 0;
        for k in (1..SAH_BINS).rev() {
            accumulated = merge(accumulated, boxes[k]);
            count += counts[k];
            right_cost[k] = area(accumulated) * count as f64;
        }
        let mut best: Option<(f64, usize)> = None;
        let mut accumulated = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        let mut left_count = 0;
        for k in 0..SAH_BINS - 1 {
            accumulated = merge(accumulated, boxes[k]);
            left_count += counts[k];
            if left_count == 0 || left_count == order.len() {
                continue;
            }
            let cost = area(accumulated) * left_count as f64 + right_cost[k + 1];
            if best.is_none_or(|(c, _)| cost < c) {
                best = Some((cost, k));
            }
        }
        let (_, split_bin) = best?;
        // Partition in place: bins ≤ split_bin first.
        let mut middle = 0;
        for i in 0..order.len() {
            if bin_of(order[i]) <= split_bin {
                order.swap(i, middle);
                middle += 1;
            }
        }
        Some(middle)
    }
}

#[inline]
fn box_distance_squared(node: &BvhNode, p: DVec3) -> f64 {
    let mut sum = 0.0;
    for a in 0..3 {
        let lower = f64::from(node.lower[a]);
        let upper = f64::from(node.upper[a]);
        let d = (lower - p[a]).max(p[a] - upper).max(0.0);
        sum += d * d;
    }
    sum
}

/// Whether the ray `origin + t·direction` (`t ≥ 0`, `inverse` the direction's reciprocal) meets the node's box.
#[inline]
fn ray_hits_box(node: &BvhNode, origin: DVec3, inverse: DVec3) -> bool {
    let (mut near, mut far) = (0.0f64, f64::INFINITY);
    for a in 0..3 {
        let t0 = (f64::from(node.lower[a]) - origin[a]) * inverse[a];
        let t1 = (f64::from(node.upper[a]) - origin[a]) * inverse[a];
        near = near.max(t0.min(t1));
        far = far.min(t0.max(t1));
    }
    near <= far
}

/// Where the ray `origin + t·direction` (`inverse` the direction's reciprocal) enters the node's box, if it meets
/// the box for some `t` in `[0, t_max)`.
#[inline]
fn ray_box_entry(node: &BvhNode, origin: DVec3, inverse: DVec3, t_max: f64) -> Option<f64> {
    let (mut near, mut far) = (0.0f64, t_max);
    for a in 0..3 {
        let t0 = (f64::from(node.lower[a]) - origin[a]) * inverse[a];
        let t1 = (f64::from(node.upper[a]) - origin[a]) * inverse[a];
        near = near.max(t0.min(t1));
        far = far.min(t0.max(t1));
    }
    (near <= far).then_some(near)
}

/// The `t > 0` at which the ray `origin + t·direction` meets triangle `abc` (either face), or `None` (Möller and
/// Trumbore 1997).
#[inline]
pub fn ray_triangle(origin: DVec3, direction: DVec3, a: DVec3, b: DVec3, c: DVec3) -> Option<f64> {
    let (ab, ac) = (b - a, c - a);
    let pvec = direction.cross(ac);
    let det = ab.dot(pvec);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let inverse_det = 1.0 / det;
    let tvec = origin - a;
    let u = tvec.dot(pvec) * inverse_det;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let qvec = tvec.cross(ab);
    let v = direction.dot(qvec) * inverse_det;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = ac.dot(qvec) * inverse_det;
    (t > 0.0 && t.is_finite()).then_some(t)
}

/// +1 if the ray `origin + t·direction` (`t > 0`) leaves through triangle `abc`'s front, −1 if it enters through it,
/// 0 if it misses (Möller and Trumbore, "Fast, minimum storage ray/triangle intersection", 1997).
#[inline]
fn ray_crossing(origin: DVec3, direction: DVec3, a: DVec3, b: DVec3, c: DVec3) -> i64 {
    let (ab, ac) = (b - a, c - a);
    let pvec = direction.cross(ac);
    // det = −direction · (ab × ac): negative where the ray runs along the front normal.
    let det = ab.dot(pvec);
    if det == 0.0 || !det.is_finite() {
        return 0;
    }
    let tvec = origin - a;
    let u = tvec.dot(pvec) / det;
    if !(0.0..=1.0).contains(&u) {
        return 0;
    }
    let qvec = tvec.cross(ab);
    let v = direction.dot(qvec) / det;
    if v < 0.0 || u + v > 1.0 {
        return 0;
    }
    if ac.dot(qvec) / det <= 0.0 {
        return 0;
    }
    if det < 0.0 {
        1
    } else {
        -1
    }
}

/// The point of triangle `abc` closest to `p`, and the feature it lies on (Ericson §5.1.5, Voronoi regions).
pub fn closest_on_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> (DVec3, TriangleFeature) {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(ap);
    let d2 = ac.dot(ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return (a, TriangleFeature::Vertex(0));
    }
    let bp = p - b;
    let d3 = ab.dot(bp);
    let d4 = ac.dot(bp);
    if d3 >= 0.0 && d4 <= d3 {
        return (b, TriangleFeature::Vertex(1));
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (a + ab * v, TriangleFeature::Edge(0));
    }
    let cp = p - c;
    let d5 = ab.dot(cp);
    let d6 = ac.dot(cp);
    if d6 >= 0.0 && d5 <= d6 {
        return (c, TriangleFeature::Vertex(2));
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (a + ac * w, TriangleFeature::Edge(2));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (b + (c - b) * w, TriangleFeature::Edge(1));
    }
    let denominator = 1.0 / (va + vb + vc);
    let v = vb * denominator;
    let w = vc * denominator;
    (a + ab * v + ac * w, TriangleFeature::Face)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn random_triangles(count: usize, seed: u64) -> (Vec<DVec3>, Vec<[u32; 3]>) {
        let mut state = seed;
        let mut next = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut positions = Vec::new();
        for _ in 0..count {
            let centre = DVec3::new(next(), next(), next());
            for _ in 0..3 {
                positions.push(centre + DVec3::new(next(), next(), next()) * 0.05);
            }
        }
        (positions, (0..count as u32).map(|t| [3 * t, 3 * t + 1, 3 * t + 2]).collect())
    }

    #[test]
    fn closest_point_equals_brute_force() {
        let (positions, triangles) = random_triangles(500, 7);
        let bvh = TriangleBvh::build(&positions, &triangles);
        assert!(bvh.depth() <= MAX_DEPTH, "the depth is bounded: {}", bvh.depth());
        for i in 0..200 {
            let p = DVec3::new((i % 7) as f64 / 6.0, (i % 11) as f64 / 10.0, (i % 13) as f64 / 12.0) * 1.2
                - DVec3::splat(0.1);
            let brute = triangles
                .iter()
                .map(|t| t.map(|i| positions[i as usize]))
                .map(|[a, b, c]| (closest_on_triangle(p, a, b, c).0 - p).length_squared())
                .fold(f64::INFINITY, f64::min);
            let found = bvh.closest_point(&positions, &triangles, p, f64::INFINITY).unwrap();
            assert_eq!(found.distance_squared, brute, "at {p}");
            // A bound just above the distance still finds it; one below finds nothing.
            assert!(bvh.closest_point(&positions, &triangles, p, brute.sqrt() * 1.0001 + 1e-12).is_some());
            assert!(bvh.closest_point(&positions, &triangles, p, brute.sqrt() * 0.9999).is_none());
        }
    }

    #[test]
    fn a_tree_built_in_parallel_finds_the_same_closest_points() {
        let (positions, triangles) = random_triangles(3 * PARALLEL_TRIANGLES, 9);
        let bvh = TriangleBvh::build(&positions, &triangles);
        let mut seen = vec![false; triangles.len()];
        for &t in &bvh.order {
            seen[t as usize] = true;
        }
        assert!(seen.iter().all(|&s| s), "every triangle is in one leaf");
        for i in 0..40 {
            let p = DVec3::new((i % 5) as f64 / 4.0, (i % 3) as f64 / 2.0, (i % 7) as f64 / 6.0);
            let brute = triangles
                .iter()
                .map(|t| t.map(|i| positions[i as usize]))
                .map(|[a, b, c]| (closest_on_triangle(p, a, b, c).0 - p).length_squared())
                .fold(f64::INFINITY, f64::min);
            assert_eq!(bvh.closest_point(&positions, &triangles, p, f64::INFINITY).unwrap().distance_squared, brute);
        }
    }

    #[test]
    fn ray_winding_counts_a_tetrahedron_from_every_direction() {
        // An outward-facing tetrahedron: winding 1 inside, 0 outside, whatever the direction.
        let positions = vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z];
        let triangles = vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
        let bvh = TriangleBvh::build(&positions, &triangles);
        let directions = [DVec3::new(0.3, 0.5, 0.81), DVec3::new(-0.7, 0.2, -0.1), DVec3::new(0.1, -0.9, 0.35)];
        for direction in directions {
            let inside = bvh.ray_winding(&positions, &triangles, DVec3::splat(0.1), direction);
            assert_eq!(inside, 1, "inside along {direction}");
            let outside = bvh.ray_winding(&positions, &triangles, DVec3::new(0.6, 0.6, 0.6), direction);
            assert_eq!(outside, 0, "outside along {direction}");
            let below = bvh.ray_winding(&positions, &triangles, DVec3::new(0.2, 0.2, -1.0), direction);
            assert_eq!(below, 0, "below along {direction}");
        }
        // Entering and leaving: from below along +z crosses the base (−1) and the slanted face (+1).
        assert_eq!(bvh.ray_winding(&positions, &triangles, DVec3::new(0.2, 0.2, -1.0), DVec3::new(0.01, 0.02, 1.0)), 0);
    }

    #[test]
    fn first_hit_equals_brute_force() {
        let (positions, triangles) = random_triangles(4000, 11);
        let bvh = TriangleBvh::build(&positions, &triangles);
        let mut state = 3u64;
        let mut next = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut hits = 0;
        for i in 0..400 {
            // Origins around and inside the cloud, directions towards a random point of it (some rays miss).
            let origin = DVec3::new(next(), next(), next()) * 2.0 - DVec3::splat(0.5);
            let target = DVec3::new(next(), next(), next());
            let direction = (target - origin) * (0.5 + next());
            let t_max = if i % 5 == 0 { 0.5 } else { f64::INFINITY };
            let brute = triangles
                .iter()
                .enumerate()
                .filter_map(|(t, tri)| {
                    let [a, b, c] = tri.map(|i| positions[i as usize]);
                    ray_triangle(origin, direction, a, b, c).filter(|&hit| hit < t_max).map(|hit| (hit, t as u32))
                })
                .min_by(|x, y| x.0.total_cmp(&y.0));
            let found = bvh.first_hit(&positions, &triangles, origin, direction, t_max);
            assert_eq!(found, brute, "ray {i} from {origin} along {direction}");
            hits += usize::from(found.is_some());
        }
        assert!(hits > 100 && hits < 400, "both hits and misses are tested: {hits} hits");
        // A known triangle: z = 1 plane hit from the origin along (0.1, 0.1, 2) at t = 0.5, from either side.
        let positions = vec![DVec3::new(-1.0, -1.0, 1.0), DVec3::new(1.0, -1.0, 1.0), DVec3::new(0.0, 1.0, 1.0)];
        let bvh = TriangleBvh::build(&positions, &[[0, 1, 2]]);
        let hit = bvh.first_hit(&positions, &[[0, 1, 2]], DVec3::ZERO, DVec3::new(0.1, 0.1, 2.0), 10.0).unwrap();
        assert!((hit.0 - 0.5).abs() < 1e-15 && hit.1 == 0, "{hit:?}");
        let back = bvh.first_hit(&positions, &[[0, 1, 2]], DVec3::new(0.0, 0.0, 3.0), DVec3::NEG_Z, 10.0);
        assert_eq!(back, Some((2.0, 0)));
        assert_eq!(bvh.first_hit(&positions, &[[0, 1, 2]], DVec3::ZERO, DVec3::Z, 0.99), None, "beyond t_max");
        assert_eq!(bvh.first_hit(&positions, &[[0, 1, 2]], DVec3::ZERO, DVec3::NEG_Z, 10.0), None, "behind");
    }

    #[test]
    fn features_are_classified() {
        let (a, b, c) = (DVec3::ZERO, DVec3::X, DVec3::Y);
        let (point, feature) = closest_on_triangle(DVec3::new(0.2, 0.2, 1.0), a, b, c);
        assert!((point - DVec3::new(0.2, 0.2, 0.0)).length() < 1e-15);
        assert_eq!(feature, TriangleFeature::Face);
        assert_eq!(closest_on_triangle(DVec3::new(-1.0, -1.0, 0.0), a, b, c).1, TriangleFeature::Vertex(0));
        assert_eq!(closest_on_triangle(DVec3::new(2.0, -0.1, 0.0), a, b, c).1, TriangleFeature::Vertex(1));
        assert_eq!(closest_on_triangle(DVec3::new(0.5, -1.0, 0.0), a, b, c).1, TriangleFeature::Edge(0));
        assert_eq!(closest_on_triangle(DVec3::new(1.0, 1.0, 0.3), a, b, c).1, TriangleFeature::Edge(1));
        assert_eq!(closest_on_triangle(DVec3::new(-1.0, 0.5, 0.0), a, b, c).1, TriangleFeature::Edge(2));
    }
}
