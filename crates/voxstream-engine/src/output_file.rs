//! Writing what a front end produces (PNG frames, stats and bench JSON, the viewer's screenshots, camera and transfer
//! function) so that no reader sees a half-written file and nothing but a regular file is ever replaced.
//!
//! A new name or a regular file is written to a temporary file beside it, `NAME.<pid>-<n>.partial` (unique per
//! process and call, so two runs writing the same path never share one), which is then renamed over it. Renaming
//! over anything else would replace that thing: run as root, `render --out /dev/null` once turned the machine's
//! `/dev/null` into a regular file, and a named pipe became a file (issue 42). So the target is looked at first
//! ([`output_target`]), following symbolic links:
//!
//! | the path names               | what happens                                                   | why |
//! |------------------------------|----------------------------------------------------------------|-----|
//! | nothing, or a regular file   | temporary file beside it, renamed over it                      | readers see the old file or the whole new one |
//! | a link to a regular file     | the same, beside the link's final target; the link stays       | the link is the user's; renaming over it would replace the link and leave its target stale |
//! | a character device, a FIFO   | opened and written into directly                               | `--out /dev/null`, `/dev/stdout` or a pipe mean "send the bytes there"; there is nothing to replace |
//! | a folder                     | refused                                                        | a folder is not a file name |
//! | a block device               | refused                                                        | an image written over a disk destroys its file system; nobody means that |
//! | a socket                     | refused                                                        | it cannot be opened as a file |
//! | a link to nothing            | refused                                                        | as GNU `cp`: writing through it would create a file away from where the user looks |
//!
//! Opening a FIFO for writing waits until something reads it, as a shell's `>` does. The look and the rename are two
//! steps: a path swapped for a special file in between is still replaced (no portable call closes that gap).

use std::fs::{File, OpenOptions};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// What can stop an output from being written.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// The path names something outputs are never written over.
    #[error("{path} is {what}: {fix}")]
    Refused {
        /// The path as given.
        path: PathBuf,
        /// What it is ("a folder", "a block device", …).
        what: String,
        /// What to give instead.
        fix: &'static str,
    },
    /// Creating, writing or renaming failed.
    #[error("cannot {action} {path}: {source}")]
    Io {
        /// What was being done ("create", "write", "move the output to").
        action: &'static str,
        /// The file it was done to.
        path: PathBuf,
        /// The system's error.
        source: std::io::Error,
    },
}

/// Where the bytes for a path go.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum OutputTarget {
    /// A regular file (or a new name): written beside it and renamed over it. For a link, its final target.
    Replace(PathBuf),
    /// A character device or a FIFO: written into directly.
    Stream,
}

/// Temporary files created by this process so far (makes each name unique within the process).
static TEMPORARY_COUNT: AtomicU64 = AtomicU64::new(0);

/// A fresh temporary name next to `path`: `NAME.<pid>-<n>.partial`.
pub fn temporary_path(path: &Path) -> PathBuf {
    let mut name = path.file_name().map(|n| n.to_os_string()).unwrap_or_default();
    name.push(format!(".{}-{}.partial", std::process::id(), TEMPORARY_COUNT.fetch_add(1, Ordering::Relaxed)));
    path.with_file_name(name)
}

/// Decides where the bytes for `path` go, or refuses it (see the module's table). Creates and changes nothing: front
/// ends call it before a long render, so a bad `--out` is refused at once.
pub fn output_target(path: &Path) -> Result<OutputTarget, OutputError> {
    let refuse = |what: String, fix| Err(OutputError::Refused { path: path.to_path_buf(), what, fix });
    let metadata = match std::fs::metadata(path) {
        Ok(metadata) => metadata,
        Err(error) if error.kind() == std::io::ErrorKind::NotFound => {
            return match std::fs::symlink_metadata(path) {
                Ok(link) if link.file_type().is_symlink() => {
                    let to = std::fs::read_link(path).map(|t| t.display().to_string()).unwrap_or_default();
                    refuse(
                        format!("a symbolic link to {to}, which does not exist"),
                        "remove the link or create what it points to",
                    )
                }
                _ => Ok(OutputTarget::Replace(path.to_path_buf())),
            };
        }
        Err(source) => return Err(OutputError::Io { action: "look at", path: path.to_path_buf(), source }),
    };
    let kind = metadata.file_type();
    if kind.is_file() {
        let is_link = std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink());
        if !is_link {
            return Ok(OutputTarget::Replace(path.to_path_buf()));
        }
        return std::fs::canonicalize(path).map(OutputTarget::Replace).map_err(|source| OutputError::Io {
            action: "follow the link",
            path: path.to_path_buf(),
            source,
        });
    }
    if kind.is_dir() {
        return refuse("a folder".into(), "name a file inside it");
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if kind.is_char_device() || kind.is_fifo() {
            return Ok(OutputTarget::Stream);
        }
        if kind.is_block_device() {
            return refuse("a block device".into(), "outputs are never written over a disk; name a regular file");
        }
        if kind.is_socket() {
            return refuse("a socket".into(), "a socket cannot be written as a file; name a regular file or a FIFO");
        }
    }
    refuse("neither a file nor a device".into(), "name a regular file")
}

/// An output being written: [`OutputFile::writer`], then [`OutputFile::finish`]. Dropped unfinished, it removes its
/// temporary file and leaves the target as it was.
pub struct OutputFile {
    /// The path as given (for messages).
    path: PathBuf,
    writer: BufWriter<File>,
    /// `Some((temporary, target))` while a temporary file waits to be renamed over `target`.
    pending: Option<(PathBuf, PathBuf)>,
}

