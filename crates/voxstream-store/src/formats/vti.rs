//! VTK XML ImageData (`.vti`): the first point-data array, inline (`binary`, `ascii`) or appended (`raw`, `base64`),
//! zlib-compressed or not, with UInt32 or UInt64 block headers (https://docs.vtk.org/en/latest/design_documents/VTKFileFormats.html).
//!
//! The file is decoded whole in memory (XML has no random access); the samples then stream like any other input. So
//! that a small file cannot claim a huge volume (a zlib bomb), a `.vti` is read only up to [`MAX_VTI_FILE_BYTES`]
//! and decodes to at most [`MAX_VTI_SAMPLE_BYTES`] of samples; every size in its binary block headers is checked
//! against the extent before anything is inflated, and every block must inflate to exactly the size its header gives
//! (zlib's adler32 checked).
//! A `Direction` other than the identity is not applied (the volume stays axis-aligned, as in `vtkImageData`).

use std::io::Read;
use std::path::Path;

use base64::Engine;
use quick_xml::events::Event;

use super::sample_stream::{Endian, SampleStream, DEFLATE_MAX_RATIO};
use crate::error::StoreError;
use crate::volume::{DType, VolumeInfo};

/// The most bytes of samples a `.vti` may decode to: the array is held in memory whole, beside the file itself.
/// Convert larger volumes to a streamed format (NRRD, MetaImage, NIfTI), which import in bounded memory.
pub const MAX_VTI_SAMPLE_BYTES: u64 = 1 << 30;

/// The largest `.vti` file read (ascii floats take up to ~4 characters per byte of samples).
pub const MAX_VTI_FILE_BYTES: u64 = 4 * MAX_VTI_SAMPLE_BYTES;

