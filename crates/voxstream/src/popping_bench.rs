//! `voxstream bench --popping`: popping and seams (Thiele et al.'s evaluation, [`voxstream_engine::popping`]) along
//! four camera paths (at rest, orbit, zoom, fly-through; [`crate::camera_path::PathKind`]), each from a cold cache with a
//! bounded number of requests per frame, level blending off and on (and on with Thiele et al.'s restriction of the
//! working set lifted, to show what it adds), against the converged images at the same cameras; with the frame
//! times, so the cost of blending shows next to what it buys.

use std::io::Write;
use std::sync::Arc;

use anyhow::{Context, Result};
use serde::Serialize;
use voxstream_core::Producer;
use voxstream_engine::{LoopLimits, Mode, PoppingSummary, Session};
use voxstream_render::{Camera, RenderSettings};
use voxstream_store::{StoreProducer, StoreReader};

use crate::camera_path::{generated_path, PathKind};
use crate::cli::BenchArgs;
use crate::output_file::write_output;
use crate::popping_run::{write_strip, FrameRecorder};
use crate::render_budget::{check_budget, plan_budget};
use crate::render_command::{default_store_transfer_function, store_camera, store_placement};
use crate::scenes::builtin;

/// Scenes measured when `--scenes` is not given.
pub const DEFAULT_POPPING_SCENES: [&str; 1] = ["hypertexture"];

/// Frames of the strip written with `--strip`.
const STRIP_FRAMES: usize = 6;

/// One source and path, blending off and on.
#[derive(Clone, Debug, Serialize)]
pub struct PathFigures {
    /// Scene or store.
    pub source: String,
    /// rest, orbit, zoom or fly.
    pub path: String,
    /// Frames of the path.
    pub frames: usize,
    /// Blending off.
    pub off: PoppingSummary,
    /// Blending on.
    pub on: PoppingSummary,
    /// Median frame time, blending off, ms.
    pub off_frame_ms: f64,
    /// Median frame time, blending on, ms.
    pub on_frame_ms: f64,
    /// Frames until the image at the path's last camera was final (the path, then as many frames at its last
    /// camera as it takes, at most 1000 more), blending off.
    pub off_frames_to_final: usize,
    /// The same, blending on.
    pub on_frames_to_final: usize,
    /// Blending on with a free working set (Thiele et al.'s restriction off): what the restriction adds.
    pub free: PoppingSummary,
    /// Median frame time, blending on, working set free, ms.
    pub free_frame_ms: f64,
    /// Frames to final, blending on, working set free.
    pub free_frames_to_final: usize,
    /// Forced steps served over the path with blending on (the restricted working set), and evictions that yielded
    /// to the budget.
    pub forced_steps: u64,
    /// Evictions that broke the restriction for the budget's sake, over the path.
    pub restriction_yielded: u64,
}

