//! Shared driver of the import fuzz targets: the fuzz input becomes a file with the format's extension, which is
//! opened by the importer and, if its header is accepted, imported into a scratch store as `voxstream import` would.
//! Errors are the expected outcome for most inputs; a panic, an abort (an allocation that fails), a hang or a run
//! past libFuzzer's `-rss_limit_mb` is a finding.

use std::path::{Path, PathBuf};

use voxstream_store::formats::{open_volume, RawLayout};
use voxstream_store::{import_volume, ImportOptions};

/// A scratch folder of this fuzzing process.
pub fn scratch() -> PathBuf {
    let dir = std::env::temp_dir().join(format!("voxstream-fuzz-{}", std::process::id()));
    let _ = std::fs::create_dir_all(&dir);
    dir
}

/// Writes `data` to `input.<extension>` in the scratch folder and imports it (as raw with `raw` if given).
pub fn import_bytes(extension: &str, data: &[u8], raw: Option<&RawLayout>) {
    let dir = scratch();
    let input = dir.join(format!("input.{extension}"));
    if std::fs::write(&input, data).is_err() {
        return;
    }
    import_file(&input, raw, &dir.join("store.zarr"));
}

/// Imports `input` into `store` (removed afterwards); every error is simply an answer.
pub fn import_file(input: &Path, raw: Option<&RawLayout>, store: &Path) {
    let Ok(mut source) = open_volume(input, raw) else { return };
    let options = ImportOptions { brick_size: 8, overwrite: true, ..ImportOptions::default() };
    let _ = import_volume(source.as_mut(), store, &options, &mut |_, _| {});
    let _ = std::fs::remove_dir_all(store);
}

/// The `store_shards` target's driver (also replayed by `crates/voxstream/tests/fuzz_regressions.rs`).
#[path = "shard_input.rs"]
mod shard_input;
pub use shard_input::{edited_shard, read_shard_input as read_shard_input_in};

/// [`read_shard_input_in`] this process's scratch folder.
pub fn read_shard_input(data: &[u8]) {
    let _ = read_shard_input_in(&scratch(), data);
}

/// The metadata files of a foreign image made from fuzz input: the first byte's low bit picks Zarr v3 (`zarr.json`
/// for the group and each dataset) or v2 (`.zgroup` + `.zattrs` for the group, `.zarray` for each dataset); the
/// rest is split at NUL bytes into the group's document, then dataset `0`'s and dataset `1`'s (as
/// `crates/voxstream/tests/fuzz_regressions.rs` replays them).
pub fn foreign_files(data: &[u8]) -> Vec<(String, Vec<u8>)> {
    let Some((&selector, rest)) = data.split_first() else { return Vec::new() };
    let mut documents = rest.splitn(3, |&b| b == 0);
    let is_v2 = selector & 1 == 1;
    let mut files = Vec::new();
    if let Some(group) = documents.next() {
        if is_v2 {
            files.push((".zgroup".to_string(), br#"{"zarr_format": 2}"#.to_vec()));
            files.push((".zattrs".to_string(), group.to_vec()));
        } else {
            files.push(("zarr.json".to_string(), group.to_vec()));
        }
    }
    for (index, document) in documents.enumerate() {
        let name = if is_v2 { ".zarray" } else { "zarr.json" };
        files.push((format!("{index}/{name}"), document.to_vec()));
    }
    files
}

/// Writes [`foreign_files`] of `data` into a fresh store and opens it as `voxstream info` and `render` do (which
/// reads a brick of each level), then counts each level's stored chunks as `info` does.
pub fn open_foreign_bytes(data: &[u8]) {
    let store = scratch().join("foreign.zarr");
    let _ = std::fs::remove_dir_all(&store);
    for (name, bytes) in foreign_files(data) {
        let path = store.join(name);
        if path.parent().is_some_and(|p| std::fs::create_dir_all(p).is_err()) || std::fs::write(&path, bytes).is_err()
        {
            return;
        }
    }
    if let Ok(reader) = voxstream_store::StoreReader::open(&store) {
        for level in 0..reader.layout().levels() {
            let _ = reader.stored_chunks(level);
        }
    }
}
