//! VTK XML PolyData (`.vtp`) and UnstructuredGrid (`.vtu`,
//! <https://docs.vtk.org/en/latest/design_documents/VTKFileFormats.html>): the points of every `Piece` as particles,
//! with arrays of their `PointData`. SPH codes write their particles as either (PySPH's `pysph dump_vtk` writes
//! `.vtu`, one vertex cell per particle; the cells are not needed and not read).
//!
//! Arrays are read inline (`ascii`, `binary`: base64) or appended (`raw` or `base64`), uncompressed or
//! zlib-compressed (`vtkZLibDataCompressor`), little- or big-endian, with UInt32 or UInt64 block headers, of any
//! integer or floating-point type; the decoding follows the store's `.vti` reader. The `Points` array must have 3
//! components. Of the point data, one-component arrays are taken by name ([`super::xyz`]'s rules): the first named
//! like a smoothing length (`h`, `hsml`, `radius`, `smoothing_length`) becomes `smoothing`, the first named `mass` or
//! `m` the masses, and the first other one the scalar attribute. Pieces are concatenated; an array taken in one
//! piece must be there, under the same name, in every piece with points.
//!
//! Every array's size follows from `NumberOfPoints` and is checked before anything is decoded: at most
//! [`MAX_ARRAY_BYTES`], within what the inline text or the file holds, and for compressed arrays the block header
//! must add up to it, the compressed bytes must be able to inflate to it, and each block must inflate to exactly
//! its announced size (zlib's adler32 checked). Appended arrays name their data by offset, so several could name the
//! same bytes: all binary and appended arrays together may decode to no more than the file could hold (its length
//! uncompressed, 1032 times it compressed), which bounds what the reader allocates whatever the pieces announce.
//!
//! Not read: cells (`Verts`, `Lines`, `Strips`, `Polys`; an unstructured grid's `Cells`), cell and field data, other
//! dataset types (`.vti` and the rest), other compressors (LZ4, LZMA), `String` and `Bit` arrays. The `VTKFile`
//! type must match the file name's ending.

use std::cell::Cell;
use std::io::Read;
use std::path::Path;

use base64::Engine;
use quick_xml::events::Event;

use super::xyz::{column_role, ColumnRole};
use crate::error::GeometryError;
use crate::particles::RawParticles;

/// The most bytes one array may decode to: arrays are held in memory whole.
pub const MAX_ARRAY_BYTES: u64 = 1 << 32;

/// The most deflate can expand: a compressed array announcing more than this many times its compressed bytes is
/// refused before it is inflated (the store's `DEFLATE_MAX_RATIO`).
const DEFLATE_MAX_RATIO: u64 = 1032;

/// A numeric array type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Ty {
    U8,
    I8,
    U16,
    I16,
    U32,
    I32,
    U64,
    I64,
    F32,
    F64,
}

impl Ty {
    fn parse(name: &str) -> Option<Ty> {
        Some(match name {
            "UInt8" => Ty::U8,
            "Int8" => Ty::I8,
            "UInt16" => Ty::U16,
            "Int16" => Ty::I16,
            "UInt32" => Ty::U32,
            "Int32" => Ty::I32,
            "UInt64" => Ty::U64,
            "Int64" => Ty::I64,
            "Float32" => Ty::F32,
            "Float64" => Ty::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Ty::U8 | Ty::I8 => 1,
            Ty::U16 | Ty::I16 => 2,
            Ty::U32 | Ty::I32 | Ty::F32 => 4,
            Ty::U64 | Ty::I64 | Ty::F64 => 8,
        }
    }

    /// Decodes one value from `b` ([`Ty::size`] bytes).
    fn decode(self, b: &[u8], big_endian: bool) -> f64 {
        let n = self.size().min(b.len());
        let mut a = [0u8; 8];
        // Read into the low bytes of a little-endian u64 whatever the file's order.
        for (i, &byte) in b.iter().take(n).enumerate() {
            let to = if big_endian { n - 1 - i } else { i };
            if let Some(slot) = a.get_mut(to) {
                *slot = byte;
            }
        }
        let bits = u64::from_le_bytes(a);
        match self {
            Ty::U8 => f64::from(bits as u8),
            Ty::I8 => f64::from(bits as u8 as i8),
            Ty::U16 => f64::from(bits as u16),
            Ty::I16 => f64::from(bits as u16 as i16),
            Ty::U32 => f64::from(bits as u32),
            Ty::I32 => f64::from(bits as u32 as i32),
            Ty::F32 => f64::from(f32::from_bits(bits as u32)),
            Ty::U64 => bits as f64,
            Ty::I64 => bits as i64 as f64,
            Ty::F64 => f64::from_bits(bits),
        }
    }
}

/// The `VTKFile` attributes that decoding needs.
#[derive(Clone, Copy, Default)]
struct Header {
    big_endian: bool,
    header_u64: bool,
    compressed: bool,
}

impl Header {
    fn hsize(self) -> usize {
        if self.header_u64 {
            8
        } else {
            4
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Format {
    Ascii,
    Binary,
    Appended,
}

/// A `DataArray` to decode.
struct Array {
    name: String,
    ty: Ty,
    components: usize,
    format: Format,
    offset: usize,
    text: Vec<u8>,
    /// Where its tag is in the file (for the line in errors).
    at: usize,
}

/// The arrays of one `Piece`.
#[derive(Default)]
struct Piece {
    points: usize,
    positions: Option<Array>,
    smoothing: Option<Array>,
    mass: Option<Array>,
    value: Option<Array>,
}

/// Which array text is being collected.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Slot {
    Positions,
    Role(ColumnRole),
}

fn line_at(bytes: &[u8], at: usize) -> u64 {
    bytes.get(..at).unwrap_or(bytes).iter().filter(|&&b| b == b'\n').count() as u64 + 1
}

fn find(haystack: &[u8], needle: &[u8]) -> Option<usize> {
    haystack.windows(needle.len()).position(|w| w == needle)
}

/// The dataset types read, by file-name ending.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dataset {
    /// `.vtp`.
    PolyData,
    /// `.vtu`.
    UnstructuredGrid,
}

impl Dataset {
    /// The `VTKFile` element's `type`.
    fn type_name(self) -> &'static str {
        match self {
            Dataset::PolyData => "PolyData",
            Dataset::UnstructuredGrid => "UnstructuredGrid",
        }
    }

