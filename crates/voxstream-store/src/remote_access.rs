//! How a remote store is to be read (issue 43): the client's timeouts and retries, and the on-disk cache of fetched
//! bytes. A store path that is a URL (`https://…`, `s3://…`, `gs://…`, `az://…`) is opened through
//! [`voxstream_remote::RemoteStore`] wherever a folder would be (see [`crate::StoreReader::open_with_options`]).

use std::path::PathBuf;

use voxstream_remote::RemoteOptions;

/// Default limit of the on-disk cache (`--cache-mb`): 4 GiB.
pub const DEFAULT_DISK_CACHE_BYTES: u64 = 4 << 30;

/// How a remote store is read.
#[derive(Clone, Debug)]
pub struct RemoteAccess {
    /// Timeouts, retries and caps of the client.
    pub options: RemoteOptions,
    /// The folder fetched bytes are kept in (`--cache-dir`); none by default.
    pub cache_dir: Option<PathBuf>,
    /// The most bytes the cache folder holds.
    pub cache_limit_bytes: u64,
    /// Any native store, local or remote: the bytes of bricks kept in memory as stored (compressed), besides the
    /// host cache (`--compressed-cache-mb`); `None` gives that cache half of the host cache instead.
    pub compressed_cache_bytes: Option<u64>,
}

impl Default for RemoteAccess {
    fn default() -> Self {
        RemoteAccess {
            options: RemoteOptions::default(),
            cache_dir: None,
            cache_limit_bytes: DEFAULT_DISK_CACHE_BYTES,
            compressed_cache_bytes: None,
        }
    }
}
