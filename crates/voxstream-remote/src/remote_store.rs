//! A read-only Zarr store over HTTP(S), S3, GCS or Azure: zarrs's synchronous storage traits on top of
//! `object_store`'s asynchronous clients, with every byte checked before it reaches a decoder.
//!
//! - **No request but the read.** A brick is one ranged GET (a shard's inner chunk by its offset and length, a shard
//!   index by a suffix range); no size request goes before it (zarrs's own `object_store` adapter sends a HEAD per
//!   read). Several ranges of one call are fetched concurrently. Callers that want many bricks at once call from many
//!   threads: each call blocks only its own thread.
//! - **Faults are retried, then reported.** 5xx, 429, connection resets and timeouts are retried with exponential
//!   backoff by the client (`RetryConfig`), a body cut short mid-stream is resumed when the server sends an ETag, and a
//!   body whose length is not the length asked for (a proxy that truncates, a `Content-Length` lie) is fetched again
//!   here, up to `retries` times, then reported as an error: never handed to the decoder. Each request has a
//!   timeout, and the whole read a deadline, so a server that stops answering ends in an error, never a hang.
//! - **Bounded.** An explicit range is never longer than the caller's bound (checked before the request); a whole
//!   value (metadata, unsharded chunks) is read as a stream and stops one byte past its cap (Zarr metadata files:
//!   `max_metadata_bytes`; others `max_value_bytes`).
//! - **Cached on disk** where a [`crate::DiskCache`] is given: a second run over the same store reads there first.
//! - **No secrets out.** Errors and statistics name [`RemoteLocation::shown`]; HTTP credentials go in a header
//!   marked sensitive.

use std::ops::Range;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use bytes::Bytes;
use futures::StreamExt;
use object_store::path::Path as ObjectPath;
use object_store::{GetOptions, GetRange, ObjectStore, ObjectStoreExt};
use zarrs_storage::byte_range::{ByteRange, ByteRangeIterator};
use zarrs_storage::{MaybeBytesIterator, ReadableStorageTraits, StorageError, StoreKey};

use crate::client::{build_client, client_runtime};
use crate::disk_cache::DiskCache;
use crate::error::RemoteError;
use crate::location::RemoteLocation;

/// Requests in flight by default (tensorstore's default is 32, Neuroglancer allows 100). Measured on a 2048³ store
/// at 50 ms per round trip (BENCHMARKS.md, "Remote stores"): a complete view in 50 s with 32, 31 s with 64, 22 s
/// with 128, 15 s with 256; 128 keeps a plain HTTP server's default connection limits in view.
pub const DEFAULT_CONCURRENCY: usize = 128;

/// How a remote store is read.
#[derive(Clone, Debug)]
pub struct RemoteOptions {
    /// The longest one request may take, body included, before it is retried.
    pub request_timeout: Duration,
    /// The longest a connection may take to open.
    pub connect_timeout: Duration,
    /// Retries of a failed or truncated request (5xx, 429, resets, timeouts, short bodies).
    pub retries: usize,
    /// The most bytes a whole-value read of a Zarr metadata file (`zarr.json`, `.zattrs`, `.zarray`, `.zgroup`)
    /// takes.
    pub max_metadata_bytes: u64,
    /// The most bytes any other whole-value read takes (an unsharded chunk).
    pub max_value_bytes: u64,
    /// Requests a reader keeps in flight at once (its fetching threads; see `Producer::concurrency`).
    pub concurrency: usize,
}

impl Default for RemoteOptions {
    fn default() -> Self {
        RemoteOptions {
            request_timeout: Duration::from_secs(30),
            connect_timeout: Duration::from_secs(10),
            retries: 5,
            max_metadata_bytes: 4 << 20,
            max_value_bytes: 1 << 30,
            concurrency: DEFAULT_CONCURRENCY,
        }
    }
}

/// What a remote store has done so far (for `--stats`).
#[derive(Debug, Default)]
pub struct RemoteStats {
    /// Requests that returned bytes or a definite "not found".
    pub requests: AtomicU64,
    /// Bytes received in bodies that were used.
    pub bytes: AtomicU64,
    /// Requests sent again here after a short body or a transport error.
    pub retries: AtomicU64,
    /// Reads that failed after every retry.
    pub failures: AtomicU64,
    /// Reads answered from the disk cache.
    pub cache_hits: AtomicU64,
}

