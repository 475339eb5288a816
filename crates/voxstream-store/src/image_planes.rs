//! Which 3-D volume of a 4-D or 5-D OME-Zarr image is read: the axes before z, y, x (time, channel) and the index
//! chosen along each (`--channel C`, `--time T`; 0 by default, and said), and the `omero` display metadata of the
//! chosen channel (its name, colour and contrast window), which the default transfer function follows (issue 42
//! item 5: an image's other channels were never reachable, and channel 0 was read silently).
//!
//! OME-NGFF names the leading axes in `axes` (type `time` or `channel`, or the names `t` and `c`); images without
//! `axes` (NGFF ≤ 0.3) are `t, c, z, y, x` when they have five dimensions.

use std::ops::Range;

use serde_json::Value;
use zarrs::array::Array;
use zarrs::storage::ReadableStorageTraits;

/// What a leading axis is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LeadingKind {
    /// Time points (`--time`).
    Time,
    /// Channels (`--channel`).
    Channel,
    /// Neither (read at index 0).
    Other,
}

impl LeadingKind {
    /// The kind's name in `info`'s text and JSON and the Python package's `info()`: `time`, `channel` or `other`.
    pub fn name(self) -> &'static str {
        match self {
            LeadingKind::Time => "time",
            LeadingKind::Channel => "channel",
            LeadingKind::Other => "other",
        }
    }
}

/// One axis before z, y, x: what it is, its name, how many samples it has and which one is read.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LeadingAxis {
    /// Time, channel or other.
    pub kind: LeadingKind,
    /// Its name in the metadata (`t`, `c`, …).
    pub name: String,
    /// Samples along it (level 0's).
    pub extent: u64,
    /// The index read.
    pub index: u64,
}

/// The channel and time point asked for (`None`: the first, 0).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PlaneChoice {
    /// `--channel`.
    pub channel: Option<u64>,
    /// `--time`.
    pub time: Option<u64>,
}

/// A channel's `omero` display metadata (OME-NGFF's "transitional" rendering settings).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct OmeroChannel {
    /// `label`.
    pub label: Option<String>,
    /// `color` (`RRGGBB`), as linear-free 0–1 RGB.
    pub color: Option<[f32; 3]>,
    /// `window.start`, `window.end`: the contrast limits the image's author chose.
    pub window: Option<[f64; 2]>,
}

/// What a reader shows of a 4-D/5-D image: its leading axes with the index read along each, and the chosen
/// channel's `omero` metadata. Empty for 3-D images and voxstream's own stores.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ImagePlanes {
    /// The axes before z, y, x.
    pub axes: Vec<LeadingAxis>,
    /// The chosen channel's display metadata, where the image has it.
    pub omero: Option<OmeroChannel>,
}

impl ImagePlanes {
    /// The axis of `kind`, if the image has one.
    pub fn axis(&self, kind: LeadingKind) -> Option<&LeadingAxis> {
        self.axes.iter().find(|a| a.kind == kind)
    }
}

/// The sample index read along each leading axis, as the reads and the value-range scan need it.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub(crate) struct LeadingIndex(pub Vec<u64>);

impl LeadingIndex {
    /// The subset ranges of the leading axes (one sample each), to which z, y, x ranges are appended.
    pub(crate) fn ranges(&self) -> Vec<Range<u64>> {
        self.0.iter().map(|&i| i..i + 1).collect()
    }

    /// How many leading axes there are.
    pub(crate) fn len(&self) -> usize {
        self.0.len()
    }

    /// Whether the chunk at grid indices `chunk` holds the chosen samples of the leading axes (a regular chunk grid).
    pub(crate) fn chunk_holds(&self, array: &Array<dyn ReadableStorageTraits>, chunk: &[u64]) -> bool {
        let Ok(Some(shape)) = array.chunk_shape(&vec![0; array.dimensionality()]).map(Some) else {
            return false;
        };
        self.0.iter().enumerate().all(|(a, &i)| chunk.get(a) == Some(&(i / shape[a].get())))
    }
}

