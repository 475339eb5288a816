//! Many rays side by side (Knoll et al.'s packets, seed 002 §4, as a stream): [`LANES`] rays walk the tree each on
//! its own, exactly as one ray does, and their samples are taken together, one per lane per step.

use voxstream_core::{Dequantize, PoolVoxels, Request, Voxel};

use super::bricks::BrickLine;
use super::descent::DescentPath;
use super::segments::{March, RayWalk};
use super::{Ray, RaySource, RayStats, Traversal};
use crate::gathered_corners::CornerGather;
use crate::integrand::{Integrand, Sample};
use crate::sampler::{values_across, values_and_gradients_across, LANES};

/// In a lane of [`Traversal::trace_stream`] whose runs come from the blocks' range tests (integrands without block
/// bits), a run of samples is extended through the following blocks that can contribute until it is this long, so
/// that the lanes' runs (the shortest of which ends a burst) are long. One ray alone extends none: checking blocks
/// ahead costs more than it saves where rays turn opaque within a few samples (the sponge: about 2 samples per ray).
/// Runs read from block bits are as long as the blocks allow ([`Traversal::visible_run`]).
pub(super) const LONG_RUN: u32 = 4 * LANES as u32;

/// Steps of a burst sampled across the lanes before the lanes' integrands take them.
pub(super) const BURST_CHUNK: usize = 16;

/// The fewest steps of a burst while some lane has that many samples left in its run: lanes whose run is shorter
/// sample on past its end (positions stay clamped in their brick, so the reads are harmless) and their integrands
/// take only the run's samples. A burst ending with the shortest run made a round of refills every 4 to 8 steps;
/// refills cost more than the idle lanes' samples (measured: 1.03–1.09× on the peers' scenes, the same bytes).
pub(super) const MIN_BURST: u32 = 16;

impl<'a> Traversal<'a> {
    /// Traces the rays `next_ray` hands out ([`RaySource`]), [`LANES`] side by side (Knoll et al.'s packets, seed
    /// 002 §4, as a stream): each lane walks its own ray exactly as [`Traversal::trace`] does (same descents,
    /// segments, steps, skipped blocks and samples, so the same bits), but the samples of all lanes are taken
    /// together, one per lane per step, by [`values_across`], each lane in its own brick. A lane whose ray ends
    /// takes the next ray at once, so the lanes stay full until the rays run out; rays therefore finish out of
    /// order, and `finish` gets each one's id, integrand and whether it made requests. Segments that blend levels or
    /// need gradients are marched by their lane alone ([`Traversal::march_bricks`]); span integrands
    /// ([`Integrand::TAKES_SPANS`]) take the whole path of `trace` (one lane at a time). Always inlined, like
    /// `trace`.
    ///
    /// With `GRADIENT`, the lanes take gradients too (for shaded integrands); without, segments of integrands that
    /// want gradients are marched alone.
    #[inline(always)]
    pub fn trace_stream<I: Integrand, const GRADIENT: bool>(
        &self,
        next_ray: impl RaySource<I>,
        finish: impl FnMut(usize, &I, bool),
        stats: &mut RayStats,
        requests: &mut Vec<Request>,
        paths: &mut [DescentPath; LANES],
    ) {
        // One loop per voxel width, chosen once.
        match self.view.voxels {
            PoolVoxels::Wide(voxels) => {
                self.trace_stream_in::<_, _, GRADIENT>(voxels, next_ray, finish, stats, requests, paths)
            }
            PoolVoxels::Narrow(voxels) => {
                self.trace_stream_in::<_, _, GRADIENT>(voxels, next_ray, finish, stats, requests, paths)
            }
        }
    }

