//! A spinner on stderr while a mesh or particle file is read and indexed (issue 42 item 14: a million text points
//! took 9–25 s without a word): the file, the stage (reading, indexing, binning) and the time so far. Only for files
//! large enough to take a while ([`SPINNER_FROM_BYTES`]), never with `quiet`, and drawn only where stderr is a
//! terminal (indicatif's rule), so logs and tests see nothing of it.

use std::path::Path;
use std::time::Duration;

use indicatif::{ProgressBar, ProgressStyle};

/// Files from this size on get a spinner (16 MiB: about half a million text points, a second or more to read).
pub const SPINNER_FROM_BYTES: u64 = 16 << 20;

/// Whether a file of `file_bytes` gets a spinner.
pub fn wanted(file_bytes: u64, quiet: bool) -> bool {
    !quiet && file_bytes >= SPINNER_FROM_BYTES
}

/// The spinner of one file's opening; cleared when dropped.
pub struct LoadingSpinner {
    bar: ProgressBar,
}

impl LoadingSpinner {
    /// Starts the spinner for `path` at `stage` (`"reading"`, `"binning"`), or a hidden one (see [`wanted`]).
    pub fn start(path: &Path, stage: &str, quiet: bool) -> LoadingSpinner {
        let bytes = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
        if !wanted(bytes, quiet) {
            return LoadingSpinner { bar: ProgressBar::hidden() };
        }
        let bar = ProgressBar::new_spinner();
        bar.set_style(
            ProgressStyle::with_template("{spinner} {msg} ({elapsed})")
                .unwrap_or_else(|_| ProgressStyle::default_spinner()),
        );
        bar.set_message(format!("{stage} {} ({} MB)", path.display(), bytes / 1_000_000));
        bar.enable_steady_tick(Duration::from_millis(200));
        LoadingSpinner { bar }
    }

    /// Says what is being done now.
    pub fn stage(&self, text: String) {
        self.bar.set_message(text);
    }
}

impl Drop for LoadingSpinner {
    fn drop(&mut self) {
        self.bar.finish_and_clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_large_files_get_a_spinner_and_never_when_quiet() {
        assert!(wanted(SPINNER_FROM_BYTES, false));
        assert!(!wanted(SPINNER_FROM_BYTES - 1, false));
        assert!(!wanted(1 << 40, true));
        // A spinner that is not drawn still takes stages and clears without a terminal.
        let spinner = LoadingSpinner::start(Path::new("/nonexistent/cloud.xyz"), "reading", false);
        spinner.stage("indexing 3 particles".into());
        drop(spinner);
    }
}
