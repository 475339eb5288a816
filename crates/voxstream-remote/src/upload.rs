//! Writing a store to object storage (`import --out s3://…`, `gs://…`, `az://…`): a store built in a local folder,
//! then uploaded object by object, its root `zarr.json` last (issue 43: "`import --out s3://…` writing a store
//! remotely").
//!
//! - **A store appears whole or not at all.** Readers take a prefix for a store by its root `zarr.json`; it is put
//!   after every other object has been, so a reader never opens a store whose shards are still on their way, and an
//!   upload that fails leaves no store (its objects stay, named in the error; importing again to the same `--out`
//!   writes over them).
//! - **Nothing replaced.** A location that already holds a store (a root `zarr.json` or `.zattrs`) is refused before
//!   anything is imported: object storage has no rename, so a store there could only be overwritten in place, and an
//!   interrupted overwrite would leave neither the old store nor the new one. HTTP(S) locations are read-only.
//! - **Bounded.** Up to [`UPLOAD_CONCURRENCY`] objects in flight; files up to [`WHOLE_PUT_BYTES`] are put in one
//!   request, larger ones in parts of that size, so memory stays within a few hundred MiB whatever the store's size.
//! - **Faults.** The client retries 5xx, 429, timeouts and resets with backoff (as for reading); a failure that
//!   remains stops the upload with the object's name and the count done. No credential reaches a message.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use bytes::Bytes;
use futures::{StreamExt, TryStreamExt};
use object_store::path::Path as ObjectPath;
use object_store::{ObjectStore, ObjectStoreExt, PutPayload, WriteMultipart};

use crate::client::{build_client, client_runtime};
use crate::error::RemoteError;
use crate::location::{RemoteLocation, Service};
use crate::remote_store::{explain, RemoteOptions};

/// Objects put at once.
pub const UPLOAD_CONCURRENCY: usize = 8;

/// Files up to this size are put in one request; larger ones in parts of this size (S3 wants at least 5 MiB a part).
pub const WHOLE_PUT_BYTES: u64 = 16 << 20;

/// What an upload wrote.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct UploadReport {
    /// Objects put.
    pub objects: u64,
    /// Bytes put.
    pub bytes: u64,
}

/// A writer of one store to a remote location.
pub struct StoreUpload {
    store: Arc<dyn ObjectStore>,
    location: RemoteLocation,
    runtime: tokio::runtime::Runtime,
}

impl std::fmt::Debug for StoreUpload {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StoreUpload").field("location", &self.location.shown()).finish()
    }
}

impl StoreUpload {
    /// A writer to `location` (S3, GCS or Azure; HTTP is refused), with `options`' timeouts and retries.
    pub fn open(location: RemoteLocation, options: &RemoteOptions) -> Result<StoreUpload, RemoteError> {
        if location.service == Service::Http {
            return Err(RemoteError::NotWritable {
                url: location.shown().into(),
                problem: "HTTP(S) stores are read-only: write to a folder, s3://BUCKET/PREFIX, gs://… or az://…, \
                          then serve it"
                    .into(),
            });
        }
        if location.prefix.is_empty() {
            return Err(RemoteError::NotWritable {
                url: location.shown().into(),
                problem: "name the store's folder in the bucket (s3://BUCKET/NAME.zarr), not the bucket itself".into(),
            });
        }
        let store = build_client(&location, options)?;
        let runtime = client_runtime(&location, "voxstream-upload")?;
        Ok(StoreUpload { store, location, runtime })
    }

    /// Where the store goes (as shown: no credentials).
    pub fn location(&self) -> &RemoteLocation {
        &self.location
    }

    fn object_path(&self, key: &str) -> ObjectPath {
        ObjectPath::from(format!("{}/{key}", self.location.prefix))
    }

    fn failed(&self, key: &str, error: &object_store::Error) -> RemoteError {
        RemoteError::Upload { url: format!("{}/{key}", self.location.shown()), problem: explain(&self.location, error) }
    }

