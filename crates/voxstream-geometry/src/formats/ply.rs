//! PLY, the Stanford polygon format (<http://paulbourke.net/dataformats/ply/>): `format ascii 1.0`,
//! `binary_little_endian 1.0` and `binary_big_endian 1.0`; every scalar type under both its names (`char`/`int8`,
//! `uchar`/`uint8`, `short`/`int16`, `ushort`/`uint16`, `int`/`int32`, `uint`/`uint32`, `float`/`float32`,
//! `double`/`float64`); list properties with any count and item types; `comment` and `obj_info` lines.
//!
//! A file whose `face` element holds at least one face is a mesh: the `vertex` element's `x y z`, and the face
//! element's `vertex_indices` (or `vertex_index`) list with polygons into triangles by [`super::polygon::triangulate`]. Otherwise
//! the vertices are particles: `x y z`; `radius`, `h`, `smoothing_length` or `hsml` as the smoothing length; `mass`
//! or `m` as the mass; the first other scalar property (normals `nx ny nz`, colours `red green blue alpha` and
//! texture coordinates `u v s t` excepted) as the value. Every other element (edges, materials, a scanner's range
//! grid …) and every other property is read past, list properties included, in ASCII and binary bodies alike.
//!
//! Not read: triangle strips (a `tristrips` element is refused rather than shown as points), colours, normals and
//! texture coordinates; format versions other than 1.0.
//!
//! Hand-written rather than taken from a crate: the header is a handful of lines, and reading it here is what lets
//! each element count be checked against the bytes that follow the header before anything is allocated for it
//! (count × the element's smallest size in a binary body, count × its fewest words in an ASCII one), and every
//! error name the element, its number and, for ASCII, the line.

use std::path::Path;

use super::polygon::triangulate;
use super::words::shown;
use super::RawGeometry;
use crate::error::GeometryError;
use crate::particles::RawParticles;
use crate::triangle_mesh::RawMesh;

/// Parses a PLY file: a mesh if its `face` element holds faces, otherwise its vertices as particles.
pub fn parse(bytes: &[u8], path: &Path) -> Result<RawGeometry, GeometryError> {
    let header = parse_header(bytes, path)?;
    let body = bytes.get(header.body_start..).unwrap_or_default();
    let plan = Plan::new(&header, path)?;
    check_counts(&header, body.len(), path)?;
    let len = body.len();
    match header.encoding {
        Encoding::Ascii => {
            read_body(&mut AsciiBody { bytes: body, pos: 0, line: header.body_line }, len, &header, plan, path)
        }
        Encoding::BinaryLittle => {
            read_body(&mut BinaryBody { bytes: body, pos: 0, big: false }, len, &header, plan, path)
        }
        Encoding::BinaryBig => read_body(&mut BinaryBody { bytes: body, pos: 0, big: true }, len, &header, plan, path),
    }
}

/// The most header bytes [`PlyPointStream::open`] reads looking for `end_header`.
const STREAM_HEADER_BYTES: u64 = 1 << 20;

/// About this many body bytes are read and decoded at a time by [`PlyPointStream::for_each_chunk`].
const STREAM_CHUNK_BYTES: usize = 4 << 20;

/// A binary PLY point file read in chunks, for particle sets larger than memory: only its header is held, and each
/// pass over its vertices reads them a few megabytes at a time.
///
/// Takes what [`parse`] reads as particles, in binary bodies whose vertex element has only scalar properties and
/// whose elements before it (if any) too; anything else is refused with a line saying so.
#[derive(Clone, Debug)]
pub struct PlyPointStream {
    path: std::path::PathBuf,
    big: bool,
    /// Byte offset of the first vertex.
    start: u64,
    /// The vertex element's properties: type and role.
    layout: Vec<(Scalar, Role)>,
    record_bytes: usize,
    count: u64,
    value_name: String,
}

impl PlyPointStream {
    /// Reads and checks the header of `path`, and that the file holds every vertex it announces.
    pub fn open(path: &Path) -> Result<PlyPointStream, GeometryError> {
        use std::io::Read;
        let io = |error| GeometryError::Io { path: path.to_path_buf(), error };
        let unsupported = |message: String| GeometryError::Unsupported { path: path.to_path_buf(), message };
        let file = std::fs::File::open(path).map_err(io)?;
        let file_len = file.metadata().map_err(io)?.len();
        let mut head = Vec::new();
        file.take(STREAM_HEADER_BYTES).read_to_end(&mut head).map_err(io)?;
        let header = parse_header(&head, path)?;
        let plan = Plan::new(&header, path)?;
        if plan.mesh {
            return Err(unsupported("the file holds faces (a mesh); only point files are read out of core".into()));
        }
        let big = match header.encoding {
            Encoding::Ascii => {
                return Err(unsupported(
                    "an ASCII PLY body is read whole; to read it out of core, write it as binary_little_endian".into(),
                ))
            }
            Encoding::BinaryLittle => false,
            Encoding::BinaryBig => true,
        };
        let mut start = header.body_start as u64;
        let mut vertex = None;
        for (element, roles) in header.elements.iter().zip(&plan.roles) {
            let mut record = 0u64;
            let mut layout = Vec::new();
            for (property, role) in element.properties.iter().zip(roles) {
                match property.kind {
                    Kind::Scalar(ty) => {
                        record += ty.size();
                        layout.push((ty, *role));
                    }
                    Kind::List { .. } if element.count == 0 => {}
                    Kind::List { .. } => {
                        return Err(unsupported(format!(
                            "the '{}' element's list property '{}' gives its records varying sizes; out of core reads \
                             fixed-size vertex records",
                            shown(&element.name),
                            shown(&property.name)
                        )))
                    }
                }
            }
            if element.name == "vertex" {
                vertex = Some((element, layout, record));
                break;
            }
            start = element.count.checked_mul(record).and_then(|n| n.checked_add(start)).unwrap_or(u64::MAX);
        }
        let Some((element, layout, record)) = vertex else {
            return Err(GeometryError::format(path, None, "the header declares no 'vertex' element"));
        };
        let end = element.count.checked_mul(record).and_then(|n| n.checked_add(start)).unwrap_or(u64::MAX);
        if end > file_len {
            return Err(GeometryError::format(
                path,
                Some(element.line),
                format!(
                    "header announces {} vertices ({record} bytes each, from byte {start}) but the file has {file_len} bytes",
                    element.count
                ),
            ));
        }
        Ok(PlyPointStream {
            path: path.to_path_buf(),
            big,
            start,
            record_bytes: record as usize,
            layout,
            count: element.count,
            value_name: plan.value_name,
        })
    }

