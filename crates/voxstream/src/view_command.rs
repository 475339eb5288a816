//! `voxstream view`: opens the source as `render` does (same flags, same errors), builds the session, and hands it
//! to the viewer's window ([`voxstream_viewer::run_viewer`]).

use anyhow::{bail, Context, Result};
use voxstream_api::Source;
use voxstream_render::TransferFunction;
use voxstream_viewer::script::{Script, ScriptCommand};
use voxstream_viewer::{run_viewer, Refinement, ViewerConfig};

use crate::cli::{RefineArg, ViewArgs};
use crate::exit_status::IncompleteImage;
use crate::iso_flags::check_isovalue;
use crate::output_file::check_output;
use crate::render_budget::check_budget;
use crate::view_flags;

/// Runs `voxstream view`.
pub fn run(args: &ViewArgs) -> Result<()> {
    if args.input.fluid.fluid {
        bail!(
            "view --fluid is not built yet: `voxstream render --fluid` draws the fluid (with --path for a camera path)"
        );
    }
    crate::fluid_command::check_no_fluid_flags(&args.input.fluid)?;
    // `render`'s checks and messages (size, budget, requests per frame, backend flags).
    crate::backend::check_backend_flags(args.look.backend, args.look.gpu_filter)?;
    crate::render_command::check_fade_frames(args.look.fade_frames)?;
    if args.width == 0 || args.height == 0 {
        bail!("image size must be positive, got {}x{}", args.width, args.height);
    }
    if args.requests_per_frame == 0 {
        bail!("--requests-per-frame must be at least 1");
    }
    if let Some(path) = &args.stats {
        check_output(path, "--stats")?;
    }
    // The script is checked before anything is opened: a typo on line 12 should not wait for a window.
    let script = match &args.script {
        Some(path) => Some(Script::read(path)?),
        None => None,
    };
    let budget = check_budget(args.budget_mb, args.width, args.height, "--width/--height")?;
    let refinement = match args.refine {
        RefineArg::Converged => Refinement::Converged,
        RefineArg::Blended => Refinement::Blended,
    };
    let source_options = view_flags::source_options(&args.input, args.width, args.height, true);
    let Source { producer, meta } = voxstream_api::open(&args.input.source, &source_options, &budget)?;
    let prepared = voxstream_api::prepare_view(&view_flags::view_options(&args.look, args.width, args.height), &meta)?;
    // The script's isovalues meet render's --iso checks, now that the data's range is known.
    if let Some(script) = &script {
        check_script_isovalues(script, meta.value_range)?;
    }
    // After the source and the flags (their errors are `render`'s), before the pools are allocated and before a GPU
    // is opened for a window that cannot open.
    if !voxstream_viewer::has_display() {
        bail!(voxstream_viewer::ViewerError::NoDisplay);
    }
    let session_options = view_flags::session_options(&args.look, args.budget_mb, args.requests_per_frame);
    let (session, plan) = voxstream_api::start_session(producer, &meta, &prepared, &session_options, &budget)?;
    let renderer_warning = session.renderer().device_warning();
    if let Some(warning) = &renderer_warning {
        eprintln!("warning: {warning}");
    }
    let config = ViewerConfig {
        title: format!("voxstream view {}", meta.name),
        camera: prepared.camera,
        transfer_function: prepared.transfer_function,
        settings: prepared.settings,
        volume_adaptive_step: prepared.volume_adaptive_step,
        value_range: meta.value_range,
        presets: presets(meta.typical_range),
        script,
        pool_budget_bytes: plan.pool_bytes,
        stats_path: args.stats.clone(),
        refinement,
        renderer: session.renderer().describe(),
        renderer_warning,
        annotations: voxstream_api::annotations::Annotations {
            color_bar: args.look.color_bar,
            scale_bar: args.look.scale_bar,
        },
        unit: meta.store.as_ref().and_then(|s| s.info().unit.map(|u| u.name().to_string())),
        host_caches: meta.store.clone().map(|store| -> Box<dyn Fn() -> String + Send> {
            Box::new(move || host_caches_status(&store.host_caches()))
        }),
    };
    let summary = run_viewer(session, config).context("voxstream view");
    if let Some(warning) = meta.clipped_warning() {
        eprintln!("{warning}");
    }
    // As `render`: bricks that could not be read make the run incomplete (exit 3).
    let failed_bricks = summary?.failed_bricks;
    if failed_bricks > 0 {
        return Err(IncompleteImage { failed_bricks }.into());
    }
    Ok(())
}

/// Refuses a script's `iso VALUE` that `render --iso VALUE` would refuse on the same data.
fn check_script_isovalues(script: &Script, value_range: [f64; 2]) -> Result<()> {
    for (line, command) in &script.commands {
        if let ScriptCommand::Iso(Some(value)) = command {
            check_isovalue(*value, value_range, &format!("{} line {line}: iso", script.name))?;
        }
    }
    Ok(())
}

/// Presets over the bulk of the values: a grey ramp, a warm "bone" ramp, and a cool-to-warm map.
fn presets(range: [f64; 2]) -> Vec<(String, TransferFunction)> {
    let [lo, hi] = range;
    let hi = if hi > lo { hi } else { lo + 1.0 };
    let at = |f: f64| lo + (hi - lo) * f;
    let make = |points: Vec<[f64; 5]>| TransferFunction::new(points, None).ok();
    [
        ("grey ramp", make(vec![[at(0.0), 0.0, 0.0, 0.0, 0.0], [at(1.0), 1.0, 1.0, 1.0, 0.1]])),
        (
            "bone",
            make(vec![
                [at(0.0), 0.0, 0.0, 0.0, 0.0],
                [at(0.45), 0.55, 0.25, 0.15, 0.0],
                [at(0.7), 0.9, 0.8, 0.65, 0.3],
                [at(1.0), 1.0, 1.0, 0.95, 0.8],
            ]),
        ),
        (
            "cool to warm",
            make(vec![
                [at(0.0), 0.23, 0.3, 0.75, 0.0],
                [at(0.5), 0.87, 0.87, 0.87, 0.03],
                [at(1.0), 0.71, 0.02, 0.15, 0.12],
            ]),
        ),
    ]
    .into_iter()
    .filter_map(|(name, tf)| tf.map(|tf| (name.to_string(), tf)))
    .collect()
}

/// The status line's words for a store's host caches: the decoded-brick cache's budget, and the compressed one's
/// use of its budget and the reads it saved.
fn host_caches_status(caches: &voxstream_store::store_reader::HostCaches) -> String {
    let mib = |b: u64| b as f64 / (1 << 20) as f64;
    match caches.compressed {
        Some(c) => format!(
            "host cache {:.0} MiB decoded + {:.1} of {:.0} MiB compressed ({} reads saved)",
            mib(caches.decoded_bytes),
            mib(c.held_bytes),
            mib(c.capacity_bytes),
            c.hits
        ),
        None => format!("host cache {:.0} MiB decoded", mib(caches.decoded_bytes)),
    }
}