    /// Refuses a location that already holds a store (its root `zarr.json` or `.zattrs`); also proves, before any
    /// import work, that the bucket answers with these credentials.
    pub fn check_free(&self) -> Result<(), RemoteError> {
        for key in ["zarr.json", ".zattrs"] {
            let path = self.object_path(key);
            match self.runtime.block_on(self.store.head(&path)) {
                Ok(_) => {
                    return Err(RemoteError::NotWritable {
                        url: self.location.shown().into(),
                        problem: format!(
                            "a store is already there ({key}): give another --out, or delete it first (voxstream \
                             never replaces a remote store in place)"
                        ),
                    })
                }
                Err(object_store::Error::NotFound { .. }) => {}
                Err(error) => return Err(self.failed(key, &error)),
            }
        }
        // A missing bucket answers a HEAD as a missing object does: a listing tells them apart.
        let prefix = ObjectPath::from(self.location.prefix.as_str());
        match self.runtime.block_on(self.store.list_with_delimiter(Some(&prefix))) {
            Ok(_) => Ok(()),
            // S3 answers a listing of a missing bucket 404 (NoSuchBucket), which object_store passes on as a
            // generic error.
            Err(error)
                if matches!(error, object_store::Error::NotFound { .. }) || error.to_string().contains(" 404 ") =>
            {
                Err(RemoteError::NotWritable {
                    url: self.location.shown().into(),
                    problem: format!(
                        "the bucket {} does not exist: create it first (for S3: aws s3 mb s3://{})",
                        self.location.bucket().unwrap_or_default(),
                        self.location.bucket().unwrap_or_default()
                    ),
                })
            }
            Err(error) => Err(self.failed("", &error)),
        }
    }

    /// Uploads every file under `folder` (a store), the root `zarr.json` last; `progress(done, total)` hears bytes.
    pub fn upload(
        &self,
        folder: &Path,
        progress: &mut (dyn FnMut(u64, u64) + Send),
    ) -> Result<UploadReport, RemoteError> {
        let local = |path: &Path, e: std::io::Error| RemoteError::Upload {
            url: self.location.shown().into(),
            problem: format!("{}: {e}", path.display()),
        };
        let mut files = Vec::new();
        list_files(folder, &mut files).map_err(|e| local(folder, e))?;
        let mut sized = Vec::with_capacity(files.len());
        for path in files {
            let len = std::fs::metadata(&path).map_err(|e| local(&path, e))?.len();
            let key =
                relative_key(folder, &path).ok_or_else(|| local(&path, std::io::ErrorKind::InvalidInput.into()))?;
            sized.push((path, key, len));
        }
        // The root metadata last: until it is there, no reader takes the prefix for a store.
        let (root, others): (Vec<_>, Vec<_>) = sized.into_iter().partition(|(_, key, _)| key == "zarr.json");
        if root.is_empty() {
            return Err(local(&folder.join("zarr.json"), std::io::ErrorKind::NotFound.into()));
        }
        let total: u64 = others.iter().chain(&root).map(|(_, _, len)| len).sum();
        let mut report = UploadReport::default();
        let count = others.len() + root.len();
        let (sender, receiver) = std::sync::mpsc::channel::<u64>();
        let result = std::thread::scope(|scope| {
            let uploads = scope.spawn(|| {
                self.runtime.block_on(async {
                    futures::stream::iter(others.iter().map(|(path, key, len)| {
                        let sender = sender.clone();
                        async move {
                            self.put_file(path, key, *len).await?;
                            let _ = sender.send(*len);
                            Ok::<(), RemoteError>(())
                        }
                    }))
                    .buffer_unordered(UPLOAD_CONCURRENCY)
                    .try_collect::<Vec<()>>()
                    .await?;
                    for (path, key, len) in &root {
                        self.put_file(path, key, *len).await?;
                        let _ = sender.send(*len);
                    }
                    drop(sender);
                    Ok::<(), RemoteError>(())
                })
            });
            for bytes in receiver {
                report.objects += 1;
                report.bytes += bytes;
                progress(report.bytes, total);
            }
            uploads.join().unwrap_or_else(|_| {
                Err(RemoteError::Upload { url: self.location.shown().into(), problem: "the upload panicked".into() })
            })
        });
        result.map_err(|error| match error {
            RemoteError::Upload { url, problem } => RemoteError::Upload {
                url,
                problem: format!(
                    "{problem}; {} of {count} objects were put, the root zarr.json not: no reader takes the prefix \
                     for a store (import again to the same --out to write over them, or delete them)",
                    report.objects
                ),
            },
            error => error,
        })?;
        Ok(report)
    }