/// Runs the popping benchmark and prints a Markdown table.
pub fn run(args: &BenchArgs) -> Result<()> {
    let frames = args.path_frames.max(2);
    let scenes: Vec<String> = if args.scenes.is_empty() {
        DEFAULT_POPPING_SCENES.iter().map(|s| s.to_string()).collect()
    } else {
        args.scenes.clone()
    };
    let budget = check_budget(args.budget_mb, args.size, args.size, "--size")?;
    let settings = RenderSettings { width: args.size, height: args.size, ..RenderSettings::default() };
    let mut figures = Vec::new();
    // The first path's recordings and the first frame of the strip.
    let mut strip_source: Option<(FrameRecorder, FrameRecorder, usize)> = None;
    for name in &scenes {
        let scene = builtin(name).with_context(|| format!("unknown scene '{name}'"))?;
        let settings = RenderSettings { shading: scene.shading, light_direction: scene.light, ..settings.clone() };
        let plan = plan_budget(&budget, &scene.producer.shape(), 0)?;
        for kind in PathKind::ALL {
            eprintln!("bench --popping: {name}, {} of {frames} frames …", kind.name());
            let mut make = |limits: LoopLimits| -> Result<Session<crate::scenes::SceneProducer>> {
                let tf = &scene.transfer_function;
                Ok(Session::new(scene.producer, tf, settings.clone(), plan.pool_bytes, limits)?)
            };
            let (figure, off, on) = study(name, &scene.camera, kind, frames, args, &mut make)?;
            if strip_source.is_none() {
                strip_source = Some((off, on, strip_start(&figure)));
            }
            figures.push(figure);
        }
    }
    if let Some(store) = &args.store {
        let name = store.display().to_string();
        let cache_bytes = budget.store_cache_bytes();
        let open = || StoreReader::open_with_cache(store, cache_bytes).with_context(|| format!("cannot open {name}"));
        let reader = open()?;
        let attributes = reader.attributes().clone();
        let transfer_function = default_store_transfer_function(attributes.typical_range())?;
        let camera = store_camera(reader.info(), args.size, args.size);
        let settings = RenderSettings { placement: store_placement(&reader), ..settings.clone() };
        let plan = plan_budget(&budget, &StoreProducer::new(Arc::new(open()?))?.shape(), cache_bytes)?;
        for kind in PathKind::ALL {
            eprintln!("bench --popping: {name}, {} of {frames} frames …", kind.name());
            // A new reader per run: each starts cold, its host cache empty too.
            let mut make = |limits: LoopLimits| -> Result<Session<StoreProducer>> {
                let producer = StoreProducer::new(Arc::new(open()?))?;
                Ok(Session::with_value_range(
                    producer,
                    &transfer_function,
                    settings.clone(),
                    plan.pool_bytes,
                    limits,
                    attributes.value_range,
                )?)
            };
            let (figure, off, on) = study(&name, &camera, kind, frames, args, &mut make)?;
            if strip_source.is_none() {
                strip_source = Some((off, on, strip_start(&figure)));
            }
            figures.push(figure);
        }
    }
    print_table(&figures, args, frames);
    if let (Some(path), Some((off, on, start))) = (&args.strip, &strip_source) {
        let start = *start;
        let rows = [off, on].map(|recorder| recorder.frames().skip(start).take(STRIP_FRAMES).collect::<Vec<&[u8]>>());
        write_strip(&rows, args.size, args.size, path)?;
        eprintln!(
            "bench --popping: wrote {} (frames {start}…{}, top: blending off, bottom: on)",
            path.display(),
            start + STRIP_FRAMES - 1
        );
    }
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&figures)?;
        write_output(path, |file| Ok(file.write_all(text.as_bytes())?)).context("--json")?;
    }
    Ok(())
}

/// The first recorded frame of a strip centred on the path's largest pop without blending.
fn strip_start(figure: &PathFigures) -> usize {
    let popping = &figure.off.popping_per_frame;
    let peak = popping.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)).map_or(0, |(i, _)| i);
    (figure.off.empty_frames_skipped + peak).saturating_sub(STRIP_FRAMES / 2 - 1)
}

/// One path from `view` over a source, blending off, on with a free working set, and on (restricted), each from a
/// cold session made by `make`; returns the figures and the recordings without and with blending (restricted).
fn study<P: Producer>(
    source: &str,
    view: &Camera,
    kind: PathKind,
    frames: usize,
    args: &BenchArgs,
    make: &mut dyn FnMut(LoopLimits) -> Result<Session<P>>,
) -> Result<(PathFigures, FrameRecorder, FrameRecorder)> {
    let cameras = generated_path(kind, frames, view);
    let mut runs = Vec::new();
    let mut exact = Vec::new();
    let (mut forced_steps, mut restriction_yielded) = (0, 0);
    // Off, on with a free working set, on (restricted).
    for (fade_frames, restrict) in [(None, false), (Some(args.fade_frames), false), (Some(args.fade_frames), true)] {
        let limits = LoopLimits {
            requests_per_frame: args.requests_per_frame,
            blending_fade_frames: fade_frames,
            restrict_working_set: restrict,
            ..LoopLimits::default()
        };
        let mut session = make(limits)?;
        let mut recorder = FrameRecorder::new(args.size, args.size, frames as u64).map_err(anyhow::Error::msg)?;
        let mut frame_ms = Vec::with_capacity(frames);
        let mut last_final = false;
        for camera in &cameras {
            let result = session.render(camera, Mode::Interactive)?;
            frame_ms.push(result.elapsed_ms);
            if restrict {
                forced_steps += result.forced_steps;
                restriction_yielded += result.restriction_yielded;
            }
            recorder.record(camera, &result.image);
            last_final = result.is_final();
        }
        // Then at the path's last camera: frames until its image is final.
        let mut frames_to_final = frames;
        if !last_final {
            let (extra, _) = session.render_until_converged_interactively(cameras.last().unwrap_or(view), 1000)?;
            frames_to_final += extra as usize;
        }
        if exact.is_empty() {
            exact = recorder.exact_images(&mut session)?;
        }
        frame_ms.sort_by(f64::total_cmp);
        runs.push((recorder, frame_ms[frame_ms.len() / 2], frames_to_final));
    }
    let (on, on_ms, on_final) = runs.pop().expect("three runs");
    let (free, free_ms, free_final) = runs.pop().expect("three runs");
    let (off, off_ms, off_final) = runs.pop().expect("three runs");
    let figure = PathFigures {
        source: source.to_string(),
        path: kind.name().to_string(),
        frames,
        off: off.summary(&exact),
        on: on.summary(&exact),
        off_frame_ms: off_ms,
        on_frame_ms: on_ms,
        off_frames_to_final: off_final,
        on_frames_to_final: on_final,
        free: free.summary(&exact),
        free_frame_ms: free_ms,
        free_frames_to_final: free_final,
        forced_steps,
        restriction_yielded,
    };
    Ok((figure, off, on))
}

