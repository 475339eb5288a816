//! Legacy VTK files (`.vtk`, <https://docs.vtk.org/en/latest/design_documents/VTKFileFormats.html>): the points of a
//! `POLYDATA`, `UNSTRUCTURED_GRID` or `STRUCTURED_GRID` dataset as particles, ASCII or `BINARY` (big-endian).
//!
//! `POINTS` of any numeric type give the positions. The cells (`VERTICES`, `LINES`, `POLYGONS`,
//! `TRIANGLE_STRIPS`, `CELLS`, `CELL_TYPES`, in both the classic layout and version 5's `OFFSETS`/`CONNECTIVITY`),
//! `CELL_DATA`, dataset `FIELD` data and `METADATA` blocks are read past. Of the `POINT_DATA`, one-component
//! `SCALARS` and `FIELD` arrays are taken by name ([`super::xyz`]'s rules): the first named like a smoothing length
//! (`h`, `hsml`, `radius`, `smoothing_length`) becomes `smoothing`, the first named `mass` or `m` the masses, and the
//! first other one the scalar attribute; vectors, normals, tensors, texture coordinates, colours and lookup tables are
//! read past. Every count is checked against the bytes that follow before anything is allocated for it; errors name
//! the line in ASCII files.
//!
//! Binary `long` and `unsigned_long` are taken as 8 bytes, `vtkIdType` as 4 (what VTK writes). Not read:
//! `STRUCTURED_POINTS` and `RECTILINEAR_GRID` (volumes, not point sets), `string` and `variant` arrays, bit arrays
//! as attributes (read past), cells themselves (only their points are particles).

use std::path::Path;

use super::xyz::{column_role, ColumnRole};
use crate::error::GeometryError;
use crate::particles::RawParticles;

/// A VTK data type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Ty {
    Bit,
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
    fn parse(name: &[u8]) -> Option<Ty> {
        Some(match name.to_ascii_lowercase().as_slice() {
            b"bit" => Ty::Bit,
            b"unsigned_char" | b"vtktypeuint8" => Ty::U8,
            b"char" | b"signed_char" | b"vtktypeint8" => Ty::I8,
            b"unsigned_short" | b"vtktypeuint16" => Ty::U16,
            b"short" | b"vtktypeint16" => Ty::I16,
            b"unsigned_int" | b"vtktypeuint32" => Ty::U32,
            b"int" | b"vtkidtype" | b"vtktypeint32" => Ty::I32,
            b"unsigned_long" | b"unsigned_long_long" | b"vtktypeuint64" => Ty::U64,
            b"long" | b"long_long" | b"vtktypeint64" => Ty::I64,
            b"float" | b"vtktypefloat32" => Ty::F32,
            b"double" | b"vtktypefloat64" => Ty::F64,
            _ => return None,
        })
    }

    /// Bytes per value in a binary file (bits: 0, see [`binary_len`]).
    fn size(self) -> usize {
        match self {
            Ty::Bit => 0,
            Ty::U8 | Ty::I8 => 1,
            Ty::U16 | Ty::I16 => 2,
            Ty::U32 | Ty::I32 | Ty::F32 => 4,
            Ty::U64 | Ty::I64 | Ty::F64 => 8,
        }
    }

    /// Decodes one big-endian value of [`Ty::size`] bytes.
    fn decode(self, b: &[u8]) -> f64 {
        let mut a = [0u8; 8];
        let n = self.size().min(b.len()).min(8);
        a[..n].copy_from_slice(&b[..n]);
        match self {
            Ty::Bit => 0.0,
            Ty::U8 => f64::from(a[0]),
            Ty::I8 => f64::from(a[0] as i8),
            Ty::U16 => f64::from(u16::from_be_bytes([a[0], a[1]])),
            Ty::I16 => f64::from(i16::from_be_bytes([a[0], a[1]])),
            Ty::U32 => f64::from(u32::from_be_bytes([a[0], a[1], a[2], a[3]])),
            Ty::I32 => f64::from(i32::from_be_bytes([a[0], a[1], a[2], a[3]])),
            Ty::F32 => f64::from(f32::from_be_bytes([a[0], a[1], a[2], a[3]])),
            Ty::U64 => u64::from_be_bytes(a) as f64,
            Ty::I64 => i64::from_be_bytes(a) as f64,
            Ty::F64 => f64::from_be_bytes(a),
        }
    }
}

