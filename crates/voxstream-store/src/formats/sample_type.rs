//! Sample types as files hold them, and what each is stored as: the four store types as they are, and the types a
//! store does not hold converted on import, always the same way whatever the format (NumPy, NIfTI, NRRD, MetaImage,
//! INR, raw `--dtype`), so a scientist's `int32` labels or `float64` simulation imports instead of being refused.
//!
//! | in the file | stored as | exact? |
//! |---|---|---|
//! | int8 | int16 | always |
//! | int32, uint32 | float32 | for values within ±2^24; larger ones are rounded, and the note says by how much |
//! | float64 | float32 | rounded to float32's 24-bit precision; a finite value beyond float32's range is refused |
//!
//! [`SampleConversion`] counts, while the samples stream through, what the conversion rounded; displayed, it is the
//! note the import prints (`note: int32 converted to float32: …`).

use std::fmt;

use crate::volume::DType;

/// A sample type in a file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SampleType {
    /// Signed 8-bit (stored as i16).
    I8,
    /// Unsigned 8-bit.
    U8,
    /// Unsigned 16-bit.
    U16,
    /// Signed 16-bit.
    I16,
    /// Signed 32-bit (stored as f32).
    I32,
    /// Unsigned 32-bit (stored as f32).
    U32,
    /// 32-bit float.
    F32,
    /// 64-bit float (stored as f32).
    F64,
}

/// The names `--dtype` accepts, for messages.
pub const DTYPE_NAMES: &str = "u8, u16, i16, f32 (stored as they are), i8, i32, u32, f64 (converted)";

impl SampleType {
    /// Bytes per sample in the file.
    pub fn size(self) -> usize {
        match self {
            SampleType::I8 | SampleType::U8 => 1,
            SampleType::U16 | SampleType::I16 => 2,
            SampleType::I32 | SampleType::U32 | SampleType::F32 => 4,
            SampleType::F64 => 8,
        }
    }

    /// The type the store keeps these samples as.
    pub fn stored(self) -> DType {
        match self {
            SampleType::U8 => DType::U8,
            SampleType::U16 => DType::U16,
            SampleType::I8 | SampleType::I16 => DType::I16,
            SampleType::I32 | SampleType::U32 | SampleType::F32 | SampleType::F64 => DType::F32,
        }
    }

    /// Whether the store keeps another type than the file's.
    pub fn is_converted(self) -> bool {
        matches!(self, SampleType::I8 | SampleType::I32 | SampleType::U32 | SampleType::F64)
    }

    /// NumPy's name (`int8`, `uint8`, …, `float64`), used in notes.
    pub fn name(self) -> &'static str {
        match self {
            SampleType::I8 => "int8",
            SampleType::U8 => "uint8",
            SampleType::U16 => "uint16",
            SampleType::I16 => "int16",
            SampleType::I32 => "int32",
            SampleType::U32 => "uint32",
            SampleType::F32 => "float32",
            SampleType::F64 => "float64",
        }
    }

    /// Parses a `--dtype` name: `u8`, `i8`, …, `f64` or NumPy's `uint8`, `int8`, …, `float64`.
    pub fn from_name(name: &str) -> Option<SampleType> {
        Some(match name {
            "i8" | "int8" => SampleType::I8,
            "i32" | "int32" => SampleType::I32,
            "u32" | "uint32" => SampleType::U32,
            "f64" | "float64" => SampleType::F64,
            other => DType::from_name(other)?.into(),
        })
    }
}

impl From<DType> for SampleType {
    fn from(dtype: DType) -> SampleType {
        match dtype {
            DType::U8 => SampleType::U8,
            DType::U16 => SampleType::U16,
            DType::I16 => SampleType::I16,
            DType::F32 => SampleType::F32,
        }
    }
}

/// The largest magnitude below which every integer is a float32: 2^24.
pub const F32_EXACT_INTEGERS: f64 = 16_777_216.0;

