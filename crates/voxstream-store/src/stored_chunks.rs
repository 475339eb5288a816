//! Counting the chunks a foreign store holds, for `voxstream info`: work proportional to the files that exist, never
//! to the chunks the metadata declares (a 2^20³ shape with no chunks declares 3.5·10¹³ bricks of 32³).
//!
//! A native store's per-brick min/max arrays already say which bricks hold data (and were checked against their
//! files' sizes at open); a foreign store has no such record, so its dataset folders are listed instead.

use std::path::Path;

use crate::error::StoreError;
use crate::level_source::LevelSource;
use crate::metadata_files::METADATA_FILE_NAMES;
use crate::store_reader::StoreReader;

/// The chunks of the dataset behind one level of a foreign store.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LevelChunks {
    /// The dataset's path inside the store (`0`, `s1`, …).
    pub dataset: String,
    /// Chunks (or shards) its chunk grid declares, saturating at `u64::MAX`.
    pub declared: u64,
    /// Chunk (or shard) files present in its folder; `None` for a remote store that cannot be listed (HTTP).
    pub stored: Option<u64>,
}

/// Whether `folder` holds a Zarr node of its own (a nested array or group, whose files are not this array's).
fn is_node(folder: &Path) -> bool {
    METADATA_FILE_NAMES.iter().any(|name| folder.join(name).exists())
}

/// Regular files under `folder`, at any depth, other than metadata files and nested nodes' files; symbolic links
/// to folders are not followed (a link cycle cannot loop).
fn count_chunk_files(folder: &Path) -> Result<u64, StoreError> {
    let mut count = 0;
    let mut pending = vec![folder.to_path_buf()];
    while let Some(dir) = pending.pop() {
        let entries = match std::fs::read_dir(&dir) {
            Ok(entries) => entries,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => continue,
            Err(e) => return Err(StoreError::io(&dir, e)),
        };
        for entry in entries {
            let entry = entry.map_err(|e| StoreError::io(&dir, e))?;
            let kind = entry.file_type().map_err(|e| StoreError::io(entry.path(), e))?;
            if kind.is_dir() {
                if !is_node(&entry.path()) {
                    pending.push(entry.path());
                }
            } else if !METADATA_FILE_NAMES.iter().any(|name| entry.file_name() == *name) {
                count += 1;
            }
        }
    }
    Ok(count)
}

impl StoreReader {
    /// Chunks declared and stored for `level` of a foreign store; `None` for native stores and for levels averaged
    /// from the level below (nothing stored).
    pub fn stored_chunks(&self, level: usize) -> Result<Option<LevelChunks>, StoreError> {
        if self.is_native() {
            return Ok(None);
        }
        let Some(LevelSource::Array { array, .. }) = self.level_source(level) else {
            return Ok(None);
        };
        let dataset = array.path().as_str().trim_start_matches('/').to_string();
        let declared = array.chunk_grid_shape().iter().fold(1u64, |n, &d| n.saturating_mul(d));
        let stored = match self.remote() {
            Some(remote) => remote
                .list(&dataset, usize::MAX)
                .map_err(|e| StoreError::store(self.path(), e.to_string()))?
                .map(|keys| {
                    let is_chunk = |key: &&String| {
                        let file = key.rsplit('/').next().unwrap_or(key);
                        !METADATA_FILE_NAMES.contains(&file)
                    };
                    keys.iter().filter(is_chunk).count() as u64
                }),
            None => Some(count_chunk_files(&self.path().join(&dataset))?),
        };
        Ok(Some(LevelChunks { dataset, declared, stored }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chunk_files_are_counted_without_metadata_or_nested_nodes() {
        let dir = std::env::temp_dir().join(format!("voxstream-stored-chunks-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        for folder in ["c/0/0", "c/1/0", "nested"] {
            std::fs::create_dir_all(dir.join(folder)).unwrap();
        }
        for file in ["zarr.json", "c/0/0/0", "c/0/0/1", "c/1/0/0", "nested/zarr.json", "nested/0"] {
            std::fs::write(dir.join(file), b"x").unwrap();
        }
        assert_eq!(count_chunk_files(&dir).unwrap(), 3);
        assert_eq!(count_chunk_files(&dir.join("absent")).unwrap(), 0);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
