//! The size cap on a store's Zarr metadata files, checked before zarrs reads them.
//!
//! zarrs reads a node's metadata itself (`zarr.json`, or Zarr v2's `.zarray` / `.zgroup` with `.zattrs`) and parses
//! it whole, so the store reader stats those files of each node (the root group, each level or dataset, each min/max
//! array) before handing the node to zarrs: each must be a regular file (a FIFO would block zarrs forever) of at most
//! [`MAX_JSON_BYTES`](voxstream_core::json_limits::MAX_JSON_BYTES) (4 MiB).

use std::path::Path;

use voxstream_core::json_limits::check_json_file;

use crate::error::StoreError;

/// The metadata files zarrs may read for one node (Zarr v3, then v2's array, group and attributes files).
pub const METADATA_FILE_NAMES: [&str; 4] = ["zarr.json", ".zarray", ".zgroup", ".zattrs"];

/// Checks the metadata files of node `node` (a path inside the store such as `""`, `"0"` or `"/s1"`) of the store
/// at `store`: those present must be regular files within the JSON cap; absent ones are left to zarrs to report.
pub fn check_node_metadata(store: &Path, node: &str) -> Result<(), StoreError> {
    let folder = store.join(node.trim_matches('/'));
    for name in METADATA_FILE_NAMES {
        let file = folder.join(name);
        match std::fs::symlink_metadata(&file) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => continue,
            _ => {
                check_json_file(&file, "Zarr metadata")?;
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxstream_core::json_limits::MAX_JSON_BYTES;

    #[test]
    fn each_metadata_file_of_a_node_is_held_to_the_cap_before_it_is_read() {
        let store = std::env::temp_dir().join(format!("voxstream-metadata-files-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&store);
        std::fs::create_dir_all(store.join("s1")).unwrap();
        std::fs::write(store.join("zarr.json"), "{}").unwrap();
        assert!(check_node_metadata(&store, "").is_ok());
        assert!(check_node_metadata(&store, "/s1").is_ok(), "absent files are zarrs' to report");
        for name in METADATA_FILE_NAMES {
            let file = store.join("s1").join(name);
            std::fs::File::create(&file).unwrap().set_len(MAX_JSON_BYTES + 1).unwrap();
            let message = check_node_metadata(&store, "/s1").unwrap_err().to_string();
            assert!(message.contains(&format!("s1/{name}")) && message.contains("cap"), "{message}");
            std::fs::remove_file(&file).unwrap();
            std::fs::create_dir(&file).unwrap();
            let message = check_node_metadata(&store, "/s1").unwrap_err().to_string();
            assert!(message.contains("not a regular file"), "{message}");
            std::fs::remove_dir(&file).unwrap();
        }
        std::fs::remove_dir_all(&store).unwrap();
    }
}
