//! A read-only storage adapter that checks every byte range before anything is allocated or read.
//!
//! zarrs reads a shard by its index: the index says where each brick lies (offset, length), and zarrs's filesystem
//! store allocates the claimed length before reading. A forged index entry (a brick of 2^62 bytes, CRC32C of the
//! index recomputed) would then abort the process on the allocation. [`CheckedStore`] sits between zarrs and the
//! [`FilesystemStore`] and refuses, with a [`StorageError`], every read that
//! - names something other than a regular file (a FIFO in place of a shard would block `open` forever, a device
//!   would stream without end),
//! - reaches past the end of the file (the file's real size, taken before the read), or
//! - asks for more than `max_range_bytes` in one range of an offset and a length (the largest a brick can take
//!   encoded: an index entry within the file can still claim more than any brick needs; the index itself is read
//!   as a suffix, sized by the shard's shape, and held to the file's size only).
//!
//! Whole-value reads (`zarr.json`, unsharded chunks) are bounded by the file's real size.
//!
//! A remote store ([`CheckedStore::remote`]) is held to the same brick bound before any request; it does not ask for
//! sizes first (a round trip per read), but checks that every body is exactly the length asked for and bounds
//! whole-value reads itself (see [`voxstream_remote::RemoteStore`]).

use std::path::Path;
use std::sync::Arc;

use zarrs::filesystem::FilesystemStore;
use zarrs::storage::byte_range::{ByteRange, ByteRangeIterator};
use zarrs::storage::{MaybeBytesIterator, ReadableStorageTraits, StorageError, StoreKey};

/// What a [`CheckedStore`] reads from.
#[derive(Debug)]
enum Inner {
    /// A folder on disk.
    Folder(FilesystemStore),
    /// A remote store (HTTP, S3, GCS, Azure).
    Remote(Arc<voxstream_remote::RemoteStore>),
}

/// Bytes of shard indexes kept ([`CheckedStore`]'s suffix reads): 16 MiB, the indexes of 16,000 shards of 64
/// bricks.
const INDEX_CACHE_BYTES: usize = 16 << 20;

/// A [`FilesystemStore`] (or a remote store) whose reads are checked against the files' real sizes and kinds.
///
/// Suffix reads (zarrs reads a shard's index as its last bytes, before every brick of the shard) are kept in a
/// small LRU cache: a shard's index is fetched once, not once per brick (over a network, a round trip each).
#[derive(Debug)]
pub struct CheckedStore {
    inner: Inner,
    /// Shard indexes read, by key and suffix length, least recently used first out, within [`INDEX_CACHE_BYTES`].
    indexes: std::sync::Mutex<lru::LruCache<(String, u64), Option<zarrs::storage::Bytes>>>,
    /// Shard indexes being read now (one read per index however many threads want it).
    reading: crate::single_flight::SingleFlight<(String, u64)>,
    /// Bricks as stored (compressed), by key, offset and length, within a byte bound
    /// ([`CheckedStore::with_range_cache`]): the host cache of compressed bricks (Reichl's, seed 004 ch. 4–5), so
    /// that a brick the decoded-brick cache let go is decoded again from memory instead of read again.
    ranges: Option<std::sync::Mutex<RangeCache>>,
    /// The most bytes one explicit range may ask for; `u64::MAX` when unbounded (the file's size still bounds it).
    max_range_bytes: u64,
    /// Whole values read ahead ([`CheckedStore::read_ahead`]) by key, `None` where the value is missing: the next
    /// whole read of the key takes its entry, and a size request is answered from it.
    ahead: std::sync::Mutex<std::collections::HashMap<String, Option<zarrs::storage::Bytes>>>,
    /// Brick ranges being fetched now (by key, offset and length), by [`CheckedStore::warm_ranges`] or a read: a read
    /// of one waits for it and takes it from the range cache, and `warm_ranges` leaves it out, so that no range is
    /// fetched twice at once.
    in_flight: InFlight,
}