#[derive(Default)]
struct Header {
    big_endian: bool,
    header_u64: bool,
    compressed: bool,
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
    let appended_at = find(&bytes, b"<AppendedData");
    let xml_end = appended_at.and_then(|a| find(&bytes[a..], b">").map(|p| a + p + 1)).unwrap_or(bytes.len());
    let mut h = Header { spacing: [1.0; 3], ..Header::default() };
    let mut reader = quick_xml::Reader::from_reader(&bytes[..xml_end]);
    let mut in_array = false;
    let mut have_array = false;
    let mut buffer = Vec::new();
    loop {
        let event = reader.read_event_into(&mut buffer).map_err(|e| bad(format!("malformed XML: {e}")))?;
        match event {
            Event::Start(ref e) | Event::Empty(ref e) => {
                let attr = |name: &str| -> Option<String> {
                    e.attributes()
                        .flatten()
                        .find(|a| a.key.as_ref() == name.as_bytes())
                        .map(|a| String::from_utf8_lossy(&a.value).into_owned())
                };
                match e.name().as_ref() {
                    b"VTKFile" => {
                        if attr("type").as_deref() != Some("ImageData") {
                            return Err(StoreError::Unsupported {
                                path: path.into(),
                                message: "only VTK ImageData files".into(),
                            });
                        }
                        h.big_endian = attr("byte_order").as_deref() == Some("BigEndian");
                        h.header_u64 = attr("header_type").as_deref() == Some("UInt64");
                        match attr("compressor").as_deref() {
                            None | Some("") => {}
                            Some("vtkZLibDataCompressor") => h.compressed = true,
                            Some(other) => {
                                return Err(StoreError::Unsupported {
                                    path: path.into(),
                                    message: format!("compressor {other}"),
                                })
                            }
                        }
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
    let info = VolumeInfo { dims, dtype, spacing: h.spacing, origin };
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
        Some("ascii") => ascii(&h.inline_text, dtype, expected / dtype.size(), h.big_endian).map_err(bad)?,
        Some("binary") => decode_base64_array(h.inline_text.trim().as_bytes(), &h, expected).map_err(bad)?,
        Some("appended") => {
            let start = appended_at.ok_or_else(|| bad("appended array but no AppendedData".into()))?;
            let underscore = find(&bytes[start..], b"_").ok_or_else(|| bad("AppendedData has no '_' marker".into()))?;
            let body = &bytes[start + underscore + 1..];
            if h.appended_encoding.as_deref() == Some("base64") {
                let text: Vec<u8> =
                    body.iter().copied().take_while(|&c| c != b'<').filter(|c| !c.is_ascii_whitespace()).collect();
                decode_base64_array(
                    text.get(h.offset..).ok_or_else(|| bad("offset beyond the data".into()))?,
                    &h,
                    expected,
                )
                .map_err(bad)?
            } else {
                decode_raw_array(
                    body.get(h.offset..).ok_or_else(|| bad("offset beyond the data".into()))?,
                    &h,
                    expected,
                )
                .map_err(bad)?
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
    let endian = if h.big_endian { Endian::Big } else { Endian::Little };
    SampleStream::from_reader(path, Box::new(std::io::Cursor::new(data)), info, endian)
}

fn find(haystack: &[u8], needle: &[u8]) -> Option<usize> {
    haystack.windows(needle.len()).position(|w| w == needle)
}

fn read_uint(bytes: &[u8], at: usize, h: &Header) -> Result<u64, String> {
    let size = if h.header_u64 { 8 } else { 4 };
    let b = at.checked_add(size).and_then(|end| bytes.get(at..end)).ok_or("truncated block header")?;
    let mut v = [0u8; 8];
    if h.big_endian {
        v[8 - size..].copy_from_slice(b);
        Ok(u64::from_be_bytes(v))
    } else {
        v[..size].copy_from_slice(b);
        Ok(u64::from_le_bytes(v))
    }
}

/// An uncompressed array: a byte count, then the bytes; the count must be what the extent needs.
fn uncompressed(all: &[u8], h: &Header, expected: usize) -> Result<Vec<u8>, String> {
    let hsize = if h.header_u64 { 8 } else { 4 };
    let n = read_uint(all, 0, h)?;
    if n != expected as u64 {
        return Err(format!("the array's header says {n} bytes, the extent needs {expected}"));
    }
    all.get(hsize..hsize + expected).map(<[u8]>::to_vec).ok_or_else(|| "truncated data".into())
}

/// Inline or appended base64: the header and the data are two separate base64 runs when compressed.
fn decode_base64_array(text: &[u8], h: &Header, expected: usize) -> Result<Vec<u8>, String> {
    let engine = base64::engine::general_purpose::STANDARD;
    let decode = |t: &[u8]| engine.decode(t).map_err(|e| format!("bad base64: {e}"));
    let hsize: usize = if h.header_u64 { 8 } else { 4 };
    if !h.compressed {
        return uncompressed(&decode(text)?, h, expected);
    }
    let first_chars = 4 * hsize.div_ceil(3);
    let first = decode(text.get(..first_chars).ok_or("truncated header")?)?;
    let blocks = read_uint(&first, 0, h)?;
    let header_chars = block_header_len(blocks, hsize, text.len())?.div_ceil(3) * 4;
    let header = decode(text.get(..header_chars).ok_or("truncated header")?)?;
    let data = decode(text.get(header_chars..).ok_or("truncated data")?)?;
    inflate_blocks(&header, &data, blocks as usize, h, expected)
}

fn decode_raw_array(bytes: &[u8], h: &Header, expected: usize) -> Result<Vec<u8>, String> {
    let hsize = if h.header_u64 { 8 } else { 4 };
    if !h.compressed {
        return uncompressed(bytes, h, expected);
    }
    let blocks = read_uint(bytes, 0, h)?;
    let header_len = block_header_len(blocks, hsize, bytes.len())?;
    inflate_blocks(&bytes[..header_len], &bytes[header_len..], blocks as usize, h, expected)
}

/// Bytes of a `[blocks, block size, last block size, compressed sizes…]` header, which must fit in `available`.
fn block_header_len(blocks: u64, hsize: usize, available: usize) -> Result<usize, String> {
    blocks
        .checked_add(3)
        .and_then(|n| n.checked_mul(hsize as u64))
        .filter(|&n| n <= available as u64)
        .map(|n| n as usize)
        .ok_or_else(|| format!("{blocks} compressed blocks announced, more than the data can hold"))
}

/// zlib blocks after the `[blocks, block size, last block size, compressed sizes…]` header. The sizes must add up to
/// the `expected` bytes before anything is inflated, and each block must inflate to exactly its size.
fn inflate_blocks(header: &[u8], data: &[u8], blocks: usize, h: &Header, expected: usize) -> Result<Vec<u8>, String> {
    let hsize = if h.header_u64 { 8 } else { 4 };
    let block_size = read_uint(header, hsize, h)?;
    let last_size = match read_uint(header, 2 * hsize, h)? {
        0 => block_size,
        n => n,
    };
    let total = match blocks {
        0 => Some(0),
        n => block_size.checked_mul(n as u64 - 1).and_then(|t| t.checked_add(last_size)),
    };
    if last_size > block_size || total != Some(expected as u64) {
        return Err(format!(
            "the compression header ({blocks} blocks of {block_size} bytes, the last {last_size}) does not add up to \
             the {expected} bytes the extent needs"
        ));
    }
    if expected as u64 > (data.len() as u64).saturating_mul(DEFLATE_MAX_RATIO) {
        return Err(format!(
            "{} compressed bytes cannot inflate to the {expected} bytes the extent needs (deflate expands at most \
             {DEFLATE_MAX_RATIO}:1)",
            data.len()
        ));
    }
    let mut out = Vec::with_capacity(expected);
    let mut at = 0usize;
    for block in 0..blocks {
        let size = read_uint(header, (3 + block) * hsize, h)?;
        let chunk = usize::try_from(size)
            .ok()
            .and_then(|size| data.get(at..at.checked_add(size)?))
            .ok_or_else(|| format!("compressed block {block} ({size} bytes) runs past the end of the data"))?;
        let want = if block + 1 == blocks { last_size } else { block_size };
        let before = out.len();
        // One byte more than announced is enough to tell a block that inflates too far.
        flate2::read::ZlibDecoder::new(chunk)
            .take(want + 1)
            .read_to_end(&mut out)
            .map_err(|e| format!("corrupt zlib block {block}: {e}"))?;
        let got = (out.len() - before) as u64;
        if got != want {
            let got = if got > want { format!("more than {want}") } else { got.to_string() };
            return Err(format!("zlib block {block} inflates to {got} bytes, its header says {want}"));
        }
        at += chunk.len();
    }
    Ok(out)
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
