//! Orthogonal slices of a store (issue 42 item 8, napari's and ParaView's slice views): `--slice z=K` (also
//! `axial=K`, `coronal=K`, `sagittal=K`) draws the plane of level-0 samples `K` along that axis, alone, seen
//! face-on. It is made of seams the renderer already has, not a renderer of its own: two clipping planes keep the
//! slab one sample thick centred on the plane (world `origin + spacing·(K ± ½)`), the mean projection shows the
//! mean value through it (¾ of the plane's own samples and ⅛ of each neighbouring plane's, the trilinear
//! interpolant's mean over the slab), and the camera looks along the axis unless another view is given. The value
//! is shown through the transfer function as projections are: its colour, its opacity relative to its most opaque
//! point (transparent values show the background: a window). Volumes and slices in one image are not drawn yet.
//!
//! `axial`, `coronal` and `sagittal` name z, y and x: the anatomical planes for volumes stored with x across the
//! body (left–right), y front to back and z feet to head, as NIfTI's RAS and LPS orientations are.

use anyhow::{bail, Result};
use voxstream_render::{ClipPlane, Projection};

use crate::camera_presets::ViewDirection;
use crate::source::SourceMeta;
use crate::view::ViewOptions;

/// A slice: the plane of level-0 samples `index` along `axis` (0: x, 1: y, 2: z).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Slice {
    /// 0, 1 or 2 for x, y, z.
    pub axis: usize,
    /// The sample plane along it.
    pub index: u64,
}

/// Parses `AXIS=INDEX`: `x`, `y`, `z`, or `sagittal`, `coronal`, `axial`, and a sample index.
pub fn parse_slice(text: &str) -> Result<Slice, String> {
    let (name, index) = text.split_once('=').ok_or_else(|| {
        format!("'{text}' is not AXIS=INDEX: give e.g. --slice z=100 (x, y, z, or sagittal, coronal, axial)")
    })?;
    let axis = match name.trim().to_ascii_lowercase().as_str() {
        "x" | "sagittal" => 0,
        "y" | "coronal" => 1,
        "z" | "axial" => 2,
        other => return Err(format!("'{other}' is not an axis: give x, y, z, or sagittal, coronal, axial")),
    };
    let index = index
        .trim()
        .parse::<u64>()
        .map_err(|_| format!("'{}' is not a sample index: give a whole number, e.g. --slice z=100", index.trim()))?;
    Ok(Slice { axis, index })
}

/// `view` with `slice` applied for `source`: the slab's two clipping planes added, the mean projection (unless
/// another is asked for), and the camera along the axis unless the view places one.
pub(crate) fn slice_view(view: &ViewOptions, slice: Slice, source: &SourceMeta) -> Result<ViewOptions> {
    let axis_name = ["x", "y", "z"][slice.axis];
    let Some(store) = &source.store else {
        bail!("--slice applies to stores; {} is not one", source.name);
    };
    let info = store.info();
    if slice.index >= info.dims[slice.axis] {
        bail!(
            "--slice {axis_name}={}: {} has {} samples along {axis_name} (0 to {})",
            slice.index,
            source.name,
            info.dims[slice.axis],
            info.dims[slice.axis] - 1
        );
    }
    if !view.iso.values.is_empty() {
        bail!("--slice draws the values in a plane, not isosurfaces: drop --iso or --slice");
    }
    let mut sliced = view.clone();
    if sliced.projection == Projection::Composite {
        sliced.projection = Projection::Mean;
    }
    let a = slice.axis;
    let at = |offset: f64| {
        let mut point = info.origin;
        point[a] += info.spacing[a] * (slice.index as f64 + offset);
        point
    };
    let mut normal = [0.0; 3];
    normal[a] = 1.0;
    sliced.clip_planes.push(ClipPlane { point: at(-0.5), normal });
    normal[a] = -1.0;
    sliced.clip_planes.push(ClipPlane { point: at(0.5), normal });
    let camera = &view.camera;
    let placed = camera.file.is_some()
        || camera.camera.is_some()
        || camera.eye.is_some()
        || camera.target.is_some()
        || camera.preset.is_some();
    if !placed {
        sliced.camera.preset = Some([ViewDirection::PlusX, ViewDirection::PlusY, ViewDirection::MinusZ][slice.axis]);
    }
    Ok(sliced)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slices_parse_by_axis_or_anatomical_name() {
        assert_eq!(parse_slice("z=100"), Ok(Slice { axis: 2, index: 100 }));
        assert_eq!(parse_slice("Sagittal=7"), Ok(Slice { axis: 0, index: 7 }));
        assert_eq!(parse_slice("coronal = 3"), Ok(Slice { axis: 1, index: 3 }));
        assert!(parse_slice("z").unwrap_err().contains("AXIS=INDEX"));
        assert!(parse_slice("w=1").unwrap_err().contains("not an axis"));
        assert!(parse_slice("z=-1").unwrap_err().contains("not a sample index"));
    }
}