    /// The file-name ending.
    fn ending(self) -> &'static str {
        match self {
            Dataset::PolyData => ".vtp",
            Dataset::UnstructuredGrid => ".vtu",
        }
    }
}

/// Parses a `.vtp` file.
pub fn parse(bytes: &[u8], path: &Path) -> Result<RawParticles, GeometryError> {
    parse_dataset(bytes, path, Dataset::PolyData)
}

/// Parses a `.vtp` or `.vtu` file: `dataset` is what its name announces.
pub fn parse_dataset(bytes: &[u8], path: &Path, dataset: Dataset) -> Result<RawParticles, GeometryError> {
    let bad = |at: usize, message: String| GeometryError::format(path, Some(line_at(bytes, at)), message);
    let unsupported = |message: String| GeometryError::Unsupported { path: path.into(), message };
    // The XML part ends where appended raw data begins.
    let appended_at = find(bytes, b"<AppendedData");
    let xml_end = appended_at.and_then(|a| find(bytes.get(a..)?, b">").map(|p| a + p + 1)).unwrap_or(bytes.len());
    let mut reader = quick_xml::Reader::from_reader(bytes.get(..xml_end).unwrap_or(bytes));
    let mut header = Header::default();
    let mut seen_file = false;
    let mut pieces: Vec<Piece> = Vec::new();
    let (mut in_points, mut in_point_data) = (false, false);
    let mut collecting: Option<Slot> = None;
    let mut appended_encoding: Option<String> = None;
    let mut buffer = Vec::new();
    loop {
        let at = usize::try_from(reader.buffer_position()).unwrap_or(usize::MAX);
        let event = reader.read_event_into(&mut buffer).map_err(|e| bad(at, format!("malformed XML: {e}")))?;
        match event {
            Event::Start(ref e) | Event::Empty(ref e) => {
                let attr = |name: &str| -> Option<String> {
                    e.attributes()
                        .flatten()
                        .find(|a| a.key.as_ref() == name.as_bytes())
                        .map(|a| String::from_utf8_lossy(&a.value).into_owned())
                };
                let start = matches!(event, Event::Start(_));
                match e.name().as_ref() {
                    b"VTKFile" => {
                        seen_file = true;
                        let kind = attr("type").unwrap_or_default();
                        if kind != dataset.type_name() {
                            let other = [Dataset::PolyData, Dataset::UnstructuredGrid]
                                .into_iter()
                                .find(|d| d.type_name() == kind)
                                .map(|d| format!(" (name the file {} to read it)", d.ending()))
                                .unwrap_or_default();
                            return Err(unsupported(format!(
                                "VTKFile type '{kind}': only {} is read from {}{other}",
                                dataset.type_name(),
                                dataset.ending()
                            )));
                        }
                        header.big_endian = attr("byte_order").as_deref() == Some("BigEndian");
                        header.header_u64 = attr("header_type").as_deref() == Some("UInt64");
                        match attr("compressor").as_deref() {
                            None | Some("") => {}
                            Some("vtkZLibDataCompressor") => header.compressed = true,
                            Some(other) => return Err(unsupported(format!("compressor {other}"))),
                        }
                    }
                    b"Piece" => {
                        let text =
                            attr("NumberOfPoints").ok_or_else(|| bad(at, "Piece has no NumberOfPoints".into()))?;
                        let points = text
                            .trim()
                            .parse()
                            .map_err(|_| bad(at, format!("NumberOfPoints '{text}' is not a count")))?;
                        pieces.push(Piece { points, ..Piece::default() });
                    }
                    b"Points" => in_points = start,
                    b"PointData" => in_point_data = start,
                    b"DataArray" if in_points || in_point_data => {
                        let Some(piece) = pieces.last_mut() else {
                            return Err(bad(at, "a DataArray outside a Piece".into()));
                        };
                        let name = attr("Name").unwrap_or_default();
                        let components: usize = match attr("NumberOfComponents") {
                            None => 1,
                            Some(c) => c
                                .trim()
                                .parse()
                                .ok()
                                .filter(|&c| c >= 1)
                                .ok_or_else(|| bad(at, format!("DataArray '{name}': NumberOfComponents '{c}'")))?,
                        };
                        let type_name = attr("type").unwrap_or_default();
                        let ty = Ty::parse(&type_name);
                        let slot = if in_points {
                            if piece.positions.is_some() {
                                return Err(bad(at, "a second DataArray in Points".into()));
                            }
                            if ty.is_none() {
                                return Err(bad(at, format!("Points of type '{type_name}'")));
                            }
                            if components != 3 {
                                return Err(bad(at, format!("Points with {components} components (3 expected)")));
                            }
                            Some(Slot::Positions)
                        } else if ty.is_none() || components != 1 {
                            None
                        } else {
                            let role = column_role(&name);
                            let taken = match role {
                                ColumnRole::Smoothing => piece.smoothing.is_some(),
                                ColumnRole::Mass => piece.mass.is_some(),
                                ColumnRole::Value => piece.value.is_some(),
                            };
                            (!taken).then_some(Slot::Role(role))
                        };
                        if let (Some(slot), Some(ty)) = (slot, ty) {
                            let format = match attr("format").as_deref() {
                                Some("ascii") => Format::Ascii,
                                Some("binary") => Format::Binary,
                                Some("appended") => Format::Appended,
                                other => {
                                    return Err(bad(
                                        at,
                                        format!("DataArray '{name}': unknown format {:?}", other.unwrap_or("")),
                                    ))
                                }
                            };
                            let offset = match attr("offset") {
                                None => 0,
                                Some(o) => o
                                    .trim()
                                    .parse()
                                    .map_err(|_| bad(at, format!("DataArray '{name}': offset '{o}'")))?,
                            };
                            let name = match (slot, name.is_empty()) {
                                (Slot::Positions, true) => "Points".to_string(),
                                _ => name,
                            };
                            let array = Array { name, ty, components, format, offset, text: Vec::new(), at };
                            *match slot {
                                Slot::Positions => &mut piece.positions,
                                Slot::Role(ColumnRole::Smoothing) => &mut piece.smoothing,
                                Slot::Role(ColumnRole::Mass) => &mut piece.mass,
                                Slot::Role(ColumnRole::Value) => &mut piece.value,
                            } = Some(array);
                            collecting = start.then_some(slot);
                        }
                    }
                    b"AppendedData" => appended_encoding = attr("encoding"),
                    _ => {}
                }
            }
            Event::Text(ref t) if collecting.is_some() => collect(&mut pieces, collecting, t.as_ref()),
            Event::CData(ref t) if collecting.is_some() => collect(&mut pieces, collecting, t.as_ref()),
            Event::End(ref e) => match e.name().as_ref() {
                b"DataArray" => collecting = None,
                b"Points" => in_points = false,
                b"PointData" => in_point_data = false,
                _ => {}
            },
            Event::Eof => break,
            _ => {}
        }
        buffer.clear();
    }
    if !seen_file {
        return Err(GeometryError::format(path, None, "not a VTK XML file: no VTKFile element"));
    }
    // The appended data: after the `_` that follows the AppendedData tag.
    let appended = match appended_at {
        None => None,
        Some(_) => {
            let body = bytes.get(xml_end..).unwrap_or(&[]);
            let underscore = find(body, b"_").ok_or_else(|| bad(xml_end, "AppendedData has no '_' marker".into()))?;
            Some(body.get(underscore + 1..).unwrap_or(&[]))
        }
    };
    let appended_base64: Option<Vec<u8>> = match (appended, appended_encoding.as_deref()) {
        (Some(body), Some("base64")) => {
            Some(body.iter().copied().take_while(|&c| c != b'<').filter(|c| !c.is_ascii_whitespace()).collect())
        }
        _ => None,
    };
    let decoder =
        Decoder { bytes, path, header, appended, appended_base64: appended_base64.as_deref(), decoded: Cell::new(0) };
    assemble(pieces, &decoder, path)
}

