//! Intensity projections: the largest, smallest or mean value along each ray (MIP, MinIP, mean), the blend modes
//! ParaView and napari offer beside compositing, as one more [`Integrand`] of the one traversal.
//!
//! The traversal hands over samples (and constant nodes) as for emission–absorption; the integrand keeps their
//! maximum, minimum or length-weighted mean. The projected value is shown in the transfer function's colour at it,
//! with the transfer function's opacity there relative to its most opaque point (a window: where the transfer
//! function is transparent the background shows, where it is most opaque the pixel is opaque), as VTK's
//! maximum-intensity blend maps the value through its colour and opacity functions.
//!
//! Skipping is exact, as the traversal requires ([`Integrand::can_contribute`]): once a ray's maximum is `m`, a
//! brick or occupancy block whose values all lie at or below `m` cannot change it, so it is neither sampled nor
//! loaded (for the minimum, at or above). The mean takes every sample. Like every integrand, the projection samples
//! the level of detail the cone asks for (GigaVoxels [P09] §6): far away, a maximum of averaged voxels; raise
//! `lod_bias` for finer levels.

use std::ops::ControlFlow;

use glam::DVec3;
use serde::{Deserialize, Serialize};
use voxstream_core::{FeedbackBuffer, Request, TreeView};

use crate::frame::PixelTracer;
use crate::integrand::{Integrand, Sample};
use crate::settings::RenderSettings;
use crate::step_table::StepLength;
use crate::transfer_function::TransferLut;
use crate::traversal::{DescentPath, Ray, RayStats, Traversal};

/// How samples along a ray make a pixel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Projection {
    /// Emission–absorption compositing (volume rendering), or isosurfaces.
    #[default]
    Composite,
    /// The largest value along the ray (maximum-intensity projection).
    Maximum,
    /// The smallest value along the ray (minimum-intensity projection).
    Minimum,
    /// The mean value along the ray, weighted by the length each sample stands for.
    Mean,
}

impl Projection {
    /// The name on the command line (`--projection`).
    pub fn name(self) -> &'static str {
        match self {
            Projection::Composite => "composite",
            Projection::Maximum => "max",
            Projection::Minimum => "min",
            Projection::Mean => "mean",
        }
    }
}

/// One ray's projected value so far.
#[derive(Clone, Copy, Debug)]
pub struct ProjectedValue {
    kind: Projection,
    /// The extreme so far (Maximum, Minimum); NaN before the first sample.
    extreme: f32,
    /// Mean: the sum of values times the length they stand for, and that length.
    weighted_sum: f64,
    length: f64,
    /// The length the following samples stand for.
    step: f64,
}

impl ProjectedValue {
    /// A ray with nothing seen yet.
    pub fn new(kind: Projection) -> ProjectedValue {
        ProjectedValue { kind, extreme: f32::NAN, weighted_sum: 0.0, length: 0.0, step: 0.0 }
    }

    /// The projected normalised value, `None` where the ray met no data.
    pub fn value(&self) -> Option<f32> {
        match self.kind {
            Projection::Mean => (self.length > 0.0).then(|| (self.weighted_sum / self.length) as f32),
            _ => (!self.extreme.is_nan()).then_some(self.extreme),
        }
    }

    #[inline(always)]
    fn take(&mut self, value: f32, length: f64) {
        match self.kind {
            Projection::Maximum => {
                if !(value <= self.extreme) && !value.is_nan() {
                    self.extreme = value;
                }
            }
            Projection::Minimum => {
                if !(value >= self.extreme) && !value.is_nan() {
                    self.extreme = value;
                }
            }
            Projection::Mean | Projection::Composite => {
                if value.is_finite() {
                    self.weighted_sum += value as f64 * length;
                    self.length += length;
                }
            }
        }
    }
}

impl Integrand for ProjectedValue {
    #[inline(always)]
    fn can_contribute(&self, lower: f32, upper: f32) -> bool {
        match self.kind {
            // Before the first sample `extreme` is NaN and every comparison with it is false: all may contribute.
            Projection::Maximum => !(upper <= self.extreme),
            Projection::Minimum => !(lower >= self.extreme),
            Projection::Mean | Projection::Composite => true,
        }
    }

    #[inline(always)]
    fn wants_gradient(&self) -> bool {
        false
    }

    #[inline(always)]
    fn set_step(&mut self, step: StepLength) {
        self.step = step.world;
    }

    #[inline(always)]
    fn sample(&mut self, sample: Sample) -> ControlFlow<()> {
        self.take(sample.value, self.step);
        ControlFlow::Continue(())
    }

    #[inline(always)]
    fn constant(&mut self, from: f64, to: f64, value: f32) -> ControlFlow<()> {
        self.take(value, (to - from).max(0.0));
        ControlFlow::Continue(())
    }
}

/// How a projected value is shown: the transfer function's colour there, and its opacity relative to the most
/// opaque entry of the table.
#[derive(Clone, Copy, Debug)]
pub struct ProjectionShading<'a> {
    lut: &'a TransferLut,
    /// `1 / σ_max` over the table (0 for a transparent function: every pixel shows the background).
    inverse_max_sigma: f32,
}