    /// Puts one file: in one request, or in parts where it is larger than [`WHOLE_PUT_BYTES`].
    async fn put_file(&self, path: &Path, key: &str, len: u64) -> Result<(), RemoteError> {
        let local = |e: std::io::Error| RemoteError::Upload {
            url: format!("{}/{key}", self.location.shown()),
            problem: format!("{}: {e}", path.display()),
        };
        let object = self.object_path(key);
        if len <= WHOLE_PUT_BYTES {
            let bytes = std::fs::read(path).map_err(local)?;
            if bytes.len() as u64 != len {
                return Err(local(std::io::Error::other("the file changed while it was uploaded")));
            }
            self.store.put(&object, PutPayload::from(Bytes::from(bytes))).await.map_err(|e| self.failed(key, &e))?;
            return Ok(());
        }
        let upload = self.store.put_multipart(&object).await.map_err(|e| self.failed(key, &e))?;
        let mut writer = WriteMultipart::new_with_chunk_size(upload, WHOLE_PUT_BYTES as usize);
        let mut file = std::fs::File::open(path).map_err(local)?;
        let mut buffer = vec![0u8; WHOLE_PUT_BYTES as usize];
        let mut sent = 0u64;
        loop {
            let n = std::io::Read::read(&mut file, &mut buffer).map_err(local)?;
            if n == 0 {
                break;
            }
            writer.wait_for_capacity(2).await.map_err(|e| self.failed(key, &e))?;
            writer.write(&buffer[..n]);
            sent += n as u64;
        }
        if sent != len {
            writer.abort().await.ok();
            return Err(local(std::io::Error::other("the file changed while it was uploaded")));
        }
        writer.finish().await.map_err(|e| self.failed(key, &e))?;
        Ok(())
    }
}

/// Every regular file under `folder`, recursively (links and other kinds are refused: a store built here has none).
fn list_files(folder: &Path, files: &mut Vec<PathBuf>) -> std::io::Result<()> {
    for entry in std::fs::read_dir(folder)? {
        let entry = entry?;
        let kind = entry.file_type()?;
        if kind.is_dir() {
            list_files(&entry.path(), files)?;
        } else if kind.is_file() {
            files.push(entry.path());
        } else {
            return Err(std::io::Error::other(format!("{}: not a regular file", entry.path().display())));
        }
    }
    Ok(())
}

/// `path`'s key below `folder`, `/`-separated; `None` for a name that is not UTF-8.
fn relative_key(folder: &Path, path: &Path) -> Option<String> {
    let relative = path.strip_prefix(folder).ok()?;
    let parts: Option<Vec<&str>> = relative.components().map(|c| c.as_os_str().to_str()).collect();
    Some(parts?.join("/"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn http_and_bare_buckets_are_refused_in_one_line() {
        let options = RemoteOptions::default();
        let http = RemoteLocation::parse("https://example.org/ball.zarr").unwrap().unwrap();
        let error = StoreUpload::open(http, &options).unwrap_err().to_string();
        assert!(error.starts_with("https://example.org/ball.zarr: HTTP(S) stores are read-only"), "{error}");
        let bucket = RemoteLocation::parse("s3://scans").unwrap().unwrap();
        let error = StoreUpload::open(bucket, &options).unwrap_err().to_string();
        assert!(error.contains("name the store's folder in the bucket"), "{error}");
    }

    #[test]
    fn keys_are_the_files_below_the_store_slash_separated() {
        let dir = std::env::temp_dir().join(format!("voxstream-upload-keys-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("0/c/1")).unwrap();
        std::fs::write(dir.join("zarr.json"), "{}").unwrap();
        std::fs::write(dir.join("0/c/1/2"), "x").unwrap();
        let mut files = Vec::new();
        list_files(&dir, &mut files).unwrap();
        let mut keys: Vec<String> = files.iter().map(|f| relative_key(&dir, f).unwrap()).collect();
        keys.sort();
        assert_eq!(keys, ["0/c/1/2", "zarr.json"]);
        std::os::unix::fs::symlink("/etc/hostname", dir.join("link")).unwrap();
        assert!(list_files(&dir, &mut Vec::new()).is_err(), "a link inside a store is refused");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
