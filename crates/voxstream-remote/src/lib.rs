//! voxstream's remote stores: OME-Zarr (voxstream's own stores and other tools' images) read from where large
//! volumes live, over HTTP(S), S3, GCS and Azure (issue 43; the pools-as-caches design of GigaVoxels [R08] §4 and
//! Reichl's streaming framework, seed 004 ch. 4, with the slowest storage tier being the network).
//!
//! - [`RemoteLocation`]: a URL parsed once, its credentials kept out of everything shown.
//! - [`RemoteStore`]: zarrs's storage traits over `object_store`, one ranged request per brick, retried, checked for
//!   length, bounded, with a deadline; [`RemoteStore::get_ranges`] fetches many ranges at once, abutting ones
//!   merged ([`merged_ranges`]).
//! - [`DiskCache`]: fetched bytes kept on disk within a limit, least recently used out first.
//! - [`StoreUpload`]: a store built in a local folder, written to S3, GCS or Azure, its root metadata last.
//!
//! The store reader (`voxstream-store`) wraps a [`RemoteStore`] in the same checks as a local folder.

pub mod aws_profile;
mod client;
pub mod disk_cache;
pub mod error;
pub mod location;
pub mod merged_ranges;
pub mod remote_store;
pub mod upload;

pub use disk_cache::DiskCache;
pub use error::RemoteError;
pub use location::{is_remote, redact, RemoteLocation, Service};
pub use remote_store::{RemoteCounts, RemoteOptions, RemoteStore};
pub use upload::{StoreUpload, UploadReport};
