//! Clipping planes: half-spaces that cut the volume open, as ParaView's and napari's clipping planes do.
//!
//! A plane is given in world units by a point on it and a normal pointing towards the part that is kept. Each ray's
//! interval inside the volume's clip box is narrowed to the kept side of every plane before the traversal starts
//! ([`crate::traversal`]), so a clipped-away part is neither sampled nor requested: the feedback asks only for what
//! the remaining rays cross (ray-guided loading, GigaVoxels [R08] §4). A crop box is the clip box itself
//! ([`crate::VolumePlacement::clip_lower`]); planes cut at any angle.

use glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::settings::VolumePlacement;

/// The most clipping planes a view may have (a box's six faces, at any angle).
pub const MAX_CLIP_PLANES: usize = 6;

/// A half-space of the world: the points `x` with `normal · (x − point) ≥ 0` are kept.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ClipPlane {
    /// A point on the plane, world units.
    pub point: [f64; 3],
    /// The plane's normal, towards the part kept (any non-zero length).
    pub normal: [f64; 3],
}

impl ClipPlane {
    /// Whether the plane is finite with a non-zero normal.
    pub fn is_valid(&self) -> bool {
        let normal = DVec3::from(self.normal);
        self.point.iter().all(|v| v.is_finite()) && normal.is_finite() && normal.length_squared() > 0.0
    }
}

/// A clipping plane in the volume's unit-cube coordinates, where rays are traced: `normal · v ≥ offset` is kept.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VolumePlane {
    normal: DVec3,
    offset: f64,
}

impl VolumePlane {
    /// `plane` in the unit-cube coordinates of `placement` (`world = origin + scale ⊙ v`): then
    /// `n · (world − p) = (n ⊙ scale) · v − n · (p − origin)`.
    pub fn new(plane: &ClipPlane, placement: &VolumePlacement) -> VolumePlane {
        let n = DVec3::from(plane.normal);
        let scale = DVec3::from(placement.scale);
        let normal = n * scale;
        // Normalised, so that the interval test's rounding does not depend on how long the normal was given.
        let length = normal.length();
        let offset = n.dot(DVec3::from(plane.point) - DVec3::from(placement.origin));
        VolumePlane { normal: normal / length, offset: offset / length }
    }

    /// Whether the unit-cube point `v` is kept.
    pub fn keeps(&self, v: DVec3) -> bool {
        self.normal.dot(v) >= self.offset
    }
}

/// Narrows the ray `origin + t·direction` over `[t_enter, t_leave]` to the part every plane keeps; `None` when
/// nothing is left.
#[inline]
pub fn clip_to_planes(
    origin: DVec3,
    direction: DVec3,
    (mut t_enter, mut t_leave): (f64, f64),
    planes: &[VolumePlane],
) -> Option<(f64, f64)> {
    for plane in planes {
        // f(t) = n·(o + t d) − offset ≥ 0.
        let at_origin = plane.normal.dot(origin) - plane.offset;
        let rate = plane.normal.dot(direction);
        if rate == 0.0 {
            if at_origin < 0.0 {
                return None;
            }
            continue;
        }
        let crossing = -at_origin / rate;
        if rate > 0.0 {
            t_enter = t_enter.max(crossing);
        } else {
            t_leave = t_leave.min(crossing);
        }
        if t_enter >= t_leave {
            return None;
        }
    }
    Some((t_enter, t_leave))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plane(point: [f64; 3], normal: [f64; 3]) -> ClipPlane {
        ClipPlane { point, normal }
    }

    #[test]
    fn a_plane_keeps_the_side_its_normal_points_to_in_volume_coordinates() {
        // A volume of 10 × 20 × 40 world units at (−5, 0, 100).
        let placement = VolumePlacement { origin: [-5.0, 0.0, 100.0], scale: [10.0, 20.0, 40.0], ..Default::default() };
        let keep_above = VolumePlane::new(&plane([0.0, 0.0, 110.0], [0.0, 0.0, 3.0]), &placement);
        // World z = 110 is volume z = 0.25.
        assert!(keep_above.keeps(DVec3::new(0.5, 0.5, 0.26)));
        assert!(!keep_above.keeps(DVec3::new(0.5, 0.5, 0.24)));
        // An oblique plane through the world point (0, 10, 120), normal (1, 1, 0): kept where x + y ≥ 10 (world).
        let oblique = VolumePlane::new(&plane([0.0, 10.0, 120.0], [1.0, 1.0, 0.0]), &placement);
        for (world, kept) in [([1.0, 10.0, 0.0], true), ([-1.0, 10.0, 0.0], false), ([4.0, 6.5, 0.0], true)] {
            let v = (DVec3::from(world) - DVec3::from(placement.origin)) / DVec3::from(placement.scale);
            assert_eq!(oblique.keeps(v), kept, "{world:?}");
        }
    }

    #[test]
    fn rays_are_cut_where_they_cross_and_dropped_when_nothing_is_left() {
        let placement = VolumePlacement::default();
        let planes = [
            VolumePlane::new(&plane([0.0, 0.0, 0.3], [0.0, 0.0, 1.0]), &placement),
            VolumePlane::new(&plane([0.0, 0.0, 0.7], [0.0, 0.0, -1.0]), &placement),
        ];
        // Along +z from z = −1: the slab [0.3, 0.7] is t ∈ [1.3, 1.7].
        let (a, b) = clip_to_planes(DVec3::new(0.5, 0.5, -1.0), DVec3::Z, (1.0, 2.0), &planes).expect("crosses");
        assert!((a - 1.3).abs() < 1e-12 && (b - 1.7).abs() < 1e-12, "{a} {b}");
        // Backwards, the same slab from the other side.
        let (a, b) = clip_to_planes(DVec3::new(0.5, 0.5, 2.0), -DVec3::Z, (1.0, 2.0), &planes).expect("crosses");
        assert!((a - 1.3).abs() < 1e-12 && (b - 1.7).abs() < 1e-12, "{a} {b}");
        // Parallel to the planes: kept inside the slab, dropped outside it.
        assert!(clip_to_planes(DVec3::new(0.0, 0.5, 0.5), DVec3::X, (0.0, 1.0), &planes).is_some());
        assert!(clip_to_planes(DVec3::new(0.0, 0.5, 0.9), DVec3::X, (0.0, 1.0), &planes).is_none());
        // Two planes that keep nothing between them.
        let disjoint = [planes[0], VolumePlane::new(&plane([0.0, 0.0, 0.2], [0.0, 0.0, -1.0]), &placement)];
        assert!(clip_to_planes(DVec3::new(0.5, 0.5, -1.0), DVec3::Z, (1.0, 2.0), &disjoint).is_none());
        assert!(!plane([0.0; 3], [0.0; 3]).is_valid());
        assert!(!plane([f64::NAN, 0.0, 0.0], [1.0, 0.0, 0.0]).is_valid());
    }
}
