//! A storage adapter that keeps whole stored values (a foreign array's chunks as on disk, compressed) in a
//! byte-bounded LRU, so that a chunk the decoded-chunk cache ([`crate::chunk_cache`]) had to let go is decoded again
//! from memory rather than read again from the disk: compressed chunks are small next to decoded ones, so many more
//! fit in the same bytes, and a render reads each chunk from the storage about once.
//!
//! Only whole-value reads are kept (a chunk read to be decoded whole); partial reads (an inner chunk of a shard)
//! pass through, and are served from a kept value when there is one. Values larger than a quarter of the capacity
//! are never kept.

use std::sync::{Arc, Mutex};

use lru::LruCache;
use zarrs::storage::byte_range::{ByteRange, ByteRangeIterator};
use zarrs::storage::{Bytes, MaybeBytes, MaybeBytesIterator, ReadableStorageTraits, StorageError, StoreKey};

/// The LRU of values and the bytes it holds.
struct Entries {
    lru: LruCache<StoreKey, Bytes>,
    bytes: u64,
}

/// Whole values of `inner`, kept least recently used first out within `capacity_bytes`.
pub(crate) struct EncodedCache<S: ?Sized> {
    inner: Arc<S>,
    capacity_bytes: u64,
    entries: Mutex<Entries>,
}

impl<S: ?Sized> EncodedCache<S> {
    /// A cache of at most `capacity_bytes` over `inner`.
    pub fn new(inner: Arc<S>, capacity_bytes: u64) -> EncodedCache<S> {
        EncodedCache { inner, capacity_bytes, entries: Mutex::new(Entries { lru: LruCache::unbounded(), bytes: 0 }) }
    }

    fn cached(&self, key: &StoreKey) -> Option<Bytes> {
        self.entries.lock().unwrap_or_else(|p| p.into_inner()).lru.get(key).cloned()
    }

    fn keep(&self, key: &StoreKey, value: &Bytes) {
        let size = value.len() as u64;
        if size > self.capacity_bytes / 4 {
            return;
        }
        let mut entries = self.entries.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(old) = entries.lru.put(key.clone(), value.clone()) {
            entries.bytes -= old.len() as u64;
        }
        entries.bytes += size;
        while entries.bytes > self.capacity_bytes {
            match entries.lru.pop_lru() {
                Some((_, evicted)) => entries.bytes -= evicted.len() as u64,
                None => break,
            }
        }
    }
}

/// `range` of `value`, or an error when it reaches past the value's end.
fn slice(key: &StoreKey, value: &Bytes, range: ByteRange) -> Result<Bytes, StorageError> {
    let size = value.len() as u64;
    let wanted = range.to_range(size);
    if wanted.start > wanted.end || wanted.end > size {
        return Err(StorageError::from(format!("{key}: byte range {range:?} reaches past its {size} bytes")));
    }
    Ok(value.slice(wanted.start as usize..wanted.end as usize))
}

impl<S: ?Sized + ReadableStorageTraits> ReadableStorageTraits for EncodedCache<S> {
    fn get(&self, key: &StoreKey) -> Result<MaybeBytes, StorageError> {
        if let Some(value) = self.cached(key) {
            return Ok(Some(value));
        }
        let value = self.inner.get(key)?;
        if let Some(value) = &value {
            self.keep(key, value);
        }
        Ok(value)
    }

    fn get_partial_many<'a>(
        &'a self,
        key: &StoreKey,
        byte_ranges: ByteRangeIterator<'a>,
    ) -> Result<MaybeBytesIterator<'a>, StorageError> {
        let ranges: Vec<ByteRange> = byte_ranges.collect();
        let value = match self.cached(key) {
            Some(value) => value,
            None if ranges == [ByteRange::FromStart(0, None)] => match self.get(key)? {
                Some(value) => value,
                None => return Ok(None),
            },
            None => return self.inner.get_partial_many(key, Box::new(ranges.into_iter())),
        };
        let key = key.clone();
        Ok(Some(Box::new(ranges.into_iter().map(move |range| slice(&key, &value, range)))))
    }

    fn size_key(&self, key: &StoreKey) -> Result<Option<u64>, StorageError> {
        match self.cached(key) {
            Some(value) => Ok(Some(value.len() as u64)),
            None => self.inner.size_key(key),
        }
    }

    fn supports_get_partial(&self) -> bool {
        self.inner.supports_get_partial()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use zarrs::storage::storage_adapter::performance_metrics::PerformanceMetricsStorageAdapter;
    use zarrs::storage::store::MemoryStore;
    use zarrs::storage::WritableStorageTraits;

    #[test]
    fn whole_values_are_read_once_and_ranges_served_from_them() {
        let store = Arc::new(MemoryStore::new());
        let key = StoreKey::new("0/0/0").unwrap();
        store.set(&key, Bytes::from((0u8..100).collect::<Vec<_>>())).unwrap();
        let metrics = Arc::new(PerformanceMetricsStorageAdapter::new(store));
        let cache = EncodedCache::new(metrics.clone(), 1000);
        assert_eq!(cache.get(&key).unwrap().unwrap().len(), 100);
        assert_eq!(cache.get(&key).unwrap().unwrap().len(), 100);
        let parts: Vec<Bytes> = cache
            .get_partial_many(&key, Box::new([ByteRange::FromStart(10, Some(2)), ByteRange::Suffix(1)].into_iter()))
            .unwrap()
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        assert_eq!(parts, [Bytes::from_static(&[10, 11]), Bytes::from_static(&[99])]);
        assert_eq!(metrics.bytes_read(), 100);
        assert!(cache
            .get_partial_many(&key, Box::new([ByteRange::FromStart(90, Some(20))].into_iter()))
            .unwrap()
            .unwrap()
            .next()
            .unwrap()
            .is_err());
        // A value above a quarter of the capacity passes through unkept.
        let small = EncodedCache::new(metrics.clone(), 100);
        small.get(&key).unwrap();
        small.get(&key).unwrap();
        assert_eq!(metrics.bytes_read(), 300);
    }
}
