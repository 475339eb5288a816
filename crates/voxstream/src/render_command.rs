//! `voxstream render`: builds the session from the flags, renders a frame or a camera path, writes PNGs and stats.

use std::io::Write;

use anyhow::{bail, Context, Result};
use voxstream_api::annotations::{annotate, AnnotationContext, Annotations};
use voxstream_api::{PreparedView, SessionOptions, Source, SourceMeta, SourceOptions, ViewOptions};
use voxstream_engine::{MemoryBudget, Mode, MAX_BUDGET_MB};

pub use voxstream_api::defaults::{
    counted, default_store_transfer_function, frame_box, shown_number, store_camera, store_placement,
    STORE_VIEW_DIRECTION,
};

use crate::camera_path::path_cameras;
use crate::cli::{RenderArgs, Switch};
use crate::exit_status::IncompleteImage;
use crate::memory::{bytes_read, peak_rss_bytes};
use crate::output_file::{check_output, write_output};
use crate::png_output::{numbered_path, write_png};
use crate::popping_run::FrameRecorder;
use crate::render_budget::check_budget;
use crate::render_progress::RenderProgress;
use crate::render_warnings::{empty_image, transfer_function_mismatch};
use crate::stats::RemoteStats;
use crate::stats::RunStats;
use crate::video_output::VideoWriter;
use crate::view_flags;

/// Runs `voxstream render`.
pub fn run(args: &RenderArgs) -> Result<()> {
    if args.input.fluid.fluid {
        check_flags(args)?;
        // The image's buffers are sized by --width and --height: checked against the budget and the machine first.
        check_budget(args.budget_mb, args.width, args.height, "--width/--height")?;
        return crate::fluid_command::run(args);
    }
    // Bytes read before the store is open: its metadata, and for other tools' stores the scan of their values.
    let read_at_start = bytes_read();
    crate::fluid_command::check_no_fluid_flags(&args.input.fluid)?;
    check_flags(args)?;
    let budget = check_budget(args.budget_mb, args.width, args.height, "--width/--height")?;
    let source = open_source(args, &budget)?;
    let meta = source.meta.clone();
    let result = render_source(args, source, &budget, read_at_start);
    if let Some(warning) = meta.clipped_warning() {
        eprintln!("{warning}");
    }
    result
}

/// Opens `args.source` (a built-in scene, a mesh or particle file, or a store) with its defaults, through the
/// facade ([`voxstream_api::open`]); a mesh's or particles' description is shown unless `--quiet`.
pub fn open_source(args: &RenderArgs, budget: &MemoryBudget) -> Result<Source> {
    let source = voxstream_api::open(&args.input.source, &source_options(args), budget)?;
    if let Some(description) = source.meta.description.as_ref().filter(|_| !args.quiet) {
        eprintln!("{description}");
    }
    Ok(source)
}

/// The source options the flags give.
pub fn source_options(args: &RenderArgs) -> SourceOptions {
    view_flags::source_options(&args.input, args.width, args.height, args.quiet)
}

/// The view options the flags give.
pub fn view_options(args: &RenderArgs) -> ViewOptions {
    view_flags::view_options(&args.look, args.width, args.height)
}

/// The session options the flags give.
pub fn session_options(args: &RenderArgs) -> SessionOptions {
    view_flags::session_options(&args.look, args.budget_mb, args.requests_per_frame)
}

/// Applies the flags to a source's defaults.
pub fn prepare_view(args: &RenderArgs, source: &SourceMeta) -> Result<PreparedView> {
    voxstream_api::prepare_view(&view_options(args), source)
}

/// `render`'s checks of the flags (also `view`'s, on the arguments it builds).
pub fn check_flags(args: &RenderArgs) -> Result<()> {
    crate::backend::check_backend_flags(args.look.backend, args.look.gpu_filter)?;
    if args.look.backend == crate::backend::Backend::Gpu && args.look.preintegrate {
        bail!("--preintegrate is not drawn by the GPU backend yet: use --backend cpu, or drop --preintegrate");
    }
    if args.width == 0 || args.height == 0 {
        bail!("image size must be positive, got {}x{}", args.width, args.height);
    }
    if args.budget_mb == 0 {
        bail!("--budget-mb must be at least 1");
    }
    if args.budget_mb > MAX_BUDGET_MB {
        bail!("--budget-mb {} is larger than 1 TiB", args.budget_mb);
    }
    if args.frames == 0 {
        bail!("--frames must be at least 1");
    }
    if args.requests_per_frame == 0 {
        bail!("--requests-per-frame must be at least 1");
    }
    if let Some(video) = &args.video {
        if args.path.is_none() {
            bail!("--video encodes a camera path's frames: add --path (e.g. --path orbit:120:360), or drop --video");
        }
        if !(args.fps.is_finite() && args.fps > 0.0 && args.fps <= 1000.0) {
            bail!("--fps {} must be a number of frames a second in (0, 1000]", args.fps);
        }
        crate::video_output::check_video(video)?;
    }
    if args.popping && (args.mode != Mode::Interactive || args.stats.is_none()) {
        bail!("--popping measures interactive frames into the stats file: add --mode interactive and --stats FILE");
    }
    check_fade_frames(args.look.fade_frames)
}

