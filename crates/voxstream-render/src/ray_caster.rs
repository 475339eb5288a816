//! The volume renderer's ray: the tree [`Traversal`] with the [`EmissionAbsorption`] integrand.
//!
//! This is what [`crate::frame`] calls per pixel; other integrands (isosurfaces, blending weights) pair with the
//! same traversal the same way.

use glam::DVec3;
use voxstream_core::{FeedbackBuffer, Request, TreeView};

use crate::emission_absorption::{EmissionAbsorption, EmissionAbsorptionSettings};
use crate::frame::PixelTracer;
use crate::settings::RenderSettings;
use crate::transfer_function::TransferLut;
use crate::traversal::{DescentPath, Ray, RayStats, Traversal};

/// Traces emission–absorption rays against one frame's tree view, writing feedback.
pub struct RayCaster<'a> {
    traversal: Traversal<'a>,
    lut: &'a TransferLut,
    integrand: EmissionAbsorptionSettings,
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
        }
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
        let mut integrand = EmissionAbsorption::new(self.lut, &self.integrand, direction);
        self.traversal.trace(&Ray { origin, direction, spread, start: 0.0 }, &mut integrand, stats, requests, path);
        integrand.result()
    }
}
