//! DICOM series (CT, MR, PET, RT dose, as scanners and PACS exports write them): a folder of files, one slice each,
//! under any names and in any order (subfolders included), or one multi-frame file. Read through dicom-rs with its
//! pure-Rust decoders: uncompressed (little or big endian, implicit or explicit VR), deflate, RLE, JPEG baseline,
//! extended and lossless, JPEG 2000. JPEG-LS and JPEG XL need a C library and are refused with the way to
//! decompress them.
//!
//! The slices are ordered by their position along the slice normal (Image Position · the orientation's normal), not
//! by file name or instance number, and the spacing between them is measured from those positions; a series whose
//! slices are unevenly spaced (a missing file), share a position (several echoes or time points), lie in different
//! orientations (a localizer) or shift in-plane from slice to slice (a gantry tilt) is refused with what was found,
//! never stacked into a wrong volume. Values are the modality's (`stored × Rescale Slope + Rescale Intercept`: CT in
//! Hounsfield units), kept as u8, u16 or i16 when every slice's rescale is an integer shift whose range fits one of
//! them, as f32 otherwise. The anatomical orientation is the nearest to the slices' (LPS, [`crate::Orientation`]); as for NIfTI, its rotation is not applied: the volume is axis-aligned in
//! voxstream's world (x along the rows, y down the columns, z along the normal), its origin the first slice's
//! position, in millimetres.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use dicom_object::DefaultDicomObject;
use dicom_pixeldata::PixelDecoder;
use dicom_transfer_syntax_registry::{TransferSyntaxIndex, TransferSyntaxRegistry};
use rayon::prelude::*;

use super::dicom_header::{has_dicom_magic, normal, read_header, DicomHeader};
use super::sample_type::{SampleConversion, SampleType};
use crate::error::StoreError;
use crate::orientation::Orientation;
use crate::space_unit::SpaceUnit;
use crate::volume::{DType, VolumeInfo, VolumeSource};

/// The most files a folder may hold for a series (a whole-body CT has a few thousand).
pub const MAX_DICOM_FILES: usize = 200_000;

/// How deep below the folder given files are looked for (PACS exports nest patient/study/series folders).
const MAX_FOLDER_DEPTH: usize = 6;

/// The most slices a volume may have (the store's limit per axis).
const MAX_SLICES: u64 = 1 << 20;

/// The most a decoded frame may hold: a 32768² f32 slice.
const MAX_FRAME_BYTES: u64 = 4 << 30;

/// The most a compressed frame may expand over its file's size.
const MAX_EXPANSION: u64 = 4096;

/// File names that mark a DICOM file whatever its content's first bytes say.
pub fn has_dicom_extension(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| ["dcm", "dicom", "ima"].contains(&e.to_ascii_lowercase().as_str()))
}

/// One z slice of the volume: its file and frame, and the rescale of its values.
#[derive(Clone, Debug)]
struct Slice {
    path: PathBuf,
    frame: u32,
    /// Frames in its file (a multi-frame file is kept open between its slices).
    frames_in_file: u32,
    rescale: (f64, f64),
}

/// The sample encoding every slice shares.
#[derive(Clone, Copy, Debug)]
struct Encoding {
    bits_allocated: u16,
    bits_stored: u16,
    signed: bool,
    frame_bytes: u64,
}

impl Encoding {
    /// The smallest and largest stored value the bits can hold.
    fn stored_range(&self) -> (f64, f64) {
        let bits = self.bits_stored as i32;
        if self.signed {
            (-(2f64.powi(bits - 1)), 2f64.powi(bits - 1) - 1.0)
        } else {
            (0.0, 2f64.powi(bits) - 1.0)
        }
    }

    /// The stored value of sample `raw` (the allocated bits as read): its stored bits, sign-extended when signed.
    #[inline]
    fn value(&self, raw: u32) -> f64 {
        let unused = 32 - self.bits_stored as u32;
        if self.signed {
            (((raw << unused) as i32) >> unused) as f64
        } else {
            ((raw << unused) >> unused) as f64
        }
    }
}