/// Ranges being fetched, and a signal when any is done.
#[derive(Debug, Default)]
struct InFlight {
    ranges: std::sync::Mutex<std::collections::HashSet<(String, u64, u64)>>,
    done: std::sync::Condvar,
}

impl InFlight {
    /// Waits while `id` is being fetched, then claims it: returns a guard that releases it (and wakes waiters)
    /// when dropped.
    fn claim(&self, id: &(String, u64, u64)) -> InFlightGuard<'_> {
        let mut ranges = self.ranges.lock().unwrap_or_else(|p| p.into_inner());
        while ranges.contains(id) {
            ranges = self.done.wait(ranges).unwrap_or_else(|p| p.into_inner());
        }
        ranges.insert(id.clone());
        InFlightGuard { in_flight: self, ids: vec![id.clone()] }
    }
}

/// Ranges claimed in an [`InFlight`], released when dropped.
struct InFlightGuard<'a> {
    in_flight: &'a InFlight,
    ids: Vec<(String, u64, u64)>,
}

impl Drop for InFlightGuard<'_> {
    fn drop(&mut self) {
        let mut ranges = self.in_flight.ranges.lock().unwrap_or_else(|p| p.into_inner());
        for id in &self.ids {
            ranges.remove(id);
        }
        self.in_flight.done.notify_all();
    }
}

impl CheckedStore {
    /// Reads from the folder `base`; each explicit byte range is at most `max_range_bytes` long.
    pub fn new(base: &Path, max_range_bytes: u64) -> Result<CheckedStore, StorageError> {
        let inner = FilesystemStore::new(base).map_err(|e| StorageError::Other(e.to_string()))?;
        Ok(CheckedStore {
            inner: Inner::Folder(inner),
            indexes: index_cache(),
            reading: Default::default(),
            ranges: None,
            max_range_bytes,
            ahead: Default::default(),
            in_flight: Default::default(),
        })
    }

    /// Reads from `remote`; each explicit byte range is at most `max_range_bytes` long.
    pub fn remote(remote: Arc<voxstream_remote::RemoteStore>, max_range_bytes: u64) -> CheckedStore {
        CheckedStore {
            inner: Inner::Remote(remote),
            indexes: index_cache(),
            reading: Default::default(),
            ranges: None,
            max_range_bytes,
            ahead: Default::default(),
            in_flight: Default::default(),
        }
    }

    /// The same store keeping up to `bytes` of brick ranges as read (compressed); 0 keeps none.
    pub fn with_range_cache(mut self, bytes: u64) -> CheckedStore {
        if bytes > 0 {
            self.ranges = Some(std::sync::Mutex::new(RangeCache {
                lru: lru::LruCache::unbounded(),
                held: 0,
                capacity: bytes,
                hits: 0,
                hit_bytes: 0,
            }));
        }
        self
    }

    /// What the cache of compressed brick ranges holds and has served; `None` without one.
    pub fn compressed_cache(&self) -> Option<CompressedCacheStats> {
        let cache = self.ranges.as_ref()?.lock().unwrap_or_else(|p| p.into_inner());
        Some(CompressedCacheStats {
            capacity_bytes: cache.capacity,
            held_bytes: cache.held,
            bricks_held: cache.lru.len() as u64,
            hits: cache.hits,
            hit_bytes: cache.hit_bytes,
        })
    }

    /// The size of `key`'s file, `None` when it does not exist; an error when it is not a regular file.
    fn regular_file_size(&self, folder: &FilesystemStore, key: &StoreKey) -> Result<Option<u64>, StorageError> {
        let path = folder.key_to_fspath(key);
        // `metadata` follows symbolic links: what counts is what a read would open.
        match std::fs::metadata(&path) {
            Ok(metadata) if metadata.is_file() => Ok(Some(metadata.len())),
            Ok(metadata) if metadata.is_dir() => Ok(None),
            Ok(_) => Err(StorageError::Other(format!(
                "{key} is not a regular file (a FIFO, socket or device in place of a chunk); replace it with the \
                 store's own file or import the volume again"
            ))),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(StorageError::Other(format!("{key}: {}", crate::error::describe_io(&e)))),
        }
    }