    /// [`Traversal::trace_stream`] over the pool's voxels.
    #[inline(always)]
    pub(super) fn trace_stream_in<V: Voxel, I: Integrand, const GRADIENT: bool>(
        &self,
        voxels: &[V],
        mut next_ray: impl RaySource<I>,
        mut finish: impl FnMut(usize, &I, bool),
        stats: &mut RayStats,
        requests: &mut Vec<Request>,
        paths: &mut [DescentPath; LANES],
    ) {
        let b = self.stored;
        let per_brick = self.view.shape.voxels_per_brick();
        let gather = self.gather;
        let mut lanes: [Option<Lane<'a, I>>; LANES] = std::array::from_fn(|_| None);
        let mut exhausted = false;
        // The busy lanes' lines, lane by lane (what `values_across` reads).
        let mut bases = [0u32; LANES];
        let mut start = [[0f32; LANES]; 3];
        let mut delta = [[0f32; LANES]; 3];
        let mut kf = [0f32; LANES];
        // One chunk of a burst's samples, step by step, lane by lane.
        let mut chunk_values = [[0f32; LANES]; BURST_CHUNK];
        let mut chunk_gradients = [[[0f32; 3]; LANES]; BURST_CHUNK];
        loop {
            // Every lane gets samples to take: the rest of its run, the next run of its segment, the next segment
            // of its ray, or a new ray.
            let mut burst = u32::MAX;
            let mut longest = 0u32;
            for (j, (lane, path)) in lanes.iter_mut().zip(paths.iter_mut()).enumerate() {
                let mut sources =
                    LaneSources { next_ray: &mut next_ray, finish: &mut finish, exhausted: &mut exhausted };
                if let Some(run) = self.fill_lane(lane, path, &mut sources, GRADIENT, stats, requests) {
                    bases[j] = (run.line.slot.0 as usize * per_brick) as u32;
                    for a in 0..3 {
                        start[a][j] = run.line.start[a];
                        delta[a][j] = run.line.delta[a];
                    }
                    kf[j] = run.k as f32;
                    burst = burst.min(run.end - run.k);
                    longest = longest.max(run.end - run.k);
                }
            }
            if burst == u32::MAX {
                return;
            }
            let burst = burst.max(MIN_BURST.min(longest));
            // Until the burst ends, no lane needs a check: samples only. They are taken across the lanes a chunk of
            // steps at a time, then each lane's integrand takes its own, up to its run's end, in one loop (its state
            // stays in registers, and no step asks every lane whether it is busy).
            let mut taken = 0u64;
            let dq = self.dequantize;
            let mut left = burst;
            while left > 0 {
                let steps = left.min(BURST_CHUNK as u32) as usize;
                left -= steps as u32;
                for step in 0..steps {
                    let (values, gradients) =
                        samples_across::<_, GRADIENT>(voxels, b, &bases, &start, &delta, &kf, dq, gather);
                    chunk_values[step] = values;
                    if GRADIENT {
                        chunk_gradients[step] = gradients;
                    }
                    for k in &mut kf {
                        *k += 1.0;
                    }
                }
                for (j, slot) in lanes.iter_mut().enumerate() {
                    let Some(lane) = slot else { continue };
                    let Some(run) = &mut lane.run else { continue };
                    for step in 0..steps.min((run.end - run.k) as usize) {
                        let gradient = if GRADIENT { chunk_gradients[step][j] } else { [0.0; 3] };
                        let sample =
                            Sample { t: run.first + run.k as f64 * run.dt, value: chunk_values[step][j], gradient };
                        run.k += 1;
                        taken += 1;
                        if lane.integrand.sample(sample).is_break() {
                            finish(lane.id, &lane.integrand, lane.walk.requested);
                            *slot = None;
                            break;
                        }
                    }
                }
            }
            stats.samples += taken;
        }
    }

    /// Gives `slot` samples to take: the rest of its run, else the next run of its segment, else the next segment
    /// of its ray (segments that cannot go in a lane are marched here), else a new ray; finishes the rays that end
    /// on the way. Returns the lane's run, or `None` once the rays have run out.
    #[inline(always)]
    pub(super) fn fill_lane<'l, I: Integrand, N, F>(
        &self,
        slot: &'l mut Option<Lane<'a, I>>,
        path: &mut DescentPath,
        sources: &mut LaneSources<'_, N, F>,
        lanes_take_gradients: bool,
        stats: &mut RayStats,
        requests: &mut Vec<Request>,
    ) -> Option<&'l LaneRun<'a>>
    where
        N: RaySource<I>,
        F: FnMut(usize, &I, bool),
    {
        loop {
            let Some(lane) = slot else {
                if *sources.exhausted {
                    return None;
                }
                let Some((id, ray, integrand)) = sources.next_ray.next_ray() else {
                    *sources.exhausted = true;
                    return None;
                };
                match self.begin(&ray, stats, path) {
                    Some(walk) => *slot = Some(Lane { id, walk, integrand, run: None }),
                    None => (sources.finish)(id, &integrand, false),
                }
                continue;
            };
            let mut ended = false;
            if let Some(run) = &mut lane.run {
                if run.k >= run.end {
                    // With dilated runs, the sample one step beyond the segment's end after a run that reaches it.
                    if I::DILATED_RUNS && run.end == run.count {
                        let edge = (run.first, run.dt);
                        self.edge_sample(&run.line, &None, edge, run.count as f32, &mut lane.integrand);
                    }
                    // The next run of the segment, if any.
                    let k = run.resume.unwrap_or(run.end);
                    let segment = (run.first, run.dt, run.count);
                    match self.run_from(&run.line, None, segment, k, LONG_RUN, &lane.integrand) {
                        Some((from, to, resume)) => {
                            let (from, to) = dilated::<I>(from, to, run.count);
                            (run.k, run.end, run.resume) = (from, to, resume);
                        }
                        _ => lane.run = None,
                    }
                }
            }
            if lane.run.is_none() {
                match self.next_march(&mut lane.walk, &mut lane.integrand, stats, requests, path) {
                    None => ended = true,
                    Some(march) => {
                        if march.coarse.is_some() || (lane.integrand.wants_gradient() && !lanes_take_gradients) {
                            ended = self.march_bricks(&lane.walk.ray, march, &mut lane.integrand, stats).is_break();
                        } else {
                            let front_edge = march.front_edge;
                            lane.run = self.lane_run(&lane.walk.ray, march, &lane.integrand);
                            // With dilated runs, the sample one step before the segment's start when the first run
                            // begins there.
                            if let Some(run) =
                                lane.run.as_ref().filter(|run| I::DILATED_RUNS && front_edge && run.k == 0)
                            {
                                let edge = (run.first, run.dt);
                                self.edge_sample(&run.line, &None, edge, -1.0, &mut lane.integrand);
                            }
                        }
                    }
                }
            }
            if ended {
                (sources.finish)(lane.id, &lane.integrand, lane.walk.requested);
                *slot = None;
                continue;
            }
            if let Some(Lane { run: Some(run), .. }) = slot {
                return Some(run);
            }
        }
    }

