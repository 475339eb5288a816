//! The self-describing brick header (15 bytes + 3 samples: 18 for u8, 21 for u16, 27 for f32; little-endian) and
//! its validation. Kept small on purpose: a 32³ brick of empty space codes to the header alone, and zstd's own frame
//! of such a brick is about as large.
//!
//! | bytes | field |
//! |---|---|
//! | 0..2 | magic `VW` |
//! | 2 | version (1) |
//! | 3 | sample type ([`DType`]) << 4 \| payload kind ([`Kind`]) |
//! | 4 | DWT levels (0–3) << 4 \| entropy stage ([`Entropy`]: 0 rANS, 1 zstd planes) |
//! | 5..11 | dims x, y, z (u16 each, 1..=[`MAX_DIM`]) |
//! | 11..15 | quantisation step (f32; 1 in lossless mode) |
//! | then | quantisation offset, one sample: decoded = offset + q · step |
//! | then | min of the DECODED samples, one sample (NaNs ignored; ±inf only in raw bricks) |
//! | then | max of the DECODED samples, one sample |
//!
//! The payload is the rest of the buffer (its inner lengths are checked). min/max are those of what
//! [`crate::decode`] returns (the decoder recomputes and compares them), so a renderer that skips empty space by the
//! header's range never skips a voxel the decoded brick shows.

use crate::sample::DType;
use crate::{DecodeError, Entropy};

/// Bytes of the header before the three samples.
const FIXED_LEN: usize = 15;

/// Bytes of the header of a brick of this sample type.
pub fn header_len(dtype: DType) -> usize {
    FIXED_LEN + 3 * dtype.size()
}
/// Largest edge length accepted (a brick, not a volume).
pub const MAX_DIM: usize = 1024;
/// Largest number of samples accepted (the decoder allocates at most this many).
pub const MAX_VOXELS: usize = 1 << 24;
const MAGIC: [u8; 2] = *b"VW";
const VERSION: u8 = 1;

/// How the payload represents the samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// Every sample equals `min` (= `max`); no payload.
    Constant,
    /// zstd of the raw samples, byte-shuffled (lossless, bit-exact; the fallback for non-finite floats, f32
    /// lossless, and bricks the wavelet path would not shrink).
    Raw,
    /// Quantised integers → integer CDF 5/3 DWT → entropy stage, then exact corrections.
    Wavelet,
}

/// A parsed, validated header.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Header {
    /// Sample type.
    pub dtype: DType,
    /// Payload kind.
    pub kind: Kind,
    /// DWT levels.
    pub levels: u8,
    /// Edge lengths, x fastest.
    pub dims: [usize; 3],
    /// Entropy stage of a wavelet payload.
    pub entropy: Entropy,
    /// Quantisation step.
    pub step: f64,
    /// Quantisation offset.
    pub offset: f64,
    /// Smallest decoded sample.
    pub min: f64,
    /// Largest decoded sample.
    pub max: f64,
    /// Payload bytes after the header (the rest of the buffer).
    pub payload_len: usize,
}

impl Header {
    /// Number of samples.
    pub fn voxels(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }

    /// Bytes of this header.
    pub fn byte_len(&self) -> usize {
        header_len(self.dtype)
    }

    pub(crate) fn write(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&MAGIC);
        out.push(VERSION);
        let kind = match self.kind {
            Kind::Constant => 0,
            Kind::Raw => 1,
            Kind::Wavelet => 2,
        };
        out.push((self.dtype as u8) << 4 | kind);
        let entropy = match self.entropy {
            Entropy::ZstdPlanes => 1,
            Entropy::Rans | Entropy::Smallest => 0,
        };
        out.push(self.levels << 4 | entropy);
        for d in self.dims {
            out.extend_from_slice(&(d as u16).to_le_bytes());
        }
        out.extend_from_slice(&(self.step as f32).to_le_bytes());
        for v in [self.offset, self.min, self.max] {
            match self.dtype {
                DType::U8 => out.push(v as u8),
                DType::U16 => out.extend_from_slice(&(v as u16).to_le_bytes()),
                DType::F32 => out.extend_from_slice(&(v as f32).to_le_bytes()),
            }
        }
    }

    /// Parses and validates the header at the start of `b`; the payload is the rest of `b`.
    pub fn read(b: &[u8]) -> Result<Self, DecodeError> {
        let h = b.get(..FIXED_LEN).ok_or(DecodeError::Truncated)?;
        if h[..2] != MAGIC {
            return Err(DecodeError::Magic);
        }
        if h[2] != VERSION {
            return Err(DecodeError::Version(h[2]));
        }
        let bad = DecodeError::Header;
        let dtype = DType::from_u8(h[3] >> 4).ok_or(bad("unknown sample type"))?;
        let kind = match h[3] & 15 {
            0 => Kind::Constant,
            1 => Kind::Raw,
            2 => Kind::Wavelet,
            _ => return Err(bad("unknown payload kind")),
        };
        let levels = h[4] >> 4;
        if levels > 3 {
            return Err(bad("more than 3 DWT levels"));
        }
        let entropy = match h[4] & 15 {
            0 => Entropy::Rans,
            1 => Entropy::ZstdPlanes,
            _ => return Err(bad("unknown entropy stage")),
        };
        let dims = [0, 1, 2].map(|i| u16::from_le_bytes([h[5 + 2 * i], h[6 + 2 * i]]) as usize);
        if dims.iter().any(|&d| d == 0 || d > MAX_DIM) || dims[0] * dims[1] * dims[2] > MAX_VOXELS {
            return Err(bad("dims out of range"));
        }
        let step = f32::from_le_bytes([h[11], h[12], h[13], h[14]]) as f64;
        let len = header_len(dtype);
        let t = b.get(FIXED_LEN..len).ok_or(DecodeError::Truncated)?;
        let sz = dtype.size();
        let f = |i: usize| {
            let c = &t[i * sz..(i + 1) * sz];
            match dtype {
                DType::U8 => c[0] as f64,
                DType::U16 => u16::from_le_bytes([c[0], c[1]]) as f64,
                DType::F32 => f32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64,
            }
        };
        let (offset, min, max) = (f(0), f(1), f(2));
        if !(step.is_finite() && step > 0.0 && offset.is_finite()) {
            return Err(bad("step or offset not finite and positive"));
        }
        // Only a raw (bit-exact) brick may hold infinities, or only NaNs (then min = +inf > max = -inf).
        let ordered = min.is_finite() && max.is_finite() && min <= max;
        let raw_unordered = kind == Kind::Raw && !min.is_nan() && !max.is_nan();
        if !ordered && !raw_unordered {
            return Err(bad("range not finite and ordered"));
        }
        if dtype != DType::F32 && step.fract() != 0.0 {
            return Err(bad("integer samples need an integral step"));
        }
        let payload_len = b.len() - len;
        if kind == Kind::Constant && (min != max || payload_len != 0) {
            return Err(bad("a constant brick has min = max and no payload"));
        }
        Ok(Self { dtype, kind, levels, dims, entropy, step, offset, min, max, payload_len })
    }
}
