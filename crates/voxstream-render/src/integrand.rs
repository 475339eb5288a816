//! What the traversal hands out, and the interface of whatever consumes it.
//!
//! The traversal ([`crate::traversal`]) walks the tree and produces samples; an [`Integrand`] turns them into a
//! result: emission–absorption colour ([`crate::emission_absorption`]) today; first-hit isosurfaces (Knoll et al.)
//! and Thiele's blending weights next, each without a copy of the traversal. The split follows pbrt-v4's
//! `SampleTmaj(ray, tMax, u, rng, lambda, callback)` (`src/pbrt/media.h`): the medium walks its majorant segments and
//! calls back at each point; the callback decides what the point contributes and whether to go on. As in Open VKL's
//! interval iterators, the traversal first asks whether a value range can contribute at all, and skips it otherwise.
//!
//! Every method is called in ray order. Generic dispatch (`trace::<I>`) inlines the integrand into the sample loop.
//!
//! An integrand that needs the field itself rather than samples of it (exact isosurfaces solve a cubic per trilinear
//! cell, [`crate::isosurface`]) sets [`Integrand::TAKES_SPANS`] and receives each brick segment whole, as a
//! [`BrickSpan`]: the brick's voxels and the ray's line through them, which [`crate::cell_walk`] walks cell by cell.

use std::ops::ControlFlow;

use voxstream_core::{Dequantize, PoolVoxels};

use crate::block_visibility::BlockVisibility;
use crate::step_table::StepLength;

/// One sample of the field along a ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// Distance along the ray, world units.
    pub t: f64,
    /// Value, normalised to `[0, 1]` over the data range (what bricks hold).
    pub value: f32,
    /// Gradient in value per voxel of the finer sampled level, brick axes (zero unless
    /// [`Integrand::wants_gradient`]).
    pub gradient: [f32; 3],
}

/// One brick segment of a ray: the brick (the finest resident at the cone's level) and the ray's continuous voxel
/// index in it, `x(t) = origin + t·rate`, over the distances `[from, to)`. Index `i` is voxel `i` of the stored brick
/// (border included), so the segment's cells are `⌊x⌋ ∈ [0, B−2]` for `B` stored voxels per axis.
#[derive(Clone, Copy, Debug)]
pub struct BrickSpan<'v> {
    /// The brick's voxels, `B³`, x fastest.
    pub voxels: PoolVoxels<'v>,
    /// How its stored voxels map to values.
    pub dequantize: Dequantize,
    /// Stored voxels per axis, `B = M + 2`.
    pub stored: usize,
    /// Continuous voxel index at `t = 0`.
    pub origin: [f64; 3],
    /// Voxels per world unit of `t`, per axis.
    pub rate: [f64; 3],
    /// Where the segment starts.
    pub from: f64,
    /// Where it ends.
    pub to: f64,
    /// Value ranges of the brick's occupancy blocks (stored units), `blocks³`, x fastest: block `(i, j, k)` bounds
    /// every trilinear value in the cells `8i .. 8i+8` (and so on) ([`voxstream_core::BLOCK_CELLS`]).
    pub block_ranges: &'v [[u16; 2]],
    /// Blocks per axis.
    pub blocks: usize,
    /// Whether blocks the integrand cannot use may be skipped (off only to test that skipping is exact).
    pub cull_blocks: bool,
    /// The step (world units of `t`) the volume renderer samples this segment at: the cone's footprint or the
    /// brick's voxel, whichever is larger, times the step factor (for integrands that also sample a volume,
    /// [`crate::surfaces_in_volume`]).
    pub step: f64,
}

/// Consumes the samples of one ray.
pub trait Integrand {
    /// Whether brick segments come whole ([`Integrand::span`]) instead of as samples ([`Integrand::sample`]).
    const TAKES_SPANS: bool = false;

    /// Whether a descent may stop at a subtree none of whose values can contribute and skip it as one segment,
    /// never loading deeper (Knoll et al.'s min/max culling; span integrands only). An integrand that also samples
    /// a volume keeps it off: its samples are placed by the step of each finer node, which skipping would shift.
    const CULLS_SUBTREES: bool = Self::TAKES_SPANS;

