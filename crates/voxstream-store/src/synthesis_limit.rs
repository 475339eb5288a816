//! The bound on averaging a foreign pyramid's missing coarse levels: work proportional to what is visible.
//!
//! A level a foreign OME-Zarr image lacks is averaged 2×2×2 from the level below when one of its bricks is read
//! ([`LevelSource::Synthesized`]), recursively down to the nearest level the store holds. One brick of a missing
//! level `l` thus reads `(B · 2^(l−k))³` samples of the stored level `k` below it (at most all of level `k`), and the
//! renderer asks for the coarsest brick first: a store holding only level 0 at 8192³ would read all 5.5·10¹¹ of its
//! samples before the first picture.
//!
//! The store is refused at open, before anything is read, when one brick of a missing level would read more than
//! [`MAX_SYNTHESIS_SAMPLES`], with a line naming the fix (store the coarse levels, or import the volume, which writes
//! a full pyramid once). Sparse sampling instead of averaging was the alternative: it aliases (a coarse level that
//! is not the mean of the finer one, so pictures change as levels load), and still decodes up to one stored chunk per
//! sample (32³ chunks per brick), so its cost would depend on the chunking rather than on what is visible.

use std::path::Path;

use crate::error::StoreError;
use crate::layout::PyramidLayout;
use crate::level_source::LevelSource;

/// Most samples of a stored level that averaging one brick of a missing level may read: 2^30 (one 1024³ level, a
/// few seconds of decoding; a foreign image holding only its 1024³ level 0 renders, a 2048³ one does not).
pub const MAX_SYNTHESIS_SAMPLES: u64 = 1 << 30;

/// Samples of level `from` that averaging one brick of level `to > from` reads (clipped to level `from`).
pub fn synthesis_samples(layout: &PyramidLayout, from: usize, to: usize) -> u64 {
    let span = layout.brick_size.saturating_mul(1u64 << (to - from).min(63));
    layout.level_dims[from].iter().fold(1u64, |n, &d| n.saturating_mul(d.min(span)))
}

/// Refuses a pyramid in which averaging one brick of a missing level reads more than [`MAX_SYNTHESIS_SAMPLES`] of
/// the stored level below it.
pub(crate) fn check_synthesis(path: &Path, layout: &PyramidLayout, levels: &[LevelSource]) -> Result<(), StoreError> {
    let mut stored_below = 0;
    for (level, source) in levels.iter().enumerate() {
        if !matches!(source, LevelSource::Synthesized) {
            stored_below = level;
            continue;
        }
        if synthesis_samples(layout, stored_below, level) > MAX_SYNTHESIS_SAMPLES {
            // The whole run of missing levels above the stored one, to name what the store lacks.
            let first_missing = stored_below + 1;
            let run = levels[first_missing..].iter().take_while(|s| matches!(s, LevelSource::Synthesized)).count();
            let coarsest = first_missing + run - 1;
            let [x, y, z] = layout.level_dims[stored_below];
            return Err(StoreError::Unsupported {
                path: path.into(),
                message: format!(
                    "the OME-Zarr pyramid lacks levels {first_missing} to {coarsest} above its {x}x{y}x{z} level \
                     {stored_below}: averaging one brick of level {coarsest} would read {} samples, more than the \
                     {MAX_SYNTHESIS_SAMPLES} voxstream averages per brick; add the coarse levels to the image's \
                     multiscales (each halving the one before), or import the volume with `voxstream import`, \
                     which writes the whole pyramid",
                    synthesis_samples(layout, stored_below, coarsest)
                ),
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn only_level_0(layout: &PyramidLayout) -> Vec<LevelSource> {
        (0..layout.levels()).map(|_| LevelSource::Synthesized).collect()
    }

    #[test]
    fn a_missing_level_costs_the_samples_below_one_of_its_bricks() {
        let layout = PyramidLayout::new([8192, 8192, 8192], 32).unwrap();
        assert_eq!(layout.levels(), 9);
        assert_eq!(synthesis_samples(&layout, 0, 1), 64 * 64 * 64);
        assert_eq!(synthesis_samples(&layout, 0, 8), 8192u64.pow(3));
        assert_eq!(synthesis_samples(&layout, 3, 8), 1024u64.pow(3), "clipped to the stored level");
        let huge = PyramidLayout::new([1 << 20; 3], 32).unwrap();
        assert_eq!(synthesis_samples(&huge, 0, huge.levels() - 1), 1 << 60);
    }

    #[test]
    fn averaging_more_than_the_bound_per_brick_is_refused_naming_the_fix() {
        // Level 0 present only (the source's first entry stands for it: only Synthesized entries are inspected).
        let small = PyramidLayout::new([1024, 1024, 1024], 32).unwrap();
        assert!(check_synthesis(Path::new("s.zarr"), &small, &only_level_0(&small)[..]).is_ok(), "1024³ is within");
        let large = PyramidLayout::new([8192, 8192, 8192], 32).unwrap();
        let message = check_synthesis(Path::new("s.zarr"), &large, &only_level_0(&large)).unwrap_err().to_string();
        for needle in ["s.zarr", "levels 1 to 8", "549755813888", "voxstream import", "multiscales"] {
            assert!(message.contains(needle), "'{message}' lacks '{needle}'");
        }
    }
}