/// An axis' name from OME-NGFF 0.4+ (`{"name": "c", "type": "channel"}`) or 0.3 (`"c"`), lower case.
fn axis_name(axis: &Value) -> Option<String> {
    axis.as_str().or_else(|| axis.get("name").and_then(Value::as_str)).map(str::to_ascii_lowercase)
}

/// The kinds and names of the `shape.len() - 3` leading axes of a multiscales entry.
fn leading_kinds(multiscale: &Value, dimensions: usize) -> Vec<(LeadingKind, String)> {
    let leading = dimensions.saturating_sub(3);
    match multiscale.get("axes").and_then(Value::as_array) {
        Some(axes) => axes[..leading.min(axes.len())]
            .iter()
            .map(|axis| {
                let name = axis_name(axis).unwrap_or_default();
                let kind = match (axis.get("type").and_then(Value::as_str), name.as_str()) {
                    (Some("time"), _) | (None, "t") => LeadingKind::Time,
                    (Some("channel"), _) | (None, "c") => LeadingKind::Channel,
                    _ => LeadingKind::Other,
                };
                (kind, name)
            })
            .collect(),
        // NGFF ≤ 0.3: five dimensions are t, c, z, y, x.
        None if leading == 2 => vec![(LeadingKind::Time, "t".into()), (LeadingKind::Channel, "c".into())],
        None => (0..leading).map(|a| (LeadingKind::Other, format!("axis {a}"))).collect(),
    }
}

/// The leading axes of an image of level-0 `shape` and the index read along each, from `choice`. A channel or time
/// point beyond the image's, or asked of an image without such an axis, is refused naming what there is.
pub(crate) fn choose_planes(
    multiscale: &Value,
    shape: &[u64],
    choice: PlaneChoice,
) -> Result<Vec<LeadingAxis>, String> {
    let kinds = leading_kinds(multiscale, shape.len());
    let mut axes = Vec::new();
    for (a, (kind, name)) in kinds.into_iter().enumerate() {
        let extent = shape[a];
        let (asked, flag, noun) = match kind {
            LeadingKind::Channel => (choice.channel, "--channel", "channels"),
            LeadingKind::Time => (choice.time, "--time", "time points"),
            LeadingKind::Other => (None, "", ""),
        };
        let index = asked.unwrap_or(0);
        if index >= extent {
            return Err(format!("{flag} {index}: the image has {extent} {noun} (0 to {})", extent - 1));
        }
        axes.push(LeadingAxis { kind, name, extent, index });
    }
    for (asked, kind, flag, noun) in [
        (choice.channel, LeadingKind::Channel, "--channel", "channel"),
        (choice.time, LeadingKind::Time, "--time", "time"),
    ] {
        if asked.is_some() && !axes.iter().any(|axis| axis.kind == kind) {
            let names: Vec<String> =
                axes.iter().map(|a| a.name.clone()).chain(["z", "y", "x"].map(String::from)).collect();
            return Err(format!("{flag}: the image has no {noun} axis (its axes: {})", names.join(", ")));
        }
    }
    Ok(axes)
}

/// The indices read along `axes`.
pub(crate) fn leading_index(axes: &[LeadingAxis]) -> LeadingIndex {
    LeadingIndex(axes.iter().map(|a| a.index).collect())
}

/// Channel `channel`'s `omero` metadata in a group's attributes (`ome.omero` in Zarr v3, `omero` in v2), if any.
pub(crate) fn omero_channel(attributes: &serde_json::Map<String, Value>, channel: u64) -> Option<OmeroChannel> {
    let omero = attributes.get("ome").and_then(|ome| ome.get("omero")).or_else(|| attributes.get("omero"))?;
    let entry = omero.get("channels")?.as_array()?.get(usize::try_from(channel).ok()?)?;
    let label = entry.get("label").and_then(Value::as_str).map(str::to_string);
    let color = entry.get("color").and_then(Value::as_str).and_then(parse_color);
    let window = entry.get("window").and_then(|w| {
        let start = w.get("start").and_then(Value::as_f64)?;
        let end = w.get("end").and_then(Value::as_f64)?;
        (start.is_finite() && end.is_finite() && start < end).then_some([start, end])
    });
    Some(OmeroChannel { label, color, window })
}

