//! What `voxstream render` tells the user while it works and when it is done: a progress bar on a terminal (pixels
//! complete and passes for one converged frame, frames for a sequence, each with an ETA), the files written, and one
//! summary line. The bar is drawn only when stderr is a terminal and `--quiet` is off; the lines are printed unless
//! `--quiet`.

use std::path::Path;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use voxstream_engine::PassProgress;

/// The progress display of one `render` run.
pub struct RenderProgress {
    bar: ProgressBar,
    quiet: bool,
    /// Output frames of the run (cameras × frames per camera, an upper bound with `--frames`).
    frames: u64,
    started: Instant,
}

impl RenderProgress {
    /// A display for a run of `frames` output frames; `quiet` silences everything.
    pub fn new(frames: u64, quiet: bool) -> RenderProgress {
        let target = if quiet { ProgressDrawTarget::hidden() } else { ProgressDrawTarget::stderr() };
        let bar = ProgressBar::with_draw_target(Some(if frames > 1 { frames } else { 1000 }), target);
        let template = if frames > 1 {
            "rendering [{bar:30}] frame {pos}/{len} {msg} ETA {eta}"
        } else {
            "rendering [{bar:30}] {percent}% of pixels {msg} ETA {eta}"
        };
        bar.set_style(
            ProgressStyle::with_template(template)
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> "),
        );
        bar.enable_steady_tick(Duration::from_millis(200));
        RenderProgress { bar, quiet, frames, started: Instant::now() }
    }

    /// After a pass of the current frame.
    pub fn pass(&self, pass: &PassProgress) {
        if self.frames <= 1 && pass.pixels > 0 {
            let done = pass.pixels - pass.pixels_pending;
            self.bar.set_position((done as u64 * 1000) / pass.pixels as u64);
        }
        self.bar.set_message(format!("(pass {}, {} bricks loaded)", pass.pass, pass.bricks_produced));
    }

    /// After an output frame; `written` is the file, when this frame was written.
    pub fn frame_done(&self, written: Option<&Path>) {
        if self.frames > 1 {
            self.bar.inc(1);
            if let Some(path) = written.filter(|_| !self.quiet) {
                self.bar.suspend(|| eprintln!("wrote {}", path.display()));
            }
        }
    }

    /// A warning, printed above the bar.
    pub fn warn(&self, text: &str) {
        self.bar.suspend(|| eprintln!("warning: {text}"));
    }

    /// Clears the bar and prints the summary line (unless quiet).
    pub fn finish(&self, summary: &str) {
        self.bar.finish_and_clear();
        if !self.quiet {
            eprintln!("{summary} in {:.2} s", self.started.elapsed().as_secs_f64());
        }
    }
}
