//! The store's metadata: OME-Zarr 0.5 multiscales (what standard readers use) plus voxstream's own attributes.

use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

use crate::layout::PyramidLayout;
use crate::volume::{DType, VolumeInfo};

/// Path of the per-brick min/max arrays under the store root (`minmax/0`, `minmax/1`, …).
pub const MINMAX_GROUP: &str = "voxstream_minmax";

/// The `format_version` this voxstream writes and reads; a store with a larger one was written by a newer voxstream.
pub const FORMAT_VERSION: u32 = 1;

/// voxstream's attributes, under `attributes.voxstream` of the root group.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StoreAttributes {
    /// Format version of these attributes.
    pub format_version: u32,
    /// Samples per axis at level 0 (x, y, z).
    pub dims: [u64; 3],
    /// Sample type name (`u8`, `u16`, `i16`, `f32`).
    pub dtype: String,
    /// World spacing (x, y, z).
    pub spacing: [f64; 3],
    /// World origin of sample (0, 0, 0).
    pub origin: [f64; 3],
    /// Unit of `spacing` and `origin`, an OME-Zarr space unit name (`millimeter`); absent when the input did not
    /// say it, and in stores written before units were kept.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unit: Option<String>,
    /// The anatomical direction each axis (x, y, z) points to, as three letters ([`crate::Orientation`]: `RAS`);
    /// absent when the input did not say it, and in stores written before orientations were kept.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub orientation: Option<String>,
    /// Brick (inner chunk) edge.
    pub brick_size: u64,
    /// Levels, 0 = full resolution.
    pub levels: usize,
    /// Smallest and largest sample value at level 0.
    pub value_range: [f64; 2],
    /// The import finished: absent or false means an interrupted import.
    #[serde(default)]
    pub complete: bool,
    /// `[percent, value]` pairs of the level-0 samples, percents increasing (see
    /// [`crate::value_histogram::STORED_PERCENTILES`]); absent in stores written before they were kept, and for
    /// foreign OME-Zarr images.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub value_percentiles: Option<Vec<[f64; 2]>>,
    /// How the bricks are compressed, when not zstd (`{"name": "wavelet", "max_error": E}`): absent for zstd, the
    /// codec every Zarr reader opens. A lossy codec's per-brick min/max (`minmax/`) are its decoded samples'.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub brick_codec: Option<crate::import::BrickCodec>,
}

impl StoreAttributes {
    /// Attributes for a volume and layout.
    pub fn new(info: &VolumeInfo, layout: &PyramidLayout, value_range: [f64; 2], complete: bool) -> StoreAttributes {
        StoreAttributes {
            format_version: FORMAT_VERSION,
            dims: info.dims,
            dtype: info.dtype.name().into(),
            spacing: info.spacing,
            origin: info.origin,
            unit: info.unit.map(|u| u.name().to_string()),
            orientation: info.orientation.map(|o| o.code()),
            brick_size: layout.brick_size,
            levels: layout.levels(),
            value_range,
            complete,
            value_percentiles: None,
            brick_codec: None,
        }
    }

    /// The value at `percent` of the stored percentiles, if kept.
    pub fn percentile(&self, percent: f64) -> Option<f64> {
        self.value_percentiles.as_ref()?.iter().find(|p| p[0] == percent).map(|p| p[1])
    }

    /// The values that the bulk of the data spans: from the 0.5th to the 99.5th percentile when the store keeps
    /// them and they differ, otherwise the value range. Default transfer functions are placed over it.
    pub fn typical_range(&self) -> [f64; 2] {
        match (self.percentile(0.5), self.percentile(99.5)) {
            (Some(low), Some(high)) if high > low => [low, high],
            _ => self.value_range,
        }
    }

    /// The sample type.
    pub fn dtype(&self) -> Option<DType> {
        DType::from_name(&self.dtype)
    }
}

/// The `ome` attribute: axes z, y, x (with the volume's unit and anatomical orientation, when known) and one dataset per level with its scale
/// and translation.
pub fn ome_multiscales(name: &str, info: &VolumeInfo, layout: &PyramidLayout) -> Value {
    let datasets: Vec<Value> = (0..layout.levels())
        .map(|level| {
            let factor = (1u64 << level) as f64;
            // A level-l sample averages a 2^l block: its centre is (2^l − 1)/2 samples from the block's first one.
            let shift = (factor - 1.0) / 2.0;
            let [sx, sy, sz] = info.spacing;
            let [ox, oy, oz] = info.origin;
            json!({
                "path": level.to_string(),
                "coordinateTransformations": [
                    {"type": "scale", "scale": [sz * factor, sy * factor, sx * factor]},
                    {"type": "translation", "translation": [oz + shift * sz, oy + shift * sy, ox + shift * sx]}
                ]
            })
        })
        .collect();
    let axes: Vec<Value> = [(2, "z"), (1, "y"), (0, "x")]
        .iter()
        .map(|&(index, axis)| {
            let mut entry = json!({"name": axis, "type": "space"});
            if let Some(unit) = info.unit {
                entry["unit"] = json!(unit.name());
            }
            // OME-NGFF RFC-4's anatomical orientation of the axis.
            if let Some(orientation) = info.orientation {
                entry["orientation"] = json!({"type": "anatomical", "value": orientation.axis(index).rfc4_value()});
            }
            entry
        })
        .collect();
    json!({
        "version": "0.5",
        "multiscales": [{
            "name": name,
            "axes": axes,
            "datasets": datasets,
            "type": "mean"
        }]
    })
}
