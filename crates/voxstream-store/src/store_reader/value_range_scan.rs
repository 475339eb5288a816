//! Foreign stores' value range and percentiles: scanned at open from the stored samples of one level
//! ([`crate::value_range`], [`crate::value_histogram`]), and the samples read later that lie outside the range (they
//! saturate when normalised).

use crate::error::StoreError;
use crate::level_source::LevelSource;
use crate::metadata_check::validate_attributes;
use crate::value_histogram::ValueHistogram;
use crate::value_range::{bricks_over_stored_chunks, fold_samples, unwritten_fill_value, ScanProgress, EMPTY_RANGE};

use super::StoreReader;

impl StoreReader {
    /// Foreign stores: sets the value range to that of `level` (level 0 unless it holds more than the scan's bound,
    /// [`crate::foreign::MAX_SCAN_SAMPLES`]), read brick by brick over its `stored` chunks, chunk by chunk (through
    /// the caches, which keep what they can for the first frames), plus the fill value where a chunk was never
    /// written; bricks that cannot be read are left out. A level with no finite sample gets `[0, 1]`.
    pub(super) fn scan_value_range(
        &mut self,
        level: usize,
        stored: &[Vec<u64>],
        progress: ScanProgress,
    ) -> Result<(), StoreError> {
        let LevelSource::Array { array, leading, .. } = &self.levels[level] else {
            return Err(StoreError::store(&self.path, format!("level {level} has no array")));
        };
        self.value_range_level = level;
        let failed = |e: zarrs::array::ArrayError| StoreError::store(&self.path, format!("level {level}: {e}"));
        let bricks = bricks_over_stored_chunks(array, leading, stored, self.layout.brick_size).map_err(failed)?;
        let mut range = EMPTY_RANGE;
        if let Some(fill) = unwritten_fill_value(array, leading, self.info.dtype, stored) {
            range = [fill, fill];
        }
        // The stored samples' percentiles too, as an import keeps them: the default transfer function is placed
        // over the bulk of the values, not stretched by a few outliers.
        let mut histogram = ValueHistogram::new(self.info.dtype);
        let total = bricks.len() as u64;
        for (done, ijk) in bricks.into_iter().enumerate() {
            // A brick that cannot be read is left out here: reading it fails again when it is wanted, and is
            // reported then (its ancestor stands in), as for any unreadable brick.
            if let Ok(samples) = self.brick(level, ijk) {
                let values = samples.to_f32();
                fold_samples(&values, &mut range);
                histogram.add(&values);
            }
            progress(done as u64 + 1, total);
        }
        self.attributes.value_range = if range[0] <= range[1] { range } else { [0.0, 1.0] };
        let percentiles = histogram.stored_percentiles();
        self.attributes.value_percentiles = (!percentiles.is_empty()).then_some(percentiles);
        validate_attributes(&self.path, &self.attributes)?;
        // The bricks were read against the placeholder range.
        self.clipped.store(0, std::sync::atomic::Ordering::Relaxed);
        Ok(())
    }

    /// Foreign stores: counts the samples outside the value range (they saturate when normalised).
    pub(super) fn count_clipped(&self, samples: &[f32]) {
        if self.minmax.is_some() {
            return;
        }
        let [lo, hi] = self.attributes.value_range.map(|v| v as f32);
        let outside = samples.iter().filter(|&&v| v < lo || v > hi).count() as u64;
        if outside > 0 {
            self.clipped.fetch_add(outside, std::sync::atomic::Ordering::Relaxed);
        }
    }

    /// The level whose stored samples gave a foreign store's value range at open (0 unless level 0 holds more than
    /// the scan's bound; see [`crate::foreign::MAX_SCAN_SAMPLES`]; also 0 for native stores and `--value-range`).
    pub fn value_range_level(&self) -> usize {
        self.value_range_level
    }

    /// Samples read so far from a foreign store that lay outside its value range, so that they saturate (0 for a
    /// range taken from level 0; more where `--value-range` or a coarse level written by another tool exceeds it).
    pub fn clipped_samples(&self) -> u64 {
        self.clipped.load(std::sync::atomic::Ordering::Relaxed)
    }
}
