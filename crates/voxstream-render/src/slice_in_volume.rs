//! A plane of samples drawn with the volume (issue 42 item 8; the cut-away of medical viewers, ParaView's slice over
//! a clipped volume rendering): the part of the volume between the eye and the plane is cut away, and the plane is
//! drawn over the volume beyond it, so that the section shows in the context of the volume behind it.
//!
//! Along a ray that crosses the plane inside the volume's box, the slab (the plane one sample thick, its mean value
//! as `--slice` alone draws it: the mean projection between the slab's two planes) comes first, then the far part
//! (emission–absorption with one more clipping plane, at the slab's face away from the eye); rays that miss the
//! plane see the far part alone (its sides beyond the cut). Both are the one traversal ([`crate::traversal`]) with
//! their integrands, and both request what they miss, so the plane's bricks load as the volume's do. Where the slab
//! is opaque, the far part is not traced (it could not show).

use glam::DVec3;
use voxstream_core::{FeedbackBuffer, Request, TreeView};

use crate::clip_plane::ClipPlane;
use crate::frame::PixelTracer;
use crate::projection::{Projection, ProjectionCaster};
use crate::ray_caster::RayCaster;
use crate::settings::RenderSettings;
use crate::transfer_function::TransferLut;
use crate::traversal::{DescentPath, RayStats};

/// Opacity of the slab beyond which the volume behind it is not traced.
const OPAQUE: f32 = 0.999;

/// The clipping plane keeping the part of the volume beyond the slab `[a, b]` (two planes whose kept sides hold the
/// slab), seen from `eye`: the face the eye is not beyond, turned round. An eye inside the slab keeps `b`'s far side.
pub fn far_side(slab: &[ClipPlane; 2], eye: [f64; 3]) -> ClipPlane {
    let beyond = |plane: &ClipPlane| DVec3::from(plane.normal).dot(DVec3::from(eye) - DVec3::from(plane.point)) < 0.0;
    let face = if beyond(&slab[1]) { slab[0] } else { slab[1] };
    ClipPlane { point: face.point, normal: face.normal.map(|v| -v) }
}

/// Traces the slab's mean value and, behind it, the part of the volume beyond it.
pub struct SliceInVolume<'a> {
    slice: ProjectionCaster<'a>,
    volume: RayCaster<'a>,
}

impl<'a> SliceInVolume<'a> {
    /// Prepares both tracers for one frame seen from the world point `eye`; `settings.volume_slice` is the slab.
    pub fn new(
        view: TreeView<'a>,
        feedback: &'a FeedbackBuffer,
        lut: &'a TransferLut,
        settings: &RenderSettings,
        slab: [ClipPlane; 2],
        eye: [f64; 3],
    ) -> SliceInVolume<'a> {
        let mut volume = settings.clone();
        volume.volume_slice = None;
        volume.clip_planes.push(far_side(&slab, eye));
        let mut slice = settings.clone();
        slice.volume_slice = None;
        slice.projection = Projection::Mean;
        slice.clip_planes.extend(slab);
        SliceInVolume {
            slice: ProjectionCaster::new(view, feedback, lut, &slice),
            volume: RayCaster::new(view, feedback, lut, &volume),
        }
    }
}

impl PixelTracer for SliceInVolume<'_> {
    fn view(&self) -> TreeView<'_> {
        self.volume.view()
    }

    fn trace(
        &self,
        origin: DVec3,
        direction: DVec3,
        spread: f64,
        stats: &mut RayStats,
        requests: &mut Vec<Request>,
        path: &mut DescentPath,
    ) -> ([f32; 3], f32) {
        let (plane, plane_alpha) = self.slice.trace(origin, direction, spread, stats, requests, path);
        if plane_alpha >= OPAQUE {
            return (plane, plane_alpha);
        }
        let (far, far_alpha) = self.volume.trace(origin, direction, spread, stats, requests, path);
        let through = 1.0 - plane_alpha;
        (
            [plane[0] + through * far[0], plane[1] + through * far[1], plane[2] + through * far[2]],
            plane_alpha + through * far_alpha,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_far_side_is_beyond_the_slab_from_the_eye() {
        // The slab 4.5 ≤ z ≤ 5.5, as `--slice z=5` makes it.
        let slab = [
            ClipPlane { point: [0.0, 0.0, 4.5], normal: [0.0, 0.0, 1.0] },
            ClipPlane { point: [0.0, 0.0, 5.5], normal: [0.0, 0.0, -1.0] },
        ];
        let keeps = |plane: ClipPlane, z: f64| plane.normal[2] * (z - plane.point[2]) >= 0.0;
        let from_above = far_side(&slab, [1.0, 2.0, 30.0]);
        assert!(keeps(from_above, 1.0) && keeps(from_above, 4.5) && !keeps(from_above, 5.0) && !keeps(from_above, 9.0));
        let from_below = far_side(&slab, [1.0, 2.0, -30.0]);
        assert!(keeps(from_below, 9.0) && keeps(from_below, 5.5) && !keeps(from_below, 5.0) && !keeps(from_below, 1.0));
    }
}
