//! How the brick pool stores a voxel: 16 bits for every source, or 8 bits for sources whose samples are 8-bit
//! integers (most CT, MRI and microscopy scans).
//!
//! Producers always write 16-bit voxels, the value normalised to `[0, 1]` (`value = voxel / 65535`). A producer
//! whose values are all of the form `b · scale + offset` for a byte `b` (a `u8` store: `b` is the sample,
//! `scale = 1 / (max − min)` and `offset = −min / (max − min)` of its value range) says so with
//! [`crate::Producer::voxel_format`], and the pool keeps `b` instead: half the memory and the bandwidth of the
//! 16-bit pool (issue "a ray caster faster than VTK's", item 2: "u8 scans in u8 bricks"). The narrowing is exact
//! for such values (the 16-bit voxel is within half a step of `65535 · (b · scale + offset)`, and a step of `b`
//! spans at least 257 of them). Renderers read the voxels through [`Voxel`] and [`Dequantize`]: a sample is
//! `interpolated · scale + offset`, whatever the width.

use crate::brick_pool::{dequantize, VOXEL_MAX};

/// How the brick pool stores voxels.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub enum VoxelFormat {
    /// 16 bits per voxel, `value = voxel / 65535`.
    #[default]
    Wide,
    /// 8 bits per voxel, `value = voxel · scale + offset`.
    Narrow {
        /// Value of one step of the byte.
        scale: f32,
        /// Value of byte 0.
        offset: f32,
    },
}

impl VoxelFormat {
    /// 8-bit voxels for integer samples in `[0, 255]` normalised by `value_range` (`(v − min) / (max − min)`),
    /// `None` when that is not exact: the range must be integers within `[0, 255]` and wide enough for the
    /// narrowing to round back to the byte (any range of a `u8` source is).
    pub fn for_bytes(value_range: [f64; 2]) -> Option<VoxelFormat> {
        let [lower, upper] = value_range;
        let integral = |v: f64| v.fract() == 0.0 && (0.0..=255.0).contains(&v);
        if !(integral(lower) && integral(upper) && upper > lower) {
            return None;
        }
        let scale = (1.0 / (upper - lower)) as f32;
        // `−(lower · scale)` in f32, so that the byte `lower` stands for exactly 0 (air stays skippable).
        Some(VoxelFormat::Narrow { scale, offset: -(lower as f32 * scale) })
    }

    /// Bytes of one voxel.
    pub fn voxel_bytes(self) -> usize {
        match self {
            VoxelFormat::Wide => 2,
            VoxelFormat::Narrow { .. } => 1,
        }
    }

    /// What a renderer multiplies and adds to an interpolated stored value.
    #[inline]
    pub fn dequantize(self) -> Dequantize {
        match self {
            VoxelFormat::Wide => Dequantize { scale: 1.0 / VOXEL_MAX as f32, offset: 0.0 },
            VoxelFormat::Narrow { scale, offset } => Dequantize { scale, offset },
        }
    }

    /// The 16-bit range `[lo, hi]` whose values (`dequantize`) bound the values of the stored voxels `[lower,
    /// upper]` as renderers compute them (`stored · scale + offset` in f32, and every interpolation between them):
    /// the same integers for 16-bit voxels; for 8-bit ones the nearest 16-bit voxels at or beyond them.
    pub fn wide_bounds(self, [lower, upper]: [u16; 2]) -> [u16; 2] {
        let VoxelFormat::Narrow { scale, offset } = self else { return [lower, upper] };
        let value = |stored: u16| stored as f32 * scale + offset;
        let (low, high) = (value(lower), value(upper));
        let nearest = |v: f32| (v.clamp(0.0, 1.0) * VOXEL_MAX as f32).round() as u16;
        let mut lo = nearest(low);
        while lo > 0 && dequantize(lo) > low {
            lo -= 1;
        }
        let mut hi = nearest(high);
        while hi < VOXEL_MAX && dequantize(hi) < high {
            hi += 1;
        }
        [lo, hi]
    }

    /// The byte a 16-bit voxel stands for (the nearest; exact for the values [`VoxelFormat::for_bytes`] admits).
    #[inline]
    pub fn narrow(scale: f32, offset: f32, voxel: u16) -> u8 {
        Narrowing::new(scale, offset).byte(voxel)
    }
}

/// [`VoxelFormat::narrow`] with its constants computed once (a multiply and an add per voxel): a byte step spans at
/// least 257 16-bit steps, so the rounding error of the constants (a few parts in 10⁷ of a byte) never changes the
/// nearest byte.
#[derive(Clone, Copy, Debug)]
pub struct Narrowing {
    per_voxel: f32,
    at_zero: f32,
}