impl<'a> ProjectionShading<'a> {
    /// For the transfer function `lut`.
    pub fn new(lut: &'a TransferLut) -> ProjectionShading<'a> {
        let max_sigma = lut.entries().iter().map(|e| e.sigma).fold(0.0f32, f32::max);
        ProjectionShading { lut, inverse_max_sigma: if max_sigma > 0.0 { 1.0 / max_sigma } else { 0.0 } }
    }

    /// Premultiplied colour and opacity of the normalised value `value` (`None`: nothing, transparent).
    pub fn shade(&self, value: Option<f32>) -> ([f32; 3], f32) {
        let Some(value) = value else { return ([0.0; 3], 0.0) };
        let entry = self.lut.lookup(value);
        let alpha = (entry.sigma * self.inverse_max_sigma).clamp(0.0, 1.0);
        (entry.color.map(|c| c * alpha), alpha)
    }
}

/// Traces projection rays against one frame's tree view, writing feedback.
pub struct ProjectionCaster<'a> {
    traversal: Traversal<'a>,
    kind: Projection,
    shading: ProjectionShading<'a>,
}

impl<'a> ProjectionCaster<'a> {
    /// Prepares a projection caster for one frame of `settings.projection`.
    pub fn new(
        view: TreeView<'a>,
        feedback: &'a FeedbackBuffer,
        lut: &'a TransferLut,
        settings: &RenderSettings,
    ) -> ProjectionCaster<'a> {
        ProjectionCaster {
            traversal: Traversal::new(view, feedback, settings),
            kind: settings.projection,
            shading: ProjectionShading::new(lut),
        }
    }
}

impl PixelTracer for ProjectionCaster<'_> {
    fn view(&self) -> TreeView<'_> {
        self.traversal.view()
    }

    #[inline(always)]
    fn trace(
        &self,
        origin: DVec3,
        direction: DVec3,
        spread: f64,
        stats: &mut RayStats,
        requests: &mut Vec<Request>,
        path: &mut DescentPath,
    ) -> ([f32; 3], f32) {
        let ray = Ray { origin, direction, spread, start: 0.0 };
        let mut projected = ProjectedValue::new(self.kind);
        self.traversal.trace(&ray, &mut projected, stats, requests, path);
        self.shading.shade(projected.value())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::transfer_function::TransferFunction;

    fn sample(value: f32) -> Sample {
        Sample { t: 0.0, value, gradient: [0.0; 3] }
    }

    #[test]
    fn each_projection_keeps_its_value_and_says_what_can_change_it() {
        let values = [0.3, 0.8, f32::NAN, 0.1, 0.5];
        let mut max = ProjectedValue::new(Projection::Maximum);
        let mut min = ProjectedValue::new(Projection::Minimum);
        let mut mean = ProjectedValue::new(Projection::Mean);
        assert!(max.can_contribute(0.0, 0.0) && min.can_contribute(1.0, 1.0), "before any sample, everything");
        assert_eq!(max.value(), None);
        for ray in [&mut max, &mut min, &mut mean] {
            ray.set_step(StepLength::at_most(0.5));
            let step = ray.step;
            for v in values {
                let _ = ray.sample(sample(v));
            }
            // A constant node of 0.9 over four steps.
            let _ = ray.constant(1.0, 1.0 + 4.0 * step, 0.9);
        }
        assert_eq!(max.value(), Some(0.9));
        assert_eq!(min.value(), Some(0.1));
        // Four finite samples and four steps of 0.9: (0.3 + 0.8 + 0.1 + 0.5 + 3.6) / 8.
        let expected = (0.3 + 0.8 + 0.1 + 0.5 + 3.6) / 8.0;
        assert!((mean.value().unwrap() - expected).abs() < 1e-6, "{:?}", mean.value());
        assert!(!max.can_contribute(0.2, 0.9) && max.can_contribute(0.2, 0.91));
        assert!(!min.can_contribute(0.1, 0.5) && min.can_contribute(0.09, 0.5));
        assert!(mean.can_contribute(0.0, 0.0));
    }

    #[test]
    fn the_value_takes_the_transfer_functions_colour_and_relative_opacity() {
        // Transparent below 0.25, half as opaque at 0.5 as at 1 (in extinction).
        let tf = TransferFunction::new(
            vec![[0.0, 0.0, 0.0, 1.0, 0.0], [0.25, 0.0, 0.0, 1.0, 0.0], [1.0, 1.0, 0.5, 0.0, 0.5]],
            Some(1.0),
        )
        .expect("valid function");
        let lut = TransferLut::new(&tf, 0.0, 1.0, 1.0);
        let shading = ProjectionShading::new(&lut);
        assert_eq!(shading.shade(None), ([0.0; 3], 0.0));
        assert_eq!(shading.shade(Some(0.1)).1, 0.0);
        let (colour, alpha) = shading.shade(Some(1.0));
        assert!((alpha - 1.0).abs() < 1e-6);
        assert!((colour[0] - 1.0).abs() < 1e-6 && (colour[1] - 0.5).abs() < 1e-6 && colour[2].abs() < 1e-6);
        let (_, half) = shading.shade(Some(0.625));
        assert!(half > 0.2 && half < 0.8, "between: {half}");
    }
}
