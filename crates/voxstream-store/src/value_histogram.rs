//! A histogram of a volume's level-0 samples, filled while importing, from which the store keeps a few percentiles
//! (`value_percentiles` in its attributes). The default transfer function is placed between two of them, so that
//! one outlier sample (a single 65535 in a u16 scan, a padding value of −32768 in a CT) cannot stretch it over a
//! range the data does not use; opening a store stays cheap because only the percentiles are stored.
//!
//! 65536 bins, exact for 8- and 16-bit integer samples (one bin per value). For f32 samples a bin is the top 16 bits
//! of the float in an order-preserving encoding (sign, exponent and 7 bits of mantissa): a relative resolution of
//! 2⁻⁷ at any magnitude, without knowing the range in advance. Non-finite samples are not counted.

use crate::volume::DType;

/// The non-empty bins of a [`ValueHistogram`] (`keys[i]` counted `counts[i]` times) and its samples' range.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct HistogramParts {
    pub keys: Vec<u32>,
    pub counts: Vec<u64>,
    pub low: f32,
    pub high: f32,
}

/// Bins of the histogram: one per 16-bit key.
const BINS: usize = 1 << 16;

/// The percentiles a store keeps, in percent.
pub const STORED_PERCENTILES: [f64; 9] = [0.5, 1.0, 5.0, 25.0, 50.0, 75.0, 95.0, 99.0, 99.5];

/// Counts of samples per 16-bit key.
#[derive(Clone, Debug)]
pub struct ValueHistogram {
    dtype: DType,
    counts: Vec<u64>,
    total: u64,
    /// Smallest and largest sample counted: percentiles are clamped to them (an f32 bin's lower edge may lie below
    /// the smallest sample).
    low: f32,
    high: f32,
}

impl ValueHistogram {
    /// An empty histogram for samples of `dtype`.
    pub fn new(dtype: DType) -> ValueHistogram {
        ValueHistogram { dtype, counts: vec![0; BINS], total: 0, low: f32::INFINITY, high: f32::NEG_INFINITY }
    }

    /// Counts `samples` (the source's values as f32; non-finite ones are skipped).
    pub fn add(&mut self, samples: &[f32]) {
        for &value in samples {
            if value.is_finite() {
                let key = self.key(value);
                self.counts[key] += 1;
                self.total += 1;
                self.low = self.low.min(value);
                self.high = self.high.max(value);
            }
        }
    }

    /// Samples counted.
    pub fn total(&self) -> u64 {
        self.total
    }

    /// The value below which `percent` % of the samples lie (the lower edge of the bin that holds that rank, clamped
    /// to the samples' range; exact for integer samples), or `None` when nothing was counted.
    pub fn percentile(&self, percent: f64) -> Option<f64> {
        if self.total == 0 {
            return None;
        }
        let rank = ((percent.clamp(0.0, 100.0) / 100.0) * (self.total - 1) as f64).round() as u64;
        let mut seen = 0u64;
        for (key, &count) in self.counts.iter().enumerate() {
            seen += count;
            if seen > rank {
                return Some(self.value(key).clamp(f64::from(self.low), f64::from(self.high)));
            }
        }
        None
    }

    /// `[percent, value]` for each of [`STORED_PERCENTILES`], or empty when nothing was counted.
    pub fn stored_percentiles(&self) -> Vec<[f64; 2]> {
        STORED_PERCENTILES.iter().filter_map(|&p| self.percentile(p).map(|v| [p, v])).collect()
    }

    /// The counted bins and the samples' range, as a task of a distributed import sends them to be merged.
    pub fn parts(&self) -> HistogramParts {
        let (keys, counts) =
            self.counts.iter().enumerate().filter(|(_, &c)| c > 0).map(|(key, &count)| (key as u32, count)).unzip();
        HistogramParts { keys, counts, low: self.low, high: self.high }
    }

    /// Adds another histogram's [`parts`](Self::parts) (of samples of the same type). Keys past the last bin and
    /// totals that overflow are refused: the parts crossed a process boundary.
    pub fn merge(&mut self, parts: &HistogramParts) -> Result<(), String> {
        if parts.keys.len() != parts.counts.len() {
            return Err(format!("{} bins but {} counts", parts.keys.len(), parts.counts.len()));
        }
        for (&key, &count) in parts.keys.iter().zip(&parts.counts) {
            let bin = self.counts.get_mut(key as usize).ok_or_else(|| format!("bin {key} does not exist"))?;
            *bin = bin.checked_add(count).ok_or("a bin's count overflows")?;
            self.total = self.total.checked_add(count).ok_or("the total count overflows")?;
        }
        if !parts.keys.is_empty() {
            self.low = self.low.min(parts.low);
            self.high = self.high.max(parts.high);
        }
        Ok(())
    }

