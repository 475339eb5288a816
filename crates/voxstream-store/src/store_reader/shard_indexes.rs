//! Shard indexes fetched when a remote store opens (issue 43): a brick of a shard is two round trips, its index
//! (a suffix of the shard) and then its bytes, unless the index is already known. The coarse levels' indexes are
//! few and nearly always all needed (every view starts at the root and refines), so they are fetched at once while
//! the levels are probed, and each later brick of those levels costs one round trip. Only shards holding a brick
//! with data (per the store's min/max) are asked for, coarsest level first, at most [`OPEN_INDEXES`] in all; the
//! finest levels of a large store are left to be fetched as the rays reach them.
//!
//! The index is read through [`CheckedStore`]'s suffix cache with the length zarrs's sharding codec asks for
//! (16 bytes per brick, and 4 for the `crc32c` index codec voxstream writes), so that the first brick read of a
//! shard finds it there. A store whose index is encoded otherwise is left alone: nothing is fetched ahead.
//!
//! The same indexes say where each brick lies in its shard ([`StoreReader::fetch_bricks_by_range`]): a batch of bricks
//! is fetched as byte ranges, those that abut in a shard (neighbours along x, stored one after another) in one
//! request, into the compressed-brick cache the reads that follow are answered from.

use zarrs::storage::StoreKey;

use crate::checked_store::CheckedStore;
use crate::level_source::LevelSource;

use super::background::on_plain_threads;
use super::StoreReader;

/// Most shard indexes fetched at open: with 64 bricks per shard, 256 indexes are 263 KB and cover 16,384 bricks.
pub(super) const OPEN_INDEXES: usize = 256;

/// Threads fetching indexes at open (each waits on one request at a time).
const FETCH_THREADS: usize = 32;

impl StoreReader {
    /// The shards whose indexes [`StoreReader::fetch_shard_indexes`] reads, with the suffix length of their index:
    /// the shards that hold a brick with data, coarsest level first, at most [`OPEN_INDEXES`]; none for a foreign
    /// store or a level whose shard index is not `bytes` + `crc32c` at the end of the shard.
    pub(super) fn shard_indexes_to_fetch(&self) -> Vec<(StoreKey, u64)> {
        let mut wanted = Vec::new();
        for level in (0..self.layout.levels()).rev() {
            let Some(LevelSource::Array { array, .. }) = self.levels.get(level) else { continue };
            let metadata = serde_json::to_value(array.metadata()).unwrap_or_default();
            let Some((shard_bricks, index_bytes)) = shard_geometry(&metadata, self.layout.brick_size) else {
                continue;
            };
            let bricks = self.layout.bricks(level);
            let mut shards = std::collections::BTreeSet::new();
            for z in 0..bricks[2] {
                for y in 0..bricks[1] {
                    for x in 0..bricks[0] {
                        if !self.holds_only_zero(level, [x, y, z]) {
                            // Shard indices in the array's axis order (z, y, x).
                            shards.insert([z / shard_bricks[0], y / shard_bricks[1], x / shard_bricks[2]]);
                        }
                    }
                }
            }
            if wanted.len() + shards.len() > OPEN_INDEXES {
                break;
            }
            wanted.extend(shards.into_iter().map(|shard| (array.chunk_key(&shard), index_bytes)));
        }
        wanted
    }

    /// Reads the indexes `wanted` into `store`'s suffix cache, [`FETCH_THREADS`] at a time. A failure is left alone:
    /// the brick read that needs the index fetches it again and reports what persists.
    pub(super) fn fetch_shard_indexes(store: &CheckedStore, wanted: &[(StoreKey, u64)]) {
        on_plain_threads(wanted, FETCH_THREADS, |(key, length)| {
            let _ = store.shard_index(key, *length);
        });
    }
}

/// A shard's key, the length of its index, and the bricks wanted in it (each its place in the index and its ijk).
type ShardBricks = (StoreKey, u64, Vec<(u64, [u64; 3])>);

impl StoreReader {
    /// Per level, its bricks per shard (z, y, x) and its shard index's length, where [`shard_geometry`] reads them.
    fn shard_geometries(&self) -> &[Option<([u64; 3], u64)>] {
        self.shard_geometries.get_or_init(|| {
            self.levels
                .iter()
                .map(|level| match level {
                    LevelSource::Array { array, .. } => shard_geometry(
                        &serde_json::to_value(array.metadata()).unwrap_or_default(),
                        self.layout.brick_size,
                    ),
                    LevelSource::Synthesized => None,
                })
                .collect()
        })
    }

