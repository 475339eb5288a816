//! Writing output files (PNG, stats JSON) so that no reader ever sees a half-written one: the bytes go to a
//! temporary file next to the target, named uniquely per process and call (`NAME.<pid>-<n>.partial`), which is then
//! renamed over the target. Two runs writing the same `--out` never share a temporary file; the last rename wins.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use anyhow::{Context, Result};

/// Temporary files created by this process so far (makes each name unique within the process).
static TEMPORARY_COUNT: AtomicU64 = AtomicU64::new(0);

/// A fresh temporary name next to `path`: `NAME.<pid>-<n>.partial`.
pub fn temporary_path(path: &Path) -> PathBuf {
    let mut name = path.file_name().map(|n| n.to_os_string()).unwrap_or_default();
    name.push(format!(".{}-{}.partial", std::process::id(), TEMPORARY_COUNT.fetch_add(1, Ordering::Relaxed)));
    path.with_file_name(name)
}

/// Writes `path` through `write` into a unique temporary file, then renames it into place; on failure the
/// temporary file is removed and `path` is untouched.
pub fn write_atomically(path: &Path, write: impl FnOnce(&mut BufWriter<File>) -> Result<()>) -> Result<()> {
    let temporary = temporary_path(path);
    let result = (|| -> Result<()> {
        let file = File::create(&temporary).with_context(|| format!("cannot create {}", temporary.display()))?;
        let mut writer = BufWriter::new(file);
        write(&mut writer)?;
        writer.flush().with_context(|| format!("cannot write {}", path.display()))?;
        std::fs::rename(&temporary, path).with_context(|| format!("cannot move the output to {}", path.display()))
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&temporary);
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn temporary_names_are_unique_and_next_to_the_target() {
        let a = temporary_path(Path::new("out/frame.png"));
        let b = temporary_path(Path::new("out/frame.png"));
        assert_ne!(a, b);
        assert_eq!(a.parent(), Some(Path::new("out")));
        assert!(a.to_string_lossy().contains(&format!(".{}-", std::process::id())));
    }

    #[test]
    fn a_failed_write_leaves_nothing() {
        let dir = std::env::temp_dir().join(format!("voxstream-output-file-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let target = dir.join("x.json");
        assert!(write_atomically(&target, |_| anyhow::bail!("no")).is_err());
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0);
        write_atomically(&target, |w| Ok(w.write_all(b"{}")?)).unwrap();
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "{}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