    fn key(&self, value: f32) -> usize {
        match self.dtype {
            DType::U8 | DType::U16 => value as usize & (BINS - 1),
            DType::I16 => (value as i32 + 32768) as usize & (BINS - 1),
            DType::F32 => (ordered_bits(value) >> 16) as usize,
        }
    }

    fn value(&self, key: usize) -> f64 {
        match self.dtype {
            DType::U8 | DType::U16 => key as f64,
            DType::I16 => key as f64 - 32768.0,
            DType::F32 => f64::from(from_ordered_bits((key as u32) << 16)),
        }
    }
}

/// The bits of `value` mapped so that unsigned order is float order (negative floats reversed below positive ones).
fn ordered_bits(value: f32) -> u32 {
    let bits = value.to_bits();
    if bits & 0x8000_0000 != 0 {
        !bits
    } else {
        bits | 0x8000_0000
    }
}

/// Inverse of [`ordered_bits`].
fn from_ordered_bits(bits: u32) -> f32 {
    if bits & 0x8000_0000 != 0 {
        f32::from_bits(bits & 0x7fff_ffff)
    } else {
        f32::from_bits(!bits)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integer_percentiles_are_exact_and_ignore_one_outlier() {
        let mut histogram = ValueHistogram::new(DType::U16);
        let mut samples: Vec<f32> = (0..1000).map(|i| (i % 100) as f32).collect();
        samples.push(65535.0);
        histogram.add(&samples);
        assert_eq!(histogram.total(), 1001);
        assert_eq!(histogram.percentile(0.0), Some(0.0));
        assert_eq!(histogram.percentile(50.0), Some(50.0));
        assert_eq!(histogram.percentile(99.5), Some(99.0));
        assert_eq!(histogram.percentile(100.0), Some(65535.0));
    }

    #[test]
    fn signed_and_float_samples_keep_their_order() {
        let mut histogram = ValueHistogram::new(DType::I16);
        histogram.add(&[-1000.0, -1.0, 0.0, 5.0, 300.0]);
        assert_eq!(histogram.percentile(0.0), Some(-1000.0));
        assert_eq!(histogram.percentile(25.0), Some(-1.0));
        assert_eq!(histogram.percentile(100.0), Some(300.0));

        let mut histogram = ValueHistogram::new(DType::F32);
        histogram.add(&[-2.5e6, -0.001, 0.0, 1.0, 3.75e-3, f32::NAN, f32::INFINITY, 7.0e20]);
        assert_eq!(histogram.total(), 6, "non-finite samples are not counted");
        let values: Vec<f64> =
            [0.0, 20.0, 40.0, 60.0, 80.0, 100.0].iter().map(|&p| histogram.percentile(p).unwrap()).collect();
        assert!(values.windows(2).all(|w| w[0] <= w[1]), "{values:?}");
        assert_eq!(values[0], -2.5e6, "clamped to the smallest sample, not its bin's lower edge");
        assert!(values[5] <= f64::from(7.0e20f32), "never above the largest sample");
        for (got, want) in values.iter().zip([-2.5e6, -0.001, 0.0, 3.75e-3, 1.0, 7.0e20]) {
            // The lower edge of its bin (towards −∞): within 2^-7 of the value.
            assert!((got - want).abs() <= want.abs() / 128.0 + 1e-30, "{got} for {want}");
        }
    }

    #[test]
    fn merged_parts_give_the_histogram_of_all_samples() {
        let samples: Vec<f32> = (0..5000).map(|i| ((i * 7919) % 1013) as f32 - 300.0).collect();
        let mut whole = ValueHistogram::new(DType::I16);
        whole.add(&samples);
        let mut merged = ValueHistogram::new(DType::I16);
        for piece in samples.chunks(777) {
            let mut part = ValueHistogram::new(DType::I16);
            part.add(piece);
            merged.merge(&part.parts()).unwrap();
        }
        assert_eq!(merged.parts(), whole.parts());
        assert_eq!(merged.stored_percentiles(), whole.stored_percentiles());
        let forged = HistogramParts { keys: vec![1 << 16], counts: vec![1], low: 0.0, high: 0.0 };
        assert!(merged.merge(&forged).is_err());
    }

    #[test]
    fn ordered_bits_round_trip_and_sort() {
        let values = [-f32::MAX, -1.0, -f32::MIN_POSITIVE, -0.0, 0.0, f32::MIN_POSITIVE, 1.0, f32::MAX];
        for pair in values.windows(2) {
            assert!(ordered_bits(pair[0]) <= ordered_bits(pair[1]), "{pair:?}");
        }
        for v in values {
            assert_eq!(from_ordered_bits(ordered_bits(v)).to_bits(), v.to_bits());
        }
        assert_eq!(ValueHistogram::new(DType::U8).percentile(50.0), None);
    }
}