    /// Checks `range` of `key` (a file of `size` bytes): within the file, and no longer than `max_range_bytes`.
    fn check_range(&self, key: &StoreKey, size: u64, range: ByteRange) -> Result<(), StorageError> {
        let (start, length) = match range {
            ByteRange::FromStart(start, None) => (start, size.checked_sub(start).unwrap_or(u64::MAX)),
            ByteRange::FromStart(start, Some(length)) => (start, length),
            ByteRange::Suffix(length) => (size.saturating_sub(length), length),
        };
        // A brick is read by an offset and a length from the shard's index; the index itself by a suffix whose length
        // zarrs computes from the shard's shape (64 bricks of 8³ bytes have a 1028-byte index, more than a brick), so
        // only offset-and-length ranges are held to the brick bound. Every range is held to the file's size.
        let explicit = matches!(range, ByteRange::FromStart(_, Some(_)));
        if start.checked_add(length).is_none_or(|end| end > size) {
            return Err(StorageError::Other(format!(
                "{key}: {length} bytes at offset {start} reach past the end of the file ({size} bytes): the shard \
                 is truncated or its index corrupt; import the volume again"
            )));
        }
        if explicit && length > self.max_range_bytes {
            return Err(StorageError::Other(format!(
                "{key}: the shard index claims a brick of {length} bytes, more than the {} any brick can take \
                 encoded: the index is corrupt; import the volume again",
                self.max_range_bytes
            )));
        }
        Ok(())
    }
}

/// Brick ranges as read, least recently used first out within `capacity` bytes.
#[derive(Debug)]
struct RangeCache {
    lru: lru::LruCache<(String, u64, u64), zarrs::storage::Bytes>,
    held: u64,
    capacity: u64,
    /// Reads answered from the cache, and their bytes.
    hits: u64,
    hit_bytes: u64,
}

/// The compressed-brick cache's state ([`CheckedStore::compressed_cache`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct CompressedCacheStats {
    /// Its budget.
    pub capacity_bytes: u64,
    /// Bytes of bricks it holds now.
    pub held_bytes: u64,
    /// Bricks it holds now.
    pub bricks_held: u64,
    /// Brick reads it answered (not read from the files or the network again).
    pub hits: u64,
    /// Bytes of those reads.
    pub hit_bytes: u64,
}

impl RangeCache {
    fn keep(&mut self, id: (String, u64, u64), bytes: zarrs::storage::Bytes) {
        let size = bytes.len() as u64;
        if size > self.capacity / 4 {
            return;
        }
        if let Some(old) = self.lru.put(id, bytes) {
            self.held -= old.len() as u64;
        }
        self.held += size;
        while self.held > self.capacity {
            match self.lru.pop_lru() {
                Some((_, b)) => self.held -= b.len() as u64,
                None => break,
            }
        }
    }
}

fn index_cache() -> std::sync::Mutex<lru::LruCache<(String, u64), Option<zarrs::storage::Bytes>>> {
    std::sync::Mutex::new(lru::LruCache::unbounded())
}

impl CheckedStore {
    /// Reads the whole value of `key` now, with the same checks as any read, and keeps it for the next whole read of
    /// `key` (and its size for a size request): a caller that knows a value's key before the metadata that will ask
    /// for it (a remote store's min/max chunk) fetches both at once. A value longer than `max_bytes` is an error and
    /// nothing is kept (the reads after fetch and check it as usual). An entry no read takes is dropped with
    /// [`CheckedStore::forget_ahead`].
    pub(crate) fn read_ahead(&self, key: &StoreKey, max_bytes: u64) -> Result<(), StorageError> {
        let value = match &self.inner {
            // Held to `max_bytes` while it is fetched: a forged value past it costs no download.
            Inner::Remote(remote) => remote.get_capped(key, max_bytes)?,
            Inner::Folder(_) => match self.read_checked(key, vec![ByteRange::FromStart(0, None)])? {
                None => None,
                Some(mut parts) => {
                    Some(parts.next().unwrap_or_else(|| Err(StorageError::Other(format!("{key}: no bytes"))))?)
                }
            },
        };
        if let Some(bytes) = value.as_ref().filter(|bytes| bytes.len() as u64 > max_bytes) {
            return Err(StorageError::Other(format!(
                "{key}: {} bytes, more than the {max_bytes} expected",
                bytes.len()
            )));
        }
        self.ahead.lock().unwrap_or_else(|p| p.into_inner()).insert(key.as_str().to_string(), value);
        Ok(())
    }

