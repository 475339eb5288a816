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
