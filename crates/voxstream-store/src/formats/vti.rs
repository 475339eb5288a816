//! VTK XML ImageData (`.vti`): the first point-data array, inline (`binary`, `ascii`) or appended (`raw`, `base64`),
//! zlib-compressed or not, with UInt32 or UInt64 block headers (https://docs.vtk.org/en/latest/design_documents/VTKFileFormats.html).
//!
//! The file is decoded whole in memory (XML has no random access); the samples then stream like any other input.
//! A `Direction` other than the identity is not applied (the volume stays axis-aligned, as in `vtkImageData`).

use std::io::Read;
use std::path::Path;

use base64::Engine;
use quick_xml::events::Event;

use super::sample_stream::{Endian, SampleStream};
use crate::error::StoreError;
use crate::volume::{DType, VolumeInfo};

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
    let bytes = std::fs::read(path).map_err(|e| StoreError::io(path, e))?;
    let bad = |m: String| StoreError::format(path, m);
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
                        h.offset = attr("offset").and_then(|o| o.trim().parse().ok()).unwrap_or(0);
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
    let expected = info.byte_len() as usize;
    let data = match h.format.as_deref() {
        Some("ascii") => ascii(&h.inline_text, dtype, expected / dtype.size(), h.big_endian).map_err(bad)?,
        Some("binary") => decode_base64_array(h.inline_text.trim().as_bytes(), &h).map_err(bad)?,
        Some("appended") => {
            let start = appended_at.ok_or_else(|| bad("appended array but no AppendedData".into()))?;
            let underscore = find(&bytes[start..], b"_").ok_or_else(|| bad("AppendedData has no '_' marker".into()))?;
            let body = &bytes[start + underscore + 1..];
            if h.appended_encoding.as_deref() == Some("base64") {
                let text: Vec<u8> =
                    body.iter().copied().take_while(|&c| c != b'<').filter(|c| !c.is_ascii_whitespace()).collect();
                decode_base64_array(text.get(h.offset..).ok_or_else(|| bad("offset beyond the data".into()))?, &h)
                    .map_err(bad)?
            } else {
                decode_raw_array(body.get(h.offset..).ok_or_else(|| bad("offset beyond the data".into()))?, &h)
                    .map_err(bad)?
            }
        }
        other => return Err(bad(format!("unknown DataArray format {other:?}"))),
    };
    if data.len() < expected {
        return Err(StoreError::Truncated { path: path.into(), expected: expected as u64, found: data.len() as u64 });
    }
    let endian = if h.big_endian { Endian::Big } else { Endian::Little };
    SampleStream::from_reader(path, Box::new(std::io::Cursor::new(data)), info, endian)
}

fn find(haystack: &[u8], needle: &[u8]) -> Option<usize> {
    haystack.windows(needle.len()).position(|w| w == needle)
}

fn read_uint(bytes: &[u8], at: usize, h: &Header) -> Result<usize, String> {
    let size = if h.header_u64 { 8 } else { 4 };
    let b = bytes.get(at..at + size).ok_or("truncated block header")?;
    let mut v = [0u8; 8];
    if h.big_endian {
        v[8 - size..].copy_from_slice(b);
        Ok(u64::from_be_bytes(v) as usize)
    } else {
        v[..size].copy_from_slice(b);
        Ok(u64::from_le_bytes(v) as usize)
    }
}

/// Inline or appended base64: the header and the data are two separate base64 runs when compressed.
fn decode_base64_array(text: &[u8], h: &Header) -> Result<Vec<u8>, String> {
    let engine = base64::engine::general_purpose::STANDARD;
    let decode = |t: &[u8]| engine.decode(t).map_err(|e| format!("bad base64: {e}"));
    let hsize = if h.header_u64 { 8 } else { 4 };
    if !h.compressed {
        let all = decode(text)?;
        let n = read_uint(&all, 0, h)?;
        return all.get(hsize..hsize + n).map(<[u8]>::to_vec).ok_or_else(|| "truncated data".into());
    }
    let first_chars = 4 * hsize.div_ceil(3);
    let first = decode(text.get(..first_chars).ok_or("truncated header")?)?;
    let blocks = read_uint(&first, 0, h)?;
    let header_chars = 4 * ((3 + blocks) * hsize).div_ceil(3);
    let header = decode(text.get(..header_chars).ok_or("truncated header")?)?;
    let data = decode(text.get(header_chars..).ok_or("truncated data")?)?;
    inflate_blocks(&header, &data, blocks, h)
}

fn decode_raw_array(bytes: &[u8], h: &Header) -> Result<Vec<u8>, String> {
    let hsize = if h.header_u64 { 8 } else { 4 };
    if !h.compressed {
        let n = read_uint(bytes, 0, h)?;
        return bytes.get(hsize..hsize + n).map(<[u8]>::to_vec).ok_or_else(|| "truncated data".into());
    }
    let blocks = read_uint(bytes, 0, h)?;
    let header_len = (3 + blocks) * hsize;
    inflate_blocks(bytes.get(..header_len).ok_or("truncated header")?, &bytes[header_len..], blocks, h)
}

/// zlib blocks after the `[blocks, block size, last block size, compressed sizes…]` header.
fn inflate_blocks(header: &[u8], data: &[u8], blocks: usize, h: &Header) -> Result<Vec<u8>, String> {
    let hsize = if h.header_u64 { 8 } else { 4 };
    let mut out = Vec::new();
    let mut at = 0;
    for block in 0..blocks {
        let size = read_uint(header, (3 + block) * hsize, h)?;
        let chunk = data.get(at..at + size).ok_or("truncated compressed block")?;
        flate2::read::ZlibDecoder::new(chunk)
            .read_to_end(&mut out)
            .map_err(|e| format!("corrupt zlib block {block}: {e}"))?;
        at += size;
    }
    Ok(out)
}

fn ascii(text: &str, dtype: DType, count: usize, big_endian: bool) -> Result<Vec<u8>, String> {
    let mut out = Vec::with_capacity(count * dtype.size());
    for token in text.split_whitespace() {
        let v: f64 = token.parse().map_err(|_| format!("'{token}' is not a number"))?;
        let bytes: Vec<u8> = match (dtype, big_endian) {
            (DType::U8, _) => vec![v as u8],
            (DType::U16, false) => (v as u16).to_le_bytes().to_vec(),
            (DType::U16, true) => (v as u16).to_be_bytes().to_vec(),
            (DType::I16, false) => (v as i16).to_le_bytes().to_vec(),
            (DType::I16, true) => (v as i16).to_be_bytes().to_vec(),
            (DType::F32, false) => (v as f32).to_le_bytes().to_vec(),
            (DType::F32, true) => (v as f32).to_be_bytes().to_vec(),
        };
        out.extend(bytes);
    }
    Ok(out)
}
