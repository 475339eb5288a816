//! How a frame is completed, pass by pass: the display [`Mode`]s, the loop's [`LoopLimits`], and the
//! [`PassPolicy`] that decides for one frame how sparsely each pass traces, what is produced after it, and whether
//! another pass follows ([`crate::Session::render_interruptible`] runs the passes it asks for).
//!
//! - **converged**: passes go on while the rays ask for data that can be served; the request-gathering passes may
//!   trace one pixel in [`GATHER_STRIDE`]², then ever more, and a last pass traces every pixel still pending;
//! - **interactive**: one pass per frame (unless a sparse pass leaves its rays nothing to ask), then a bounded number
//!   of requests served.

use voxstream_core::{ServeOptions, ServeReport, DEFAULT_FADE_FRAMES};

/// How a frame is completed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "lowercase"))]
pub enum Mode {
    /// Repeat render + produce until no request remains.
    Converged,
    /// One render per frame, bounded production between frames.
    Interactive,
}

/// Requests a ray may report per pass in converged mode.
pub const CONVERGED_REQUESTS_PER_RAY: u32 = 64;

/// Limits of the frame loop.
#[derive(Clone, Copy, Debug)]
pub struct LoopLimits {
    /// Requests served per frame in interactive mode.
    pub requests_per_frame: usize,
    /// Passes after which a converged frame gives up (reported as not converged; one more traces every pixel the
    /// sparse passes left untraced, if any).
    pub max_passes: u32,
    /// Converged mode only: when a node is subdivided, also produce its new children's bricks in the same pass,
    /// into free brick slots (never evicting). Fewer passes, the same image.
    pub prefetch_new_children: bool,
    /// Converged mode only: the passes that only gather requests trace one pixel in [`GATHER_STRIDE`]² (their
    /// neighbours ask for the same nodes, and subdividing produces whole tiles), until such a pass asks for
    /// nothing, or until its requests, once served, leave those rays nothing more to ask; then one in half that
    /// stride squared, and so on down to every pixel still pending. Each ray's final value is traced with all it
    /// needs resident, so the image is the same; the early passes cost a quarter. The root is produced before the
    /// first pass. A frame after one that needed no data starts with every pixel.
    pub gather_sparsely: bool,
    /// Interactive mode only: Thiele et al.'s level blending ([`voxstream_core::level_blending`]) with a fade-in of
    /// this many frames; `None` turns it off. Converged frames never blend (their image is exact either way).
    pub blending_fade_frames: Option<u32>,
    /// Interactive frames with level blending: keep the working set restricted (Thiele et al.: neighbouring data at
    /// most one level apart, forced splits first; [`voxstream_core::restriction`]). Converged frames, and frames
    /// without blending, leave it free.
    pub restrict_working_set: bool,
    /// Interactive frames with level blending: fades keep pace with a camera that approaches or backs away (at least
    /// [`voxstream_core::level_blending::FADES_PER_LEVEL`] fades in the frames the camera takes to want the next
    /// level, measured by [`crate::level_rate`] between consecutive interactive cameras). At rest and on an orbit
    /// fades take their `blending_fade_frames`.
    pub pace_fades_to_camera: bool,
}

/// The pixel stride of the request-gathering passes of a converged frame ([`LoopLimits::gather_sparsely`]).
pub const GATHER_STRIDE: u32 = 4;

impl Default for LoopLimits {
    fn default() -> Self {
        LoopLimits {
            requests_per_frame: 1024,
            max_passes: 400,
            prefetch_new_children: true,
            gather_sparsely: true,
            blending_fade_frames: Some(DEFAULT_FADE_FRAMES),
            restrict_working_set: true,
            pace_fades_to_camera: true,
        }
    }
}

/// What follows a pass ([`PassPolicy::after_pass`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NextPass {
    /// Another pass, tracing one pixel in [`PassPolicy::pixel_stride`]² of those still pending.
    Render,
    /// The frame is done.
    Stop,
}

/// One frame's pass policy: the pixel stride of the next pass, what serving its requests may do, and when the frame
/// ends. It sees only the serve reports; the session renders, serves and observes.
#[derive(Clone, Copy, Debug)]
pub struct PassPolicy {
    mode: Mode,
    limits: LoopLimits,
    /// The pixel stride of the next pass.
    pixel_stride: u32,
    /// Set once the frame must end after the pass that traces every pending pixel.
    final_pass: bool,
    /// Passes so far.
    passes: u32,
}