fn print_table(figures: &[PathFigures], args: &BenchArgs, frames: usize) {
    println!(
        "{frames} frames of {0}x{0}, {1} requests per frame, fade-in {3} frames, threads: {2}; popping \
         and seams in 8-bit levels per pixel and channel (off → on); floor: the least mean popping any sequence from \
         the blended run's first image, showing the converged images from the frame it does on (or ending at its \
         last image), could have, and the ratio to the popping without blending that such a sequence would reach\n",
        args.size,
        args.requests_per_frame,
        rayon::current_num_threads(),
        args.fade_frames
    );
    println!("| source | path | popping mean | ratio | floor | ratio at the floor | popping p99 | ratio | seams mean | ratio | frame ms (median) | cost | frames to final |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    let ratio = |off: f64, on: f64| if on > 0.0 { format!("{:.2}×", off / on) } else { "∞".into() };
    for f in figures {
        println!(
            "| {} | {} | {:.3} → {:.3} | {} | {:.3} | {} | {:.2} → {:.2} | {} | {:.3} → {:.3} | {} | {:.0} → {:.0} | {:+.0}% | {} → {} |",
            f.source,
            f.path,
            f.off.popping_mean,
            f.on.popping_mean,
            ratio(f.off.popping_mean, f.on.popping_mean),
            f.on.popping_floor,
            ratio(f.off.popping_mean, f.on.popping_floor),
            f.off.popping_p99,
            f.on.popping_p99,
            ratio(f.off.popping_p99, f.on.popping_p99),
            f.off.seam_mean,
            f.on.seam_mean,
            ratio(f.off.seam_mean, f.on.seam_mean),
            f.off_frame_ms,
            f.on_frame_ms,
            (f.on_frame_ms / f.off_frame_ms.max(1e-9) - 1.0) * 100.0,
            f.off_frames_to_final,
            f.on_frames_to_final,
        );
    }
    println!(
        "\nWhat the restricted working set adds to blending (blending on, working set free → restricted; forced: steps \
         served so that neighbours stay within one level, yielded: evictions that broke it for the budget)\n"
    );
    println!("| source | path | popping mean | popping p99 | seams mean | frame ms (median) | frames to final | forced | yielded |");
    println!("|---|---|---|---|---|---|---|---|---|");
    for f in figures {
        println!(
            "| {} | {} | {:.3} → {:.3} | {:.2} → {:.2} | {:.3} → {:.3} | {:.0} → {:.0} | {} → {} | {} | {} |",
            f.source,
            f.path,
            f.free.popping_mean,
            f.on.popping_mean,
            f.free.popping_p99,
            f.on.popping_p99,
            f.free.seam_mean,
            f.on.seam_mean,
            f.free_frame_ms,
            f.on_frame_ms,
            f.free_frames_to_final,
            f.on_frames_to_final,
            f.forced_steps,
            f.restriction_yielded,
        );
    }
}
