//! The renderer interface: what the frame loop needs from a renderer, so that the CPU ray caster and a GPU backend
//! are interchangeable behind [`Session`](crate::Session).
//!
//! One pass reads the pools through an immutable [`TreeView`](voxstream_core::TreeView) (on a GPU: the node and brick buffers described by
//! `voxstream_layout::TreeHeader`), writes what its rays used and missed into the [`FeedbackBuffer`](voxstream_core::FeedbackBuffer) (on a GPU: the
//! `voxstream_layout` feedback records, read back and converted), and completes the pending pixels of a
//! [`ProgressiveImage`]. It never calls the cache manager or a producer: the loop does that between passes.

use voxstream_render::{PassInputs, ProgressiveImage, RayStats, RenderError};

/// A renderer the frame loop can drive, one pass at a time.
pub trait FrameRenderer {
    /// Traces the pending pixels of `progressive` from the inputs' camera and records the rays' usage and requests
    /// in their feedback buffer; returns the rays' counters and the number of requests they made (before deduplication).
    fn render_pass(
        &mut self,
        inputs: PassInputs<'_>,
        progressive: &mut ProgressiveImage,
    ) -> Result<(RayStats, usize), RenderError>;

    /// The renderer and the device it runs on, in one line (for `--stats`).
    fn describe(&self) -> String;

    /// A warning about the device the renderer runs on, in one line (front ends print it once and put it in
    /// `--stats`): e.g. a GPU renderer on a CPU emulation of a GPU, slower than the CPU renderer. `None` by default.
    fn device_warning(&self) -> Option<String> {
        None
    }

    /// Bytes of pool data copied to the renderer's own memory so far (0 for a renderer that reads the CPU pools in
    /// place).
    fn bytes_uploaded(&self) -> u64 {
        0
    }

    /// Whether the renderer keeps its own copy of the bricks in 16 bits whatever the pool holds (the GPU atlas):
    /// the session then plans its pool with 16-bit bricks, so that the memory budget bounds that copy too (8-bit
    /// bricks would fit twice as many in the budget as the copy has room for).
    fn needs_sixteen_bit_bricks(&self) -> bool {
        false
    }
}

/// A renderer chosen at run time (`--backend`), `Send` so that it can move to the viewer's render thread.
impl FrameRenderer for Box<dyn FrameRenderer + Send + '_> {
    fn render_pass(
        &mut self,
        inputs: PassInputs<'_>,
        progressive: &mut ProgressiveImage,
    ) -> Result<(RayStats, usize), RenderError> {
        (**self).render_pass(inputs, progressive)
    }

    fn describe(&self) -> String {
        (**self).describe()
    }

    fn device_warning(&self) -> Option<String> {
        (**self).device_warning()
    }

    fn bytes_uploaded(&self) -> u64 {
        (**self).bytes_uploaded()
    }

    fn needs_sixteen_bit_bricks(&self) -> bool {
        (**self).needs_sixteen_bit_bricks()
    }
}

/// The CPU cone-tracing ray caster of `voxstream-render` (rayon over image tiles): the reference renderer.
#[derive(Clone, Copy, Debug, Default)]
pub struct CpuRenderer;

impl FrameRenderer for CpuRenderer {
    fn render_pass(
        &mut self,
        inputs: PassInputs<'_>,
        progressive: &mut ProgressiveImage,
    ) -> Result<(RayStats, usize), RenderError> {
        voxstream_render::render_pass(inputs, progressive)
    }

    fn describe(&self) -> String {
        "cpu: the cone-tracing ray caster on rayon's threads".to_string()
    }
}
