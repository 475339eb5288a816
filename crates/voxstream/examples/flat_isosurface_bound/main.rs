//! How fast can exact isosurface ray casting be on this CPU when there is no tree at all? A bound for the
//! isosurfaces' frame-rate targets (issue: exact isosurfaces, Knoll et al.), measured on a store's finest level
//! copied into one flat array, as `flat_march_bound` does for the volume renderer.
//!
//! Each ray does what the renderer's isosurface integrand must do at the least, and nothing a tree costs:
//! - the ray is clipped to the box of voxel centres;
//! - a DDA over occupancy blocks of 8³ cells skips every block whose values all lie below the isovalue (one bit per
//!   block, computed once for the isovalue, usable from the ray's entry on, where the renderer can cull only once
//!   it has read the ray's first data);
//! - inside a block that can hold the surface, a DDA over its trilinear cells; a cell whose corners straddle the
//!   isovalue is intersected exactly by the renderer's own [`CellCubic`](voxstream_render::cell_intersection::CellCubic) (split at the cubic's extrema, regula
//!   falsi), the first crossing ends the ray;
//! - the hit is shaded by two-sided Phong with the cell's analytic gradient (the renderer's [`RayLight`]).
//!
//! No descents, no segments, no bricks, no level of detail, no feedback, no requests, one surface, no shadows. Three
//! rows:
//! - `8³-cell blocks`: one ray at a time, scalar;
//! - `… within 32³-cell macro-blocks`: the same with a level above the blocks, macro-blocks of 4³ blocks with a bit
//!   each, walked by their own DDA, so that empty space is crossed in fewer steps;
//! - `8³-cell blocks, 8 rays in lock-step` (x86-64 with AVX2): the first row's walk for eight rays at once, Knoll et
//!   al.'s packets in the form voxstream's volume renderer uses for samples (each lane its own ray, refilled when it
//!   ends), with the DDA arithmetic in AVX2 registers and the corners read by gathers; the example checks that its
//!   image is the first row's, bit for bit.
//!
//! They are straightforward walks, not a floor under every way of finding the surface: finer blocks, distance fields
//! or packets sharing a slice cache would do less per ray.
//!
//! ```sh
//! cargo run --release -p voxstream --example flat_isosurface_bound -- STORE ISO CAMERA.json [SIZE] [FRAMES] [LIGHT] [OUT.png]
//! ```
//!
//! Prints, per row, the frame time (median), the rays that hit, the macro-blocks and blocks stepped and the cells
//! examined per ray, and ns per ray and core; with `OUT.png`, writes the image (compare it with `voxstream render
//! STORE --iso ISO` with the same camera and light to see the same surface). The store must hold 8-bit values and
//! have cubic voxels.

use std::path::Path;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use voxstream::bench::median;
use voxstream::camera_path::read_camera_path;
use voxstream::cli::parse_vec3;
use voxstream::png_output::write_rgb8_png;
use voxstream_render::lighting::LightingSettings;
use voxstream_render::{RenderSettings, Shading};
use voxstream_store::StoreReader;

/// The lock-step row: x86-64 with AVX2 only.
#[cfg(target_arch = "x86_64")]
mod lock_step;
mod scene;

