//! The coarser levels' bits of the whole grid, made once after binning where they are small (Reichl §6.5.1's binary
//! mipmap, for the domain rather than per brick).
//!
//! A brick of level `L ≥ 1` made from the level-0 cell lists under it reads `8^L` lists: at level 2 of a 100-million
//! particle splash, 64 leaves and about 3 million cells for one brick, most of a first frame's time. Instead, the
//! finest coarse level whose bits fit [`MAX_DENSE_BYTES`] is set from every list once (in parallel), the coarser
//! ones OR-ed from it, and a brick of those levels is 4,096 words copied. Levels finer than that are still made
//! from the lists.

use std::sync::atomic::{AtomicU64, Ordering};

use rayon::prelude::*;

use crate::grid::{BrickKey, FluidGrid, BRICK};

/// Most bytes the dense coarse levels take together (all levels from the finest that fits).
pub const MAX_DENSE_BYTES: u64 = 64 << 20;

/// One level's bits over the whole grid: rows along x of whole bricks (`words_per_row = bricks_x`), row
/// `y + height·z`.
#[derive(Debug)]
pub struct DenseLevel {
    /// The level.
    pub level: u8,
    /// Bricks per axis at this level.
    pub bricks: [u32; 3],
    words: Vec<u64>,
}

impl DenseLevel {
    fn empty(grid: &FluidGrid, level: u8) -> DenseLevel {
        let bricks = grid.bricks(level);
        let words = bricks.iter().map(|&b| u64::from(b)).product::<u64>() * (BRICK * BRICK) as u64;
        DenseLevel { level, bricks, words: vec![0; words as usize] }
    }

    #[inline]
    fn index(&self, word_x: usize, y: usize, z: usize) -> usize {
        let height = self.bricks[1] as usize * BRICK;
        word_x + self.bricks[0] as usize * (y + height * z)
    }

    /// The 64 bits of row `(y, z)` (within the brick) of `key`.
    #[inline]
    pub fn brick_row(&self, key: BrickKey, y: usize, z: usize) -> u64 {
        let y = key.at[1] as usize * BRICK + y;
        let z = key.at[2] as usize * BRICK + z;
        self.words[self.index(key.at[0] as usize, y, z)]
    }

    /// Bytes held.
    pub fn bytes(&self) -> u64 {
        8 * self.words.len() as u64
    }

    /// The next coarser level: each bit the OR of its 2×2×2 cells here.
    fn coarser(&self, grid: &FluidGrid) -> DenseLevel {
        let mut out = DenseLevel::empty(grid, self.level + 1);
        let (height, depth) = (out.bricks[1] as usize * BRICK, out.bricks[2] as usize * BRICK);
        let (fine_height, fine_depth) = (self.bricks[1] as usize * BRICK, self.bricks[2] as usize * BRICK);
        let words_x = out.bricks[0] as usize;
        let fine_words_x = self.bricks[0] as usize;
        out.words.par_chunks_mut(words_x).enumerate().for_each(|(r, row)| {
            let (y, z) = (r % height, r / height);
            if z >= depth {
                return;
            }
            for (wx, word) in row.iter_mut().enumerate() {
                let mut bits = 0u64;
                for (dy, dz) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let (fy, fz) = (2 * y + dy, 2 * z + dz);
                    if fy >= fine_height || fz >= fine_depth {
                        continue;
                    }
                    for half in 0..2 {
                        let fx = 2 * wx + half;
                        if fx >= fine_words_x {
                            continue;
                        }
                        let w = self.words[fx + fine_words_x * (fy + fine_height * fz)];
                        bits |= u64::from(pair_or(w)) << (32 * half);
                    }
                }
                *word = bits;
            }
        });
        out
    }
}

/// The 32 ORs of the adjacent bit pairs of `w` (bits 2i and 2i+1 → bit i).
#[inline]
fn pair_or(w: u64) -> u32 {
    let mut x = (w | (w >> 1)) & 0x5555_5555_5555_5555;
    x = (x | (x >> 1)) & 0x3333_3333_3333_3333;
    x = (x | (x >> 2)) & 0x0f0f_0f0f_0f0f_0f0f;
    x = (x | (x >> 4)) & 0x00ff_00ff_00ff_00ff;
    x = (x | (x >> 8)) & 0x0000_ffff_0000_ffff;
    x = (x | (x >> 16)) & 0x0000_0000_ffff_ffff;
    x as u32
}

/// Bytes the dense levels from `level` up take.
fn bytes_from(grid: &FluidGrid, level: u8) -> u64 {
    (level..grid.levels)
        .map(|l| grid.bricks(l).iter().map(|&b| u64::from(b)).product::<u64>() * (BRICK * BRICK * 8) as u64)
        .sum()
}

/// The dense coarse levels of a grid whose level-0 cells `leaves` lists, brick by brick (`unpack` gives a packed
/// cell's coordinates in its brick); from the finest coarse level whose levels together fit [`MAX_DENSE_BYTES`]
/// (none when the grid has one level or even the coarsest would not fit).
pub fn dense_levels<F>(grid: &FluidGrid, leaves: &[(BrickKey, &[u32])], unpack: F) -> Vec<DenseLevel>
where
    F: Fn(u32) -> [u32; 3] + Sync,
{
    let Some(finest) = (1..grid.levels).find(|&l| bytes_from(grid, l) <= MAX_DENSE_BYTES) else {
        return Vec::new();
    };
    let first = DenseLevel::empty(grid, finest);
    let atomic: Vec<AtomicU64> = first.words.iter().map(|_| AtomicU64::new(0)).collect();
    let height = first.bricks[1] as usize * BRICK;
    let words_x = first.bricks[0] as usize;
    let shift = u32::from(finest);
    leaves.par_iter().for_each(|(leaf, cells)| {
        for &packed in *cells {
            let c = unpack(packed);
            let g: [usize; 3] = std::array::from_fn(|a| (leaf.at[a] as usize * BRICK + c[a] as usize) >> shift);
            let index = g[0] / 64 + words_x * (g[1] + height * g[2]);
            atomic[index].fetch_or(1 << (g[0] % 64), Ordering::Relaxed);
        }
    });
    let mut levels = vec![DenseLevel { words: atomic.into_iter().map(AtomicU64::into_inner).collect(), ..first }];
    while levels.last().is_some_and(|l| l.level + 1 < grid.levels) {
        let next = levels.last().map(|l| l.coarser(grid)).unwrap_or_else(|| unreachable!());
        levels.push(next);
    }
    levels
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pairs_of_bits_or_into_one() {
        assert_eq!(pair_or(0), 0);
        assert_eq!(pair_or(0b01), 1);
        assert_eq!(pair_or(0b10), 1);
        assert_eq!(pair_or(0b1100), 0b10);
        assert_eq!(pair_or(1 << 63), 1 << 31);
        assert_eq!(pair_or(u64::MAX), u32::MAX);
        assert_eq!(pair_or(0x5555_5555_5555_5555), u32::MAX);
    }
}