/// Bytes that `values` values of `ty` take in a binary file (bits are packed, 8 a byte).
fn binary_len(values: usize, ty: Ty) -> Option<usize> {
    match ty {
        Ty::Bit => Some(values.div_ceil(8)),
        _ => values.checked_mul(ty.size()),
    }
}

/// Reads through the file: tokens, header lines and data arrays.
struct Cursor<'a> {
    bytes: &'a [u8],
    at: usize,
    binary: bool,
    path: &'a Path,
}

impl<'a> Cursor<'a> {
    /// A format error at the current place (with its line in ASCII files).
    fn error(&self, message: impl Into<String>) -> GeometryError {
        let line = (!self.binary).then(|| {
            let before = self.bytes.get(..self.at).unwrap_or(self.bytes);
            before.iter().filter(|&&b| b == b'\n').count() as u64 + 1
        });
        GeometryError::format(self.path, line, message)
    }

    fn remaining(&self) -> usize {
        self.bytes.len().saturating_sub(self.at)
    }

    /// The next blank-separated token (crossing lines), if any.
    fn token(&mut self) -> Option<&'a [u8]> {
        let rest = self.bytes.get(self.at..)?;
        let start = rest.iter().position(|b| !b.is_ascii_whitespace())?;
        let len = rest.get(start..)?.iter().position(u8::is_ascii_whitespace).unwrap_or(rest.len() - start);
        self.at += start + len;
        rest.get(start..start + len)
    }

    /// The next token, without consuming it.
    fn peek(&mut self) -> Option<&'a [u8]> {
        let at = self.at;
        let token = self.token();
        self.at = at;
        token
    }

    /// The next token, which must be there: `what` names it in the error.
    fn expect(&mut self, what: &str) -> Result<&'a [u8], GeometryError> {
        self.token().ok_or_else(|| self.error(format!("the file ends where {what} should be")))
    }

    /// The next token as a count.
    fn count(&mut self, what: &str) -> Result<usize, GeometryError> {
        let token = self.expect(what)?;
        let text = String::from_utf8_lossy(token);
        text.parse().map_err(|_| self.error(format!("{what} '{text}' is not a count")))
    }

    /// The rest of the current line (its newline consumed).
    fn rest_of_line(&mut self) -> &'a [u8] {
        let rest = self.bytes.get(self.at..).unwrap_or(&[]);
        let len = rest.iter().position(|&b| b == b'\n').unwrap_or(rest.len());
        self.at += (len + 1).min(rest.len());
        rest.get(..len).unwrap_or(&[])
    }

    /// In a binary file, moves past the newline that ends a header line, to where its data begins.
    fn data_begins(&mut self) {
        if self.binary {
            self.rest_of_line();
        }
    }

    /// Reads `tuples` × `components` values of `ty`, keeping them if `keep`. `what` names the array in errors.
    fn array(
        &mut self,
        tuples: usize,
        components: usize,
        ty: Ty,
        keep: bool,
        what: &str,
    ) -> Result<Vec<f64>, GeometryError> {
        let total = tuples
            .checked_mul(components)
            .ok_or_else(|| self.error(format!("{what} announces {tuples} × {components} values, too many")))?;
        let remaining = self.remaining();
        if self.binary {
            let len = binary_len(total, ty).filter(|&len| len <= remaining).ok_or_else(|| {
                self.error(format!("{what} announces {tuples} × {components} values but only {remaining} bytes follow"))
            })?;
            let data = self.bytes.get(self.at..self.at + len).unwrap_or(&[]);
            self.at += len;
            if !keep {
                return Ok(Vec::new());
            }
            return Ok(match ty {
                Ty::Bit => {
                    (0..total).map(|i| f64::from(data.get(i / 8).map_or(0, |byte| (byte >> (7 - i % 8)) & 1))).collect()
                }
                _ => data.chunks_exact(ty.size()).map(|b| ty.decode(b)).collect(),
            });
        }
        // Each ASCII value takes at least a character and a separator.
        if total > remaining / 2 + 1 {
            return Err(self
                .error(format!("{what} announces {tuples} × {components} values but only {remaining} bytes follow")));
        }
        let mut values = Vec::with_capacity(if keep { total } else { 0 });
        for read in 0..total {
            let Some(token) = self.token() else {
                return Err(self
                    .error(format!("{what} announces {tuples} × {components} values but the file ends after {read}")));
            };
            let value: f64 = std::str::from_utf8(token).ok().and_then(|t| t.parse().ok()).ok_or_else(|| {
                self.error(format!(
                    "{what}: '{}' is not a number (value {} of {total})",
                    String::from_utf8_lossy(token),
                    read + 1
                ))
            })?;
            if keep {
                values.push(value);
            }
        }
        Ok(values)
    }

    /// The type token of an array header.
    fn ty(&mut self, what: &str) -> Result<Ty, GeometryError> {
        let token = self.expect(&format!("the type of {what}"))?;
        Ty::parse(token).ok_or_else(|| {
            let name = String::from_utf8_lossy(token);
            if name.eq_ignore_ascii_case("string") || name.eq_ignore_ascii_case("variant") {
                GeometryError::Unsupported { path: self.path.into(), message: format!("{name} arrays ({what})") }
            } else {
                self.error(format!("unknown data type '{name}' for {what}"))
            }
        })
    }

    /// A `METADATA` block: text lines up to a blank one.
    fn skip_metadata(&mut self) {
        self.rest_of_line();
        while self.at < self.bytes.len() && !self.rest_of_line().trim_ascii().is_empty() {}
    }
}