    /// The first run of samples of a segment in a lane (`None` when nothing in it can contribute).
    #[inline(always)]
    pub(super) fn lane_run<I: Integrand>(&self, ray: &Ray, march: March, integrand: &I) -> Option<LaneRun<'a>> {
        let March { fine, first, dt, count, .. } = march;
        let count = count.min(u32::MAX as u64) as u32;
        let mut check_blocks = self.skip_empty_space;
        if self.skip_empty_space {
            let [lo, hi] = self.view.brick_range(fine.slot);
            if !integrand.can_contribute(lo, hi) {
                return None;
            }
            check_blocks = !integrand.contributes_throughout(lo, hi);
        }
        let line = self.brick_line(ray, &fine, first, dt);
        let (k, end, resume) = if check_blocks {
            self.run_from(&line, None, (first, dt, count), 0, LONG_RUN, integrand)?
        } else {
            (0, count, None)
        };
        let (k, end) = dilated::<I>(k, end, count);
        Some(LaneRun { line, first, dt, count, k, end, resume })
    }
}

/// A run `k..end` of a segment of `count` samples, widened by a sample on either side for integrands that ask
/// ([`Integrand::DILATED_RUNS`]).
#[inline(always)]
fn dilated<I: Integrand>(k: u32, end: u32, count: u32) -> (u32, u32) {
    if I::DILATED_RUNS {
        (k.saturating_sub(1), (end + 1).min(count))
    } else {
        (k, end)
    }
}

/// One sample on each lane's line ([`values_across`]), with gradients when `GRADIENT`.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(super) fn samples_across<V: Voxel, const GRADIENT: bool>(
    voxels: &[V],
    b: usize,
    bases: &[u32; LANES],
    start: &[[f32; LANES]; 3],
    delta: &[[f32; LANES]; 3],
    k: &[f32; LANES],
    dq: Dequantize,
    gather: CornerGather,
) -> ([f32; LANES], [[f32; 3]; LANES]) {
    if GRADIENT {
        values_and_gradients_across(voxels, b, bases, start, delta, k, dq, gather)
    } else {
        (values_across(voxels, b, bases, start, delta, k, dq, gather), [[0.0; 3]; LANES])
    }
}

