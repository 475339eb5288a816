//! The size cap on every JSON file voxstream reads: a store's Zarr metadata (`zarr.json`, `.zattrs`, `.zarray`,
//! `.zgroup`), transfer functions, camera paths and cameras.
//!
//! Parsing JSON into a tree takes many times the text's size in memory (a 75 MB `zarr.json` took 1.3 GiB, a 72 MB
//! transfer function 3 GiB), so the cap is checked on the file's size before a byte of it is read, and the read
//! itself stops one byte past the cap (a file that grows meanwhile, or a pipe, is held to it too). The real files
//! are kilobytes: the largest voxstream meets are ParaView colour-map collections, about 1 MB.

use std::io::Read;
use std::path::{Path, PathBuf};

use thiserror::Error;

/// Largest JSON file voxstream reads, bytes (4 MiB).
pub const MAX_JSON_BYTES: u64 = 4 << 20;

/// Why a JSON file was not read.
#[derive(Debug, Error)]
pub enum JsonFileError {
    /// The file is larger than [`MAX_JSON_BYTES`].
    #[error(
        "{path}: {what} of {size} bytes is over the {MAX_JSON_BYTES}-byte (4 MiB) cap on JSON inputs; real ones are \
         kilobytes: check that this is the intended file"
    )]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// What the file is (`transfer function`, `zarr metadata`, …).
        what: String,
        /// Its size (or, for a pipe, the bytes read before stopping).
        size: u64,
    },
    /// Store metadata that is not a regular file (a FIFO would block the reader forever, a device never end).
    #[error("{path}: {what} is not a regular file; replace it with the file itself")]
    NotAFile {
        /// The file.
        path: PathBuf,
        /// What the file is.
        what: String,
    },
    /// The file could not be read.
    #[error("cannot read {what} {path}: {}", crate::io_message::describe_io(.error))]
    Io {
        /// The file.
        path: PathBuf,
        /// What the file is.
        what: String,
        /// The I/O error.
        error: std::io::Error,
    },
}

/// Checks, without reading it, that the file at `path` (a `what`) is a regular file of at most [`MAX_JSON_BYTES`];
/// returns its size. For files another reader (zarrs) opens after this check.
pub fn check_json_file(path: &Path, what: &str) -> Result<u64, JsonFileError> {
    let metadata =
        std::fs::metadata(path).map_err(|error| JsonFileError::Io { path: path.into(), what: what.into(), error })?;
    if !metadata.is_file() {
        return Err(JsonFileError::NotAFile { path: path.into(), what: what.into() });
    }
    if metadata.len() > MAX_JSON_BYTES {
        return Err(JsonFileError::TooLarge { path: path.into(), what: what.into(), size: metadata.len() });
    }
    Ok(metadata.len())
}

/// Reads the JSON text of `path` (a `what`), refusing it past [`MAX_JSON_BYTES`]: a regular file by its size before
/// reading, anything else (a pipe from process substitution) by reading at most one byte past the cap.
pub fn read_json_file(path: &Path, what: &str) -> Result<String, JsonFileError> {
    let io = |error| JsonFileError::Io { path: path.into(), what: what.into(), error };
    let metadata = std::fs::metadata(path).map_err(io)?;
    if metadata.is_file() && metadata.len() > MAX_JSON_BYTES {
        return Err(JsonFileError::TooLarge { path: path.into(), what: what.into(), size: metadata.len() });
    }
    let file = std::fs::File::open(path).map_err(io)?;
    let mut bytes = Vec::new();
    file.take(MAX_JSON_BYTES + 1).read_to_end(&mut bytes).map_err(io)?;
    if bytes.len() as u64 > MAX_JSON_BYTES {
        return Err(JsonFileError::TooLarge { path: path.into(), what: what.into(), size: bytes.len() as u64 });
    }
    String::from_utf8(bytes).map_err(|e| io(std::io::Error::new(std::io::ErrorKind::InvalidData, e.utf8_error())))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("voxstream-json-limits-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn a_file_over_the_cap_is_refused_by_its_size_and_one_at_the_cap_is_read() {
        let dir = scratch("cap");
        let at_cap = dir.join("at.json");
        std::fs::write(&at_cap, vec![b' '; MAX_JSON_BYTES as usize]).unwrap();
        assert_eq!(check_json_file(&at_cap, "test").unwrap(), MAX_JSON_BYTES);
        assert_eq!(read_json_file(&at_cap, "test").unwrap().len() as u64, MAX_JSON_BYTES);
        // A sparse file: a huge size costs no disk, and must cost no memory either.
        let over = dir.join("over.json");
        std::fs::File::create(&over).unwrap().set_len(1 << 40).unwrap();
        for error in [check_json_file(&over, "transfer function").unwrap_err(), read_json_file(&over, "x").unwrap_err()]
        {
            let message = error.to_string();
            assert!(matches!(error, JsonFileError::TooLarge { size, .. } if size == 1 << 40), "{message}");
            assert!(message.contains("over.json") && message.contains("4 MiB"), "{message}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn store_metadata_must_be_a_regular_file() {
        let dir = scratch("folder");
        let error = check_json_file(&dir, "zarr metadata").unwrap_err();
        assert!(matches!(error, JsonFileError::NotAFile { .. }), "{error}");
        assert!(matches!(check_json_file(&dir.join("none"), "x"), Err(JsonFileError::Io { .. })));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
