//! The fused scene's bricks, grouped in world chunks (seed 004 §8.3.1, §8.6).
//!
//! Bricks are found by their integer brick coordinate in one hash map (the thesis' GPU hash of chunks, flattened:
//! on a CPU one lookup per brick costs the same as one per chunk plus one per octree level). Every brick belongs to
//! the world chunk of 32³ bricks around it, and chunks are the unit of streaming: when the resident bricks exceed the
//! budget, the chunks farthest from the camera are written to disk ([`crate::spill`]) and dropped, and a chunk is
//! read back as soon as a frame touches it again. The scene therefore has no fixed extent and its memory stays
//! under the budget however long the scan runs.

use std::path::PathBuf;

use glam::{DVec3, IVec3};
use rustc_hash::{FxHashMap, FxHashSet};

use crate::brick::{BinaryBrick, BRICK};
use crate::spill;
use crate::FusionError;

/// Bricks along a world chunk's edge (32 bricks of 8 voxels: 2.56 m at 1 cm voxels, the thesis' 2 m chunks).
pub const CHUNK_BRICKS: i32 = 32;

/// Bytes a map entry costs besides the brick itself (key, hash control byte, load-factor slack).
const ENTRY_OVERHEAD: usize = std::mem::size_of::<IVec3>() + 8;

/// The chunk of brick `key`.
pub fn chunk_of(key: IVec3) -> IVec3 {
    IVec3::new(key.x.div_euclid(CHUNK_BRICKS), key.y.div_euclid(CHUNK_BRICKS), key.z.div_euclid(CHUNK_BRICKS))
}

/// The bricks of a fused scene, resident or on disk.
#[derive(Debug)]
pub struct BrickMap {
    /// Voxel edge, metres; voxel `(i, j, k)` covers `[i, i + 1) · voxel` along each axis.
    voxel: f64,
    bricks: FxHashMap<IVec3, BinaryBrick>,
    /// Chunks written to disk and not resident.
    spilled: FxHashSet<IVec3>,
    /// Where spilled chunks go; `None`: never spill (the budget is then a limit that fails).
    spill_dir: Option<PathBuf>,
    /// Bytes of the resident bricks, kept up to date by [`BrickMap::recount`].
    resident_bytes: usize,
    /// Chunks written and read back so far.
    pub chunks_written: u64,
    pub chunks_read: u64,
}

impl BrickMap {
    pub fn new(voxel: f64, spill_dir: Option<PathBuf>) -> BrickMap {
        BrickMap {
            voxel,
            bricks: FxHashMap::default(),
            spilled: FxHashSet::default(),
            spill_dir,
            resident_bytes: 0,
            chunks_written: 0,
            chunks_read: 0,
        }
    }

    /// Voxel edge, metres.
    pub fn voxel(&self) -> f64 {
        self.voxel
    }

    /// The voxel containing world point `p`.
    pub fn voxel_of(&self, p: DVec3) -> IVec3 {
        (p / self.voxel).floor().as_ivec3()
    }

    /// The world position of voxel `v`'s centre.
    pub fn centre(&self, v: IVec3) -> DVec3 {
        (v.as_dvec3() + DVec3::splat(0.5)) * self.voxel
    }

    /// The brick holding voxel `v`, and the voxel's coordinates in it.
    pub fn split(v: IVec3) -> (IVec3, IVec3) {
        let brick = IVec3::new(v.x.div_euclid(BRICK), v.y.div_euclid(BRICK), v.z.div_euclid(BRICK));
        (brick, v - brick * BRICK)
    }

    pub fn brick(&self, key: IVec3) -> Option<&BinaryBrick> {
        self.bricks.get(&key)
    }

    pub fn brick_mut(&mut self, key: IVec3) -> Option<&mut BinaryBrick> {
        self.bricks.get_mut(&key)
    }

    /// Whether voxel `v` is behind the surface (absent bricks are outside); with `confident_only`, non-confident
    /// voxels count as outside (what high-quality renderings show, §8.3.4).
    pub fn inside(&self, v: IVec3, confident_only: bool) -> bool {
        let (key, local) = Self::split(v);
        self.bricks.get(&key).is_some_and(|b| {
            let i = crate::brick::voxel_index(local.x, local.y, local.z);
            b.inside.get(i) && (!confident_only || b.confident.get(i))
        })
    }

