//! One DICOM file's header, as far as a volume needs it: which series it belongs to, its image's size and sample
//! encoding, where its slice (or each of its frames) lies in the patient's space, and the rescale to the modality's
//! values (Hounsfield units for CT). Read with dicom-rs up to the pixel data, so a header costs a few kilobytes of
//! reading whatever the image's size. [`super::dicom`] assembles the headers of a folder into one volume.
//!
//! Positions and orientations are DICOM's patient coordinates (millimetres, LPS); enhanced multi-frame files keep
//! them per frame in the functional group sequences (PS3.3 C.7.6.16), RT dose grids as offsets along the normal
//! (`GridFrameOffsetVector`), both read here.

use std::path::{Path, PathBuf};

use dicom_dictionary_std::tags;
use dicom_object::mem::InMemElement;
use dicom_object::{InMemDicomObject, OpenFileOptions, Tag};

use crate::error::StoreError;

/// What a volume needs from one DICOM file's header.
#[derive(Clone, Debug)]
pub struct DicomHeader {
    /// The file.
    pub path: PathBuf,
    /// Series Instance UID (empty when absent).
    pub series: String,
    /// Series Description, for messages.
    pub description: String,
    /// Modality (CT, MR, PT, RTDOSE …), for messages.
    pub modality: String,
    /// The transfer syntax's UID.
    pub transfer_syntax: String,
    /// Rows (y) and Columns (x) of each frame.
    pub rows: u32,
    /// Columns (x).
    pub columns: u32,
    /// Frames in the file (1 for a classic single-slice file).
    pub frames: u32,
    /// Bits Allocated per sample (8, 16 or 32 are read).
    pub bits_allocated: u16,
    /// Bits Stored (the low bits of each allocated sample that carry its value).
    pub bits_stored: u16,
    /// High Bit (must be `bits_stored - 1`).
    pub high_bit: u16,
    /// Pixel Representation 1: two's complement.
    pub signed: bool,
    /// Samples per Pixel (1 for greyscale).
    pub samples_per_pixel: u16,
    /// Photometric Interpretation.
    pub photometric: String,
    /// Image Orientation (Patient): the row's then the column's direction cosines.
    pub orientation: Option<[f64; 6]>,
    /// Image Position (Patient) of each frame's first sample, when the file says it.
    pub positions: Vec<[f64; 3]>,
    /// Pixel Spacing: between rows (y), then between columns (x), in mm.
    pub pixel_spacing: Option<[f64; 2]>,
    /// Spacing Between Slices, or Slice Thickness where that is absent.
    pub slice_spacing: Option<f64>,
    /// Instance Number, for series without positions.
    pub instance: Option<i64>,
    /// Rescale slope and intercept of each frame (one pair for all frames when the file has one).
    pub rescale: Vec<(f64, f64)>,
}

impl DicomHeader {
    /// Bytes one frame takes decoded.
    pub fn frame_bytes(&self) -> u64 {
        self.rows as u64
            * self.columns as u64
            * self.samples_per_pixel as u64
            * (self.bits_allocated as u64).div_ceil(8)
    }

    /// Rescale slope and intercept of frame `frame`.
    pub fn rescale_of(&self, frame: usize) -> (f64, f64) {
        self.rescale.get(frame).or(self.rescale.first()).copied().unwrap_or((1.0, 0.0))
    }
}

/// `true` when `path` is a DICOM Part 10 file: 128 bytes of preamble, then `DICM`.
pub fn has_dicom_magic(path: &Path) -> bool {
    use std::io::Read;
    let mut head = [0u8; 132];
    std::fs::File::open(path).and_then(|mut f| f.read_exact(&mut head)).is_ok() && &head[128..132] == b"DICM"
}

fn element<'a>(object: &'a InMemDicomObject, tag: Tag) -> Option<&'a InMemElement> {
    object.get(tag)
}

fn text(object: &InMemDicomObject, tag: Tag) -> String {
    element(object, tag).and_then(|e| e.to_str().ok()).map(|s| s.trim().to_string()).unwrap_or_default()
}

