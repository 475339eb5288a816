//! A ray's walk from segment to segment (steps 1, 3 and 5 of [`super`]'s walk): where the ray enters the volume,
//! the node box each descent finds, constant nodes and whole spans handed to the integrand, and for brick segments
//! the samples' step (the cone's footprint, GigaVoxels [P09] §6) and the weights that blend them with the coarser
//! level (Thiele et al.'s caps). [`Traversal::next_march`] is the iterator: each call returns the next brick segment
//! to sample, so that it can be driven alone, as pbrt's majorant iterator.

use std::ops::ControlFlow;

use glam::DVec3;
use voxstream_core::{BrickBlend, Request};

use super::boxes::{exit_distance, intersect_aabb};
use super::bricks::{Blend, WeightRamp};
use super::descent::{BrickRef, DescentPath, RequestSink, SegmentData};
use super::{Ray, RayStats, Traversal, MAX_SEGMENTS};
use crate::clip_plane::clip_to_planes;
use crate::integrand::Integrand;
use crate::step_table::StepLength;

impl<'a> Traversal<'a> {
    /// Starts `ray`: counts it, clips it to the volume (`None` when it misses) and starts `path` for it
    /// ([`DescentPath::start_ray`]).
    #[inline(always)]
    pub(super) fn begin(&self, ray: &Ray, stats: &mut RayStats, path: &mut DescentPath) -> Option<RayWalk> {
        stats.rays += 1;
        let mut interval = intersect_aabb(ray.origin, ray.direction, self.clip_lower, self.clip_upper)?;
        if !self.clip_planes.is_empty() {
            interval = clip_to_planes(ray.origin, ray.direction, interval, &self.clip_planes)?;
        }
        let (t_enter, t_leave) = interval;
        let t = t_enter.max(ray.start);
        // Kept nodes are found again exactly only where an ancestor's coordinates are the point's shifted (N a
        // power of two); with N = 3 a point within a rounding of a node's face could keep a neighbour's node where
        // the descent from the root clamps into the other (see `descend`).
        path.start_ray(self.view, self.n_shift.is_some());
        if let Some(slot) = path.entries[0].node.brick() {
            self.feedback.mark_brick(slot);
        }
        Some(RayWalk {
            ray: *ray,
            speed: ray.direction.length(),
            inverse_direction: DVec3::ONE / ray.direction,
            t,
            t_leave,
            covered: t,
            step: None,
            after_bricks: false,
            segments: 0,
            level_hint: 0,
            requests_left: self.max_requests_per_ray,
            requested: false,
        })
    }