/// Adds text to the array being collected.
fn collect(pieces: &mut [Piece], slot: Option<Slot>, text: &[u8]) {
    let Some(piece) = pieces.last_mut() else { return };
    let array = match slot {
        Some(Slot::Positions) => &mut piece.positions,
        Some(Slot::Role(ColumnRole::Smoothing)) => &mut piece.smoothing,
        Some(Slot::Role(ColumnRole::Mass)) => &mut piece.mass,
        Some(Slot::Role(ColumnRole::Value)) => &mut piece.value,
        None => return,
    };
    if let Some(array) = array {
        array.text.extend_from_slice(text);
    }
}

/// Decodes arrays.
struct Decoder<'a> {
    bytes: &'a [u8],
    path: &'a Path,
    header: Header,
    appended: Option<&'a [u8]>,
    appended_base64: Option<&'a [u8]>,
    /// Bytes the binary and appended arrays decoded so far.
    decoded: Cell<u64>,
}

impl Decoder<'_> {
    /// The `tuples` × components values of `array`.
    fn values(&self, array: &Array, tuples: usize) -> Result<Vec<f64>, GeometryError> {
        let bad = |message: String| {
            GeometryError::format(
                self.path,
                Some(line_at(self.bytes, array.at)),
                format!("DataArray '{}': {message}", array.name),
            )
        };
        let count = tuples
            .checked_mul(array.components)
            .ok_or_else(|| bad(format!("{tuples} × {} values, too many", array.components)))?;
        let expected =
            count.checked_mul(array.ty.size()).filter(|&n| n as u64 <= MAX_ARRAY_BYTES).ok_or_else(|| {
                bad(format!("{tuples} × {} values: more than {MAX_ARRAY_BYTES} bytes in one array", array.components))
            })?;
        let data = match array.format {
            Format::Ascii => return ascii(&array.text, count).map_err(bad),
            Format::Binary => {
                let text: Vec<u8> = array.text.iter().copied().filter(|c| !c.is_ascii_whitespace()).collect();
                decode_base64_array(&text, self.header, expected).map_err(bad)?
            }
            Format::Appended => {
                let Some(body) = self.appended else { return Err(bad("appended, but no AppendedData".into())) };
                let beyond = || bad(format!("offset {} beyond the appended data", array.offset));
                match self.appended_base64 {
                    Some(text) => {
                        decode_base64_array(text.get(array.offset..).ok_or_else(beyond)?, self.header, expected)
                    }
                    None => decode_raw_array(body.get(array.offset..).ok_or_else(beyond)?, self.header, expected),
                }
                .map_err(bad)?
            }
        };
        // Each array's data is bytes of its own (inline text, or a stretch of the appended data), so together they
        // decode to at most the file's length, or what that inflates to; checked once the array's own checks have
        // passed, before its values are kept.
        let file = self.bytes.len() as u64;
        let (limit, holds) = if self.header.compressed {
            (
                file.saturating_mul(DEFLATE_MAX_RATIO),
                format!("inflate to (deflate expands at most {DEFLATE_MAX_RATIO}:1)"),
            )
        } else {
            (file, "hold".to_string())
        };
        let total = self.decoded.get().saturating_add(data.len() as u64);
        if total > limit {
            return Err(bad(format!(
                "with the arrays before it, {total} bytes of data, more than the file's {file} bytes can {holds}: \
                 arrays cannot share their data"
            )));
        }
        self.decoded.set(total);
        let size = array.ty.size();
        Ok(data.chunks_exact(size).map(|b| array.ty.decode(b, self.header.big_endian)).collect())
    }
}

