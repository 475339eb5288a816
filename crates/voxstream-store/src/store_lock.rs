//! One writer per store: the import lock, and what it tells about folders left beside a store.
//!
//! An import of `STORE` holds an exclusive advisory lock (`flock` on Unix, `LockFileEx` on Windows, through std's
//! [`File::try_lock`]) on the file `STORE.lock` beside it from before it writes anything until its new store is in
//! place and the old one deleted; the lock file holds the importer's pid. A second import of the same store finds
//! the lock taken and refuses, touching nothing ([`StoreError::Busy`]). The operating system drops the lock when
//! its process ends, however it ends, so a killed import never blocks the next one. Readers take no lock.
//!
//! The lock file is deleted by its holder before the lock is released; an importer that locked a file which was
//! deleted meanwhile (it opened it just before) sees that the path now names another file, or none, and tries again.
//!
//! Folders `STORE.old-<pid>` are the stores an `import --overwrite` moved aside while swapping (see
//! [`crate::import`]). Once `STORE` is back in place such a folder is a leftover unless the import that made it is
//! still running: [`leftover_aside_paths`] names the leftovers for `info` and `render`, and an import removes them.

use std::fs::{File, OpenOptions, TryLockError};
use std::io::{Read, Seek, Write};
use std::path::{Path, PathBuf};

use crate::error::StoreError;
use crate::import::aside_paths;

/// How often an importer retries when the lock file it locked was deleted under it (by the previous holder).
const LOCK_ATTEMPTS: usize = 16;

/// The file an import of `out` locks: `STORE.lock` beside `STORE`.
pub fn lock_path(out: &Path) -> PathBuf {
    let mut name = out.file_name().map(|n| n.to_os_string()).unwrap_or_default();
    name.push(".lock");
    out.with_file_name(name)
}

/// The import lock of one store, held until dropped.
#[derive(Debug)]
pub struct ImportLock {
    file: File,
    path: PathBuf,
}

impl ImportLock {
    /// Takes the lock of the store `out` without waiting: [`StoreError::Busy`] if another import holds it.
    pub fn acquire(out: &Path) -> Result<ImportLock, StoreError> {
        let path = lock_path(out);
        if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
            // A file where a folder of the path should be (`--out notes.txt/v.zarr`): said as such, not as the
            // "already exists" that creating the folders would report.
            if let Some(file) = parent.ancestors().find(|a| !a.as_os_str().is_empty() && a.exists()) {
                if !file.is_dir() {
                    return Err(StoreError::store(file, "is a file, not a folder: name an --out inside a folder"));
                }
            }
            std::fs::create_dir_all(parent).map_err(|e| StoreError::io(parent, e))?;
        }
        for _ in 0..LOCK_ATTEMPTS {
            let mut file = OpenOptions::new()
                .read(true)
                .write(true)
                .create(true)
                .truncate(false)
                .open(&path)
                .map_err(|e| StoreError::io(&path, e))?;
            match file.try_lock() {
                Ok(()) => {}
                Err(TryLockError::WouldBlock) => {
                    let mut text = String::new();
                    let pid = file.read_to_string(&mut text).ok().and_then(|_| text.trim().parse().ok());
                    return Err(StoreError::Busy { path: out.to_path_buf(), pid });
                }
                Err(TryLockError::Error(error)) => {
                    return Err(StoreError::store(
                        &path,
                        format!(
                            "cannot take the import lock ({}): import onto a local file system",
                            crate::error::describe_io(&error)
                        ),
                    ))
                }
            }
            if !is_same_file(&file, &path) {
                // The previous holder deleted the file after this process opened it: the lock guards nothing.
                continue;
            }
            file.set_len(0).map_err(|e| StoreError::io(&path, e))?;
            file.rewind().map_err(|e| StoreError::io(&path, e))?;
            writeln!(file, "{}", std::process::id()).map_err(|e| StoreError::io(&path, e))?;
            return Ok(ImportLock { file, path });
        }
        Err(StoreError::store(&path, "the import lock changed hands too often; run the import again"))
    }
}

impl Drop for ImportLock {
    fn drop(&mut self) {
        // Deleted while still locked (so no importer can be left holding a lock on a file that is gone); Windows
        // cannot delete an open file, so the empty file stays there.
        if cfg!(unix) {
            let _ = std::fs::remove_file(&self.path);
        }
        let _ = self.file.unlock();
    }
}

/// Whether the open `file` is still the one at `path`.
#[cfg(unix)]
fn is_same_file(file: &File, path: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    match (file.metadata(), std::fs::metadata(path)) {
        (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
        _ => false,
    }
}

#[cfg(not(unix))]
fn is_same_file(_file: &File, _path: &Path) -> bool {
    true
}

/// The pid written in `out`'s lock file, if there is one: the import holding the lock, or one killed since.
fn lock_file_pid(out: &Path) -> Option<u32> {
    std::fs::read_to_string(lock_path(out)).ok()?.trim().parse().ok()
}

/// Whether process `pid` is running (where `/proc` does not tell, assumed running).
fn is_running(pid: u32) -> bool {
    let proc = Path::new("/proc");
    !proc.join("self").exists() || proc.join(pid.to_string()).exists()
}

/// Aside folders `STORE.old-<pid>` beside a store that is in place, left by an interrupted `import --overwrite`:
/// all of them except the one of an import swapping right now (its pid holds the lock and is running). Empty while
/// `out` is missing: an aside folder is then the only whole copy of the store (the store reader says so).
pub fn leftover_aside_paths(out: &Path) -> Vec<PathBuf> {
    if !out.is_dir() {
        return Vec::new();
    }
    let swapping = lock_file_pid(out).filter(|&pid| is_running(pid)).map(|pid| crate::import::aside_path(out, pid));
    aside_paths(out).into_iter().filter(|aside| Some(aside) != swapping.as_ref()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("voxstream-lock-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn a_second_lock_is_refused_naming_the_holder_and_the_file_goes_with_the_lock() {
        let out = scratch("busy").join("v.zarr");
        let lock = ImportLock::acquire(&out).unwrap();
        assert_eq!(lock_file_pid(&out), Some(std::process::id()));
        match ImportLock::acquire(&out) {
            Err(StoreError::Busy { pid, .. }) => assert_eq!(pid, Some(std::process::id())),
            other => panic!("expected Busy, got {other:?}"),
        }
        drop(lock);
        assert!(!lock_path(&out).exists(), "the lock file outlived the lock");
        drop(ImportLock::acquire(&out).unwrap());
    }

    #[test]
    fn asides_are_leftovers_unless_the_store_is_missing_or_their_import_is_swapping() {
        let dir = scratch("leftovers");
        let out = dir.join("v.zarr");
        let mine = crate::import::aside_path(&out, std::process::id());
        std::fs::create_dir_all(&mine).unwrap();
        // The store is missing: the aside is its only copy, never a leftover.
        assert!(leftover_aside_paths(&out).is_empty());
        std::fs::create_dir_all(&out).unwrap();
        assert_eq!(leftover_aside_paths(&out), vec![mine.clone()]);
        // A running import (this process) holds the lock: its own aside is not a leftover.
        let lock = ImportLock::acquire(&out).unwrap();
        assert!(leftover_aside_paths(&out).is_empty());
        drop(lock);
        // A lock file left by a killed import names a process that is gone.
        std::fs::write(lock_path(&out), format!("{}\n", u32::MAX)).unwrap();
        let dead = crate::import::aside_path(&out, u32::MAX);
        std::fs::create_dir_all(&dead).unwrap();
        assert_eq!(leftover_aside_paths(&out).len(), 2);
    }
}
