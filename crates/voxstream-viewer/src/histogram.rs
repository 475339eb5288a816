//! The value histogram drawn under the transfer-function editor, sampled from the producer's coarse levels.
//!
//! Any source (a store, a foreign OME-Zarr, a procedural scene, a mesh or particle set) answers the same question
//! through [`Producer`]: the deepest level with at most [`MAX_SAMPLED_NODES`] nodes is produced (or answered by the
//! oracle) and its voxels are counted. That is a downsampled copy of the whole volume, read in a fraction of a
//! second, off the window's thread.

use voxstream_core::{NodeContent, NodeKey, Producer, BRICK_BORDER};

/// Nodes produced at most for the histogram.
pub const MAX_SAMPLED_NODES: u64 = 64;

/// Bins of the histogram.
pub const HISTOGRAM_BINS: usize = 128;

/// Counts of voxel values over the producer's value range.
#[derive(Clone, Debug, PartialEq)]
pub struct SampledHistogram {
    /// Data values of the first bin's lower edge and the last bin's upper edge.
    pub value_range: [f64; 2],
    /// Voxels per bin, equal widths.
    pub counts: Vec<u64>,
    /// The tree level sampled.
    pub level: u32,
}

impl SampledHistogram {
    /// The largest count (0 when empty).
    pub fn max_count(&self) -> u64 {
        self.counts.iter().copied().max().unwrap_or(0)
    }
}

/// Samples the histogram of `producer`, whose voxel values 0 and 1 stand for `value_range`. Nodes that fail to
/// produce are left out (the renderer reports them).
pub fn sample_histogram<P: Producer>(producer: &P, value_range: [f64; 2]) -> SampledHistogram {
    let shape = producer.shape();
    let n = shape.n as u64;
    let mut level = 0;
    while level < shape.max_level && (n.pow(3)).saturating_pow(level + 1) <= MAX_SAMPLED_NODES {
        level += 1;
    }
    let per_axis = shape.nodes_per_axis(level);
    let m = shape.brick_size as usize;
    let stored = shape.stored_brick_size() as usize;
    let border = BRICK_BORDER as usize;
    let mut counts = vec![0u64; HISTOGRAM_BINS];
    let bin_of =
        |normalised: f64| ((normalised.clamp(0.0, 1.0) * HISTOGRAM_BINS as f64) as usize).min(HISTOGRAM_BINS - 1);
    let brick_voxels = (m * m * m) as u64;
    let mut voxels = vec![0u16; stored * stored * stored];
    for k in 0..per_axis {
        for j in 0..per_axis {
            for i in 0..per_axis {
                let key = NodeKey { level, ijk: [i, j, k] };
                if let Some(value) = producer.oracle(key) {
                    counts[bin_of(value as f64)] += brick_voxels;
                    continue;
                }
                match producer.produce(key, &mut voxels) {
                    Ok(produced) => match produced.content {
                        NodeContent::Empty => counts[0] += brick_voxels,
                        NodeContent::Constant(value) => counts[bin_of(value as f64)] += brick_voxels,
                        NodeContent::Brick => {
                            for z in border..border + m {
                                for y in border..border + m {
                                    let row = (z * stored + y) * stored;
                                    for &v in &voxels[row + border..row + border + m] {
                                        counts[bin_of(v as f64 / u16::MAX as f64)] += 1;
                                    }
                                }
                            }
                        }
                    },
                    Err(_) => continue,
                }
            }
        }
    }
    SampledHistogram { value_range, counts, level }
}

#[cfg(test)]
mod tests {
    use voxstream_core::{ProduceError, Produced, TreeShape};

    use super::*;

    /// Level-0 values: a ramp in x; deeper nodes: constant halves.
    struct Ramp;
    impl Producer for Ramp {
        fn shape(&self) -> TreeShape {
            TreeShape::new(2, 4, 3).unwrap()
        }
        fn produce(&self, key: NodeKey, voxels: &mut [u16]) -> Result<Produced, ProduceError> {
            let stored = 6;
            for (index, v) in voxels.iter_mut().enumerate() {
                let x = index % stored;
                // Inner voxels x = 1..=4: values 0, 1/3, 2/3, 1 of the node's own range.
                let t = (x.clamp(1, 4) - 1) as f64 / 3.0;
                *v = if key.ijk[0] == 0 { (t * 0.5 * 65535.0) as u16 } else { 65535 };
            }
            Ok(Produced { content: NodeContent::Brick, is_terminal: false })
        }
    }

    #[test]
    fn the_histogram_counts_the_inner_voxels_of_the_sampled_level() {
        let histogram = sample_histogram(&Ramp, [10.0, 20.0]);
        // N = 2: levels 0 (1 node), 1 (8), 2 (64) have at most 64 nodes; level 2 is sampled.
        assert_eq!(histogram.level, 2);
        assert_eq!(histogram.counts.iter().sum::<u64>(), 64 * 64);
        // Half the nodes (ijk[0] == 0 … only the first column of 4) carry the ramp; the others are all 1.
        let last = *histogram.counts.last().unwrap();
        assert_eq!(last, 48 * 64, "three of four x columns are 1");
        assert_eq!(histogram.counts[0], 16 * 16, "a quarter of the ramp voxels are 0");
        assert_eq!(histogram.max_count(), last);
    }
}
