//! The PLY header: the format line, the elements and their properties, and the counts it declares checked
//! against the bytes of the body before anything is allocated for them.

use std::path::Path;

use crate::error::GeometryError;
use crate::formats::words::shown;

/// How the body is stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Encoding {
    Ascii,
    BinaryLittle,
    BinaryBig,
}

/// A PLY scalar type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Scalar {
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
    pub(super) fn from_name(name: &str) -> Option<Scalar> {
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
    pub(super) fn size(self) -> u64 {
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
pub(super) enum Kind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Debug)]
pub(super) struct Property {
    pub(super) name: String,
    pub(super) kind: Kind,
}

#[derive(Debug)]
pub(super) struct Element {
    pub(super) name: String,
    pub(super) count: u64,
    pub(super) properties: Vec<Property>,
    /// The header line declaring it.
    pub(super) line: u64,
}

impl Element {
    /// "vertex 12", "face 3", "'edge' element 7".
    pub(super) fn singular(&self) -> String {
        match self.name.as_str() {
            "vertex" | "face" => self.name.clone(),
            other => format!("'{other}' element"),
        }
    }

    /// "vertices", "faces", "'edge' elements".
    pub(super) fn plural(&self) -> String {
        match self.name.as_str() {
            "vertex" => "vertices".into(),
            "face" => "faces".into(),
            other => format!("'{other}' elements"),
        }
    }
}

#[derive(Debug)]
pub(super) struct Header {
    pub(super) encoding: Encoding,
    pub(super) elements: Vec<Element>,
    /// Byte offset of the body (just after the `end_header` line).
    pub(super) body_start: usize,
    /// Line number of the body's first line.
    pub(super) body_line: u64,
}

/// At most this many characters of a file's word are quoted in an error.
pub(super) fn parse_header(bytes: &[u8], path: &Path) -> Result<Header, GeometryError> {
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

/// Checks each element count against the body's length before anything is allocated: in a binary body an element
/// takes at least its scalars' sizes plus its lists' length fields, in an ASCII body at least that many words, each a
/// character and a separator.
pub(super) fn check_counts(header: &Header, body_len: usize, path: &Path) -> Result<(), GeometryError> {
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