    /// Number of particles.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// The name of the value property (`""` if none).
    pub fn value_name(&self) -> &str {
        &self.value_name
    }

    /// Whether the vertices carry a smoothing length, a mass and a value.
    pub fn columns(&self) -> [bool; 3] {
        [Role::Smoothing, Role::Mass, Role::Value].map(|r| self.layout.iter().any(|(_, role)| *role == r))
    }

    /// Calls `f` with consecutive runs of the particles, each with the index of its first, in file order; stops at
    /// the first error, from the file or from `f`.
    pub fn for_each_chunk(
        &self,
        f: &mut dyn FnMut(u64, &RawParticles) -> Result<(), GeometryError>,
    ) -> Result<(), GeometryError> {
        use std::io::{Read, Seek, SeekFrom};
        let io = |error| GeometryError::Io { path: self.path.clone(), error };
        let mut file = std::fs::File::open(&self.path).map_err(io)?;
        file.seek(SeekFrom::Start(self.start)).map_err(io)?;
        let mut reader = std::io::BufReader::new(file);
        let per_chunk = (STREAM_CHUNK_BYTES / self.record_bytes.max(1)).max(1) as u64;
        let [smoothing, masses, values] = self.columns();
        let mut bytes = Vec::new();
        let mut chunk = RawParticles { value_name: self.value_name.clone(), ..RawParticles::default() };
        let mut first = 0u64;
        while first < self.count {
            let n = per_chunk.min(self.count - first) as usize;
            bytes.resize(n * self.record_bytes, 0);
            reader.read_exact(&mut bytes).map_err(|error| {
                GeometryError::format(&self.path, None, format!("the vertices end early, after {first} ({error})"))
            })?;
            chunk.positions.clear();
            chunk.smoothing.clear();
            chunk.masses.clear();
            chunk.values.clear();
            let mut body = BinaryBody { bytes: &bytes, pos: 0, big: self.big };
            for _ in 0..n {
                let mut xyz = [0.0f64; 3];
                for &(ty, role) in &self.layout {
                    // The buffer holds n whole records: a read cannot miss.
                    let v = body.scalar(ty).unwrap_or(0.0);
                    match role {
                        Role::X => xyz[0] = v,
                        Role::Y => xyz[1] = v,
                        Role::Z => xyz[2] = v,
                        Role::Smoothing if smoothing => chunk.smoothing.push(v as f32),
                        Role::Mass if masses => chunk.masses.push(v as f32),
                        Role::Value if values => chunk.values.push(v as f32),
                        _ => {}
                    }
                }
                chunk.positions.push(xyz);
            }
            f(first, &chunk)?;
            first += n as u64;
        }
        Ok(())
    }
}

/// How the body is stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Encoding {
    Ascii,
    BinaryLittle,
    BinaryBig,
}

/// A PLY scalar type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn from_name(name: &str) -> Option<Scalar> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    /// Bytes in a binary body.
    fn size(self) -> u64 {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
}

/// A property: one scalar, or a list (its length, then that many items).
#[derive(Clone, Copy, Debug)]
enum Kind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Debug)]
struct Property {
    name: String,
    kind: Kind,
}

#[derive(Debug)]
struct Element {
    name: String,
    count: u64,
    properties: Vec<Property>,
    /// The header line declaring it.
    line: u64,
}

impl Element {
    /// "vertex 12", "face 3", "'edge' element 7".
    fn singular(&self) -> String {
        match self.name.as_str() {
            "vertex" | "face" => self.name.clone(),
            other => format!("'{other}' element"),
        }
    }

    /// "vertices", "faces", "'edge' elements".
    fn plural(&self) -> String {
        match self.name.as_str() {
            "vertex" => "vertices".into(),
            "face" => "faces".into(),
            other => format!("'{other}' elements"),
        }
    }
}

#[derive(Debug)]
struct Header {
    encoding: Encoding,
    elements: Vec<Element>,
    /// Byte offset of the body (just after the `end_header` line).
    body_start: usize,
    /// Line number of the body's first line.
    body_line: u64,
}