    /// Drops what [`CheckedStore::read_ahead`] kept for `key`, if no read took it.
    pub(crate) fn forget_ahead(&self, key: &StoreKey) {
        self.ahead.lock().unwrap_or_else(|p| p.into_inner()).remove(key.as_str());
    }

    /// Reads the shard index of `key` (its last `length` bytes) into the cache of indexes, as the first brick read
    /// of the shard would (see `store_reader::shard_indexes`).
    pub(crate) fn shard_index(&self, key: &StoreKey, length: u64) -> Result<(), StorageError> {
        self.suffix(key, length).map(|_| ())
    }

    /// The shard index `key`'s last `length` bytes (read once, then kept); `None` where the shard is not there.
    pub(crate) fn shard_index_bytes(
        &self,
        key: &StoreKey,
        length: u64,
    ) -> Result<Option<zarrs::storage::Bytes>, StorageError> {
        match self.suffix(key, length)? {
            None => Ok(None),
            Some(mut parts) => parts.next().transpose(),
        }
    }

    /// A remote store's bricks as stored, fetched ahead into the cache of brick ranges: of `wanted` (per shard key,
    /// each brick's offset and length as the shard's index gives them) the ranges the cache lacks, those that abut in
    /// a shard in one request, all at once (`RemoteStore::get_ranges`), so that the reads that follow find them in
    /// memory. A range longer than a brick can be encoded is skipped (the read that asks for it refuses it); failures
    /// are left to the reads, which retry and report. Nothing for a local folder or without a range cache. Returns
    /// how many ranges were fetched.
    pub(crate) fn warm_ranges(&self, wanted: Vec<(StoreKey, Vec<(u64, u64)>)>) -> usize {
        let (Inner::Remote(remote), Some(cache)) = (&self.inner, &self.ranges) else { return 0 };
        // Ranges cached or being fetched already are left out; the rest are claimed until they are cached.
        let mut claimed = InFlightGuard { in_flight: &self.in_flight, ids: Vec::new() };
        let wanted: Vec<(String, Vec<std::ops::Range<u64>>)> = {
            let cache = cache.lock().unwrap_or_else(|p| p.into_inner());
            let mut in_flight = self.in_flight.ranges.lock().unwrap_or_else(|p| p.into_inner());
            wanted
                .into_iter()
                .map(|(key, ranges)| {
                    let ranges = ranges
                        .into_iter()
                        .filter(|&(offset, length)| {
                            length > 0
                                && length <= self.max_range_bytes
                                && offset.checked_add(length).is_some()
                                && !cache.lru.contains(&(key.as_str().to_string(), offset, length))
                                && in_flight.insert((key.as_str().to_string(), offset, length))
                        })
                        .inspect(|&(offset, length)| claimed.ids.push((key.as_str().to_string(), offset, length)))
                        .map(|(offset, length)| offset..offset + length)
                        .collect();
                    (key.as_str().to_string(), ranges)
                })
                .filter(|(_, ranges): &(String, Vec<std::ops::Range<u64>>)| !ranges.is_empty())
                .collect()
        };
        let mut fetched = 0;
        for ((key, ranges), answer) in wanted.iter().zip(remote.get_ranges(&wanted)) {
            let Ok(Some(pieces)) = answer else { continue };
            let mut cache = cache.lock().unwrap_or_else(|p| p.into_inner());
            for (range, bytes) in ranges.iter().zip(pieces) {
                cache.keep((key.clone(), range.start, range.end - range.start), bytes);
                fetched += 1;
            }
        }
        drop(claimed);
        fetched
    }

