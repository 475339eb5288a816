//! Reading bricks: a region of a level assembled from the bricks that overlap it, each brick read once (threads
//! after the same brick wait for one read) into the host-side LRU cache of decoded bricks (Reichl's host cache, seed
//! 004 ch. 4), checked against its min/max, padded where a foreign level is short, averaged where it is missing.

use std::sync::Arc;

use zarrs::array::{Array, ArraySubset};
use zarrs::storage::ReadableStorageTraits;

use crate::error::StoreError;
use crate::level_source::{retrieve_f32, LevelSource};

use super::decoded_brick::DecodedBrick;
use super::StoreReader;

/// Extends `data` (dims `have`, x fastest) to dims `want` by repeating its last samples.
fn pad_to(data: &[f32], have: [u64; 3], want: [u64; 3]) -> Vec<f32> {
    if have == want {
        return data.to_vec();
    }
    let mut out = Vec::with_capacity((want[0] * want[1] * want[2]) as usize);
    for z in 0..want[2] {
        for y in 0..want[1] {
            for x in 0..want[0] {
                let (sx, sy, sz) = (x.min(have[0] - 1), y.min(have[1] - 1), z.min(have[2] - 1));
                out.push(data[((sz * have[1] + sy) * have[0] + sx) as usize]);
            }
        }
    }
    out
}

/// 2×2×2 means of `data` (dims `size`, x fastest); odd edges average the samples that exist.
fn average_2x(data: &[f32], size: [u64; 3]) -> Vec<f32> {
    let [nx, ny, nz] = size.map(|v| v as usize);
    let [ox, oy, oz] = [nx.div_ceil(2), ny.div_ceil(2), nz.div_ceil(2)];
    let mut out = Vec::with_capacity(ox * oy * oz);
    for z in 0..oz {
        for y in 0..oy {
            for x in 0..ox {
                let (mut sum, mut n) = (0f64, 0u32);
                for (dx, dy, dz) in
                    [(0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0), (0, 0, 1), (1, 0, 1), (0, 1, 1), (1, 1, 1)]
                {
                    let (sx, sy, sz) = (2 * x + dx, 2 * y + dy, 2 * z + dz);
                    if sx < nx && sy < ny && sz < nz {
                        sum += data[(sz * ny + sy) * nx + sx] as f64;
                        n += 1;
                    }
                }
                out.push((sum / n as f64) as f32);
            }
        }
    }
    out
}

impl StoreReader {
    /// Reads samples `[lower, lower + size)` (x, y, z) of `level` as `f32`, x fastest, assembled from the bricks
    /// that overlap it (each read once from disk, then from the brick cache).
    pub fn read_region(&self, level: usize, lower: [u64; 3], size: [u64; 3]) -> Result<Vec<f32>, StoreError> {
        let b = self.layout.brick_size;
        let dims = self.layout.level_dims[level];
        let upper = [0, 1, 2].map(|a| lower[a] + size[a]);
        if (0..3).any(|a| upper[a] > dims[a] || size[a] == 0) {
            return Err(StoreError::store(&self.path, format!("region {lower:?}+{size:?} outside level {level}")));
        }
        let mut out = vec![0f32; (size[0] * size[1] * size[2]) as usize];
        let first = lower.map(|v| v / b);
        let last = [0, 1, 2].map(|a| (upper[a] - 1) / b);
        let mut ijks = Vec::new();
        for bz in first[2]..=last[2] {
            for by in first[1]..=last[1] {
                for bx in first[0]..=last[0] {
                    ijks.push([bx, by, bz]);
                }
            }
        }
        // A remote store's bricks (a node's and its neighbours', for the border) are fetched at once, each a round
        // trip; a local folder's one after another.
        let bricks: Vec<Arc<DecodedBrick>> = if self.remote.is_some() && ijks.len() > 1 {
            use rayon::prelude::*;
            ijks.par_iter().map(|&ijk| self.brick(level, ijk)).collect::<Result<_, _>>()?
        } else {
            ijks.iter().map(|&ijk| self.brick(level, ijk)).collect::<Result<_, _>>()?
        };
        for (&ijk, brick) in ijks.iter().zip(&bricks) {
            {
                {
                    let origin = ijk.map(|v| v * b);
                    let extent = [0, 1, 2].map(|a| (origin[a] + b).min(dims[a]) - origin[a]);
                    let from = [0, 1, 2].map(|a| origin[a].max(lower[a]));
                    let to = [0, 1, 2].map(|a| (origin[a] + extent[a]).min(upper[a]));
                    let run = (to[0] - from[0]) as usize;
                    for z in from[2]..to[2] {
                        for y in from[1]..to[1] {
                            let src = (((z - origin[2]) * extent[1] + (y - origin[1])) * extent[0]
                                + (from[0] - origin[0])) as usize;
                            let dst =
                                (((z - lower[2]) * size[1] + (y - lower[1])) * size[0] + (from[0] - lower[0])) as usize;
                            brick.copy_to_f32(src, &mut out[dst..dst + run]);
                        }
                    }
                }
            }
        }
        Ok(out)
    }