    /// Resident bricks.
    pub fn len(&self) -> usize {
        self.bricks.len()
    }

    pub fn is_empty(&self) -> bool {
        self.bricks.is_empty() && self.spilled.is_empty()
    }

    /// Chunks on disk.
    pub fn spilled_chunks(&self) -> usize {
        self.spilled.len()
    }

    /// Bytes of the chunk files on disk (about what their bricks take back in memory).
    pub fn spilled_bytes(&self) -> u64 {
        let Some(dir) = &self.spill_dir else { return 0 };
        self.spilled
            .iter()
            .filter_map(|&chunk| std::fs::metadata(spill::chunk_path(dir, chunk)).ok())
            .map(|m| m.len())
            .sum()
    }

    /// Resident bricks' keys and bricks.
    pub fn iter(&self) -> impl Iterator<Item = (&IVec3, &BinaryBrick)> {
        self.bricks.iter()
    }

    /// Bytes the resident bricks hold (as of the last [`BrickMap::recount`]).
    pub fn resident_bytes(&self) -> usize {
        self.resident_bytes
    }

    /// Recounts [`BrickMap::resident_bytes`].
    pub fn recount(&mut self) {
        self.resident_bytes = self.bricks.values().map(|b| b.bytes() + ENTRY_OVERHEAD).sum();
    }

    /// Makes sure the chunks of `keys` are resident (reading spilled ones back), then inserts an empty brick for
    /// every key not yet present. Returns the keys that were new.
    pub fn allocate(&mut self, keys: &FxHashSet<IVec3>) -> Result<Vec<IVec3>, FusionError> {
        let wanted: FxHashSet<IVec3> = keys.iter().map(|&k| chunk_of(k)).filter(|c| self.spilled.contains(c)).collect();
        for chunk in wanted {
            self.read_back(chunk)?;
        }
        let mut new = Vec::new();
        for &key in keys {
            if let std::collections::hash_map::Entry::Vacant(slot) = self.bricks.entry(key) {
                slot.insert(BinaryBrick::default());
                new.push(key);
            }
        }
        Ok(new)
    }

    /// Stores a processed brick (replacing what was there).
    pub fn put(&mut self, key: IVec3, brick: BinaryBrick) {
        self.bricks.insert(key, brick);
    }

    /// Removes the bricks of `keys` that hold no voxel behind the surface; returns how many went.
    pub fn remove_empty(&mut self, keys: &[IVec3]) -> usize {
        let mut removed = 0;
        for key in keys {
            if self.bricks.get(key).is_some_and(|b| b.is_empty() && b.integrated) {
                self.bricks.remove(key);
                removed += 1;
            }
        }
        removed
    }

    /// While the resident bricks hold more than `budget` bytes, writes the chunk farthest from `camera` (and not
    /// within `keep_radius` of it) to disk and drops it, down to ¾ of the budget. Returns the chunks written.
    pub fn stream_out(&mut self, camera: DVec3, keep_radius: f64, budget: usize) -> Result<usize, FusionError> {
        self.recount();
        if self.resident_bytes <= budget {
            return Ok(0);
        }
        let Some(dir) = self.spill_dir.clone() else {
            return Err(FusionError::Budget(format!(
                "the fused scene holds {} MiB of bricks, over --memory {} MiB, and there is nowhere to stream \
                 chunks to; raise --memory or give --out (chunks are streamed next to it)",
                self.resident_bytes >> 20,
                budget >> 20
            )));
        };
        let chunk_edge = self.voxel * f64::from(BRICK * CHUNK_BRICKS);
        let mut by_chunk: FxHashMap<IVec3, usize> = FxHashMap::default();
        for (key, brick) in &self.bricks {
            *by_chunk.entry(chunk_of(*key)).or_default() += brick.bytes() + ENTRY_OVERHEAD;
        }
        let mut far: Vec<(f64, IVec3, usize)> = by_chunk
            .into_iter()
            .map(|(chunk, bytes)| {
                let centre = (chunk.as_dvec3() + DVec3::splat(0.5)) * chunk_edge;
                (centre.distance(camera), chunk, bytes)
            })
            .filter(|(distance, _, _)| *distance - chunk_edge * 0.87 > keep_radius)
            .collect();
        far.sort_by(|a, b| b.0.total_cmp(&a.0));
        let target = budget / 4 * 3;
        let mut written = 0;
        for (_, chunk, bytes) in far {
            if self.resident_bytes <= target {
                break;
            }
            let keys: Vec<IVec3> = self.bricks.keys().copied().filter(|k| chunk_of(*k) == chunk).collect();
            let bricks: Vec<(IVec3, BinaryBrick)> =
                keys.iter().filter_map(|k| self.bricks.remove(k).map(|b| (*k, b))).collect();
            spill::write_chunk(&dir, chunk, &bricks)?;
            self.spilled.insert(chunk);
            self.resident_bytes -= bytes;
            self.chunks_written += 1;
            written += 1;
        }
        Ok(written)
    }