/// A snapshot of [`RemoteStats`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RemoteCounts {
    /// See [`RemoteStats::requests`].
    pub requests: u64,
    /// See [`RemoteStats::bytes`].
    pub bytes: u64,
    /// See [`RemoteStats::retries`].
    pub retries: u64,
    /// See [`RemoteStats::failures`].
    pub failures: u64,
    /// See [`RemoteStats::cache_hits`].
    pub cache_hits: u64,
}

/// A remote Zarr store, read through zarrs's [`ReadableStorageTraits`].
pub struct RemoteStore {
    store: Arc<dyn ObjectStore>,
    location: RemoteLocation,
    options: RemoteOptions,
    pub(crate) runtime: tokio::runtime::Runtime,
    stats: RemoteStats,
    cache: Option<DiskCache>,
    /// Merged requests in flight across every [`RemoteStore::get_ranges`] call, at most `options.concurrency`.
    pub(crate) permits: tokio::sync::Semaphore,
}

impl std::fmt::Debug for RemoteStore {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RemoteStore").field("location", &self.location.shown()).finish()
    }
}

/// Whether a key names Zarr metadata (held to `max_metadata_bytes`).
fn is_metadata_key(key: &str) -> bool {
    let name = key.rsplit('/').next().unwrap_or(key);
    matches!(name, "zarr.json" | ".zattrs" | ".zarray" | ".zgroup")
}

/// The outcome of one fetch: bytes, or "there is no such value".
///
/// Retries: the client retries failed requests (5xx, 429, timeouts, resets before a response) with backoff, and
/// resumes a body cut mid-stream where the server sends an ETag; [`RemoteStore::fetch`] retries what is left, a
/// body that ended early or is not the length asked for.
pub(crate) enum Fetched {
    Bytes(Bytes),
    Missing,
}

impl RemoteStore {
    /// A store reading `location` with `options`, its fetched bytes kept in `cache` where given.
    pub fn open(
        location: RemoteLocation,
        options: RemoteOptions,
        cache: Option<DiskCache>,
    ) -> Result<RemoteStore, RemoteError> {
        let store = build_client(&location, &options)?;
        let runtime = client_runtime(&location, "voxstream-remote")?;
        let permits = tokio::sync::Semaphore::new(options.concurrency.max(1));
        Ok(RemoteStore { store, location, options, runtime, stats: RemoteStats::default(), cache, permits })
    }

    /// Where the store is (as shown: no credentials).
    pub fn location(&self) -> &RemoteLocation {
        &self.location
    }

    /// Requests to keep in flight at once.
    pub fn concurrency(&self) -> usize {
        self.options.concurrency
    }

    /// Counts so far.
    pub fn counts(&self) -> RemoteCounts {
        let s = &self.stats;
        RemoteCounts {
            requests: s.requests.load(Ordering::Relaxed),
            bytes: s.bytes.load(Ordering::Relaxed),
            retries: s.retries.load(Ordering::Relaxed),
            failures: s.failures.load(Ordering::Relaxed),
            cache_hits: s.cache_hits.load(Ordering::Relaxed),
        }
    }

    fn object_path(&self, key: &str) -> ObjectPath {
        if self.location.prefix.is_empty() {
            ObjectPath::from(key)
        } else {
            ObjectPath::from(format!("{}/{key}", self.location.prefix))
        }
    }

    pub(crate) fn error(&self, key: &str, problem: impl std::fmt::Display) -> StorageError {
        StorageError::Other(format!("{}/{key}: {problem}", self.location.shown()))
    }

    /// The message for a client error, with the fix where one is likely.
    fn describe(&self, key: &str, error: &object_store::Error) -> StorageError {
        self.error(key, explain(&self.location, error))
    }

    /// Fetches `range` of `key` (whole value when `None`), from the disk cache where it is, checked for length,
    /// retried on short bodies and transport errors.
    async fn fetch(&self, key: &str, range: Option<GetRange>) -> Result<Fetched, StorageError> {
        self.fetch_capped(key, range, u64::MAX).await
    }

    /// [`RemoteStore::fetch`] with a whole value held to at most `limit` bytes (and the store's own cap).
    async fn fetch_capped(&self, key: &str, range: Option<GetRange>, limit: u64) -> Result<Fetched, StorageError> {
        if let Some(bytes) = self.cached_on_disk(key, &range) {
            return Ok(Fetched::Bytes(bytes));
        }
        let fetched = self.fetch_uncached(key, range.clone(), limit).await?;
        if let Fetched::Bytes(bytes) = &fetched {
            // Metadata is always read fresh (it says what the bytes mean); bricks and chunks are cached.
            if !is_metadata_key(key) {
                self.keep_on_disk(key, &range, bytes);
            }
        }
        Ok(fetched)
    }

