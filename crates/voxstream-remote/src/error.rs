//! Why a remote store could not be opened or read. Every message names the location as shown (no credentials) and,
//! where there is one, the likely fix.

use thiserror::Error;

/// An error opening or reading a remote store.
#[derive(Debug, Error)]
pub enum RemoteError {
    /// The location is not a URL voxstream reads.
    #[error("{url}: {problem}")]
    BadUrl {
        /// The location, redacted.
        url: String,
        /// What is wrong with it.
        problem: String,
    },
    /// The client could not be set up (a bad endpoint or region, unreadable credentials).
    #[error("{url}: cannot set up the client: {problem}")]
    Client {
        /// The location, redacted.
        url: String,
        /// Why.
        problem: String,
    },
    /// A store cannot be written there.
    #[error("{url}: {problem}")]
    NotWritable {
        /// The location, redacted.
        url: String,
        /// Why, and what to do instead.
        problem: String,
    },
    /// Writing a store's objects failed.
    #[error("{url}: {problem}")]
    Upload {
        /// The location (and object), redacted.
        url: String,
        /// What failed, and what was left.
        problem: String,
    },
    /// A profile file could not be read.
    #[error("{path}: {problem}")]
    Profile {
        /// The profile file.
        path: String,
        /// Why.
        problem: String,
    },
}
