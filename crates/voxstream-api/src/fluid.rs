//! A particle file (or one step of a time series of them) opened as a fluid: binned into binary-voxel bricks and
//! drawn as smoothed spheres (Reichl ch. 6, `voxstream-fluid`), the representation for liquids; the density path
//! ([`crate::geometry_source`]) stays the one for SPH gas and molecules.
//!
//! A time series is a folder of particle files or a file pattern with `*` (`splash_*.ply`): its files sorted by
//! name are the time steps, and `time` picks one.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use voxstream_fluid::scene::{FluidRenderSettings, FluidScene, Smoothing};
use voxstream_fluid::{FluidBins, FluidSettings};
use voxstream_geometry::formats::ply::PlyPointStream;
use voxstream_geometry::formats::xyz::TextPointStream;
use voxstream_geometry::formats::{is_geometry_file_name, read_geometry, RawGeometry};
use voxstream_geometry::{ParticleChunks, ParticleSet};
use voxstream_render::Camera;

use crate::defaults::frame_box;

/// How a fluid is opened and drawn.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FluidOptions {
    /// `--particle-radius`: sphere radius in the file's units (`None`: from the particles' spacing).
    pub radius: Option<f64>,
    /// `--fluid-cell`: the cell edge (`None`: the radius).
    pub cell: Option<f64>,
    /// `--time`: the time step of a series (0-based).
    pub time: Option<usize>,
    /// How it is drawn.
    pub render: FluidRenderSettings,
    /// Memory for bricks, MiB.
    pub budget_mb: u64,
    /// Image size, for the default camera.
    pub width: u32,
    /// Image height.
    pub height: u32,
}

/// A fluid time step ready to render.
pub struct FluidSource {
    /// The bins and the bricks made from them.
    pub scene: FluidScene,
    /// The default view: the particles' bounds from the front right, above.
    pub camera: Camera,
    /// The file read.
    pub path: PathBuf,
    /// Time to read and bin the particles.
    pub binning: Duration,
    /// One line saying what was read.
    pub description: String,
}

/// The view direction for fluids (as for other particle files: `+y` up, front right, from above).
const FLUID_VIEW_DIRECTION: [f64; 3] = [0.55, 0.45, 0.7];

/// The time steps of `source`: a folder's particle files, or the files matching a pattern with one `*` in its
/// file name, sorted by name; a plain file is a series of one.
pub fn time_steps(source: &str) -> Result<Vec<PathBuf>> {
    let path = Path::new(source);
    type NameFilter = Box<dyn Fn(&str) -> bool>;
    let (folder, matches): (PathBuf, NameFilter) = if path.is_dir() {
        (path.to_path_buf(), Box::new(|name: &str| is_geometry_file_name(Path::new(name))))
    } else if let Some(name) = path.file_name().and_then(|n| n.to_str()).filter(|n| n.contains('*')) {
        let Some((head, tail)) = name.split_once('*') else { unreachable!("the name holds a '*'") };
        if tail.contains('*') {
            bail!("{source}: a time-series pattern takes one '*' (e.g. splash_*.ply)");
        }
        let (head, tail) = (head.to_string(), tail.to_string());
        let folder = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new(".")).to_path_buf();
        (
            folder,
            Box::new(move |n: &str| n.len() >= head.len() + tail.len() && n.starts_with(&head) && n.ends_with(&tail)),
        )
    } else {
        return Ok(vec![path.to_path_buf()]);
    };
    let entries = std::fs::read_dir(&folder).with_context(|| format!("cannot list {}", folder.display()))?;
    let mut steps: Vec<PathBuf> = entries
        .filter_map(|e| e.ok())
        .filter(|e| e.file_type().is_ok_and(|t| t.is_file()))
        .filter(|e| e.file_name().to_str().is_some_and(&matches))
        .map(|e| e.path())
        .collect();
    steps.sort();
    if steps.is_empty() {
        bail!("{source}: no particle files there (a time series is a folder of particle files or a pattern such as splash_*.ply)");
    }
    Ok(steps)
}