/// One ray in a lane of [`Traversal::trace_stream`]: its id, walk and integrand, and the run of samples it is in.
pub(super) struct Lane<'v, I> {
    pub(super) id: usize,
    pub(super) walk: RayWalk,
    pub(super) integrand: I,
    pub(super) run: Option<LaneRun<'v>>,
}

/// A lane's run of samples: samples `k..end` of a segment of `count` samples `first + k·dt` on `line` need no
/// block check; `resume` is where the next run may start (see [`Traversal::next_run`]).
pub(super) struct LaneRun<'v> {
    pub(super) line: BrickLine<'v>,
    pub(super) first: f64,
    pub(super) dt: f64,
    pub(super) count: u32,
    pub(super) k: u32,
    pub(super) end: u32,
    pub(super) resume: Option<u32>,
}

/// Where a stream's lanes get rays and leave them.
pub(super) struct LaneSources<'s, N, F> {
    pub(super) next_ray: &'s mut N,
    pub(super) finish: &'s mut F,
    pub(super) exhausted: &'s mut bool,
}

#[cfg(test)]
mod tests {
    use super::super::test_tree::{ray, Child, Record, TestTree};
    use super::*;
    use crate::settings::RenderSettings;

    struct Rays(std::vec::IntoIter<(usize, Ray)>);

    impl RaySource<Record> for Rays {
        fn next_ray(&mut self) -> Option<(usize, Ray, Record)> {
            self.0.next().map(|(id, ray)| (id, ray, Record::default()))
        }
    }

    /// Rays traced side by side take exactly the samples (the same bits) and make exactly the requests that each
    /// takes and makes alone, whatever lane they land in and in whatever order they finish.
    #[test]
    fn lanes_take_exactly_what_each_ray_takes_alone() {
        let mut children = [Child::Brick; 8];
        children[2] = Child::Constant(0.5);
        children[5] = Child::Missing;
        let tree = TestTree::new(|p| 0.1 + 0.2 * p.y, |p| (p.x * 3.0).sin().abs() * p.z, children);
        let settings = RenderSettings { max_requests_per_ray: 8, ..RenderSettings::default() };
        let rays: Vec<Ray> = (0..3 * LANES + 1)
            .map(|i| {
                let f = i as f64 / (3 * LANES) as f64;
                ray([-0.5, 0.1 + 0.8 * f, 0.9 - 0.7 * f], [1.0, 0.3 * (f - 0.5), 0.2 - 0.4 * f * f])
            })
            .collect();
        let feedback = tree.feedback();
        let traversal = tree.traversal(&feedback, &settings);
        let (mut alone_stats, mut alone_requests) = (RayStats::default(), Vec::new());
        let alone: Vec<Record> = rays
            .iter()
            .map(|ray| {
                let mut record = Record::default();
                let mut path = DescentPath::new(tree.view());
                traversal.trace(ray, &mut record, &mut alone_stats, &mut alone_requests, &mut path);
                record
            })
            .collect();
        let (mut lane_stats, mut lane_requests) = (RayStats::default(), Vec::new());
        let mut paths: [DescentPath; LANES] = std::array::from_fn(|_| DescentPath::new(tree.view()));
        let mut in_lanes = vec![None; rays.len()];
        let source = Rays(rays.iter().copied().enumerate().collect::<Vec<_>>().into_iter());
        traversal.trace_stream::<Record, false>(
            source,
            |id, record, _| in_lanes[id] = Some(record.clone()),
            &mut lane_stats,
            &mut lane_requests,
            &mut paths,
        );
        for (id, (alone, in_lane)) in alone.iter().zip(&in_lanes).enumerate() {
            assert_eq!(Some(alone), in_lane.as_ref(), "ray {id}");
        }
        assert!(alone.iter().map(|r| r.samples.len()).sum::<usize>() > 100, "the rays take samples");
        assert_eq!(alone_stats, lane_stats);
        let sorted = |mut requests: Vec<Request>| {
            requests.sort_by_key(|r| (r.node, r.deficit));
            requests
        };
        assert!(!alone_requests.is_empty());
        assert_eq!(sorted(alone_requests), sorted(lane_requests));
    }
}