/// The particles of all pieces.
fn assemble(pieces: Vec<Piece>, decoder: &Decoder, path: &Path) -> Result<RawParticles, GeometryError> {
    let mut raw = RawParticles::default();
    let pieces: Vec<(usize, Piece)> = pieces.into_iter().enumerate().filter(|(_, p)| p.points > 0).collect();
    if pieces.is_empty() {
        return Ok(raw);
    }
    for (index, piece) in &pieces {
        let Some(array) = &piece.positions else {
            return Err(GeometryError::format(
                path,
                None,
                format!("piece {} has {} points but no Points array", index + 1, piece.points),
            ));
        };
        let values = decoder.values(array, piece.points)?;
        raw.positions.extend(values.chunks_exact(3).map(|p| [p[0], p[1], p[2]]));
    }
    type Pick = fn(&Piece) -> &Option<Array>;
    let roles: [(&str, Pick); 3] =
        [("smoothing length", |p| &p.smoothing), ("mass", |p| &p.mass), ("scalar", |p| &p.value)];
    for (what, pick) in roles {
        let (first_index, first) = match pieces.iter().find_map(|(i, p)| pick(p).as_ref().map(|a| (i, a))) {
            Some(found) => found,
            None => continue,
        };
        let mut column = Vec::new();
        for (index, piece) in &pieces {
            let array = pick(piece).as_ref().filter(|a| what != "scalar" || a.name == first.name).ok_or_else(|| {
                GeometryError::format(
                    path,
                    None,
                    format!(
                        "piece {} has no {what} array '{}' that piece {} has: every piece needs the same arrays",
                        index + 1,
                        first.name,
                        first_index + 1
                    ),
                )
            })?;
            column.extend(decoder.values(array, piece.points)?.into_iter().map(|v| v as f32));
        }
        match what {
            "smoothing length" => raw.smoothing = column,
            "mass" => raw.masses = column,
            _ => {
                raw.values = column;
                raw.value_name.clone_from(&first.name);
            }
        }
    }
    Ok(raw)
}

/// ASCII values: exactly `count` numbers.
fn ascii(text: &[u8], count: usize) -> Result<Vec<f64>, String> {
    let text = std::str::from_utf8(text).map_err(|_| "ascii data is not text".to_string())?;
    // Each value takes at least a character and a separator.
    let mut values = Vec::with_capacity(count.min(text.len() / 2 + 1));
    for token in text.split_whitespace() {
        if values.len() == count {
            return Err(format!("more than the {count} values the point count needs"));
        }
        values.push(token.parse::<f64>().map_err(|_| format!("'{token}' is not a number"))?);
    }
    if values.len() < count {
        return Err(format!("{} values, the point count needs {count}", values.len()));
    }
    Ok(values)
}

