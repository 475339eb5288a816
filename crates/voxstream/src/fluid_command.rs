//! `voxstream render --fluid`: a particle file (or a step of a time series) drawn as a liquid through the facade's
//! fluid path ([`voxstream_api::fluid`], Reichl ch. 6): binned once, bricks of bits made as rays ask, spheres
//! smoothed in screen space. One frame or a camera path, PNGs and a stats file.

use std::io::Write;

use anyhow::{bail, Result};
use serde_json::json;
use voxstream_api::camera_path::path_cameras;
use voxstream_api::fluid::{open_fluid, smoothing, FluidOptions};
use voxstream_api::view::apply_camera_options;
use voxstream_engine::Mode;
use voxstream_fluid::scene::FluidRenderSettings;

use crate::cli::{FluidFlags, RenderArgs, SmoothArg};
use crate::memory::peak_rss_bytes;
use crate::output_file::{check_output, write_output};
use crate::png_output::{numbered_path, write_png};
use crate::view_flags;

/// The flags that shape the volume, density or GPU paths, which the fluid path does not take: each is refused
/// with the reason, rather than ignored.
fn check_fluid_flags(args: &RenderArgs) -> Result<()> {
    let input = &args.input;
    let look = &args.look;
    let refused: [(bool, &str); 13] = [
        (input.attribute, "--attribute (the fluid path draws where particles are, not an attribute)"),
        (input.smoothing_scale.is_some(), "--smoothing-scale (spheres take --particle-radius)"),
        (input.resolution.is_some(), "--resolution (the grid's cell is --fluid-cell)"),
        (input.amplify.is_some(), "--amplify (meshes only)"),
        (input.particle_memory.is_some(), "--particle-memory (binning holds 4 bytes per particle)"),
        (input.in_memory, "--in-memory (stores only)"),
        (!look.iso.is_empty(), "--iso (the fluid's surface is its spheres)"),
        (look.tf.is_some(), "--tf (a fluid has no transfer function)"),
        (look.backend != crate::cli::Backend::Cpu, "--backend gpu (the fluid caster runs on the CPU)"),
        (args.mode != Mode::Converged, "--mode interactive (fluid frames are drawn complete)"),
        (args.popping, "--popping"),
        (look.preintegrate, "--preintegrate"),
        (look.colour_by_level, "--colour-by-level"),
    ];
    if let Some((_, flag)) = refused.iter().find(|(given, _)| *given) {
        bail!("{flag} does not apply with --fluid: drop it, or drop --fluid to render the particles' density");
    }
    check_fluid_values(&input.fluid)
}

/// The fluid flags' own ranges.
fn check_fluid_values(flags: &FluidFlags) -> Result<()> {
    for (name, value) in [("--particle-radius", flags.particle_radius), ("--fluid-cell", flags.fluid_cell)] {
        if let Some(v) = value.filter(|v| !(v.is_finite() && *v > 0.0)) {
            bail!("{name} {v} is out of range: give a positive length in the file's units");
        }
    }
    if let (Some(radius), Some(cell)) = (flags.particle_radius, flags.fluid_cell) {
        if radius / cell > 3.0 {
            bail!(
                "--particle-radius {radius} is more than 3 cells of --fluid-cell {cell}: each ray would test too many \
                 spheres; give a cell of at least a third of the radius"
            );
        }
    }
    if flags.smooth_iterations == 0 || flags.smooth_iterations > 10_000 {
        bail!(
            "--smooth-iterations {} is out of range: give 1 to 10000 (--smooth none for no smoothing)",
            flags.smooth_iterations
        );
    }
    if !(flags.smooth_strength.is_finite() && flags.smooth_strength > 0.0) {
        bail!("--smooth-strength {} is out of range: give a positive factor", flags.smooth_strength);
    }
    Ok(())
}

/// The fluid flags given without `--fluid`.
pub fn check_no_fluid_flags(flags: &FluidFlags) -> Result<()> {
    let defaults = FluidFlags::default();
    let given = [
        (flags.particle_radius.is_some(), "--particle-radius"),
        (flags.fluid_cell.is_some(), "--fluid-cell"),
        (flags.smooth != defaults.smooth, "--smooth"),
        (flags.smooth_iterations != defaults.smooth_iterations, "--smooth-iterations"),
        (flags.smooth_strength != defaults.smooth_strength, "--smooth-strength"),
        (flags.foam != defaults.foam, "--foam"),
    ];
    if let Some((_, flag)) = given.iter().find(|(g, _)| *g) {
        bail!("{flag} applies to fluids: add --fluid to draw the particle file as a fluid");
    }
    Ok(())
}

