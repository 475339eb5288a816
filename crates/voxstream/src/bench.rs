//! `voxstream bench`: per built-in scene — or any source `render` opens: a store's folder or URL, a mesh or particle
//! file — converged time from a cold cache, frames to converge interactively, warm frame time once resident
//! (frames/s, rays/s, samples/s, ns per sample and core next to a scalar trilinear bound measured in the same run),
//! and frame times along an interactive camera path. Each cold measurement opens its source afresh (through the
//! facade, as `render` does), so a remote store's figures include its fetching.

use std::io::Write;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use serde::Serialize;
use voxstream_api::{Source, SourceOptions};
use voxstream_core::Producer;
use voxstream_engine::{FrameRenderer, LoopLimits, Mode, Session};
use voxstream_render::RenderSettings;

use crate::camera_path::orbit;
use crate::cli::{BenchArgs, Switch};
use crate::memory::peak_rss_bytes;
use crate::output_file::{check_output, write_output};
use crate::render_budget::{check_budget, plan_budget};
use crate::scenes::{builtin, SCENE_NAMES};
use crate::trilinear_bound::{lanes_trilinear_ns_per_sample, scalar_trilinear_ns_per_sample, BoundVoxel};

/// How long each trilinear bound is measured (four of them: scalar and lanes, 16-bit and 8-bit voxels; 2 s in all).
const BOUND_DURATION: std::time::Duration = std::time::Duration::from_millis(500);

/// Figures for one scene.
#[derive(Clone, Debug, Serialize)]
pub struct SceneFigures {
    /// Scene name.
    pub scene: String,
    /// Image edge.
    pub size: u32,
    /// Cold converged frame: wall time, ms.
    pub converged_ms: f64,
    /// Cold converged frame: render passes.
    pub converged_passes: u32,
    /// Interactive frames until a frame is final (needed nothing more, and nothing was blending in).
    pub frames_to_converge: u32,
    /// Warm frame (data resident): median ms.
    pub warm_frame_ms: f64,
    /// Warm frames per second.
    pub warm_fps: f64,
    /// Warm rays per second.
    pub rays_per_second: f64,
    /// Warm samples per second.
    pub samples_per_second: f64,
    /// Warm: wall time per sample multiplied by the worker threads, ns (the cost of a sample on one core).
    pub ns_per_sample_per_core: f64,
    /// The scalar trilinear bound measured in the same run on voxels of the scene's width (see
    /// [`crate::trilinear_bound`]), ns per sample.
    pub trilinear_bound_ns: f64,
    /// The same bound with eight rays in lock-step through the renderer's lane sampler, ns per sample.
    pub lanes_trilinear_bound_ns: f64,
    /// Bytes per voxel of the scene's bricks (the bounds' voxel width).
    pub voxel_bytes: usize,
    /// Interactive camera path: median frame ms (render + bounded production).
    pub path_median_ms: f64,
    /// Interactive camera path: 95th percentile frame ms.
    pub path_p95_ms: f64,
    /// Bricks resident after the path.
    pub bricks_resident: u32,
    /// Peak pool bytes.
    pub resident_bytes_peak: u64,
    /// The renderer and its device.
    pub backend: String,
    /// What the renderer warned of its device (a GPU adapter that is a CPU emulation), if anything.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub backend_warning: Option<String>,
    /// Bytes of tiles and bricks uploaded to the renderer's memory (the GPU's; 0 on the CPU) by the cold converged
    /// frame.
    pub converged_bytes_uploaded: u64,
    /// The same per warm frame (nothing changes: 0 when only changes are uploaded).
    pub warm_bytes_uploaded_per_frame: f64,
    /// The same per frame of the interactive camera path, mean.
    pub path_bytes_uploaded_per_frame: f64,
}