    /// Reads chunk `chunk` back from disk and makes it resident.
    fn read_back(&mut self, chunk: IVec3) -> Result<(), FusionError> {
        let dir = self.spill_dir.as_ref().expect("a chunk was spilled, so there is a spill folder");
        for (key, brick) in spill::read_chunk(dir, chunk)? {
            self.bricks.insert(key, brick);
        }
        spill::remove_chunk(dir, chunk);
        self.spilled.remove(&chunk);
        self.chunks_read += 1;
        Ok(())
    }

    /// Makes every spilled chunk resident again (for saving the whole scene; the caller has checked that it fits).
    pub fn read_all_back(&mut self) -> Result<(), FusionError> {
        let chunks: Vec<IVec3> = self.spilled.iter().copied().collect();
        for chunk in chunks {
            self.read_back(chunk)?;
        }
        self.recount();
        Ok(())
    }

    /// The smallest and largest brick coordinates of the resident bricks, `None` if there are none.
    pub fn brick_bounds(&self) -> Option<(IVec3, IVec3)> {
        let mut keys = self.bricks.keys();
        let first = *keys.next()?;
        Some(keys.fold((first, first), |(lo, hi), &k| (lo.min(k), hi.max(k))))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn voxels_split_into_bricks_below_zero_too() {
        assert_eq!(BrickMap::split(IVec3::new(-1, 8, 15)), (IVec3::new(-1, 1, 1), IVec3::new(7, 0, 7)));
        assert_eq!(chunk_of(IVec3::new(-1, 31, 32)), IVec3::new(-1, 0, 1));
        let map = BrickMap::new(0.01, None);
        assert_eq!(map.voxel_of(DVec3::new(-0.001, 0.0, 0.0199)), IVec3::new(-1, 0, 1));
    }

    #[test]
    fn over_budget_without_a_folder_is_an_error_and_with_one_far_chunks_go_and_come_back() {
        let mut keys = FxHashSet::default();
        for x in 0..4 {
            keys.insert(IVec3::new(x * CHUNK_BRICKS, 0, 0));
        }
        let mut map = BrickMap::new(0.01, None);
        map.allocate(&keys).unwrap();
        for key in keys.iter() {
            map.brick_mut(*key).unwrap().inside.set(3, true);
        }
        assert!(matches!(map.stream_out(DVec3::ZERO, 0.5, 100), Err(FusionError::Budget(_))));

        let dir = std::env::temp_dir().join(format!("voxstream-fusion-map-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let mut map = BrickMap::new(0.01, Some(dir.clone()));
        map.allocate(&keys).unwrap();
        for key in keys.iter() {
            map.brick_mut(*key).unwrap().inside.set(3, true);
        }
        map.recount();
        let all = map.resident_bytes();
        // Room for about one chunk: the three farther from the camera at x = 0 go, the nearest stays.
        let written = map.stream_out(DVec3::ZERO, 0.5, all / 3).unwrap();
        assert_eq!(written, 3);
        assert_eq!(map.len(), 1);
        assert!(map.brick(IVec3::ZERO).is_some());
        assert!(!map.inside(IVec3::new(3 * CHUNK_BRICKS * BRICK + 3, 0, 0), false), "not resident");
        // Touching a spilled chunk reads it back with its bits.
        let far = IVec3::new(3 * CHUNK_BRICKS, 0, 0);
        let new = map.allocate(&[far].into_iter().collect()).unwrap();
        assert!(new.is_empty(), "the brick came back, it is not new");
        assert!(map.brick(far).unwrap().inside.get(3));
        assert_eq!((map.chunks_written, map.chunks_read, map.spilled_chunks()), (3, 1, 2));
        map.read_all_back().unwrap();
        assert_eq!(map.len(), 4);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
