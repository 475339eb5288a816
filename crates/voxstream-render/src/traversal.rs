//! One ray through the N³-tree: cone-traced level of detail, kd-restart descent, empty-space skipping, samples.
//!
//! Implements GigaVoxels [P09] §6 ("Rendering": stackless descent from the root at every new segment, cone tracing
//! with quadrilinear mip filtering) and §5 (the ray's feedback). What the samples are used for is an
//! [`Integrand`]'s business (see [`crate::integrand`]); the traversal does not know what is computed.
//!
//! 1. At the current distance `t`, the cone's footprint `w = t·spread` gives the continuous level
//!    `ℓ = log_N(1 / (M·w))`: the level whose voxel matches the pixel. Its voxel `N^(−ℓ)/M` and `⌈ℓ⌉` are computed
//!    once per segment without a logarithm (a search in the levels' voxel sizes); `frac(ℓ)` only where levels blend.
//! 2. Descend from the root to the node containing the point at level `⌈ℓ⌉`, marking each tile and brick used.
//!    Stop early at a constant node, a terminal node, a node whose data is missing (request production; the deepest
//!    ancestor with data stands in) or a node without children (request a subdivision), reporting at most
//!    `max_requests_per_ray` misses per ray and pass.
//! 3. The node's box is one segment. A constant node is handed over whole (the integrand integrates it
//!    analytically). In bricks, each sample stands for one step `Δt` around it and the next sample starts where the
//!    last one's step ended, so the samples tile the ray without gap or overlap even where `Δt` changes. `Δt` is the
//!    cone's footprint voxel (or the sampled level's voxel where only coarser data exists) times the step factor,
//!    rounded down to the ladder of [`StepLength`] so that the integrand's pre-corrected tables apply exactly. A
//!    sample belongs to the segment its centre lies in; skipping never moves a sample.
//! 4. Skip the segment at once if the integrand says no value of its bricks can contribute (per-brick min/max), and
//!    within a brick the runs of samples inside an occupancy block that cannot contribute (per-block min/max, of the
//!    finer and, when blended, the coarser brick). Other samples are trilinear in the finer brick, blended with the
//!    coarser by `frac(ℓ)` (quadrilinear), positions stepped in `f32` brick coordinates.
//! 5. Leave the box and descend again for the next point, from the deepest node of the previous path that still
//!    contains it (kd-restart from the root, shortened by keeping the path).
//!
//! Positions between segments are `f64` in the unit cube and node coordinates are integers, so zooms far below
//! `2⁻²⁰` stay exact (GigaVoxels stopped at `2¹⁹` because of float32 precision); inside a brick, `f32` brick
//! coordinates are exact to ~10⁻⁵ voxel.

use std::ops::ControlFlow;

use glam::DVec3;
use voxstream_core::{
    BrickBlend, BrickSlot, Dequantize, FeedbackBuffer, Node, NodeData, NodeId, PoolVoxels, Request, RequestKind,
    TreeView, Voxel, BLOCK_CELLS,
};

use crate::block_visibility::BrickBlocks;
use crate::gathered_corners::CornerGather;
use crate::integrand::{BrickSpan, Integrand, Sample};
use crate::sampler::{
    floor_index, values_across, values_along, values_and_gradients_across, values_and_gradients_along, Cell, LANES,
};
use crate::settings::RenderSettings;
use crate::step_table::StepLength;

/// Deepest level the precomputed scale table covers.
const MAX_TABLE_LEVELS: usize = 64;
/// A ray may not cross more segments than this (guards against any numerical stall).
const MAX_SEGMENTS: u32 = 1 << 20;
/// In a lane of [`Traversal::trace_stream`] whose runs come from the blocks' range tests (integrands without block
/// bits), a run of samples is extended through the following blocks that can contribute until it is this long, so
/// that the lanes' runs (the shortest of which ends a burst) are long. One ray alone extends none: checking blocks
/// ahead costs more than it saves where rays turn opaque within a few samples (the sponge: about 2 samples per ray).
/// Runs read from block bits are as long as the blocks allow ([`Traversal::visible_run`]).
const LONG_RUN: u32 = 4 * LANES as u32;

/// Steps of a burst sampled across the lanes before the lanes' integrands take them.
const BURST_CHUNK: usize = 16;

/// The fewest steps of a burst while some lane has that many samples left in its run: lanes whose run is shorter
/// sample on past its end (positions stay clamped in their brick, so the reads are harmless) and their integrands
/// take only the run's samples. A burst ending with the shortest run made a round of refills every 4 to 8 steps;
/// refills cost more than the idle lanes' samples (measured: 1.03–1.09× on the peers' scenes, the same bytes).
const MIN_BURST: u32 = 16;

/// Counters of one ray batch.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RayStats {
    /// Rays traced.
    pub rays: u64,
    /// Brick samples taken plus constant segments integrated.
    pub samples: u64,
    /// Descents (one per segment), each from the deepest node of the path kept that contains the segment's point.
    pub descents: u64,
    /// Child nodes entered by those descents: the levels walked down, which a descent restarting from a kept path
    /// saves ([`DescentPath`]). Counted by the CPU traversal only (0 from the GPU renderer).
    pub nodes_entered: u64,
}

impl RayStats {
    /// Adds another batch's counters.
    pub fn add(&mut self, other: &RayStats) {
        self.rays += other.rays;
        self.samples += other.samples;
        self.descents += other.descents;
        self.nodes_entered += other.nodes_entered;
    }
}

/// Deepest level a descent path can hold.
const MAX_PATH: usize = MAX_TABLE_LEVELS;

/// One node of the current descent.
#[derive(Clone, Copy, Debug)]
struct PathEntry {
    id: NodeId,
    node: Node,
    ijk: [u64; 3],
}

/// The nodes from the root to the last node reached, reused between segments so that a new descent restarts from
/// the deepest ancestor that still contains the point (a short-stack variant of kd-restart). One per thread, reused
/// from ray to ray.
///
/// A path made by `DescentPath::for_rays_of_one_view` (each pass of a frame makes its own) also keeps the nodes of
/// each ray's first descent, and the next ray starts from them rather than from the root: its first descent restarts
/// from the deepest of them that contains its first point (neighbouring rays of a tile mostly enter the volume in the
/// same nodes). These are the shared descents of Knoll et al.'s packets (seed 002 §4), shared in time rather than in
/// lock-step. A descent finds the same node from any kept ancestor of the point as from the root, so the rays'
/// results are the same bits: where N is a power of two (an ancestor's coordinates are then the point's, shifted,
/// with no rounding; other trees start every ray from the root), and with the kept nodes that an integrand's
/// min/max culling would have stopped at cut off. The nodes kept were marked used when they were first descended
/// to, in the same feedback buffer.
pub struct DescentPath {
    entries: [PathEntry; MAX_PATH],
    len: usize,
    /// Whether a new ray starts from the last ray's first descent (see `DescentPath::for_rays_of_one_view`).
    kept_between_rays: bool,
    /// The nodes of the last ray's first descent, and how many.
    first_descent: [PathEntry; MAX_PATH],
    first_len: usize,
    /// Whether the next descent is a ray's first (its nodes are then kept in `first_descent`).
    first_to_keep: bool,
}