/// A DICOM series read slice by slice.
pub struct DicomSeries {
    info: VolumeInfo,
    slices: Vec<Slice>,
    encoding: Encoding,
    next: usize,
    conversion: Option<SampleConversion>,
    /// The multi-frame file being read, kept open between its frames.
    open: Option<(PathBuf, Arc<DefaultDicomObject>)>,
    /// What was found, for the import's report.
    summary: String,
}

fn files_in(folder: &Path) -> Result<Vec<PathBuf>, StoreError> {
    let mut files = Vec::new();
    let mut folders = vec![(folder.to_path_buf(), 0usize)];
    while let Some((dir, depth)) = folders.pop() {
        for entry in std::fs::read_dir(&dir).map_err(|e| StoreError::io(&dir, e))?.flatten() {
            let path = entry.path();
            if entry.file_name().to_string_lossy().starts_with('.') {
                continue;
            }
            // Links are followed (a series assembled from links to an archive's files); the depth bounds loops.
            let Ok(kind) = std::fs::metadata(&path) else { continue };
            if kind.is_dir() && depth < MAX_FOLDER_DEPTH {
                folders.push((path, depth + 1));
            } else if kind.is_file() {
                files.push(path);
                if files.len() > MAX_DICOM_FILES {
                    return Err(StoreError::format(
                        folder,
                        format!("more than {MAX_DICOM_FILES} files below this folder: give the folder of one series"),
                    ));
                }
            }
        }
    }
    files.sort();
    Ok(files)
}

/// Reads the headers of `files` (in parallel: a series has hundreds), dropping DICOM files without an image.
fn headers_of(files: &[PathBuf]) -> Result<(Vec<DicomHeader>, usize), StoreError> {
    let read: Vec<Option<DicomHeader>> = files.par_iter().map(|f| read_header(f)).collect::<Result<_, _>>()?;
    let without_image = read.iter().filter(|h| h.is_none()).count();
    Ok((read.into_iter().flatten().collect(), without_image))
}

fn describe_series(series: &BTreeMap<String, Vec<DicomHeader>>) -> String {
    series
        .iter()
        .enumerate()
        .map(|(i, (uid, headers))| {
            let first = &headers[0];
            let folder = first.path.parent().map(|p| p.display().to_string()).unwrap_or_default();
            let frames: u64 = headers.iter().map(|h| h.frames as u64).sum();
            // Said here so that the list shows which series can be one volume.
            let several = headers.iter().any(|h| match (h.orientation, first.orientation) {
                (Some(a), Some(b)) => !same_orientation(&a, &b),
                _ => false,
            });
            format!(
                "{}. {} \"{}\" ({} slice{} of {}x{}{}, in {folder}, UID {uid})",
                i + 1,
                if first.modality.is_empty() { "?" } else { &first.modality },
                first.description,
                frames,
                if frames == 1 { "" } else { "s" },
                first.columns,
                first.rows,
                if several { ", in several orientations: a localizer, not one volume" } else { "" }
            )
        })
        .collect::<Vec<_>>()
        .join("; ")
}

/// An error and its causes, in one line.
fn causes(error: &dyn std::error::Error) -> String {
    let mut text = error.to_string();
    let mut source = error.source();
    while let Some(cause) = source {
        text.push_str(": ");
        text.push_str(&cause.to_string());
        source = cause.source();
    }
    text
}

fn same_orientation(a: &[f64; 6], b: &[f64; 6]) -> bool {
    a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-4)
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

impl DicomSeries {
    /// A folder holding one series (in any number of files and subfolders), or one DICOM file.
    pub fn open(path: &Path) -> Result<DicomSeries, StoreError> {
        Self::open_series(path, None)
    }

