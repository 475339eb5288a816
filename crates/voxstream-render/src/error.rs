//! Typed errors of the render crate.

use thiserror::Error;

/// Invalid render inputs: camera, transfer function, settings.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum RenderError {
    /// The camera cannot form an image.
    #[error("degenerate camera: {0}")]
    DegenerateCamera(String),
    /// The transfer function is malformed.
    #[error("invalid transfer function: {0}")]
    InvalidTransferFunction(String),
    /// Image size, step or other setting out of range.
    #[error("invalid render setting: {0}")]
    InvalidSetting(String),
    /// A rendering backend (the GPU) failed or cannot draw what was asked.
    #[error("{0}")]
    Backend(String),
}
