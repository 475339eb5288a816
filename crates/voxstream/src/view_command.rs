//! `voxstream view`: opens the source as `render` does (same flags, same errors), builds the session, and hands it
//! to the viewer's window ([`voxstream_viewer::run_viewer`]).

use anyhow::{bail, Context, Result};
use clap::Parser;
use voxstream_core::Producer;
use voxstream_engine::{LoopLimits, MemoryBudget, Session};
use voxstream_render::TransferFunction;
use voxstream_viewer::script::{Script, ScriptCommand};
use voxstream_viewer::{run_viewer, Refinement, ViewerConfig};

use crate::backend::open_renderer;
use crate::cli::{Cli, Command, RefineArg, RenderArgs, Switch, ViewArgs};
use crate::exit_status::IncompleteImage;
use crate::iso_flags::check_isovalue;
use crate::output_file::check_output;
use crate::render_budget::{check_budget, plan_budget};
use crate::render_command::{check_flags, open_source, prepare_view, Source, SourceUser};

/// Runs `voxstream view`.
pub fn run(args: &ViewArgs) -> Result<()> {
    let render_args = render_args(args)?;
    // `render`'s checks and messages (size, budget, requests per frame).
    check_flags(&render_args)?;
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
    open_source(&render_args, &budget, ShowInWindow { script, stats: args.stats.clone(), refinement })
}

/// `render`'s arguments with `view`'s values, so that the source, the flags and their errors are `render`'s.
fn render_args(args: &ViewArgs) -> Result<RenderArgs> {
    let mut render = match Cli::try_parse_from(["voxstream", "render", "--quiet"]) {
        Ok(Cli { command: Some(Command::Render(render)) }) => render,
        _ => bail!("internal error: the default render arguments did not parse"),
    };
    render.source = args.source.clone();
    render.remote = args.remote.clone();
    render.camera = args.camera.clone();
    render.tf = args.tf.clone();
    render.width = args.width;
    render.height = args.height;
    render.budget_mb = args.budget_mb;
    render.requests_per_frame = args.requests_per_frame;
    render.blending = args.blending;
    render.shading = args.shading;
    render.light = args.light;
    render.iso = args.iso.clone();
    render.step = args.step;
    render.lod_bias = args.lod_bias;
    render.amplify = args.amplify;
    render.resolution = args.resolution;
    render.attribute = args.attribute;
    render.smoothing_scale = args.smoothing_scale;
    render.particle_memory = args.particle_memory;
    render.in_memory = args.in_memory;
    render.value_range = args.value_range;
    render.backend = args.backend;
    render.gpu_filter = args.gpu_filter;
    Ok(render)
}

struct ShowInWindow {
    script: Option<Script>,
    stats: Option<std::path::PathBuf>,
    refinement: Refinement,
}

impl SourceUser for ShowInWindow {
    fn use_source<P: Producer + 'static>(
        self,
        args: &RenderArgs,
        source: Source<P>,
        budget: &MemoryBudget,
    ) -> Result<()> {
        let prepared = prepare_view(args, &source)?;
        // The script's isovalues meet render's --iso checks, now that the data's range is known.
        if let Some(script) = &self.script {
            check_script_isovalues(script, source.value_range)?;
        }
        // After the source and the flags (their errors are `render`'s), before the pools are allocated.
        if !voxstream_viewer::has_display() {
            bail!(voxstream_viewer::ViewerError::NoDisplay);
        }
        let plan = plan_budget(budget, &source.producer.shape(), source.producer_cache_bytes)?;
        let limits = LoopLimits {
            requests_per_frame: args.requests_per_frame,
            blending_fade_frames: (args.blending == Switch::On).then_some(args.fade_frames),
            ..LoopLimits::default()
        };
        // After the display check (no GPU is opened for a window that cannot open), before the pools.
        let renderer = open_renderer(args.backend, args.gpu_filter)?;
        let session = Session::with_renderer(
            renderer,
            source.producer,
            &prepared.transfer_function,
            prepared.settings.clone(),
            plan.pool_bytes,
            limits,
            source.value_range,
        )?;
        let config = ViewerConfig {
            title: format!("voxstream view {}", source.name),
            camera: prepared.camera,
            transfer_function: prepared.transfer_function,
            settings: prepared.settings,
            value_range: source.value_range,
            presets: presets(source.typical_range),
            script: self.script,
            pool_budget_bytes: plan.pool_bytes,
            stats_path: self.stats,
            refinement: self.refinement,
            renderer: session.renderer().describe(),
        };
        let summary = run_viewer(session, config).context("voxstream view")?;
        // As `render`: bricks that could not be read make the run incomplete (exit 3).
        if summary.failed_bricks > 0 {
            return Err(IncompleteImage { failed_bricks: summary.failed_bricks }.into());
        }
        Ok(())
    }
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
