//! Knoll et al.'s ablation for voxstream's isosurfaces, on one store and camera: exact cells alone, then culling,
//! then shared descents (in the packets' place), then the cone's level of detail, then shadows; the cold frame, the
//! warm frame time and the cells examined per ray.
//!
//! ```sh
//! cargo run --release -p voxstream --example isosurface_ablation -- STORE ISO [CAMERA.json] [SIZE] [FRAMES] [LIGHT]
//! ```
//!
//! `CAMERA.json` is a camera path file (its first camera is used; `-` for the store's default view), `LIGHT` the
//! direction towards the light for the shadow row, `x,y,z`. Knoll's packets trace coherent rays in lock-step, which
//! is not implemented; what stands in their row is the part of them voxstream has: each ray's first descent shared
//! with the ray before it ([`RenderSettings::shared_descents`]).

use std::sync::Arc;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use voxstream::camera_path::read_camera_path;
use voxstream::cli::parse_vec3;
use voxstream::render_command::{store_camera, store_placement};
use voxstream_engine::{LoopLimits, Mode, Session};
use voxstream_render::{IsoSurface, RenderSettings, Shading, TransferFunction};
use voxstream_store::{StoreProducer, StoreReader};

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 2 {
        bail!("usage: isosurface_ablation STORE ISO [CAMERA.json|-] [SIZE] [FRAMES] [LIGHT x,y,z]");
    }
    let reader = Arc::new(StoreReader::open(std::path::Path::new(&args[0])).context("opening the store")?);
    let iso: f64 = args[1].parse().context("ISO must be a number")?;
    let size: u32 = args.get(3).map(|s| s.parse()).transpose().context("SIZE")?.unwrap_or(512);
    let frames: usize = args.get(4).map(|s| s.parse()).transpose().context("FRAMES")?.unwrap_or(5);
    let light = match args.get(5) {
        Some(text) => parse_vec3(text).map_err(anyhow::Error::msg)?,
        None => [0.0, 0.0, 1.0],
    };
    let camera = match args.get(2).map(String::as_str) {
        None | Some("-") => store_camera(reader.info(), size, size),
        Some(path) => read_camera_path(std::path::Path::new(path))?[0],
    };
    let range = reader.attributes().value_range;
    let unused = TransferFunction::new(vec![[range[0], 0.0, 0.0, 0.0, 0.0], [range[1], 0.0, 0.0, 0.0, 0.0]], None)?;
    let base = RenderSettings {
        width: size,
        height: size,
        placement: store_placement(&reader),
        shading: Shading::Phong,
        light_direction: Some(light),
        surfaces: vec![IsoSurface { value: iso, color: [0.9, 0.75, 0.65], opacity: 1.0 }],
        ..RenderSettings::default()
    };
    let variants: [(&str, RenderSettings); 5] = [
        (
            "exact cells, finest level, no culling",
            RenderSettings { skip_empty_space: false, lod_bias: 8.0, shared_descents: false, ..base.clone() },
        ),
        (
            "+ culling (subtrees, bricks, blocks)",
            RenderSettings { lod_bias: 8.0, shared_descents: false, ..base.clone() },
        ),
        ("+ shared descents (not lock-step packets)", RenderSettings { lod_bias: 8.0, ..base.clone() }),
        ("+ level of detail (the cone's)", base.clone()),
        ("+ shadows", RenderSettings { shadows: true, ..base.clone() }),
    ];
    println!("{} at {iso}, {size}², {frames} warm frames (median)\n", args[0]);
    println!("| variant | cold frame | bricks loaded | warm frame | cells per ray |");
    println!("|---|---:|---:|---:|---:|");
    for (name, settings) in variants {
        let producer = StoreProducer::new(reader.clone())?;
        let mut session =
            Session::with_value_range(producer, &unused, settings, 1 << 30, LoopLimits::default(), range)?;
        let start = Instant::now();
        let cold = session.render(&camera, Mode::Converged)?;
        let cold_ms = start.elapsed().as_secs_f64() * 1e3;
        let mut warm = Vec::new();
        let mut cells_per_ray = 0.0;
        for _ in 0..frames {
            let start = Instant::now();
            let frame = session.render(&camera, Mode::Converged)?;
            warm.push(start.elapsed().as_secs_f64() * 1e3);
            cells_per_ray = frame.samples as f64 / frame.rays.max(1) as f64;
        }
        warm.sort_by(f64::total_cmp);
        println!(
            "| {name} | {cold_ms:.0} ms | {} | {:.1} ms | {cells_per_ray:.1} |",
            cold.bricks_produced,
            warm[warm.len() / 2]
        );
    }
    Ok(())
}