/// Runs the benchmark and prints a Markdown table.
pub fn run(args: &BenchArgs) -> Result<()> {
    crate::render_command::check_fade_frames(args.fade_frames)?;
    if let Some(path) = &args.json {
        check_output(path, "--json")?;
    }
    if let Some(path) = &args.strip {
        check_output(path, "--strip")?;
    }
    if args.popping {
        return crate::popping_bench::run(args);
    }
    let names: Vec<String> =
        if args.scenes.is_empty() { SCENE_NAMES.iter().map(|s| s.to_string()).collect() } else { args.scenes.clone() };
    check_budget(args.budget_mb, args.size, args.size, "--size")?;
    crate::backend::check_backend_flags(args.backend, args.gpu_filter)?;
    // Every source opens (and its isovalues fit its data) before anything is measured.
    for name in &names {
        bench_surfaces(args, open_source(name, args)?.meta.value_range)?;
    }
    eprintln!("bench: the trilinear bounds …");
    let bounds = TrilinearBounds { wide: TrilinearBounds::measure::<u16>(), narrow: TrilinearBounds::measure::<u8>() };
    let mut figures = Vec::new();
    for name in &names {
        eprintln!("bench: {name} at {0}x{0} …", args.size);
        let scene = bench_source(name, args, &bounds)?;
        if let (None, Some(warning)) = (figures.first(), &scene.backend_warning) {
            eprintln!("warning: {warning}");
        }
        figures.push(scene);
    }
    println!(
        "backend: {}\nthreads: {}, ray loop: {}, peak RSS: {:.0} MiB, trilinear bounds in ns per sample on one core \
         (scalar, 8 rays in lock-step): 16-bit voxels {:.1}, {:.1}; 8-bit voxels {:.1}, {:.1}\n",
        figures.first().map_or("", |f| f.backend.as_str()),
        rayon::current_num_threads(),
        voxstream_render::InstructionSet::detected(),
        peak_rss_bytes().unwrap_or(0) as f64 / 1048576.0,
        bounds.wide.0,
        bounds.wide.1,
        bounds.narrow.0,
        bounds.narrow.1,
    );
    println!("| scene | size | converged (cold) | passes | frames to converge (interactive) | warm frame | warm fps | rays/s | samples/s | ns/sample/core (bounds at its voxel width: scalar, lanes) | path median | path p95 | uploaded: cold, per warm frame, per path frame |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for f in &figures {
        println!(
            "| {} | {}² | {:.0} ms | {} | {} | {:.1} ms | {:.1} | {:.2} M | {:.1} M | {:.1} ({:.1}, {:.1}) | {:.1} ms | {:.1} ms | {:.1} MB, {:.0} B, {:.1} kB |",
            f.scene,
            f.size,
            f.converged_ms,
            f.converged_passes,
            f.frames_to_converge,
            f.warm_frame_ms,
            f.warm_fps,
            f.rays_per_second / 1e6,
            f.samples_per_second / 1e6,
            f.ns_per_sample_per_core,
            f.trilinear_bound_ns,
            f.lanes_trilinear_bound_ns,
            f.path_median_ms,
            f.path_p95_ms,
            f.converged_bytes_uploaded as f64 / 1e6,
            f.warm_bytes_uploaded_per_frame,
            f.path_bytes_uploaded_per_frame / 1e3,
        );
    }
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&figures)?;
        write_output(path, |file| Ok(file.write_all(text.as_bytes())?)).context("--json")?;
    }
    Ok(())
}

/// The light of `bench --iso` (towards the light, world axes).
const BENCH_LIGHT: [f64; 3] = [0.3, 0.8, 0.5];

/// `name` opened as `render` opens it (a built-in scene, a store's folder or URL, a mesh or particle file), framed
/// for the benchmark's image size, within its budget.
fn open_source(name: &str, args: &BenchArgs) -> Result<Source> {
    let budget = check_budget(args.budget_mb, args.size, args.size, "--size")?;
    let options = SourceOptions { width: args.size, height: args.size, ..SourceOptions::default() };
    voxstream_api::open(name, &options, &budget)
}