impl PassPolicy {
    /// The policy of a frame in `mode` whose settings trace one pixel in `pixel_stride`²; `gather_sparsely` says
    /// whether a converged frame may start with sparse request-gathering passes ([`LoopLimits::gather_sparsely`],
    /// which must allow it too: a frame after one that needed no data starts with every pixel).
    pub fn new(mode: Mode, limits: LoopLimits, pixel_stride: u32, gather_sparsely: bool) -> PassPolicy {
        let pixel_stride = if mode == Mode::Converged && limits.gather_sparsely && gather_sparsely {
            GATHER_STRIDE
        } else {
            pixel_stride
        };
        PassPolicy { mode, limits, pixel_stride, final_pass: false, passes: 0 }
    }

    /// The pixel stride of the next pass.
    pub fn pixel_stride(&self) -> u32 {
        self.pixel_stride
    }

    /// Requests a ray may report per pass, given the settings' `configured` number: converged frames let each ray
    /// report every miss along its path ([`CONVERGED_REQUESTS_PER_RAY`] at least), so that passes are few.
    pub fn max_requests_per_ray(&self, configured: u32) -> u32 {
        match self.mode {
            Mode::Converged => configured.max(CONVERGED_REQUESTS_PER_RAY),
            Mode::Interactive => configured,
        }
    }

    /// Whether the frame's passes blend levels: converged frames never do (no transitions to track between their
    /// passes, and their image is exact either way).
    pub fn blends(&self) -> bool {
        self.mode == Mode::Interactive
    }

    /// How to serve the root before the first pass: only a converged frame that starts sparsely does.
    pub fn serve_root_first(&self) -> Option<ServeOptions> {
        (self.mode == Mode::Converged && self.pixel_stride > 1).then_some(ServeOptions {
            limit: None,
            prefetch_new_children: self.limits.prefetch_new_children,
            wait_for_data: true,
        })
    }

    /// How to serve the requests of the pass about to be rendered.
    pub fn serve_options(&self) -> ServeOptions {
        match self.mode {
            // The last pass of a frame whose view the pools cannot hold: its image is final, so nothing is
            // produced for it (usage is still recorded).
            Mode::Converged if self.final_pass => {
                ServeOptions { limit: Some(0), prefetch_new_children: false, wait_for_data: true }
            }
            // A converged frame waits for its data; an interactive one never does (ancestors stand in).
            Mode::Converged => ServeOptions {
                limit: None,
                prefetch_new_children: self.limits.prefetch_new_children,
                wait_for_data: true,
            },
            Mode::Interactive => ServeOptions {
                limit: Some(self.limits.requests_per_frame),
                prefetch_new_children: false,
                wait_for_data: false,
            },
        }
    }