/// The points a PLY point file (`.ply`, or `.ply.gz` decompressed only as far as its header) declares, read from its
/// header alone, before anything is allocated for them: `None` for a mesh, an unreadable file or a header this
/// reader refuses (reading the file then names the problem).
pub fn declared_points(path: &Path) -> Option<u64> {
    use std::io::Read;
    let file = std::fs::File::open(path).ok()?;
    let file_len = file.metadata().ok()?.len();
    let gz = path.to_string_lossy().to_lowercase().ends_with(".gz");
    let mut head = Vec::new();
    if gz {
        let decoder = flate2::read::MultiGzDecoder::new(std::io::BufReader::new(file));
        // A header shorter than the limit ends the read early; a gzip error leaves what was decoded before it.
        let _ = decoder.take(STREAM_HEADER_BYTES).read_to_end(&mut head);
    } else {
        file.take(STREAM_HEADER_BYTES).read_to_end(&mut head).ok()?;
    }
    let header = parse_header(&head, path).ok()?;
    let plan = Plan::new(&header, path).ok()?;
    if plan.mesh {
        return None;
    }
    let vertex = header.elements.iter().find(|e| e.name == "vertex")?;
    // An uncompressed file too short for its count is the reader's to name (a truncated body, not a budget).
    let least_bytes: u64 = vertex
        .properties
        .iter()
        .map(|p| match (&header.encoding, &p.kind) {
            (Encoding::Ascii, _) => 2,
            (_, Kind::Scalar(ty)) => ty.size(),
            (_, Kind::List { .. }) => 1,
        })
        .sum();
    let body = file_len.saturating_sub(header.body_start as u64);
    if !gz && vertex.count.saturating_mul(least_bytes) > body {
        return None;
    }
    Some(vertex.count)
}

/// At most this many characters of a file's word are quoted in an error.
fn parse_header(bytes: &[u8], path: &Path) -> Result<Header, GeometryError> {
    let at = |line: u64, message: String| GeometryError::format(path, Some(line), message);
    let first_line = bytes.split(|&b| b == b'\n').next().unwrap_or_default();
    if first_line.strip_suffix(b"\r").unwrap_or(first_line) != b"ply" {
        return Err(GeometryError::format(path, Some(1), "not a PLY file (it does not begin with a 'ply' line)"));
    }
    let mut pos = 0usize;
    let mut number = 0u64;
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        let rest = bytes.get(pos..).unwrap_or_default();
        let Some(end) = rest.iter().position(|&b| b == b'\n') else {
            return Err(GeometryError::format(path, None, "the header has no 'end_header' line"));
        };
        let line = rest.get(..end).unwrap_or_default();
        pos = pos.saturating_add(end + 1);
        number += 1;
        if number == 1 {
            continue;
        }
        let text = String::from_utf8_lossy(line);
        let words: Vec<&str> = text.split_whitespace().collect();
        match words.as_slice() {
            [] | ["comment", ..] | ["obj_info", ..] => {}
            ["end_header"] => break,
            ["format", name, version @ ..] => {
                encoding = Some(match *name {
                    "ascii" => Encoding::Ascii,
                    "binary_little_endian" => Encoding::BinaryLittle,
                    "binary_big_endian" => Encoding::BinaryBig,
                    other => return Err(at(number, format!("unknown PLY format '{}'", shown(other)))),
                });
                if let Some(version) = version.first().filter(|v| !matches!(**v, "1.0" | "1")) {
                    return Err(GeometryError::Unsupported {
                        path: path.to_path_buf(),
                        message: format!("PLY version {} (only 1.0)", shown(version)),
                    });
                }
            }
            ["element", name, count] => {
                let count = count
                    .parse::<u64>()
                    .map_err(|_| at(number, format!("element '{}': '{}' is not a count", shown(name), shown(count))))?;
                if elements.iter().any(|e| e.name == *name) {
                    return Err(at(number, format!("element '{}' is declared twice", shown(name))));
                }
                elements.push(Element { name: (*name).to_string(), count, properties: Vec::new(), line: number });
            }
            ["property", rest @ ..] => {
                let Some(element) = elements.last_mut() else {
                    return Err(at(number, "a property before any element".into()));
                };
                let scalar = |name: &str| {
                    Scalar::from_name(name).ok_or_else(|| at(number, format!("unknown PLY type '{}'", shown(name))))
                };
                let (kind, name) = match rest {
                    ["list", count, item, name] => {
                        let count = scalar(count)?;
                        if matches!(count, Scalar::F32 | Scalar::F64) {
                            return Err(at(number, format!("list '{}' has a floating-point length type", shown(name))));
                        }
                        (Kind::List { count, item: scalar(item)? }, name)
                    }
                    [ty, name] if *ty != "list" => (Kind::Scalar(scalar(ty)?), name),
                    _ => return Err(at(number, format!("malformed property line '{}'", shown(&text)))),
                };
                element.properties.push(Property { name: (*name).to_string(), kind });
            }
            _ => return Err(at(number, format!("unknown header line '{}'", shown(text.trim())))),
        }
    }
    let encoding = encoding.ok_or_else(|| GeometryError::format(path, None, "the header has no 'format' line"))?;
    Ok(Header { encoding, elements, body_start: pos, body_line: number + 1 })
}

/// What a property becomes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Role {
    X,
    Y,
    Z,
    Smoothing,
    Mass,
    Value,
    /// The face element's vertex index list.
    Indices,
    Skip,
}

/// The reading plan: whether the file is a mesh, and each element's properties' roles.
struct Plan {
    mesh: bool,
    roles: Vec<Vec<Role>>,
    value_name: String,
}