use scene::{Scene, Volume, BLOCK, MACRO};

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 3 {
        bail!("usage: flat_isosurface_bound STORE ISO CAMERA.json [SIZE] [FRAMES] [LIGHT x,y,z] [OUT.png]");
    }
    let reader = StoreReader::open(Path::new(&args[0])).context("opening the store")?;
    let iso: f32 = args[1].parse().context("ISO: a number")?;
    let size: u32 = args.get(3).map(|s| s.parse()).transpose().context("SIZE")?.unwrap_or(512);
    let frames: usize = args.get(4).map(|s| s.parse()).transpose().context("FRAMES")?.unwrap_or(5);
    let light = args.get(5).map(|s| parse_vec3(s)).transpose().map_err(anyhow::Error::msg).context("LIGHT")?;
    if !(1..=16384).contains(&size) {
        bail!("SIZE must be 1 to 16384 pixels");
    }
    if frames == 0 {
        bail!("FRAMES must be at least 1");
    }
    if !iso.is_finite() {
        bail!("ISO must be a finite number");
    }
    if let Some(l) = light {
        if !l.iter().all(|v| v.is_finite()) || l == [0.0; 3] {
            bail!("LIGHT must be a finite, non-zero direction x,y,z");
        }
    }
    let info = reader.info().clone();
    if info.spacing.iter().any(|&s| !(s > 0.0 && s.is_finite())) || info.origin.iter().any(|o| !o.is_finite()) {
        bail!("the store's voxel spacing must be positive and its origin finite");
    }
    if info.spacing.iter().any(|&s| (s - info.spacing[0]).abs() > 1e-9 * info.spacing[0]) {
        bail!("this bound shades in voxel units, which matches the renderer only for cubic voxels: the store's spacing differs between axes");
    }
    let dims = info.dims.map(|d| d as usize);
    if dims.iter().any(|&n| n < 2) {
        bail!("the volume needs at least two voxels along each axis");
    }
    let values = reader.read_region(0, [0; 3], info.dims).context("reading level 0")?;
    if values.iter().any(|&v| !(0.0..=255.0).contains(&v) || v.fract() != 0.0) {
        bail!("this bound holds 8-bit data: the store's values must be whole numbers in 0..=255");
    }
    let voxels: Vec<u8> = values.iter().map(|&v| v as u8).collect();
    // One bit per block of 8³ cells (each cell reaching one voxel further): whether any value reaches the isovalue.
    let cells = dims.map(|n| n as i64 - 1);
    let blocks = cells.map(|c| (c + BLOCK - 1) / BLOCK);
    let mut active = vec![false; (blocks[0] * blocks[1] * blocks[2]) as usize];
    for (z, plane) in voxels.chunks(dims[0] * dims[1]).enumerate() {
        for (y, row) in plane.chunks(dims[0]).enumerate() {
            for (x, &v) in row.iter().enumerate() {
                if f32::from(v) < iso {
                    continue;
                }
                // The voxel is a corner of the cells ending at it too: mark every block whose cells touch it.
                let range = |p: usize, a: usize| {
                    let p = p as i64;
                    let lo = ((p - 1).max(0) / BLOCK).min(blocks[a] - 1);
                    let hi = (p.min(cells[a] - 1) / BLOCK).min(blocks[a] - 1);
                    lo..=hi
                };
                for bz in range(z, 2) {
                    for by in range(y, 1) {
                        for bx in range(x, 0) {
                            active[((bz * blocks[1] + by) * blocks[0] + bx) as usize] = true;
                        }
                    }
                }
            }
        }
    }
    let macros = blocks.map(|b| (b + MACRO - 1) / MACRO);
    let mut macro_active = vec![false; (macros[0] * macros[1] * macros[2]) as usize];
    for bz in 0..blocks[2] {
        for by in 0..blocks[1] {
            for bx in 0..blocks[0] {
                if active[((bz * blocks[1] + by) * blocks[0] + bx) as usize] {
                    let m = ((bz / MACRO) * macros[1] + by / MACRO) * macros[0] + bx / MACRO;
                    macro_active[m as usize] = true;
                }
            }
        }
    }
    let volume = Volume { dims, voxels, blocks, active, macros, macro_active, iso };
    let camera = read_camera_path(Path::new(&args[2]))?[0];
    let settings = RenderSettings { shading: Shading::Phong, light_direction: light, ..RenderSettings::default() };
    let scene = Scene {
        volume: &volume,
        frame: camera.frame(size, size)?,
        size,
        lighting: LightingSettings::new(&settings),
        color: Vec3::new(0.9, 0.75, 0.65),
        world_origin: DVec3::from(info.origin),
        spacing: DVec3::from(info.spacing),
    };
    let cores = rayon::current_num_threads() as f64;
    println!("{} ({}×{}×{}), iso {iso}, {size}², {frames} frames, {cores} threads", args[0], dims[0], dims[1], dims[2]);
    let rays = (size * size) as usize;
    let mut image = vec![[0f32; 4]; rays];
    println!(
        "| culling | frame (median) | rays that hit | macro-blocks per ray | blocks per ray | cells per ray | ns per ray and core |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|");
    for two_levels in [false, true] {
        let mut times = Vec::new();
        let (mut cells, mut blocks_stepped, mut macros_stepped) = (0u64, 0u64, 0u64);
        for _ in 0..frames {
            let start = Instant::now();
            (cells, blocks_stepped, macros_stepped) = image
                .par_chunks_mut(size as usize)
                .enumerate()
                .map(|(y, row)| {
                    let (mut cells, mut blocks, mut macros) = (0, 0, 0);
                    for (x, pixel) in row.iter_mut().enumerate() {
                        let r = scene.trace(x as u32, y as u32, two_levels);
                        *pixel = r.rgba;
                        cells += r.cells;
                        blocks += r.blocks;
                        macros += r.macros;
                    }
                    (cells, blocks, macros)
                })
                .reduce(|| (0, 0, 0), |a, b| (a.0 + b.0, a.1 + b.1, a.2 + b.2));
            times.push(start.elapsed().as_secs_f64());
        }
        let t = median(&mut times);
        let hits = image.iter().filter(|p| p[3] > 0.0).count();
        println!(
            "| {} | {:.1} ms | {hits} of {rays} | {:.1} | {:.1} | {:.1} | {:.0} |",
            if two_levels { "8³-cell blocks within 32³-cell macro-blocks" } else { "8³-cell blocks" },
            t * 1e3,
            macros_stepped as f64 / rays as f64,
            blocks_stepped as f64 / rays as f64,
            cells as f64 / rays as f64,
            t * cores * 1e9 / rays as f64
        );
    }
    // The one-level walk again, eight rays in lock-step; its image must be the one-level row's bits.
    let mut reference = vec![[0f32; 4]; rays];
    for (y, row) in reference.chunks_mut(size as usize).enumerate() {
        for (x, pixel) in row.iter_mut().enumerate() {
            *pixel = scene.trace(x as u32, y as u32, false).rgba;
        }
    }
    let mut times = Vec::new();
    let (mut cells, mut blocks_stepped) = (0u64, 0u64);
    for _ in 0..frames {
        let start = Instant::now();
        #[cfg(target_arch = "x86_64")]
        let counts = lock_step::frame(&scene, &mut image);
        #[cfg(not(target_arch = "x86_64"))]
        let counts: Option<(u64, u64)> = None;
        let Some(counts) = counts else {
            println!("(the lock-step row needs x86-64 with AVX2 and a volume below 2³¹ voxels: not run)");
            return write_image(args.get(6), &image, size);
        };
        (cells, blocks_stepped) = counts;
        times.push(start.elapsed().as_secs_f64());
    }
    let t = median(&mut times);
    let hits = image.iter().filter(|p| p[3] > 0.0).count();
    println!(
        "| 8³-cell blocks, {} rays in lock-step | {:.1} ms | {hits} of {rays} | | {:.1} | {:.1} | {:.0} |",
        voxstream_render::sampler::LANES,
        t * 1e3,
        blocks_stepped as f64 / rays as f64,
        cells as f64 / rays as f64,
        t * cores * 1e9 / rays as f64
    );
    let differing = image.iter().zip(&reference).filter(|(a, b)| a != b).count();
    if differing != 0 {
        bail!("the lock-step image differs from the one-ray-at-a-time image in {differing} pixels");
    }
    write_image(args.get(6), &image, size)
}

/// Writes `image` to `out` as an 8-bit RGB PNG, when asked.
fn write_image(out: Option<&String>, image: &[[f32; 4]], size: u32) -> Result<()> {
    let Some(out) = out else { return Ok(()) };
    let bytes: Vec<u8> =
        image.iter().flat_map(|p| [p[0], p[1], p[2]].map(|c| (c.clamp(0.0, 1.0) * 255.0).round() as u8)).collect();
    write_rgb8_png(&bytes, size, size, Path::new(out))
}
