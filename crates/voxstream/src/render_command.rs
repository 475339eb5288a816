//! `voxstream render`: builds the session from the flags, renders a frame or a camera path, writes PNGs and stats.

use std::path::Path;

use anyhow::{bail, Context, Result};
use voxstream_render::{RenderSettings, Shading, TransferFunction};

use crate::camera_path::read_camera_path;
use crate::cli::{RenderArgs, ShadingArg};
use crate::memory::peak_rss_bytes;
use crate::png_output::{numbered_path, write_png};
use crate::scenes::{builtin, SCENE_NAMES};
use crate::session::{LoopLimits, Mode, Session};
use crate::stats::RunStats;

/// Largest accepted budget (1 TiB): guards against typos that would overflow.
const MAX_BUDGET_MB: u64 = 1 << 20;

/// Runs `voxstream render`.
pub fn run(args: &RenderArgs) -> Result<()> {
    let scene = builtin(&args.source).with_context(|| {
        format!("unknown source '{}': expected a built-in scene ({})", args.source, SCENE_NAMES.join(", "))
    })?;
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
    let transfer_function = match &args.tf {
        Some(path) => read_transfer_function(path)?,
        None => scene.transfer_function.clone(),
    };
    let settings = RenderSettings {
        width: args.width,
        height: args.height,
        shading: match args.shading {
            Some(ShadingArg::None) => Shading::None,
            Some(ShadingArg::Phong) => Shading::Phong,
            None => scene.shading,
        },
        light_direction: args.light,
        background: args.background.map(|c| c as f32),
        step_factor: args.step,
        lod_bias: args.lod_bias,
        ..RenderSettings::default()
    };
    settings.validate().context("invalid flags")?;
    let cameras = match &args.path {
        Some(path) => read_camera_path(path)?,
        None => {
            let mut camera = scene.camera;
            if let Some(eye) = args.eye {
                camera.eye = eye;
            }
            if let Some(target) = args.target {
                camera.target = target;
            }
            if let Some(up) = args.up {
                camera.up = up;
            }
            if let Some(fov) = args.fov {
                camera.fov = fov;
            }
            camera.frame(args.width, args.height).context("invalid camera")?;
            vec![camera]
        }
    };
    if let Some(parent) = args.out.parent().filter(|p| !p.as_os_str().is_empty()) {
        if !parent.is_dir() {
            bail!("output folder {} does not exist", parent.display());
        }
    }

    let budget_bytes = args.budget_mb * 1024 * 1024;
    let limits = LoopLimits { requests_per_frame: args.requests_per_frame, ..LoopLimits::default() };
    let mut session = Session::new(scene.producer, &transfer_function, settings, budget_bytes, limits)?;
    let mut stats = RunStats {
        source: scene.name.to_string(),
        mode: format!("{:?}", args.mode).to_lowercase(),
        budget_bytes,
        threads: rayon::current_num_threads(),
        ..RunStats::default()
    };
    let sequence = args.path.is_some();
    let mut reported_failures = 0usize;
    for (index, camera) in cameras.iter().enumerate() {
        let repeats = if sequence || args.mode == Mode::Converged { 1 } else { args.frames };
        for repeat in 0..repeats {
            let result = session.render(camera, args.mode)?;
            for failure in &result.failures {
                // Each failed brick is reported once; its ancestor stands in.
                if reported_failures < 20 {
                    eprintln!("warning: {failure}; drawing its coarser ancestor instead");
                }
                reported_failures += 1;
            }
            stats.frame_ms.push(result.elapsed_ms);
            stats.passes.push(result.passes);
            stats.rays += result.rays;
            stats.samples += result.samples;
            stats.requests += result.requests;
            stats.bricks_produced += result.bricks_produced;
            stats.converged = result.is_converged();
            if repeat + 1 == repeats {
                let out = if sequence { numbered_path(&args.out, index) } else { args.out.clone() };
                write_png(&result.image, &out)?;
                stats.frames += 1;
            }
        }
    }
    let residency = session.residency();
    stats.bricks_resident = residency.bricks as u64;
    stats.nodes_resident = residency.nodes;
    stats.resident_bytes_peak = session.peak_resident_bytes();
    stats.producer_failures = reported_failures;
    stats.peak_rss_bytes = peak_rss_bytes();
    if !stats.converged && args.mode == Mode::Converged {
        eprintln!(
            "warning: the last frame did not converge: the budget of {} MiB cannot hold what the view needs; \
             coarser data stands in",
            args.budget_mb
        );
    }
    if let Some(path) = &args.stats {
        let text = serde_json::to_string_pretty(&stats)?;
        std::fs::write(path, text).with_context(|| format!("cannot write stats to {}", path.display()))?;
    }
    Ok(())
}

fn read_transfer_function(path: &Path) -> Result<TransferFunction> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read transfer function {}", path.display()))?;
    TransferFunction::from_json(&text).with_context(|| format!("in {}", path.display()))
}