    /// Whether each run of samples in occupancy blocks that can contribute is widened by one sample on both sides
    /// (and a segment's runs that touch its ends get its [`Integrand::edge`] samples):
    /// for integrands whose samples' contributions depend on their neighbours (pre-integration, where the segment
    /// from a run's last sample to the skipped one after it can cross visible values). Such an integrand passes over
    /// a sample at or before one it has taken.
    const DILATED_RUNS: bool = false;

    /// With [`Integrand::DILATED_RUNS`]: the sample one step beyond a segment's start (`before`; only where the
    /// segment before was a brick segment too) or end, evaluated in the segment's bricks, where a run of samples
    /// reaches that end. It is not a sample of the ray (it lies in
    /// the neighbouring segment, which may hand over its own); it tells the integrand what the field does next to
    /// the run, for opening or closing it.
    #[inline(always)]
    fn edge(&mut self, sample: Sample, before: bool) {
        let _ = (sample, before);
    }

    /// A segment of empty space (a node with no data) over which nothing is sampled.
    #[inline(always)]
    fn gap(&mut self) -> ControlFlow<()> {
        ControlFlow::Continue(())
    }

    /// Whether some normalised value in `[lower, upper]` can change the result. The traversal skips bricks and
    /// occupancy blocks whose values all lie in a range that cannot, so this must be conservative: skipping must not
    /// change a single bit of the result.
    fn can_contribute(&self, lower: f32, upper: f32) -> bool;

    /// Whether every value in `[lower, upper]` can change the result, so that [`Integrand::can_contribute`] holds
    /// for every range inside it: the traversal then checks no occupancy block of a brick whose values lie there.
    /// `false` is always correct (the default).
    #[inline(always)]
    fn contributes_throughout(&self, lower: f32, upper: f32) -> bool {
        let _ = (lower, upper);
        false
    }

    /// The bits of [`Integrand::can_contribute`] for every occupancy block, computed once per brick and pass
    /// ([`BlockVisibility`]), when this integrand has them: the traversal then reads a bit per block instead of
    /// testing its range. They must have been made for this integrand's configuration and the traversal's tree view
    /// (`None`, the default, is always correct).
    #[inline(always)]
    fn block_visibility(&self) -> Option<&BlockVisibility> {
        None
    }

    /// Whether [`Sample::gradient`] is needed (it costs a few operations per sample).
    fn wants_gradient(&self) -> bool;

    /// Whether this integrand chooses its step per brick segment ([`Integrand::adapt_step`]); `false` (the
    /// default): the fixed step, and the traversal asks nothing.
    #[inline(always)]
    fn adapts_step(&self) -> bool {
        false
    }

    /// The step (world units of `t`) for a brick segment whose values lie in `[lower, upper]`, given the fixed step
    /// `base` there: at least `base` ([`crate::adaptive_step`]). Only asked when [`Integrand::adapts_step`].
    #[inline(always)]
    fn adapt_step(&self, lower: f32, upper: f32, base: f64) -> f64 {
        let _ = (lower, upper);
        base
    }

    /// The step that every following sample stands for, until the next call.
    fn set_step(&mut self, step: StepLength);

    /// One sample; `Break` ends the ray (e.g. once it is opaque).
    fn sample(&mut self, sample: Sample) -> ControlFlow<()>;

    /// A constant `value` (a constant node) over the distances `[from, to)`, to integrate analytically.
    fn constant(&mut self, from: f64, to: f64, value: f32) -> ControlFlow<()>;

    /// The tree level of the data the following samples or constant come from (called once per segment). Only
    /// diagnostic integrands use it ([`RenderSettings::colour_by_level`](crate::RenderSettings::colour_by_level)).
    #[inline(always)]
    fn set_level(&mut self, level: u32) {
        let _ = level;
    }

    /// A brick segment over `[from, to)` skipped because nothing in its bricks can contribute (only when
    /// [`Integrand::TAKES_SPANS`]), with the volume renderer's `step` there ([`BrickSpan::step`]): for integrands
    /// that keep sample positions along the ray, so that skipping moves none of them.
    #[inline(always)]
    fn skip_span(&mut self, from: f64, to: f64, step: f64) {
        let _ = (from, to, step);
    }

    /// A whole brick segment (only when [`Integrand::TAKES_SPANS`]); adds the work done (cells examined) to `work`.
    fn span(&mut self, span: &BrickSpan<'_>, work: &mut u64) -> ControlFlow<()> {
        let _ = (span, work);
        ControlFlow::Continue(())
    }
}