    /// [`DicomSeries::open`], choosing among a folder's series by `series`: its number in the list a folder of
    /// several series is refused with (1, 2, …, in UID order), or its Series Instance UID.
    pub fn open_series(path: &Path, choice: Option<&str>) -> Result<DicomSeries, StoreError> {
        let files = if path.is_dir() {
            let all = files_in(path)?;
            let dicom: Vec<PathBuf> =
                all.into_iter().filter(|f| has_dicom_extension(f) || has_dicom_magic(f)).collect();
            if dicom.is_empty() {
                return Err(StoreError::format(
                    path,
                    "folder holds neither .tif/.tiff slices nor DICOM files: give the folder of a TIFF stack or of a \
                     DICOM series",
                ));
            }
            dicom
        } else {
            vec![path.to_path_buf()]
        };
        let (headers, without_image) = headers_of(&files)?;
        if headers.is_empty() {
            return Err(StoreError::format(
                path,
                format!(
                    "no DICOM image among its {} DICOM files ({without_image} hold no pixel data: reports, \
                         structure sets, a DICOMDIR)",
                    files.len()
                ),
            ));
        }
        let mut series: BTreeMap<String, Vec<DicomHeader>> = BTreeMap::new();
        for header in headers {
            series.entry(header.series.clone()).or_default().push(header);
        }
        let chosen = match choice {
            Some(choice) => {
                let by_number = choice.parse::<usize>().ok().filter(|n| (1..=series.len()).contains(n));
                let key = match by_number {
                    Some(n) => series.keys().nth(n - 1).cloned(),
                    None => series.contains_key(choice.trim()).then(|| choice.trim().to_string()),
                };
                let Some(key) = key else {
                    return Err(StoreError::Unsupported {
                        path: path.into(),
                        message: format!(
                            "--series {choice} is neither a number from 1 to {} nor the UID of one of its series: {}",
                            series.len(),
                            describe_series(&series)
                        ),
                    });
                };
                key
            }
            None if series.len() > 1 => {
                return Err(StoreError::Unsupported {
                    path: path.into(),
                    message: format!(
                        "{} series found: {}. Import one at a time: choose it with --series N (its number here) or \
                         --series UID",
                        series.len(),
                        describe_series(&series)
                    ),
                })
            }
            None => series.keys().next().cloned().expect("one series"),
        };
        let headers = series.remove(&chosen).expect("a series found above");
        Self::assemble(path, headers)
    }

