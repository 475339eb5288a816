//! `--backend`: the renderer that draws a session's passes, the CPU ray caster or the GPU one
//! (`voxstream-gpu`, behind the default feature `gpu`).

use anyhow::Result;
use voxstream_engine::{CpuRenderer, FrameRenderer};

/// Which renderer draws the passes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum Backend {
    /// The CPU ray caster (the reference).
    #[default]
    Cpu,
    /// The GPU ray caster (wgpu, Vulkan).
    Gpu,
}

/// How the GPU renderer filters brick samples (`voxstream_gpu::BrickFiltering`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum GpuFilter {
    /// The texture units where the adapter can filter 16-bit bricks, else exact.
    #[default]
    Auto,
    /// The texture units' trilinear filtering (one fetch per sample; weights at the GPU's precision).
    Hardware,
    /// Trilinear filtering in the shader from eight texel loads: the CPU's arithmetic.
    Exact,
}

impl Backend {
    /// The backend a name means (`"cpu"`, `"gpu"`), for front ends that take strings.
    pub fn from_name(name: &str) -> Result<Backend> {
        match name {
            "cpu" => Ok(Backend::Cpu),
            "gpu" => Ok(Backend::Gpu),
            other => anyhow::bail!("backend '{other}' is not one of cpu, gpu"),
        }
    }
}

/// Opens the renderer `backend` names (`Send`: the viewer draws on its own thread).
/// `filter` is `--gpu-filter`, which only the GPU renderer takes ([`check_backend_flags`]).
pub fn open_renderer(backend: Backend, filter: GpuFilter) -> Result<Box<dyn FrameRenderer + Send>> {
    check_backend_flags(backend, filter)?;
    match backend {
        Backend::Cpu => Ok(Box::new(CpuRenderer)),
        Backend::Gpu => open_gpu(filter),
    }
}

/// Refuses `--gpu-filter` without `--backend gpu` (checked with the other flags, before any work).
pub fn check_backend_flags(backend: Backend, filter: GpuFilter) -> Result<()> {
    if backend == Backend::Cpu && filter != GpuFilter::Auto {
        anyhow::bail!(
            "--gpu-filter is for --backend gpu (the CPU filters bricks exactly): add --backend gpu or drop it"
        );
    }
    Ok(())
}

#[cfg(feature = "gpu")]
fn open_gpu(filter: GpuFilter) -> Result<Box<dyn FrameRenderer + Send>> {
    use anyhow::Context;
    use voxstream_gpu::BrickFiltering;
    let filtering = match filter {
        GpuFilter::Auto => None,
        GpuFilter::Hardware => Some(BrickFiltering::Hardware),
        GpuFilter::Exact => Some(BrickFiltering::Exact),
    };
    Ok(Box::new(voxstream_gpu::GpuRenderer::with_filtering(filtering).context("--backend gpu")?))
}

#[cfg(not(feature = "gpu"))]
fn open_gpu(_filter: GpuFilter) -> Result<Box<dyn FrameRenderer + Send>> {
    anyhow::bail!(
        "--backend gpu: this voxstream was built without the GPU renderer (the `gpu` feature); build it with the \
         default features (cargo build --release) or use --backend cpu"
    )
}
