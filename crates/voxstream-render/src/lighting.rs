//! Two-sided Phong lighting with a field's gradient as normal, shared by every integrand that shades (GigaVoxels
//! [R08] §5 for volumes; Knoll et al., seed 002 §5, for isosurfaces).

use glam::{DVec3, Vec3};

use crate::settings::{PhongCoefficients, RenderSettings, Shading};

/// What stays the same for every ray of a frame.
#[derive(Clone, Copy, Debug)]
pub struct LightingSettings {
    phong: Option<PhongCoefficients>,
    /// Fixed light direction (unit, world), or `None` for a headlight.
    light: Option<Vec3>,
    /// World units per unit of gradient along each brick axis (the placement's inverse scale).
    pub gradient_scale: Vec3,
}

impl LightingSettings {
    /// From the frame's settings.
    pub fn new(settings: &RenderSettings) -> LightingSettings {
        LightingSettings {
            phong: (settings.shading == Shading::Phong).then_some(settings.phong),
            light: settings.light_direction.map(|l| DVec3::from(l).normalize().as_vec3()),
            gradient_scale: Vec3::from(settings.placement.scale.map(|s| (1.0 / s) as f32)),
        }
    }

    /// The light of one ray (`None` without shading); `volume_direction` is the ray's direction in volume units per
    /// world unit.
    #[inline]
    pub fn ray(&self, volume_direction: DVec3) -> Option<RayLight> {
        self.phong.map(|phong| {
            let view = -(volume_direction.as_vec3() / self.gradient_scale).normalize();
            let light = self.light.unwrap_or(view);
            RayLight { light, half: (light + view).normalize_or_zero(), view, phong }
        })
    }
}

/// Light, half vector and view of one ray (world space, unit).
#[derive(Clone, Copy, Debug)]
pub struct RayLight {
    /// Towards the light.
    pub light: Vec3,
    /// Between light and view.
    pub half: Vec3,
    /// Towards the eye.
    pub view: Vec3,
    phong: PhongCoefficients,
}

impl RayLight {
    /// The ambient part of [`RayLight::shade`]: what stays where the light is blocked.
    #[inline]
    pub fn ambient(&self, color: Vec3) -> Vec3 {
        color * self.phong.ambient
    }

    /// Two-sided Phong of a premultiplied colour `color` of opacity `alpha`, with `gradient` (world axes, any length)
    /// as normal: `color·(ambient + diffuse·|N·L|) + specular·|N·H|^shininess·alpha`. A vanishing gradient gets the
    /// ambient and full diffuse terms.
    #[inline(always)]
    pub fn shade(&self, color: Vec3, alpha: f32, gradient: Vec3) -> Vec3 {
        let phong = self.phong;
        let length = gradient.length();
        if length < 1e-6 {
            return color * (phong.ambient + phong.diffuse);
        }
        // The normal points away from denser material; two-sided, so its sign does not matter.
        let normal = gradient / length;
        let diffuse = normal.dot(self.light).abs();
        let specular = power(normal.dot(self.half).abs(), phong.shininess);
        color * (phong.ambient + phong.diffuse * diffuse) + Vec3::splat(phong.specular * specular * alpha)
    }
}

/// `base^exponent`, by repeated squaring when the exponent is a small whole number (the usual Phong case).
#[inline]
pub fn power(base: f32, exponent: f32) -> f32 {
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

    #[test]
    fn power_matches_powf() {
        for (b, e) in [(0.5f32, 16.0f32), (0.9, 3.0), (0.7, 2.5), (0.0, 0.0)] {
            assert!((power(b, e) - b.powf(e)).abs() < 1e-6);
        }
    }

    #[test]
    fn shading_is_two_sided() {
        let settings = RenderSettings { shading: Shading::Phong, ..RenderSettings::default() };
        let light = LightingSettings::new(&settings).ray(DVec3::Z).expect("phong");
        let (a, b) = (light.shade(Vec3::ONE, 1.0, Vec3::Z), light.shade(Vec3::ONE, 1.0, -Vec3::Z));
        assert_eq!(a, b);
        // Facing the headlight: ambient + diffuse + specular.
        assert!((a.x - 1.25).abs() < 1e-6, "{a}");
    }
}
