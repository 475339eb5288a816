//! A plane of samples drawn with the volume (issue 42 item 8; ParaView's slice inside a volume rendering, napari's
//! plane over a volume): the volume on the eye's side of the plane is composited over the plane's values, and the
//! volume beyond the plane is hidden behind it.
//!
//! The plane cuts the volume's box through and through, so every ray that would reach the far side crosses it
//! first: the picture is the near half's emission–absorption (the traversal with one more clipping plane, at the
//! slab's face nearer the eye) over the slab's mean value (the mean projection between the slab's two planes, as
//! `--slice` alone draws it), each ray tracing both with the one traversal ([`crate::traversal`]). Both request
//! what they miss, so the plane's bricks load as the volume's do. Where the near half is opaque, the slab is not
//! traced (it could not show).

use glam::DVec3;
use voxstream_core::{FeedbackBuffer, Request, TreeView};

use crate::clip_plane::ClipPlane;
use crate::frame::PixelTracer;
use crate::projection::{Projection, ProjectionCaster};
use crate::ray_caster::RayCaster;
use crate::settings::RenderSettings;
use crate::transfer_function::TransferLut;
use crate::traversal::{DescentPath, RayStats};

/// Opacity of the near half beyond which the slab behind it is not traced.
const OPAQUE: f32 = 0.999;

/// The clipping plane keeping the part of the volume on `eye`'s side of the slab `[a, b]` (two planes whose kept
/// sides hold the slab): the face the eye is beyond, turned round. An eye inside the slab keeps the side of `a`'s.
pub fn near_side(slab: &[ClipPlane; 2], eye: [f64; 3]) -> ClipPlane {
    let beyond = |plane: &ClipPlane| DVec3::from(plane.normal).dot(DVec3::from(eye) - DVec3::from(plane.point)) < 0.0;
    let face = if beyond(&slab[1]) { slab[1] } else { slab[0] };
    ClipPlane { point: face.point, normal: face.normal.map(|v| -v) }
}

/// Traces the near half of the volume and, behind it, the slab's mean value.
pub struct SliceInVolume<'a> {
    volume: RayCaster<'a>,
    slice: ProjectionCaster<'a>,
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
        volume.clip_planes.push(near_side(&slab, eye));
        let mut slice = settings.clone();
        slice.volume_slice = None;
        slice.projection = Projection::Mean;
        slice.clip_planes.extend(slab);
        SliceInVolume {
            volume: RayCaster::new(view, feedback, lut, &volume),
            slice: ProjectionCaster::new(view, feedback, lut, &slice),
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
        let (near, near_alpha) = self.volume.trace(origin, direction, spread, stats, requests, path);
        if near_alpha >= OPAQUE {
            return (near, near_alpha);
        }
        let (plane, plane_alpha) = self.slice.trace(origin, direction, spread, stats, requests, path);
        let through = 1.0 - near_alpha;
        (
            [near[0] + through * plane[0], near[1] + through * plane[1], near[2] + through * plane[2]],
            near_alpha + through * plane_alpha,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_near_side_is_the_eyes_side_of_the_slab() {
        // The slab 4.5 ≤ z ≤ 5.5, as `--slice z=5` makes it.
        let slab = [
            ClipPlane { point: [0.0, 0.0, 4.5], normal: [0.0, 0.0, 1.0] },
            ClipPlane { point: [0.0, 0.0, 5.5], normal: [0.0, 0.0, -1.0] },
        ];
        let keeps = |plane: ClipPlane, z: f64| plane.normal[2] * (z - plane.point[2]) >= 0.0;
        let above = near_side(&slab, [1.0, 2.0, 30.0]);
        assert!(keeps(above, 9.0) && keeps(above, 5.5) && !keeps(above, 5.0) && !keeps(above, 1.0));
        let below = near_side(&slab, [1.0, 2.0, -30.0]);
        assert!(keeps(below, 1.0) && keeps(below, 4.5) && !keeps(below, 5.0) && !keeps(below, 9.0));
    }
}