/// The surfaces `--iso` asks for (empty: volume rendering), checked against the source's data range.
fn bench_surfaces(args: &BenchArgs, value_range: [f64; 2]) -> Result<Vec<voxstream_render::IsoSurface>> {
    if args.iso.is_empty() {
        if args.shadows {
            bail!("--shadows applies to isosurfaces: add --iso VALUE");
        }
        return Ok(Vec::new());
    }
    if args.iso.len() > voxstream_render::MAX_SURFACES {
        bail!(
            "--iso names {} values; at most {} surfaces are drawn at once",
            args.iso.len(),
            voxstream_render::MAX_SURFACES
        );
    }
    for &value in &args.iso {
        crate::iso_flags::check_isovalue(value, value_range, "--iso")?;
    }
    Ok(args
        .iso
        .iter()
        .zip(crate::iso_flags::PALETTE)
        .map(|(&value, color)| voxstream_render::IsoSurface { value, color, opacity: 1.0 })
        .collect())
}

/// A session over `name` opened afresh (cold caches), and the source's defaults.
fn new_session(
    name: &str,
    args: &BenchArgs,
) -> Result<(Session<Box<dyn Producer>, Box<dyn FrameRenderer + Send>>, voxstream_api::SourceMeta)> {
    let Source { producer, meta } = open_source(name, args)?;
    let surfaces = bench_surfaces(args, meta.value_range)?;
    let settings = if surfaces.is_empty() {
        RenderSettings {
            width: args.size,
            height: args.size,
            shading: meta.shading,
            light_direction: meta.light,
            placement: meta.placement,
            ..RenderSettings::default()
        }
    } else {
        RenderSettings {
            width: args.size,
            height: args.size,
            shading: voxstream_render::Shading::Phong,
            light_direction: Some(BENCH_LIGHT),
            shadows: args.shadows,
            surfaces,
            placement: meta.placement,
            ..RenderSettings::default()
        }
    };
    // The same split as `render`: the frame's buffers count, and a budget beyond the machine is refused.
    let budget = check_budget(args.budget_mb, args.size, args.size, "--size")?;
    let plan = plan_budget(&budget, &producer.shape(), meta.producer_cache_bytes)?;
    let blending = args.blending == Switch::On;
    let limits = LoopLimits { blending_fade_frames: blending.then_some(args.fade_frames), ..LoopLimits::default() };
    let renderer = crate::backend::open_renderer(args.backend, args.gpu_filter)?;
    let session = Session::with_renderer(
        renderer,
        producer,
        &meta.transfer_function,
        settings,
        plan.pool_bytes,
        limits,
        meta.value_range,
    )?;
    Ok((session, meta))
}

/// The trilinear bounds (scalar, eight rays in lock-step; ns per sample on one core) per voxel width.
struct TrilinearBounds {
    wide: (f64, f64),
    narrow: (f64, f64),
}

impl TrilinearBounds {
    fn measure<V: BoundVoxel>() -> (f64, f64) {
        (
            scalar_trilinear_ns_per_sample::<V>(BOUND_DURATION),
            lanes_trilinear_ns_per_sample::<V>(BOUND_DURATION, voxstream_render::InstructionSet::Detect),
        )
    }
}

