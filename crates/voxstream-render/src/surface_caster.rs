//! The isosurface ray: the tree [`Traversal`] with the [`Isosurfaces`] integrand (or [`SurfacesInVolume`], the
//! surfaces inside the transfer function's volume), and optional hard shadows.
//!
//! Shadows follow Knoll et al. (seed 002 §5): from the first crossing, a ray towards the light through the same
//! tree with the same exact intersection, at a coarser level of detail (its cone twice as wide as the primary ray's
//! at the surface). A blocked light leaves the crossing its ambient term. The shadow ray reports its misses like any
//! ray, so the data it needs is loaded too.

use glam::DVec3;
use voxstream_core::{FeedbackBuffer, Request, TreeView};

use crate::frame::PixelTracer;
use crate::isosurface::{Isosurfaces, SurfaceSettings};
use crate::sampler::LANES;
use crate::settings::RenderSettings;
use crate::surfaces_in_volume::{SurfacesInVolume, VolumeAroundSurfaces};
use crate::transfer_function::TransferLut;
use crate::traversal::{DescentPath, Ray, RayStats, Traversal};

/// How much wider a shadow ray's cone is than the primary ray's at the surface (mirrored by the GPU's shader, as
/// is [`SHADOW_OFFSET`]; voxstream-gpu's `tests/shader_interface.rs` checks both).
pub const SHADOW_CONE: f64 = 2.0;
/// A shadow ray starts this many of its footprints off the surface (no self-shadowing by the crossing itself).
pub const SHADOW_OFFSET: f64 = 1.5;

/// Traces isosurface rays against one frame's tree view, writing feedback.
pub struct SurfaceCaster<'a> {
    traversal: Traversal<'a>,
    surfaces: &'a SurfaceSettings,
    /// Towards the light in volume units per world unit, when shadows are on and a fixed light is set.
    shadow_direction: Option<DVec3>,
    /// World length of the finest voxel (the least shadow offset).
    finest_voxel: f64,
    /// The volume drawn around the surfaces, if any ([`RenderSettings::surfaces_in_volume`]).
    volume: Option<VolumeAroundSurfaces<'a>>,
}

impl<'a> SurfaceCaster<'a> {
    /// Prepares a surface caster for one frame; with [`RenderSettings::surfaces_in_volume`], `lut`'s volume is drawn
    /// around the surfaces.
    pub fn new(
        view: TreeView<'a>,
        feedback: &'a FeedbackBuffer,
        surfaces: &'a SurfaceSettings,
        lut: &'a TransferLut,
        settings: &RenderSettings,
    ) -> SurfaceCaster<'a> {
        let scale = DVec3::from(settings.placement.scale);
        let shadow_direction = settings
            .light_direction
            .filter(|_| settings.shadows && settings.shading == crate::Shading::Phong)
            .map(|l| DVec3::from(l).normalize() / scale);
        let shape = view.shape;
        SurfaceCaster {
            traversal: Traversal::new(view, feedback, settings),
            surfaces,
            shadow_direction,
            finest_voxel: settings.placement.mean_scale() * shape.voxel_size(shape.max_level),
            volume: settings.surfaces_in_volume.then(|| VolumeAroundSurfaces::new(lut, settings)),
        }
    }
}

impl PixelTracer for SurfaceCaster<'_> {
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
        self.trace_with_shadow(&ray, stats, requests, path, None)
    }

    /// One ray after another, as [`trace_one_by_one`](crate::frame::trace_one_by_one), but the shadow rays descend
    /// through a path of their own: paths kept between rays (a frame's, [`RenderSettings::shared_descents`]) then
    /// start each primary ray from the last primary ray's nodes and each shadow ray from the last shadow ray's.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn trace_rays(
        &self,
        origin: DVec3,
        rays: impl Iterator<Item = (usize, DVec3)>,
        spread: f64,
        stats: &mut RayStats,
        requests: &mut Vec<Request>,
        paths: &mut [DescentPath; LANES],
        mut emit: impl FnMut(usize, [f32; 3], f32, bool),
    ) {
        let [primary_path, shadow_path, ..] = paths;
        for (id, direction) in rays {
            let before = requests.len();
            let ray = Ray { origin, direction, spread, start: 0.0 };
            let (color, alpha) = self.trace_with_shadow(&ray, stats, requests, primary_path, Some(shadow_path));
            emit(id, color, alpha, requests.len() > before);
        }
    }
}

impl SurfaceCaster<'_> {
    /// The primary ray, then its shadow ray (through `shadow_path` if given, else through `path` too).
    #[inline(always)]
    fn trace_with_shadow(
        &self,
        ray: &Ray,
        stats: &mut RayStats,
        requests: &mut Vec<Request>,
        path: &mut DescentPath,
        shadow_path: Option<&mut DescentPath>,
    ) -> ([f32; 3], f32) {
        match self.volume {
            None => {
                let mut surfaces = Isosurfaces::new(self.surfaces, ray.direction);
                self.traversal.trace(ray, &mut surfaces, stats, requests, path);
                self.shadow(ray, &mut surfaces, stats, requests, shadow_path.unwrap_or(path));
                surfaces.result()
            }
            Some(volume) => {
                let mut both = SurfacesInVolume::new(self.surfaces, volume, ray.direction);
                self.traversal.trace(ray, &mut both, stats, requests, path);
                self.shadow(ray, both.surfaces(), stats, requests, shadow_path.unwrap_or(path));
                both.result()
            }
        }
    }

    /// With shadows on, a ray from the first crossing towards the light; a blocked light leaves the crossing its
    /// ambient term.
    #[inline(always)]
    fn shadow(
        &self,
        primary: &Ray,
        surfaces: &mut Isosurfaces<'_>,
        stats: &mut RayStats,
        requests: &mut Vec<Request>,
        path: &mut DescentPath,
    ) {
        let (Some(toward_light), Some(t_hit)) = (self.shadow_direction, surfaces.first_hit()) else { return };
        let Ray { origin, direction, spread, .. } = *primary;
        let point = origin + direction * t_hit;
        // Start the shadow ray `back` before its origin so that its cone at the surface is SHADOW_CONE times the
        // primary one's, then skip SHADOW_OFFSET footprints.
        let back = t_hit * SHADOW_CONE;
        let footprint = (t_hit * spread * SHADOW_CONE).max(self.finest_voxel);
        let shadow = Ray {
            origin: point - toward_light * back,
            direction: toward_light,
            spread,
            start: back + SHADOW_OFFSET * footprint,
        };
        let mut blocker = Isosurfaces::occlusion(self.surfaces);
        self.traversal.trace(&shadow, &mut blocker, stats, requests, path);
        if blocker.first_hit().is_some() {
            surfaces.shadow_first_hit();
        }
    }
}