    /// The name of `range` of `key` in the disk cache.
    fn disk_cache_key(&self, key: &str, range: &Option<GetRange>) -> String {
        format!("{}/{key}#{range:?}", self.location.shown())
    }

    /// `range` of `key` from the disk cache, where there is one and it holds it (counted as a hit).
    pub(crate) fn cached_on_disk(&self, key: &str, range: &Option<GetRange>) -> Option<Bytes> {
        let bytes = self.cache.as_ref()?.get(&self.disk_cache_key(key, range))?;
        self.stats.cache_hits.fetch_add(1, Ordering::Relaxed);
        Some(bytes)
    }

    /// Keeps `bytes`, `range` of `key`, in the disk cache where there is one.
    pub(crate) fn keep_on_disk(&self, key: &str, range: &Option<GetRange>, bytes: &Bytes) {
        if let Some(cache) = &self.cache {
            cache.put(&self.disk_cache_key(key, range), bytes);
        }
    }

    /// [`RemoteStore::fetch_capped`] from the network only (the disk cache neither read nor written).
    pub(crate) async fn fetch_uncached(
        &self,
        key: &str,
        range: Option<GetRange>,
        limit: u64,
    ) -> Result<Fetched, StorageError> {
        let path = self.object_path(key);
        let cap = if is_metadata_key(key) { self.options.max_metadata_bytes } else { self.options.max_value_bytes };
        let cap = cap.min(limit);
        let expected = match &range {
            Some(GetRange::Bounded(r)) => Some(r.end - r.start),
            Some(GetRange::Suffix(n)) => Some(*n),
            _ => None,
        };
        let mut last_problem = String::new();
        for attempt in 0..=self.options.retries {
            if attempt > 0 {
                self.stats.retries.fetch_add(1, Ordering::Relaxed);
                let backoff = Duration::from_millis(100u64 << attempt.min(6));
                tokio::time::sleep(backoff).await;
            }
            let options = GetOptions { range: range.clone(), ..GetOptions::default() };
            let result = match self.store.get_opts(&path, options).await {
                Ok(result) => result,
                Err(object_store::Error::NotFound { .. }) => {
                    self.stats.requests.fetch_add(1, Ordering::Relaxed);
                    return Ok(Fetched::Missing);
                }
                Err(
                    e @ (object_store::Error::PermissionDenied { .. } | object_store::Error::Unauthenticated { .. }),
                ) => {
                    self.stats.failures.fetch_add(1, Ordering::Relaxed);
                    return Err(self.describe(key, &e));
                }
                Err(e) => {
                    // The client has already retried what it retries (5xx, 429, timeouts, refused connections):
                    // retrying here too would multiply the attempts and the wait.
                    self.stats.failures.fetch_add(1, Ordering::Relaxed);
                    return Err(self.describe(key, &e));
                }
            };
            if result.meta.size > cap && expected.is_none() {
                self.stats.failures.fetch_add(1, Ordering::Relaxed);
                return Err(
                    self.error(key, format!("{} bytes, over the {cap} bytes such a value may take", result.meta.size))
                );
            }
            let mut body = Vec::new();
            let mut stream = result.into_stream();
            let mut failed = None;
            while let Some(part) = stream.next().await {
                match part {
                    Ok(part) => {
                        body.extend_from_slice(&part);
                        if body.len() as u64 > expected.unwrap_or(cap) {
                            break;
                        }
                    }
                    Err(e) => {
                        failed = Some(self.describe(key, &e).to_string());
                        break;
                    }
                }
            }
            if let Some(problem) = failed {
                last_problem = problem;
                continue;
            }
            let got = body.len() as u64;
            match expected {
                Some(want) if got != want => {
                    last_problem = format!("the server sent {got} bytes for a range of {want}");
                    continue;
                }
                None if got > cap => {
                    self.stats.failures.fetch_add(1, Ordering::Relaxed);
                    return Err(self.error(key, format!("more than the {cap} bytes such a value may take")));
                }
                _ => {}
            }
            self.stats.requests.fetch_add(1, Ordering::Relaxed);
            self.stats.bytes.fetch_add(got, Ordering::Relaxed);
            return Ok(Fetched::Bytes(Bytes::from(body)));
        }
        self.stats.failures.fetch_add(1, Ordering::Relaxed);
        Err(self.error(key, format!("failed after {} retries: {last_problem}", self.options.retries)))
    }

    /// The deadline of one read: every attempt's timeout and backoff, and a margin.
    pub(crate) fn deadline(&self) -> Duration {
        let attempts = self.options.retries as u32 + 1;
        (self.options.request_timeout + Duration::from_secs(7)) * attempts
    }