fn bench_source(name: &str, args: &BenchArgs, bounds: &TrilinearBounds) -> Result<SceneFigures> {
    // Cold, converged.
    let (mut session, meta) = new_session(name, args)?;
    let camera = meta.camera;
    let cold = session.render(&camera, Mode::Converged)?;
    // The bounds for the width the session's pool keeps (a GPU session keeps 16 bits whatever the scene allows).
    let voxel_bytes = session.cache().brick_pool().format().voxel_bytes();
    let (bound_ns, lanes_bound_ns) = if voxel_bytes == 1 { bounds.narrow } else { bounds.wide };
    let converged_bytes_uploaded = session.renderer().bytes_uploaded();

    // Warm: everything resident, no request left.
    let mut warm_ms = Vec::new();
    let (mut rays, mut samples) = (0u64, 0u64);
    let start = Instant::now();
    for _ in 0..args.warm_frames.max(1) {
        let frame = session.render(&camera, Mode::Interactive)?;
        warm_ms.push(frame.elapsed_ms);
        rays += frame.rays;
        samples += frame.samples;
    }
    let warm_seconds = start.elapsed().as_secs_f64();
    let warm_bytes_uploaded_per_frame =
        (session.renderer().bytes_uploaded() - converged_bytes_uploaded) as f64 / args.warm_frames.max(1) as f64;
    let backend = session.renderer().describe();
    let backend_warning = session.renderer().device_warning();
    let warm_frame_ms = median(&mut warm_ms);

    // Interactive from cold: frames until complete.
    let (mut session, _) = new_session(name, args)?;
    let (frames_to_converge, _) = session.render_until_converged_interactively(&camera, 2000)?;

    // Interactive camera path from cold: an orbit about the default view's target, at the built-in scenes' 2.6
    // (their figures stay comparable with earlier runs), else at the default view's distance.
    let distance = if builtin(name).is_some() {
        2.6
    } else {
        let [dx, dy, dz] = [0, 1, 2].map(|k| camera.eye[k] - camera.target[k]);
        (dx * dx + dy * dy + dz * dz).sqrt()
    };
    let (mut session, _) = new_session(name, args)?;
    let mut path_ms = Vec::new();
    for camera in orbit(args.path_frames.max(1), camera.target, distance, 0.45, camera.fov) {
        path_ms.push(session.render(&camera, Mode::Interactive)?.elapsed_ms);
    }
    let path_bytes_uploaded_per_frame = session.renderer().bytes_uploaded() as f64 / path_ms.len() as f64;
    let path_median_ms = median(&mut path_ms.clone());
    path_ms.sort_by(f64::total_cmp);
    let path_p95_ms = path_ms[((path_ms.len() as f64 * 0.95) as usize).min(path_ms.len() - 1)];

    Ok(SceneFigures {
        scene: meta.name.clone(),
        size: args.size,
        converged_ms: cold.elapsed_ms,
        converged_passes: cold.passes,
        frames_to_converge,
        warm_frame_ms,
        warm_fps: 1e3 / warm_frame_ms,
        rays_per_second: rays as f64 / warm_seconds,
        samples_per_second: samples as f64 / warm_seconds,
        ns_per_sample_per_core: warm_seconds * 1e9 * rayon::current_num_threads() as f64 / samples.max(1) as f64,
        trilinear_bound_ns: bound_ns,
        lanes_trilinear_bound_ns: lanes_bound_ns,
        voxel_bytes,
        path_median_ms,
        path_p95_ms,
        bricks_resident: session.residency().bricks,
        resident_bytes_peak: session.peak_resident_bytes(),
        backend,
        backend_warning,
        converged_bytes_uploaded,
        warm_bytes_uploaded_per_frame,
        path_bytes_uploaded_per_frame,
    })
}

/// The median of `values`, sorted in place (by [`f64::total_cmp`]): the middle value, or with an even count the upper
/// of the two middle ones (index `len / 2`); 0 for none.
pub fn median(values: &mut [f64]) -> f64 {
    values.sort_by(f64::total_cmp);
    values.get(values.len() / 2).copied().unwrap_or(0.0)
}

#[cfg(test)]
mod tests {
    use super::median;

    #[test]
    fn the_median_is_the_middle_value_or_the_upper_of_the_two_middle_ones() {
        let mut odd = [3.0, 1.0, 2.0];
        assert_eq!(median(&mut odd), 2.0);
        assert_eq!(odd, [1.0, 2.0, 3.0], "sorted in place");
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), 3.0, "an even count gives the upper middle value");
        assert_eq!(median(&mut [5.0]), 5.0);
        assert_eq!(median(&mut []), 0.0);
    }
}
