//! Exact isosurfaces: the first-hit [`Integrand`] of Knoll et al. (seed 002; `../shared/notes/knoll-isosurface.md`).
//!
//! The traversal hands over whole brick segments ([`Integrand::TAKES_SPANS`]); each is walked cell by cell
//! ([`crate::cell_walk`]) and every cell whose corner range holds an isovalue is intersected exactly
//! ([`crate::cell_intersection`]): the first crossing is found even when the ray crosses twice inside the cell.
//!
//! - **State, not samples.** The ray carries, per surface, whether it is inside (`f ≥ iso`). A crossing is any
//!   change of that state: inside a cell (a root of the cubic), or between two pieces of the ray whose fields differ
//!   (a level-of-detail seam, a constant node). So a surface that moves slightly where the level changes still
//!   closes: the ray meets it on one side of the seam or at the seam, never neither (Knoll's transition slices aim at
//!   the same: no cracks).
//! - **Culling.** A brick, occupancy block or cell whose value range lies on the ray's current side of every
//!   isovalue is skipped ([`Integrand::can_contribute`]); that is exact, because nothing in it can change the state.
//! - **Several surfaces**, each with a colour and an opacity: crossings are composited front to back in order, so
//!   nested translucent surfaces show each other; an opaque one ends the ray.
//! - **Shading**: two-sided Phong ([`crate::lighting`]) with the analytic gradient of the trilinear cell as normal,
//!   or central differences at its corners interpolated trilinearly ([`SurfaceNormals`]).

use std::ops::ControlFlow;

use glam::{DVec3, Vec3};
use serde::{Deserialize, Serialize};
use voxstream_core::VOXEL_MAX;

use crate::cell_intersection::{cell_gradient, CellCubic};
use crate::cell_walk::{walk_cells, CellVisit, CellVisitor};
use crate::integrand::{BrickSpan, Integrand, Sample};
use crate::lighting::{LightingSettings, RayLight};
use crate::settings::RenderSettings;
use crate::step_table::StepLength;

/// Surfaces one frame can draw at most.
pub const MAX_SURFACES: usize = 8;

/// Margin (normalised value) by which brick and block ranges must clear an isovalue before they are culled: the
/// ranges are normalised `f32`, the cells compare the stored integers, and the margin keeps the two decisions
/// consistent whatever the rounding.
const RANGE_MARGIN: f32 = 1e-6;

/// Where an isosurface's normal comes from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SurfaceNormals {
    /// The analytic gradient of the trilinear cell hit: exact for the surface drawn, continuous in value but not in
    /// direction across cells.
    #[default]
    Cell,
    /// Central differences at the cell's corners, interpolated trilinearly: smoother shading (Knoll et al. §3).
    CentralDifferences,
}

/// One isosurface to draw.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct IsoSurface {
    /// The isovalue, in data values (what the transfer function is written in).
    pub value: f64,
    /// Linear colour.
    pub color: [f32; 3],
    /// Opacity in `(0, 1]`: 1 hides what is behind; less shows nested surfaces through.
    pub opacity: f32,
}

/// The surfaces of a frame in the bricks' scale, and their lighting: what stays the same for every ray.
#[derive(Clone, Debug)]
pub struct SurfaceSettings {
    count: usize,
    /// Isovalues in stored units (`[0, 65535]`), what cell corners are compared with.
    iso: [f32; MAX_SURFACES],
    /// Isovalues normalised, less and plus [`RANGE_MARGIN`], for range culling.
    lower: [f32; MAX_SURFACES],
    upper: [f32; MAX_SURFACES],
    /// Premultiplied colours.
    color: [Vec3; MAX_SURFACES],
    opacity: [f32; MAX_SURFACES],
    lighting: LightingSettings,
    stop_below: f32,
    /// Normals from central differences at the cell's corners, interpolated, instead of the cell's own gradient.
    central_normals: bool,
}

impl SurfaceSettings {
    /// From the frame's settings; `normalise` maps a data value to the bricks' `[0, 1]`.
    pub fn new(settings: &RenderSettings, normalise: impl Fn(f64) -> f64) -> SurfaceSettings {
        let mut s = SurfaceSettings {
            count: settings.surfaces.len().min(MAX_SURFACES),
            iso: [0.0; MAX_SURFACES],
            lower: [0.0; MAX_SURFACES],
            upper: [0.0; MAX_SURFACES],
            color: [Vec3::ZERO; MAX_SURFACES],
            opacity: [0.0; MAX_SURFACES],
            lighting: LightingSettings::new(settings),
            stop_below: 1.0 - settings.opacity_cutoff,
            central_normals: settings.surface_normals == SurfaceNormals::CentralDifferences,
        };
        for (i, surface) in settings.surfaces.iter().take(MAX_SURFACES).enumerate() {
            let normalised = normalise(surface.value) as f32;
            s.iso[i] = normalised * VOXEL_MAX as f32;
            s.lower[i] = normalised - RANGE_MARGIN;
            s.upper[i] = normalised + RANGE_MARGIN;
            s.color[i] = Vec3::from(surface.color) * surface.opacity;
            s.opacity[i] = surface.opacity;
        }
        s
    }