    /// Walks on from `walk.t` to the next brick segment whose samples must be taken, and returns it; constant
    /// nodes, skipped segments and whole-span segments are handed to the integrand on the way. `None` when the ray
    /// has left the volume or the integrand stopped it.
    #[inline(always)]
    pub(super) fn next_march<I: Integrand>(
        &self,
        walk: &mut RayWalk,
        integrand: &mut I,
        stats: &mut RayStats,
        requests: &mut Vec<Request>,
        path: &mut DescentPath,
    ) -> Option<March> {
        let ray = &walk.ray;
        let (origin, direction, speed) = (ray.origin, ray.direction, walk.speed);
        while walk.t < walk.t_leave && walk.segments < MAX_SEGMENTS {
            let t = walk.t;
            walk.segments += 1;
            stats.descents += 1;
            let p = origin + direction * t;
            let (footprint_voxel, target_level) = self.footprint_at(t, ray.spread, &mut walk.level_hint);
            let mut sink = RequestSink { requests, remaining: walk.requests_left, pushed: false };
            // Find the node a hair ahead of `t` (well above the rounding of p, far below any node): where the last
            // segment ended on a node's face, the node the ray enters, not the one it leaves. (Looked up at `p`,
            // a face the ray leaves through towards lower coordinates rounds into the node left behind, and the
            // ray would take one more descent for an empty sliver: two fifths of all descents on the MNI head.)
            let probe = origin + direction * (t + sliver(self.finest_node, p, t, speed));
            let (data, box_level, box_ijk) =
                self.descend(probe, target_level, path, &mut sink, integrand, &mut stats.nodes_entered);
            walk.requests_left = sink.remaining;
            walk.requested |= sink.pushed;
            let node_size = 1.0 / self.scale[box_level as usize];
            // Node coordinates are below 2⁶³: through `i64`, one instruction each (a `u64` conversion is several).
            let lower = DVec3::from_array(box_ijk.map(|v| v as i64 as f64)) * node_size;
            let t_exit = exit_distance(origin, walk.inverse_direction, lower, node_size).min(walk.t_leave);
            // Never stall on a boundary: move at least a sliver of the node.
            let t_exit = t_exit.max(t + sliver(node_size, p, t, speed));
            walk.t = t_exit;
            let flow = match data {
                SegmentData::Nothing => {
                    walk.covered = walk.covered.max(t_exit);
                    walk.after_bricks = false;
                    integrand.gap()
                }
                SegmentData::Constant(value) => {
                    walk.after_bricks = false;
                    integrand.set_level(box_level);
                    // Integrated over exactly the distance not yet accounted for.
                    let from = walk.covered;
                    walk.covered = walk.covered.max(t_exit);
                    if from < t_exit {
                        stats.samples += 1;
                        integrand.constant(from, t_exit, value)
                    } else {
                        ControlFlow::Continue(())
                    }
                }
                SegmentData::Bricks { fine, stand_in, .. } if I::TAKES_SPANS => {
                    // The whole segment at the fine brick's level: no level blending (the integrand closes the
                    // seams where the level changes).
                    walk.covered = walk.covered.max(t_exit);
                    walk.after_bricks = true;
                    let skip = self.skip_empty_space && {
                        let [lo, hi] = self.view.brick_range(fine.slot);
                        !integrand.can_contribute(lo, hi)
                    };
                    // The step the bricks' branch below would take (for integrands that sample a volume too).
                    let step = self.level_voxel[self.sampled_level(&fine, stand_in) as usize].max(footprint_voxel)
                        * self.step_factor
                        / speed;
                    if skip {
                        integrand.skip_span(t, t_exit, step);
                        ControlFlow::Continue(())
                    } else {
                        integrand.span(&self.brick_span(ray, &fine, t, t_exit, step), &mut stats.samples)
                    }
                }
                SegmentData::Bricks { fine, coarse, blend_level, stand_in } => {
                    // Step by the cone's footprint (the voxel of the continuous level ℓ), or by the sampled voxel
                    // where the data is coarser: a quadrilinear sample is filtered at the footprint, so finer steps
                    // would only re-sample the same filtered signal (GigaVoxels [P09] §6, cone tracing).
                    // With `steps_ignore_stand_ins`, a stand-in is stepped as the data it stands in for will be, down
                    // to `stand_in_levels` levels below it (a bound on the extra samples where the wanted data is
                    // still far from resident, e.g. during a fast zoom).
                    let sampled_voxel = self.level_voxel[self.sampled_level(&fine, stand_in) as usize];
                    integrand.set_level(fine.level);
                    let front_edge = std::mem::replace(&mut walk.after_bricks, true);
                    let blend = coarse.and(self.view.brick_blends.get(fine.slot.0 as usize)).filter(|b| !b.is_full());
                    let mut desired_step = sampled_voxel.max(footprint_voxel) * self.step_factor / speed;
                    // The cone's level weight (1 where only coarser data exists).
                    let cone = match coarse {
                        Some(c) if blend_level => {
                            let footprint = self.footprint(0.5 * (t + t_exit), ray.spread);
                            // At least the fine level there (the usual case): the weight is 1 without the
                            // logarithm.
                            if footprint <= self.footprint_within_level[c.level as usize + 1] {
                                1.0
                            } else {
                                (self.level_of_footprint(footprint) - c.level as f64).clamp(0.0, 1.0) as f32
                            }
                        }
                        _ => 1.0,
                    };
                    if integrand.adapts_step() {
                        // Every sample's value lies in the fine brick's range, or, where the coarse brick is blended
                        // in, between it and the coarse one's.
                        let [mut lo, mut hi] = self.view.brick_range(fine.slot);
                        if let Some(c) = coarse.filter(|_| cone < 1.0 || blend.is_some()) {
                            let [c_lo, c_hi] = self.view.brick_range(c.slot);
                            (lo, hi) = (lo.min(c_lo), hi.max(c_hi));
                        }
                        desired_step = integrand.adapt_step(lo, hi, desired_step);
                    }
                    let segment_step = StepLength::keep_or_at_most(walk.step, desired_step);
                    if walk.step != Some(segment_step) {
                        walk.step = Some(segment_step);
                        integrand.set_step(segment_step);
                    }
                    let dt = segment_step.world;
                    // Each sample stands for the step around it: samples continue where the last one's step ended
                    // (exact where the step changes), and those before the node's exit belong to this segment.
                    let first = walk.covered + 0.5 * dt;
                    let count = if first < t_exit { ((t_exit - first) / dt).ceil().max(1.0) as u64 } else { 0 };
                    walk.covered += count as f64 * dt;
                    if count == 0 {
                        ControlFlow::Continue(())
                    } else {
                        let coarse = coarse.and_then(|c| {
                            // The cone's level weight, capped by the fine brick's blending caps (Thiele et al.: fade-in, coarser neighbours) at the first and the last
                            // sample, and ramped linearly between them.
                            let (cap_first, cap_last) = match blend {
                                Some(blend) => {
                                    let last = first + (count - 1) as f64 * dt;
                                    (self.cap_at(ray, &fine, blend, first), self.cap_at(ray, &fine, blend, last))
                                }
                                None => (1.0, 1.0),
                            };
                            let value = WeightRamp::between(cone.min(cap_first), cone.min(cap_last), count);
                            // Normals blend by the caps alone (the cone's blend keeps the fine brick's normals, as
                            // without blending), so that they are continuous when a transition ends.
                            let gradient = blend.map(|_| WeightRamp::between(cap_first, cap_last, count));
                            (!value.is_fine() || gradient.is_some()).then_some((c, Blend { value, gradient }))
                        });
                        return Some(March { fine, coarse, first, dt, count, front_edge });
                    }
                }
            };
            if flow.is_break() {
                return None;
            }
        }
        None
    }