    fn assemble(path: &Path, headers: Vec<DicomHeader>) -> Result<DicomSeries, StoreError> {
        let first = headers[0].clone();
        for h in &headers {
            let differs = (h.rows, h.columns, h.bits_allocated, h.bits_stored, h.signed, h.samples_per_pixel)
                != (
                    first.rows,
                    first.columns,
                    first.bits_allocated,
                    first.bits_stored,
                    first.signed,
                    first.samples_per_pixel,
                );
            if differs {
                return Err(StoreError::format(
                    &h.path,
                    format!(
                        "image of {}x{} with {} bits ({} stored{}), but {} is {}x{} with {} bits ({} stored{}): every \
                         slice of a volume must have one size and encoding",
                        h.columns,
                        h.rows,
                        h.bits_allocated,
                        h.bits_stored,
                        if h.signed { ", signed" } else { "" },
                        first.path.display(),
                        first.columns,
                        first.rows,
                        first.bits_allocated,
                        first.bits_stored,
                        if first.signed { ", signed" } else { "" }
                    ),
                ));
            }
            check_decodable(h)?;
        }
        let encoding = Encoding {
            bits_allocated: first.bits_allocated,
            bits_stored: first.bits_stored,
            signed: first.signed,
            frame_bytes: first.frame_bytes(),
        };

        let total: u64 = headers.iter().map(|h| h.frames as u64).sum();
        if total > MAX_SLICES {
            return Err(StoreError::format(
                path,
                format!("{total} slices: more than {MAX_SLICES}, the most a volume has"),
            ));
        }
        // The slices, each with its position where the files say it.
        let mut slices: Vec<(Slice, Option<[f64; 3]>, Option<i64>)> = Vec::new();
        for h in &headers {
            for frame in 0..h.frames {
                let slice = Slice {
                    path: h.path.clone(),
                    frame,
                    frames_in_file: h.frames,
                    rescale: h.rescale_of(frame as usize),
                };
                slices.push((slice, h.positions.get(frame as usize).copied(), h.instance));
            }
        }
        let orientation = first.orientation;
        if let Some(o) = orientation {
            if let Some(other) = headers.iter().find(|h| h.orientation.is_some_and(|x| !same_orientation(&x, &o))) {
                return Err(StoreError::Unsupported {
                    path: path.into(),
                    message: format!(
                        "slices in different orientations ({} has {:?}, {} has {:?}): a localizer or a series of \
                         several stacks; import a series whose slices are parallel",
                        first.path.display(),
                        o,
                        other.path.display(),
                        other.orientation.unwrap_or_default()
                    ),
                });
            }
        }
        let with_position = slices.iter().filter(|s| s.1.is_some()).count();
        let z_spacing = match orientation {
            Some(o) if with_position == slices.len() && slices.len() > 1 => {
                sort_by_position(path, &o, &first, &mut slices)?
            }
            _ if with_position > 0 && with_position < slices.len() => {
                return Err(StoreError::format(
                    path,
                    format!(
                        "{with_position} of {} slices say their Image Position, the others do not: the order of the \
                         slices is unknown",
                        slices.len()
                    ),
                ))
            }
            _ => {
                slices.sort_by(|a, b| (a.2, &a.0.path, a.0.frame).cmp(&(b.2, &b.0.path, b.0.frame)));
                first.slice_spacing.unwrap_or(1.0)
            }
        };
        let origin = slices[0].1.unwrap_or([0.0; 3]);

        let (dtype, integral, conversion) = sample_type(&encoding, slices.iter().map(|s| s.0.rescale));
        let spacing = first.pixel_spacing.map_or([1.0, 1.0, z_spacing], |[row, column]| [column, row, z_spacing]);
        let info = VolumeInfo {
            dims: [first.columns as u64, first.rows as u64, slices.len() as u64],
            dtype,
            spacing,
            origin,
            unit: first.pixel_spacing.map(|_| SpaceUnit::from_name("millimeter").expect("an OME unit")),
            // x along the rows, y down the columns, z along the normal: the slices are sorted that way when every
            // one has a position (otherwise the stack's direction is not known).
            orientation: orientation
                .filter(|_| with_position == slices.len())
                .and_then(|o| Orientation::nearest_lps([[o[0], o[1], o[2]], [o[3], o[4], o[5]], normal(&o)])),
        };
        info.validate(path)?;
        let rescales: Vec<(f64, f64)> = slices.iter().map(|s| s.0.rescale).collect();
        let rescale = match (rescales.first(), rescales.iter().all(|r| Some(r) == rescales.first())) {
            (Some(&(1.0, 0.0)), true) => "values as stored".to_string(),
            (Some(&(slope, intercept)), true) => {
                let scaled =
                    if slope == 1.0 { "stored values".to_string() } else { format!("stored values × {slope}") };
                let sign = if intercept < 0.0 { '-' } else { '+' };
                format!("{scaled} {sign} {} (the modality's rescale)", intercept.abs())
            }
            _ => "values rescaled slice by slice (the modality's rescale)".to_string(),
        };
        let stack = match slices.len() {
            1 => format!("one slice of {}x{}", first.columns, first.rows),
            n => {
                format!("{n} slices of {}x{}, {z_spacing:.4} mm apart, ordered by position", first.columns, first.rows)
            }
        };
        let summary = format!(
            "DICOM {} series{}: {stack}; {rescale}",
            if first.modality.is_empty() { "?" } else { &first.modality },
            if first.description.is_empty() { String::new() } else { format!(" \"{}\"", first.description) },
        );
        let mut series = DicomSeries {
            info,
            slices: slices.into_iter().map(|s| s.0).collect(),
            encoding,
            next: 0,
            conversion,
            open: None,
            summary,
        };
        // The first slice decoded now, so that pixel data the decoders cannot read (a 12-bit JPEG, a 32-bit RLE) is
        // refused before anything is written.
        let mut first_values = Vec::with_capacity(series.info.slice_len());
        series.read_slices(1, &mut first_values)?;
        series.next = 0;
        series.conversion = conversion;
        if integral && dtype == DType::F32 && encoding.bits_stored <= 16 {
            // The bits could hold values no 16-bit type holds (CT stored as unsigned 16 bits, intercept -1024), but
            // the values themselves usually fit one: read once to know, rather than store every CT as f32.
            let (min, max) = series.value_range()?;
            if let Some(dtype) = integer_type(min, max, encoding.bits_allocated) {
                series.info.dtype = dtype;
            }
        }
        Ok(series)
    }