    /// How many surfaces.
    pub fn count(&self) -> usize {
        self.count
    }

    /// Surface `i` as the GPU's `SurfaceRecord` holds it: the isovalue in stored units, the normalised culling
    /// bounds (isovalue less and plus the margin), the premultiplied colour and the opacity.
    pub fn surface(&self, i: usize) -> SurfaceParameters {
        SurfaceParameters {
            iso: self.iso[i],
            lower: self.lower[i],
            upper: self.upper[i],
            color: self.color[i].to_array(),
            opacity: self.opacity[i],
        }
    }
}

/// One surface of [`SurfaceSettings`] in the units the cells and the culling use ([`SurfaceSettings::surface`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceParameters {
    /// Isovalue in stored units (`[0, 65535]`).
    pub iso: f32,
    /// Normalised isovalue less the culling margin.
    pub lower: f32,
    /// Normalised isovalue plus the culling margin.
    pub upper: f32,
    /// Linear colour premultiplied by the opacity.
    pub color: [f32; 3],
    /// Opacity in `(0, 1]`.
    pub opacity: f32,
}

/// The surfaces met along one ray, composited front to back.
pub struct Isosurfaces<'a> {
    settings: &'a SurfaceSettings,
    /// The ray's light, once something needs it ([`Isosurfaces::light`]): most rays of a frame meet no surface, and
    /// making it up front for every ray was 7.3% of the samples of an MNI isosurface profile (BENCHMARKS.md).
    light: Option<RayLight>,
    /// The ray's direction in volume units per world unit while `light` is not made yet (`None` once it is, and for
    /// shadow rays, which never shade).
    light_pending: Option<DVec3>,
    /// Per surface (bit `i`): whether the ray is inside (`f ≥ iso`) where it is now.
    inside: u32,
    /// Whether `inside` has been read from data yet (the volume's boundary is not a crossing).
    known: bool,
    color: Vec3,
    transmittance: f32,
    first_hit: Option<f64>,
    /// What the first crossing's light added beyond its ambient term (removed if the crossing is in shadow).
    first_lit: Vec3,
    /// Stop at the first crossing whatever its opacity (shadow rays).
    any_hit: bool,
}