    /// The level whose voxel sets the step in the bricks of `fine`: its own, or with `steps_ignore_stand_ins`, for a
    /// stand-in, the level it stands in for (at most `stand_in_levels` below it).
    #[inline]
    pub(super) fn sampled_level(&self, fine: &BrickRef, stand_in: bool) -> u32 {
        if stand_in && self.steps_ignore_stand_ins {
            (fine.level + self.stand_in_levels).min(self.view.shape.max_level)
        } else {
            fine.level
        }
    }

    /// The blending cap of `fine` (interpolated between its corners) where the ray is at `t`.
    #[inline]
    pub(super) fn cap_at(&self, ray: &Ray, fine: &BrickRef, blend: &BrickBlend, t: f64) -> f32 {
        let s = self.scale[fine.level as usize];
        let p = ray.origin + ray.direction * t;
        let (pa, ijk) = (p.to_array(), fine.ijk);
        blend.at(std::array::from_fn(|a| (pa[a] * s - ijk[a] as i64 as f64) as f32))
    }
}

/// One ray on its way through the tree, between segments: what [`Traversal::next_march`] needs to go on.
#[derive(Clone, Copy, Debug)]
pub(super) struct RayWalk {
    pub(super) ray: Ray,
    /// Volume units travelled per unit of `t`.
    pub(super) speed: f64,
    pub(super) inverse_direction: DVec3,
    /// Where the next segment starts.
    pub(super) t: f64,
    /// Where the ray leaves the (clipped) volume.
    pub(super) t_leave: f64,
    /// The distance up to which samples have accounted for the ray.
    pub(super) covered: f64,
    /// The current step (None before the first brick segment).
    pub(super) step: Option<StepLength>,
    /// Whether the last segment was a brick segment (its samples taken or skipped).
    pub(super) after_bricks: bool,
    pub(super) segments: u32,
    /// The previous segment's level of detail (where [`Traversal::footprint_at`] starts its search).
    pub(super) level_hint: usize,
    /// Requests this ray may still make this pass.
    pub(super) requests_left: u32,
    /// Whether it made any (its pixel must be traced again).
    pub(super) requested: bool,
}

/// The samples of one brick segment: `count` points `first + k·dt` in `fine`, blended with `coarse` when given.
#[derive(Clone, Copy, Debug)]
pub(super) struct March {
    pub(super) fine: BrickRef,
    pub(super) coarse: Option<(BrickRef, Blend)>,
    pub(super) first: f64,
    pub(super) dt: f64,
    pub(super) count: u64,
    /// Whether the segment before was a brick segment too, so that the sample one step before this one's first
    /// lies in data ([`Integrand::edge`]).
    pub(super) front_edge: bool,
}

/// A distance along the ray (moving at `speed` volume units per unit of `t`) of `1e-7` of a node of edge
/// `node_size`, plus more than the rounding of the point `p` at `t`: far below any node, well above rounding.
#[inline]
pub(super) fn sliver(node_size: f64, p: DVec3, t: f64, speed: f64) -> f64 {
    (node_size * 1e-7 + 8e-16 * p.abs().max_element()) / speed + 8e-16 * t
}