impl Plan {
    fn new(header: &Header, path: &Path) -> Result<Plan, GeometryError> {
        let find = |name: &str| header.elements.iter().find(|e| e.name == name);
        let vertex = find("vertex")
            .ok_or_else(|| GeometryError::format(path, None, "the header declares no 'vertex' element"))?;
        let face = find("face").filter(|f| f.count > 0);
        let mesh = face.is_some();
        if !mesh {
            if let Some(strips) = find("tristrips").filter(|s| s.count > 0) {
                return Err(GeometryError::Unsupported {
                    path: path.to_path_buf(),
                    message: format!("{} triangle strips ('tristrips'): only 'face' lists are read", strips.count),
                });
            }
        }
        for axis in ["x", "y", "z"] {
            if !vertex.properties.iter().any(|p| p.name == axis && matches!(p.kind, Kind::Scalar(_))) {
                return Err(GeometryError::format(
                    path,
                    Some(vertex.line),
                    format!("the vertex element has no scalar '{axis}' property"),
                ));
            }
        }
        if let Some(face) = face {
            let lists = |p: &&Property| matches!(p.kind, Kind::List { .. });
            if !face
                .properties
                .iter()
                .filter(lists)
                .any(|p| matches!(p.name.as_str(), "vertex_indices" | "vertex_index"))
            {
                return Err(GeometryError::format(
                    path,
                    Some(face.line),
                    "the face element has no 'vertex_indices' (or 'vertex_index') list",
                ));
            }
        }
        let mut value_name = String::new();
        let roles = header
            .elements
            .iter()
            .map(|element| {
                let mut taken = Vec::new();
                element
                    .properties
                    .iter()
                    .map(|p| {
                        let role = match (element.name.as_str(), p.kind) {
                            ("vertex", Kind::Scalar(_)) => match p.name.as_str() {
                                "x" => Role::X,
                                "y" => Role::Y,
                                "z" => Role::Z,
                                _ if mesh => Role::Skip,
                                "radius" | "h" | "smoothing_length" | "hsml" => Role::Smoothing,
                                "mass" | "m" => Role::Mass,
                                "nx" | "ny" | "nz" | "red" | "green" | "blue" | "alpha" | "u" | "v" | "s" | "t" => {
                                    Role::Skip
                                }
                                name => {
                                    if value_name.is_empty() && !taken.contains(&Role::Value) {
                                        value_name = name.to_string();
                                    }
                                    Role::Value
                                }
                            },
                            ("face", Kind::List { .. })
                                if matches!(p.name.as_str(), "vertex_indices" | "vertex_index") =>
                            {
                                Role::Indices
                            }
                            _ => Role::Skip,
                        };
                        // Only the first property of each role is read (a repeated `x`, a second smoothing name …).
                        if role != Role::Skip && taken.contains(&role) {
                            return Role::Skip;
                        }
                        taken.push(role);
                        role
                    })
                    .collect()
            })
            .collect();
        Ok(Plan { mesh, roles, value_name })
    }

    fn vertex_has(&self, header: &Header, role: Role) -> bool {
        header.elements.iter().zip(&self.roles).any(|(e, roles)| e.name == "vertex" && roles.contains(&role))
    }
}

/// Checks each element count against the body's length before anything is allocated: in a binary body an element
/// takes at least its scalars' sizes plus its lists' length fields, in an ASCII body at least that many words, each a
/// character and a separator.
fn check_counts(header: &Header, body_len: usize, path: &Path) -> Result<(), GeometryError> {
    let binary = header.encoding != Encoding::Ascii;
    let capacity = if binary { body_len as u64 } else { (body_len as u64).saturating_add(1) / 2 };
    let mut needed = 0u64;
    for element in &header.elements {
        let least: u64 = element
            .properties
            .iter()
            .map(|p| match (p.kind, binary) {
                (Kind::Scalar(ty), true) => ty.size(),
                (Kind::List { count, .. }, true) => count.size(),
                (_, false) => 1,
            })
            .sum();
        needed = element.count.checked_mul(least).and_then(|n| n.checked_add(needed)).unwrap_or(u64::MAX);
        if needed > capacity {
            return Err(GeometryError::format(
                path,
                Some(element.line),
                format!(
                    "header announces {} {} but only {body_len} bytes follow the header",
                    element.count,
                    element.plural()
                ),
            ));
        }
    }
    Ok(())
}

/// Why a value could not be read.
enum Miss {
    /// The body ended.
    End,
    /// An ASCII word that is not a number.
    Bad(String),
}

/// The values of a body, in order.
trait Body {
    /// The next value, of type `ty`.
    fn scalar(&mut self, ty: Scalar) -> Result<f64, Miss>;
    /// Reads past `count` values of type `ty`.
    fn skip(&mut self, ty: Scalar, count: u64) -> Result<(), Miss>;
    /// The line being read (ASCII bodies), for errors.
    fn line(&self) -> Option<u64>;
}

/// An ASCII body: values are words separated by white space.
struct AsciiBody<'a> {
    bytes: &'a [u8],
    pos: usize,
    line: u64,
}

impl<'a> AsciiBody<'a> {
    fn word(&mut self) -> Option<&'a [u8]> {
        while let Some(&b) = self.bytes.get(self.pos).filter(|b| b.is_ascii_whitespace()) {
            self.line += u64::from(b == b'\n');
            self.pos += 1;
        }
        let start = self.pos;
        while self.bytes.get(self.pos).is_some_and(|b| !b.is_ascii_whitespace()) {
            self.pos += 1;
        }
        self.bytes.get(start..self.pos).filter(|w| !w.is_empty())
    }
}

impl Body for AsciiBody<'_> {
    fn scalar(&mut self, _ty: Scalar) -> Result<f64, Miss> {
        let word = self.word().ok_or(Miss::End)?;
        std::str::from_utf8(word)
            .ok()
            .and_then(|w| w.parse::<f64>().ok())
            .ok_or_else(|| Miss::Bad(shown(&String::from_utf8_lossy(word))))
    }

    fn skip(&mut self, _ty: Scalar, count: u64) -> Result<(), Miss> {
        for _ in 0..count {
            self.word().ok_or(Miss::End)?;
        }
        Ok(())
    }

    fn line(&self) -> Option<u64> {
        Some(self.line)
    }
}

/// A binary body, little- or big-endian.
struct BinaryBody<'a> {
    bytes: &'a [u8],
    pos: usize,
    big: bool,
}

