//! A source's defaults: where a store's volume sits in the world, the camera that frames it, the transfer function
//! that shows it, and the checks and number formats shared by every front end's messages.

use anyhow::{bail, Result};
use voxstream_render::{Camera, TransferFunction, VolumePlacement};
use voxstream_store::StoreReader;

/// Where a store's tree cube sits in the world: sample `(i, j, k)` at `origin + spacing·(i, j, k)` (VTK/ITK), the
/// rays clipped to the box of the sample centres, as VTK's ray casters do. Along an axis of one sample (a single
/// slice), where that box would be flat and show nothing, the box is the sample's cell, one spacing thick.
pub fn store_placement(reader: &StoreReader) -> VolumePlacement {
    let info = reader.info();
    let layout = reader.layout();
    let span = (layout.brick_size << layout.max_tree_level()) as f64;
    let single = |a: usize| info.dims[a] <= 1;
    VolumePlacement {
        origin: [0, 1, 2].map(|a| info.origin[a] - 0.5 * info.spacing[a]),
        scale: [0, 1, 2].map(|a| info.spacing[a] * span),
        clip_lower: [0, 1, 2].map(|a| if single(a) { 0.0 } else { 0.5 / span }),
        clip_upper: [0, 1, 2].map(|a| if single(a) { 1.0 / span } else { (info.dims[a] as f64 - 0.5) / span }),
    }
}

/// Direction from a store's centre towards the default eye, in the volume's axes when it has no anatomical
/// orientation: a three-quarter view from the −y side, +x and above (+z up). For a volume in DICOM's LPS axes this is
/// the view from the patient's front, left and above, which [`ANATOMICAL_VIEW_DIRECTION`] gives every orientation.
pub const STORE_VIEW_DIRECTION: [f64; 3] = [0.55, -0.65, 0.52];

/// Direction from a store's centre towards the default eye, in RAS, for a volume with an anatomical orientation:
/// from the front (anterior), the patient's left and above, superior up (3D Slicer's default 3D view, turned to three
/// quarters as the index-axes default is).
pub const ANATOMICAL_VIEW_DIRECTION: [f64; 3] = [-0.55, 0.65, 0.52];

/// The default view's direction towards the eye and its up direction, in the volume's axes: from the patient's
/// front-left and above, head up, where the volume's anatomical orientation is known; otherwise
/// [`STORE_VIEW_DIRECTION`], `+z` up.
pub fn store_view_direction(info: &voxstream_store::VolumeInfo) -> ([f64; 3], [f64; 3]) {
    match info.orientation {
        Some(orientation) => {
            (orientation.volume_direction(ANATOMICAL_VIEW_DIRECTION), orientation.volume_direction([0.0, 0.0, 1.0]))
        }
        None => (STORE_VIEW_DIRECTION, [0.0, 0.0, 1.0]),
    }
}

/// Fraction of the image's half-width and half-height the volume's box may fill in the default store view.
const STORE_FRAME_FILL: f64 = 0.95;

/// A three-quarter view of the volume's centre ([`store_view_direction`]: from the front, head up, when the volume's
/// anatomical orientation is known), 30° vertical field of view, just far enough that all eight corners of the
/// volume's box (the sample centres) fall inside a `width × height` image.
pub fn store_camera(info: &voxstream_store::VolumeInfo, width: u32, height: u32) -> Camera {
    let lower = info.origin;
    let upper = [0, 1, 2].map(|a| info.origin[a] + (info.dims[a] as f64 - 1.0) * info.spacing[a]);
    let (towards_eye, up) = store_view_direction(info);
    frame_box(lower, upper, width, height, towards_eye, up)
}

/// A view of the box `lower..upper` from its centre's side `towards_eye`, `up` up, 30° vertical field of view, just
/// far enough that all eight corners fall inside a `width × height` image.
pub fn frame_box(
    lower: [f64; 3],
    upper: [f64; 3],
    width: u32,
    height: u32,
    towards_eye: [f64; 3],
    up: [f64; 3],
) -> Camera {
    frame_box_with_fov(lower, upper, width, height, towards_eye, up, 30.0)
}