#[cfg(test)]
mod tests {
    use super::super::test_tree::{ray, Child, Record, TestTree};
    use super::*;
    use crate::settings::RenderSettings;

    /// The segment iterator driven alone: each call hands out the next brick segment, whose samples start where the
    /// last segment's ended, stand for one step each, and have their centres inside the segment's node box.
    #[test]
    fn brick_segments_tile_the_ray_from_entry_to_exit() {
        let tree = TestTree::new(|p| 0.5 * p.x, |p| 0.25 + 0.5 * p.y, [Child::Brick; 8]);
        let feedback = tree.feedback();
        let traversal = tree.traversal(&feedback, &RenderSettings::default());
        // Across x = 0.5, y = 0.5 and z = 0.5: four children.
        let ray = ray([-0.5, 0.2, 0.3], [1.0, 0.35, 0.25]);
        let (t_enter, t_leave) = intersect_aabb(ray.origin, ray.direction, DVec3::ZERO, DVec3::ONE).unwrap();
        let (mut stats, mut requests, mut path) = (RayStats::default(), Vec::new(), DescentPath::new(tree.view()));
        let mut integrand = Record::default();
        let mut walk = traversal.begin(&ray, &mut stats, &mut path).expect("the ray hits the volume");
        let (mut covered, mut segments, mut segment_start) = (t_enter, 0, walk.t);
        while let Some(march) = traversal.next_march(&mut walk, &mut integrand, &mut stats, &mut requests, &mut path) {
            let (first, dt, count) = (march.first, march.dt, march.count);
            assert!(count > 0 && dt > 0.0);
            assert!((first - 0.5 * dt - covered).abs() < 1e-12, "segment {segments} starts where the last ended");
            let last = first + (count - 1) as f64 * dt;
            assert!(first >= segment_start - 1e-12 && last < walk.t, "sample centres lie in the node box");
            assert!(last + dt >= walk.t, "the samples reach the box's exit");
            assert_eq!(march.fine.level, 1, "the finest level everywhere");
            assert!(march.coarse.is_none(), "no level blending where the cone is at the finest level");
            covered = first + (count as f64 - 0.5) * dt;
            segment_start = walk.t;
            segments += 1;
        }
        assert_eq!(segments, 4);
        assert_eq!(stats.descents, 4);
        assert!(covered >= t_leave - 1e-12 && covered < t_leave + 0.1, "samples cover the ray to the exit");
        assert!(requests.is_empty(), "everything is resident");
    }

    /// A constant node is integrated over exactly the distance the samples before it left, and samples after it
    /// start where it ended.
    #[test]
    fn constant_segments_abut_the_samples_around_them() {
        let mut children = [Child::Brick; 8];
        children[0] = Child::Constant(0.3);
        let tree = TestTree::new(|_| 0.1, |p| p.x, children);
        let feedback = tree.feedback();
        let traversal = tree.traversal(&feedback, &RenderSettings::default());
        for (origin, direction) in [([-0.5, 0.25, 0.25], [1.0, 0.0, 0.0]), ([1.5, 0.25, 0.25], [-1.0, 0.01, 0.02])] {
            let ray = ray(origin, direction);
            let (t_enter, t_leave) = intersect_aabb(ray.origin, ray.direction, DVec3::ZERO, DVec3::ONE).unwrap();
            let mut record = Record::default();
            let mut path = DescentPath::new(tree.view());
            traversal.trace(&ray, &mut record, &mut RayStats::default(), &mut Vec::new(), &mut path);
            assert_eq!(record.constants.len(), 1);
            let (from, to, value) = record.constants[0];
            assert_eq!(value, 0.3);
            // Pieces in order of distance: each sample stands for its step around it.
            let mut pieces: Vec<(f64, f64)> =
                record.samples.iter().map(|&(t, _, dt)| (t - 0.5 * dt, t + 0.5 * dt)).collect();
            pieces.push((from, to));
            pieces.sort_by(|a, b| a.0.total_cmp(&b.0));
            assert!((pieces[0].0 - t_enter).abs() < 1e-12, "the first piece starts at the entry");
            for pair in pieces.windows(2) {
                assert!((pair[1].0 - pair[0].1).abs() < 1e-12, "pieces abut: {:?} then {:?}", pair[0], pair[1]);
            }
            assert!(pieces.last().unwrap().1 >= t_leave - 1e-12);
            assert!((to - from - 0.5).abs() < 0.05, "the constant child is half the volume's width along the ray");
        }
    }
}
