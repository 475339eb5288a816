//! VTK XML PolyData (`.vtp`) and UnstructuredGrid (`.vtu`,
//! <https://docs.vtk.org/en/latest/design_documents/VTKFileFormats.html>): the points of every `Piece` as particles,
//! with arrays of their `PointData`. SPH codes write their particles as either (PySPH's `pysph dump_vtk` writes
//! `.vtu`, one vertex cell per particle; the cells are not needed and not read).
//!
//! Arrays are read inline (`ascii`, `binary`: base64) or appended (`raw` or `base64`), uncompressed or
//! zlib-compressed (`vtkZLibDataCompressor`), little- or big-endian, with UInt32 or UInt64 block headers, of any
//! integer or floating-point type; `voxstream-vtk-xml` decodes them, as it does for the store's `.vti` reader. The `Points` array must have 3
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
//!
//! This module scans the XML for the pieces and their arrays; `assemble` decodes the arrays and puts the particles
//! together.

mod assemble;
#[cfg(test)]
mod tests;

use std::cell::Cell;
use std::path::Path;

use quick_xml::events::Event;
use voxstream_vtk_xml::{appended_base64_text, attribute, find, xml_end, Encoding};

use super::xyz::{column_role, ColumnRole};
use crate::error::GeometryError;
use crate::particles::RawParticles;
use assemble::{assemble, Decoder, Ty};

/// The most bytes one array may decode to: arrays are held in memory whole.
pub const MAX_ARRAY_BYTES: u64 = 1 << 32;

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

/// The line of byte `at`, counted from 1.
fn line_at(bytes: &[u8], at: usize) -> u64 {
    bytes.get(..at).unwrap_or(bytes).iter().filter(|&&b| b == b'\n').count() as u64 + 1
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
    let (appended_at, xml_end) = xml_end(bytes);
    let mut reader = quick_xml::Reader::from_reader(bytes.get(..xml_end).unwrap_or(bytes));
    let mut encoding = Encoding::default();
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
                let attr = |name: &str| attribute(e, name);
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
                        encoding = Encoding::from_attributes(attr)
                            .map_err(|compressor| unsupported(compressor.to_string()))?;
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
        (Some(body), Some("base64")) => Some(appended_base64_text(body)),
        _ => None,
    };
    let decoder =
        Decoder { bytes, path, encoding, appended, appended_base64: appended_base64.as_deref(), decoded: Cell::new(0) };
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
