//! A decoded brick as the host cache keeps it: in the store's own sample type where its samples are exact there
//! (a native level of an integer store), so that a `u8` store's cache holds four times the bricks it would as `f32`
//! (Reichl's host cache, seed 004 ch. 4: bytes of host memory are the budget); `f32` otherwise (float stores, and
//! foreign levels averaged from the level below, whose samples are fractions).

use crate::volume::DType;

/// A brick's samples, x fastest.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum DecodedBrick {
    U8(Vec<u8>),
    U16(Vec<u16>),
    I16(Vec<i16>),
    F32(Vec<f32>),
}

impl DecodedBrick {
    /// `samples` kept as `dtype` when every one of them is exactly a value of it, else as `f32`.
    pub(crate) fn new(samples: Vec<f32>, dtype: DType) -> DecodedBrick {
        fn narrow<T: Copy>(samples: &[f32], convert: impl Fn(f32) -> T, back: impl Fn(T) -> f32) -> Option<Vec<T>> {
            let narrowed: Vec<T> = samples.iter().map(|&v| convert(v)).collect();
            narrowed.iter().zip(samples).all(|(&n, &v)| back(n).to_bits() == v.to_bits()).then_some(narrowed)
        }
        let narrowed = match dtype {
            DType::U8 => narrow(&samples, |v| v as u8, f32::from).map(DecodedBrick::U8),
            DType::U16 => narrow(&samples, |v| v as u16, f32::from).map(DecodedBrick::U16),
            DType::I16 => narrow(&samples, |v| v as i16, f32::from).map(DecodedBrick::I16),
            DType::F32 => None,
        };
        narrowed.unwrap_or(DecodedBrick::F32(samples))
    }

    /// Number of samples.
    pub(crate) fn len(&self) -> usize {
        match self {
            DecodedBrick::U8(v) => v.len(),
            DecodedBrick::U16(v) => v.len(),
            DecodedBrick::I16(v) => v.len(),
            DecodedBrick::F32(v) => v.len(),
        }
    }

    /// Copies samples `start..start + out.len()` into `out` as `f32`.
    #[inline]
    pub(crate) fn copy_to_f32(&self, start: usize, out: &mut [f32]) {
        let range = start..start + out.len();
        match self {
            DecodedBrick::U8(v) => out.iter_mut().zip(&v[range]).for_each(|(o, &s)| *o = f32::from(s)),
            DecodedBrick::U16(v) => out.iter_mut().zip(&v[range]).for_each(|(o, &s)| *o = f32::from(s)),
            DecodedBrick::I16(v) => out.iter_mut().zip(&v[range]).for_each(|(o, &s)| *o = f32::from(s)),
            DecodedBrick::F32(v) => out.copy_from_slice(&v[range]),
        }
    }

    /// All samples as `f32`.
    pub(crate) fn to_f32(&self) -> Vec<f32> {
        let mut out = vec![0f32; self.len()];
        self.copy_to_f32(0, &mut out);
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_samples_narrow_to_the_store_type_and_fractions_stay_f32() {
        let bytes = DecodedBrick::new(vec![0.0, 17.0, 255.0], DType::U8);
        assert_eq!(bytes, DecodedBrick::U8(vec![0, 17, 255]));
        assert_eq!(bytes.to_f32(), vec![0.0, 17.0, 255.0]);
        assert_eq!(DecodedBrick::new(vec![-300.0, 2.0], DType::I16), DecodedBrick::I16(vec![-300, 2]));
        // An averaged level (fractions), a value beyond the type, and -0.0 keep every bit as f32.
        for (samples, dtype) in
            [(vec![1.5, 2.0], DType::U8), (vec![256.0], DType::U8), (vec![-0.0], DType::U16), (vec![0.25], DType::F32)]
        {
            let kept = DecodedBrick::new(samples.clone(), dtype);
            assert_eq!(kept, DecodedBrick::F32(samples.clone()), "{samples:?} as {dtype:?}");
        }
        let mut out = [0f32; 2];
        DecodedBrick::U16(vec![5, 6, 7, 8]).copy_to_f32(1, &mut out);
        assert_eq!(out, [6.0, 7.0]);
    }
}