impl Narrowing {
    /// The narrowing of [`VoxelFormat::Narrow`]`{ scale, offset }`.
    pub fn new(scale: f32, offset: f32) -> Narrowing {
        Narrowing { per_voxel: 1.0 / (VOXEL_MAX as f32 * scale), at_zero: -offset / scale }
    }

    /// The byte nearest to what `voxel` stands for.
    #[inline(always)]
    #[allow(clippy::manual_clamp)] // `clamp` keeps NaN; `max` then `min` turn it into 0, as the cast does.
    pub fn byte(self, voxel: u16) -> u8 {
        // The rounded value clamped to [0, 255] (NaN to 0, as `as u8` would), then converted by adding 2²³: the
        // float's low mantissa byte is then the integer. Unlike `as u8`, this vectorises.
        let nearest = (voxel as f32 * self.per_voxel + self.at_zero).round().max(0.0).min(255.0);
        (nearest + 8_388_608.0).to_bits() as u8
    }
}

/// The affine map from an interpolated stored value to the normalised value: `stored · scale + offset` (gradients:
/// `stored · scale`). For 16-bit voxels `scale = 1/65535` and `offset = 0`, the same bits as dividing by 65535.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dequantize {
    /// Value per stored unit.
    pub scale: f32,
    /// Value of stored 0.
    pub offset: f32,
}

impl Dequantize {
    /// The normalised value of an interpolated stored value.
    #[inline(always)]
    pub fn value(self, stored: f32) -> f32 {
        stored * self.scale + self.offset
    }

    /// The normalised slope of a slope in stored units.
    #[inline(always)]
    pub fn slope(self, stored: f32) -> f32 {
        stored * self.scale
    }
}

/// A stored voxel: `u16` or `u8`.
pub trait Voxel: Copy + Send + Sync + 'static {
    /// The stored integer as `f32` (exact).
    fn stored(self) -> f32;

    /// The normalised value of an interpolated stored value ([`Dequantize::value`]; for 16-bit voxels, whose
    /// offset is 0, without the addition: the same bits as dividing by 65535).
    fn value(stored: f32, dq: Dequantize) -> f32;
}

impl Voxel for u16 {
    #[inline(always)]
    fn stored(self) -> f32 {
        self as f32
    }

    #[inline(always)]
    fn value(stored: f32, dq: Dequantize) -> f32 {
        stored * dq.scale
    }
}

impl Voxel for u8 {
    #[inline(always)]
    fn stored(self) -> f32 {
        self as f32
    }

    #[inline(always)]
    fn value(stored: f32, dq: Dequantize) -> f32 {
        dq.value(stored)
    }
}

