//! The self-describing brick header (52 bytes, little-endian) and its validation.
//!
//! | bytes | field |
//! |---|---|
//! | 0..4 | magic `VXWB` |
//! | 4 | version (1) |
//! | 5 | sample type ([`DType`]) |
//! | 6 | payload kind ([`Kind`]) |
//! | 7 | DWT levels (0–3) |
//! | 8..14 | dims x, y, z (u16 each, 1..=[`MAX_DIM`]) |
//! | 14 | entropy stage ([`Entropy`]: 0 rANS, 1 zstd planes) |
//! | 15 | reserved, 0 |
//! | 16..24 | quantisation step (f64; 1 in lossless mode) |
//! | 24..32 | quantisation offset (f64): sample = offset + q · step |
//! | 32..40 | min of the DECODED samples (f64; NaNs ignored, ±inf only in raw bricks) |
//! | 40..48 | max of the DECODED samples (f64) |
//! | 48..52 | payload length (u32), which must be exactly the rest of the buffer |
//!
//! min/max are those of what [`crate::decode`] returns (the decoder recomputes and compares them), so a renderer that
//! skips empty space by the header's range never skips a voxel the decoded brick shows.

use crate::sample::DType;
use crate::{DecodeError, Entropy};

/// Bytes of the header.
pub const HEADER_LEN: usize = 52;
/// Largest edge length accepted (a brick, not a volume).
pub const MAX_DIM: usize = 1024;
/// Largest number of samples accepted (the decoder allocates at most this many).
pub const MAX_VOXELS: usize = 1 << 24;
const MAGIC: [u8; 4] = *b"VXWB";
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
    /// Payload bytes after the header.
    pub payload_len: usize,
}

impl Header {
    /// Number of samples.
    pub fn voxels(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }

    pub(crate) fn write(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&MAGIC);
        out.push(VERSION);
        out.push(self.dtype as u8);
        out.push(match self.kind {
            Kind::Constant => 0,
            Kind::Raw => 1,
            Kind::Wavelet => 2,
        });
        out.push(self.levels);
        for d in self.dims {
            out.extend_from_slice(&(d as u16).to_le_bytes());
        }
        out.push(match self.entropy {
            Entropy::Rans => 0,
            Entropy::ZstdPlanes => 1,
            Entropy::Smallest => 0,
        });
        out.push(0);
        for v in [self.step, self.offset, self.min, self.max] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&(self.payload_len as u32).to_le_bytes());
    }

    /// Parses and validates the header at the start of `b`, including that the payload is exactly the rest of `b`.
    pub fn read(b: &[u8]) -> Result<Self, DecodeError> {
        let h = b.get(..HEADER_LEN).ok_or(DecodeError::Truncated)?;
        if h[..4] != MAGIC {
            return Err(DecodeError::Magic);
        }
        if h[4] != VERSION {
            return Err(DecodeError::Version(h[4]));
        }
        let bad = DecodeError::Header;
        let dtype = DType::from_u8(h[5]).ok_or(bad("unknown sample type"))?;
        let kind = match h[6] {
            0 => Kind::Constant,
            1 => Kind::Raw,
            2 => Kind::Wavelet,
            _ => return Err(bad("unknown payload kind")),
        };
        let levels = h[7];
        if levels > 3 {
            return Err(bad("more than 3 DWT levels"));
        }
        let dims = [0, 1, 2].map(|i| u16::from_le_bytes([h[8 + 2 * i], h[9 + 2 * i]]) as usize);
        if dims.iter().any(|&d| d == 0 || d > MAX_DIM) || dims[0] * dims[1] * dims[2] > MAX_VOXELS {
            return Err(bad("dims out of range"));
        }
        let entropy = match h[14] {
            0 => Entropy::Rans,
            1 => Entropy::ZstdPlanes,
            _ => return Err(bad("unknown entropy stage")),
        };
        if h[15] != 0 {
            return Err(bad("reserved byte set"));
        }
        let f = |i: usize| f64::from_le_bytes(h[16 + 8 * i..24 + 8 * i].try_into().unwrap_or([0; 8]));
        let (step, offset, min, max) = (f(0), f(1), f(2), f(3));
        if !(step.is_finite() && step > 0.0 && offset.is_finite()) {
            return Err(bad("step or offset not finite and positive"));
        }
        // Only a raw (bit-exact) brick may hold infinities, or only NaNs (then min = +inf > max = -inf).
        let ordered = min.is_finite() && max.is_finite() && min <= max;
        if !(ordered || (kind == Kind::Raw && !min.is_nan() && !max.is_nan())) {
            return Err(bad("range not finite and ordered"));
        }
        if dtype != DType::F32 && (step.fract() != 0.0 || offset.fract() != 0.0 || step > 1e9 || offset.abs() > 1e9) {
            return Err(bad("integer samples need an integral step and offset"));
        }
        let payload_len = u32::from_le_bytes([h[48], h[49], h[50], h[51]]) as usize;
        if payload_len != b.len() - HEADER_LEN {
            return Err(DecodeError::Truncated);
        }
        if kind == Kind::Constant && (min != max || payload_len != 0) {
            return Err(bad("a constant brick has min = max and no payload"));
        }
        Ok(Self { dtype, kind, levels, dims, entropy, step, offset, min, max, payload_len })
    }
}
