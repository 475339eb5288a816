//! Emission–absorption volume rendering: the first [`Integrand`].
//!
//! Front-to-back compositing of [R08] §5 / GigaVoxels [P09] §6: each sample adds `T·α·c` and multiplies the
//! transmittance `T` by `1 − α`, where `α·c` and `α` come premultiplied from the transfer function's table for the
//! current step ([`crate::step_table`]: no `exp` per sample). Optional two-sided Phong shading with the trilinear
//! field's analytic gradient as normal. The ray stops once its opacity reaches the cutoff.

use std::ops::ControlFlow;

use glam::{DVec3, Vec3, Vec4};

use crate::adaptive_step::StepVariation;
use crate::block_visibility::BlockVisibility;
use crate::integrand::{Integrand, Sample};
use crate::lighting::{LightingSettings, RayLight};
use crate::preintegration::PreIntegration;
use crate::settings::RenderSettings;
use crate::step_table::{StepLength, StepTable, STEPS_PER_OCTAVE};
use crate::transfer_function::TransferLut;

/// What stays the same for every ray of a frame.
#[derive(Clone, Copy, Debug)]
pub struct EmissionAbsorptionSettings {
    lighting: LightingSettings,
    /// Transmittance below which a ray stops.
    stop_below: f32,
    /// Colour samples by their data's tree level ([`RenderSettings::colour_by_level`]).
    colour_by_level: bool,
    /// The adaptive step's tolerance ([`RenderSettings::adaptive_step`]).
    adaptive_step: Option<f64>,
}

impl EmissionAbsorptionSettings {
    /// From the frame's settings.
    pub fn new(settings: &RenderSettings) -> EmissionAbsorptionSettings {
        EmissionAbsorptionSettings {
            lighting: LightingSettings::new(settings),
            stop_below: 1.0 - settings.opacity_cutoff,
            colour_by_level: settings.colour_by_level,
            adaptive_step: settings.adaptive_step,
        }
    }
}

/// A pre-integrating ray's last sample, whose segment to the next sample is not known yet.
#[derive(Clone, Copy, Debug)]
struct Pending {
    t: f64,
    value: f32,
    gradient: [f32; 3],
    /// The step it stands for.
    step: f64,
}

/// What a pre-integrating ray keeps between samples ([`crate::preintegration`]).
///
/// Samples stand for the ray as before (each its step around it, tiling the ray); pre-integrated, the ray between
/// two consecutive samples is one segment, integrated over the values between theirs. A run of consecutive samples
/// is closed at both ends by half a step of its end sample's own value, so a run accounts for exactly the distance
/// its samples stand for: where samples are not consecutive (a constant node, the volume's end, invisible blocks
/// skipped) nothing is integrated across the gap. The traversal widens the runs it hands over by the skipped sample
/// on either side ([`Integrand::DILATED_RUNS`]), whose own step is transparent but whose segment to the run is not
/// always.
#[derive(Clone, Copy, Debug)]
struct PreIntegrating<'a> {
    table: &'a PreIntegration,
    /// The half-step table of the current step.
    half_table: Option<&'a StepTable>,
    /// The current step, world units.
    step: f64,
    pending: Option<Pending>,
    /// The value one step after `pending` where the traversal handed it over as a run's back edge
    /// ([`Integrand::edge`]): if the ray does not go on from `pending` by the next sample, the run is closed by the
    /// segment towards it (the skipped sample's) instead of a half step.
    back: Option<(f64, f32)>,
    /// A front edge: `(t, value)` one step before where the next run starts (a skipped sample), whose segment to
    /// the run's first sample then opens the run instead of a half step.
    front: Option<(f64, f32)>,
}

impl PreIntegrating<'_> {
    /// Where the sample after `last` lies when they are consecutive: half of each one's step on (the steps may
    /// differ across segments).
    #[inline(always)]
    fn next_after(&self, last: &Pending) -> f64 {
        last.t + 0.5 * (last.step + self.step)
    }

    /// How far two distances along the ray may differ and still be the same place: a thousandth of the step (far
    /// above their rounding, far below a step).
    #[inline(always)]
    fn slack(&self) -> f64 {
        1e-3 * self.step
    }
}

