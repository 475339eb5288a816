//! The volume renderer's ray: the tree [`Traversal`] with the [`EmissionAbsorption`] integrand.
//!
//! This is what [`crate::frame`] calls per pixel; other integrands (isosurfaces, blending weights) pair with the
//! same traversal the same way.

use glam::DVec3;
use voxstream_core::{FeedbackBuffer, Request, TreeView};

use crate::block_visibility::BlockVisibility;
use crate::emission_absorption::{EmissionAbsorption, EmissionAbsorptionSettings};
use crate::frame::{trace_one_by_one, PixelTracer};
use crate::sampler::LANES;
use crate::settings::{RenderSettings, Shading};
use crate::transfer_function::TransferLut;
use crate::traversal::{DescentPath, Ray, RaySource, RayStats, Traversal};

/// Traces emission–absorption rays against one frame's tree view, writing feedback.
pub struct RayCaster<'a> {
    traversal: Traversal<'a>,
    lut: &'a TransferLut,
    integrand: EmissionAbsorptionSettings,
    /// Whether rays are traced side by side ([`RenderSettings::ray_packets`]).
    ray_packets: bool,
    /// Whether samples need gradients (Phong shading).
    shaded: bool,
    /// Whether segments between samples are pre-integrated ([`RenderSettings::preintegrated`]).
    preintegrated: bool,
    /// Which occupancy blocks the transfer function can see, per brick of this pass's view
    /// ([`RenderSettings::block_visibility_bits`]).
    block_visibility: Option<BlockVisibility>,
}

impl<'a> RayCaster<'a> {
    /// Prepares a ray caster for one frame.
    pub fn new(
        view: TreeView<'a>,
        feedback: &'a FeedbackBuffer,
        lut: &'a TransferLut,
        settings: &RenderSettings,
    ) -> RayCaster<'a> {
        RayCaster {
            traversal: Traversal::new(view, feedback, settings),
            lut,
            integrand: EmissionAbsorptionSettings::new(settings),
            // The lanes address the pool with `u32` voxel indices.
            ray_packets: settings.ray_packets && view.voxels.len() <= u32::MAX as usize,
            shaded: settings.shading == Shading::Phong,
            preintegrated: settings.preintegrated,
            block_visibility: settings.block_visibility_bits.then(|| BlockVisibility::new(&view)),
        }
    }
}

impl RayCaster<'_> {
    /// A ray's integrand, with this pass's block bits when they are on.
    #[inline(always)]
    fn ray_integrand<const PRE: bool>(&self, direction: DVec3) -> EmissionAbsorption<'_, PRE> {
        EmissionAbsorption::new(self.lut, &self.integrand, direction)
            .with_block_visibility(self.block_visibility.as_ref())
    }

    /// One ray, integrated with or without pre-integration.
    #[inline(always)]
    fn trace_one<const PRE: bool>(
        &self,
        ray: &Ray,
        stats: &mut RayStats,
        requests: &mut Vec<Request>,
        path: &mut DescentPath,
    ) -> ([f32; 3], f32) {
        let mut integrand = self.ray_integrand::<PRE>(ray.direction);
        self.traversal.trace(ray, &mut integrand, stats, requests, path);
        integrand.result()
    }

    /// Rays side by side, with or without pre-integration, with or without gradients.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn trace_lanes<const PRE: bool, const GRADIENT: bool>(
        &self,
        origin: DVec3,
        rays: impl Iterator<Item = (usize, DVec3)>,
        spread: f64,
        stats: &mut RayStats,
        requests: &mut Vec<Request>,
        paths: &mut [DescentPath; LANES],
        mut emit: impl FnMut(usize, [f32; 3], f32, bool),
    ) {
        let next_ray = PixelRays::<_, PRE> { caster: self, rays, origin, spread };
        let finish = |id, integrand: &EmissionAbsorption<'_, PRE>, requested| {
            let (color, alpha) = integrand.result();
            emit(id, color, alpha, requested);
        };
        self.traversal.trace_stream::<_, GRADIENT>(next_ray, finish, stats, requests, paths);
    }
}

/// The pixels' rays of one tile, each with its emission–absorption integrand.
struct PixelRays<'c, 'a, R, const PRE: bool> {
    caster: &'c RayCaster<'a>,
    rays: R,
    origin: DVec3,
    spread: f64,
}

impl<'c, R: Iterator<Item = (usize, DVec3)>, const PRE: bool> RaySource<EmissionAbsorption<'c, PRE>>
    for PixelRays<'c, '_, R, PRE>
{
    #[inline(always)]
    fn next_ray(&mut self) -> Option<(usize, Ray, EmissionAbsorption<'c, PRE>)> {
        let (id, direction) = self.rays.next()?;
        let ray = Ray { origin: self.origin, direction, spread: self.spread, start: 0.0 };
        Some((id, ray, self.caster.ray_integrand::<PRE>(direction)))
    }
}

impl PixelTracer for RayCaster<'_> {
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
        if self.preintegrated {
            self.trace_one::<true>(&ray, stats, requests, path)
        } else {
            self.trace_one::<false>(&ray, stats, requests, path)
        }
    }

    #[inline(always)]
    fn trace_rays(
        &self,
        origin: DVec3,
        rays: impl Iterator<Item = (usize, DVec3)>,
        spread: f64,
        stats: &mut RayStats,
        requests: &mut Vec<Request>,
        paths: &mut [DescentPath; LANES],
        emit: impl FnMut(usize, [f32; 3], f32, bool),
    ) {
        if !self.ray_packets {
            return trace_one_by_one(self, origin, rays, spread, stats, requests, &mut paths[0], emit);
        }
        match (self.preintegrated, self.shaded) {
            (false, false) => self.trace_lanes::<false, false>(origin, rays, spread, stats, requests, paths, emit),
            (false, true) => self.trace_lanes::<false, true>(origin, rays, spread, stats, requests, paths, emit),
            (true, false) => self.trace_lanes::<true, false>(origin, rays, spread, stats, requests, paths, emit),
            (true, true) => self.trace_lanes::<true, true>(origin, rays, spread, stats, requests, paths, emit),
        }
    }
}
