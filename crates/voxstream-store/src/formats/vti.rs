//! VTK XML ImageData (`.vti`): the first point-data array, inline (`binary`, `ascii`) or appended (`raw`, `base64`),
//! zlib-compressed or not, with UInt32 or UInt64 block headers (https://docs.vtk.org/en/latest/design_documents/VTKFileFormats.html).
//!
//! The file is decoded whole in memory (XML has no random access); the samples then stream like any other input. So
//! that a small file cannot claim a huge volume (a zlib bomb), a `.vti` is read only up to [`MAX_VTI_FILE_BYTES`]
//! and decodes to at most [`MAX_VTI_SAMPLE_BYTES`] of samples; every size in its binary block headers is checked
//! against the extent before anything is inflated, and every block must inflate to exactly the size its header gives
//! (zlib's adler32 checked).
//! The array encodings (base64, appended, zlib blocks) are decoded by `voxstream-vtk-xml`, as for the particle
//! reader's `.vtp` and `.vtu`.
//! A `Direction` other than the identity is not applied (the volume stays axis-aligned, as in `vtkImageData`).

use std::path::Path;

use quick_xml::events::Event;
use voxstream_vtk_xml::{appended_base64_text, attribute, decode_base64_array, decode_raw_array, find, xml_end};
use voxstream_vtk_xml::{Bounds, Encoding};

use super::sample_stream::{Endian, SampleStream, DEFLATE_MAX_RATIO};
use crate::error::StoreError;
use crate::volume::{DType, VolumeInfo};

/// The most bytes of samples a `.vti` may decode to: the array is held in memory whole, beside the file itself.
/// Convert larger volumes to a streamed format (NRRD, MetaImage, NIfTI), which import in bounded memory.
pub const MAX_VTI_SAMPLE_BYTES: u64 = 1 << 30;

/// The largest `.vti` file read (ascii floats take up to ~4 characters per byte of samples).
pub const MAX_VTI_FILE_BYTES: u64 = 4 * MAX_VTI_SAMPLE_BYTES;

/// How the arrays' sizes are bounded and named in messages.
const BOUNDS: Bounds = Bounds { needed_by: "the extent", deflate_max_ratio: DEFLATE_MAX_RATIO };

#[derive(Default)]
struct Header {
    encoding: Encoding,
    extent: Option<[i64; 6]>,
    origin: [f64; 3],
    spacing: [f64; 3],
    array_type: Option<String>,
    format: Option<String>,
    offset: usize,
    inline_text: String,
    appended_encoding: Option<String>,
}

