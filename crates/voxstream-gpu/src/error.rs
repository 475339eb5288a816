//! Typed errors of the GPU backend: each names the problem and what to do about it.

use thiserror::Error;
use voxstream_render::RenderError;

/// What can keep the GPU backend from rendering.
#[derive(Debug, Error)]
pub enum GpuError {
    /// No Vulkan adapter could be opened.
    #[error(
        "no GPU adapter found (no Vulkan driver could be loaded): install one (on Debian: apt-get install \
         mesa-vulkan-drivers libvulkan1, whose lavapipe runs on the CPU) or use --backend cpu"
    )]
    NoAdapter,
    /// The adapter refused to open a device.
    #[error("the GPU adapter {adapter} could not open a device ({reason}); use --backend cpu")]
    Device {
        /// The adapter's name.
        adapter: String,
        /// What wgpu said.
        reason: String,
    },
    /// Hardware-filtered bricks were asked for on an adapter that cannot filter their format.
    #[error(
        "the GPU adapter {adapter} cannot filter 16-bit normalised textures (R16Unorm), which --gpu-filter hardware \
         needs: use --gpu-filter exact (or auto, which picks what the adapter can do)"
    )]
    NoHardwareFiltering {
        /// The adapter's name.
        adapter: String,
    },
    /// A pool or frame buffer is larger than the adapter can bind.
    #[error(
        "the {what} needs {bytes} bytes on the GPU, more than this adapter holds in one ({limit} bytes): lower \
         --budget-mb (or the image size) or use --backend cpu"
    )]
    TooLarge {
        /// Which buffer.
        what: &'static str,
        /// Bytes it needs.
        bytes: u64,
        /// The adapter's limit.
        limit: u64,
    },
    /// The shader or a GPU command failed validation (a bug of voxstream's, not of the input).
    #[error("the GPU rejected voxstream's ray caster ({0}); please report this, and use --backend cpu meanwhile")]
    Validation(String),
    /// The GPU ran out of memory.
    #[error("the GPU ran out of memory ({0}): lower --budget-mb (or the image size) or use --backend cpu")]
    OutOfMemory(String),
    /// Reading a result back from the GPU failed.
    #[error("reading the frame back from the GPU failed ({0}); use --backend cpu")]
    Readback(String),
    /// What was asked is not drawn by the GPU backend yet.
    #[error("{what} is not drawn by the GPU backend yet; use {instead}")]
    Unsupported {
        /// What was asked.
        what: &'static str,
        /// What to use instead.
        instead: &'static str,
    },
}

impl From<GpuError> for RenderError {
    fn from(error: GpuError) -> RenderError {
        RenderError::Backend(error.to_string())
    }
}