/// `RRGGBB` (optionally `#`-prefixed) as 0–1 RGB.
fn parse_color(text: &str) -> Option<[f32; 3]> {
    let hex = text.trim_start_matches('#');
    if hex.len() != 6 || !hex.is_ascii() {
        return None;
    }
    let byte = |i: usize| u8::from_str_radix(&hex[i..i + 2], 16).ok().map(|b| f32::from(b) / 255.0);
    Some([byte(0)?, byte(2)?, byte(4)?])
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn channels_and_time_points_are_chosen_and_checked() {
        let ms = json!({"axes": [{"name": "t", "type": "time"}, {"name": "c", "type": "channel"}, "z", "y", "x"]});
        let shape = [3, 2, 10, 10, 10];
        let axes = choose_planes(&ms, &shape, PlaneChoice { channel: Some(1), time: Some(2) }).unwrap();
        assert_eq!(leading_index(&axes), LeadingIndex(vec![2, 1]));
        assert_eq!((axes[0].kind, axes[1].kind), (LeadingKind::Time, LeadingKind::Channel));
        assert_eq!(leading_index(&choose_planes(&ms, &shape, PlaneChoice::default()).unwrap()).0, [0, 0]);
        let error = choose_planes(&ms, &shape, PlaneChoice { channel: Some(2), time: None }).unwrap_err();
        assert_eq!(error, "--channel 2: the image has 2 channels (0 to 1)");
        let error = choose_planes(&ms, &shape, PlaneChoice { channel: None, time: Some(3) }).unwrap_err();
        assert_eq!(error, "--time 3: the image has 3 time points (0 to 2)");
        // NGFF 0.3 (no axes): five dimensions are t, c, z, y, x.
        let axes = choose_planes(&json!({}), &shape, PlaneChoice { channel: Some(1), time: None }).unwrap();
        assert_eq!(leading_index(&axes).0, [0, 1]);
        // A 3-D image has neither.
        let error = choose_planes(&json!({}), &[10, 10, 10], PlaneChoice { channel: Some(0), time: None });
        assert_eq!(error.unwrap_err(), "--channel: the image has no channel axis (its axes: z, y, x)");
        let ms = json!({"axes": [{"name": "c", "type": "channel"}, "z", "y", "x"]});
        let error = choose_planes(&ms, &[4, 10, 10, 10], PlaneChoice { channel: None, time: Some(1) });
        assert_eq!(error.unwrap_err(), "--time: the image has no time axis (its axes: c, z, y, x)");
    }

    #[test]
    fn omero_channels_give_their_label_colour_and_window() {
        let attributes = json!({"omero": {"channels": [
            {"label": "DAPI", "color": "0000FF", "window": {"start": 10, "end": 400, "min": 0, "max": 4095}},
            {"label": "GFP", "color": "#00ff00", "window": {"start": 5, "end": 5}},
        ]}});
        let attributes = attributes.as_object().unwrap();
        let dapi = omero_channel(attributes, 0).unwrap();
        assert_eq!(dapi.label.as_deref(), Some("DAPI"));
        assert_eq!(dapi.color, Some([0.0, 0.0, 1.0]));
        assert_eq!(dapi.window, Some([10.0, 400.0]));
        // An empty window is no window.
        let gfp = omero_channel(attributes, 1).unwrap();
        assert_eq!((gfp.color, gfp.window), (Some([0.0, 1.0, 0.0]), None));
        assert_eq!(omero_channel(attributes, 2), None);
        let v3 = json!({"ome": {"omero": {"channels": [{"color": "zz0000"}]}}});
        assert_eq!(omero_channel(v3.as_object().unwrap(), 0), Some(OmeroChannel::default()));
    }
}
