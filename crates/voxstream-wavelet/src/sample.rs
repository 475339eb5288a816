//! The sample types a brick may hold (u8, u16, f32) and the arithmetic the codec needs from them.

/// The type of a brick's samples, as written in its header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum DType {
    /// Unsigned 8-bit integers.
    U8 = 0,
    /// Unsigned 16-bit integers.
    U16 = 1,
    /// 32-bit IEEE floats.
    F32 = 2,
}

impl DType {
    /// Bytes per sample.
    pub fn size(self) -> usize {
        match self {
            Self::U8 => 1,
            Self::U16 => 2,
            Self::F32 => 4,
        }
    }

    pub(crate) fn from_u8(v: u8) -> Option<Self> {
        match v {
            0 => Some(Self::U8),
            1 => Some(Self::U16),
            2 => Some(Self::F32),
            _ => None,
        }
    }
}

mod sealed {
    pub trait Sealed {}
    impl Sealed for u8 {}
    impl Sealed for u16 {}
    impl Sealed for f32 {}
}

/// A sample type the codec handles. Sealed: u8, u16, f32.
pub trait Sample: Copy + PartialOrd + Default + Send + Sync + std::fmt::Debug + sealed::Sealed + 'static {
    /// Its tag in the header.
    const DTYPE: DType;
    /// Bytes per sample.
    const SIZE: usize;
    /// Integer samples quantise with odd integer steps and are exact in lossless mode.
    const INTEGER: bool;
    /// Exact widening.
    fn to_f64(self) -> f64;
    /// Integers: clamped to the type's range. f32: rounded to nearest.
    fn from_i64(v: i64) -> Self;
    /// Rounding narrowing (f32) or clamped rounding (integers).
    fn from_f64(v: f64) -> Self;
    /// Little-endian bytes into `out`.
    fn put(self, out: &mut Vec<u8>);
    /// From `Self::SIZE` little-endian bytes.
    fn get(b: &[u8]) -> Self;
    /// Whether `v` is exactly a value of this type (the header's min/max/constant are checked with it).
    fn representable(v: f64) -> bool {
        Self::from_f64(v).to_f64() == v
    }
    /// Same value and, for floats, same bits.
    fn same(self, other: Self) -> bool;
}

impl Sample for u8 {
    const DTYPE: DType = DType::U8;
    const SIZE: usize = 1;
    const INTEGER: bool = true;
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self as f64
    }
    #[inline(always)]
    fn from_i64(v: i64) -> Self {
        v.clamp(0, u8::MAX as i64) as u8
    }
    #[inline(always)]
    fn from_f64(v: f64) -> Self {
        v.round() as u8 // `as` saturates; NaN → 0
    }
    #[inline(always)]
    fn put(self, out: &mut Vec<u8>) {
        out.push(self)
    }
    #[inline(always)]
    fn get(b: &[u8]) -> Self {
        b[0]
    }
    fn same(self, other: Self) -> bool {
        self == other
    }
}

impl Sample for u16 {
    const DTYPE: DType = DType::U16;
    const SIZE: usize = 2;
    const INTEGER: bool = true;
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self as f64
    }
    #[inline(always)]
    fn from_i64(v: i64) -> Self {
        v.clamp(0, u16::MAX as i64) as u16
    }
    #[inline(always)]
    fn from_f64(v: f64) -> Self {
        v.round() as u16
    }
    #[inline(always)]
    fn put(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes())
    }
    #[inline(always)]
    fn get(b: &[u8]) -> Self {
        u16::from_le_bytes([b[0], b[1]])
    }
    fn same(self, other: Self) -> bool {
        self == other
    }
}

impl Sample for f32 {
    const DTYPE: DType = DType::F32;
    const SIZE: usize = 4;
    const INTEGER: bool = false;
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self as f64
    }
    #[inline(always)]
    fn from_i64(v: i64) -> Self {
        v as f32
    }
    #[inline(always)]
    fn from_f64(v: f64) -> Self {
        v as f32
    }
    #[inline(always)]
    fn put(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes())
    }
    #[inline(always)]
    fn get(b: &[u8]) -> Self {
        f32::from_le_bytes([b[0], b[1], b[2], b[3]])
    }
    fn representable(v: f64) -> bool {
        v.is_finite() && (v as f32) as f64 == v
    }
    fn same(self, other: Self) -> bool {
        self.to_bits() == other.to_bits()
    }
}
