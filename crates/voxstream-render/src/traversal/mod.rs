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
//!
//! The walk is split along its mechanisms, one module each: [`descent`] (the stackless descent, the kept path and
//! the requests), [`segments`] (a ray's walk from segment to segment: the node boxes, steps and level blending
//! weights of step 3), [`bricks`] (the samples inside a segment's bricks, blended between levels), [`block_runs`]
//! (step 4's runs of samples in occupancy blocks that can contribute), [`lanes`] (many rays side by side, sampled
//! together) and [`boxes`] (ray–box intersections).

mod block_runs;
mod boxes;
mod bricks;
mod descent;
mod lanes;
mod segments;
#[cfg(test)]
mod step_choice_tests;
#[cfg(test)]
mod test_tree;

use glam::DVec3;
use voxstream_core::{Dequantize, FeedbackBuffer, Request, TreeView};

use crate::clip_plane::VolumePlane;
use crate::gathered_corners::CornerGather;
use crate::integrand::Integrand;
use crate::settings::RenderSettings;

pub use boxes::{intersect_aabb, intersect_box};
pub use descent::DescentPath;

/// Deepest level the precomputed scale table covers.
const MAX_TABLE_LEVELS: usize = 64;
/// A ray may not cross more segments than this (guards against any numerical stall).
const MAX_SEGMENTS: u32 = 1 << 20;

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
    /// The view's clipping planes in unit-cube coordinates ([`crate::clip_plane`]).
    clip_planes: Vec<VolumePlane>,
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
            clip_planes: settings.clip_planes.iter().map(|p| VolumePlane::new(p, &settings.placement)).collect(),
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
}