    /// The shard index `key`'s last `length` bytes, read once and then kept.
    fn suffix(&self, key: &StoreKey, length: u64) -> Result<MaybeBytesIterator<'_>, StorageError> {
        let cache_key = (key.as_str().to_string(), length);
        let lock = || self.indexes.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(bytes) = lock().get(&cache_key) {
            return Ok(bytes.clone().map(|b| Box::new(std::iter::once(Ok(b))) as _));
        }
        self.reading.run(&cache_key.clone(), || self.read_suffix(key, cache_key, length))
    }

    fn read_suffix(
        &self,
        key: &StoreKey,
        cache_key: (String, u64),
        length: u64,
    ) -> Result<MaybeBytesIterator<'_>, StorageError> {
        let lock = || self.indexes.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(bytes) = lock().get(&cache_key) {
            return Ok(bytes.clone().map(|b| Box::new(std::iter::once(Ok(b))) as _));
        }
        let Some(mut parts) = self.read_checked(key, vec![ByteRange::Suffix(length)])? else {
            // A shard that is not there (all its bricks empty) is remembered as such.
            lock().put(cache_key, None);
            return Ok(None);
        };
        let bytes =
            parts.next().unwrap_or_else(|| Err(StorageError::Other(format!("{key}: no bytes for the suffix"))))?;
        let mut cache = lock();
        cache.put(cache_key, Some(bytes.clone()));
        let size = |b: &Option<zarrs::storage::Bytes>| b.as_ref().map_or(0, |b| b.len()) + 64;
        let mut held: usize = cache.iter().map(|(_, b)| size(b)).sum();
        while held > INDEX_CACHE_BYTES {
            match cache.pop_lru() {
                Some((_, b)) => held -= size(&b),
                None => break,
            }
        }
        Ok(Some(Box::new(std::iter::once(Ok(bytes)))))
    }
}

impl ReadableStorageTraits for CheckedStore {
    fn get_partial_many<'a>(
        &'a self,
        key: &StoreKey,
        byte_ranges: ByteRangeIterator<'a>,
    ) -> Result<MaybeBytesIterator<'a>, StorageError> {
        let ranges: Vec<ByteRange> = byte_ranges.collect();
        if let [ByteRange::FromStart(0, None)] = ranges[..] {
            if let Some(value) = self.ahead.lock().unwrap_or_else(|p| p.into_inner()).remove(key.as_str()) {
                return Ok(value.map(|bytes| Box::new(std::iter::once(Ok(bytes))) as _));
            }
        }
        if let [ByteRange::Suffix(length)] = ranges[..] {
            return self.suffix(key, length);
        }
        if let (Some(cache), [ByteRange::FromStart(offset, Some(length))]) = (&self.ranges, &ranges[..]) {
            let id = (key.as_str().to_string(), *offset, *length);
            let hit = {
                let mut cache = cache.lock().unwrap_or_else(|p| p.into_inner());
                let hit = cache.lru.get(&id).cloned();
                if let Some(bytes) = &hit {
                    cache.hits += 1;
                    cache.hit_bytes += bytes.len() as u64;
                }
                hit
            };
            if let Some(bytes) = hit {
                return Ok(Some(Box::new(std::iter::once(Ok(bytes)))));
            }
            // Being fetched already (ahead, or by another read): wait for it and take it from the cache.
            let _claim = self.in_flight.claim(&id);
            let hit = cache.lock().unwrap_or_else(|p| p.into_inner()).lru.get(&id).cloned();
            if let Some(bytes) = hit {
                return Ok(Some(Box::new(std::iter::once(Ok(bytes)))));
            }
            let Some(parts) = self.read_checked(key, ranges)? else { return Ok(None) };
            let parts: Vec<Result<zarrs::storage::Bytes, StorageError>> = parts.collect();
            if let [Ok(bytes)] = &parts[..] {
                cache.lock().unwrap_or_else(|p| p.into_inner()).keep(id, bytes.clone());
            }
            return Ok(Some(Box::new(parts.into_iter())));
        }
        self.read_checked(key, ranges)
    }

    fn size_key(&self, key: &StoreKey) -> Result<Option<u64>, StorageError> {
        if let Some(value) = self.ahead.lock().unwrap_or_else(|p| p.into_inner()).get(key.as_str()) {
            return Ok(value.as_ref().map(|bytes| bytes.len() as u64));
        }
        match &self.inner {
            Inner::Folder(folder) => self.regular_file_size(folder, key),
            Inner::Remote(remote) => remote.size_key(key),
        }
    }

    fn supports_get_partial(&self) -> bool {
        true
    }
}