impl BinaryBody<'_> {
    fn take<const N: usize>(&mut self) -> Result<[u8; N], Miss> {
        let chunk = self.bytes.get(self.pos..).and_then(|rest| rest.first_chunk::<N>()).ok_or(Miss::End)?;
        self.pos += N;
        Ok(*chunk)
    }
}

impl Body for BinaryBody<'_> {
    fn scalar(&mut self, ty: Scalar) -> Result<f64, Miss> {
        macro_rules! read {
            ($t:ty, $n:literal) => {{
                let b = self.take::<$n>()?;
                f64::from(if self.big { <$t>::from_be_bytes(b) } else { <$t>::from_le_bytes(b) })
            }};
        }
        Ok(match ty {
            Scalar::I8 => read!(i8, 1),
            Scalar::U8 => read!(u8, 1),
            Scalar::I16 => read!(i16, 2),
            Scalar::U16 => read!(u16, 2),
            Scalar::I32 => read!(i32, 4),
            Scalar::U32 => read!(u32, 4),
            Scalar::F32 => read!(f32, 4),
            Scalar::F64 => read!(f64, 8),
        })
    }

    fn skip(&mut self, ty: Scalar, count: u64) -> Result<(), Miss> {
        let left = self.bytes.len().saturating_sub(self.pos) as u64;
        match count.checked_mul(ty.size()) {
            Some(n) if n <= left => {
                self.pos += n as usize;
                Ok(())
            }
            _ => Err(Miss::End),
        }
    }

    fn line(&self) -> Option<u64> {
        None
    }
}

/// Reads every element of the body as `plan` says.
fn read_body(
    body: &mut impl Body,
    body_len: usize,
    header: &Header,
    plan: Plan,
    path: &Path,
) -> Result<RawGeometry, GeometryError> {
    let vertex_count = header.elements.iter().find(|e| e.name == "vertex").map_or(0, |e| e.count) as usize;
    let face_count = header.elements.iter().find(|e| e.name == "face").map_or(0, |e| e.count) as usize;
    let column = |role| if !plan.mesh && plan.vertex_has(header, role) { vertex_count } else { 0 };
    let mut mesh = RawMesh {
        positions: Vec::with_capacity(if plan.mesh { vertex_count } else { 0 }),
        // A valid face takes at least 4 bytes (a length and 3 one-byte indices), or 4 words.
        triangles: Vec::with_capacity(face_count.min(body_len / 4)),
    };
    // One face's corners (each read from the body: bounded by the file).
    let mut corners: Vec<u32> = Vec::new();
    let mut particles = RawParticles {
        positions: Vec::with_capacity(if plan.mesh { 0 } else { vertex_count }),
        smoothing: Vec::with_capacity(column(Role::Smoothing)),
        masses: Vec::with_capacity(column(Role::Mass)),
        values: Vec::with_capacity(column(Role::Value)),
        value_name: plan.value_name.clone(),
    };
    for (element, roles) in header.elements.iter().zip(&plan.roles) {
        if element.properties.is_empty() {
            continue;
        }
        for index in 0..element.count {
            let fail = |body: &dyn Body, message: String| GeometryError::format(path, body.line(), message);
            let missed = |body: &dyn Body, miss: Miss| match miss {
                Miss::End => fail(
                    body,
                    format!("header announces {} {} but the file ends after {index}", element.count, element.plural()),
                ),
                Miss::Bad(word) => fail(body, format!("{} {index}: '{word}' is not a number", element.singular())),
            };
            let mut xyz = [0.0f64; 3];
            for (property, role) in element.properties.iter().zip(roles) {
                match property.kind {
                    Kind::Scalar(ty) => {
                        let v = body.scalar(ty).map_err(|m| missed(body, m))?;
                        match role {
                            Role::X => xyz[0] = v,
                            Role::Y => xyz[1] = v,
                            Role::Z => xyz[2] = v,
                            Role::Smoothing => particles.smoothing.push(v as f32),
                            Role::Mass => particles.masses.push(v as f32),
                            Role::Value => particles.values.push(v as f32),
                            Role::Indices | Role::Skip => {}
                        }
                    }
                    Kind::List { count, item } => {
                        let length = body.scalar(count).map_err(|m| missed(body, m))?;
                        if !(length >= 0.0 && length.fract() == 0.0) {
                            return Err(fail(
                                body,
                                format!("{} {index}: list length {length} is not a count", element.singular()),
                            ));
                        }
                        let length = length as u64;
                        if *role != Role::Indices {
                            body.skip(item, length).map_err(|m| missed(body, m))?;
                            continue;
                        }
                        if length < 3 {
                            return Err(fail(
                                body,
                                format!("face {index} uses {length} vertices: a face needs at least 3"),
                            ));
                        }
                        corners.clear();
                        for _ in 0..length {
                            let v = body.scalar(item).map_err(|m| missed(body, m))?;
                            corners.push(
                                vertex_index(v).map_err(|problem| {
                                    fail(body, format!("face {index} uses vertex {v}: {problem}"))
                                })?,
                            );
                        }
                        triangulate(&corners, &mut mesh.triangles);
                    }
                }
            }
            if element.name == "vertex" {
                if plan.mesh {
                    mesh.positions.push(xyz.map(|c| c as f32));
                } else {
                    particles.positions.push(xyz);
                }
            }
        }
    }
    Ok(if plan.mesh { RawGeometry::Mesh(mesh) } else { RawGeometry::Particles(particles) })
}

