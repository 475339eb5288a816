//! The order worker threads take a batch in: space-filling-curve (Morton) order of its nodes, so that a producer
//! reading spatial bins finds them still cached; results come back in the batch's order.

use rayon::prelude::*;

use crate::key::{NodeKey, TreeShape};

/// `work(i)` for every item of `batch`, on worker threads, computed in space-filling-curve order of the items' nodes
/// (the Morton code of each node's corner at the finest level, then the level) and returned in the batch's order.
///
/// Nodes near each other in space are then made by the same thread close together in time, so a producer reading
/// spatial bins (a store's chunks, out-of-core particle superbricks) finds them still cached: the batch's order is
/// the rays' priority, not space. What is produced and the order results are applied in do not change.
pub(super) fn in_space_order<T: Sync, R: Send>(
    batch: &[T],
    key_of: impl Fn(&T) -> NodeKey,
    shape: &TreeShape,
    work: impl Fn(usize) -> R + Sync,
) -> Vec<R> {
    let mut order: Vec<(u64, u32, usize)> = batch
        .iter()
        .enumerate()
        .map(|(index, item)| {
            let key = key_of(item);
            // The node's corner in nodes of the finest level (N^(levels below) per node; an order, so an overflow
            // only costs locality).
            let scale = u64::from(shape.n).saturating_pow(shape.max_level.saturating_sub(key.level));
            let corner = key.ijk.map(|c| c.saturating_mul(scale));
            (morton_code(corner), key.level, index)
        })
        .collect();
    order.sort_unstable();
    let mut results: Vec<(usize, R)> = order.par_iter().map(|&(_, _, index)| (index, work(index))).collect();
    results.sort_unstable_by_key(|&(index, _)| index);
    results.into_iter().map(|(_, result)| result).collect()
}

/// The Morton (Z-order) code of `ijk`'s low 21 bits per axis.
pub(super) fn morton_code(ijk: [u64; 3]) -> u64 {
    fn spread(v: u64) -> u64 {
        let mut x = v & 0x1f_ffff;
        x = (x | x << 32) & 0x1f00000000ffff;
        x = (x | x << 16) & 0x1f0000ff0000ff;
        x = (x | x << 8) & 0x100f00f00f00f00f;
        x = (x | x << 4) & 0x10c30c30c30c30c3;
        (x | x << 2) & 0x1249249249249249
    }
    spread(ijk[0]) | spread(ijk[1]) << 1 | spread(ijk[2]) << 2
}
#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn morton_codes_interleave_the_axes() {
        assert_eq!(morton_code([1, 0, 0]), 1);
        assert_eq!(morton_code([0, 1, 0]), 2);
        assert_eq!(morton_code([0, 0, 1]), 4);
        assert_eq!(morton_code([3, 5, 6]), 0b110_101_011);
        assert_eq!(morton_code([(1 << 21) - 1; 3]), (1 << 63) - 1);
        // Results come back in the batch's order whatever the order of work.
        let shape = TreeShape::new(2, 8, 4).unwrap();
        let keys: Vec<NodeKey> =
            (0..50u64).map(|i| NodeKey { level: (i % 5) as u32, ijk: [i % 3, (i * 7) % 5, i % 2] }).collect();
        let results = in_space_order(&keys, |k| *k, &shape, |i| keys[i]);
        assert_eq!(results, keys);
    }
}