/// What converting a file's samples did, counted as they stream through.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampleConversion {
    /// The file's type (one that [`SampleType::is_converted`]).
    pub from: SampleType,
    /// Samples converted.
    pub samples: u64,
    /// Samples whose stored value differs from the file's.
    pub rounded: u64,
    /// The largest difference between a file value and its stored value.
    pub largest_error: f64,
    /// The largest magnitude of a file value.
    pub largest_magnitude: f64,
}

impl SampleConversion {
    /// Nothing counted yet, for samples of `from`.
    pub fn new(from: SampleType) -> SampleConversion {
        SampleConversion { from, samples: 0, rounded: 0, largest_error: 0.0, largest_magnitude: 0.0 }
    }

    /// Counts one sample: `value` in the file, `stored` in the store.
    #[inline]
    pub fn count(&mut self, value: f64, stored: f32) {
        self.samples += 1;
        self.largest_magnitude = self.largest_magnitude.max(value.abs());
        let error = (value - stored as f64).abs();
        if error > 0.0 {
            self.rounded += 1;
            self.largest_error = self.largest_error.max(error);
        }
    }
}

/// Displayed, the note an import prints: `int32 converted to float32: exact (every value within ±2^24, …)`.
impl fmt::Display for SampleConversion {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let t = self;
        write!(f, "{} converted to {}", t.from.name(), SampleType::from(t.from.stored()).name())?;
        match t.from {
            SampleType::I8 => write!(f, " (every int8 value is an int16: exact)"),
            SampleType::I32 | SampleType::U32 if t.rounded == 0 && t.largest_magnitude <= F32_EXACT_INTEGERS => {
                write!(f, ": exact (every value within ±2^24, where float32 holds every integer)")
            }
            SampleType::I32 | SampleType::U32 if t.rounded == 0 => {
                write!(f, ": exact (values beyond ±2^24, up to {}, but each one a float32)", t.largest_magnitude)
            }
            SampleType::I32 | SampleType::U32 => write!(
                f,
                ": {} of {} values beyond ±2^24 were rounded to the nearest float32, by at most {}",
                t.rounded, t.samples, t.largest_error
            ),
            _ if t.rounded == 0 => write!(f, ": exact (every value is a float32)"),
            _ => write!(
                f,
                ": {} of {} values rounded to float32's 24-bit precision (largest change {:e})",
                t.rounded, t.samples, t.largest_error
            ),
        }
    }
}

