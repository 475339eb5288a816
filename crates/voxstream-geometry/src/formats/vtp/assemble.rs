//! Assembling a VTK XML file's particles: each array decoded (ascii here, binary and appended by
//! `voxstream-vtk-xml`) to values of its type, bounded together by what the file can hold, and the pieces' arrays
//! concatenated into positions, smoothing lengths, masses and the scalar attribute.

use std::cell::Cell;
use std::path::Path;

use voxstream_vtk_xml::{decode_base64_array, decode_raw_array, Bounds, Encoding, DEFLATE_MAX_RATIO};

use super::{line_at, Array, Format, Piece, MAX_ARRAY_BYTES};
use crate::error::GeometryError;
use crate::particles::RawParticles;

/// How the arrays' sizes are bounded and named in messages.
const BOUNDS: Bounds = Bounds { needed_by: "the point count", deflate_max_ratio: DEFLATE_MAX_RATIO };

/// A numeric array type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Ty {
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
    pub(super) fn parse(name: &str) -> Option<Ty> {
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

/// Decodes arrays.
pub(super) struct Decoder<'a> {
    pub(super) bytes: &'a [u8],
    pub(super) path: &'a Path,
    pub(super) encoding: Encoding,
    pub(super) appended: Option<&'a [u8]>,
    pub(super) appended_base64: Option<&'a [u8]>,
    /// Bytes the binary and appended arrays decoded so far.
    pub(super) decoded: Cell<u64>,
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
                decode_base64_array(&text, self.encoding, expected, &BOUNDS).map_err(|e| bad(e.to_string()))?
            }
            Format::Appended => {
                let Some(body) = self.appended else { return Err(bad("appended, but no AppendedData".into())) };
                let beyond = || bad(format!("offset {} beyond the appended data", array.offset));
                match self.appended_base64 {
                    Some(text) => decode_base64_array(
                        text.get(array.offset..).ok_or_else(beyond)?,
                        self.encoding,
                        expected,
                        &BOUNDS,
                    ),
                    None => {
                        decode_raw_array(body.get(array.offset..).ok_or_else(beyond)?, self.encoding, expected, &BOUNDS)
                    }
                }
                .map_err(|e| bad(e.to_string()))?
            }
        };
        // Each array's data is bytes of its own (inline text, or a stretch of the appended data), so together they
        // decode to at most the file's length, or what that inflates to; checked once the array's own checks have
        // passed, before its values are kept.
        let file = self.bytes.len() as u64;
        let (limit, holds) = if self.encoding.compressed {
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
        Ok(data.chunks_exact(size).map(|b| array.ty.decode(b, self.encoding.big_endian)).collect())
    }
}

/// The particles of all pieces.
pub(super) fn assemble(pieces: Vec<Piece>, decoder: &Decoder, path: &Path) -> Result<RawParticles, GeometryError> {
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