    /// The smallest and largest value of every slice, read from the start (the reading starts over after).
    fn value_range(&mut self) -> Result<(f64, f64), StoreError> {
        let (mut min, mut max) = (f64::INFINITY, f64::NEG_INFINITY);
        let mut values = Vec::new();
        while self.next < self.slices.len() {
            values.clear();
            self.read_slices((self.slices.len() - self.next).min(32), &mut values)?;
            for &v in &values {
                min = min.min(v as f64);
                max = max.max(v as f64);
            }
        }
        self.next = 0;
        self.open = None;
        Ok((min, max))
    }

    /// Decodes slice `slice` of `object` into `out`.
    fn decode(
        object: &DefaultDicomObject,
        slice: &Slice,
        encoding: &Encoding,
        out: &mut Vec<f32>,
        conversion: Option<&mut SampleConversion>,
    ) -> Result<(), StoreError> {
        let path = &slice.path;
        let Some(pixel_data) = object.get(dicom_dictionary_std::tags::PIXEL_DATA) else {
            return Err(StoreError::format(path, "holds no pixel data"));
        };
        let encapsulated = pixel_data.value().primitive().is_none();
        if let Some(samples) = pixel_data.value().primitive() {
            let expected = encoding.frame_bytes * slice.frames_in_file as u64;
            let found = samples.calculate_byte_len() as u64;
            if found < expected {
                return Err(StoreError::Truncated { path: path.clone(), expected, found });
            }
        }
        let hint = if encapsulated {
            ": decompress the series first (e.g. `gdcmconv --raw IN OUT` from Debian's libgdcm-tools) and import that"
        } else {
            ""
        };
        let decoded = object.decode_pixel_data_frame(slice.frame).map_err(|e| {
            StoreError::format(
                path,
                format!("frame {} of the pixel data cannot be decoded ({}){hint}", slice.frame, causes(&e)),
            )
        })?;
        let data = decoded
            .frame_data(0)
            .map_err(|e| StoreError::format(path, format!("frame {} of the pixel data: {e}", slice.frame)))?;
        if data.len() as u64 != encoding.frame_bytes {
            return Err(StoreError::Truncated {
                path: path.clone(),
                expected: encoding.frame_bytes,
                found: data.len() as u64,
            });
        }
        let (slope, intercept) = slice.rescale;
        let push = |raw: u32, out: &mut Vec<f32>| out.push((encoding.value(raw) * slope + intercept) as f32);
        match encoding.bits_allocated {
            8 => data.iter().for_each(|&b| push(b as u32, out)),
            16 => data.chunks_exact(2).for_each(|c| push(u16::from_ne_bytes([c[0], c[1]]) as u32, out)),
            _ => {
                let before = out.len();
                data.chunks_exact(4).for_each(|c| push(u32::from_ne_bytes([c[0], c[1], c[2], c[3]]), out));
                if let Some(conversion) = conversion {
                    for (i, c) in data.chunks_exact(4).enumerate() {
                        let value = encoding.value(u32::from_ne_bytes([c[0], c[1], c[2], c[3]])) * slope + intercept;
                        conversion.count(value, out[before + i]);
                    }
                }
            }
        }
        Ok(())
    }

    fn open_file(path: &Path) -> Result<DefaultDicomObject, StoreError> {
        dicom_object::OpenFileOptions::new()
            .open_file(path)
            .map_err(|e| StoreError::format(path, format!("unreadable DICOM file: {e}")))
    }
}

