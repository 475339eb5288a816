//! Typed errors of the store crate: each names the file and the problem.

use std::path::PathBuf;

use thiserror::Error;

/// Errors of importers, the store and the streaming producer.
#[derive(Debug, Error)]
pub enum StoreError {
    /// The file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
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
}

impl StoreError {
    /// A format error for `path`.
    pub fn format(path: impl Into<PathBuf>, message: impl Into<String>) -> StoreError {
        StoreError::Format { path: path.into(), message: message.into() }
    }

    /// An I/O error for `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> StoreError {
        StoreError::Io { path: path.into(), source }
    }

    /// A store error for `path`.
    pub fn store(path: impl Into<PathBuf>, message: impl Into<String>) -> StoreError {
        StoreError::Store { path: path.into(), message: message.into() }
    }
}