fn read_uint(bytes: &[u8], at: usize, h: Header) -> Result<u64, String> {
    let size = h.hsize();
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

/// An uncompressed array: a byte count, then the bytes; the count must be what the point count needs.
fn uncompressed(all: &[u8], h: Header, expected: usize) -> Result<Vec<u8>, String> {
    let n = read_uint(all, 0, h)?;
    if n != expected as u64 {
        return Err(format!("the array's header says {n} bytes, the point count needs {expected}"));
    }
    h.hsize().checked_add(expected).and_then(|end| all.get(h.hsize()..end)).map(<[u8]>::to_vec).ok_or_else(|| {
        format!("truncated data: {} bytes of the {expected} announced", all.len().saturating_sub(h.hsize()))
    })
}

fn base64_decode(text: &[u8]) -> Result<Vec<u8>, String> {
    base64::engine::general_purpose::STANDARD.decode(text).map_err(|e| format!("bad base64: {e}"))
}

/// Characters of base64 that encode `bytes` bytes (padded).
fn base64_len(bytes: usize) -> Option<usize> {
    bytes.div_ceil(3).checked_mul(4)
}

/// Inline or appended base64, of exactly one array (what follows it in appended data is not decoded). Uncompressed,
/// the header and the data are one base64 run (as VTK writes them) or two (as some writers do: the header's run is
/// then padded); compressed, the block header and the blocks are two runs.
fn decode_base64_array(text: &[u8], h: Header, expected: usize) -> Result<Vec<u8>, String> {
    let hsize = h.hsize();
    let first_chars = 4 * hsize.div_ceil(3);
    let first_text = text.get(..first_chars).ok_or("truncated header")?;
    let too_long = || "the array is longer than the file".to_string();
    if !h.compressed {
        let all = if first_text.contains(&b'=') {
            let mut all = base64_decode(first_text)?;
            let data_chars = base64_len(expected).ok_or_else(too_long)?;
            let data = first_chars.checked_add(data_chars).and_then(|end| text.get(first_chars..end));
            all.extend(base64_decode(data.ok_or("truncated data")?)?);
            all
        } else {
            let chars = hsize.checked_add(expected).and_then(base64_len).ok_or_else(too_long)?;
            base64_decode(text.get(..chars).ok_or("truncated data")?)?
        };
        return uncompressed(&all, h, expected);
    }
    let blocks = read_uint(&base64_decode(first_text)?, 0, h)?;
    let header_len = block_header_len(blocks, hsize, text.len())?;
    let header_chars = base64_len(header_len).ok_or_else(too_long)?;
    let header = base64_decode(text.get(..header_chars).ok_or("truncated header")?)?;
    let compressed = compressed_len(&header, blocks, h)?;
    let data_chars = base64_len(compressed).ok_or_else(too_long)?;
    let data = header_chars.checked_add(data_chars).and_then(|end| text.get(header_chars..end));
    let data = base64_decode(data.ok_or("truncated compressed data")?)?;
    inflate_blocks(&header, &data, blocks, h, expected)
}

fn decode_raw_array(bytes: &[u8], h: Header, expected: usize) -> Result<Vec<u8>, String> {
    if !h.compressed {
        return uncompressed(bytes, h, expected);
    }
    let blocks = read_uint(bytes, 0, h)?;
    let header_len = block_header_len(blocks, h.hsize(), bytes.len())?;
    let (header, data) = bytes.split_at_checked(header_len).ok_or("truncated header")?;
    inflate_blocks(header, data, blocks, h, expected)
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

/// The sum of the compressed block sizes of a block header.
fn compressed_len(header: &[u8], blocks: u64, h: Header) -> Result<usize, String> {
    let mut total = 0u64;
    for block in 0..blocks {
        let at = usize::try_from(block).ok().and_then(|b| b.checked_add(3)?.checked_mul(h.hsize()));
        let size = read_uint(header, at.ok_or("truncated block header")?, h)?;
        total = total.checked_add(size).ok_or("compressed block sizes overflow")?;
    }
    usize::try_from(total).map_err(|_| "compressed block sizes overflow".to_string())
}

/// zlib blocks after the `[blocks, block size, last block size, compressed sizes…]` header. The sizes must add up to
/// the `expected` bytes before anything is inflated, and each block must inflate to exactly its size.
fn inflate_blocks(header: &[u8], data: &[u8], blocks: u64, h: Header, expected: usize) -> Result<Vec<u8>, String> {
    let hsize = h.hsize();
    let block_size = read_uint(header, hsize, h)?;
    let last_size = match read_uint(header, 2 * hsize, h)? {
        0 => block_size,
        n => n,
    };
    let total = match blocks {
        0 => Some(0),
        n => block_size.checked_mul(n - 1).and_then(|t| t.checked_add(last_size)),
    };
    if last_size > block_size || total != Some(expected as u64) {
        return Err(format!(
            "the compression header ({blocks} blocks of {block_size} bytes, the last {last_size}) does not add up to \
             the {expected} bytes the point count needs"
        ));
    }
    if expected as u64 > (data.len() as u64).saturating_mul(DEFLATE_MAX_RATIO) {
        return Err(format!(
            "{} compressed bytes cannot inflate to the {expected} bytes the point count needs (deflate expands at \
             most {DEFLATE_MAX_RATIO}:1)",
            data.len()
        ));
    }
    let mut out = Vec::with_capacity(expected);
    let mut at = 0usize;
    for block in 0..blocks {
        let entry = usize::try_from(block).ok().and_then(|b| b.checked_add(3)?.checked_mul(hsize));
        let size = read_uint(header, entry.ok_or("truncated block header")?, h)?;
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

#[cfg(test)]
mod tests {
    use std::io::Write;

    use super::*;

    fn parse_bytes(bytes: &[u8]) -> Result<RawParticles, GeometryError> {
        parse(bytes, Path::new("p.vtp"))
    }

    fn error(bytes: &[u8]) -> String {
        parse_bytes(bytes).unwrap_err().to_string()
    }

    const ASCII: &str = r#"<?xml version="1.0"?>
<VTKFile type="PolyData" version="0.1" byte_order="LittleEndian">
  <PolyData>
    <Piece NumberOfPoints="3" NumberOfVerts="0" NumberOfLines="0" NumberOfStrips="0" NumberOfPolys="0">
      <PointData Scalars="density">
        <DataArray type="Float32" Name="velocity" NumberOfComponents="3" format="ascii">0 0 0 1 1 1 2 2 2</DataArray>
        <DataArray type="Float64" Name="density" format="ascii">
          1.5 2.5 3.5
        </DataArray>
        <DataArray type="Float32" Name="Mass" format="ascii">1 2 3</DataArray>
        <DataArray type="Int32" Name="id" format="ascii">7 8 9</DataArray>
      </PointData>
      <Points>
        <DataArray type="Float32" Name="Points" NumberOfComponents="3" format="ascii">
          0 0 0 1 0 0 0 1 0.5
        </DataArray>
      </Points>
      <Verts><DataArray type="Int64" Name="connectivity" format="ascii">0 1 2</DataArray></Verts>
    </Piece>
  </PolyData>
</VTKFile>
"#;

    #[test]
    fn ascii_polydata() {
        let p = parse_bytes(ASCII.as_bytes()).unwrap();
        assert_eq!(p.positions, vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.5]]);
        assert_eq!(p.values, vec![1.5, 2.5, 3.5]);
        assert_eq!(p.value_name, "density");
        assert_eq!(p.masses, vec![1.0, 2.0, 3.0]);
        assert!(p.smoothing.is_empty());
    }

    fn zlib(bytes: &[u8]) -> Vec<u8> {
        let mut e = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        e.write_all(bytes).unwrap();
        e.finish().unwrap()
    }

    fn b64(bytes: &[u8]) -> String {
        base64::engine::general_purpose::STANDARD.encode(bytes)
    }

    /// A zlib-compressed array as VTK writes it inline: the block header (UInt64 or UInt32 entries) and the blocks,
    /// two base64 runs. `block` bytes a block.
    fn compressed_inline_with(data: &[u8], block: usize, header_u64: bool) -> String {
        let blocks: Vec<Vec<u8>> = data.chunks(block).map(zlib).collect();
        let last = data.len() - (blocks.len() - 1) * block;
        let entries = [blocks.len(), block, if last == block { 0 } else { last }];
        let entries = entries.into_iter().chain(blocks.iter().map(Vec::len));
        let header: Vec<u8> = if header_u64 {
            entries.flat_map(|v| (v as u64).to_le_bytes()).collect()
        } else {
            entries.flat_map(|v| (v as u32).to_le_bytes()).collect()
        };
        format!("{}{}", b64(&header), b64(&blocks.concat()))
    }

    fn compressed_inline(data: &[u8], block: usize) -> String {
        compressed_inline_with(data, block, true)
    }

    fn le_bytes<T: Copy, const N: usize>(values: &[T], f: fn(T) -> [u8; N]) -> Vec<u8> {
        values.iter().flat_map(|&v| f(v)).collect()
    }

    #[test]
    fn binary_zlib_compressed() {
        let points = le_bytes(&[0.0f64, 0.0, 0.0, 1.0, 2.0, 3.0, -1.0, 0.5, 9.0], f64::to_le_bytes);
        let hsml = le_bytes(&[0.1f32, 0.2, 0.3], f32::to_le_bytes);
        let text = format!(
            r#"<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian" header_type="UInt64" compressor="vtkZLibDataCompressor">
<PolyData><Piece NumberOfPoints="3">
<PointData><DataArray type="Float32" Name="hsml" format="binary">
  {}
</DataArray></PointData>
<Points><DataArray type="Float64" NumberOfComponents="3" format="binary">{}</DataArray></Points>
</Piece></PolyData></VTKFile>"#,
            compressed_inline(&hsml, 12),
            compressed_inline(&points, 32)
        );
        let p = parse_bytes(text.as_bytes()).unwrap();
        assert_eq!(p.positions, vec![[0.0; 3], [1.0, 2.0, 3.0], [-1.0, 0.5, 9.0]]);
        assert_eq!(p.smoothing, vec![0.1, 0.2, 0.3]);
        // A block header announcing a size the point count does not need.
        let lying = text.replace("NumberOfPoints=\"3\"", "NumberOfPoints=\"2\"");
        let e = error(lying.as_bytes());
        let expected =
            "line 6: DataArray 'Points': the compression header (3 blocks of 32 bytes, the last 8) does not \
                        add up to the 48 bytes";
        assert!(e.contains(expected), "{e}");
        // UInt32 block headers.
        let text32 = format!(
            r#"<VTKFile type="PolyData" compressor="vtkZLibDataCompressor"><PolyData><Piece NumberOfPoints="3">
<Points><DataArray type="Float64" NumberOfComponents="3" format="binary">{}</DataArray></Points>
</Piece></PolyData></VTKFile>"#,
            compressed_inline_with(&points, 40, false)
        );
        assert_eq!(parse_bytes(text32.as_bytes()).unwrap().positions, p.positions);
        // A zlib bomb: a consistent header announcing 12 MB from 10 compressed bytes is refused before inflating.
        let mut header = Vec::new();
        for v in [1u32, 12_000_000, 0, 10] {
            header.extend(v.to_le_bytes());
        }
        let bomb = format!(
            r#"<VTKFile type="PolyData" compressor="vtkZLibDataCompressor"><PolyData><Piece NumberOfPoints="1000000">
<Points><DataArray type="Float32" NumberOfComponents="3" format="binary">{}{}</DataArray></Points>
</Piece></PolyData></VTKFile>"#,
            b64(&header),
            b64(&[0x78, 0x9c, 0, 0, 0, 0, 0, 0, 0, 0])
        );
        assert_eq!(
            error(bomb.as_bytes()),
            "p.vtp line 2: DataArray 'Points': 10 compressed bytes cannot inflate to the 12000000 bytes the point \
             count needs (deflate expands at most 1032:1)"
        );
    }

    #[test]
    fn binary_uncompressed_big_endian_one_or_two_runs() {
        let points: Vec<u8> = [1.0f32, 2.0, 3.0].iter().flat_map(|v| v.to_be_bytes()).collect();
        let mut one_run = 12u32.to_be_bytes().to_vec();
        one_run.extend(&points);
        let two_runs = format!("{}{}", b64(&12u32.to_be_bytes()), b64(&points));
        for encoded in [b64(&one_run), two_runs] {
            let text = format!(
                r#"<VTKFile type="PolyData" byte_order="BigEndian"><PolyData><Piece NumberOfPoints="1"><Points>
<DataArray type="Float32" NumberOfComponents="3" format="binary">{encoded}</DataArray></Points></Piece></PolyData></VTKFile>"#
            );
            assert_eq!(parse_bytes(text.as_bytes()).unwrap().positions, vec![[1.0, 2.0, 3.0]]);
        }
    }

    /// An appended raw file: two pieces, Int16 values and Float32 points.
    fn appended_raw(value_name_second: &str) -> Vec<u8> {
        let mut data = Vec::new();
        let mut offsets = Vec::new();
        let arrays: [Vec<u8>; 4] = [
            le_bytes(&[0.0f32, 0.0, 0.0, 1.0, 1.0, 1.0], f32::to_le_bytes),
            le_bytes(&[-5i16, 6], i16::to_le_bytes),
            le_bytes(&[2.0f32, 2.0, 2.0], f32::to_le_bytes),
            le_bytes(&[7i16], i16::to_le_bytes),
        ];
        for a in &arrays {
            offsets.push(data.len());
            data.extend((a.len() as u32).to_le_bytes());
            data.extend(a);
        }
        let mut f = format!(
            r#"<?xml version="1.0"?>
<VTKFile type="PolyData" version="0.1" byte_order="LittleEndian">
<PolyData>
<Piece NumberOfPoints="2"><PointData><DataArray type="Int16" Name="T" format="appended" offset="{}"/></PointData>
<Points><DataArray type="Float32" NumberOfComponents="3" format="appended" offset="{}"/></Points></Piece>
<Piece NumberOfPoints="1"><PointData><DataArray type="Int16" Name="{value_name_second}" format="appended" offset="{}"/></PointData>
<Points><DataArray type="Float32" NumberOfComponents="3" format="appended" offset="{}"/></Points></Piece>
</PolyData>
<AppendedData encoding="raw">
_"#,
            offsets[1], offsets[0], offsets[3], offsets[2]
        )
        .into_bytes();
        f.extend(&data);
        f.extend(b"\n</AppendedData>\n</VTKFile>\n");
        f
    }

    #[test]
    fn appended_raw_pieces() {
        let p = parse_bytes(&appended_raw("T")).unwrap();
        assert_eq!(p.positions, vec![[0.0; 3], [1.0; 3], [2.0; 3]]);
        assert_eq!(p.values, vec![-5.0, 6.0, 7.0]);
        assert_eq!(p.value_name, "T");
        assert_eq!(
            error(&appended_raw("U")),
            "p.vtp: piece 2 has no scalar array 'T' that piece 1 has: every piece needs the same arrays"
        );
        let file = appended_raw("T");
        for end in 0..file.len() {
            let _ = parse_bytes(&file[..end]);
        }
    }

    /// Pieces whose appended arrays all name the same data, which would decode to far more than the file holds.
    fn shared_offsets(pieces: usize, points: usize, compressed: bool) -> Vec<u8> {
        let zeros = vec![0u8; points * 12];
        let data = if compressed {
            let block = zlib(&zeros);
            let mut data = le_bytes(&[1u32, zeros.len() as u32, 0, block.len() as u32], u32::to_le_bytes);
            data.extend(block);
            data
        } else {
            let mut data = (zeros.len() as u32).to_le_bytes().to_vec();
            data.extend(&zeros);
            data
        };
        let compressor = if compressed { r#" compressor="vtkZLibDataCompressor""# } else { "" };
        let piece = format!(
            r#"<Piece NumberOfPoints="{points}"><Points>{}</Points></Piece>"#,
            r#"<DataArray type="Float32" NumberOfComponents="3" format="appended" offset="0"/>"#
        );
        let mut f = format!(
            r#"<VTKFile type="PolyData"{compressor}><PolyData>{}</PolyData><AppendedData encoding="raw">_"#,
            piece.repeat(pieces)
        )
        .into_bytes();
        f.extend(data);
        f.extend(b"</AppendedData></VTKFile>");
        f
    }

    #[test]
    fn appended_arrays_sharing_their_data_are_refused() {
        // Sharing within what the file holds is read.
        assert_eq!(parse_bytes(&shared_offsets(2, 1, false)).unwrap().positions, vec![[0.0; 3]; 2]);
        let e = error(&shared_offsets(3, 1000, false));
        assert!(e.contains("DataArray 'Points': with the arrays before it, 24000 bytes of data, more than the"), "{e}");
        assert!(e.ends_with("bytes can hold: arrays cannot share their data"), "{e}");
        // A zlib block of 1.2 MB of zeros, named by 3 pieces: one inflates within 1032:1, two do not.
        let e = error(&shared_offsets(3, 100_000, true));
        assert!(e.contains("with the arrays before it, 2400000 bytes of data"), "{e}");
        assert!(e.ends_with("can inflate to (deflate expands at most 1032:1): arrays cannot share their data"), "{e}");
    }

    #[test]
    fn appended_base64_compressed() {
        let points = le_bytes(&[4.0f32, 5.0, 6.0], f32::to_le_bytes);
        let mass = le_bytes(&[3.0f64], f64::to_le_bytes);
        let first = compressed_inline(&mass, 8);
        let text = format!(
            r#"<VTKFile type="PolyData" header_type="UInt64" compressor="vtkZLibDataCompressor">
<PolyData><Piece NumberOfPoints="1"><PointData><DataArray type="Float64" Name="m" format="appended" offset="0"/></PointData>
<Points><DataArray type="Float32" NumberOfComponents="3" format="appended" offset="{}"/></Points></Piece></PolyData>
<AppendedData encoding="base64">
_{first}{}
</AppendedData></VTKFile>"#,
            first.len(),
            compressed_inline(&points, 12)
        );
        let p = parse_bytes(text.as_bytes()).unwrap();
        assert_eq!(p.positions, vec![[4.0, 5.0, 6.0]]);
        assert_eq!(p.masses, vec![3.0]);
    }

    /// The layout PySPH's `dump_vtk` (through pyvisfile) writes: an unstructured grid of one vertex cell per particle,
    /// every array appended as its own base64 run of a UInt32 byte count and the values.
    #[test]
    fn unstructured_grid_as_pysph_writes_it() {
        let run = |data: Vec<u8>| b64(&[(data.len() as u32).to_le_bytes().to_vec(), data].concat());
        let arrays = [
            ("Float64", "rho", 1, run(le_bytes(&[1000.5f64, 1001.5], f64::to_le_bytes))),
            ("Float64", "m", 1, run(le_bytes(&[0.064f64, 0.064], f64::to_le_bytes))),
            ("Float64", "h", 1, run(le_bytes(&[0.052f64, 0.052], f64::to_le_bytes))),
            ("Float64", "velocity", 3, run(le_bytes(&[0.0f64, 1.0, 2.0, 3.0, 4.0, 5.0], f64::to_le_bytes))),
            ("Float64", "points", 3, run(le_bytes(&[0.1f64, 0.2, 0.3, 1.1, 1.2, 1.3], f64::to_le_bytes))),
            ("Int64", "connectivity", 1, run(le_bytes(&[0i64, 1], i64::to_le_bytes))),
        ];
        let mut offset = 0;
        let mut elements = Vec::new();
        for (ty, name, components, text) in &arrays {
            elements.push(format!(
                r#"<DataArray type="{ty}" Name="{name}" NumberOfComponents="{components}" format="appended" offset="{offset}"/>"#
            ));
            offset += text.len();
        }
        let appended: String = arrays.iter().map(|a| a.3.as_str()).collect();
        let text = format!(
            r#"<?xml version="1.0"?>
<VTKFile type="UnstructuredGrid" version="0.1" byte_order="LittleEndian">
<UnstructuredGrid>
<Piece NumberOfPoints="2" NumberOfCells="2">
<PointData>
{}
{}
{}
{}
</PointData>
<Points>
{}
</Points>
<Cells>
{}
</Cells>
</Piece>
</UnstructuredGrid>
<AppendedData encoding="base64">
_{appended}
</AppendedData>
</VTKFile>
"#,
            elements[0], elements[1], elements[2], elements[3], elements[4], elements[5]
        );
        let p = parse_dataset(text.as_bytes(), Path::new("p.vtu"), Dataset::UnstructuredGrid).unwrap();
        assert_eq!(p.positions, vec![[0.1, 0.2, 0.3], [1.1, 1.2, 1.3]]);
        assert_eq!(p.smoothing, vec![0.052, 0.052]);
        assert_eq!(p.masses, vec![0.064, 0.064]);
        assert_eq!(p.values, vec![1000.5, 1001.5]);
        assert_eq!(p.value_name, "rho");
        // The type must be what the name says.
        assert_eq!(
            error(text.as_bytes()),
            "p.vtp: unsupported: VTKFile type 'UnstructuredGrid': only PolyData is read from .vtp (name the file .vtu to \
             read it)"
        );
        let polydata = parse_dataset(ASCII.as_bytes(), Path::new("p.vtu"), Dataset::UnstructuredGrid);
        assert_eq!(
            polydata.unwrap_err().to_string(),
            "p.vtu: unsupported: VTKFile type 'PolyData': only UnstructuredGrid is read from .vtu (name the file .vtp to \
             read it)"
        );
    }

    #[test]
    fn errors_name_the_problem() {
        let count = ASCII.replace("NumberOfPoints=\"3\"", "NumberOfPoints=\"4\"");
        assert_eq!(error(count.as_bytes()), "p.vtp line 14: DataArray 'Points': 9 values, the point count needs 12");
        let many = ASCII.replace("1.5 2.5 3.5", "1.5 2.5 3.5 4.5");
        assert_eq!(
            error(many.as_bytes()),
            "p.vtp line 7: DataArray 'density': more than the 3 values the point count needs"
        );
        let word = ASCII.replace("1.5 2.5", "1.5 x");
        assert_eq!(error(word.as_bytes()), "p.vtp line 7: DataArray 'density': 'x' is not a number");
        let two = ASCII
            .replace("NumberOfComponents=\"3\" format=\"ascii\">\n", "NumberOfComponents=\"2\" format=\"ascii\">\n");
        assert_eq!(error(two.as_bytes()), "p.vtp line 14: Points with 2 components (3 expected)");
        let huge = ASCII.replace("NumberOfPoints=\"3\"", "NumberOfPoints=\"18446744073709551615\"");
        assert!(error(huge.as_bytes()).contains("too many"));
        let big = ASCII.replace("NumberOfPoints=\"3\"", "NumberOfPoints=\"1000000000000\"");
        assert!(error(big.as_bytes()).contains("more than 4294967296 bytes in one array"));
        let grid = ASCII.replace("type=\"PolyData\"", "type=\"UnstructuredGrid\"");
        assert!(error(grid.as_bytes()).contains("unsupported: VTKFile type 'UnstructuredGrid'"));
        assert!(error(b"<VTKFile type=\"PolyData\"><PolyData><Piece></Piece></PolyData></VTKFile>")
            .contains("Piece has no NumberOfPoints"));
        assert!(error(b"<VTKFile type=\"PolyData\"><Piece NumberOfPoints=\"1\"></Piece></VTKFile>")
            .contains("piece 1 has 1 points but no Points array"));
        assert!(error(b"<a><b></a>").contains("malformed XML"));
        assert_eq!(error(b"hello"), "p.vtp: not a VTK XML file: no VTKFile element");
        let mut raw = b"<VTKFile type=\"PolyData\"><PolyData><Piece NumberOfPoints=\"1000\"><Points>\
            <DataArray type=\"Float32\" NumberOfComponents=\"3\" format=\"appended\" offset=\"0\"/></Points></Piece>\
            </PolyData><AppendedData encoding=\"raw\">_"
            .to_vec();
        raw.extend(12000u32.to_le_bytes());
        raw.extend(b"\0\0\0\0</AppendedData></VTKFile>");
        assert_eq!(error(&raw), "p.vtp line 1: DataArray 'Points': truncated data: 29 bytes of the 12000 announced");
    }
}