impl DescentPath {
    /// A path holding only the root of `view`; every ray starts from the root.
    pub fn new(view: TreeView<'_>) -> DescentPath {
        let root = PathEntry { id: NodeId::ROOT, node: view.root(), ijk: [0; 3] };
        DescentPath {
            entries: [root; MAX_PATH],
            len: 1,
            kept_between_rays: false,
            first_descent: [root; MAX_PATH],
            first_len: 1,
            first_to_keep: false,
        }
    }

    /// A path that starts each ray from the nodes of the last ray's first descent. Only for rays traced through this
    /// `view` and written into one feedback buffer (one pass of a frame): its nodes would be stale in a later view,
    /// and their marks missing from another buffer. Crate-private for that reason: the frame makes these paths for
    /// each pass ([`RenderSettings::shared_descents`]); paths made by [`DescentPath::new`] can be reused freely.
    pub(crate) fn for_rays_of_one_view(view: TreeView<'_>) -> DescentPath {
        DescentPath { kept_between_rays: true, ..DescentPath::new(view) }
    }

    /// Readies the path for a new ray: the root, or with `DescentPath::for_rays_of_one_view` and `may_keep` the nodes
    /// of the last ray's first descent.
    #[inline(always)]
    fn start_ray(&mut self, view: TreeView<'_>, may_keep: bool) {
        if self.kept_between_rays && may_keep {
            debug_assert!(self.first_descent[0].node == view.root(), "a kept path used with another tree view");
            self.entries[..self.first_len].copy_from_slice(&self.first_descent[..self.first_len]);
            self.len = self.first_len;
            self.first_to_keep = true;
        } else {
            self.entries[0] = PathEntry { id: NodeId::ROOT, node: view.root(), ijk: [0; 3] };
            self.len = 1;
        }
    }

    /// After a descent that kept the first `kept` nodes: if it was the ray's first, its new nodes are kept for the
    /// next ray.
    #[inline(always)]
    fn descended(&mut self, kept: usize) {
        if self.first_to_keep {
            self.first_to_keep = false;
            self.first_descent[kept..self.len].copy_from_slice(&self.entries[kept..self.len]);
            self.first_len = self.len;
        }
    }
}

/// A ray in volume space: `origin` in unit-cube coordinates, `direction` = the unit world direction divided by the
/// placement's scale (so `t` stays in world units), and the cone's `spread` (footprint per unit distance).
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    /// Origin, unit-cube coordinates.
    pub origin: DVec3,
    /// Unit-cube units per world unit of `t`.
    pub direction: DVec3,
    /// Cone footprint per unit distance (world units).
    pub spread: f64,
    /// Distance at which the ray starts (0 for a primary ray; a shadow ray starts at its surface point, with an
    /// origin moved back so that its cone is already as wide as the primary ray's there).
    pub start: f64,
}

/// A brick found on the descent: which slot and which node it belongs to.
#[derive(Clone, Copy, Debug)]
struct BrickRef {
    slot: BrickSlot,
    level: u32,
    ijk: [u64; 3],
}

/// What the descent found for the current segment.
enum SegmentData {
    /// Nothing resident at all (the root is missing): the segment is skipped.
    Nothing,
    /// A constant node: its samples are all the same value.
    Constant(f32),
    /// Bricks: the finest with data, and its parent for level blending; `stand_in` when finer data is wanted but not
    /// drawable yet (missing, not subdivided, or fading in).
    Bricks { fine: BrickRef, coarse: Option<BrickRef>, blend_level: bool, stand_in: bool },
}

/// A brick sampled along a segment: its voxels and the ray's continuous voxel index there, `x_k = start + k·delta`
/// for sample `k` of the segment.
#[derive(Clone, Copy)]
struct BrickLine<'v> {
    voxels: PoolVoxels<'v>,
    slot: BrickSlot,
    start: [f32; 3],
    delta: [f32; 3],
    /// The same line in `f64` over `t`, for block exits: `x(t) = origin + t·rate`.
    origin: [f64; 3],
    rate: [f64; 3],
    /// `1 / rate` (infinite along an axis the ray does not move on).
    inverse_rate: [f64; 3],
}

impl BrickLine<'_> {
    #[inline(always)]
    fn at(&self, k: f32) -> [f32; 3] {
        [self.start[0] + k * self.delta[0], self.start[1] + k * self.delta[1], self.start[2] + k * self.delta[2]]
    }
}

/// The rays [`Traversal::trace_stream`] traces, each with its integrand. A trait rather than a closure so that an
/// implementation can be inlined into the tile loop, and compiled for its instruction set, whatever its size (a
/// closure's inlining is up to the compiler).
pub trait RaySource<I> {
    /// The next ray: its id, the ray and its integrand; `None` once they have run out.
    fn next_ray(&mut self) -> Option<(usize, Ray, I)>;
}

/// Walks rays through one frame's tree view, writing feedback and handing samples to an integrand.
pub struct Traversal<'a> {
    view: TreeView<'a>,
    /// How the pool's stored voxels map to values ([`voxstream_core::VoxelFormat`]).
    dequantize: Dequantize,
    feedback: &'a FeedbackBuffer,
    step_factor: f64,
    lod_bias: f64,
    world_per_volume: f64,
    clip_lower: DVec3,
    clip_upper: DVec3,
    max_requests_per_ray: u32,
    skip_empty_space: bool,
    sample_batches: bool,
    steps_ignore_stand_ins: bool,
    /// Levels below a stand-in whose voxel may set the step (`N^levels ≤ 4`).
    stand_in_levels: u32,
    /// `N^d` for every level.
    scale: [f64; MAX_TABLE_LEVELS],
    n: u64,
    brick_size: f64,
    stored: usize,
    inv_ln_n: f64,
    /// `N^(−lod_bias)`.
    bias_scale: f64,
    /// Voxel edge (unit cube) of every level: `N^(−d) / M`, decreasing.
    level_voxel: [f64; MAX_TABLE_LEVELS],
    /// Per level `d`, a footprint below which the cone's continuous level is surely at least `d`
    /// ([`Traversal::level_of_footprint`] without its logarithm; a relative margin of 10⁻⁹ covers its rounding).
    footprint_within_level: [f64; MAX_TABLE_LEVELS],
    /// `log2 N` when `N` is a power of two.
    n_shift: Option<u32>,
    /// Edge of the finest level's nodes (unit cube).
    finest_node: f64,
    /// Occupancy blocks per brick axis.
    blocks_per_axis: usize,
    /// How the samplers read brick corners: with AVX2 gathers where the ray loop runs its AVX2 build.
    gather: CornerGather,
}