impl<'a> Isosurfaces<'a> {
    /// A ray that has met nothing; `volume_direction` is its direction in volume units per world unit.
    pub fn new(settings: &'a SurfaceSettings, volume_direction: DVec3) -> Isosurfaces<'a> {
        Isosurfaces {
            settings,
            light: None,
            light_pending: Some(volume_direction),
            inside: 0,
            known: false,
            color: Vec3::ZERO,
            transmittance: 1.0,
            first_hit: None,
            first_lit: Vec3::ZERO,
            any_hit: false,
        }
    }

    /// A shadow ray: it stops at the first crossing of any surface.
    pub fn occlusion(settings: &'a SurfaceSettings) -> Isosurfaces<'a> {
        Isosurfaces { light_pending: None, any_hit: true, ..Isosurfaces::new(settings, DVec3::Z) }
    }

    /// Premultiplied `[r, g, b]` and opacity.
    pub fn result(&self) -> ([f32; 3], f32) {
        (self.color.to_array(), 1.0 - self.transmittance)
    }

    /// Distance of the first crossing, if any.
    pub fn first_hit(&self) -> Option<f64> {
        self.first_hit
    }

    /// The light of the ray (`None` without shading, and for shadow rays), made on first use.
    #[inline]
    pub fn light(&mut self) -> Option<&RayLight> {
        if let Some(volume_direction) = self.light_pending.take() {
            self.light = self.settings.lighting.ray(volume_direction);
        }
        self.light.as_ref()
    }

    /// The first crossing is in shadow: only its ambient term stays.
    pub fn shadow_first_hit(&mut self) {
        self.color -= self.first_lit;
        self.first_lit = Vec3::ZERO;
    }

    /// A crossing of surface `i` at `t`, with the field's gradient there (world axes; zero where unknown).
    #[inline]
    fn hit(&mut self, i: usize, t: f64, gradient: Vec3) -> ControlFlow<()> {
        if self.any_hit {
            self.first_hit = Some(t);
            self.transmittance = 0.0;
            return ControlFlow::Break(());
        }
        let (color, opacity) = (self.settings.color[i], self.settings.opacity[i]);
        let light = self.light().copied();
        let shaded = match &light {
            Some(light) => light.shade(color, opacity, gradient),
            None => color,
        };
        if self.first_hit.is_none() {
            self.first_hit = Some(t);
            if let Some(light) = &light {
                self.first_lit = self.transmittance * (shaded - light.ambient(color));
            }
        }
        self.absorb(shaded, opacity)
    }

    /// The surfaces a stored value is inside of.
    #[inline]
    fn inside_of(&self, stored: f32) -> u32 {
        let mut bits = 0;
        for i in 0..self.settings.count {
            bits |= ((stored >= self.settings.iso[i]) as u32) << i;
        }
        bits
    }

    /// The state is `entry` from `t` on: crossings at `t` for every surface that changed (none for the first data).
    #[inline]
    fn enter(&mut self, entry: u32, t: f64, gradient: impl Fn() -> Vec3) -> ControlFlow<()> {
        if !self.known {
            self.known = true;
            self.inside = entry;
            return ControlFlow::Continue(());
        }
        let changed = entry ^ self.inside;
        self.inside = entry;
        if changed != 0 {
            let g = gradient();
            for i in 0..self.settings.count {
                if changed & (1 << i) != 0 {
                    self.hit(i, t, g)?;
                }
            }
        }
        ControlFlow::Continue(())
    }

    /// Composites premultiplied `color` of opacity `alpha` at the ray's current depth: a crossing, or the volume
    /// around the surfaces ([`crate::surfaces_in_volume`]).
    #[inline(always)]
    pub(crate) fn absorb(&mut self, color: Vec3, alpha: f32) -> ControlFlow<()> {
        self.color += self.transmittance * color;
        self.transmittance *= 1.0 - alpha;
        if self.transmittance <= self.settings.stop_below {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    }

    /// One trilinear cell: seams at its entry, then its exact crossings in order.
    #[inline(always)]
    fn cell(&mut self, c: &CellVisit<'_>) -> ControlFlow<()> {
        self.cell_with(c, |_, _| ControlFlow::Continue(()))
    }

    /// [`Isosurfaces::cell`], calling `before(self, t)` before each crossing at `t` and at the cell's exit
    /// (`t = t_out`), so that what lies between crossings is composited in depth order.
    #[inline(always)]
    pub(crate) fn cell_with(
        &mut self,
        c: &CellVisit<'_>,
        mut before: impl FnMut(&mut Self, f64) -> ControlFlow<()>,
    ) -> ControlFlow<()> {
        let s = self.settings;
        let (mut lo, mut hi) = (c.corners[0], c.corners[0]);
        for &v in &c.corners[1..] {
            lo = lo.min(v);
            hi = hi.max(v);
        }
        let (mut above, mut straddle) = (0u32, 0u32);
        for i in 0..s.count {
            if lo >= s.iso[i] {
                above |= 1 << i;
            } else if hi >= s.iso[i] {
                straddle |= 1 << i;
            }
        }
        if straddle == 0 && self.known && above == self.inside {
            return before(self, c.t_out);
        }
        let scale = s.lighting.gradient_scale;
        let start = c.start();
        let central = s.central_normals;
        let gradient_at = |u: f32| {
            let p = std::array::from_fn(|a| start[a] + u * c.rate[a]);
            let g = if central { c.central_gradient(p) } else { cell_gradient(&c.corners, p) };
            Vec3::from(g) * scale
        };
        if straddle == 0 {
            self.enter(above, c.t_in, || gradient_at(0.0))?;
            return before(self, c.t_out);
        }
        let cubic = CellCubic::new(&c.corners, start, c.rate);
        let f0 = cubic.at(0.0);
        let mut entry = above;
        for i in 0..s.count {
            if straddle & (1 << i) != 0 && f0 >= s.iso[i] {
                entry |= 1 << i;
            }
        }
        self.enter(entry, c.t_in, || gradient_at(0.0))?;
        // Every surface's crossings in the cell, merged in ray order.
        let length = (c.t_out - c.t_in) as f32;
        let mut crossings = [(0.0f32, 0u8); 3 * MAX_SURFACES];
        let mut count = 0;
        for i in 0..s.count {
            if straddle & (1 << i) != 0 {
                let mut roots = [0.0f32; 3];
                let found = cubic.crossings(s.iso[i], length, &mut roots);
                for &u in &roots[..found] {
                    // Insertion keeps the list sorted (a handful of entries at most).
                    let mut k = count;
                    while k > 0 && crossings[k - 1].0 > u {
                        crossings[k] = crossings[k - 1];
                        k -= 1;
                    }
                    crossings[k] = (u, i as u8);
                    count += 1;
                }
            }
        }
        for &(u, i) in &crossings[..count] {
            let t = c.t_in + u as f64;
            before(self, t)?;
            self.inside ^= 1 << i;
            self.hit(i as usize, t, gradient_at(u))?;
        }
        before(self, c.t_out)
    }
}

impl CellVisitor for Isosurfaces<'_> {
    #[inline]
    fn block_can_contribute(&self, lower: u16, upper: u16) -> bool {
        let scale = 1.0 / VOXEL_MAX as f32;
        self.can_contribute(lower as f32 * scale, upper as f32 * scale)
    }

    #[inline(always)]
    fn visit(&mut self, cell: &CellVisit<'_>) -> ControlFlow<()> {
        self.cell(cell)
    }
}

impl Integrand for Isosurfaces<'_> {
    const TAKES_SPANS: bool = true;

    #[inline]
    fn can_contribute(&self, lower: f32, upper: f32) -> bool {
        if !self.known {
            return true;
        }
        let s = self.settings;
        (0..s.count).any(|i| {
            let may_straddle = lower <= s.upper[i] && upper >= s.lower[i];
            let all_inside = lower > s.upper[i];
            may_straddle || all_inside != (self.inside & (1 << i) != 0)
        })
    }

    /// Before the ray has read any data, every range can contribute (its side of each surface is not known yet).
    #[inline(always)]
    fn contributes_throughout(&self, _lower: f32, _upper: f32) -> bool {
        !self.known
    }

    fn wants_gradient(&self) -> bool {
        false
    }

    fn set_step(&mut self, _step: StepLength) {}

    /// A lone sample (not used by the traversal for this integrand, which takes spans): a point of the field.
    fn sample(&mut self, sample: Sample) -> ControlFlow<()> {
        let entry = self.inside_of(sample.value * VOXEL_MAX as f32);
        self.enter(entry, sample.t, || Vec3::ZERO)
    }

    fn constant(&mut self, from: f64, _to: f64, value: f32) -> ControlFlow<()> {
        let entry = self.inside_of(value * VOXEL_MAX as f32);
        self.enter(entry, from, || Vec3::ZERO)
    }

    #[inline(always)]
    fn span(&mut self, span: &BrickSpan<'_>, work: &mut u64) -> ControlFlow<()> {
        let (flow, cells) = walk_cells(span, self);
        *work += cells;
        flow
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::settings::Shading;

    fn phong_settings() -> RenderSettings {
        RenderSettings {
            shading: Shading::Phong,
            light_direction: Some([0.3, 0.8, 0.5]),
            surfaces: vec![IsoSurface { value: 0.5, color: [0.9, 0.6, 0.3], opacity: 1.0 }],
            ..RenderSettings::default()
        }
    }

    /// The light made on first use is the one the frame's lighting gives the ray, and a crossing is shaded with it
    /// exactly as with a light made up front.
    #[test]
    fn a_ray_makes_its_light_when_it_first_needs_it() {
        let render = phong_settings();
        let surfaces = SurfaceSettings::new(&render, |v| v);
        let direction = DVec3::new(0.2, -0.4, 1.0);
        let eager = LightingSettings::new(&render).ray(direction).expect("Phong shading gives every ray a light");

        let mut ray = Isosurfaces::new(&surfaces, direction);
        assert!(ray.light.is_none(), "no light is made before something needs it");
        assert!(ray.constant(0.0, 1.0, 0.2).is_continue());
        assert!(ray.light.is_none(), "a ray outside every surface needs no light");
        let gradient = Vec3::new(0.0, 0.0, -1.0);
        let _ = ray.hit(0, 1.0, gradient);
        let made = ray.light().copied().expect("the crossing made the light");
        assert_eq!((made.light, made.half, made.view), (eager.light, eager.half, eager.view));

        let color = Vec3::from(render.surfaces[0].color);
        let (rgb, alpha) = ray.result();
        assert_eq!(rgb, eager.shade(color, 1.0, gradient).to_array());
        assert_eq!(alpha, 1.0);
        // In shadow, the crossing keeps the ambient term of that same light.
        ray.shadow_first_hit();
        let ambient = eager.ambient(color).to_array();
        assert!(ray.result().0.iter().zip(ambient).all(|(a, b)| (a - b).abs() < 1e-6), "{:?}", ray.result());
    }

    /// Shadow rays only ask whether anything blocks the light: they have no light, and nothing left to make one
    /// from.
    #[test]
    fn a_shadow_ray_has_no_light() {
        let render = phong_settings();
        let surfaces = SurfaceSettings::new(&render, |v| v);
        let mut blocker = Isosurfaces::occlusion(&surfaces);
        assert!(blocker.light_pending.is_none(), "a shadow ray has no light to make");
        assert!(blocker.light().is_none());
        assert!(blocker.constant(0.0, 1.0, 0.2).is_continue());
        assert!(blocker.constant(1.0, 2.0, 0.8).is_break(), "the first crossing stops a shadow ray");
        assert_eq!(blocker.first_hit(), Some(1.0));
        assert!(blocker.light().is_none());
    }
}
