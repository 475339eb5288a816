//! Orthogonal slices of a store (issue 42 item 8, napari's and ParaView's slice views): `--slice z=K` (also
//! `axial=K`, `coronal=K`, `sagittal=K`) draws the plane of level-0 samples `K` along that axis, alone, seen
//! face-on. It is made of seams the renderer already has, not a renderer of its own: two clipping planes keep the
//! slab one sample thick centred on the plane (world `origin + spacing·(K ± ½)`), the mean projection shows the
//! mean value through it (¾ of the plane's own samples and ⅛ of each neighbouring plane's, the trilinear
//! interpolant's mean over the slab), and the camera looks along the axis unless another view is given. The value
//! is shown through the transfer function as projections are: its colour, its opacity relative to its most opaque
//! point (transparent values show the background: a window). With `--with-volume` the plane is drawn inside the
//! volume rendering instead: the volume between the eye and the plane cut away, the plane over the volume beyond it,
//! seen from the default view
//! ([`voxstream_render::slice_in_volume`]).
//!
//! `axial`, `coronal` and `sagittal` name the planes across the body's head–feet, front–back and left–right axes:
//! where the store says its anatomical orientation ([`voxstream_store::Orientation`]), the sample axis nearest to
//! each (a sagittal DICOM series' `sagittal` is its z), seen as radiologists show them (axial from the feet, the
//! front up; coronal from the front; sagittal from the patient's left, head up); otherwise z, y and x, the planes of
//! volumes stored as NIfTI's RAS and DICOM's LPS are, seen along the axis.

use anyhow::{bail, Result};
use voxstream_render::{ClipPlane, Projection};

use voxstream_store::Orientation;

use crate::camera_presets::ViewDirection;
use crate::source::SourceMeta;
use crate::view::ViewOptions;

/// A slice: the plane of level-0 samples `index` along `axis`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Slice {
    /// The axis across the plane.
    pub axis: SliceAxis,
    /// The sample plane along it.
    pub index: u64,
    /// Drawn with the volume (`--with-volume`): the plane over the volume beyond it (what lies between the eye and
    /// the plane cut away), the
    /// source's default view (see [`voxstream_render::slice_in_volume`]); otherwise the plane alone, face-on.
    pub with_volume: bool,
}

/// The axis a slice is taken across: one of the data's, or the body's (resolved through the store's orientation).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SliceAxis {
    /// 0, 1 or 2 for x, y, z.
    Data(usize),
    /// Across the left–right axis.
    Sagittal,
    /// Across the front–back axis.
    Coronal,
    /// Across the head–feet axis.
    Axial,
}

impl SliceAxis {
    /// The data axis (0, 1, 2) this is across for a volume of `orientation`, and the preset the plane is seen from.
    fn resolve(self, orientation: Option<Orientation>) -> (usize, ViewDirection) {
        const ALONG: [ViewDirection; 3] = [ViewDirection::PlusX, ViewDirection::PlusY, ViewDirection::MinusZ];
        let (body_axis, seen_from) = match self {
            SliceAxis::Data(axis) => return (axis, ALONG[axis]),
            SliceAxis::Sagittal => (0, ViewDirection::Left),
            SliceAxis::Coronal => (1, ViewDirection::Anterior),
            SliceAxis::Axial => (2, ViewDirection::Inferior),
        };
        match orientation {
            Some(o) => {
                let axis = (0..3).find(|&a| o.axis(a).body_axis() == body_axis).unwrap_or(body_axis);
                (axis, seen_from)
            }
            None => (body_axis, ALONG[body_axis]),
        }
    }
}

/// Parses `AXIS=INDEX`: `x`, `y`, `z`, or `sagittal`, `coronal`, `axial`, and a sample index.
pub fn parse_slice(text: &str) -> Result<Slice, String> {
    let (name, index) = text.split_once('=').ok_or_else(|| {
        format!("'{text}' is not AXIS=INDEX: give e.g. --slice z=100 (x, y, z, or sagittal, coronal, axial)")
    })?;
    let axis = match name.trim().to_ascii_lowercase().as_str() {
        "x" => SliceAxis::Data(0),
        "y" => SliceAxis::Data(1),
        "z" => SliceAxis::Data(2),
        "sagittal" => SliceAxis::Sagittal,
        "coronal" => SliceAxis::Coronal,
        "axial" => SliceAxis::Axial,
        other => return Err(format!("'{other}' is not an axis: give x, y, z, or sagittal, coronal, axial")),
    };
    let index = index
        .trim()
        .parse::<u64>()
        .map_err(|_| format!("'{}' is not a sample index: give a whole number, e.g. --slice z=100", index.trim()))?;
    Ok(Slice { axis, index, with_volume: false })
}

