//! A bounded on-disk cache of fetched bytes (`--cache-dir`), so that a second run over the same remote store starts
//! warm: least recently used entries leave first when the cache grows past its limit.
//!
//! Each entry is one file, named by a hash of its key (the store's URL as shown, the value's key and the byte
//! range) and holding the key itself, the bytes and a CRC-32 of both: a read that finds another key (a hash
//! collision), a wrong length or a wrong CRC (a torn or corrupted file) deletes the entry and counts as a miss, so
//! the bytes are fetched again, never used. Entries are written to a temporary file and renamed into place, so two
//! processes sharing the folder never see half an entry; a hit refreshes the file's modification time, which orders
//! eviction. Zarr metadata is never cached (see [`crate::RemoteStore`]): it is read fresh at every open.
//!
//! Entries do not expire: a store rewritten in place under the same URL (rare for published data) needs its cache
//! folder emptied.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

use bytes::Bytes;

use crate::error::RemoteError;

const MAGIC: &[u8; 4] = b"VXC1";

/// The on-disk cache of one folder.
#[derive(Debug)]
pub struct DiskCache {
    dir: PathBuf,
    limit_bytes: u64,
    /// Bytes of entries, as counted at open plus what this process wrote since (others' writes are found when
    /// evicting).
    used: AtomicU64,
    evicting: Mutex<()>,
    counter: AtomicU64,
}

/// A 64-bit FNV-1a hash (the file name only: the key inside the entry decides).
fn fnv1a(text: &str) -> u64 {
    text.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3))
}

fn entries(dir: &Path) -> Vec<(PathBuf, u64, std::time::SystemTime)> {
    let mut found = Vec::new();
    let Ok(fans) = std::fs::read_dir(dir) else { return found };
    for fan in fans.flatten() {
        if !fan.file_type().is_ok_and(|t| t.is_dir()) {
            continue;
        }
        let Ok(files) = std::fs::read_dir(fan.path()) else { continue };
        for file in files.flatten() {
            if let Ok(meta) = file.metadata() {
                if meta.is_file() {
                    let modified = meta.modified().unwrap_or(std::time::UNIX_EPOCH);
                    found.push((file.path(), meta.len(), modified));
                }
            }
        }
    }
    found
}

impl DiskCache {
    /// Opens (creating it if needed) the cache folder `dir`, holding at most `limit_bytes`.
    pub fn open(dir: &Path, limit_bytes: u64) -> Result<DiskCache, RemoteError> {
        let bad = |problem: String| RemoteError::Client { url: dir.display().to_string(), problem };
        if dir.exists() && !dir.is_dir() {
            return Err(bad("--cache-dir names a file, not a folder: name a folder (it is created if missing)".into()));
        }
        std::fs::create_dir_all(dir).map_err(|e| bad(format!("cannot create the cache folder: {e}")))?;
        let used = entries(dir).iter().map(|(_, len, _)| len).sum();
        Ok(DiskCache {
            dir: dir.to_path_buf(),
            limit_bytes,
            used: AtomicU64::new(used),
            evicting: Mutex::new(()),
            counter: AtomicU64::new(0),
        })
    }

    fn path_of(&self, key: &str) -> PathBuf {
        let hash = format!("{:016x}{:08x}", fnv1a(key), crc32fast::hash(key.as_bytes()));
        self.dir.join(&hash[..2]).join(&hash[2..])
    }

    /// The bytes kept for `key`, or `None` (absent, or found damaged and removed).
    pub fn get(&self, key: &str) -> Option<Bytes> {
        let path = self.path_of(key);
        let data = std::fs::read(&path).ok()?;
        match decode(&data, key) {
            Some(bytes) => {
                // Refresh the entry's age for eviction (best effort).
                if let Ok(file) = std::fs::File::options().append(true).open(&path) {
                    let _ = file.set_modified(std::time::SystemTime::now());
                }
                Some(Bytes::copy_from_slice(bytes))
            }
            None => {
                let _ = std::fs::remove_file(&path);
                None
            }
        }
    }

    /// Keeps `bytes` for `key` (best effort: a full disk only costs the cache).
    pub fn put(&self, key: &str, bytes: &[u8]) {
        let entry = encode(key, bytes);
        if entry.len() as u64 > self.limit_bytes / 4 {
            return;
        }
        let path = self.path_of(key);
        let Some(folder) = path.parent() else { return };
        if std::fs::create_dir_all(folder).is_err() {
            return;
        }
        let n = self.counter.fetch_add(1, Ordering::Relaxed);
        let temporary = folder.join(format!(".tmp-{}-{n}", std::process::id()));
        let written = std::fs::File::create(&temporary).and_then(|mut f| f.write_all(&entry));
        if written.is_err() || std::fs::rename(&temporary, &path).is_err() {
            let _ = std::fs::remove_file(&temporary);
            return;
        }
        let used = self.used.fetch_add(entry.len() as u64, Ordering::Relaxed) + entry.len() as u64;
        if used > self.limit_bytes {
            self.evict();
        }
    }