/// Opens a `.vti` volume.
pub fn open(path: &Path) -> Result<SampleStream, StoreError> {
    let bad = |m: String| StoreError::format(path, m);
    let file_len = std::fs::metadata(path).map_err(|e| StoreError::io(path, e))?.len();
    if file_len > MAX_VTI_FILE_BYTES {
        return Err(bad(format!(
            "{file_len} bytes: .vti files are read whole, up to {MAX_VTI_FILE_BYTES} bytes; convert larger volumes \
             to NRRD or MetaImage, which stream"
        )));
    }
    let bytes = std::fs::read(path).map_err(|e| StoreError::io(path, e))?;
    // The XML part ends where appended raw data begins.
    let (appended_at, xml_end) = xml_end(&bytes);
    let mut h = Header { spacing: [1.0; 3], ..Header::default() };
    let mut reader = quick_xml::Reader::from_reader(&bytes[..xml_end]);
    let mut in_array = false;
    let mut have_array = false;
    let mut buffer = Vec::new();
    loop {
        let event = reader.read_event_into(&mut buffer).map_err(|e| bad(format!("malformed XML: {e}")))?;
        match event {
            Event::Start(ref e) | Event::Empty(ref e) => {
                let attr = |name: &str| attribute(e, name);
                match e.name().as_ref() {
                    b"VTKFile" => {
                        if attr("type").as_deref() != Some("ImageData") {
                            return Err(StoreError::Unsupported {
                                path: path.into(),
                                message: "only VTK ImageData files".into(),
                            });
                        }
                        h.encoding = Encoding::from_attributes(attr).map_err(|unsupported| {
                            StoreError::Unsupported { path: path.into(), message: unsupported.to_string() }
                        })?;
                    }
                    b"ImageData" => {
                        let numbers = |name: &str, n: usize| -> Result<Option<Vec<f64>>, StoreError> {
                            match attr(name) {
                                None => Ok(None),
                                Some(text) => {
                                    let v: Result<Vec<f64>, _> = text.split_whitespace().map(str::parse).collect();
                                    let v = v.map_err(|_| bad(format!("'{name}' is not a list of numbers")))?;
                                    if v.len() != n {
                                        return Err(bad(format!("'{name}' needs {n} numbers")));
                                    }
                                    Ok(Some(v))
                                }
                            }
                        };
                        let e = numbers("WholeExtent", 6)?.ok_or_else(|| bad("ImageData has no WholeExtent".into()))?;
                        if e.iter().any(|v| v.fract() != 0.0 || v.abs() > (1u64 << 40) as f64) {
                            return Err(bad(format!("WholeExtent {e:?} is not a list of integers")));
                        }
                        h.extent = Some([0, 1, 2, 3, 4, 5].map(|i| e[i] as i64));
                        if let Some(o) = numbers("Origin", 3)? {
                            h.origin = [o[0], o[1], o[2]];
                        }
                        if let Some(s) = numbers("Spacing", 3)? {
                            h.spacing = [s[0], s[1], s[2]];
                        }
                    }
                    b"DataArray" if !have_array => {
                        h.array_type = attr("type");
                        h.format = attr("format");
                        h.offset = match attr("offset") {
                            None => 0,
                            Some(o) => o.trim().parse().map_err(|_| bad(format!("DataArray offset '{o}'")))?,
                        };
                        if attr("NumberOfComponents").is_some_and(|c| c.trim() != "1") {
                            return Err(StoreError::Unsupported {
                                path: path.into(),
                                message: "multi-component arrays".into(),
                            });
                        }
                        have_array = true;
                        in_array = matches!(event, Event::Start(_));
                    }
                    b"AppendedData" => h.appended_encoding = attr("encoding"),
                    _ => {}
                }
            }
            Event::Text(t) if in_array => h.inline_text.push_str(&String::from_utf8_lossy(t.as_ref())),
            Event::End(ref e) if e.name().as_ref() == b"DataArray" => in_array = false,
            Event::Eof => break,
            _ => {}
        }
        buffer.clear();
    }
    let extent = h.extent.ok_or_else(|| bad("no ImageData element".into()))?;
    if !have_array {
        return Err(bad("no DataArray in PointData".into()));
    }
    let dims = [0, 1, 2].map(|a| (extent[2 * a + 1] - extent[2 * a] + 1).max(0) as u64);
    let dtype = match h.array_type.as_deref() {
        Some("UInt8") => DType::U8,
        Some("UInt16") => DType::U16,
        Some("Int16") => DType::I16,
        Some("Float32") => DType::F32,
        other => {
            return Err(StoreError::Unsupported {
                path: path.into(),
                message: format!("array type {} (UInt8, UInt16, Int16, Float32)", other.unwrap_or("missing")),
            })
        }
    };
    let origin = [0, 1, 2].map(|a| h.origin[a] + h.spacing[a] * extent[2 * a] as f64);
    let info = VolumeInfo { dims, dtype, spacing: h.spacing, origin, unit: None, orientation: None };
    info.validate(path)?;
    if info.byte_len() > MAX_VTI_SAMPLE_BYTES {
        return Err(bad(format!(
            "the extent {dims:?} needs {} bytes of samples; a .vti is decoded whole in memory, up to \
             {MAX_VTI_SAMPLE_BYTES} bytes: convert larger volumes to NRRD or MetaImage, which stream",
            info.byte_len()
        )));
    }
    let expected = info.byte_len() as usize;
    let data = match h.format.as_deref() {
        Some("ascii") => ascii(&h.inline_text, dtype, expected / dtype.size(), h.encoding.big_endian).map_err(bad)?,
        Some("binary") => decode_base64_array(h.inline_text.trim().as_bytes(), h.encoding, expected, &BOUNDS)
            .map_err(|e| bad(e.to_string()))?,
        Some("appended") => {
            let start = appended_at.ok_or_else(|| bad("appended array but no AppendedData".into()))?;
            let underscore = find(&bytes[start..], b"_").ok_or_else(|| bad("AppendedData has no '_' marker".into()))?;
            let body = &bytes[start + underscore + 1..];
            if h.appended_encoding.as_deref() == Some("base64") {
                let text = appended_base64_text(body);
                decode_base64_array(
                    text.get(h.offset..).ok_or_else(|| bad("offset beyond the data".into()))?,
                    h.encoding,
                    expected,
                    &BOUNDS,
                )
                .map_err(|e| bad(e.to_string()))?
            } else {
                decode_raw_array(
                    body.get(h.offset..).ok_or_else(|| bad("offset beyond the data".into()))?,
                    h.encoding,
                    expected,
                    &BOUNDS,
                )
                .map_err(|e| bad(e.to_string()))?
            }
        }
        other => return Err(bad(format!("unknown DataArray format {other:?}"))),
    };
    if data.len() < expected {
        return Err(StoreError::Truncated { path: path.into(), expected: expected as u64, found: data.len() as u64 });
    }
    if data.len() > expected {
        return Err(bad(format!(
            "the array holds {} bytes but the extent {dims:?} needs {expected}: the extent or the type is wrong",
            data.len()
        )));
    }
    let endian = if h.encoding.big_endian { Endian::Big } else { Endian::Little };
    SampleStream::from_reader(path, Box::new(std::io::Cursor::new(data)), info, dtype.into(), endian)
}