/// Array names in VTK files encode blanks and other characters as `%XX`.
fn decode_name(token: &[u8]) -> String {
    let mut out = Vec::with_capacity(token.len());
    let mut i = 0;
    while let Some(&b) = token.get(i) {
        let hex = token
            .get(i + 1..i + 3)
            .and_then(|h| std::str::from_utf8(h).ok())
            .and_then(|h| u8::from_str_radix(h, 16).ok());
        match (b, hex) {
            (b'%', Some(decoded)) => {
                out.push(decoded);
                i += 3;
            }
            _ => {
                out.push(b);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// Which attribute section the arrays being read belong to.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Section {
    Dataset,
    Points(usize),
    Cells(usize),
}

/// The point arrays taken so far.
#[derive(Default)]
struct Taken {
    smoothing: bool,
    mass: bool,
    value: bool,
}

impl Taken {
    /// Whether the point array `name` of `components` components fills a column not yet filled; marks it filled.
    fn take(&mut self, name: &str, components: usize) -> Option<ColumnRole> {
        if components != 1 {
            return None;
        }
        let role = column_role(name);
        let slot = match role {
            ColumnRole::Smoothing => &mut self.smoothing,
            ColumnRole::Mass => &mut self.mass,
            ColumnRole::Value => &mut self.value,
        };
        (!std::mem::replace(slot, true)).then_some(role)
    }
}

fn store(raw: &mut RawParticles, role: ColumnRole, name: String, values: Vec<f64>) {
    let values = values.into_iter().map(|v| v as f32).collect();
    match role {
        ColumnRole::Smoothing => raw.smoothing = values,
        ColumnRole::Mass => raw.masses = values,
        ColumnRole::Value => {
            raw.values = values;
            raw.value_name = name;
        }
    }
}

/// Parses a legacy `.vtk` file.
pub fn parse(bytes: &[u8], path: &Path) -> Result<RawParticles, GeometryError> {
    let mut c = Cursor { bytes, at: 0, binary: false, path };
    let first = c.rest_of_line();
    if !first.trim_ascii().to_ascii_lowercase().starts_with(b"# vtk datafile") {
        return Err(c.error("not a legacy VTK file: the first line must be '# vtk DataFile Version …'"));
    }
    c.rest_of_line(); // the title
    let encoding = c.rest_of_line().trim_ascii().to_ascii_uppercase();
    match encoding.as_slice() {
        b"ASCII" => {}
        b"BINARY" => c.binary = true,
        other => {
            return Err(
                c.error(format!("the third line must be ASCII or BINARY, not '{}'", String::from_utf8_lossy(other)))
            )
        }
    }
    let keyword = c.expect("DATASET")?;
    if !keyword.eq_ignore_ascii_case(b"DATASET") {
        return Err(c.error(format!("expected DATASET, found '{}'", String::from_utf8_lossy(keyword))));
    }
    let kind = c.expect("the dataset type")?.to_ascii_uppercase();
    match kind.as_slice() {
        b"POLYDATA" | b"UNSTRUCTURED_GRID" | b"STRUCTURED_GRID" => {}
        b"STRUCTURED_POINTS" | b"RECTILINEAR_GRID" => {
            return Err(GeometryError::Unsupported {
                path: path.into(),
                message: format!("DATASET {}: a grid, not a point set", String::from_utf8_lossy(&kind)),
            })
        }
        other => return Err(c.error(format!("unknown DATASET type '{}'", String::from_utf8_lossy(other)))),
    }
    let mut raw = RawParticles::default();
    let mut points: Option<usize> = None;
    let mut section = Section::Dataset;
    let mut taken = Taken::default();
    while let Some(token) = c.token() {
        let keyword = token.to_ascii_uppercase();
        let keyword_text = String::from_utf8_lossy(&keyword).into_owned();
        match keyword.as_slice() {
            b"POINTS" => {
                if points.is_some() {
                    return Err(c.error("a second POINTS section"));
                }
                let n = c.count("the number of POINTS")?;
                let ty = c.ty("POINTS")?;
                c.data_begins();
                let values = c.array(n, 3, ty, true, &format!("POINTS ({n} points)"))?;
                raw.positions = values.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect();
                points = Some(n);
            }
            b"DIMENSIONS" => {
                for axis in ["x", "y", "z"] {
                    c.count(&format!("the {axis} dimension"))?;
                }
            }
            b"VERTICES" | b"LINES" | b"POLYGONS" | b"TRIANGLE_STRIPS" | b"CELLS" => {
                let cells = c.count(&format!("the number of {keyword_text}"))?;
                let size = c.count(&format!("the size of {keyword_text}"))?;
                c.data_begins();
                if c.peek().is_some_and(|t| t == b"OFFSETS") {
                    // Version 5: offsets (one more than the cells) and connectivity, each with its type.
                    for (part, n) in [("OFFSETS", cells), ("CONNECTIVITY", size)] {
                        let found = c.expect(part)?;
                        if found != part.as_bytes() {
                            return Err(c.error(format!(
                                "{keyword_text}: expected {part}, found '{}'",
                                String::from_utf8_lossy(found)
                            )));
                        }
                        let ty = c.ty(&format!("{keyword_text} {part}"))?;
                        c.data_begins();
                        c.array(n, 1, ty, false, &format!("{keyword_text} {part}"))?;
                    }
                } else {
                    c.array(size, 1, Ty::I32, false, &keyword_text)?;
                }
            }
            b"CELL_TYPES" => {
                let n = c.count("the number of CELL_TYPES")?;
                c.data_begins();
                c.array(n, 1, Ty::I32, false, "CELL_TYPES")?;
            }
            b"POINT_DATA" => {
                let n = c.count("the number of POINT_DATA values")?;
                let Some(points) = points else { return Err(c.error("POINT_DATA before POINTS")) };
                if n != points {
                    return Err(c.error(format!("POINT_DATA {n} for {points} points")));
                }
                section = Section::Points(n);
            }
            b"CELL_DATA" => section = Section::Cells(c.count("the number of CELL_DATA values")?),
            b"METADATA" => c.skip_metadata(),
            b"FIELD" => {
                c.expect("the FIELD name")?;
                let arrays = c.count("the number of FIELD arrays")?;
                for _ in 0..arrays {
                    if c.peek().is_some_and(|t| t.eq_ignore_ascii_case(b"METADATA")) {
                        c.token();
                        c.skip_metadata();
                    }
                    let name = decode_name(c.expect("a FIELD array name")?);
                    if name == "NULL_ARRAY" {
                        continue;
                    }
                    let components = c.count(&format!("the number of components of FIELD array '{name}'"))?;
                    let tuples = c.count(&format!("the number of tuples of FIELD array '{name}'"))?;
                    let what = format!("FIELD array '{name}'");
                    let ty = c.ty(&what)?;
                    c.data_begins();
                    let role = match section {
                        Section::Points(n) => {
                            if tuples != n {
                                return Err(c.error(format!("{what} has {tuples} tuples for {n} points")));
                            }
                            if ty == Ty::Bit {
                                None
                            } else {
                                taken.take(&name, components)
                            }
                        }
                        _ => None,
                    };
                    let values = c.array(tuples, components, ty, role.is_some(), &what)?;
                    if let Some(role) = role {
                        store(&mut raw, role, name, values);
                    }
                }
            }
            b"SCALARS"
            | b"COLOR_SCALARS"
            | b"LOOKUP_TABLE"
            | b"VECTORS"
            | b"NORMALS"
            | b"TEXTURE_COORDINATES"
            | b"TENSORS"
            | b"TENSORS6" => {
                let n = match section {
                    Section::Points(n) | Section::Cells(n) => n,
                    Section::Dataset => {
                        return Err(c.error(format!("{keyword_text} outside POINT_DATA and CELL_DATA")));
                    }
                };
                let name = decode_name(c.expect(&format!("the {keyword_text} name"))?);
                let what = format!("{keyword_text} '{name}'");
                let (tuples, components, ty) = match keyword.as_slice() {
                    b"SCALARS" => {
                        let ty = c.ty(&what)?;
                        let rest = c.rest_of_line();
                        let rest = String::from_utf8_lossy(rest);
                        let components = match rest.split_whitespace().next() {
                            None => 1,
                            Some(t) => t
                                .parse::<usize>()
                                .ok()
                                .filter(|&n| n >= 1)
                                .ok_or_else(|| c.error(format!("{what}: '{t}' is not a number of components")))?,
                        };
                        if c.peek().is_some_and(|t| t.eq_ignore_ascii_case(b"LOOKUP_TABLE")) {
                            c.token();
                            c.expect("the lookup table's name")?;
                            c.data_begins();
                        }
                        (n, components, ty)
                    }
                    b"COLOR_SCALARS" => {
                        let components = c.count(&format!("the number of components of {what}"))?;
                        c.data_begins();
                        (n, components, if c.binary { Ty::U8 } else { Ty::F32 })
                    }
                    b"LOOKUP_TABLE" => {
                        let size = c.count(&format!("the size of {what}"))?;
                        c.data_begins();
                        (size, 4, if c.binary { Ty::U8 } else { Ty::F32 })
                    }
                    b"TEXTURE_COORDINATES" => {
                        let components = c.count(&format!("the dimension of {what}"))?;
                        let ty = c.ty(&what)?;
                        c.data_begins();
                        (n, components, ty)
                    }
                    _ => {
                        let ty = c.ty(&what)?;
                        c.data_begins();
                        let components = match keyword.as_slice() {
                            b"TENSORS" => 9,
                            b"TENSORS6" => 6,
                            _ => 3,
                        };
                        (n, components, ty)
                    }
                };
                let role = match (keyword.as_slice(), section) {
                    (b"SCALARS", Section::Points(_)) if ty != Ty::Bit => taken.take(&name, components),
                    _ => None,
                };
                let values = c.array(tuples, components, ty, role.is_some(), &what)?;
                if let Some(role) = role {
                    store(&mut raw, role, name, values);
                }
            }
            _ => return Err(c.error(format!("unknown keyword '{keyword_text}'"))),
        }
    }
    if points.is_none() {
        return Err(GeometryError::format(path, None, "no POINTS section"));
    }
    Ok(raw)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse_bytes(bytes: &[u8]) -> Result<RawParticles, GeometryError> {
        parse(bytes, Path::new("p.vtk"))
    }

    fn error(bytes: &[u8]) -> String {
        parse_bytes(bytes).unwrap_err().to_string()
    }

    const ASCII: &str = "\
# vtk DataFile Version 3.0
three particles
ASCII
DATASET POLYDATA
POINTS 3 float
0 0 0 1 0 0
0 1 0.5
VERTICES 3 6
1 0 1 1 1 2
POINT_DATA 3
SCALARS density double
LOOKUP_TABLE default
1.5 2.5 3.5
VECTORS velocity float
0 0 0 1 1 1 2 2 2
FIELD FieldData 2
hsml 1 3 float
0.1 0.2 0.3
mass 1 3 int
4 5 6
";

    #[test]
    fn ascii_polydata_with_a_scalar_and_fields() {
        let p = parse_bytes(ASCII.as_bytes()).unwrap();
        assert_eq!(p.positions, vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.5]]);
        assert_eq!(p.values, vec![1.5, 2.5, 3.5]);
        assert_eq!(p.value_name, "density");
        assert_eq!(p.smoothing, vec![0.1, 0.2, 0.3]);
        assert_eq!(p.masses, vec![4.0, 5.0, 6.0]);
    }

    #[test]
    fn ascii_unstructured_grid_version_5() {
        let text = "\
# vtk DataFile Version 5.1
vtk output
ASCII
DATASET UNSTRUCTURED_GRID
FIELD FieldData 1
TIME 1 1 double
0.5
POINTS 2 double
1 2 3 4 5 6
METADATA
INFORMATION 0

CELLS 3 2
OFFSETS vtktypeint64
0 1 2
CONNECTIVITY vtktypeint64
0 1
CELL_TYPES 2
1
1
CELL_DATA 2
SCALARS cell_id int 1
LOOKUP_TABLE default
7 8
POINT_DATA 2
SCALARS radius float
LOOKUP_TABLE default
0.25 0.5
SCALARS pressure%20kPa float 1
LOOKUP_TABLE default
10 20
SCALARS other float
LOOKUP_TABLE default
30 40
";
        let p = parse_bytes(text.as_bytes()).unwrap();
        assert_eq!(p.positions, vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
        assert_eq!(p.smoothing, vec![0.25, 0.5]);
        assert_eq!(p.values, vec![10.0, 20.0]);
        assert_eq!(p.value_name, "pressure kPa");
    }

    /// A binary POLYDATA file: 2 points (float), a VERTICES section, a `short` scalar and a vector.
    fn binary_file() -> Vec<u8> {
        let mut f = b"# vtk DataFile Version 3.0\nbinary\nBINARY\nDATASET POLYDATA\nPOINTS 2 float\n".to_vec();
        for v in [1.0f32, 2.0, 3.0, -4.0, 5.5, 6.0] {
            f.extend(v.to_be_bytes());
        }
        f.extend(b"\nVERTICES 1 3\n");
        for v in [2i32, 0, 1] {
            f.extend(v.to_be_bytes());
        }
        f.extend(b"\nPOINT_DATA 2\nSCALARS temperature short\nLOOKUP_TABLE default\n");
        for v in [-300i16, 10] {
            f.extend(v.to_be_bytes());
        }
        f.extend(b"\nNORMALS n double\n");
        for v in [0.0f64, 0.0, 1.0, 0.0, 1.0, 0.0] {
            f.extend(v.to_be_bytes());
        }
        f.extend(b"\nSCALARS h double\nLOOKUP_TABLE default\n");
        for v in [0.5f64, 0.75] {
            f.extend(v.to_be_bytes());
        }
        f.push(b'\n');
        f
    }

    #[test]
    fn binary_polydata_with_a_scalar() {
        let p = parse_bytes(&binary_file()).unwrap();
        assert_eq!(p.positions, vec![[1.0, 2.0, 3.0], [-4.0, 5.5, 6.0]]);
        assert_eq!(p.values, vec![-300.0, 10.0]);
        assert_eq!(p.value_name, "temperature");
        assert_eq!(p.smoothing, vec![0.5, 0.75]);
        assert!(p.masses.is_empty());
    }

    #[test]
    fn binary_version_5_cells() {
        let mut f = b"# vtk DataFile Version 5.1\nb\nBINARY\nDATASET POLYDATA\nPOINTS 1 double\n".to_vec();
        for v in [1.0f64, 2.0, 3.0] {
            f.extend(v.to_be_bytes());
        }
        f.extend(b"\nVERTICES 2 1\nOFFSETS vtktypeint64\n");
        for v in [0i64, 1] {
            f.extend(v.to_be_bytes());
        }
        f.extend(b"\nCONNECTIVITY vtktypeint64\n");
        f.extend(0i64.to_be_bytes());
        f.extend(b"\nPOINT_DATA 1\nFIELD FieldData 1\nm 1 1 unsigned_char\n\x07\n");
        let p = parse_bytes(&f).unwrap();
        assert_eq!(p.positions, vec![[1.0, 2.0, 3.0]]);
        assert_eq!(p.masses, vec![7.0]);
    }

    #[test]
    fn truncations_and_bad_counts_are_named() {
        let huge =
            b"# vtk DataFile Version 3.0\nt\nBINARY\nDATASET POLYDATA\nPOINTS 1000000 float\n\0\0\0\0\0\0\0\0\0\0\0\0";
        assert_eq!(error(huge), "p.vtk: POINTS (1000000 points) announces 1000000 × 3 values but only 12 bytes follow");
        let ascii = "# vtk DataFile Version 3.0\nt\nASCII\nDATASET POLYDATA\nPOINTS 1000000 float\n0 0 0\n";
        assert_eq!(
            error(ascii.as_bytes()),
            "p.vtk line 5: POINTS (1000000 points) announces 1000000 × 3 values but only 7 bytes follow"
        );
        let short = "# vtk DataFile Version 3.0\nt\nASCII\nDATASET POLYDATA\nPOINTS 2 float\n0 0 0 1 1\n";
        assert_eq!(
            error(short.as_bytes()),
            "p.vtk line 6: POINTS (2 points) announces 2 × 3 values but the file ends after 5"
        );
        let word = "# vtk DataFile Version 3.0\nt\nASCII\nDATASET POLYDATA\nPOINTS 2 float\n0 0 0\nVERTICES 1 2\n1 0\n";
        assert_eq!(
            error(word.as_bytes()),
            "p.vtk line 7: POINTS (2 points): 'VERTICES' is not a number (value 4 of 6)"
        );
        let overflow =
            format!("# vtk DataFile Version 3.0\nt\nBINARY\nDATASET POLYDATA\nPOINTS {} double\n", usize::MAX / 2);
        assert!(error(overflow.as_bytes()).contains("too many"));
        let mut mismatch = ASCII.replace("POINT_DATA 3", "POINT_DATA 4");
        assert_eq!(error(mismatch.as_bytes()), "p.vtk line 10: POINT_DATA 4 for 3 points");
        mismatch = ASCII.replace("hsml 1 3 float", "hsml 1 2 float");
        assert_eq!(error(mismatch.as_bytes()), "p.vtk line 17: FIELD array 'hsml' has 2 tuples for 3 points");
        assert!(error(b"hello\n").contains("not a legacy VTK file"));
        assert!(error(b"# vtk DataFile Version 3.0\nt\nUTF8\n").contains("ASCII or BINARY, not 'UTF8'"));
        assert!(error(b"# vtk DataFile Version 3.0\nt\nASCII\nDATASET STRUCTURED_POINTS\n").contains("unsupported"));
        assert_eq!(
            error(b"# vtk DataFile Version 3.0\nt\nASCII\nDATASET POLYDATA\nPOINTS 1 quad\n"),
            "p.vtk line 5: unknown data type 'quad' for POINTS"
        );
        assert_eq!(
            error(b"# vtk DataFile Version 3.0\nt\nASCII\nDATASET POLYDATA\nPOINTS -1 float\n"),
            "p.vtk line 5: the number of POINTS '-1' is not a count"
        );
        assert_eq!(error(b"# vtk DataFile Version 3.0\nt\nASCII\nDATASET POLYDATA\n"), "p.vtk: no POINTS section");
        assert_eq!(
            error(b"# vtk DataFile Version 3.0\nt\nASCII\nDATASET POLYDATA\nPOINTS 0 float\nBLOB\n"),
            "p.vtk line 6: unknown keyword 'BLOB'"
        );
        // Every truncation of a valid binary file fails cleanly or parses.
        let file = binary_file();
        for end in 0..file.len() {
            let _ = parse_bytes(&file[..end]);
        }
    }
}