/// [`frame_box`] with a vertical field of view of `fov` degrees.
pub fn frame_box_with_fov(
    lower: [f64; 3],
    upper: [f64; 3],
    width: u32,
    height: u32,
    towards_eye: [f64; 3],
    up: [f64; 3],
    fov: f64,
) -> Camera {
    use glam::DVec3;
    let lower = DVec3::from(lower);
    let upper = DVec3::from(upper);
    let centre = (lower + upper) * 0.5;
    let up_hint = DVec3::from(up);
    let towards_eye = DVec3::from(towards_eye).normalize();
    // The camera's basis (as `Camera::frame` builds it): forward = −towards_eye, right = forward × up.
    let forward = -towards_eye;
    let right = forward.cross(up_hint).normalize();
    let up = right.cross(forward);
    let tan_vertical = (fov.to_radians() * 0.5).tan() * STORE_FRAME_FILL;
    let tan_horizontal = tan_vertical * width.max(1) as f64 / height.max(1) as f64;
    // A corner at offset r from the centre lies at depth D − r·towards_eye from an eye at distance D; it is inside
    // the image when |r·right| ≤ tan_h·depth and |r·up| ≤ tan_v·depth.
    let mut distance: f64 = 1e-9;
    for corner in 0..8 {
        let pick = |axis: usize| if corner >> axis & 1 == 1 { upper[axis] } else { lower[axis] };
        let r = DVec3::new(pick(0), pick(1), pick(2)) - centre;
        let along = r.dot(towards_eye);
        distance =
            distance.max(r.dot(right).abs() / tan_horizontal + along).max(r.dot(up).abs() / tan_vertical + along);
    }
    let eye = centre + towards_eye * distance;
    Camera { eye: eye.to_array(), target: centre.to_array(), up: up_hint.to_array(), fov }
}

/// A soft ramp over the upper 80% of `range` (the data's 0.5th to 99.5th percentile), reaching opacity 0.12 per
/// sample spacing at its top.
pub fn default_store_transfer_function(range: [f64; 2]) -> Result<TransferFunction> {
    let [lo, hi] = range;
    let hi = if hi > lo { hi } else { lo + 1.0 };
    let at = |f: f64| lo + (hi - lo) * f;
    Ok(TransferFunction::new(
        vec![
            [lo, 0.0, 0.0, 0.0, 0.0],
            [at(0.2), 0.55, 0.35, 0.25, 0.0],
            [at(0.6), 0.95, 0.8, 0.6, 0.05],
            [hi, 1.0, 1.0, 1.0, 0.12],
        ],
        None,
    )?)
}

/// The transfer function of an OME-Zarr channel's `omero` display settings: opacity and brightness ramping over its
/// contrast `window` (napari's contrast limits) in its colour (white where it names none), as `default_store_…`'s
/// ramp reaches 0.12 per sample spacing at its top.
pub fn omero_transfer_function(window: [f64; 2], color: Option<[f32; 3]>) -> Result<TransferFunction> {
    let [lo, hi] = window;
    let [r, g, b] = color.unwrap_or([1.0; 3]).map(f64::from);
    let mid = lo + 0.5 * (hi - lo);
    Ok(TransferFunction::new(
        vec![[lo, 0.0, 0.0, 0.0, 0.0], [mid, 0.6 * r, 0.6 * g, 0.6 * b, 0.04], [hi, r, g, b, 0.12]],
        None,
    )?)
}

pub use voxstream_render::annotations::shown_number;

/// A sample value as a user would read it: values that are float32s (every stored sample is) with float32's
/// shortest digits (`5.4288025`, not `5.428802490234375`), otherwise as [`shown_number`].
pub fn shown_value(value: f64) -> String {
    let single = value as f32;
    if !(value.is_finite() && f64::from(single) == value) {
        return shown_number(value);
    }
    if value == 0.0 || (1e-4..1e15).contains(&value.abs()) {
        format!("{single}")
    } else {
        format!("{single:e}")
    }
}

/// `n` and the noun in its number: `1 level`, `4 levels` (`singular` or `plural` as `n` asks).
pub fn counted(n: impl Into<u64>, singular: &str, plural: &str) -> String {
    let n = n.into();
    format!("{n} {}", if n == 1 { singular } else { plural })
}

/// The volume's place in the world is the source's (a store's spacing and origin, a mesh's bounds), not the flags':
/// a bad one is blamed on the source.
pub fn check_placement(name: &str, placement: &VolumePlacement) -> Result<()> {
    let finite = placement.origin.iter().chain(&placement.scale).all(|v| v.is_finite());
    if !(finite && placement.scale.iter().all(|s| *s > 0.0)) {
        bail!(
            "{name}: its place in the world is not finite (origin {:?}, size {:?}): its coordinates are too large \
             (for a store, its spacing and origin: see `voxstream info`)",
            placement.origin,
            placement.scale
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_and_counts_read_as_a_user_would_write_them() {
        assert_eq!(shown_value(f64::from(5.428_802_5f32)), "5.4288025");
        assert_eq!(shown_value(f64::from(2.171_455_2e-13f32)), "2.1714552e-13");
        assert_eq!(shown_value(3050.0), "3050");
        assert_eq!(shown_value(-888.0), "-888");
        assert_eq!(shown_value(0.1), "0.1", "not a float32: as shown_number");
        assert_eq!(counted(1u64, "level", "levels"), "1 level");
        assert_eq!(counted(4u64, "level", "levels"), "4 levels");
        assert_eq!(counted(0u64, "brick", "bricks"), "0 bricks");
    }
}
