//! Typed errors of the store crate: each names the file and the problem.

use std::path::PathBuf;

use thiserror::Error;

/// Errors of importers, the store and the streaming producer.
#[derive(Debug, Error)]
pub enum StoreError {
    /// The file could not be read or written.
    #[error("{path}: {}", describe_io(.error))]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error (in the message, not a `source`, so that a chain of contexts does not print it twice).
        error: std::io::Error,
    },
    /// The header is malformed or inconsistent.
    #[error("{path}: {message}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The file ends before all the samples its header announces.
    #[error("{path}: truncated: expected {expected} bytes of samples, found only {found}")]
    Truncated {
        /// The file.
        path: PathBuf,
        /// Bytes the header announces.
        expected: u64,
        /// Bytes present.
        found: u64,
    },
    /// A valid file using a feature voxstream does not read.
    #[error("{path}: unsupported: {message}")]
    Unsupported {
        /// The file.
        path: PathBuf,
        /// What is not supported.
        message: String,
    },
    /// A sample is NaN or ±inf: stores hold finite values only (the value range and per-brick min/max depend on it).
    #[error(
        "sample ({x}, {y}, {z}) is {value}: stores hold finite values only (--nan-as VALUE replaces NaN and ±inf)",
        x = position[0],
        y = position[1],
        z = position[2]
    )]
    NonFinite {
        /// The offending value (NaN, inf or -inf).
        value: f32,
        /// Its sample position (x, y, z) at level 0.
        position: [u64; 3],
    },
    /// The Zarr store is missing, incomplete or corrupt.
    #[error("{path}: {message}")]
    Store {
        /// The store.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A field of the store's metadata is out of range or disagrees with the rest of the store.
    #[error("{path}: invalid store metadata: {field} {problem}")]
    Metadata {
        /// The store.
        path: PathBuf,
        /// The field, as named in `zarr.json` (`brick_size`, `value_range`, …).
        field: String,
        /// What is wrong with it, and the fix where there is one.
        problem: String,
    },
    /// Another import holds the store's lock (see [`crate::store_lock`]).
    #[error(
        "another import is writing {path}{}; wait for it to finish (or stop it), then run this import again",
        .pid.map(|pid| format!(" (pid {pid})")).unwrap_or_default(),
        path = .path.display()
    )]
    Busy {
        /// The store.
        path: PathBuf,
        /// The process holding the lock, as its lock file says.
        pid: Option<u32>,
    },
    /// A JSON file (store metadata) over the size cap, or not a regular file.
    #[error(transparent)]
    JsonFile(#[from] voxstream_core::json_limits::JsonFileError),
}

impl StoreError {
    /// A format error for `path`.
    pub fn format(path: impl Into<PathBuf>, message: impl Into<String>) -> StoreError {
        StoreError::Format { path: path.into(), message: message.into() }
    }

    /// An I/O error for `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> StoreError {
        StoreError::Io { path: path.into(), error: source }
    }

    /// An invalid metadata `field` of the store at `path`.
    pub fn metadata(path: impl Into<PathBuf>, field: impl Into<String>, problem: impl Into<String>) -> StoreError {
        StoreError::Metadata { path: path.into(), field: field.into(), problem: problem.into() }
    }

    /// A store error for `path`.
    pub fn store(path: impl Into<PathBuf>, message: impl Into<String>) -> StoreError {
        StoreError::Store { path: path.into(), message: message.into() }
    }
}

pub use voxstream_core::io_message::describe_io;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn io_errors_read_once_and_without_os_numbers() {
        let error = StoreError::io("/x/y", std::io::Error::from_raw_os_error(20));
        assert_eq!(error.to_string(), "/x/y: Not a directory");
        assert!(std::error::Error::source(&error).is_none(), "the message already holds the cause");
        let missing = StoreError::io("/x/y", std::io::Error::from(std::io::ErrorKind::NotFound));
        assert_eq!(missing.to_string(), "/x/y: not found");
    }
}