impl OutputFile {
    /// Opens the output for `path`: a temporary file beside it (or beside a link's target), or the character
    /// device or FIFO itself. Refuses what [`output_target`] refuses.
    pub fn create(path: &Path) -> Result<OutputFile, OutputError> {
        match output_target(path)? {
            OutputTarget::Replace(target) => {
                let temporary = temporary_path(&target);
                let file = File::create(&temporary).map_err(|source| OutputError::Io {
                    action: "create",
                    path: temporary.clone(),
                    source,
                })?;
                let writer = BufWriter::new(file);
                Ok(OutputFile { path: path.to_path_buf(), writer, pending: Some((temporary, target)) })
            }
            OutputTarget::Stream => {
                // No `create`, no `truncate`: the device or FIFO exists, and neither means anything for it.
                let file = OpenOptions::new().write(true).open(path).map_err(|source| OutputError::Io {
                    action: "open",
                    path: path.to_path_buf(),
                    source,
                })?;
                Ok(OutputFile { path: path.to_path_buf(), writer: BufWriter::new(file), pending: None })
            }
        }
    }

    /// Where to write the bytes.
    pub fn writer(&mut self) -> &mut BufWriter<File> {
        &mut self.writer
    }

    /// Flushes the bytes; a temporary file is synced and renamed over its target.
    pub fn finish(mut self) -> Result<(), OutputError> {
        let path = self.path.clone();
        self.writer.flush().map_err(|source| OutputError::Io { action: "write", path: path.clone(), source })?;
        if let Some((temporary, target)) = &self.pending {
            self.writer.get_ref().sync_all().map_err(|source| OutputError::Io { action: "write", path, source })?;
            std::fs::rename(temporary, target).map_err(|source| OutputError::Io {
                action: "move the output to",
                path: target.clone(),
                source,
            })?;
            self.pending = None;
        }
        Ok(())
    }
}

impl Drop for OutputFile {
    fn drop(&mut self) {
        if let Some((temporary, _)) = &self.pending {
            let _ = std::fs::remove_file(temporary);
        }
    }
}

/// Writes `bytes` to `path` ([`OutputFile`]).
pub fn write_output(path: &Path, bytes: &[u8]) -> Result<(), OutputError> {
    let mut output = OutputFile::create(path)?;
    output.writer().write_all(bytes).map_err(|source| OutputError::Io {
        action: "write",
        path: path.to_path_buf(),
        source,
    })?;
    output.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fresh folder under the system's temporary folder, removed by the caller.
    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("voxstream-output-file-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn temporary_names_are_unique_and_next_to_the_target() {
        let a = temporary_path(Path::new("out/frame.png"));
        let b = temporary_path(Path::new("out/frame.png"));
        assert_ne!(a, b);
        assert_eq!(a.parent(), Some(Path::new("out")));
        assert!(a.to_string_lossy().contains(&format!(".{}-", std::process::id())));
    }

    #[test]
    fn a_failed_write_leaves_nothing_and_keeps_the_old_file() {
        let dir = scratch("failed");
        let target = dir.join("x.json");
        write_output(&target, b"old").unwrap();
        let mut output = OutputFile::create(&target).unwrap();
        output.writer().write_all(b"half").unwrap();
        drop(output);
        assert_eq!(std::fs::read(&target).unwrap(), b"old");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
        assert!(matches!(write_output(&dir.join("missing/b.json"), b"x"), Err(OutputError::Io { .. })));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_folder_is_refused_and_left_alone() {
        let dir = scratch("folder");
        let inner = dir.join("frames");
        std::fs::create_dir(&inner).unwrap();
        let error = write_output(&inner, b"x").unwrap_err();
        assert!(matches!(error, OutputError::Refused { .. }), "{error}");
        assert!(error.to_string().contains("is a folder"), "{error}");
        assert!(inner.is_dir() && std::fs::read_dir(&inner).unwrap().count() == 0);
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1, "no temporary file is left");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[cfg(unix)]
    #[test]
    fn a_link_to_a_file_stays_a_link_and_its_target_gets_the_bytes() {
        let dir = scratch("link");
        let real = dir.join("real.json");
        std::fs::write(&real, b"old").unwrap();
        let link = dir.join("link.json");
        std::os::unix::fs::symlink("real.json", &link).unwrap();
        write_output(&link, b"new").unwrap();
        assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
        assert_eq!(std::fs::read(&real).unwrap(), b"new");
        let dangling = dir.join("dangling.json");
        std::os::unix::fs::symlink("nowhere/else.json", &dangling).unwrap();
        let error = write_output(&dangling, b"x").unwrap_err();
        assert!(error.to_string().contains("does not exist"), "{error}");
        assert!(!dir.join("nowhere").exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[cfg(unix)]
    #[test]
    fn a_fifo_is_written_into_and_stays_a_fifo() {
        use std::os::unix::fs::FileTypeExt;
        let dir = scratch("fifo");
        let fifo = dir.join("pipe");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status().expect("mkfifo runs");
        assert!(made.success());
        assert_eq!(output_target(&fifo).unwrap(), OutputTarget::Stream);
        let reader = {
            let fifo = fifo.clone();
            std::thread::spawn(move || std::fs::read(fifo).unwrap())
        };
        write_output(&fifo, b"through the pipe").unwrap();
        assert_eq!(reader.join().unwrap(), b"through the pipe");
        assert!(std::fs::symlink_metadata(&fifo).unwrap().file_type().is_fifo());
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1, "no temporary file is left");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[cfg(unix)]
    #[test]
    fn a_socket_is_refused() {
        let dir = scratch("socket");
        let socket = dir.join("socket");
        let _listener = std::os::unix::net::UnixListener::bind(&socket).unwrap();
        let error = write_output(&socket, b"x").unwrap_err();
        assert!(error.to_string().contains("is a socket"), "{error}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