fn floats(object: &InMemDicomObject, tag: Tag) -> Option<Vec<f64>> {
    element(object, tag).and_then(|e| e.to_multi_float64().ok()).filter(|v| v.iter().all(|x| x.is_finite()))
}

fn float(object: &InMemDicomObject, tag: Tag) -> Option<f64> {
    floats(object, tag).and_then(|v| v.first().copied())
}

fn int(object: &InMemDicomObject, tag: Tag) -> Option<i64> {
    element(object, tag).and_then(|e| e.to_int::<i64>().ok())
}

/// The items of sequence `tag`, or none.
fn items(object: &InMemDicomObject, tag: Tag) -> &[InMemDicomObject] {
    element(object, tag).and_then(|e| e.items()).unwrap_or(&[])
}

/// The first item of `outer`'s sequence `group` holding a sequence `inner`, and that sequence's first item.
fn nested<'a>(object: &'a InMemDicomObject, group: Tag, inner: Tag) -> Option<&'a InMemDicomObject> {
    items(object, group).first().and_then(|item| items(item, inner).first())
}

/// A value the volume needs, read from the file itself or else from the shared functional groups of an enhanced
/// multi-frame file.
fn shared<'a>(object: &'a InMemDicomObject, inner: Tag) -> Option<&'a InMemDicomObject> {
    nested(object, tags::SHARED_FUNCTIONAL_GROUPS_SEQUENCE, inner)
}

fn array<const N: usize>(values: Option<Vec<f64>>) -> Option<[f64; N]> {
    values.and_then(|v| v.get(..N).and_then(|s| <[f64; N]>::try_from(s).ok()))
}

fn rescale_in(object: &InMemDicomObject) -> Option<(f64, f64)> {
    let slope = float(object, tags::RESCALE_SLOPE);
    let intercept = float(object, tags::RESCALE_INTERCEPT);
    (slope.is_some() || intercept.is_some()).then(|| (slope.unwrap_or(1.0), intercept.unwrap_or(0.0)))
}