/// Ascii samples: exactly `count` of them, each a value of `dtype` (integers in range; any float for Float32, whose
/// NaN and infinities are then refused or replaced with the others').
fn ascii(text: &str, dtype: DType, count: usize, big_endian: bool) -> Result<Vec<u8>, String> {
    // Each value takes at least two characters (a digit and a separator), so the text bounds what to reserve.
    let mut out = Vec::with_capacity(count.min(text.len() / 2 + 1) * dtype.size());
    for (n, token) in text.split_whitespace().enumerate() {
        if n == count {
            return Err(format!("more than the {count} values the extent needs"));
        }
        let integer = |lo: f64, hi: f64| -> Result<f64, String> {
            let v: f64 = token.parse().map_err(|_| format!("'{token}' is not a number"))?;
            if v.fract() != 0.0 || !(lo..=hi).contains(&v) {
                return Err(format!("'{token}' is not a {} value", dtype.name()));
            }
            Ok(v)
        };
        match (dtype, big_endian) {
            (DType::U8, _) => out.push(integer(0.0, 255.0)? as u8),
            (DType::U16, false) => out.extend((integer(0.0, 65535.0)? as u16).to_le_bytes()),
            (DType::U16, true) => out.extend((integer(0.0, 65535.0)? as u16).to_be_bytes()),
            (DType::I16, false) => out.extend((integer(-32768.0, 32767.0)? as i16).to_le_bytes()),
            (DType::I16, true) => out.extend((integer(-32768.0, 32767.0)? as i16).to_be_bytes()),
            (DType::F32, big) => {
                let v: f32 = token.parse().map_err(|_| format!("'{token}' is not a number"))?;
                out.extend(if big { v.to_be_bytes() } else { v.to_le_bytes() });
            }
        }
    }
    Ok(out)
}