/// A vertex index read as a number, or what is wrong with it.
fn vertex_index(v: f64) -> Result<u32, &'static str> {
    if v.fract() != 0.0 {
        Err("vertex indices are whole numbers")
    } else if v < 0.0 {
        Err("vertex indices cannot be negative")
    } else if v > f64::from(u32::MAX) {
        Err("voxstream reads at most 2^32 vertices")
    } else {
        Ok(v as u32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn path() -> &'static Path {
        Path::new("test.ply")
    }

    fn mesh(bytes: &[u8]) -> RawMesh {
        match parse(bytes, path()).unwrap() {
            RawGeometry::Mesh(mesh) => mesh,
            other => panic!("expected a mesh, got {other:?}"),
        }
    }

    fn particles(bytes: &[u8]) -> RawParticles {
        match parse(bytes, path()).unwrap() {
            RawGeometry::Particles(p) => p,
            other => panic!("expected particles, got {other:?}"),
        }
    }

    fn error(bytes: &[u8]) -> String {
        parse(bytes, path()).unwrap_err().to_string()
    }

    /// A unit square (a quad) and a triangle over 5 vertices, with a skipped element holding lists.
    const ASCII_QUAD: &str = "ply\r\nformat ascii 1.0\ncomment made by hand\nobj_info nothing\n\
        element vertex 5\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\n\
        element material 2\nproperty list uchar float weights\nproperty int id\n\
        element face 2\nproperty list uchar int vertex_indices\nproperty uchar flags\nend_header\n\
        0 0 0 255\n1 0 0 255\n1 1 0 255\n0 1 0 255\n0 0 1 255\n\
        3 0.5 0.25 0.25 7\n0 8\n\
        4 0 1 2 3 9\n3 0 1 4 9\n";

    const QUAD_POSITIONS: [[f32; 3]; 5] =
        [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    const QUAD_TRIANGLES: [[u32; 3]; 3] = [[0, 1, 2], [0, 2, 3], [0, 1, 4]];

    /// The binary header and body of [`ASCII_QUAD`], in the byte order `put` writes.
    fn binary_quad(format: &str, be: bool) -> Vec<u8> {
        let mut out = format!(
            "ply\nformat {format} 1.0\nelement vertex 5\nproperty float32 x\nproperty float32 y\nproperty float32 z\n\
             property uint8 red\nelement material 2\nproperty list uint8 float32 weights\nproperty int32 id\n\
             element face 2\nproperty list uint8 int32 vertex_indices\nproperty uint8 flags\nend_header\n"
        )
        .into_bytes();
        let f = |out: &mut Vec<u8>, v: f32| out.extend(if be { v.to_be_bytes() } else { v.to_le_bytes() });
        let i = |out: &mut Vec<u8>, v: i32| out.extend(if be { v.to_be_bytes() } else { v.to_le_bytes() });
        for p in QUAD_POSITIONS {
            p.iter().for_each(|&c| f(&mut out, c));
            out.push(255);
        }
        out.push(3);
        [0.5, 0.25, 0.25].iter().for_each(|&w| f(&mut out, w));
        i(&mut out, 7);
        out.push(0);
        i(&mut out, 8);
        out.push(4);
        [0, 1, 2, 3].iter().for_each(|&v| i(&mut out, v));
        out.push(9);
        out.push(3);
        [0, 1, 4].iter().for_each(|&v| i(&mut out, v));
        out.push(9);
        out
    }

    #[test]
    fn ascii_mesh_fans_quads_and_skips_other_elements() {
        let mesh = mesh(ASCII_QUAD.as_bytes());
        assert_eq!(mesh.positions, QUAD_POSITIONS);
        assert_eq!(mesh.triangles, QUAD_TRIANGLES);
    }

    #[test]
    fn binary_little_and_big_endian_read_as_ascii() {
        for (format, be) in [("binary_little_endian", false), ("binary_big_endian", true)] {
            let mesh = mesh(&binary_quad(format, be));
            assert_eq!(mesh.positions, QUAD_POSITIONS, "{format}");
            assert_eq!(mesh.triangles, QUAD_TRIANGLES, "{format}");
        }
    }

    #[test]
    fn every_scalar_type_reads_in_both_byte_orders() {
        let types = ["char", "uchar", "short", "ushort", "int", "uint", "float", "double"];
        let aliases = ["int8", "uint8", "int16", "uint16", "int32", "uint32", "float32", "float64"];
        for names in [types, aliases] {
            for be in [false, true] {
                let format = if be { "binary_big_endian" } else { "binary_little_endian" };
                let mut header = format!("ply\nformat {format} 1.0\nelement vertex 1\n");
                for (k, ty) in names.iter().enumerate() {
                    header += &format!("property {ty} p{k}\n");
                }
                header +=
                    &format!("property {} x\nproperty {} y\nproperty {} z\nend_header\n", names[0], names[3], names[7]);
                let mut bytes = header.into_bytes();
                macro_rules! put {
                    ($v:expr) => {
                        bytes.extend(if be { $v.to_be_bytes() } else { $v.to_le_bytes() })
                    };
                }
                put!(-3i8);
                put!(200u8);
                put!(-3000i16);
                put!(60000u16);
                put!(-7i32);
                put!(4_000_000_000u32);
                put!(1.5f32);
                put!(-2.25f64);
                put!(-5i8);
                put!(65535u16);
                put!(0.125f64);
                let p = particles(&bytes);
                assert_eq!(p.positions, vec![[-5.0, 65535.0, 0.125]], "{names:?} {format}");
                // p0 is the first value-like property; the others are read past.
                assert_eq!((p.values.as_slice(), p.value_name.as_str()), ([-3.0f32].as_slice(), "p0"));
            }
        }
    }

    #[test]
    fn points_become_particles_with_named_columns() {
        let file = "ply\nformat ascii 1.0\nelement vertex 2\nproperty double x\nproperty double y\nproperty double z\n\
                    property float nx\nproperty uchar red\nproperty list uchar int neighbours\nproperty float hsml\n\
                    property float m\nproperty float temperature\nproperty float pressure\nelement face 0\n\
                    property list uchar int vertex_indices\nend_header\n\
                    1 2 3 0 9 2 1 1 0.5 2 300 1\n4 5 6 0 9 0 0.25 3 310 1\n";
        let p = particles(file.as_bytes());
        assert_eq!(p.positions, vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
        assert_eq!(p.smoothing, vec![0.5, 0.25]);
        assert_eq!(p.masses, vec![2.0, 3.0]);
        assert_eq!(p.values, vec![300.0, 310.0]);
        assert_eq!(p.value_name, "temperature");
    }

    #[test]
    fn dragon_like_vertices_with_confidence_and_intensity_make_a_mesh() {
        let file = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
                    property float confidence\nproperty float intensity\nelement face 1\n\
                    property list uchar int vertex_indices\nend_header\n\
                    -0.0378297 0.12794 0.00447467 0.850855 0.5 \n-0.0447794 0.128887 0.00190497 0.900159 0.5 \n\
                    -0.0680095 0.151244 0.0371953 0.398443 0.5 \n3 0 1 2 \n";
        let mesh = mesh(file.as_bytes());
        assert_eq!(mesh.positions.len(), 3);
        assert_eq!(mesh.triangles, vec![[0, 1, 2]]);
    }

    #[test]
    fn truncated_binary_names_the_element() {
        let bytes = binary_quad("binary_little_endian", false);
        // Cut inside the faces: the header's minimum sizes still fit, the faces do not.
        let e = error(&bytes[..bytes.len() - 12]);
        assert!(e.ends_with("test.ply: header announces 2 faces but the file ends after 1"), "{e}");
        let e = error(&bytes[..bytes.len() - 20]);
        assert!(e.ends_with("test.ply: header announces 2 faces but the file ends after 0"), "{e}");
        // Cut inside the vertices: the minimum sizes no longer fit.
        let header_len = bytes.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
        let short = error(&bytes[..header_len + 10]);
        assert!(short.contains("line 3: header announces 5 vertices but only 10 bytes follow the header"), "{short}");
    }

    #[test]
    fn huge_counts_are_refused_before_allocating() {
        let huge = "ply\nformat binary_little_endian 1.0\nelement vertex 18446744073709551615\nproperty float x\n\
                    property float y\nproperty float z\nend_header\n0123";
        let e = error(huge.as_bytes());
        assert!(e.contains("line 3: header announces 18446744073709551615 vertices but only 4 bytes follow"), "{e}");
        let ascii = "ply\nformat ascii 1.0\nelement vertex 1000000\nproperty float x\nproperty float y\n\
                     property float z\nend_header\n0 0 0\n";
        let e = error(ascii.as_bytes());
        assert!(e.contains("header announces 1000000 vertices but only 6 bytes follow the header"), "{e}");
        // A list length far beyond the data ends the file, nothing is reserved for it.
        let mut list = b"ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty uchar x\nproperty uchar y\n\
                         property uchar z\nelement face 1\nproperty list uint uint vertex_indices\nend_header\n"
            .to_vec();
        list.extend([0, 0, 0, 1, 0, 0, 0, 1, 0]);
        list.extend(u32::MAX.to_be_bytes());
        list.extend([0u8; 12]);
        let e = error(&list);
        assert!(e.contains("header announces 1 faces but the file ends after 0"), "{e}");
        // A skipped element with no properties and a vast count costs nothing.
        let empty = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n\
                     element nothing 18446744073709551615\nend_header\n1 2 3\n";
        assert_eq!(particles(empty.as_bytes()).positions, vec![[1.0, 2.0, 3.0]]);
    }

    #[test]
    fn bad_words_and_faces_are_named() {
        let with_body = |body: &str| {
            format!(
                "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
                 element face 1\nproperty list uchar int vertex_indices\nend_header\n{body}"
            )
        };
        let e = error(with_body("0 0 0\n1 0 0\n0 1 zero\n3 0 1 2\n").as_bytes());
        assert!(e.ends_with("line 12: vertex 2: 'zero' is not a number"), "{e}");
        let e = error(with_body("0 0 0\n1 0 0\n0 1 0\n2 0 1\n").as_bytes());
        assert!(e.ends_with("line 13: face 0 uses 2 vertices: a face needs at least 3"), "{e}");
        let e = error(with_body("0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n").as_bytes());
        assert!(e.ends_with("line 13: face 0 uses vertex -1: vertex indices cannot be negative"), "{e}");
        let e = error(with_body("0 0 0\n1 0 0\n0 1 0\n-3 0 1 2\n").as_bytes());
        assert!(e.ends_with("face 0: list length -3 is not a count"), "{e}");
        let e = error(with_body("0 0 0\n1 0 0\n0 1 0\n3 0 1 4294967296\n").as_bytes());
        assert!(e.ends_with("face 0 uses vertex 4294967296: voxstream reads at most 2^32 vertices"), "{e}");
    }

    #[test]
    fn header_errors_are_named() {
        assert!(error(b"PLY\n").contains("not a PLY file"));
        assert!(error(b"").contains("not a PLY file"));
        let e = error(b"ply\nformat binary_middle_endian 1.0\nend_header\n");
        assert!(e.ends_with("line 2: unknown PLY format 'binary_middle_endian'"), "{e}");
        let e = error(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n");
        assert!(e.ends_with("the header has no 'end_header' line"), "{e}");
        let e = error(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty quad x\nend_header\n");
        assert!(e.ends_with("line 4: unknown PLY type 'quad'"), "{e}");
        let e = error(b"ply\nformat ascii 1.0\nelement vertex -1\nend_header\n");
        assert!(e.ends_with("element 'vertex': '-1' is not a count"), "{e}");
        let e = error(b"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nend_header\n");
        assert!(e.ends_with("line 3: the vertex element has no scalar 'z' property"), "{e}");
        let e = error(b"ply\nelement vertex 0\nend_header\n");
        assert!(e.ends_with("the header has no 'format' line"), "{e}");
        let e = error(b"ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n");
        assert!(e.ends_with("the header declares no 'vertex' element"), "{e}");
        let e = error(b"ply\nformat ascii 2.0\nend_header\n");
        assert!(e.ends_with("unsupported: PLY version 2.0 (only 1.0)"), "{e}");
    }

    #[test]
    fn no_input_panics() {
        let files = [
            ASCII_QUAD.as_bytes().to_vec(),
            binary_quad("binary_little_endian", false),
            binary_quad("binary_big_endian", true),
        ];
        for file in &files {
            for cut in 0..file.len() {
                let _ = parse(&file[..cut], path());
            }
            for at in 0..file.len() {
                for byte in [0u8, b'\n', b' ', b'9', b'-', 0xff] {
                    let mut changed = file.clone();
                    changed[at] = byte;
                    let _ = parse(&changed, path());
                }
            }
        }
    }

    fn stream_file(name: &str, bytes: &[u8]) -> std::path::PathBuf {
        let path = std::env::temp_dir().join(format!("voxstream-ply-stream-{}-{name}.ply", std::process::id()));
        std::fs::write(&path, bytes).unwrap();
        path
    }

    fn streamed(stream: &PlyPointStream) -> RawParticles {
        let mut all = RawParticles { value_name: stream.value_name.clone(), ..RawParticles::default() };
        let mut next = 0;
        stream
            .for_each_chunk(&mut |first, run| {
                assert_eq!(first, next);
                next += run.positions.len() as u64;
                all.positions.extend(&run.positions);
                all.smoothing.extend(&run.smoothing);
                all.masses.extend(&run.masses);
                all.values.extend(&run.values);
                Ok(())
            })
            .unwrap();
        all
    }

    #[test]
    fn a_binary_point_file_streams_the_particles_parse_reads() {
        // A leading element the stream reads past, then vertices with a skipped colour, in both byte orders; enough
        // vertices for several chunks.
        let count = 300_000u32;
        for big in [false, true] {
            let order = if big { "big" } else { "little" };
            let mut bytes = format!(
                "ply\nformat binary_{order}_endian 1.0\nelement camera 2\nproperty double f\nelement vertex {count}\n\
                 property float x\nproperty double y\nproperty float z\nproperty uchar red\nproperty float hsml\n\
                 property float temperature\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n"
            )
            .into_bytes();
            let put = |bytes: &mut Vec<u8>, v: &[u8]| {
                let mut v = v.to_vec();
                if big {
                    v.reverse();
                }
                bytes.extend_from_slice(&v);
            };
            for _ in 0..2 {
                put(&mut bytes, &7.0f64.to_le_bytes());
            }
            for i in 0..count {
                let f = i as f32;
                put(&mut bytes, &(f * 0.5).to_le_bytes());
                put(&mut bytes, &(f64::from(f) * 0.25).to_le_bytes());
                put(&mut bytes, &(-f).to_le_bytes());
                bytes.push(200);
                put(&mut bytes, &(1.0 + f * 1e-6).to_le_bytes());
                put(&mut bytes, &(f * 2.0).to_le_bytes());
            }
            let path = stream_file(order, &bytes);
            let stream = PlyPointStream::open(&path).unwrap();
            assert_eq!(stream.count(), u64::from(count));
            assert_eq!(stream.columns(), [true, false, true]);
            let whole = match parse(&bytes, &path).unwrap() {
                RawGeometry::Particles(particles) => particles,
                RawGeometry::Mesh(_) => panic!("points expected"),
            };
            assert_eq!(streamed(&stream), whole);
            std::fs::remove_file(&path).ok();
        }
    }

    #[test]
    fn files_the_stream_cannot_read_are_named() {
        let header = |format: &str, rest: &str| {
            format!("ply\nformat {format} 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n{rest}end_header\n")
        };
        let refused = |name: &str, bytes: Vec<u8>, needle: &str| {
            let path = stream_file(name, &bytes);
            let error = PlyPointStream::open(&path).unwrap_err().to_string();
            assert!(error.contains(needle), "{name}: {error}");
            std::fs::remove_file(&path).ok();
        };
        refused("ascii", header("ascii", "").into_bytes(), "write it as binary_little_endian");
        let mut mesh =
            header("binary_little_endian", "element face 1\nproperty list uchar int vertex_indices\n").into_bytes();
        mesh.extend([0u8; 24 + 13]);
        refused("mesh", mesh, "holds faces (a mesh)");
        let mut short = header("binary_little_endian", "").into_bytes();
        short.extend([0u8; 23]);
        refused("short", short, "header announces 2 vertices (12 bytes each");
        let mut list = header("binary_little_endian", "property list uchar float extra\n").into_bytes();
        list.extend([0u8; 40]);
        refused("list", list, "list property 'extra'");
        let mut huge = "ply\nformat binary_little_endian 1.0\nelement vertex 18446744073709551615\nproperty double x\n\
                        property double y\nproperty double z\nend_header\n"
            .as_bytes()
            .to_vec();
        huge.extend([0u8; 48]);
        refused("huge", huge, "header announces 18446744073709551615 vertices");
    }
}