/// The particles of `path`, read a run at a time where the format allows (binary PLY, columns of text), whole
/// otherwise.
fn particle_chunks(path: &Path) -> Result<Box<dyn ParticleChunks>> {
    let shown = path.display();
    let name = path.to_string_lossy().to_lowercase();
    if name.ends_with(".ply") {
        if let Ok(stream) = PlyPointStream::open(path) {
            check_binning_memory(path, stream.count())?;
            return Ok(Box::new(stream));
        }
    } else if [".xyz", ".csv", ".txt"].iter().any(|e| name.ends_with(e)) {
        return Ok(Box::new(TextPointStream::open(path)?));
    }
    match read_geometry(path)? {
        RawGeometry::Particles(raw) => Ok(Box::new(ParticleSet::new(raw).with_context(|| format!("in {shown}"))?)),
        RawGeometry::Mesh(_) => {
            bail!("{shown} holds a mesh; --fluid draws particle files (drop --fluid to render the mesh)")
        }
    }
}

/// Bytes a particle takes at binning's peak (measured: 689–776 MiB for 98.7 M particles, 4 of them kept).
pub const BINNING_PEAK_BYTES_PER_PARTICLE: u64 = 8;

/// Refuses, before reading it, a file whose particles could not be binned in this machine's memory.
fn check_binning_memory(path: &Path, count: u64) -> Result<()> {
    let Some(machine) = voxstream_engine::machine_memory_bytes() else { return Ok(()) };
    let needed = count.saturating_mul(BINNING_PEAK_BYTES_PER_PARTICLE);
    if needed > machine / 4 * 3 {
        bail!(
            "{}: {count} particles take about {:.1} GiB to bin ({BINNING_PEAK_BYTES_PER_PARTICLE} bytes each), more \
             than three quarters of this machine's {:.1} GiB: thin the file, or render it on a larger machine",
            path.display(),
            needed as f64 / f64::from(1u32 << 30),
            machine as f64 / f64::from(1u32 << 30)
        );
    }
    Ok(())
}

/// Opens `source` (a particle file, a folder or a pattern of them) as a fluid.
pub fn open_fluid(source: &str, options: &FluidOptions) -> Result<FluidSource> {
    let steps = time_steps(source)?;
    let index = options.time.unwrap_or(0);
    let Some(path) = steps.get(index).cloned() else {
        bail!(
            "--time {index} is beyond the series: {source} has {} time steps (0 to {})",
            steps.len(),
            steps.len() - 1
        );
    };
    let shown = path.display().to_string();
    let started = Instant::now();
    let chunks = particle_chunks(&path)?;
    let settings = FluidSettings { radius: options.radius, cell: options.cell };
    let bins = FluidBins::build(&*chunks, settings, &mut |_| {}).with_context(|| format!("in {shown}"))?;
    let binning = started.elapsed();
    let (lower, upper) = bins.bounds;
    let pad = bins.radius;
    let camera = frame_box(
        lower.map(|v| v - pad),
        upper.map(|v| v + pad),
        options.width,
        options.height,
        FLUID_VIEW_DIRECTION,
        [0.0, 1.0, 0.0],
    );
    let grid = bins.grid;
    let description = format!(
        "{shown}{}: {} particles as a fluid, radius {}, cells of {} ({}×{}×{}), {} bricks of 64³, binned in {:.2} s \
         ({:.1} MB)",
        if steps.len() > 1 { format!(" (time step {index} of 0..{})", steps.len() - 1) } else { String::new() },
        bins.particles,
        crate::defaults::shown_number(bins.radius),
        crate::defaults::shown_number(grid.cell),
        grid.cells[0],
        grid.cells[1],
        grid.cells[2],
        bins.occupied_bricks(0),
        binning.as_secs_f64(),
        bins.heap_bytes() as f64 / 1e6,
    );
    let render = FluidRenderSettings { time_step: index as u32, ..options.render };
    let scene = FluidScene::new(bins, options.budget_mb << 20, render)?;
    Ok(FluidSource { scene, camera, path, binning, description })
}

/// The smoothing a `--smooth` name gives.
pub fn smoothing(name: &str, iterations: u32, strength: f32) -> Result<Smoothing> {
    Ok(match name {
        "rof" => Smoothing::Rof { iterations, strength },
        "bilateral" => Smoothing::Bilateral,
        "none" => Smoothing::None,
        other => bail!("--smooth {other}: give rof (total variation, the default), bilateral, or none"),
    })
}