    /// Whether brick `ijk` of `level` holds only 0 by its min/max (nothing to read).
    pub(super) fn holds_only_zero(&self, level: usize, ijk: [u64; 3]) -> bool {
        let Some(minmax) = &self.minmax else { return false };
        let b = self.layout.bricks(level);
        (0..3).all(|a| ijk[a] < b[a])
            && minmax[level][((ijk[2] * b[1] + ijk[1]) * b[0] + ijk[0]) as usize] == [0.0, 0.0]
    }

    /// The samples of brick `ijk` of `level` (clipped to the level), x fastest, from the cache or the disk. A read
    /// from the store that succeeds takes the brick out of the failed background fetches (see
    /// `Background::failed`); a cache hit touches nothing but the cache.
    pub(super) fn brick(&self, level: usize, ijk: [u64; 3]) -> Result<Arc<DecodedBrick>, StoreError> {
        let key = (level, ijk);
        if let Some(brick) = self.brick_cache.lock().unwrap_or_else(|p| p.into_inner()).get(&key) {
            return Ok(brick.clone());
        }
        // Threads after the same brick wait for one read (see `single_flight`).
        self.reading.run(&key, || {
            if let Some(brick) = self.brick_cache.lock().unwrap_or_else(|p| p.into_inner()).get(&key) {
                return Ok(brick.clone());
            }
            let read = self.read_brick(level, ijk);
            if read.is_ok() {
                self.background.forget_failure(key);
            }
            read
        })
    }

    /// Reads brick `ijk` of `level` from the store into the brick cache.
    pub(super) fn read_brick(&self, level: usize, ijk: [u64; 3]) -> Result<Arc<DecodedBrick>, StoreError> {
        let key = (level, ijk);
        // A brick whose min/max is [0, 0] holds only the fill value: nothing to read (its shard may not exist).
        if let Some(minmax) = &self.minmax {
            let b = self.layout.bricks(level);
            if (0..3).all(|a| ijk[a] < b[a])
                && minmax[level][((ijk[2] * b[1] + ijk[1]) * b[0] + ijk[0]) as usize] == [0.0, 0.0]
            {
                let dims = self.layout.level_dims[level];
                let size = self.layout.brick_size;
                let extent: u64 = (0..3).map(|a| (ijk[a] * size + size).min(dims[a]) - ijk[a] * size).product();
                let brick = Arc::new(DecodedBrick::new(vec![0.0; extent as usize], self.info.dtype));
                self.brick_cache.lock().unwrap_or_else(|p| p.into_inner()).put(key, brick.clone());
                return Ok(brick);
            }
        }
        let b = self.layout.brick_size;
        let dims = self.layout.level_dims[level];
        let lower = ijk.map(|v| v * b);
        let upper = [0, 1, 2].map(|a| (lower[a] + b).min(dims[a]));
        let samples = match &self.levels[level] {
            LevelSource::Array { array, leading, shape } => {
                let read_upper = [0, 1, 2].map(|a| upper[a].min(shape[a]));
                if (0..3).any(|a| read_upper[a] <= lower[a]) {
                    // The foreign level is one sample short here: repeat its last samples.
                    let inner = [0, 1, 2].map(|a| lower[a].min(shape[a] - 1));
                    let got = self.read_array(level, array, leading, inner, [0, 1, 2].map(|a| inner[a] + 1))?;
                    vec![got[0]; ((upper[0] - lower[0]) * (upper[1] - lower[1]) * (upper[2] - lower[2])) as usize]
                } else {
                    let got = if self.chunk_cache.caches(level) {
                        let corrupt = |e: zarrs::array::ArrayError| {
                            StoreError::store(
                                &self.path,
                                format!("level {level}, samples {lower:?}..{read_upper:?}: {e}"),
                            )
                        };
                        let dtype = self.info.dtype;
                        self.chunk_cache
                            .read(level, array, leading, *shape, dtype, lower, read_upper)
                            .map_err(corrupt)?
                    } else {
                        self.read_array(level, array, leading, lower, read_upper)?
                    };
                    self.check_brick(level, ijk, array, &got)?;
                    self.count_clipped(&got);
                    pad_to(&got, [0, 1, 2].map(|a| read_upper[a] - lower[a]), [0, 1, 2].map(|a| upper[a] - lower[a]))
                }
            }
            LevelSource::Synthesized => {
                let finer = self.layout.level_dims[level - 1];
                let f_lower = lower.map(|v| 2 * v);
                let f_upper = [0, 1, 2].map(|a| (2 * upper[a]).min(finer[a]));
                let size = [0, 1, 2].map(|a| f_upper[a] - f_lower[a]);
                let fine = self.read_region(level - 1, f_lower, size)?;
                average_2x(&fine, size)
            }
        };
        let brick = Arc::new(DecodedBrick::new(samples, self.info.dtype));
        self.brick_cache.lock().unwrap_or_else(|p| p.into_inner()).put(key, brick.clone());
        Ok(brick)
    }

