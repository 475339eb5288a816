//! The engine's errors: those of the crates it drives, passed through unchanged, and its own.

use voxstream_core::CoreError;
use voxstream_render::RenderError;

/// What can go wrong when a session is built or renders.
#[derive(Debug, thiserror::Error)]
pub enum EngineError {
    /// The cache could not be built (for instance, a budget too small for the pools).
    #[error(transparent)]
    Core(#[from] CoreError),
    /// The render settings or camera were refused.
    #[error(transparent)]
    Render(#[from] RenderError),
    /// A render was asked for zero frames.
    #[error("at least one frame is needed")]
    NoFrames,
    /// New settings moved the volume in the world, which a session cannot follow (its transfer function's unit
    /// distance was derived from the placement): start a new session instead.
    #[error("the volume's placement cannot change within a session; start a new session")]
    PlacementChanged,
}