impl<'a> Traversal<'a> {
    /// Prepares a traversal for one frame.
    pub fn new(view: TreeView<'a>, feedback: &'a FeedbackBuffer, settings: &RenderSettings) -> Traversal<'a> {
        let shape = view.shape;
        let mut scale = [1.0f64; MAX_TABLE_LEVELS];
        for d in 1..MAX_TABLE_LEVELS {
            scale[d] = scale[d - 1] * shape.n as f64;
        }
        let level_voxel = scale.map(|s| 1.0 / (s * shape.brick_size as f64));
        let bias_scale = (-settings.lod_bias * (shape.n as f64).ln()).exp();
        Traversal {
            view,
            dequantize: view.voxel_format.dequantize(),
            feedback,
            step_factor: settings.step_factor,
            lod_bias: settings.lod_bias,
            world_per_volume: settings.placement.mean_scale(),
            clip_lower: DVec3::from(settings.placement.clip_lower),
            clip_upper: DVec3::from(settings.placement.clip_upper),
            max_requests_per_ray: settings.max_requests_per_ray,
            skip_empty_space: settings.skip_empty_space,
            sample_batches: settings.sample_batches,
            steps_ignore_stand_ins: settings.steps_ignore_stand_ins,
            stand_in_levels: if shape.n <= 2 { 2 } else { 1 },
            scale,
            n: shape.n as u64,
            brick_size: shape.brick_size as f64,
            stored: shape.stored_brick_size() as usize,
            inv_ln_n: 1.0 / (shape.n as f64).ln(),
            bias_scale,
            level_voxel,
            footprint_within_level: level_voxel.map(|voxel| voxel / bias_scale * (1.0 - 1e-9)),
            n_shift: shape.n.is_power_of_two().then(|| shape.n.trailing_zeros()),
            finest_node: 1.0 / scale[(shape.max_level as usize).min(MAX_TABLE_LEVELS - 1)],
            blocks_per_axis: shape.blocks_per_axis(),
            gather: CornerGather::new(settings.instruction_set.gathers()),
        }
    }

    /// The tree view this traversal reads.
    pub fn view(&self) -> TreeView<'a> {
        self.view
    }

    /// The cone's footprint at distance `t` (world units) for a cone of `spread` per unit distance: its width in
    /// volume units (floored above 0, for the logarithm).
    #[inline(always)]
    fn footprint(&self, t: f64, spread: f64) -> f64 {
        (t * spread / self.world_per_volume).max(1e-300)
    }

    /// Continuous level of detail of a cone whose footprint is `footprint` ([`Traversal::footprint`]).
    #[inline]
    fn level_of_footprint(&self, footprint: f64) -> f64 {
        let level = -(self.brick_size * footprint).ln() * self.inv_ln_n + self.lod_bias;
        level.clamp(0.0, self.view.shape.max_level as f64)
    }

    /// The voxel edge of the continuous level at distance `t`, `N^(−ℓ) / M`, and the level to descend to, `⌈ℓ⌉`,
    /// without a logarithm or an exponential: unclamped, `N^(−ℓ) = M·w·N^(−bias)` for the footprint `w`, and `⌈ℓ⌉`
    /// is the coarsest level whose voxel is no larger than that. The search starts from `hint`, the previous
    /// segment's level (it changes by a level at a time along a ray), and leaves the result there.
    #[inline]
    fn footprint_at(&self, t: f64, spread: f64, hint: &mut usize) -> (f64, u32) {
        let max_level = self.view.shape.max_level as usize;
        let footprint = self.footprint(t, spread);
        let voxel = (footprint * self.bias_scale).clamp(self.level_voxel[max_level], self.level_voxel[0]);
        // The first level whose voxel is not larger than `voxel` (the table decreases; at most max_level + 1).
        let mut target = (*hint).min(max_level);
        while target > 0 && self.level_voxel[target - 1] <= voxel {
            target -= 1;
        }
        while target <= max_level && self.level_voxel[target] > voxel {
            target += 1;
        }
        let target = target.min(max_level);
        *hint = target;
        (voxel, target as u32)
    }

    /// Walks `ray`, handing its samples to `integrand` until the ray leaves the volume or the integrand stops it.
    /// Appends at most `max_requests_per_ray` requests to `requests`. Always inlined, so that the caller's
    /// instruction set ([`crate::InstructionSet`]) applies to the whole walk.
    #[inline(always)]
    pub fn trace<I: Integrand>(
        &self,
        ray: &Ray,
        integrand: &mut I,
        stats: &mut RayStats,
        requests: &mut Vec<Request>,
        path: &mut DescentPath,
    ) {
        let Some(mut walk) = self.begin(ray, stats, path) else { return };
        while let Some(march) = self.next_march(&mut walk, integrand, stats, requests, path) {
            if self.march_bricks(&walk.ray, march, integrand, stats).is_break() {
                return;
            }
        }
    }

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
    fn trace_stream_in<V: Voxel, I: Integrand, const GRADIENT: bool>(
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
    fn fill_lane<'l, I: Integrand, N, F>(
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
                    // The next run of the segment, if any.
                    let k = run.resume.unwrap_or(run.end);
                    let segment = (run.first, run.dt, run.count);
                    match self.run_from(&run.line, None, segment, k, LONG_RUN, &lane.integrand) {
                        Some((from, to, resume)) => (run.k, run.end, run.resume) = (from, to, resume),
                        None => lane.run = None,
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
                            lane.run = self.lane_run(&lane.walk.ray, march, &lane.integrand);
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
    fn lane_run<I: Integrand>(&self, ray: &Ray, march: March, integrand: &I) -> Option<LaneRun<'a>> {
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
        Some(LaneRun { line, first, dt, count, k, end, resume })
    }

    /// Starts `ray`: counts it, clips it to the volume (`None` when it misses) and starts `path` for it
    /// ([`DescentPath::start_ray`]).
    #[inline(always)]
    fn begin(&self, ray: &Ray, stats: &mut RayStats, path: &mut DescentPath) -> Option<RayWalk> {
        stats.rays += 1;
        let (t_enter, t_leave) = intersect_aabb(ray.origin, ray.direction, self.clip_lower, self.clip_upper)?;
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
    fn next_march<I: Integrand>(
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
                    ControlFlow::Continue(())
                }
                SegmentData::Constant(value) => {
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
                    let blend = coarse.and(self.view.brick_blends.get(fine.slot.0 as usize)).filter(|b| !b.is_full());
                    let desired_step = sampled_voxel.max(footprint_voxel) * self.step_factor / speed;
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
                            // The cone's level weight (1 where only coarser data exists), capped by the fine brick's
                            // blending caps (Thiele et al.: fade-in, coarser neighbours) at the first and the last
                            // sample, and ramped linearly between them.
                            let cone = if blend_level {
                                let footprint = self.footprint(0.5 * (t + t_exit), ray.spread);
                                // At least the fine level there (the usual case): the weight is 1 without the
                                // logarithm.
                                if footprint <= self.footprint_within_level[c.level as usize + 1] {
                                    1.0
                                } else {
                                    (self.level_of_footprint(footprint) - c.level as f64).clamp(0.0, 1.0) as f32
                                }
                            } else {
                                1.0
                            };
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
                        return Some(March { fine, coarse, first, dt, count });
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
    fn sampled_level(&self, fine: &BrickRef, stand_in: bool) -> u32 {
        if stand_in && self.steps_ignore_stand_ins {
            (fine.level + self.stand_in_levels).min(self.view.shape.max_level)
        } else {
            fine.level
        }
    }

    /// The blending cap of `fine` (interpolated between its corners) where the ray is at `t`.
    #[inline]
    fn cap_at(&self, ray: &Ray, fine: &BrickRef, blend: &BrickBlend, t: f64) -> f32 {
        let s = self.scale[fine.level as usize];
        let p = ray.origin + ray.direction * t;
        let (pa, ijk) = (p.to_array(), fine.ijk);
        blend.at(std::array::from_fn(|a| (pa[a] * s - ijk[a] as i64 as f64) as f32))
    }

    /// Samples `count` points `first + k·dt` inside the bricks of one segment, skipping the runs that lie in
    /// occupancy blocks the integrand cannot use.
    #[inline(always)]
    fn march_bricks<I: Integrand>(
        &self,
        ray: &Ray,
        march: March,
        integrand: &mut I,
        stats: &mut RayStats,
    ) -> ControlFlow<()> {
        let March { fine, coarse, first, dt, count } = march;
        // Whether occupancy blocks are checked: not when every value of the bricks can contribute.
        let mut check_blocks = self.skip_empty_space;
        if self.skip_empty_space {
            // Empty-space skipping: nothing in the bricks (fine, and coarse if blended) can contribute.
            let [mut lo, mut hi] = self.view.brick_range(fine.slot);
            if let Some((c, _)) = coarse {
                let [clo, chi] = self.view.brick_range(c.slot);
                lo = lo.min(clo);
                hi = hi.max(chi);
            }
            if !integrand.can_contribute(lo, hi) {
                return ControlFlow::Continue(());
            }
            check_blocks = !integrand.contributes_throughout(lo, hi);
        }
        let fine_line = self.brick_line(ray, &fine, first, dt);
        let coarse_line = coarse.map(|(c, weight)| (self.brick_line(ray, &c, first, dt), weight));
        let gradient = integrand.wants_gradient();
        let count = count.min(u32::MAX as u64) as u32;
        let coarse_brick_line = coarse_line.as_ref().map(|(line, _)| line);
        let mut k = 0u32;
        while k < count {
            // The next run of samples in blocks that can contribute, and where the one after it may start.
            let (run_start, run_end, resume) = if check_blocks {
                match self.run_from(&fine_line, coarse_brick_line, (first, dt, count), k, 0, integrand) {
                    Some(run) => run,
                    None => break,
                }
            } else {
                (k, count, None)
            };
            k = run_start;
            // One loop per combination, so that the loop itself holds no test of either.
            let (coarse, weight) = match &coarse_line {
                Some((line, weight)) => (line, *weight),
                None => (&fine_line, Blend::FINE),
            };
            let run = (first, dt, k, run_end);
            let blend_gradients = gradient && weight.gradient.is_some();
            let flow = match (gradient, coarse_line.is_some(), blend_gradients) {
                (false, false, _) => {
                    self.sample_run::<I, false, false, false>(&fine_line, coarse, weight, run, integrand)
                }
                (true, false, _) => {
                    self.sample_run::<I, true, false, false>(&fine_line, coarse, weight, run, integrand)
                }
                (false, true, _) => {
                    self.sample_run::<I, false, true, false>(&fine_line, coarse, weight, run, integrand)
                }
                (true, true, false) => {
                    self.sample_run::<I, true, true, false>(&fine_line, coarse, weight, run, integrand)
                }
                (true, true, true) => {
                    self.sample_run::<I, true, true, true>(&fine_line, coarse, weight, run, integrand)
                }
            };
            match flow {
                ControlFlow::Break(taken) => {
                    stats.samples += taken;
                    return ControlFlow::Break(());
                }
                ControlFlow::Continue(()) => stats.samples += (run_end - k) as u64,
            }
            k = resume.unwrap_or(run_end);
        }
        ControlFlow::Continue(())
    }

    /// Which occupancy blocks (fine, and coarse if blended) hold sample `k` of a segment (`first + k·dt`, `count`
    /// samples), whether the integrand can use their values, and the first sample past them: `(true, end)` when it
    /// can (samples up to the blocks' exit need no check; one past it would be harmless, it is sampled),
    /// `(false, next)` when it cannot (every sample before `next`, the exit less a margin above f32 rounding, is in
    /// these blocks). Always past `k`.
    #[inline(always)]
    fn check_blocks<I: Integrand>(
        &self,
        fine: &BrickLine<'_>,
        coarse: Option<&BrickLine<'_>>,
        (first, dt, count): (f64, f64, u32),
        k: u32,
        integrand: &I,
    ) -> (bool, u32) {
        let blocks = self.view.shape.blocks_per_axis();
        let fine_cell = Cell::locate(self.stored, fine.at(k as f32));
        let [mut lo, mut hi] = self.view.block_range(fine.slot, fine_cell.block(blocks));
        let mut exit = block_exit(fine, fine_cell.block_ijk());
        if let Some(line) = coarse {
            let coarse_cell = Cell::locate(self.stored, line.at(k as f32));
            let [clo, chi] = self.view.block_range(line.slot, coarse_cell.block(blocks));
            lo = lo.min(clo);
            hi = hi.max(chi);
            exit = exit.min(block_exit(line, coarse_cell.block_ijk()));
        }
        let contributes = integrand.can_contribute(lo, hi);
        let boundary = if contributes { (exit - first) / dt } else { (exit - 1e-3 * dt - first) / dt }.ceil();
        // `boundary` is a whole number; below 2⁵², it is the mantissa of `2⁵² + boundary` (float operations only,
        // like `floor_index`: a saturating conversion is several instructions).
        const TWO_POW_52: f64 = 4_503_599_627_370_496.0;
        let past = if boundary > k as f64 {
            ((boundary.min(count as f64) + TWO_POW_52).to_bits() - TWO_POW_52.to_bits()) as u32
        } else {
            k + 1
        };
        (contributes, past)
    }

    /// The next run of samples at or after `k` of a segment whose blocks can contribute, as `(start, end, resume)`
    /// (see [`Traversal::next_run`]): from the integrand's block bits when it has them and the segment samples one
    /// brick ([`Traversal::visible_run`]: runs as long as the blocks allow, `long_run` does not apply), else from the
    /// blocks' ranges.
    #[inline(always)]
    fn run_from<I: Integrand>(
        &self,
        fine: &BrickLine<'_>,
        coarse: Option<&BrickLine<'_>>,
        segment: (f64, f64, u32),
        k: u32,
        long_run: u32,
        integrand: &I,
    ) -> Option<(u32, u32, Option<u32>)> {
        match (coarse, integrand.block_visibility()) {
            (None, Some(visibility)) => {
                let bits = visibility.of_brick(&self.view, fine.slot, |lo, hi| integrand.can_contribute(lo, hi));
                self.visible_run(fine, bits, segment.2, k).map(|(start, end)| (start, end, None))
            }
            _ => self.next_run(fine, coarse, segment, k, long_run, integrand),
        }
    }

    /// The first run `start..end` of samples at or after `k` (of `count`) of a brick line whose cells lie in blocks
    /// whose bits say they can contribute: every sample of the run does, the one at `end` (if any) does not. Eight
    /// samples at a time ([`Traversal::visible_mask`]). `None` when no sample is left that can.
    #[inline(always)]
    fn visible_run(&self, line: &BrickLine<'_>, bits: BrickBlocks<'_>, count: u32, mut k: u32) -> Option<(u32, u32)> {
        const ALL: u32 = (1 << LANES) - 1;
        let (start, mut cannot) = loop {
            if k >= count {
                return None;
            }
            let mask = self.visible_mask(line, bits, k, count);
            if mask != 0 {
                let offset = mask.trailing_zeros();
                // The samples of this eight from the start on that cannot contribute (or lie past `count`).
                break (k + offset, !mask & ALL & (ALL << offset));
            }
            k += LANES as u32;
        };
        // Samples past `count` read as "cannot", so the run ends at `count` at the latest.
        loop {
            if cannot != 0 {
                return Some((start, k + cannot.trailing_zeros()));
            }
            k += LANES as u32;
            cannot = !self.visible_mask(line, bits, k, count) & ALL;
        }
    }

    /// Bit `j` set when sample `k + j` (`j < LANES`, `k + j < count`) of a brick line lies in a cell whose block can
    /// contribute. The cells are located as [`Cell::locate`] and the samplers locate them (the position
    /// `start + k·delta` in `f32`, clamped to the brick), so a sample's bit is the bit of the block it reads. Written
    /// out lane by lane in `u32`, as `sampler::corners_across` is, rather than through `Cell::locate(..).block(..)`
    /// (`usize` indices): that version computes the same blocks but made the frame 1.4× slower (mni-soft 240 →
    /// 344 ms).
    #[inline(always)]
    fn visible_mask(&self, line: &BrickLine<'_>, bits: BrickBlocks<'_>, k: u32, count: u32) -> u32 {
        let b = self.stored;
        let max = (b - 1) as f32;
        let last_cell = b as u32 - 2;
        let blocks = self.blocks_per_axis as u32;
        let kf = k as f32;
        let mut block = [0u32; LANES];
        for (j, block) in block.iter_mut().enumerate() {
            // `k + j` as a float: exact below 2²⁴, the same bits as the samplers' counters.
            let kj = kf + j as f32;
            let mut index = 0;
            for a in (0..3).rev() {
                let c = (line.start[a] + kj * line.delta[a]).max(0.0).min(max);
                let (i, _) = floor_index(c, last_cell);
                index = index * blocks + i / BLOCK_CELLS as u32;
            }
            *block = index;
        }
        let mut mask = 0;
        for (j, &block) in block.iter().enumerate() {
            if k + (j as u32) < count && bits.contributes(block as usize) {
                mask |= 1 << j;
            }
        }
        mask
    }

    /// The next run of samples at or after `k` whose blocks can contribute, as `(start, end, resume)`: one run
    /// through the following blocks that can contribute too, until it holds `long_run` samples, and `resume`, where the next run may start when this one ends at blocks that
    /// cannot contribute (already checked). `None` when no sample is left.
    #[inline(always)]
    fn next_run<I: Integrand>(
        &self,
        fine: &BrickLine<'_>,
        coarse: Option<&BrickLine<'_>>,
        segment: (f64, f64, u32),
        mut k: u32,
        long_run: u32,
        integrand: &I,
    ) -> Option<(u32, u32, Option<u32>)> {
        let count = segment.2;
        while k < count {
            let (contributes, past) = self.check_blocks(fine, coarse, segment, k, integrand);
            if !contributes {
                k = past;
                continue;
            }
            let mut end = past;
            while end < count && end - k < long_run {
                let (contributes, past) = self.check_blocks(fine, coarse, segment, end, integrand);
                if !contributes {
                    return Some((k, end, Some(past)));
                }
                end = past;
            }
            return Some((k, end, None));
        }
        None
    }

    /// The inner loop: samples `k..end` of a segment (`run = (first, dt, k, end)`), with no skipping checks;
    /// values blended with `coarse` by `blend.value` when `COARSE`, gradients too (by `blend.gradient`) when
    /// `BLEND_GRADIENTS`.
    #[inline(always)]
    fn sample_run<I: Integrand, const GRADIENT: bool, const COARSE: bool, const BLEND_GRADIENTS: bool>(
        &self,
        fine: &BrickLine<'_>,
        coarse: &BrickLine<'_>,
        blend: Blend,
        run: (f64, f64, u32, u32),
        integrand: &mut I,
    ) -> RunFlow {
        // Both bricks are in the one pool, so both are of its format.
        match (fine.voxels, coarse.voxels) {
            (PoolVoxels::Wide(f), PoolVoxels::Wide(c)) => self
                .sample_run_in::<_, I, GRADIENT, COARSE, BLEND_GRADIENTS>(
                    (f, fine),
                    (c, coarse),
                    blend,
                    run,
                    integrand,
                ),
            (PoolVoxels::Narrow(f), PoolVoxels::Narrow(c)) => self
                .sample_run_in::<_, I, GRADIENT, COARSE, BLEND_GRADIENTS>(
                    (f, fine),
                    (c, coarse),
                    blend,
                    run,
                    integrand,
                ),
            _ => unreachable!("the bricks of one pool have one voxel format"),
        }
    }

    /// [`Traversal::sample_run`] for the pool's voxel type.
    #[inline(always)]
    fn sample_run_in<V: Voxel, I: Integrand, const GRADIENT: bool, const COARSE: bool, const BLEND_GRADIENTS: bool>(
        &self,
        (fine_voxels, fine): (&[V], &BrickLine<'_>),
        (coarse_voxels, coarse): (&[V], &BrickLine<'_>),
        blend: Blend,
        (first, dt, k, end): (f64, f64, u32, u32),
        integrand: &mut I,
    ) -> RunFlow {
        let b = self.stored;
        let dq = self.dequantize;
        let (weight, gradient_weight) = (blend.value, blend.gradient.unwrap_or(WeightRamp::FINE));
        // A coarse gradient per coarse voxel, in fine voxels.
        let coarse_scale = 1.0 / self.n as f32;
        let blend_gradient = |fine: [f32; 3], coarse: [f32; 3], w: f32| {
            std::array::from_fn(|a| coarse[a] * coarse_scale + (fine[a] - coarse[a] * coarse_scale) * w)
        };
        // A float counter (exact below 2²⁴) instead of converting the index per sample: positions are the same
        // bits whichever sample a run starts at.
        let mut kf = k as f32;
        let mut s = k;
        // LANES samples at a time (the same values, bit for bit: see `values_along`); the integrand still takes
        // them one by one, in order. (A run's last few samples are taken one at a time: a padded batch costs more
        // where rays turn opaque within a few samples, as in the sponge.)
        if self.sample_batches {
            while s + LANES as u32 <= end {
                let (mut values, mut gradients) = if GRADIENT {
                    values_and_gradients_along(fine_voxels, b, fine.start, fine.delta, kf, dq, self.gather)
                } else {
                    (values_along(fine_voxels, b, fine.start, fine.delta, kf, dq, self.gather), [[0.0; 3]; LANES])
                };
                if BLEND_GRADIENTS {
                    let (coarse_values, coarse_gradients) =
                        values_and_gradients_along(coarse_voxels, b, coarse.start, coarse.delta, kf, dq, self.gather);
                    for j in 0..LANES {
                        let x = kf + j as f32;
                        values[j] = coarse_values[j] + (values[j] - coarse_values[j]) * weight.at(x);
                        gradients[j] = blend_gradient(gradients[j], coarse_gradients[j], gradient_weight.at(x));
                    }
                } else if COARSE {
                    let coarse_values = values_along(coarse_voxels, b, coarse.start, coarse.delta, kf, dq, self.gather);
                    for (j, (value, coarse_value)) in values.iter_mut().zip(coarse_values).enumerate() {
                        *value = coarse_value + (*value - coarse_value) * weight.at(kf + j as f32);
                    }
                }
                for (j, (&value, &gradient)) in values.iter().zip(&gradients).enumerate() {
                    let sample = Sample { t: first + (s + j as u32) as f64 * dt, value, gradient };
                    if integrand.sample(sample).is_break() {
                        return ControlFlow::Break(u64::from(s - k) + j as u64 + 1);
                    }
                }
                s += LANES as u32;
                kf += LANES as f32;
            }
        }
        for s in s..end {
            let cell = Cell::locate(b, fine.at(kf));
            let (mut value, mut gradient) = if GRADIENT {
                cell.value_and_gradient(fine_voxels, b, dq)
            } else {
                (cell.value(fine_voxels, b, dq), [0.0; 3])
            };
            if BLEND_GRADIENTS {
                let (coarse_value, coarse_gradient) =
                    Cell::locate(b, coarse.at(kf)).value_and_gradient(coarse_voxels, b, dq);
                value = coarse_value + (value - coarse_value) * weight.at(kf);
                gradient = blend_gradient(gradient, coarse_gradient, gradient_weight.at(kf));
            } else if COARSE {
                let coarse_value = Cell::locate(b, coarse.at(kf)).value(coarse_voxels, b, dq);
                value = coarse_value + (value - coarse_value) * weight.at(kf);
            }
            let sample = Sample { t: first + s as f64 * dt, value, gradient };
            if integrand.sample(sample).is_break() {
                return ControlFlow::Break(u64::from(s - k + 1));
            }
            kf += 1.0;
        }
        ControlFlow::Continue(())
    }

    /// The continuous voxel index in the brick of `node` along the ray, from sample `first` on in steps of `dt`.
    #[inline(always)]
    fn brick_line(&self, ray: &Ray, node: &BrickRef, first: f64, dt: f64) -> BrickLine<'a> {
        let s = self.scale[node.level as usize];
        let m = self.brick_size;
        let (o, d) = (ray.origin.to_array(), ray.direction.to_array());
        let origin: [f64; 3] = std::array::from_fn(|a| (o[a] * s - node.ijk[a] as i64 as f64) * m + 0.5);
        let rate: [f64; 3] = std::array::from_fn(|a| d[a] * s * m);
        BrickLine {
            voxels: self.view.brick(node.slot),
            slot: node.slot,
            start: std::array::from_fn(|a| (origin[a] + rate[a] * first) as f32),
            delta: std::array::from_fn(|a| (rate[a] * dt) as f32),
            origin,
            rate,
            inverse_rate: rate.map(|r| 1.0 / r),
        }
    }

    /// The brick of `node` along the ray over `[from, to)`, for integrands that take spans.
    #[inline(always)]
    fn brick_span(&self, ray: &Ray, node: &BrickRef, from: f64, to: f64, step: f64) -> BrickSpan<'a> {
        let s = self.scale[node.level as usize];
        let m = self.brick_size;
        let (o, d) = (ray.origin.to_array(), ray.direction.to_array());
        let blocks = self.view.shape.blocks_per_brick();
        BrickSpan {
            voxels: self.view.brick(node.slot),
            dequantize: self.dequantize,
            stored: self.stored,
            origin: std::array::from_fn(|a| (o[a] * s - node.ijk[a] as i64 as f64) * m + 0.5),
            rate: std::array::from_fn(|a| d[a] * s * m),
            from,
            to,
            block_ranges: &self.view.block_ranges[node.slot.0 as usize * blocks..(node.slot.0 as usize + 1) * blocks],
            blocks: self.view.shape.blocks_per_axis(),
            cull_blocks: self.skip_empty_space,
            step,
        }
    }

    /// Descends towards `target_level` at `p`, restarting from the deepest node of the previous descent that still
    /// contains `p` (the root at worst, which is GigaVoxels' kd-restart); returns the data to use and the box of the
    /// deepest node visited (the segment to march).
    #[inline(always)]
    fn descend<I: Integrand>(
        &self,
        p: DVec3,
        target_level: u32,
        path: &mut DescentPath,
        request: &mut RequestSink<'_>,
        integrand: &I,
        nodes_entered: &mut u64,
    ) -> (SegmentData, u32, [u64; 3]) {
        let n = self.n;
        let pa = [p.x, p.y, p.z];
        // Keep the ancestors that contain p, and no deeper than the target.
        let mut keep = path.len.min(target_level as usize + 1).max(1);
        if keep > 1 {
            // p's node coordinates at the deepest candidate level; through i64: one instruction (a u64 conversion
            // is a branchy sequence before AVX-512); positions are non-negative and node coordinates below 2⁶³.
            let s = self.scale[keep - 1];
            let deepest = [0, 1, 2].map(|a| (pa[a] * s) as i64 as u64);
            if let Some(shift) = self.n_shift {
                // N = 2^shift: multiplying by a power of two is exact, so an ancestor's coordinates are these
                // shifted, the same integers as computing them from p.
                let mut up = 0;
                while keep > 1 {
                    let ijk = path.entries[keep - 1].ijk;
                    if (0..3).all(|a| deepest[a] >> up == ijk[a]) {
                        break;
                    }
                    keep -= 1;
                    up += shift;
                }
            } else if deepest != path.entries[keep - 1].ijk {
                keep -= 1;
                while keep > 1 {
                    let s = self.scale[keep - 1];
                    if (0..3).all(|a| (pa[a] * s) as i64 as u64 == path.entries[keep - 1].ijk[a]) {
                        break;
                    }
                    keep -= 1;
                }
            }
        }
        if I::CULLS_SUBTREES
            && self.skip_empty_space
            && path.first_to_keep
            && !integrand.contributes_throughout(0.0, 1.0)
        {
            // A ray's first descent from another ray's nodes: a descent from the root would have stopped at the first
            // of them whose values cannot contribute for this ray (min/max culling, below), so keep none below it.
            // (Isosurfaces contribute anywhere before they have read data, as at a first descent: no test then.)
            if let Some(culled) = (0..keep - 1).find(|&level| {
                path.entries[level].node.brick().is_some_and(|slot| {
                    let [lo, hi] = self.view.brick_range(slot);
                    !integrand.can_contribute(lo, hi)
                })
            }) {
                keep = culled + 1;
            }
        }
        path.len = keep;
        let kept = keep;
        loop {
            let level = (path.len - 1) as u32;
            let PathEntry { id, node, ijk } = path.entries[path.len - 1];
            match node.data() {
                NodeData::Constant(value) => {
                    // Under a brick still fading in, the brick stands in (as for its other descendants).
                    if self.view.brick_blends.is_empty() || first_fading(path, self.view.brick_blends, level).is_none()
                    {
                        *nodes_entered += (path.len - kept) as u64;
                        path.descended(kept);
                        return (SegmentData::Constant(value), level, ijk);
                    }
                    break;
                }
                NodeData::Brick(_) => {}
                NodeData::Missing => {
                    // The parent stands in: drawn one level above this node.
                    let deficit = (target_level + 1).saturating_sub(level).min(u8::MAX as u32) as u8;
                    request.push(Request { node: id, kind: RequestKind::Produce, deficit });
                    break;
                }
            }
            if level >= target_level || node.is_terminal() {
                break;
            }
            // A subtree whose values cannot matter is one segment, skipped whole and never loaded deeper (Knoll et
            // al.'s min/max culling). Only for span integrands that place no samples: the sampled ones place their
            // samples by the step of each finer node, which skipping here would shift.
            if I::TAKES_SPANS && I::CULLS_SUBTREES && self.skip_empty_space {
                if let Some(slot) = node.brick() {
                    let [lo, hi] = self.view.brick_range(slot);
                    if !integrand.can_contribute(lo, hi) {
                        break;
                    }
                }
            }
            let Some(tile) = node.child_tile() else {
                let deficit = target_level.saturating_sub(level).min(u8::MAX as u32) as u8;
                request.push(Request { node: id, kind: RequestKind::Subdivide, deficit });
                break;
            };
            self.feedback.mark_tile(tile);
            let s = self.scale[level as usize + 1];
            let mut child_ijk = [0u64; 3];
            let mut child_index = 0u64;
            let mut stride = 1u64;
            for a in 0..3 {
                let lo = ijk[a] * n;
                // Positions are non-negative, so truncation is floor.
                let g = ((pa[a] * s) as i64 as u64).clamp(lo, lo + n - 1);
                child_ijk[a] = g;
                child_index += (g - lo) * stride;
                stride *= n;
            }
            let (child_id, child) = self.view.child(tile, child_index as u32);
            if let Some(slot) = child.brick() {
                self.feedback.mark_brick(slot);
            }
            path.entries[path.len] = PathEntry { id: child_id, node: child, ijk: child_ijk };
            path.len += 1;
        }
        *nodes_entered += (path.len - kept) as u64;
        path.descended(kept);
        // Every node on the path but the last holds a brick; find the two deepest bricks.
        let deepest = path.len - 1;
        let last = path.entries[deepest];
        let brick_at = |level: usize| {
            path.entries[level].node.brick().map(|slot| BrickRef {
                slot,
                level: level as u32,
                ijk: path.entries[level].ijk,
            })
        };
        let mut fine_level = if last.node.brick().is_some() { Some(deepest) } else { deepest.checked_sub(1) };
        if let (Some(fine), false) = (fine_level, self.view.brick_blends.is_empty()) {
            // Level blending: the first brick on the path that has not faded in completely is drawn (blended with
            // its parent), none below it (see `voxstream_core::level_blending`).
            if let Some(fading) = first_fading(path, self.view.brick_blends, fine as u32) {
                fine_level = Some(fading);
            }
        }
        // The data is final where the fine brick is the deepest node and either at the wanted level or terminal.
        let is_final = fine_level == Some(deepest) && (deepest as u32 >= target_level || last.node.is_terminal());
        let data = match fine_level.and_then(|l| brick_at(l).map(|b| (l, b))) {
            None => SegmentData::Nothing,
            Some((l, fine)) => SegmentData::Bricks {
                fine,
                coarse: l.checked_sub(1).and_then(brick_at),
                // Blend with the parent only when the finest data is at the level the cone asked for.
                blend_level: fine.level == target_level,
                stand_in: !is_final,
            },
        };
        (data, deepest as u32, last.ijk)
    }
}

/// One sample on each lane's line ([`values_across`]), with gradients when `GRADIENT`.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn samples_across<V: Voxel, const GRADIENT: bool>(
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

/// The fine brick's weight against its parent along a segment: `first + k·step` at sample `k` (a constant when
/// `step` is 0, the same bits as a plain weight).
#[derive(Clone, Copy, Debug)]
struct WeightRamp {
    first: f32,
    step: f32,
}

impl WeightRamp {
    /// The fine brick alone.
    const FINE: WeightRamp = WeightRamp { first: 1.0, step: 0.0 };

    /// From `first` at sample 0 to `last` at sample `count − 1`.
    #[inline]
    fn between(first: f32, last: f32, count: u64) -> WeightRamp {
        let step = if count > 1 { (last - first) / (count - 1) as f32 } else { 0.0 };
        WeightRamp { first, step }
    }

    /// Whether the ramp is the fine brick alone everywhere.
    #[inline]
    fn is_fine(self) -> bool {
        self.first >= 1.0 && self.first + self.step >= 1.0
    }

    #[inline(always)]
    fn at(self, k: f32) -> f32 {
        self.first + k * self.step
    }
}

/// The shallowest level above `below` on the path whose brick has not faded in completely.
#[inline]
fn first_fading(path: &DescentPath, blends: &[BrickBlend], below: u32) -> Option<usize> {
    (0..below as usize).find(|&level| {
        path.entries[level].node.brick().and_then(|slot| blends.get(slot.0 as usize)).is_some_and(|b| !b.is_in())
    })
}

/// How a segment's samples blend the fine brick with its parent: values by `value` (the cone's level weight, capped
/// by level blending), gradients by `gradient` when level blending caps the brick (else the fine brick's).
#[derive(Clone, Copy, Debug)]
struct Blend {
    value: WeightRamp,
    gradient: Option<WeightRamp>,
}

impl Blend {
    /// The fine brick alone.
    const FINE: Blend = Blend { value: WeightRamp::FINE, gradient: None };
}

/// How a run of samples ended: `Break(n)` after `n` samples when the integrand stopped the ray.
type RunFlow = ControlFlow<u64>;

/// Where a ray's requests go, with its remaining allowance for this frame.
struct RequestSink<'v> {
    requests: &'v mut Vec<Request>,
    remaining: u32,
    /// Whether a request was pushed.
    pushed: bool,
}

impl RequestSink<'_> {
    #[inline]
    fn push(&mut self, request: Request) {
        if self.remaining > 0 {
            self.remaining -= 1;
            self.requests.push(request);
            self.pushed = true;
        }
    }
}

