//! `--backend`: the renderer that draws a session's passes, the CPU ray caster or the GPU one
//! (`voxstream-gpu`, behind the default feature `gpu`).

use anyhow::Result;
use voxstream_engine::{CpuRenderer, FrameRenderer};

use crate::cli::Backend;

/// Opens the renderer `backend` names (`Send`: the viewer draws on its own thread).
pub fn open_renderer(backend: Backend) -> Result<Box<dyn FrameRenderer + Send>> {
    match backend {
        Backend::Cpu => Ok(Box::new(CpuRenderer)),
        Backend::Gpu => open_gpu(),
    }
}

#[cfg(feature = "gpu")]
fn open_gpu() -> Result<Box<dyn FrameRenderer + Send>> {
    use anyhow::Context;
    Ok(Box::new(voxstream_gpu::GpuRenderer::new().context("--backend gpu")?))
}

#[cfg(not(feature = "gpu"))]
fn open_gpu() -> Result<Box<dyn FrameRenderer + Send>> {
    anyhow::bail!(
        "--backend gpu: this voxstream was built without the GPU renderer (the `gpu` feature); build it with the \
         default features (cargo build --release) or use --backend cpu"
    )
}