/// Runs `voxstream render --fluid`.
pub fn run(args: &RenderArgs) -> Result<()> {
    check_fluid_flags(args)?;
    let flags = &args.input.fluid;
    let name = match flags.smooth {
        SmoothArg::Rof => "rof",
        SmoothArg::Bilateral => "bilateral",
        SmoothArg::None => "none",
    };
    let render = FluidRenderSettings {
        foam_fraction: flags.foam,
        smoothing: smoothing(name, flags.smooth_iterations, flags.smooth_strength)?,
        lod_error: 2f64.powf(-args.look.lod_bias),
        ..FluidRenderSettings::default()
    };
    let options = FluidOptions {
        radius: flags.particle_radius,
        cell: flags.fluid_cell,
        time: args.input.time.map(|t| usize::try_from(t).unwrap_or(usize::MAX)),
        render,
        budget_mb: args.budget_mb,
        width: args.width,
        height: args.height,
    };
    check_output(&if args.path.is_some() { numbered_path(&args.out, 0) } else { args.out.clone() }, "--out")?;
    if let Some(path) = &args.stats {
        check_output(path, "--stats")?;
    }
    let mut source = open_fluid(&args.input.source, &options)?;
    if !args.quiet {
        eprintln!("{}", source.description);
    }
    let view = view_flags::view_options(&args.look, args.width, args.height);
    let name = source.path.display().to_string();
    let camera = apply_camera_options(source.camera, &view.camera, args.width, args.height, &name)?;
    let cameras = path_cameras(args.path.as_deref(), &camera)?;
    let sequence = args.path.is_some();
    let mut frames = Vec::new();
    let mut written = Vec::new();
    let mut incomplete = 0;
    for (index, camera) in cameras.iter().enumerate() {
        let started = std::time::Instant::now();
        let frame = source.scene.render(camera, args.width, args.height)?;
        let elapsed = started.elapsed();
        let s = &frame.statistics;
        incomplete += usize::from(!s.complete);
        frames.push(json!({
            "ms": elapsed.as_secs_f64() * 1e3,
            "passes": s.passes,
            "complete": s.complete,
            "bricks_made": s.bricks_made,
            "cast_ms": s.cast.as_secs_f64() * 1e3,
            "build_ms": s.build.as_secs_f64() * 1e3,
            "shade_ms": s.shade.as_secs_f64() * 1e3,
            "surface_pixels": s.surface_pixels,
            "resident_bricks": s.resident_bricks,
            "resident_bytes": s.resident_bytes,
        }));
        let out = if sequence { numbered_path(&args.out, index) } else { args.out.clone() };
        write_png(&frame.image, &out)?;
        written.push(out);
    }
    let bins = source.scene.bins();
    if let Some(path) = &args.stats {
        let stats = json!({
            "source": name,
            "particles": bins.particles,
            "radius": bins.radius,
            "cell": bins.grid.cell,
            "cells": bins.grid.cells,
            "occupied_cells": bins.occupied_cells(),
            "leaf_bricks": bins.occupied_bricks(0),
            "binning_s": source.binning.as_secs_f64(),
            "bins_bytes": bins.heap_bytes(),
            "resident_bytes": source.scene.resident_bytes(),
            "peak_rss_bytes": peak_rss_bytes(),
            "frames": frames,
        });
        write_output(path, |w| {
            serde_json::to_writer_pretty(&mut *w, &stats)?;
            Ok(writeln!(w)?)
        })?;
    }
    if !args.quiet {
        let first = &frames[0];
        eprintln!(
            "{} written: {} frame{}, first in {:.0} ms ({} passes, {} bricks made), binning {:.2} s, bricks {:.1} MB",
            written.first().map(|p| p.display().to_string()).unwrap_or_default(),
            frames.len(),
            if frames.len() == 1 { "" } else { "s" },
            first["ms"].as_f64().unwrap_or(0.0),
            first["passes"],
            first["bricks_made"],
            source.binning.as_secs_f64(),
            source.scene.resident_bytes() as f64 / 1e6,
        );
    }
    if incomplete > 0 {
        bail!(
            "{incomplete} frame(s) incomplete: the bricks the view needs do not fit --budget-mb {}; give more (the \
             image shows what fitted)",
            args.budget_mb
        );
    }
    Ok(())
}