impl CheckedStore {
    /// Reads `ranges` of `key` after checking them.
    fn read_checked(&self, key: &StoreKey, ranges: Vec<ByteRange>) -> Result<MaybeBytesIterator<'_>, StorageError> {
        match &self.inner {
            Inner::Folder(folder) => {
                let Some(size) = self.regular_file_size(folder, key)? else {
                    return Ok(None);
                };
                for &range in &ranges {
                    self.check_range(key, size, range)?;
                }
                folder.get_partial_many(key, Box::new(ranges.into_iter()))
            }
            Inner::Remote(remote) => {
                for &range in &ranges {
                    if let ByteRange::FromStart(_, Some(length)) = range {
                        if length > self.max_range_bytes {
                            return Err(StorageError::Other(format!(
                                "{key}: the shard index claims a brick of {length} bytes, more than the {} any brick \
                                 can take encoded: the index is corrupt",
                                self.max_range_bytes
                            )));
                        }
                    }
                }
                remote.get_partial_many(key, Box::new(ranges.into_iter()))
            }
        }
    }
}

/// The largest a zstd frame of `decoded` bytes can be (zstd's `ZSTD_COMPRESSBOUND`), plus `trailer` bytes (a
/// checksum after it).
pub fn zstd_encoded_bound(decoded: u64, trailer: u64) -> u64 {
    let small_input_margin = if decoded < (128 << 10) { ((128 << 10) - decoded) >> 11 } else { 0 };
    decoded + (decoded >> 8) + small_input_margin + trailer
}

#[cfg(test)]
mod tests {
    use super::*;

    fn store_with(name: &str, bytes: &[u8]) -> (tempdir::Dir, CheckedStore) {
        let dir = tempdir::Dir::new(name);
        std::fs::write(dir.path().join("shard"), bytes).unwrap();
        let store = CheckedStore::new(dir.path(), 64).unwrap();
        (dir, store)
    }

    mod tempdir {
        /// A folder removed when dropped.
        pub struct Dir(std::path::PathBuf);
        impl Dir {
            pub fn new(name: &str) -> Dir {
                let path = std::env::temp_dir().join(format!("voxstream-checked-{}-{name}", std::process::id()));
                let _ = std::fs::remove_dir_all(&path);
                std::fs::create_dir_all(&path).unwrap();
                Dir(path)
            }
            pub fn path(&self) -> &std::path::Path {
                &self.0
            }
        }
        impl Drop for Dir {
            fn drop(&mut self) {
                let _ = std::fs::remove_dir_all(&self.0);
            }
        }
    }