    /// Native stores: a brick read from disk must agree with its min/max, else it is a failure, never empty space.
    /// A brick whose min/max says it holds data needs its shard file (zarrs would read a missing one as zeros); at
    /// level 0 the samples' range must equal the recorded one exactly (it was computed from these very samples), at
    /// coarser levels lie within it (a mean stays within what it averages).
    pub(super) fn check_brick(
        &self,
        level: usize,
        ijk: [u64; 3],
        array: &Array<dyn ReadableStorageTraits>,
        samples: &[f32],
    ) -> Result<(), StoreError> {
        let Some(minmax) = &self.minmax else {
            return Ok(());
        };
        let b = self.layout.bricks(level);
        let [min, max] = minmax[level][((ijk[2] * b[1] + ijk[1]) * b[0] + ijk[0]) as usize];
        let failure =
            |problem: String| StoreError::store(&self.path, format!("level {level}, brick {ijk:?}: {problem}"));
        let (lo, hi) = samples.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| (lo.min(v), hi.max(v)));
        // A missing shard reads as the fill value, 0, throughout: only a brick that read as all 0 while its min/max
        // says otherwise needs its shard looked for (a size request, a round trip on a remote store).
        if [min, max] != [0.0, 0.0] && [lo, hi] == [0.0, 0.0] {
            let lower = ijk.map(|v| v * self.layout.brick_size);
            let shard = array.chunk_shape(&[0, 0, 0]).map_err(|e| failure(e.to_string()))?;
            let indices = [lower[2] / shard[0].get(), lower[1] / shard[1].get(), lower[0] / shard[2].get()];
            let key = array.chunk_key(&indices);
            match array.storage().size_key(&key) {
                Ok(Some(_)) => {}
                Ok(None) => {
                    return Err(failure(format!(
                        "shard {key} is missing, but the brick's min/max says it holds values {min} to {max}"
                    )))
                }
                Err(e) => return Err(failure(e.to_string())),
            }
        }
        let agrees = if level == 0 { lo == min && hi == max } else { lo >= min && hi <= max };
        if !agrees {
            return Err(failure(format!(
                "reads as values {lo} to {hi}, but its min/max says {min} to {max}: the shard is corrupt"
            )));
        }
        Ok(())
    }

    pub(super) fn read_array(
        &self,
        level: usize,
        array: &Array<dyn ReadableStorageTraits>,
        leading: &crate::image_planes::LeadingIndex,
        lower: [u64; 3],
        upper: [u64; 3],
    ) -> Result<Vec<f32>, StoreError> {
        let mut ranges = leading.ranges();
        ranges.extend([lower[2]..upper[2], lower[1]..upper[1], lower[0]..upper[0]]);
        let subset = ArraySubset::new_with_ranges(&ranges);
        let corrupt = |e: zarrs::array::ArrayError| {
            use zarrs::array::{codec::api::CodecError, ArrayError};
            let problem = match e {
                ArrayError::CodecError(CodecError::InvalidChecksum) => {
                    "a brick's CRC32C does not match its bytes: the shard is corrupt; import the volume again".into()
                }
                e => e.to_string(),
            };
            StoreError::store(&self.path, format!("level {level}, samples {lower:?}..{upper:?}: {problem}"))
        };
        retrieve_f32(array, &subset, self.info.dtype).map_err(corrupt)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn padding_repeats_the_last_samples_of_each_axis() {
        // 2 × 1 × 1 samples to 3 × 2 × 1.
        assert_eq!(pad_to(&[1.0, 2.0], [2, 1, 1], [3, 2, 1]), [1.0, 2.0, 2.0, 1.0, 2.0, 2.0]);
        assert_eq!(pad_to(&[5.0], [1, 1, 1], [1, 1, 1]), [5.0]);
    }

    #[test]
    fn averaging_halves_each_axis_and_odd_edges_average_what_exists() {
        // 3 × 2 × 1: the first output sample averages x 0..2, y 0..2; the second x 2, y 0..2.
        let data = [1.0, 2.0, 3.0, 5.0, 6.0, 7.0];
        assert_eq!(average_2x(&data, [3, 2, 1]), [3.5, 5.0]);
    }
}