/// Reads `path`'s header (everything before its pixel data). `Ok(None)` for a DICOM file that holds no image (a
/// DICOMDIR, a structured report, a structure set): a folder of a study holds such files beside its images.
pub fn read_header(path: &Path) -> Result<Option<DicomHeader>, StoreError> {
    super::dicom_lengths::check_element_lengths(path)
        .map_err(|reason| StoreError::format(path, format!("damaged DICOM file: {reason}")))?;
    let object = OpenFileOptions::new()
        .read_until(tags::PIXEL_DATA)
        .open_file(path)
        .map_err(|e| StoreError::format(path, format!("unreadable DICOM file: {e}")))?;
    let transfer_syntax = object.meta().transfer_syntax().trim_end_matches('\0').to_string();
    let rows = int(&object, tags::ROWS);
    let columns = int(&object, tags::COLUMNS);
    let (Some(rows), Some(columns)) = (rows, columns) else { return Ok(None) };
    let in_range = |v: i64| u32::try_from(v).ok().filter(|&v| v > 0);
    let (Some(rows), Some(columns)) = (in_range(rows), in_range(columns)) else {
        return Err(StoreError::format(path, format!("image of {columns}x{rows} samples: both must be positive")));
    };
    let frames = match int(&object, tags::NUMBER_OF_FRAMES) {
        None => 1,
        Some(n) => u32::try_from(n)
            .ok()
            .filter(|&n| n > 0)
            .ok_or_else(|| StoreError::format(path, format!("Number of Frames is {n}: it must be positive")))?,
    };
    let bits_allocated = int(&object, tags::BITS_ALLOCATED).unwrap_or(0);
    let bits_stored = int(&object, tags::BITS_STORED).unwrap_or(bits_allocated);
    let high_bit = int(&object, tags::HIGH_BIT).unwrap_or(bits_stored - 1);
    let small = |v: i64| u16::try_from(v).unwrap_or(u16::MAX);

    // Geometry: the file's own attributes, else the enhanced multi-frame functional groups.
    let orientation = array::<6>(floats(&object, tags::IMAGE_ORIENTATION_PATIENT)).or_else(|| {
        shared(&object, tags::PLANE_ORIENTATION_SEQUENCE)
            .and_then(|o| array(floats(o, tags::IMAGE_ORIENTATION_PATIENT)))
    });
    let measures = shared(&object, tags::PIXEL_MEASURES_SEQUENCE);
    let pixel_spacing = array::<2>(floats(&object, tags::PIXEL_SPACING))
        .or_else(|| measures.and_then(|m| array(floats(m, tags::PIXEL_SPACING))))
        .or_else(|| array(floats(&object, tags::IMAGER_PIXEL_SPACING)));
    let slice_spacing = float(&object, tags::SPACING_BETWEEN_SLICES)
        .or_else(|| measures.and_then(|m| float(m, tags::SPACING_BETWEEN_SLICES)))
        .or_else(|| float(&object, tags::SLICE_THICKNESS))
        .or_else(|| measures.and_then(|m| float(m, tags::SLICE_THICKNESS)))
        .filter(|s| *s > 0.0);
    let per_frame = items(&object, tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE);
    let own_position = array::<3>(floats(&object, tags::IMAGE_POSITION_PATIENT));
    let mut positions: Vec<[f64; 3]> = per_frame
        .iter()
        .filter_map(|f| items(f, tags::PLANE_POSITION_SEQUENCE).first())
        .filter_map(|p| array(floats(p, tags::IMAGE_POSITION_PATIENT)))
        .collect();
    if positions.len() != frames as usize {
        positions.clear();
        let offsets = floats(&object, tags::GRID_FRAME_OFFSET_VECTOR).unwrap_or_default();
        match (own_position, orientation) {
            (Some(p), Some(o)) if frames > 1 && offsets.len() == frames as usize => {
                let n = normal(&o);
                positions = offsets.iter().map(|d| [0, 1, 2].map(|a| p[a] + d * n[a])).collect();
            }
            (Some(p), _) if frames == 1 => positions.push(p),
            _ => {}
        }
    }

    // Rescale: per frame, shared, or the file's own; an RT dose grid's scaling is its slope.
    let mut rescale: Vec<(f64, f64)> = per_frame
        .iter()
        .filter_map(|f| items(f, tags::PIXEL_VALUE_TRANSFORMATION_SEQUENCE).first())
        .filter_map(rescale_in)
        .collect();
    if rescale.len() != frames as usize {
        rescale = shared(&object, tags::PIXEL_VALUE_TRANSFORMATION_SEQUENCE)
            .and_then(rescale_in)
            .or_else(|| rescale_in(&object))
            .or_else(|| float(&object, tags::DOSE_GRID_SCALING).map(|s| (s, 0.0)))
            .into_iter()
            .collect();
    }
    if let Some((slope, intercept)) = rescale.iter().find(|(s, i)| !(s.is_finite() && *s != 0.0 && i.is_finite())) {
        return Err(StoreError::format(
            path,
            format!("rescale slope {slope} and intercept {intercept}: the slope must be finite and not 0"),
        ));
    }

    Ok(Some(DicomHeader {
        path: path.to_path_buf(),
        series: text(&object, tags::SERIES_INSTANCE_UID),
        description: text(&object, tags::SERIES_DESCRIPTION),
        modality: text(&object, tags::MODALITY),
        transfer_syntax,
        rows,
        columns,
        frames,
        bits_allocated: small(bits_allocated),
        bits_stored: small(bits_stored),
        high_bit: small(high_bit),
        signed: int(&object, tags::PIXEL_REPRESENTATION) == Some(1),
        samples_per_pixel: small(int(&object, tags::SAMPLES_PER_PIXEL).unwrap_or(1)),
        photometric: text(&object, tags::PHOTOMETRIC_INTERPRETATION),
        orientation,
        positions,
        pixel_spacing,
        slice_spacing,
        instance: int(&object, tags::INSTANCE_NUMBER),
        rescale,
    }))
}

/// The slice normal of an orientation: the row direction × the column direction.
pub fn normal(o: &[f64; 6]) -> [f64; 3] {
    let (r, c) = ([o[0], o[1], o[2]], [o[3], o[4], o[5]]);
    [r[1] * c[2] - r[2] * c[1], r[2] * c[0] - r[0] * c[2], r[0] * c[1] - r[1] * c[0]]
}
