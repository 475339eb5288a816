//! The value range of a foreign OME-Zarr image: the smallest and largest finite sample of level 0, streamed once
//! when the image is opened through the bricks over the chunks stored on disk, chunk by chunk (so that the reader's
//! chunk and brick caches keep what the first frames read next; see `StoreReader::open_with_options`). Coarse levels written by other tools average the brightest samples away (a stent's struts at 2000
//! read as at most 926 at the coarsest level), so they cannot give it; `omero.window` is a display setting, and its
//! `min`/`max` are not always written from level 0 either. Chunks never written hold the fill value, which then
//! belongs to the range too.

use zarrs::array::{Array, ArrayError};
use zarrs::storage::ReadableStorageTraits;

use crate::image_planes::LeadingIndex;
use crate::volume::DType;

/// Reports `(chunks done, chunks in all)` while the range is computed.
pub type ScanProgress<'a> = &'a dyn Fn(u64, u64);

/// Smallest and largest finite value of `values`, folded into `range`.
fn fold<T: Copy + Into<f64>>(values: &[T], range: &mut [f64; 2]) {
    for &v in values {
        let v: f64 = v.into();
        if v.is_finite() {
            *range = [range[0].min(v), range[1].max(v)];
        }
    }
}

/// Folds one sample given as native-endian bytes (a fill value); too few bytes fold nothing.
fn fold_bytes(bytes: &[u8], dtype: DType, range: &mut [f64; 2]) {
    match (dtype, bytes) {
        (DType::U8, [b, ..]) => fold(&[*b], range),
        (DType::U16, [b0, b1, ..]) => fold(&[u16::from_ne_bytes([*b0, *b1])], range),
        (DType::I16, [b0, b1, ..]) => fold(&[i16::from_ne_bytes([*b0, *b1])], range),
        (DType::F32, [b0, b1, b2, b3, ..]) => fold(&[f32::from_ne_bytes([*b0, *b1, *b2, *b3])], range),
        _ => {}
    }
}

/// The stored chunks of `array` (indices as found on disk) that hold the chosen indices of the `leading` axes and lie
/// within its chunk grid, each once.
fn chunks_at_leading<'c>(
    array: &Array<dyn ReadableStorageTraits>,
    leading: &LeadingIndex,
    stored: &'c [Vec<u64>],
) -> Vec<&'c Vec<u64>> {
    let grid = array.chunk_grid_shape();
    let mut chunks: Vec<&Vec<u64>> = stored
        .iter()
        .filter(|c| c.len() == grid.len() && leading.chunk_holds(array, c) && (0..grid.len()).all(|a| c[a] < grid[a]))
        .collect();
    chunks.sort();
    chunks.dedup();
    chunks
}

/// The bricks (edge `brick_size`, x, y, z indices) of level 0 that overlap the `stored` chunks of `array`, ordered
/// chunk by chunk (so that a chunk cache holding a few chunks reads each once).
pub(crate) fn bricks_over_stored_chunks(
    array: &Array<dyn ReadableStorageTraits>,
    leading: &LeadingIndex,
    stored: &[Vec<u64>],
    brick_size: u64,
) -> Result<Vec<[u64; 3]>, ArrayError> {
    let mut seen = std::collections::HashSet::new();
    let mut bricks = Vec::new();
    for chunk in chunks_at_leading(array, leading, stored) {
        let bounded = array.chunk_subset_bounded(chunk)?;
        let n = chunk.len();
        let (start, shape) = (bounded.start(), bounded.shape());
        let lower = [start[n - 1], start[n - 2], start[n - 3]].map(|v| v / brick_size);
        let upper = [0, 1, 2].map(|a| {
            let axis = n - 1 - a;
            (start[axis] + shape[axis]).div_ceil(brick_size)
        });
        for z in lower[2]..upper[2] {
            for y in lower[1]..upper[1] {
                for x in lower[0]..upper[0] {
                    if seen.insert([x, y, z]) {
                        bricks.push([x, y, z]);
                    }
                }
            }
        }
    }
    Ok(bricks)
}

/// The fill value of `array` as a number of type `dtype`, when some chunk holding the chosen indices of the
/// `leading` axes was never written (so the image holds it), else `None`.
pub(crate) fn unwritten_fill_value(
    array: &Array<dyn ReadableStorageTraits>,
    leading: &LeadingIndex,
    dtype: DType,
    stored: &[Vec<u64>],
) -> Option<f64> {
    let declared = array.chunk_grid_shape()[leading.len()..].iter().fold(1u64, |n, &d| n.saturating_mul(d));
    if chunks_at_leading(array, leading, stored).len() as u64 >= declared {
        return None;
    }
    let mut range = [f64::INFINITY, f64::NEG_INFINITY];
    fold_bytes(array.fill_value().as_ne_bytes(), dtype, &mut range);
    (range[0] <= range[1]).then_some(range[0])
}

/// `[min, max]` of the finite samples of `samples` folded into `range` (start from `EMPTY_RANGE`).
pub(crate) fn fold_samples(samples: &[f32], range: &mut [f64; 2]) {
    fold(samples, range);
}

/// The range nothing has been folded into yet.
pub(crate) const EMPTY_RANGE: [f64; 2] = [f64::INFINITY, f64::NEG_INFINITY];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn non_finite_samples_are_left_out() {
        let mut range = [f64::INFINITY, f64::NEG_INFINITY];
        fold(&[1.0f32, f32::NAN, -3.0, f32::INFINITY], &mut range);
        assert_eq!(range, [-3.0, 1.0]);
        fold_bytes(&7u16.to_ne_bytes(), DType::U16, &mut range);
        assert_eq!(range, [-3.0, 7.0]);
    }
}