    fn block_on<T>(
        &self,
        key: &str,
        work: impl std::future::Future<Output = Result<T, StorageError>>,
    ) -> Result<T, StorageError> {
        let deadline = self.deadline();
        self.runtime.block_on(async move {
            match tokio::time::timeout(deadline, work).await {
                Ok(result) => result,
                Err(_) => Err(self.error(key, format!("no answer within {} s", deadline.as_secs()))),
            }
        })
    }

    /// The whole value of `key` (`None` if it is not there), refused as an error past `limit` bytes (before its body
    /// is read where the server says its size): a read ahead of metadata that will say how long the value must be.
    pub fn get_capped(&self, key: &StoreKey, limit: u64) -> Result<Option<Bytes>, StorageError> {
        let name = key.as_str();
        match self.block_on(name, self.fetch_capped(name, None, limit))? {
            Fetched::Bytes(bytes) => Ok(Some(bytes)),
            Fetched::Missing => Ok(None),
        }
    }

    /// The keys below `folder` (relative to it, `/`-separated), or `None` where the service cannot list (HTTP) or
    /// more than `limit` keys are there.
    pub fn list(&self, folder: &str, limit: usize) -> Result<Option<Vec<String>>, StorageError> {
        if !self.location.can_list() {
            return Ok(None);
        }
        let folder = folder.trim_matches('/');
        let prefix = self.object_path(folder);
        let strip = format!("{}/", prefix.as_ref());
        self.block_on(folder, async {
            let mut listing = self.store.list(Some(&prefix));
            let mut keys = Vec::new();
            while let Some(item) = listing.next().await {
                let meta = item.map_err(|e| self.describe(folder, &e))?;
                if keys.len() >= limit {
                    return Ok(None);
                }
                let full = meta.location.as_ref();
                keys.push(full.strip_prefix(&strip).unwrap_or(full).to_string());
            }
            Ok(Some(keys))
        })
    }
}

fn to_get_range(range: ByteRange) -> Option<GetRange> {
    match range {
        ByteRange::FromStart(0, None) => None,
        ByteRange::FromStart(start, None) => Some(GetRange::Offset(start)),
        ByteRange::FromStart(start, Some(length)) => Some(GetRange::Bounded(Range { start, end: start + length })),
        ByteRange::Suffix(length) => Some(GetRange::Suffix(length)),
    }
}

impl ReadableStorageTraits for RemoteStore {
    fn get_partial_many<'a>(
        &'a self,
        key: &StoreKey,
        byte_ranges: ByteRangeIterator<'a>,
    ) -> Result<MaybeBytesIterator<'a>, StorageError> {
        let name = key.as_str();
        let ranges: Vec<ByteRange> = byte_ranges.collect();
        for range in &ranges {
            match *range {
                ByteRange::FromStart(start, Some(length)) if start.checked_add(length).is_none() => {
                    return Err(self.error(name, format!("{length} bytes at offset {start} overflow")));
                }
                // An empty range: nothing to fetch (an HTTP range cannot be empty).
                _ => {}
            }
        }
        let fetched = self.block_on(name, async {
            let requests = ranges.iter().map(|&range| async move {
                match range {
                    ByteRange::FromStart(_, Some(0)) | ByteRange::Suffix(0) => Ok(Fetched::Bytes(Bytes::new())),
                    range => self.fetch(name, to_get_range(range)).await,
                }
            });
            futures::future::try_join_all(requests).await
        })?;
        if fetched.iter().any(|f| matches!(f, Fetched::Missing)) {
            return Ok(None);
        }
        let bytes: Vec<Result<Bytes, StorageError>> = fetched
            .into_iter()
            .map(|f| match f {
                Fetched::Bytes(b) => Ok(b),
                Fetched::Missing => unreachable!("checked above"),
            })
            .collect();
        Ok(Some(Box::new(bytes.into_iter())))
    }

    fn size_key(&self, key: &StoreKey) -> Result<Option<u64>, StorageError> {
        let name = key.as_str();
        let path = self.object_path(name);
        self.block_on(name, async {
            match self.store.head(&path).await {
                Ok(meta) => Ok(Some(meta.size)),
                Err(object_store::Error::NotFound { .. }) => Ok(None),
                Err(e) => Err(self.describe(name, &e)),
            }
        })
    }

    fn supports_get_partial(&self) -> bool {
        true
    }
}