    /// Counts a pass whose requests were served as [`PassPolicy::serve_options`] said, with `report`, and decides
    /// what follows it.
    pub fn after_pass(&mut self, report: &ServeReport) -> NextPass {
        self.passes += 1;
        let options = self.serve_options();
        // Whether the sparse rays will need nothing more once this pass's requests are served: each asked for
        // at most one level more than it found, everything was served and the new tiles' children produced.
        // Then the next pass need not trace the same sparse rays again only to find that out.
        let sparse_rays_served = report.pending == 0
            || (options.prefetch_new_children
                && report.largest_deficit <= 1
                && report.deferred == 0
                && report.children_left_missing == 0);
        let stalled = report.pending > 0 && report.served == 0;
        let out_of_passes = self.passes >= self.limits.max_passes;
        if self.pixel_stride > 1 && sparse_rays_served && (report.pending == 0 || !out_of_passes) && !self.final_pass {
            // The sparse rays need nothing more (nothing was asked for, only what cannot be had: bricks that
            // failed to load, or what was just served): trace more of the pixels still pending (4×4, 2×2, all).
            self.pixel_stride /= 2;
            return NextPass::Render;
        }
        let stop = self.mode == Mode::Interactive || report.pending == 0 || stalled || out_of_passes || self.final_pass;
        if stop && self.mode == Mode::Converged && self.pixel_stride > 1 {
            // The frame would end while only some pixels were traced (the pools cannot hold what the view
            // needs, bricks failed to load, or the passes ran out): one more pass traces every pixel still
            // pending with what is resident (coarser data standing in), so that no pixel is left untraced.
            self.pixel_stride = 1;
            self.final_pass = true;
            return NextPass::Render;
        }
        if stop {
            NextPass::Stop
        } else {
            NextPass::Render
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A report of `pending` requests of which `served` were served, each wanting `deficit` levels more.
    fn report(pending: usize, served: usize, deficit: u8) -> ServeReport {
        ServeReport { requests: pending, pending, served, largest_deficit: deficit, ..ServeReport::default() }
    }

    fn dense(mode: Mode) -> PassPolicy {
        PassPolicy::new(mode, LoopLimits { gather_sparsely: false, ..LoopLimits::default() }, 1, true)
    }

    #[test]
    fn converged_frames_keep_going_while_requests_remain_and_are_served() {
        let mut policy = dense(Mode::Converged);
        assert_eq!(policy.serve_root_first(), None);
        for _ in 0..10 {
            assert_eq!(policy.after_pass(&report(5, 5, 3)), NextPass::Render);
            assert_eq!(policy.pixel_stride(), 1);
            assert_eq!(policy.serve_options().limit, None);
            assert!(policy.serve_options().wait_for_data);
        }
        assert_eq!(policy.after_pass(&report(0, 0, 0)), NextPass::Stop);
    }

    #[test]
    fn converged_frames_stop_when_stalled_or_out_of_passes() {
        let mut stalled = dense(Mode::Converged);
        assert_eq!(stalled.after_pass(&report(5, 0, 3)), NextPass::Stop);
        let limits = LoopLimits { gather_sparsely: false, max_passes: 3, ..LoopLimits::default() };
        let mut bounded = PassPolicy::new(Mode::Converged, limits, 1, true);
        assert_eq!(bounded.after_pass(&report(5, 5, 3)), NextPass::Render);
        assert_eq!(bounded.after_pass(&report(5, 5, 3)), NextPass::Render);
        assert_eq!(bounded.after_pass(&report(5, 5, 3)), NextPass::Stop);
    }

    #[test]
    fn interactive_frames_stop_after_one_pass_and_serve_a_bounded_number() {
        let limits = LoopLimits { requests_per_frame: 7, ..LoopLimits::default() };
        let mut policy = PassPolicy::new(Mode::Interactive, limits, 1, true);
        assert_eq!(policy.pixel_stride(), 1, "interactive frames never gather sparsely");
        assert_eq!(policy.serve_root_first(), None);
        assert!(policy.blends());
        assert_eq!(policy.max_requests_per_ray(2), 2);
        assert_eq!(
            policy.serve_options(),
            ServeOptions { limit: Some(7), prefetch_new_children: false, wait_for_data: false }
        );
        assert_eq!(policy.after_pass(&report(100, 7, 3)), NextPass::Stop);
    }

    #[test]
    fn converged_frames_let_rays_report_every_miss_and_never_blend() {
        let policy = dense(Mode::Converged);
        assert_eq!(policy.max_requests_per_ray(2), CONVERGED_REQUESTS_PER_RAY);
        assert_eq!(policy.max_requests_per_ray(CONVERGED_REQUESTS_PER_RAY + 1), CONVERGED_REQUESTS_PER_RAY + 1);
        assert!(!policy.blends());
    }

    #[test]
    fn sparse_converged_frames_halve_the_stride_once_the_sparse_rays_are_served() {
        let mut policy = PassPolicy::new(Mode::Converged, LoopLimits::default(), 1, true);
        assert_eq!(policy.pixel_stride(), GATHER_STRIDE);
        assert!(policy.serve_root_first().is_some_and(|options| options.prefetch_new_children));
        // Deficits over one level: the same sparse rays ask again.
        assert_eq!(policy.after_pass(&report(5, 5, 2)), NextPass::Render);
        assert_eq!(policy.pixel_stride(), GATHER_STRIDE);
        // At most one level each, all served, children produced: more pixels next.
        assert_eq!(policy.after_pass(&report(5, 5, 1)), NextPass::Render);
        assert_eq!(policy.pixel_stride(), GATHER_STRIDE / 2);
        assert_eq!(policy.after_pass(&report(0, 0, 0)), NextPass::Render);
        assert_eq!(policy.pixel_stride(), 1);
        assert_eq!(policy.after_pass(&report(0, 0, 0)), NextPass::Stop);
    }

    #[test]
    fn a_sparse_frame_that_must_end_traces_every_pixel_once_more_without_producing() {
        let mut policy = PassPolicy::new(Mode::Converged, LoopLimits::default(), 1, true);
        // Stalled while sparse: one final dense pass, whose requests are not served.
        assert_eq!(policy.after_pass(&report(5, 0, 2)), NextPass::Render);
        assert_eq!(policy.pixel_stride(), 1);
        assert_eq!(policy.serve_options().limit, Some(0));
        assert_eq!(policy.after_pass(&report(5, 0, 2)), NextPass::Stop);
    }

    #[test]
    fn a_frame_after_one_that_needed_nothing_starts_dense() {
        let policy = PassPolicy::new(Mode::Converged, LoopLimits::default(), 1, false);
        assert_eq!(policy.pixel_stride(), 1);
        assert_eq!(policy.serve_root_first(), None);
    }
}