/// Appends the samples of `bytes` (whole samples of `ty`, most significant byte first when `big`) to `out` as the
/// f32 values the store keeps, counting into `conversion` what converting rounded. A finite float64 beyond float32's
/// range is an error: its index in `bytes` and its value. (NaN and ±inf pass as they are, for the import's
/// `--nan-as` policy.)
pub fn decode(
    bytes: &[u8],
    ty: SampleType,
    big: bool,
    conversion: Option<&mut SampleConversion>,
    out: &mut Vec<f32>,
) -> Result<(), (usize, f64)> {
    macro_rules! samples {
        ($t:ty, $n:literal) => {
            bytes.chunks_exact($n).map(|c| {
                let a: [u8; $n] = c.try_into().expect("chunks_exact gives whole samples");
                if big {
                    <$t>::from_be_bytes(a)
                } else {
                    <$t>::from_le_bytes(a)
                }
            })
        };
    }
    // Converted types count what they round; the exact ones (and int8) need no tally.
    let mut spare = SampleConversion::new(ty);
    let tally = conversion.unwrap_or(&mut spare);
    match ty {
        SampleType::U8 => out.extend(bytes.iter().map(|&b| b as f32)),
        SampleType::I8 => out.extend(bytes.iter().map(|&b| b as i8 as f32)),
        SampleType::U16 => out.extend(samples!(u16, 2).map(|v| v as f32)),
        SampleType::I16 => out.extend(samples!(i16, 2).map(|v| v as f32)),
        SampleType::F32 => out.extend(samples!(f32, 4)),
        SampleType::I32 => out.extend(samples!(i32, 4).map(|v| {
            let stored = v as f32;
            tally.count(v as f64, stored);
            stored
        })),
        SampleType::U32 => out.extend(samples!(u32, 4).map(|v| {
            let stored = v as f32;
            tally.count(v as f64, stored);
            stored
        })),
        SampleType::F64 => {
            out.reserve(bytes.len() / 8);
            for (index, v) in samples!(f64, 8).enumerate() {
                let stored = v as f32;
                if stored.is_infinite() && v.is_finite() {
                    return Err((index, v));
                }
                if v.is_finite() {
                    tally.count(v, stored);
                }
                out.push(stored);
            }
        }
    }
    if ty == SampleType::I8 {
        tally.samples += bytes.len() as u64;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse_and_map_to_their_stored_types() {
        for (name, ty, stored) in [
            ("i8", SampleType::I8, DType::I16),
            ("int32", SampleType::I32, DType::F32),
            ("u32", SampleType::U32, DType::F32),
            ("float64", SampleType::F64, DType::F32),
            ("u16", SampleType::U16, DType::U16),
        ] {
            assert_eq!(SampleType::from_name(name), Some(ty));
            assert_eq!(ty.stored(), stored);
        }
        assert_eq!(SampleType::from_name("i64"), None);
        assert!(!SampleType::F32.is_converted() && SampleType::I8.is_converted());
    }

    #[test]
    fn the_note_says_whether_the_conversion_was_exact() {
        let mut tally = SampleConversion::new(SampleType::I32);
        tally.count(5.0, 5.0);
        assert!(tally.to_string().contains("int32 converted to float32: exact (every value within ±2^24"));
        // Large multiples of 64 are float32s too: exact, for that reason.
        let mut multiples = SampleConversion::new(SampleType::U32);
        multiples.count(28_760_000.0, 28_760_000.0f32);
        let note = multiples.to_string();
        assert!(note.contains("exact (values beyond ±2^24, up to 28760000, but each one a float32)"), "{note}");
        let big = 16_777_217i64;
        tally.count(big as f64, big as f32);
        let note = tally.to_string();
        assert!(note.contains("1 of 2 values beyond ±2^24 were rounded") && note.contains("by at most 1"), "{note}");
        let mut tally = SampleConversion::new(SampleType::F64);
        tally.count(0.1, 0.1f32);
        assert!(tally.to_string().contains("float64 converted to float32: 1 of 1 values rounded"));
    }

    #[test]
    fn every_type_decodes_in_both_byte_orders() {
        let mut out = Vec::new();
        decode(&[0xff, 0x80], SampleType::I8, false, None, &mut out).unwrap();
        assert_eq!(out, [-1.0, -128.0]);
        for big in [false, true] {
            let bytes = |v: &[u8; 4]| if big { v.iter().rev().copied().collect::<Vec<_>>() } else { v.to_vec() };
            let mut out = Vec::new();
            decode(&bytes(&(-7i32).to_le_bytes()), SampleType::I32, big, None, &mut out).unwrap();
            decode(&bytes(&u32::MAX.to_le_bytes()), SampleType::U32, big, None, &mut out).unwrap();
            assert_eq!(out, [-7.0, 4_294_967_296.0]);
        }
        let mut tally = SampleConversion::new(SampleType::F64);
        let mut out = Vec::new();
        let bytes: Vec<u8> = [0.5f64, f64::NAN, 1e300].iter().flat_map(|v| v.to_be_bytes()).collect();
        assert_eq!(decode(&bytes, SampleType::F64, true, Some(&mut tally), &mut out), Err((2, 1e300)));
        assert_eq!(out[0], 0.5);
        assert!(out[1].is_nan());
        assert_eq!((tally.samples, tally.rounded), (1, 0));
    }
}