/// One ray on its way through the tree, between segments: what [`Traversal::next_march`] needs to go on.
#[derive(Clone, Copy, Debug)]
struct RayWalk {
    ray: Ray,
    /// Volume units travelled per unit of `t`.
    speed: f64,
    inverse_direction: DVec3,
    /// Where the next segment starts.
    t: f64,
    /// Where the ray leaves the (clipped) volume.
    t_leave: f64,
    /// The distance up to which samples have accounted for the ray.
    covered: f64,
    /// The current step (None before the first brick segment).
    step: Option<StepLength>,
    segments: u32,
    /// The previous segment's level of detail (where [`Traversal::footprint_at`] starts its search).
    level_hint: usize,
    /// Requests this ray may still make this pass.
    requests_left: u32,
    /// Whether it made any (its pixel must be traced again).
    requested: bool,
}

/// One ray in a lane of [`Traversal::trace_stream`]: its id, walk and integrand, and the run of samples it is in.
struct Lane<'v, I> {
    id: usize,
    walk: RayWalk,
    integrand: I,
    run: Option<LaneRun<'v>>,
}

/// A lane's run of samples: samples `k..end` of a segment of `count` samples `first + k·dt` on `line` need no
/// block check; `resume` is where the next run may start (see [`Traversal::next_run`]).
struct LaneRun<'v> {
    line: BrickLine<'v>,
    first: f64,
    dt: f64,
    count: u32,
    k: u32,
    end: u32,
    resume: Option<u32>,
}

