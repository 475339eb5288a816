//! The adaptive smoothing length's rule over positions that repeat: the distance at which a particle's neighbours,
//! counted with their multiplicities, reach [`SMOOTHING_NEIGHBOURS`] (Reichl, seed 004, ch. 5: kernels adapted to the
//! local spacing). Shared by the in-memory producer (every particle at once) and the out-of-core one (a superbrick and
//! the particles around it at a time).
//!
//! The k-d tree (`kiddo`) is built over *distinct* positions, each with the number of particles it stands for: a tree
//! over many copies of one point cannot split them, and every query then scanned them all (50,000 identical points
//! took a minute, a million hours; out of core a million copies ran past five minutes). The `k` nearest particles
//! (the particle itself included) lie among the `k` nearest distinct positions, so counting multiplicities along the
//! distinct neighbours gives the same distance as a tree over every copy.

use std::num::NonZero;

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;

use crate::particle_producer::SMOOTHING_NEIGHBOURS;

/// Positions with their multiplicities, exact copies folded together.
#[derive(Debug, Default)]
pub(crate) struct DistinctPositions {
    /// Each distinct position once (in the order of their bits).
    pub positions: Vec<[f64; 3]>,
    /// How many particles each stands for.
    pub multiplicity: Vec<u64>,
    /// For every input position, the index of its distinct position.
    pub of: Vec<u32>,
}

impl DistinctPositions {
    /// Folds exact copies among the `count` positions `position(i)` (each standing for `multiplicity(i)` particles)
    /// together. At most 2³² positions.
    pub fn new(
        count: usize,
        position: impl Fn(usize) -> [f64; 3] + Sync,
        multiplicity: impl Fn(usize) -> u64,
    ) -> DistinctPositions {
        let mut order: Vec<u32> = (0..count as u32).collect();
        // `+ 0.0` makes −0 and +0 one position.
        let bits = |i: u32| position(i as usize).map(|c| (c + 0.0).to_bits());
        order.par_sort_unstable_by_key(|&i| bits(i));
        let mut distinct = DistinctPositions { of: vec![0; count], ..DistinctPositions::default() };
        for (n, &i) in order.iter().enumerate() {
            if n == 0 || bits(i) != bits(order[n - 1]) {
                distinct.positions.push(position(i as usize));
                distinct.multiplicity.push(0);
            }
            if let Some(last) = distinct.multiplicity.last_mut() {
                *last += multiplicity(i as usize);
            }
            distinct.of[i as usize] = distinct.positions.len() as u32 - 1;
        }
        distinct
    }

    /// The particles the positions stand for.
    pub fn particles(&self) -> u64 {
        self.multiplicity.iter().sum()
    }

    /// For each distinct position `queries[q]`, twice the distance at which the particles nearest it, counted with
    /// their multiplicities (its own included), reach `SMOOTHING_NEIGHBOURS + 1` or, with fewer particles, all of
    /// them: the adaptive support before it is clamped.
    pub fn neighbour_reach(&self, queries: &[u32]) -> Vec<f64> {
        let particles = self.particles();
        if self.positions.is_empty() {
            return vec![0.0; queries.len()];
        }
        let tree: ImmutableKdTree<f64, 3> = ImmutableKdTree::new_from_slice(&self.positions);
        let k = ((SMOOTHING_NEIGHBOURS + 1) as u64).min(particles).max(1);
        let wanted = NonZero::new((k as usize).min(self.positions.len())).unwrap_or(NonZero::<usize>::MIN);
        queries
            .par_iter()
            .map(|&d| {
                let mut nearest = tree.nearest_n::<SquaredEuclidean>(&self.positions[d as usize], wanted);
                nearest.sort_by(|a, b| a.distance.total_cmp(&b.distance));
                let mut counted = 0u64;
                let mut farthest = 0.0f64;
                for n in &nearest {
                    farthest = n.distance;
                    counted += self.multiplicity[n.item as usize];
                    if counted >= k {
                        break;
                    }
                }
                2.0 * farthest.sqrt()
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The reach over distinct positions with multiplicities equals the brute-force rule over every copy.
    #[test]
    fn the_reach_over_distinct_positions_is_the_reach_over_every_copy() {
        let mut state = 5u64;
        let mut next = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        // 40 random points, some repeated up to 12 times.
        let mut points: Vec<[f64; 3]> = Vec::new();
        for i in 0..40 {
            let p = [next(), next(), next()];
            for _ in 0..(1 + (i * 7) % 13) {
                points.push(p);
            }
        }
        let distinct = DistinctPositions::new(points.len(), |i| points[i], |_| 1);
        assert_eq!(distinct.positions.len(), 40);
        assert_eq!(distinct.particles(), points.len() as u64);
        let queries: Vec<u32> = (0..40).collect();
        let reach = distinct.neighbour_reach(&queries);
        for (i, p) in points.iter().enumerate() {
            let mut distances: Vec<f64> =
                points.iter().map(|q| (0..3).map(|a| (p[a] - q[a]).powi(2)).sum::<f64>().sqrt()).collect();
            distances.sort_by(f64::total_cmp);
            let brute = 2.0 * distances[SMOOTHING_NEIGHBOURS];
            let got = reach[distinct.of[i] as usize];
            assert!((got - brute).abs() < 1e-12, "point {i}: {got} vs {brute}");
        }
        // Folded records count as their multiplicity: one position standing for nine particles reaches 0.
        let folded = DistinctPositions::new(2, |i| [[0.5; 3], [0.9; 3]][i], |i| if i == 0 { 9 } else { 1 });
        let reach = folded.neighbour_reach(&[0, 1]);
        assert_eq!(reach[0], 0.0);
        assert!((reach[1] - 2.0 * (3.0f64 * 0.16).sqrt()).abs() < 1e-12, "{reach:?}");
        // Fewer particles than neighbours: the farthest of them.
        let few = DistinctPositions::new(2, |i| [[0.0; 3], [0.0, 0.0, 0.25]][i], |_| 1);
        assert_eq!(few.neighbour_reach(&[0]), vec![0.5]);
    }
}
