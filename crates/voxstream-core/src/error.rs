//! Typed errors of the core crate.

use thiserror::Error;

/// Errors raised while configuring the tree, the pools or the cache.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum CoreError {
    /// N, brick size or depth out of range.
    #[error("invalid tree shape: {0}")]
    InvalidShape(String),
    /// The memory budget cannot hold the minimum working set.
    #[error("memory budget of {budget_bytes} bytes is too small: at least {minimum_bytes} bytes are needed")]
    BudgetTooSmall {
        /// The budget asked for.
        budget_bytes: u64,
        /// The smallest budget that works for this tree shape.
        minimum_bytes: u64,
    },
}

/// Error a producer reports for one node; the cache manager records it and lets the ancestor stand in.
#[derive(Debug, Error, Clone, PartialEq, Eq)]
#[error("producing node at level {level} {ijk:?} failed: {message}")]
pub struct ProduceError {
    /// Level of the node.
    pub level: u32,
    /// Coordinates of the node.
    pub ijk: [u64; 3],
    /// What went wrong.
    pub message: String,
}
