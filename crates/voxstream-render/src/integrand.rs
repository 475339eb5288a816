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

use std::ops::ControlFlow;

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

/// Consumes the samples of one ray.
pub trait Integrand {
    /// Whether some normalised value in `[lower, upper]` can change the result. The traversal skips bricks and
    /// occupancy blocks whose values all lie in a range that cannot, so this must be conservative: skipping must not
    /// change a single bit of the result.
    fn can_contribute(&self, lower: f32, upper: f32) -> bool;

    /// Whether [`Sample::gradient`] is needed (it costs a few operations per sample).
    fn wants_gradient(&self) -> bool;

    /// The step that every following sample stands for, until the next call.
    fn set_step(&mut self, step: StepLength);

    /// One sample; `Break` ends the ray (e.g. once it is opaque).
    fn sample(&mut self, sample: Sample) -> ControlFlow<()>;

    /// A constant `value` (a constant node) over the distances `[from, to)`, to integrate analytically.
    fn constant(&mut self, from: f64, to: f64, value: f32) -> ControlFlow<()>;
}