/// Where a stream's lanes get rays and leave them.
struct LaneSources<'s, N, F> {
    next_ray: &'s mut N,
    finish: &'s mut F,
    exhausted: &'s mut bool,
}

/// The samples of one brick segment: `count` points `first + k·dt` in `fine`, blended with `coarse` when given.
#[derive(Clone, Copy, Debug)]
struct March {
    fine: BrickRef,
    coarse: Option<(BrickRef, Blend)>,
    first: f64,
    dt: f64,
    count: u64,
}

/// The `t` at which a brick line leaves the occupancy block at `ijk` (block coordinates).
#[inline]
fn block_exit(line: &BrickLine<'_>, ijk: [usize; 3]) -> f64 {
    let mut exit = f64::INFINITY;
    for (a, &block) in ijk.iter().enumerate() {
        let rate = line.rate[a];
        let edge = if rate > 0.0 {
            ((block + 1) * BLOCK_CELLS) as f64
        } else if rate < 0.0 {
            (block * BLOCK_CELLS) as f64
        } else {
            continue;
        };
        exit = exit.min((edge - line.origin[a]) * line.inverse_rate[a]);
    }
    exit
}

/// A distance along the ray (moving at `speed` volume units per unit of `t`) of `1e-7` of a node of edge
/// `node_size`, plus more than the rounding of the point `p` at `t`: far below any node, well above rounding.
#[inline]
fn sliver(node_size: f64, p: DVec3, t: f64, speed: f64) -> f64 {
    (node_size * 1e-7 + 8e-16 * p.abs().max_element()) / speed + 8e-16 * t
}