/// `view` with `slice` applied for `source`: the slab's two clipping planes added, the mean projection (unless
/// another is asked for), and the camera along the axis unless the view places one.
pub(crate) fn slice_view(view: &ViewOptions, slice: Slice, source: &SourceMeta) -> Result<ViewOptions> {
    let Some(store) = &source.store else {
        bail!("--slice applies to stores; {} is not one", source.name);
    };
    let info = store.info();
    let (a, seen_from) = slice.axis.resolve(info.orientation);
    let axis_name = ["x", "y", "z"][a];
    let given = match slice.axis {
        SliceAxis::Data(_) => axis_name.to_string(),
        SliceAxis::Sagittal => format!("sagittal (across {axis_name})"),
        SliceAxis::Coronal => format!("coronal (across {axis_name})"),
        SliceAxis::Axial => format!("axial (across {axis_name})"),
    };
    if slice.index >= info.dims[a] {
        bail!(
            "--slice {given}={}: {} has {} samples along {axis_name} (0 to {})",
            slice.index,
            source.name,
            info.dims[a],
            info.dims[a] - 1
        );
    }
    if !view.iso.values.is_empty() {
        bail!("--slice draws the values in a plane, not isosurfaces: drop --iso or --slice");
    }
    if slice.with_volume && view.projection != Projection::Composite {
        bail!("--slice … --with-volume draws the plane inside a volume rendering: drop --projection or --with-volume");
    }
    let mut sliced = view.clone();
    if sliced.projection == Projection::Composite && !slice.with_volume {
        sliced.projection = Projection::Mean;
    }
    let at = |offset: f64| {
        let mut point = info.origin;
        point[a] += info.spacing[a] * (slice.index as f64 + offset);
        point
    };
    let mut normal = [0.0; 3];
    normal[a] = 1.0;
    let lower = ClipPlane { point: at(-0.5), normal };
    normal[a] = -1.0;
    let upper = ClipPlane { point: at(0.5), normal };
    if slice.with_volume {
        // The source's default view (or the one given) sees the plane inside the volume.
        sliced.volume_slice = Some([lower, upper]);
        return Ok(sliced);
    }
    sliced.clip_planes.extend([lower, upper]);
    let camera = &view.camera;
    let placed = camera.file.is_some()
        || camera.camera.is_some()
        || camera.eye.is_some()
        || camera.target.is_some()
        || camera.preset.is_some();
    if !placed {
        sliced.camera.preset = Some(seen_from);
    }
    Ok(sliced)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slices_parse_by_axis_or_anatomical_name() {
        let slice = |axis, index| Ok(Slice { axis, index, with_volume: false });
        assert_eq!(parse_slice("z=100"), slice(SliceAxis::Data(2), 100));
        assert_eq!(parse_slice("Sagittal=7"), slice(SliceAxis::Sagittal, 7));
        assert_eq!(parse_slice("coronal = 3"), slice(SliceAxis::Coronal, 3));
        assert!(parse_slice("z").unwrap_err().contains("AXIS=INDEX"));
        assert!(parse_slice("w=1").unwrap_err().contains("not an axis"));
        assert!(parse_slice("z=-1").unwrap_err().contains("not a sample index"));
    }

    #[test]
    fn anatomical_planes_follow_the_orientation() {
        let ras = Some(Orientation::RAS);
        assert_eq!(SliceAxis::Axial.resolve(ras), (2, ViewDirection::Inferior));
        assert_eq!(SliceAxis::Sagittal.resolve(ras), (0, ViewDirection::Left));
        // A sagittal series: x front to back, y head to feet, z across the body.
        let pir = Orientation::parse("PIR").ok();
        assert_eq!(SliceAxis::Sagittal.resolve(pir).0, 2);
        assert_eq!(SliceAxis::Coronal.resolve(pir).0, 0);
        assert_eq!(SliceAxis::Axial.resolve(pir).0, 1);
        // Without an orientation: z, y, x seen along the axis, as before.
        assert_eq!(SliceAxis::Axial.resolve(None), (2, ViewDirection::MinusZ));
        assert_eq!(SliceAxis::Coronal.resolve(None), (1, ViewDirection::PlusY));
        assert_eq!(SliceAxis::Data(0).resolve(pir), (0, ViewDirection::PlusX));
    }
}
