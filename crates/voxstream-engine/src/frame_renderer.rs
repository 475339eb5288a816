//! The renderer interface: what the frame loop needs from a renderer, so that the CPU ray caster and a GPU backend
//! are interchangeable behind [`Session`](crate::Session).
//!
//! One pass reads the pools through an immutable [`TreeView`] (on a GPU: the node and brick buffers described by
//! `voxstream_layout::TreeHeader`), writes what its rays used and missed into the [`FeedbackBuffer`] (on a GPU: the
//! `voxstream_layout` feedback records, read back and converted), and completes the pending pixels of a
//! [`ProgressiveImage`]. It never calls the cache manager or a producer: the loop does that between passes.

use voxstream_core::{FeedbackBuffer, TreeView};
use voxstream_render::{Camera, ProgressiveImage, RayStats, RenderError, RenderSettings, TransferLut};

/// A renderer the frame loop can drive, one pass at a time.
pub trait FrameRenderer {
    /// Traces the pending pixels of `progressive` from `camera` and records the rays' usage and requests in
    /// `feedback`; returns the rays' counters and the number of requests they made (before deduplication).
    fn render_pass(
        &mut self,
        view: TreeView<'_>,
        feedback: &FeedbackBuffer,
        camera: &Camera,
        lut: &TransferLut,
        settings: &RenderSettings,
        progressive: &mut ProgressiveImage,
    ) -> Result<(RayStats, usize), RenderError>;
}

/// The CPU cone-tracing ray caster of `voxstream-render` (rayon over image tiles): the reference renderer.
#[derive(Clone, Copy, Debug, Default)]
pub struct CpuRenderer;

impl FrameRenderer for CpuRenderer {
    fn render_pass(
        &mut self,
        view: TreeView<'_>,
        feedback: &FeedbackBuffer,
        camera: &Camera,
        lut: &TransferLut,
        settings: &RenderSettings,
        progressive: &mut ProgressiveImage,
    ) -> Result<(RayStats, usize), RenderError> {
        voxstream_render::render_pass(view, feedback, camera, lut, settings, progressive)
    }
}