/// Distance at which a ray inside (or on) the cube `[lower, lower + size]` leaves it; `1/direction` precomputed.
#[inline]
fn exit_distance(origin: DVec3, inverse_direction: DVec3, lower: DVec3, size: f64) -> f64 {
    let mut exit = f64::INFINITY;
    for a in 0..3 {
        let inv = inverse_direction[a];
        if inv.is_finite() {
            let bound = if inv > 0.0 { lower[a] + size } else { lower[a] };
            exit = exit.min((bound - origin[a]) * inv);
        }
    }
    exit
}

/// Slab test against the box `[lower, upper]`; returns `(t_enter, t_exit)` when hit ahead.
#[inline]
pub fn intersect_aabb(origin: DVec3, direction: DVec3, lower: DVec3, upper: DVec3) -> Option<(f64, f64)> {
    let size = upper - lower;
    // Scale to a unit cube so one slab test serves both.
    let o = (origin - lower) / size;
    let d = direction / size;
    intersect_box(o, d, DVec3::ZERO, 1.0)
}

/// Slab test against the axis-aligned cube `[lower, lower + size]`; returns `(t_enter, t_exit)` when hit ahead.
#[inline]
pub fn intersect_box(origin: DVec3, direction: DVec3, lower: DVec3, size: f64) -> Option<(f64, f64)> {
    let upper = lower + DVec3::splat(size);
    let mut t0 = f64::NEG_INFINITY;
    let mut t1 = f64::INFINITY;
    for a in 0..3 {
        let (o, d) = (origin[a], direction[a]);
        if d == 0.0 {
            if o < lower[a] || o > upper[a] {
                return None;
            }
            continue;
        }
        let inv = 1.0 / d;
        let (mut near, mut far) = ((lower[a] - o) * inv, (upper[a] - o) * inv);
        if near > far {
            std::mem::swap(&mut near, &mut far);
        }
        t0 = t0.max(near);
        t1 = t1.min(far);
    }
    (t1 >= t0.max(0.0)).then_some((t0, t1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exit_distance_matches_the_slab_test() {
        let origin = DVec3::new(0.3, 0.2, 0.9);
        let direction = DVec3::new(0.5, -0.3, 0.2).normalize();
        let (_, exit) = intersect_box(origin, direction, DVec3::ZERO, 1.0).unwrap();
        assert!((exit_distance(origin, DVec3::ONE / direction, DVec3::ZERO, 1.0) - exit).abs() < 1e-12);
        let axis = DVec3::new(0.0, 0.0, -1.0);
        assert!((exit_distance(origin, DVec3::ONE / axis, DVec3::ZERO, 1.0) - 0.9).abs() < 1e-12);
    }

    #[test]
    fn box_intersection() {
        let hit = intersect_box(DVec3::new(-1.0, 0.5, 0.5), DVec3::X, DVec3::ZERO, 1.0).unwrap();
        assert_eq!(hit, (1.0, 2.0));
        assert!(intersect_box(DVec3::new(-1.0, 2.0, 0.5), DVec3::X, DVec3::ZERO, 1.0).is_none());
        assert!(intersect_box(DVec3::new(2.0, 0.5, 0.5), DVec3::X, DVec3::ZERO, 1.0).is_none(), "box behind");
        let inside = intersect_box(DVec3::splat(0.5), DVec3::Y, DVec3::ZERO, 1.0).unwrap();
        assert_eq!(inside.1, 0.5);
    }
}
