//! The CLI's outputs (PNG frames and strips, `--stats` and bench JSON) written through the engine's
//! [`OutputFile`](voxstream_engine::OutputFile): a regular file through a uniquely named temporary file and a rename
//! (no reader sees a half-written one; two runs never share a temporary file), a FIFO or character device such as
//! `/dev/null` written into directly, a folder, block device or socket refused with one line. Never a special file
//! replaced by a regular one (issue 42).

use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

use anyhow::Result;
use voxstream_engine::{output_target, OutputFile};

/// Writes `path` through `write`; on failure a temporary file is removed and `path` is untouched.
pub fn write_output(path: &Path, write: impl FnOnce(&mut BufWriter<File>) -> Result<()>) -> Result<()> {
    let mut output = OutputFile::create(path)?;
    write(output.writer())?;
    Ok(output.finish()?)
}

/// Refuses, before any work, an output `flag` names that [`write_output`] would refuse (a folder, a block device,
/// a socket, a link to nothing), and one whose folder does not exist.
pub fn check_output(path: &Path, flag: &str) -> Result<()> {
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        if !parent.is_dir() {
            anyhow::bail!("{flag}: folder {} does not exist (create it first)", parent.display());
        }
    }
    output_target(path).map_err(|e| anyhow::anyhow!("{flag}: {e}"))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_write_leaves_nothing() {
        let dir = std::env::temp_dir().join(format!("voxstream-cli-output-file-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let target = dir.join("x.json");
        assert!(write_output(&target, |_| anyhow::bail!("no")).is_err());
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0);
        write_output(&target, |w| Ok(std::io::Write::write_all(w, b"{}")?)).unwrap();
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "{}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn outputs_are_checked_before_the_work() {
        let dir = std::env::temp_dir().join(format!("voxstream-cli-check-output-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let message = check_output(&dir, "--out").unwrap_err().to_string();
        assert!(message.starts_with("--out: ") && message.contains("is a folder"), "{message}");
        let message = check_output(&dir.join("no/such.png"), "--stats").unwrap_err().to_string();
        assert!(message.contains("does not exist"), "{message}");
        assert!(check_output(&dir.join("new.png"), "--out").is_ok());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