/// Refuses what cannot be decoded: colour, unusual bit layouts, transfer syntaxes without a pure-Rust decoder, and
/// frames that could not fit in the file.
fn check_decodable(h: &DicomHeader) -> Result<(), StoreError> {
    let path = &h.path;
    let unsupported = |message: String| Err(StoreError::Unsupported { path: path.clone(), message });
    if h.samples_per_pixel != 1 || !h.photometric.starts_with("MONOCHROME") {
        return unsupported(format!(
            "{} images ({} samples per pixel): voxstream imports greyscale (MONOCHROME1/2) volumes",
            h.photometric, h.samples_per_pixel
        ));
    }
    if ![8, 16, 32].contains(&h.bits_allocated)
        || h.bits_stored == 0
        || h.bits_stored > h.bits_allocated
        || h.high_bit + 1 != h.bits_stored
    {
        return unsupported(format!(
            "samples of {} bits allocated, {} stored, high bit {} (read: 8, 16 or 32 bits allocated, the stored bits \
             the low ones)",
            h.bits_allocated, h.bits_stored, h.high_bit
        ));
    }
    let Some(syntax) = TransferSyntaxRegistry.get(&h.transfer_syntax) else {
        return unsupported(format!("transfer syntax {} is not one DICOM defines", h.transfer_syntax));
    };
    if !syntax.can_decode_all() {
        return unsupported(format!(
            "pixel data in {} ({}), which voxstream has no pure-Rust decoder for: decompress the series first (e.g. \
             `gdcmconv --raw IN OUT` from Debian's libgdcm-tools, or dcmtk's `dcmdjpls`) and import that",
            syntax.name(),
            h.transfer_syntax
        ));
    }
    if h.frames as u64 > MAX_SLICES {
        return Err(StoreError::format(path, format!("Number of Frames {} is more than {MAX_SLICES}", h.frames)));
    }
    let file_len = std::fs::metadata(path).map_err(|e| StoreError::io(path, e))?.len();
    let frame_bytes = h.frame_bytes();
    let all = frame_bytes.saturating_mul(h.frames as u64);
    if frame_bytes > MAX_FRAME_BYTES {
        return Err(StoreError::format(
            path,
            format!("frames of {}x{} samples need {frame_bytes} bytes, more than {MAX_FRAME_BYTES}", h.columns, h.rows),
        ));
    }
    if syntax.is_codec_free() && all > file_len {
        return Err(StoreError::Truncated { path: path.clone(), expected: all, found: file_len });
    }
    let limit = file_len.saturating_mul(MAX_EXPANSION);
    if all > limit {
        return Err(StoreError::format(
            path,
            format!(
                "{} frames of {frame_bytes} bytes would expand its {file_len} bytes more than {MAX_EXPANSION} times: \
                 the header is damaged",
                h.frames
            ),
        ));
    }
    Ok(())
}

/// Sorts `slices` along the normal of orientation `o` and returns the spacing between them, refusing stacks that
/// are not one evenly spaced, unsheared pile of distinct slices.
fn sort_by_position(
    path: &Path,
    o: &[f64; 6],
    first: &DicomHeader,
    slices: &mut [(Slice, Option<[f64; 3]>, Option<i64>)],
) -> Result<f64, StoreError> {
    let n = normal(o);
    let depth = |p: [f64; 3]| dot(p, n);
    slices.sort_by(|a, b| depth(a.1.unwrap_or_default()).total_cmp(&depth(b.1.unwrap_or_default())));
    let at = |i: usize| slices[i].1.unwrap_or_default();
    let name = |i: usize| format!("{} (frame {})", slices[i].0.path.display(), slices[i].0.frame);
    let gaps: Vec<f64> = (1..slices.len()).map(|i| depth(at(i)) - depth(at(i - 1))).collect();
    if let Some(i) = gaps.iter().position(|g| *g < 1e-3) {
        return Err(StoreError::Unsupported {
            path: path.into(),
            message: format!(
                "{} and {} lie at the same position: the series holds several images per slice (echoes, time \
                 points, or a file twice); give a folder with one image per position",
                name(i),
                name(i + 1)
            ),
        });
    }
    let mut sorted = gaps.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    if let Some(i) = gaps.iter().position(|g| (g - median).abs() > 0.01 * median + 1e-3) {
        return Err(StoreError::format(
            path,
            format!(
                "slices are unevenly spaced: {median:.4} mm apart, but {:.4} mm between {} and {} ({} slices in all): \
                 is a file missing? voxstream stacks evenly spaced slices only",
                gaps[i],
                name(i),
                name(i + 1),
                slices.len()
            ),
        ));
    }
    // Each slice's first sample must lie on the line through the first's along the normal.
    let pixel = first.pixel_spacing.map_or(1.0, |p| p[0].min(p[1]));
    let (row, column) = ([o[0], o[1], o[2]], [o[3], o[4], o[5]]);
    for i in 1..slices.len() {
        let d = [0, 1, 2].map(|a| at(i)[a] - at(0)[a]);
        let shift = dot(d, row).hypot(dot(d, column));
        if shift > 0.05 * pixel + 1e-3 {
            let tilt = (shift / depth(d).abs()).atan().to_degrees();
            return Err(StoreError::Unsupported {
                path: path.into(),
                message: format!(
                    "slices shift in their plane ({shift:.3} mm at {}): a gantry tilt of {tilt:.1}°, a sheared stack \
                     voxstream does not resample; resample the series (e.g. dcm2niix, which corrects tilts) and import \
                     the NIfTI",
                    name(i)
                ),
            });
        }
    }
    Ok((depth(at(slices.len() - 1)) - depth(at(0))) / gaps.len() as f64)
}