    /// Remote native stores: fetches `bricks` (level, ijk) as byte ranges of their shards into the compressed-brick
    /// cache, abutting ones in one request (see the module docs): their shards' indexes first where not known yet,
    /// then every brick's range at once. Returns the bricks this could not take (a level whose shards it cannot
    /// read, a shard or index that failed, a brick the index says is empty): the caller reads those brick by brick,
    /// and a failure is reported by that read.
    pub(super) fn fetch_bricks_by_range(&self, bricks: Vec<(usize, [u64; 3])>) -> Vec<(usize, [u64; 3])> {
        let Some(store) = &self.bricks_store else { return bricks };
        let geometries = self.shard_geometries();
        let mut rest = Vec::new();
        // Per shard: its key, its index length, and its bricks' places in the index.
        let mut shards: std::collections::BTreeMap<(usize, [u64; 3]), ShardBricks> = Default::default();
        for (level, ijk) in bricks {
            let (Some(Some((per_shard, index_bytes))), Some(LevelSource::Array { array, .. })) =
                (geometries.get(level), self.levels.get(level))
            else {
                rest.push((level, ijk));
                continue;
            };
            // Shard and inner indices in the array's axis order (z, y, x).
            let zyx = [ijk[2], ijk[1], ijk[0]];
            let shard = [0, 1, 2].map(|a| zyx[a] / per_shard[a]);
            let inner = [0, 1, 2].map(|a| zyx[a] % per_shard[a]);
            let place = (inner[0] * per_shard[1] + inner[1]) * per_shard[2] + inner[2];
            shards
                .entry((level, shard))
                .or_insert_with(|| (array.chunk_key(&shard), *index_bytes, Vec::new()))
                .2
                .push((place, ijk));
        }
        let indexes: Vec<(StoreKey, u64)> = shards.values().map(|(key, length, _)| (key.clone(), *length)).collect();
        StoreReader::fetch_shard_indexes(store, &indexes);
        let mut wanted = Vec::new();
        for (&(level, _), (key, length, places)) in &shards {
            let index = store.shard_index_bytes(key, *length).ok().flatten().filter(|i| i.len() as u64 == *length);
            let mut ranges = Vec::new();
            for &(place, ijk) in places {
                let entry = index.as_ref().and_then(|index| {
                    let at = (place * 16) as usize;
                    let field = |from: usize| Some(u64::from_le_bytes(index.get(from..from + 8)?.try_into().ok()?));
                    Some((field(at)?, field(at + 8)?))
                });
                match entry {
                    Some((offset, length)) if offset != u64::MAX && length != u64::MAX => ranges.push((offset, length)),
                    _ => rest.push((level, ijk)),
                }
            }
            if !ranges.is_empty() {
                wanted.push((key.clone(), ranges));
            }
        }
        store.warm_ranges(wanted);
        rest
    }
}

/// Bricks per shard along (z, y, x) and the encoded length of a shard's index, from a level's `zarr.json`; `None`
/// unless its one codec is `sharding_indexed` with the index at the end, encoded as `bytes` with an optional
/// `crc32c`, and its inner chunks are bricks.
fn shard_geometry(metadata: &serde_json::Value, brick_size: u64) -> Option<([u64; 3], u64)> {
    let codecs = metadata.get("codecs")?.as_array()?;
    let [sharding] = &codecs[..] else { return None };
    if sharding.get("name")?.as_str()? != "sharding_indexed" {
        return None;
    }
    let configuration = sharding.get("configuration")?;
    if configuration.get("index_location").and_then(|l| l.as_str()).unwrap_or("end") != "end" {
        return None;
    }
    let inner: Vec<u64> = configuration.get("chunk_shape")?.as_array()?.iter().filter_map(|v| v.as_u64()).collect();
    let outer: Vec<u64> = metadata
        .get("chunk_grid")?
        .get("configuration")?
        .get("chunk_shape")?
        .as_array()?
        .iter()
        .filter_map(|v| v.as_u64())
        .collect();
    if inner != [brick_size; 3] || outer.len() != 3 || outer.iter().any(|&edge| edge == 0 || edge % brick_size != 0) {
        return None;
    }
    let mut checksum = 0;
    for codec in configuration.get("index_codecs")?.as_array()? {
        match codec.get("name")?.as_str()? {
            "bytes" => {}
            "crc32c" if checksum == 0 => checksum = 4,
            _ => return None,
        }
    }
    let shard_bricks = [0, 1, 2].map(|a| outer[a] / brick_size);
    let count = shard_bricks.iter().try_fold(1u64, |n, &b| n.checked_mul(b))?;
    Some((shard_bricks, count.checked_mul(16)?.checked_add(checksum)?))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn level_metadata(index_codecs: &str, index_location: &str) -> serde_json::Value {
        serde_json::from_str(&format!(
            r#"{{"chunk_grid": {{"name": "regular", "configuration": {{"chunk_shape": [32, 256, 256]}}}},
                "codecs": [{{"name": "sharding_indexed", "configuration": {{"chunk_shape": [32, 32, 32],
                  "codecs": [{{"name": "bytes"}}], "index_codecs": {index_codecs},
                  "index_location": "{index_location}"}}}}]}}"#
        ))
        .unwrap()
    }

    #[test]
    fn the_index_length_is_sixteen_bytes_a_brick_and_the_checksum() {
        let with_crc = level_metadata(r#"[{"name": "bytes"}, {"name": "crc32c"}]"#, "end");
        assert_eq!(shard_geometry(&with_crc, 32), Some(([1, 8, 8], 64 * 16 + 4)));
        let bare = level_metadata(r#"[{"name": "bytes"}]"#, "end");
        assert_eq!(shard_geometry(&bare, 32), Some(([1, 8, 8], 64 * 16)));
        // Anything else is left alone: the index at the start, another index codec, inner chunks not bricks.
        assert_eq!(shard_geometry(&level_metadata(r#"[{"name": "bytes"}]"#, "start"), 32), None);
        assert_eq!(shard_geometry(&level_metadata(r#"[{"name": "bytes"}, {"name": "zstd"}]"#, "end"), 32), None);
        assert_eq!(shard_geometry(&with_crc, 16), None);
        assert_eq!(shard_geometry(&serde_json::json!({"codecs": [{"name": "zstd"}]}), 32), None);
    }
}