/// `--fade-frames` (render and bench): at least 1.
pub fn check_fade_frames(fade_frames: u32) -> Result<()> {
    if fade_frames == 0 {
        bail!("--fade-frames must be at least 1 (1 replaces a parent at once; use --blending off for no blending)");
    }
    Ok(())
}

/// Renders `source` as `args` say; `read_at_start`: the process' bytes read before the source was opened.
fn render_source(args: &RenderArgs, source: Source, budget: &MemoryBudget, read_at_start: Option<u64>) -> Result<()> {
    let Source { producer, meta: source } = source;
    let prepared = prepare_view(args, &source)?;
    let PreparedView { transfer_function, camera: view, drawing_surfaces, .. } = &prepared;
    let (view, drawing_surfaces) = (*view, *drawing_surfaces);
    let surfaces_in_volume = prepared.settings.surfaces_in_volume;
    let cameras = path_cameras(args.path.as_deref(), &view)?;
    let annotations = Annotations { color_bar: args.look.color_bar, scale_bar: args.look.scale_bar };
    if args.look.color_bar && drawing_surfaces && !surfaces_in_volume {
        bail!("--color-bar shows the transfer function, and only isosurfaces are drawn: add --tf to draw the volume too, or drop --color-bar");
    }
    let unit = source.store.as_ref().and_then(|store| store.info().unit.map(|u| u.name()));
    // Before the work: a folder, a disk or a missing folder as an output is refused now, not after the render.
    if args.video.is_none() {
        check_output(&if args.path.is_some() { numbered_path(&args.out, 0) } else { args.out.clone() }, "--out")?;
    }
    if let Some(path) = &args.stats {
        check_output(path, "--stats")?;
    }

    let budget_bytes = budget.total_bytes();
    let (mut session, _plan) =
        voxstream_api::start_session(producer, &source, &prepared, &session_options(args), budget)?;
    let mut stats = RunStats {
        source: source.name.clone(),
        mode: format!("{:?}", args.mode).to_lowercase(),
        budget_bytes,
        threads: rayon::current_num_threads(),
        backend: session.renderer().describe(),
        backend_warning: session.renderer().device_warning(),
        ..RunStats::default()
    };
    stats.camera = cameras.first().copied();
    let read_before = bytes_read();
    let sequence = args.path.is_some();
    let repeats = if sequence || args.mode == Mode::Converged { 1 } else { args.frames };
    let progress = RenderProgress::new(cameras.len() as u64 * u64::from(repeats), args.quiet);
    if let Some(warning) = &stats.backend_warning {
        progress.warn(warning);
    }
    let mismatch = transfer_function_mismatch(transfer_function, source.typical_range, source.value_range);
    if let Some(warning) = mismatch.filter(|_| !drawing_surfaces || surfaces_in_volume) {
        progress.warn(&warning);
    }
    // --popping: popping and seams against the converged images, rendered afterwards.
    let mut recorder = None;
    if args.popping {
        match FrameRecorder::new(args.width, args.height, cameras.len() as u64 * u64::from(repeats)) {
            Ok(r) => recorder = Some(r),
            Err(warning) => progress.warn(&warning),
        }
    }
    stats.blending = args.mode == Mode::Interactive && args.look.blending == Switch::On;
    let mut empty_images = 0usize;
    let mut reported_failures = 0usize;
    let mut written = Vec::new();
    let mut video = match &args.video {
        Some(path) => Some(VideoWriter::start(path, args.width, args.height, args.fps)?),
        None => None,
    };
    for (index, camera) in cameras.iter().enumerate() {
        for repeat in 0..repeats {
            let result = session.render_observed(camera, args.mode, &mut |pass| progress.pass(pass))?;
            for failure in &result.failures {
                // Each failed brick is reported once; its ancestor stands in.
                if reported_failures < 20 {
                    progress.warn(&format!("{failure}; drawing its coarser ancestor instead"));
                }
                reported_failures += 1;
            }
            stats.frame_ms.push(result.elapsed_ms);
            stats.passes.push(result.passes);
            stats.rays += result.rays;
            stats.samples += result.samples;
            stats.requests += result.requests;
            stats.bricks_produced += result.bricks_produced;
            stats.forced_steps += result.forced_steps;
            stats.restriction_yielded += result.restriction_yielded;
            stats.converged = result.is_converged();
            if let Some(recorder) = &mut recorder {
                recorder.record(camera, &result.image);
            }
            // A single camera stops early once a frame is final (nothing missing, nothing blending): later frames
            // would be identical.
            if repeat + 1 == repeats || (!sequence && result.is_final()) {
                // The annotations go on a copy: the checks below see the image as rendered.
                let context = AnnotationContext { transfer_function, camera, world_per_unit: 1.0, unit };
                let annotated = annotations.any().then(|| annotate(&result.image, annotations, &context));
                let image = annotated.as_ref().unwrap_or(&result.image);
                let out = match (&mut video, sequence) {
                    (Some(video), _) => {
                        video.push(image)?;
                        args.video.clone().expect("a video path")
                    }
                    (None, true) => numbered_path(&args.out, index),
                    (None, false) => args.out.clone(),
                };
                if video.is_none() {
                    write_png(image, &out)?;
                }
                let volume = !drawing_surfaces || surfaces_in_volume;
                if let Some(mut warning) = empty_image(&result.image, drawing_surfaces, volume) {
                    if prepared.settings.projection == voxstream_render::Projection::Minimum {
                        warning.push_str(
                            "; a minimum projection shows the smallest value along each ray, which a background of \
                             zeros makes transparent under most transfer functions: --crop or --clip-plane inside \
                             the object, or a --tf opaque at low values",
                        );
                    }
                    if empty_images == 0 {
                        progress.warn(&format!("{}: {warning}", out.display()));
                    }
                    empty_images += 1;
                }
                stats.frames += 1;
                // A sequence lists each file as it is written; a single image or a movie is named in the summary.
                progress.frame_done((sequence && video.is_none()).then_some(out.as_path()));
                if video.is_none() {
                    written.push(out);
                }
                break;
            }
            progress.frame_done(None);
        }
    }
    if let (Some(video), Some(path)) = (video, &args.video) {
        video.finish()?;
        written.push(path.clone());
    }
    if let Some(recorder) = &recorder {
        stats.popping = Some(recorder.measure(&mut session)?);
    }
    let residency = session.residency();
    stats.bricks_resident = residency.bricks as u64;
    stats.nodes_resident = residency.nodes;
    stats.resident_bytes_peak = session.peak_resident_bytes();
    stats.bytes_uploaded = session.renderer().bytes_uploaded();
    stats.producer_failures = reported_failures;
    stats.peak_rss_bytes = peak_rss_bytes();
    stats.first_frame_ms = stats.frame_ms.first().copied();
    if let (Some(before), Some(after)) = (read_before, bytes_read()) {
        if source.producer_cache_bytes > 0 {
            stats.file_bytes_read = Some(after - before);
            stats.file_bytes_read_opening = read_at_start.map(|start| before.saturating_sub(start));
            let m = session.cache().shape().brick_size as u64;
            stats.brick_bytes_used = Some(residency.bricks as u64 * m * m * m * source.sample_bytes);
        }
    }
    stats.remote = source.remote.as_ref().map(|remote| RemoteStats::from(remote.counts()));
    stats.host_caches = source.store.as_ref().map(|store| store.host_caches());
    if !stats.converged && args.mode == Mode::Converged {
        progress.warn(&format!(
            "the last frame did not converge: the budget of {} MiB cannot hold what the view needs; coarser data \
             stands in (raise --budget-mb)",
            args.budget_mb
        ));
    }
    if empty_images > 1 {
        progress.warn(&format!("{empty_images} of the {} images written are empty", written.len()));
    }
    if let Some(path) = &args.stats {
        let text = serde_json::to_string_pretty(&stats)?;
        write_output(path, |file| Ok(file.write_all(text.as_bytes())?))
            .with_context(|| format!("cannot write stats to {}", path.display()))?;
    }
    progress.finish(&summary_line(&written, args, &stats));
    if reported_failures > 0 {
        return Err(IncompleteImage { failed_bricks: reported_failures }.into());
    }
    Ok(())
}

/// `wrote frame.png (512x512, converged, 10 passes, 6198 bricks loaded)`, or for a sequence the first and last file.
fn summary_line(written: &[std::path::PathBuf], args: &RenderArgs, stats: &RunStats) -> String {
    let files = match written {
        [one] if args.video.is_some() => format!("{} frames into {}", stats.frames, one.display()),
        [one] => one.display().to_string(),
        [first, .., last] => format!("{} frames, {} … {}", written.len(), first.display(), last.display()),
        [] => "nothing".into(),
    };
    let state = if stats.producer_failures > 0 {
        format!("incomplete: {} bricks unreadable, coarser data stands in", stats.producer_failures)
    } else if stats.converged {
        "complete".into()
    } else {
        "incomplete: coarser data stands in".into()
    };
    let passes: u32 = stats.passes.iter().sum();
    format!(
        "wrote {files} ({}x{}, {state}, {}, {} loaded)",
        args.width,
        args.height,
        counted(passes, "pass", "passes"),
        counted(stats.bricks_produced, "brick", "bricks")
    )
}