/// The colour and opacity accumulated along one ray; `PRE`: pre-integrated segments between samples
/// ([`RenderSettings::preintegrated`]), a type of its own so that the default ray's sample loop holds no test of it.
pub struct EmissionAbsorption<'a, const PRE: bool = false> {
    lut: &'a TransferLut,
    table: Option<&'a StepTable>,
    light: Option<RayLight>,
    gradient_scale: Vec3,
    stop_below: f32,
    /// Whether samples take their level's colour.
    colour_by_level: bool,
    /// With `colour_by_level`: the colour of the current segment's level.
    tint: Option<Vec3>,
    /// Premultiplied colour so far.
    color: Vec3,
    transmittance: f32,
    /// The bits of [`Integrand::can_contribute`] per occupancy block, when the caller made them for this ray's
    /// transfer function and tree view ([`EmissionAbsorption::with_block_visibility`]).
    block_visibility: Option<&'a BlockVisibility>,
    /// With [`RenderSettings::preintegrated`]: the segments' state.
    preintegrating: Option<PreIntegrating<'a>>,
    /// With [`RenderSettings::adaptive_step`]: the variation sums and the tolerance.
    adaptive: Option<(&'a StepVariation, f64)>,
}

impl<'a, const PRE: bool> EmissionAbsorption<'a, PRE> {
    /// A ray with nothing accumulated; `volume_direction` is the ray's direction in volume units per world unit.
    #[inline(always)]
    pub fn new(
        lut: &'a TransferLut,
        settings: &EmissionAbsorptionSettings,
        volume_direction: DVec3,
    ) -> EmissionAbsorption<'a, PRE> {
        EmissionAbsorption {
            lut,
            table: None,
            light: settings.lighting.ray(volume_direction),
            gradient_scale: settings.lighting.gradient_scale,
            stop_below: settings.stop_below,
            colour_by_level: settings.colour_by_level,
            tint: None,
            color: Vec3::ZERO,
            transmittance: 1.0,
            block_visibility: None,
            preintegrating: PRE.then(|| PreIntegrating {
                table: lut.preintegration(),
                half_table: None,
                step: 0.0,
                pending: None,
                back: None,
                front: None,
            }),
            adaptive: settings.adaptive_step.map(|tolerance| (lut.variation(), tolerance)),
        }
    }

    /// The same ray, reading occupancy blocks' visibility from `visibility` when given, which must have been made
    /// for the transfer function `lut` of this ray and the tree view it is traced through.
    #[inline(always)]
    pub fn with_block_visibility(mut self, visibility: Option<&'a BlockVisibility>) -> EmissionAbsorption<'a, PRE> {
        self.block_visibility = visibility;
        self
    }

    /// Premultiplied `[r, g, b]` and opacity.
    pub fn result(&self) -> ([f32; 3], f32) {
        // A pre-integrating ray's last half step is still to be composited.
        if !PRE {
            return (self.color.to_array(), 1.0 - self.transmittance);
        }
        // The ray ends here (outside the volume, or opaque): a back edge is no data of the ray's.
        if let Some((entry, gradient)) = self.closing(false) {
            if let Some((color, alpha)) = self.shaded(entry.truncate(), entry.w, gradient) {
                let color = self.color + self.transmittance * color;
                return (color.to_array(), 1.0 - self.transmittance * (1.0 - alpha));
            }
        }
        (self.color.to_array(), 1.0 - self.transmittance)
    }

    /// A step's premultiplied colour as composited: tinted by level, shaded; `None` where it is transparent.
    #[inline(always)]
    fn shaded(&self, premultiplied: Vec3, alpha: f32, gradient: [f32; 3]) -> Option<(Vec3, f32)> {
        if alpha <= 0.0 {
            return None;
        }
        let premultiplied = match self.tint {
            None => premultiplied,
            Some(tint) => tint * alpha,
        };
        Some(match &self.light {
            Some(light) => (light.shade(premultiplied, alpha, Vec3::from(gradient) * self.gradient_scale), alpha),
            None => (premultiplied, alpha),
        })
    }

    /// Composites one step's premultiplied colour and opacity (unshaded) behind what the ray holds.
    #[inline(always)]
    fn composite(&mut self, premultiplied: Vec3, alpha: f32, gradient: [f32; 3]) -> ControlFlow<()> {
        if let Some((color, alpha)) = self.shaded(premultiplied, alpha, gradient) {
            self.color += self.transmittance * color;
            self.transmittance *= 1.0 - alpha;
        }
        if self.transmittance <= self.stop_below {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    }

    /// Closes a pre-integrated run: its last sample's half step behind it.
    #[inline]
    fn close_run(&mut self, towards_back: bool) -> ControlFlow<()> {
        let closing = self.closing(towards_back);
        if let Some(state) = self.preintegrating.as_mut() {
            (state.pending, state.back) = (None, None);
        }
        match closing {
            Some((entry, gradient)) => self.composite(entry.truncate(), entry.w, gradient),
            None => ControlFlow::Continue(()),
        }
    }

    /// What closes the current run: the half step after its last sample, or `towards_back` with a back edge, the
    /// segment from it to the edge's value (the skipped sample's: the field linear between them).
    #[inline]
    fn closing(&self, towards_back: bool) -> Option<(Vec4, [f32; 3])> {
        let state = self.preintegrating?;
        let last = state.pending?;
        let entry = match state.back.filter(|_| towards_back) {
            Some((t, back)) => state.table.segment(last.value, back, (t - last.t) as f32),
            None => state.half_table?.lookup(last.value),
        };
        Some((entry, last.gradient))
    }

    /// What opens a run at `sample`: the half step before it, or after a front edge one step before it, the
    /// segment from the edge's value (the skipped sample's).
    #[inline]
    fn opening(&self, sample: &Sample) -> Vec4 {
        let Some(state) = self.preintegrating else { return Vec4::ZERO };
        match state.front {
            Some((t, value)) if sample.t > t && sample.t - t <= state.step + state.slack() => {
                state.table.segment(value, sample.value, (sample.t - t) as f32)
            }
            _ => state.half_table.map_or(Vec4::ZERO, |t| t.lookup(sample.value)),
        }
    }

    /// One sample of a pre-integrating ray: the segment from the last sample when it is the one just before, else
    /// the last run closed and a new one opened by half a step of this sample's value (or from a front edge).
    #[inline(always)]
    fn sample_preintegrated(&mut self, sample: Sample) -> ControlFlow<()> {
        let Some(state) = self.preintegrating else { return ControlFlow::Continue(()) };
        // A sample before where the next consecutive one would be was taken already (a dilated run's sample taken
        // again by the next run, [`Integrand::DILATED_RUNS`]): passed over.
        if state.pending.is_some_and(|last| sample.t < state.next_after(&last) - state.slack()) {
            return ControlFlow::Continue(());
        }
        let consecutive = state.pending.filter(|last| (sample.t - state.next_after(last)).abs() <= state.slack());
        let next = Pending { t: sample.t, value: sample.value, gradient: sample.gradient, step: state.step };
        let flow = match consecutive {
            Some(last) => {
                let entry = state.table.segment(last.value, sample.value, (sample.t - last.t) as f32);
                // Shaded by the normal at the segment's middle (as a sample is by its own, at the middle of its
                // step): the two ends' gradients averaged.
                let gradient = std::array::from_fn(|a| 0.5 * (last.gradient[a] + sample.gradient[a]));
                self.composite(entry.truncate(), entry.w, gradient)
            }
            None => {
                if self.close_run(true).is_break() {
                    return ControlFlow::Break(());
                }
                let entry = self.opening(&sample);
                self.composite(entry.truncate(), entry.w, sample.gradient)
            }
        };
        if let Some(state) = self.preintegrating.as_mut() {
            (state.pending, state.back, state.front) = (Some(next), None, None);
        }
        flow
    }

    /// A run's edge sample (pre-integrating rays): remembered, to close or open the run with ([`Integrand::edge`]).
    #[inline(never)]
    fn edge_preintegrated(&mut self, sample: Sample, before: bool) {
        let Some(state) = self.preintegrating.as_mut() else { return };
        if before {
            // Not where the last run goes on anyway.
            if state.pending.is_none_or(|last| sample.t >= state.next_after(&last) + state.slack()) {
                state.front = Some((sample.t, sample.value));
            }
        } else if state
            .pending
            .is_some_and(|last| sample.t > last.t && sample.t <= state.next_after(&last) + state.slack())
        {
            state.back = Some((sample.t, sample.value));
        }
    }
}

impl<const PRE: bool> Integrand for EmissionAbsorption<'_, PRE> {
    const DILATED_RUNS: bool = PRE;

    #[inline(always)]
    fn can_contribute(&self, lower: f32, upper: f32) -> bool {
        // Pre-integrated too: a segment between a visible sample and a skipped one is taken by the runs' dilation
        // (`DILATED_RUNS`).
        self.lut.is_visible_in(lower, upper)
    }

    #[inline(always)]
    fn contributes_throughout(&self, lower: f32, upper: f32) -> bool {
        self.lut.is_visible_throughout(lower, upper)
    }

    #[inline(always)]
    fn block_visibility(&self) -> Option<&BlockVisibility> {
        self.block_visibility
    }

    #[inline]
    fn wants_gradient(&self) -> bool {
        self.light.is_some()
    }

    #[inline]
    fn edge(&mut self, sample: Sample, before: bool) {
        if PRE {
            self.edge_preintegrated(sample, before);
        }
    }

    #[inline]
    fn gap(&mut self) -> ControlFlow<()> {
        if PRE {
            // Empty space follows: no back edge of a brick's reaches into it.
            return self.close_run(false);
        }
        ControlFlow::Continue(())
    }

    #[inline(always)]
    fn adapts_step(&self) -> bool {
        self.adaptive.is_some()
    }

    #[inline]
    fn adapt_step(&self, lower: f32, upper: f32, base: f64) -> f64 {
        match self.adaptive {
            Some((variation, tolerance)) => variation.step(lower, upper, base, tolerance),
            None => base,
        }
    }

    #[inline]
    fn set_step(&mut self, step: StepLength) {
        self.table = Some(self.lut.step_table(step));
        if let Some(state) = self.preintegrating.as_mut() {
            // Half the step: one octave down the ladder.
            let half = StepLength { index: step.index + STEPS_PER_OCTAVE, world: 0.5 * step.world };
            state.half_table = Some(self.lut.step_table(half));
            state.step = step.world;
        }
    }

    #[inline]
    fn set_level(&mut self, level: u32) {
        if self.colour_by_level {
            self.tint = Some(Vec3::from(crate::settings::level_colour(level)));
        }
    }

    #[inline(always)]
    fn sample(&mut self, sample: Sample) -> ControlFlow<()> {
        if PRE {
            return self.sample_preintegrated(sample);
        }
        let Some(table) = self.table else { return ControlFlow::Continue(()) };
        let entry = table.lookup(sample.value);
        let premultiplied = match self.tint {
            None => entry.truncate(),
            Some(tint) => tint * entry.w,
        };
        // A transparent sample (`w = 0`: its premultiplied colour is 0 too) adds `T·0` and multiplies `T` by 1,
        // which changes no bit: unshaded, it is composited like any other (a data-dependent branch per sample
        // costs more than the arithmetic); shaded, it is passed over before the lighting.
        let color = match &self.light {
            Some(light) => {
                if entry.w <= 0.0 {
                    return ControlFlow::Continue(());
                }
                light.shade(premultiplied, entry.w, Vec3::from(sample.gradient) * self.gradient_scale)
            }
            None => premultiplied,
        };
        self.color += self.transmittance * color;
        self.transmittance *= 1.0 - entry.w;
        if self.transmittance <= self.stop_below {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    }

    #[inline]
    fn constant(&mut self, from: f64, to: f64, value: f32) -> ControlFlow<()> {
        if PRE && self.close_run(false).is_break() {
            return ControlFlow::Break(());
        }
        let Some((color, alpha)) = constant_emission(self.lut, value, to - from) else {
            return ControlFlow::Continue(());
        };
        self.color += self.transmittance * alpha * self.tint.unwrap_or(color);
        self.transmittance *= 1.0 - alpha;
        if self.transmittance <= self.stop_below {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    }
}

/// What a constant `value` over `length` world units adds: its colour (unshaded, not premultiplied) and opacity
/// `α = 1 − exp(−σ·length)`, one `exp` per constant node rather than one per sample; `None` where it is
/// transparent.
#[inline]
pub(crate) fn constant_emission(lut: &TransferLut, value: f32, length: f64) -> Option<(Vec3, f32)> {
    let entry = lut.lookup(value);
    (entry.sigma > 0.0).then(|| (Vec3::from(entry.color), -(-(entry.sigma as f64) * length).exp_m1() as f32))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::transfer_function::TransferFunction;

    #[test]
    fn a_constant_node_equals_samples_of_the_same_value() {
        let tf = TransferFunction::new(vec![[0.0, 1.0, 0.5, 0.25, 0.0], [1.0, 1.0, 0.5, 0.25, 0.3]], Some(1.0))
            .expect("valid function");
        let lut = TransferLut::new(&tf, 0.0, 1.0, 1.0);
        let settings = EmissionAbsorptionSettings::new(&RenderSettings { opacity_cutoff: 1.0, ..Default::default() });
        let step = StepLength::at_most(0.3);
        let mut one_by_one = EmissionAbsorption::<false>::new(&lut, &settings, DVec3::Z);
        let mut at_once = EmissionAbsorption::<false>::new(&lut, &settings, DVec3::Z);
        one_by_one.set_step(step);
        at_once.set_step(step);
        for k in 0..7 {
            let _ = one_by_one.sample(Sample { t: k as f64, value: 0.6, gradient: [0.0; 3] });
        }
        let _ = at_once.constant(0.0, 7.0 * step.world, 0.6);
        let ((a, alpha_a), (b, alpha_b)) = (one_by_one.result(), at_once.result());
        assert!((alpha_a - alpha_b).abs() < 1e-6, "{alpha_a} vs {alpha_b}");
        for c in 0..3 {
            assert!((a[c] - b[c]).abs() < 1e-6, "{a:?} vs {b:?}");
        }
        // σ(0.6) = −ln(1 − 0.18) per unit; seven steps of 0.2973 units: α = 1 − 0.82^2.08 ≈ 0.338.
        assert!((alpha_a - 0.338).abs() < 2e-3, "seven steps: {alpha_a}");
    }

    #[test]
    fn transparent_samples_change_no_bit() {
        // Invisible below 0.4 (a ramp of colour that opacity 0 must hide), visible above; unshaded and coloured by
        // level, both of which composite transparent samples rather than branch on them.
        let tf = TransferFunction::new(
            vec![
                [0.0, 1.0, 0.7, 0.2, 0.0],
                [0.4, 0.9, 0.8, 0.1, 0.0],
                [0.5, 0.3, 0.6, 0.9, 0.4],
                [1.0, 1.0, 1.0, 1.0, 0.9],
            ],
            Some(1.0),
        )
        .expect("valid function");
        let lut = TransferLut::new(&tf, 0.0, 1.0, 1.0);
        for colour_by_level in [false, true] {
            let settings = EmissionAbsorptionSettings::new(&RenderSettings {
                opacity_cutoff: 1.0,
                colour_by_level,
                ..Default::default()
            });
            let step = StepLength::at_most(0.3);
            let mut visible_only = EmissionAbsorption::<false>::new(&lut, &settings, DVec3::Z);
            let mut with_transparent = EmissionAbsorption::<false>::new(&lut, &settings, DVec3::Z);
            for ray in [&mut visible_only, &mut with_transparent] {
                ray.set_step(step);
                ray.set_level(2);
            }
            for k in 0..40 {
                let visible = 0.45 + 0.013 * k as f32;
                let _ = visible_only.sample(Sample { t: k as f64, value: visible, gradient: [0.0; 3] });
                let _ = with_transparent.sample(Sample { t: k as f64, value: visible, gradient: [0.0; 3] });
                // Values whose table entries (and the one after, which the lookup interpolates) have opacity 0.
                for hidden in [0.0, 0.1 + 0.007 * k as f32, 0.38, f32::NAN, -3.0] {
                    let _ = with_transparent.sample(Sample { t: k as f64, value: hidden, gradient: [1.0, 0.0, 0.0] });
                }
            }
            let ((a, alpha_a), (b, alpha_b)) = (visible_only.result(), with_transparent.result());
            assert!(alpha_a > 0.5, "the visible samples accumulate: {alpha_a}");
            assert_eq!(alpha_a.to_bits(), alpha_b.to_bits(), "colour by level {colour_by_level}");
            assert_eq!(a.map(f32::to_bits), b.map(f32::to_bits), "colour by level {colour_by_level}");
        }
    }
}