/// The integer type that holds every value in `min..=max`, if one does.
fn integer_type(min: f64, max: f64, bits_allocated: u16) -> Option<DType> {
    match () {
        _ if bits_allocated == 8 && min >= 0.0 && max <= 255.0 => Some(DType::U8),
        _ if min >= 0.0 && max <= 65535.0 => Some(DType::U16),
        _ if min >= -32768.0 && max <= 32767.0 => Some(DType::I16),
        _ => None,
    }
}

/// The store's sample type for these slices by their encoding and rescales; whether every rescale is an integer
/// shift; and the conversion to count when 32-bit values become f32.
fn sample_type(
    encoding: &Encoding,
    rescales: impl Iterator<Item = (f64, f64)>,
) -> (DType, bool, Option<SampleConversion>) {
    let (lo, hi) = encoding.stored_range();
    let (mut min, mut max, mut integral) = (f64::INFINITY, f64::NEG_INFINITY, true);
    for (slope, intercept) in rescales {
        integral &= slope == 1.0 && intercept.fract() == 0.0;
        min = min.min(lo * slope + intercept).min(hi * slope + intercept);
        max = max.max(lo * slope + intercept).max(hi * slope + intercept);
    }
    let dtype = integral.then(|| integer_type(min, max, encoding.bits_allocated)).flatten().unwrap_or(DType::F32);
    let from = match () {
        _ if !integral => SampleType::F64,
        _ if encoding.signed => SampleType::I32,
        _ => SampleType::U32,
    };
    let conversion = (dtype == DType::F32 && encoding.bits_stored > 24).then(|| SampleConversion::new(from));
    (dtype, integral, conversion)
}

impl VolumeSource for DicomSeries {
    fn info(&self) -> &VolumeInfo {
        &self.info
    }

    fn read_slices(&mut self, count: usize, out: &mut Vec<f32>) -> Result<(), StoreError> {
        let end = self.next + count;
        if end > self.slices.len() {
            return Err(StoreError::format(&self.slices[0].path, "more slices asked for than the series holds"));
        }
        let encoding = self.encoding;
        let wanted = &self.slices[self.next..end];
        if wanted.iter().all(|s| s.frames_in_file == 1) && self.conversion.is_none() {
            // Files of one slice each: decoded in parallel (compressed slices are the import's slowest part).
            let decoded: Vec<Vec<f32>> = wanted
                .par_iter()
                .map(|slice| {
                    let mut values = Vec::with_capacity(self.info.slice_len());
                    Self::decode(&Self::open_file(&slice.path)?, slice, &encoding, &mut values, None)?;
                    Ok(values)
                })
                .collect::<Result<_, StoreError>>()?;
            decoded.iter().for_each(|values| out.extend_from_slice(values));
        } else {
            for slice in wanted {
                let object = match &self.open {
                    Some((path, object)) if *path == slice.path => object.clone(),
                    _ => {
                        let object = Arc::new(Self::open_file(&slice.path)?);
                        self.open = Some((slice.path.clone(), object.clone()));
                        object
                    }
                };
                Self::decode(&object, slice, &encoding, out, self.conversion.as_mut())?;
            }
        }
        self.next = end;
        if self.next == self.slices.len() {
            self.open = None;
        }
        Ok(())
    }

    fn conversion(&self) -> Option<SampleConversion> {
        self.conversion
    }

    fn description(&self) -> Option<String> {
        Some(self.summary.clone())
    }
}
