//! Typed errors of the geometry crate: each names the file (and line, for text formats) and the problem.

use std::path::PathBuf;

use thiserror::Error;

/// Errors of the mesh and particle readers and of the producers' validation.
#[derive(Debug, Error)]
pub enum GeometryError {
    /// The file could not be read.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        error: std::io::Error,
    },
    /// The file is malformed: `line` is 1-based where the format is text.
    #[error("{path}{}: {message}", line.map(|l| format!(" line {l}")).unwrap_or_default())]
    Format {
        /// The file.
        path: PathBuf,
        /// The line, for text formats.
        line: Option<u64>,
        /// What is wrong.
        message: String,
    },
    /// A valid file using a feature voxstream does not read.
    #[error("{path}: unsupported: {message}")]
    Unsupported {
        /// The file.
        path: PathBuf,
        /// What is not supported.
        message: String,
    },
    /// The data read cannot be rendered (no triangles, NaN coordinates, a negative radius …).
    #[error("{message}")]
    Invalid {
        /// What is wrong and how to fix it.
        message: String,
    },
}

impl GeometryError {
    /// A format error at `line` (or `None` for binary formats).
    pub fn format(path: &std::path::Path, line: Option<u64>, message: impl Into<String>) -> GeometryError {
        GeometryError::Format { path: path.to_path_buf(), line, message: message.into() }
    }
}