    /// Removes the least recently used entries until the cache holds at most 90 % of its limit.
    fn evict(&self) {
        let Ok(_guard) = self.evicting.try_lock() else { return };
        let mut all = entries(&self.dir);
        all.sort_by_key(|(_, _, modified)| *modified);
        let mut total: u64 = all.iter().map(|(_, len, _)| len).sum();
        let target = self.limit_bytes / 10 * 9;
        for (path, len, _) in all {
            if total <= target {
                break;
            }
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
            // Another process's entry in the making is left alone.
            if name.starts_with(".tmp-") {
                continue;
            }
            if std::fs::remove_file(&path).is_ok() {
                total -= len;
            }
        }
        self.used.store(total, Ordering::Relaxed);
    }

    /// Bytes the entries take, as this process counts them.
    pub fn used_bytes(&self) -> u64 {
        self.used.load(Ordering::Relaxed)
    }
}

fn encode(key: &str, bytes: &[u8]) -> Vec<u8> {
    let mut entry = Vec::with_capacity(bytes.len() + key.len() + 20);
    entry.extend_from_slice(MAGIC);
    entry.extend_from_slice(&(key.len() as u32).to_le_bytes());
    entry.extend_from_slice(key.as_bytes());
    entry.extend_from_slice(&(bytes.len() as u64).to_le_bytes());
    entry.extend_from_slice(bytes);
    let crc = crc32fast::hash(&entry[4..]);
    entry.extend_from_slice(&crc.to_le_bytes());
    entry
}

/// The bytes of an entry for `key`, or `None` when it is for another key or damaged (public for the fuzz target
/// `remote_inputs`: entries are read back from a folder other processes write too).
pub fn decode<'a>(entry: &'a [u8], key: &str) -> Option<&'a [u8]> {
    let body = entry.strip_prefix(MAGIC)?;
    let (body, crc) = body.split_at_checked(body.len().checked_sub(4)?)?;
    if crc32fast::hash(body).to_le_bytes() != crc {
        return None;
    }
    let key_len = u32::from_le_bytes(body.get(..4)?.try_into().ok()?) as usize;
    let stored_key = body.get(4..4 + key_len)?;
    if stored_key != key.as_bytes() {
        return None;
    }
    let rest = &body[4 + key_len..];
    let len = u64::from_le_bytes(rest.get(..8)?.try_into().ok()?) as usize;
    let data = &rest[8..];
    (data.len() == len).then_some(data)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn folder(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("voxstream-disk-cache-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        dir
    }

    #[test]
    fn entries_round_trip_and_damage_is_a_miss_that_removes_the_entry() {
        let dir = folder("damage");
        let cache = DiskCache::open(&dir, 1 << 20).unwrap();
        cache.put("s3://b/x/0/c/0/0/0#None", b"brick bytes");
        assert_eq!(cache.get("s3://b/x/0/c/0/0/0#None").as_deref(), Some(&b"brick bytes"[..]));
        assert!(cache.get("s3://b/x/0/c/0/0/1#None").is_none());
        // Flip one byte of the stored data: the CRC catches it, the entry goes.
        let path = cache.path_of("s3://b/x/0/c/0/0/0#None");
        let mut data = std::fs::read(&path).unwrap();
        let middle = data.len() / 2;
        data[middle] ^= 1;
        std::fs::write(&path, &data).unwrap();
        assert!(cache.get("s3://b/x/0/c/0/0/0#None").is_none());
        assert!(!path.exists(), "a damaged entry is removed");
        // A truncated entry likewise.
        cache.put("k", b"0123456789");
        let path = cache.path_of("k");
        let data = std::fs::read(&path).unwrap();
        std::fs::write(&path, &data[..data.len() - 3]).unwrap();
        assert!(cache.get("k").is_none());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn the_least_recently_used_entries_leave_first_past_the_limit() {
        let dir = folder("evict");
        let cache = DiskCache::open(&dir, 4000).unwrap();
        let old = std::time::SystemTime::now() - std::time::Duration::from_secs(100);
        for i in 0..4 {
            cache.put(&format!("key{i}"), &[i as u8; 800]);
            let file = std::fs::File::options().append(true).open(cache.path_of(&format!("key{i}"))).unwrap();
            file.set_modified(old + std::time::Duration::from_secs(i)).unwrap();
        }
        assert!(cache.get("key0").is_some(), "a hit makes key0 the most recently used");
        cache.put("key4", &[4; 800]);
        assert!(cache.used_bytes() <= 3600, "{}", cache.used_bytes());
        assert!(cache.get("key0").is_some(), "the entry just used stays");
        assert!(cache.get("key1").is_none(), "the least recently used went first");
        assert!(cache.get("key4").is_some());
        let reopened = DiskCache::open(&dir, 4000).unwrap();
        assert_eq!(reopened.used_bytes(), cache.used_bytes(), "a second process counts the same bytes");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_file_in_place_of_the_folder_is_refused() {
        let dir = folder("file");
        std::fs::write(&dir, b"x").unwrap();
        let message = DiskCache::open(&dir, 1000).unwrap_err().to_string();
        assert!(message.contains("names a file"), "{message}");
        std::fs::remove_file(&dir).unwrap();
    }
}