/// The first line of a client message, without the start of an HTML body after it: a server's error page (nginx's
/// "400 The plain HTTP request was sent to HTTPS port") follows the status line in object_store's message.
/// What a client error says, with the fix where one is likely (credentials for `location`'s service, a certificate
/// authority), its transport cause named: never a credential (object_store's messages name request URLs, which hold
/// none here; see [`crate::location`]).
pub(crate) fn explain(location: &RemoteLocation, error: &object_store::Error) -> String {
    let hint = match error {
        object_store::Error::PermissionDenied { .. } | object_store::Error::Unauthenticated { .. } => {
            match location.service {
                crate::Service::S3 => {
                    "access denied: set AWS_ACCESS_KEY_ID and AWS_SECRET_ACCESS_KEY (or AWS_PROFILE), or check \
                     the bucket's policy"
                }
                crate::Service::Http => {
                    "access denied: put the user and password in the URL (https://USER:PASSWORD@host/…)"
                }
                _ => "access denied: set the service's credentials in the environment",
            }
        }
        _ if transport_cause(error).is_some_and(|cause| cause.contains("certificate")) => {
            "the server's TLS certificate is not trusted: if the server is yours, set SSL_CERT_FILE to the \
             certificate (PEM) of the authority that signed it"
        }
        _ => "",
    };
    // object_store's messages name the request's URL, which never holds credentials here (see `location`). A
    // transport failure's own message ("error sending request") hides its cause: the innermost one is added.
    let text = match transport_cause(error) {
        Some(cause) => format!("{error}: {cause}"),
        None => first_line(&error.to_string()),
    };
    if hint.is_empty() {
        text
    } else {
        format!("{hint} ({text})")
    }
}

fn first_line(text: &str) -> String {
    let line = text.lines().next().unwrap_or_default().trim_end();
    line.strip_suffix("<html>")
        .or_else(|| line.strip_suffix("<!DOCTYPE html>"))
        .unwrap_or(line)
        .trim_end_matches([':', ' '])
        .to_string()
}

/// The innermost cause under a transport error (a refused connection, a TLS certificate rejected, a reset), which
/// the client's own message ("error sending request") leaves out; `None` where the chain adds nothing.
fn transport_cause(error: &object_store::Error) -> Option<String> {
    let mut innermost: &dyn std::error::Error = error;
    while let Some(source) = innermost.source() {
        innermost = source;
    }
    let cause = innermost.to_string();
    (!std::ptr::addr_eq(innermost, error as &dyn std::error::Error) && !error.to_string().contains(&cause))
        .then_some(cause)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn metadata_keys_are_told_apart_from_chunks() {
        assert!(is_metadata_key("zarr.json"));
        assert!(is_metadata_key("0/.zarray"));
        assert!(is_metadata_key("a/b/.zattrs"));
        assert!(!is_metadata_key("0/c/0/0/0"));
        assert!(!is_metadata_key("0/0.0.0"));
    }

    #[test]
    fn ranges_map_onto_requests() {
        assert_eq!(to_get_range(ByteRange::FromStart(0, None)), None);
        assert_eq!(to_get_range(ByteRange::FromStart(5, Some(10))), Some(GetRange::Bounded(5..15)));
        assert_eq!(to_get_range(ByteRange::Suffix(8)), Some(GetRange::Suffix(8)));
        assert_eq!(to_get_range(ByteRange::FromStart(3, None)), Some(GetRange::Offset(3)));
    }

    #[test]
    fn client_messages_keep_their_first_line_without_an_error_page() {
        let page = "GET http://h/x: Server returned non-2xx status code: 400 Bad Request: <html>\n<head>…</head>\n";
        assert_eq!(first_line(page), "GET http://h/x: Server returned non-2xx status code: 400 Bad Request");
        assert_eq!(first_line("plain message"), "plain message");
        assert_eq!(first_line(""), "");
    }

    #[test]
    fn a_transport_error_names_its_innermost_cause() {
        /// A client error whose message leaves out its cause, as reqwest's "error sending request" does.
        #[derive(Debug)]
        struct Sending(std::io::Error);
        impl std::fmt::Display for Sending {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("error sending request")
            }
        }
        impl std::error::Error for Sending {
            fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
                Some(&self.0)
            }
        }
        let io = std::io::Error::new(std::io::ErrorKind::ConnectionRefused, "Connection refused");
        let error = object_store::Error::Generic { store: "HTTP", source: Box::new(Sending(io)) };
        assert_eq!(transport_cause(&error).as_deref(), Some("Connection refused"));
        let error = object_store::Error::NotFound { path: "x".into(), source: "x".into() };
        assert_eq!(transport_cause(&error), None, "a cause the message already holds is not repeated");
    }
}