    #[test]
    fn a_value_read_ahead_answers_the_next_whole_read_and_its_size_once() {
        let (dir, store) = store_with("ahead", &[7u8; 100]);
        let key = StoreKey::new("shard").unwrap();
        store.read_ahead(&key, 100).unwrap();
        // The file changes after the read ahead: the size and the next whole read are what was read ahead.
        std::fs::write(dir.path().join("shard"), [9u8; 40]).unwrap();
        assert_eq!(store.size_key(&key).unwrap(), Some(100));
        assert_eq!(store.get(&key).unwrap().unwrap().as_ref(), &[7u8; 100][..]);
        // Taken once: the next read is the file's.
        assert_eq!(store.size_key(&key).unwrap(), Some(40));
        assert_eq!(store.get(&key).unwrap().unwrap().as_ref(), &[9u8; 40][..]);
        // A missing value is read ahead as missing; what no read took is forgotten.
        let missing = StoreKey::new("nothere").unwrap();
        store.read_ahead(&missing, 100).unwrap();
        assert_eq!(store.size_key(&missing).unwrap(), None);
        store.read_ahead(&key, 100).unwrap();
        store.forget_ahead(&key);
        // Longer than the caller expects: an error, nothing kept.
        std::fs::write(dir.path().join("shard"), [5u8; 12]).unwrap();
        assert!(store.read_ahead(&key, 11).is_err());
        assert_eq!(store.size_key(&key).unwrap(), Some(12), "the size comes from the file");
        std::fs::write(dir.path().join("shard"), [3u8; 10]).unwrap();
        assert_eq!(store.get(&key).unwrap().unwrap().as_ref(), &[3u8; 10][..]);
    }

    #[test]
    fn ranges_within_the_file_read_and_ranges_past_it_or_too_long_are_refused() {
        let (_dir, store) = store_with("ranges", &[7u8; 100]);
        let key = StoreKey::new("shard").unwrap();
        assert_eq!(store.get_partial(&key, ByteRange::FromStart(90, Some(10))).unwrap().unwrap().len(), 10);
        assert_eq!(store.get_partial(&key, ByteRange::Suffix(20)).unwrap().unwrap().len(), 20);
        assert_eq!(store.get(&key).unwrap().unwrap().len(), 100, "a whole read is bounded by the file only");
        let past = store.get_partial(&key, ByteRange::FromStart(90, Some(11))).unwrap_err().to_string();
        assert!(past.contains("past the end of the file (100 bytes)"), "{past}");
        let forged = store.get_partial(&key, ByteRange::FromStart(8, Some(1 << 62))).unwrap_err().to_string();
        assert!(forged.contains("past the end"), "{forged}");
        let wrapping = store.get_partial(&key, ByteRange::FromStart(u64::MAX - 4, Some(10))).unwrap_err();
        assert!(wrapping.to_string().contains("past the end"), "{wrapping}");
        let long = store.get_partial(&key, ByteRange::FromStart(0, Some(65))).unwrap_err().to_string();
        assert!(long.contains("more than the 64"), "{long}");
        assert!(store.get_partial(&key, ByteRange::Suffix(101)).is_err());
        // A suffix (a shard's index, sized by the shard's shape) may be longer than a brick, within the file.
        assert_eq!(store.get_partial(&key, ByteRange::Suffix(80)).unwrap().unwrap().len(), 80);
        let missing = StoreKey::new("absent").unwrap();
        assert!(store.get(&missing).unwrap().is_none(), "a missing file is a missing value, not an error");
        assert_eq!(store.size_key(&key).unwrap(), Some(100));
    }

    #[test]
    fn a_fifo_in_place_of_a_file_is_refused_without_opening_it() {
        let (dir, store) = store_with("fifo", &[]);
        let fifo = dir.path().join("pipe");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status().expect("mkfifo");
        assert!(made.success(), "mkfifo failed");
        let key = StoreKey::new("pipe").unwrap();
        // Opening a FIFO for reading blocks until a writer comes: refusing before the open is what keeps this test
        // (and every reader) from hanging.
        let error = store.get(&key).unwrap_err().to_string();
        assert!(error.contains("not a regular file"), "{error}");
        assert!(store.size_key(&key).is_err());
    }

    #[test]
    fn the_zstd_bound_matches_zstd() {
        for decoded in [0u64, 1, 1000, 32 * 32 * 32 * 4, 1 << 20] {
            let expected = zstd_bound_of_the_library(decoded as usize) as u64;
            assert_eq!(zstd_encoded_bound(decoded, 0), expected, "{decoded}");
        }
    }

    fn zstd_bound_of_the_library(n: usize) -> usize {
        zstd::zstd_safe::compress_bound(n)
    }
}
