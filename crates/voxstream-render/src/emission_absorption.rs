//! Emission–absorption volume rendering: the first [`Integrand`].
//!
//! Front-to-back compositing of [R08] §5 / GigaVoxels [P09] §6: each sample adds `T·α·c` and multiplies the
//! transmittance `T` by `1 − α`, where `α·c` and `α` come premultiplied from the transfer function's table for the
//! current step ([`crate::step_table`]: no `exp` per sample). Optional two-sided Phong shading with the trilinear
//! field's analytic gradient as normal. The ray stops once its opacity reaches the cutoff.

use std::ops::ControlFlow;

use glam::{DVec3, Vec3, Vec4};

use crate::integrand::{Integrand, Sample};
use crate::settings::{PhongCoefficients, RenderSettings, Shading};
use crate::step_table::{StepLength, StepTable};
use crate::transfer_function::TransferLut;

/// What stays the same for every ray of a frame.
#[derive(Clone, Copy, Debug)]
pub struct EmissionAbsorptionSettings {
    phong: Option<PhongCoefficients>,
    /// Fixed light direction (unit, world), or `None` for a headlight.
    light: Option<Vec3>,
    /// World units per unit of gradient along each brick axis (the placement's inverse scale).
    gradient_scale: Vec3,
    /// Transmittance below which a ray stops.
    stop_below: f32,
}

impl EmissionAbsorptionSettings {
    /// From the frame's settings.
    pub fn new(settings: &RenderSettings) -> EmissionAbsorptionSettings {
        EmissionAbsorptionSettings {
            phong: (settings.shading == Shading::Phong).then_some(settings.phong),
            light: settings.light_direction.map(|l| DVec3::from(l).normalize().as_vec3()),
            gradient_scale: Vec3::from(settings.placement.scale.map(|s| (1.0 / s) as f32)),
            stop_below: 1.0 - settings.opacity_cutoff,
        }
    }
}

/// Light and half vector of one ray (world space, unit).
#[derive(Clone, Copy, Debug)]
struct RayLight {
    light: Vec3,
    half: Vec3,
    phong: PhongCoefficients,
}

/// The colour and opacity accumulated along one ray.
pub struct EmissionAbsorption<'a> {
    lut: &'a TransferLut,
    table: Option<&'a StepTable>,
    light: Option<RayLight>,
    gradient_scale: Vec3,
    stop_below: f32,
    /// Premultiplied colour so far.
    color: Vec3,
    transmittance: f32,
}

impl<'a> EmissionAbsorption<'a> {
    /// A ray with nothing accumulated; `volume_direction` is the ray's direction in volume units per world unit.
    pub fn new(
        lut: &'a TransferLut,
        settings: &EmissionAbsorptionSettings,
        volume_direction: DVec3,
    ) -> EmissionAbsorption<'a> {
        let light = settings.phong.map(|phong| {
            let view = -(volume_direction.as_vec3() / settings.gradient_scale).normalize();
            let light = settings.light.unwrap_or(view);
            RayLight { light, half: (light + view).normalize_or_zero(), phong }
        });
        EmissionAbsorption {
            lut,
            table: None,
            light,
            gradient_scale: settings.gradient_scale,
            stop_below: settings.stop_below,
            color: Vec3::ZERO,
            transmittance: 1.0,
        }
    }

    /// Premultiplied `[r, g, b]` and opacity.
    pub fn result(&self) -> ([f32; 3], f32) {
        (self.color.to_array(), 1.0 - self.transmittance)
    }

    /// Two-sided Phong of a premultiplied sample with the density gradient as normal.
    #[inline(always)]
    fn shade(light: &RayLight, premultiplied: Vec4, gradient: Vec3) -> Vec3 {
        let phong = light.phong;
        let color = premultiplied.truncate();
        let length = gradient.length();
        if length < 1e-6 {
            return color * (phong.ambient + phong.diffuse);
        }
        // The normal points away from denser material; two-sided, so its sign does not matter.
        let normal = gradient / length;
        let diffuse = normal.dot(light.light).abs();
        let specular = power(normal.dot(light.half).abs(), phong.shininess);
        color * (phong.ambient + phong.diffuse * diffuse) + Vec3::splat(phong.specular * specular * premultiplied.w)
    }
}

impl Integrand for EmissionAbsorption<'_> {
    #[inline]
    fn can_contribute(&self, lower: f32, upper: f32) -> bool {
        self.lut.is_visible_in(lower, upper)
    }

    #[inline]
    fn wants_gradient(&self) -> bool {
        self.light.is_some()
    }

    #[inline]
    fn set_step(&mut self, step: StepLength) {
        self.table = Some(self.lut.step_table(step));
    }

    #[inline(always)]
    fn sample(&mut self, sample: Sample) -> ControlFlow<()> {
        let Some(table) = self.table else { return ControlFlow::Continue(()) };
        let entry = table.lookup(sample.value);
        if entry.w <= 0.0 {
            return ControlFlow::Continue(());
        }
        let color = match &self.light {
            Some(light) => Self::shade(light, entry, Vec3::from(sample.gradient) * self.gradient_scale),
            None => entry.truncate(),
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
        let entry = self.lut.lookup(value);
        if entry.sigma <= 0.0 {
            return ControlFlow::Continue(());
        }
        // One `exp` per constant node, not per sample: α = 1 − exp(−σ·length), colour unshaded.
        let alpha = -(-(entry.sigma as f64) * (to - from)).exp_m1() as f32;
        self.color += self.transmittance * alpha * Vec3::from(entry.color);
        self.transmittance *= 1.0 - alpha;
        if self.transmittance <= self.stop_below {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    }
}

/// `base^exponent`, by repeated squaring when the exponent is a small whole number (the usual Phong case).
#[inline]
fn power(base: f32, exponent: f32) -> f32 {
    if exponent == exponent.trunc() && (0.0..=64.0).contains(&exponent) {
        let mut result = 1.0;
        let mut b = base;
        let mut e = exponent as u32;
        while e > 0 {
            if e & 1 == 1 {
                result *= b;
            }
            b *= b;
            e >>= 1;
        }
        result
    } else {
        base.powf(exponent)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::transfer_function::TransferFunction;

    #[test]
    fn power_matches_powf() {
        for (b, e) in [(0.5f32, 16.0f32), (0.9, 3.0), (0.7, 2.5), (0.0, 0.0)] {
            assert!((power(b, e) - b.powf(e)).abs() < 1e-6);
        }
    }

    #[test]
    fn a_constant_node_equals_samples_of_the_same_value() {
        let tf = TransferFunction::new(vec![[0.0, 1.0, 0.5, 0.25, 0.0], [1.0, 1.0, 0.5, 0.25, 0.3]], Some(1.0))
            .expect("valid function");
        let lut = TransferLut::new(&tf, 0.0, 1.0, 1.0);
        let settings = EmissionAbsorptionSettings::new(&RenderSettings { opacity_cutoff: 1.0, ..Default::default() });
        let step = StepLength::at_most(0.3);
        let mut one_by_one = EmissionAbsorption::new(&lut, &settings, DVec3::Z);
        let mut at_once = EmissionAbsorption::new(&lut, &settings, DVec3::Z);
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
}