/// The brick pool's voxels, brick after brick, as renderers borrow them.
#[derive(Clone, Copy, Debug)]
pub enum PoolVoxels<'a> {
    /// 16-bit voxels.
    Wide(&'a [u16]),
    /// 8-bit voxels (see [`VoxelFormat::Narrow`]).
    Narrow(&'a [u8]),
}

impl<'a> PoolVoxels<'a> {
    /// Voxels in the pool.
    pub fn len(&self) -> usize {
        match self {
            PoolVoxels::Wide(v) => v.len(),
            PoolVoxels::Narrow(v) => v.len(),
        }
    }

    /// Whether the pool holds no voxel.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Voxels `range` of the pool.
    #[inline]
    pub fn slice(&self, range: std::ops::Range<usize>) -> PoolVoxels<'a> {
        match *self {
            PoolVoxels::Wide(v) => PoolVoxels::Wide(&v[range]),
            PoolVoxels::Narrow(v) => PoolVoxels::Narrow(&v[range]),
        }
    }

    /// Voxel `index` as stored (exact as `f32`).
    #[inline]
    pub fn stored(&self, index: usize) -> f32 {
        match self {
            PoolVoxels::Wide(v) => v[index] as f32,
            PoolVoxels::Narrow(v) => v[index] as f32,
        }
    }

    /// Voxel `index` as a 16-bit voxel (`quantize` of its value; the identity for 16-bit voxels): what a consumer
    /// that only reads 16-bit voxels (the GPU's atlas) reads.
    #[inline]
    pub fn wide(&self, index: usize, format: VoxelFormat) -> u16 {
        match (*self, format) {
            (PoolVoxels::Wide(v), _) => v[index],
            (PoolVoxels::Narrow(v), VoxelFormat::Narrow { scale, offset }) => {
                crate::brick_pool::quantize(v[index] as f32 * scale + offset)
            }
            (PoolVoxels::Narrow(v), VoxelFormat::Wide) => v[index] as u16 * 257,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brick_pool::quantize;

    #[test]
    fn narrowing_equals_the_saturating_cast_for_every_voxel() {
        let formats = [[0.0, 255.0], [0.0, 29.0], [12.0, 200.0], [254.0, 255.0], [3.0, 4.0]]
            .map(|range| VoxelFormat::for_bytes(range).unwrap());
        for format in formats {
            let VoxelFormat::Narrow { scale, offset } = format else { unreachable!() };
            let narrowing = Narrowing::new(scale, offset);
            for voxel in 0..=u16::MAX {
                let reference =
                    (voxel as f32 * narrowing.per_voxel + narrowing.at_zero).round().clamp(0.0, 255.0) as u8;
                assert_eq!(narrowing.byte(voxel), reference, "{voxel} in {format:?}");
            }
        }
        // A degenerate narrowing (NaN per voxel) still gives 0, as the cast does.
        assert_eq!(Narrowing { per_voxel: f32::NAN, at_zero: 0.0 }.byte(7), 0);
    }

    #[test]
    fn bytes_narrow_back_exactly_from_their_wide_voxels() {
        for range in [[0.0, 255.0], [0.0, 29.0], [12.0, 200.0], [254.0, 255.0], [3.0, 4.0]] {
            let Some(VoxelFormat::Narrow { scale, offset }) = VoxelFormat::for_bytes(range) else {
                panic!("{range:?} should be narrow")
            };
            let [lo, hi] = range;
            for v in lo as u32..=hi as u32 {
                // What the store producer writes: the normalised value quantised to 16 bits.
                let wide = quantize(((v as f32) - lo as f32) * (1.0 / (hi - lo) as f32));
                assert_eq!(VoxelFormat::narrow(scale, offset, wide) as u32, v, "{range:?} value {v}");
                // And the renderer's value of the byte is within half a 16-bit step of the wide voxel's.
                let back = v as f32 * scale + offset;
                assert!((back * 65535.0 - wide as f32).abs() <= 0.5 + 1e-2, "{range:?} value {v}");
            }
        }
    }

    #[test]
    fn wide_bounds_hold_the_bytes_values_and_keep_air_at_zero() {
        for range in [[0.0, 255.0], [0.0, 29.0], [12.0, 200.0], [254.0, 255.0]] {
            let format = VoxelFormat::for_bytes(range).unwrap();
            let d = format.dequantize();
            for lower in (range[0] as u16..=range[1] as u16).step_by(3) {
                for upper in (lower..=range[1] as u16).step_by(5) {
                    let [lo, hi] = format.wide_bounds([lower, upper]);
                    assert!(dequantize(lo) <= d.value(lower as f32), "{range:?} {lower}");
                    assert!(dequantize(hi) >= d.value(upper as f32), "{range:?} {upper}");
                    // And they are tight: at most a step wider each side.
                    let exact = (upper - lower) as f64 * 65535.0 / (range[1] - range[0]);
                    assert!((hi - lo) as f64 <= exact + 2.0, "{range:?} [{lower}, {upper}]: [{lo}, {hi}]");
                }
            }
            // The smallest byte is exactly 0: a range of air stays [0, 0], skippable as in a 16-bit pool.
            assert_eq!(d.value(range[0] as f32), 0.0);
            assert_eq!(format.wide_bounds([range[0] as u16; 2]), [0, 0]);
        }
        assert_eq!(VoxelFormat::Wide.wide_bounds([3, 70]), [3, 70]);
    }

    #[test]
    fn ranges_that_are_not_bytes_stay_wide() {
        for range in [[0.0, 65535.0], [-1.0, 100.0], [0.5, 10.0], [7.0, 7.0], [0.0, 256.0], [f64::NAN, 1.0]] {
            assert_eq!(VoxelFormat::for_bytes(range), None, "{range:?}");
        }
    }

    #[test]
    fn wide_dequantisation_keeps_the_16_bit_arithmetic() {
        let d = VoxelFormat::Wide.dequantize();
        for stored in [0.0f32, 1.0, 257.5, 40000.25, 65535.0] {
            assert_eq!(d.value(stored).to_bits(), (stored * (1.0 / 65535.0)).to_bits());
        }
    }
}
