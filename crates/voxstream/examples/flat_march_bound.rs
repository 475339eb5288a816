//! How fast can emission–absorption ray casting be on this CPU when there is no tree at all? A bound for the ray
//! caster (issue: a ray caster faster than VTK's), measured on a store's finest level copied into one flat array.
//!
//! Both marches take the renderer's samples as far as the arithmetic allows: a step of half a voxel from where the
//! ray enters the volume's sample box, trilinear in the `u8` voxels, the transfer function's table pre-corrected for
//! the step, occupancy blocks of 8³ cells skipped by one bit each, the same opacity cutoff. What they do not do is
//! everything a tree costs: no descents, no segments, no bricks, no level of detail, no feedback.
//!
//! - `one ray at a time`: a plain scalar loop per ray.
//! - `8 rays in lock-step`: a 4×2 tile of rays marched together, sample `k` of every ray in one step (`[f32; 8]`
//!   arrays compiled for AVX2+FMA where the CPU has it); a step whose eight samples all lie in blocks that cannot
//!   contribute takes no sample.
//!
//! ```sh
//! cargo run --release -p voxstream --example flat_march_bound -- STORE TF.json CAMERA.json [SIZE] [FRAMES] [OUT.png]
//! ```
//!
//! Prints each march's frame time (median), samples per frame, and ns per sample and core; with `OUT.png`, writes
//! the lock-step march's image (compare it with `voxstream render`'s to see that the same samples were taken).

use std::path::Path;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use voxstream::bench::median;
use voxstream::camera_path::read_camera_path;
use voxstream::png_output::write_rgb8_png;
use voxstream_render::step_table::{StepLength, StepTable};
use voxstream_render::traversal::intersect_aabb;
use voxstream_render::{CameraFrame, TransferFunction, TransferLut};
use voxstream_store::StoreReader;

const BLOCK: usize = 8;
const LANES: usize = 8;
const STEP: f32 = 0.5;

struct Volume {
    dims: [usize; 3],
    voxels: Vec<u8>,
    blocks: [usize; 3],
    visible: Vec<bool>,
    /// Normalised value per stored unit.
    scale: f32,
}

impl Volume {
    #[inline(always)]
    fn block_visible(&self, p: [f32; 3]) -> bool {
        let ijk: [usize; 3] = std::array::from_fn(|a| (p[a].max(0.0) as usize / BLOCK).min(self.blocks[a] - 1));
        self.visible[(ijk[2] * self.blocks[1] + ijk[1]) * self.blocks[0] + ijk[0]]
    }

    /// Trilinear at `p` (voxel centres at integers), clamped into the volume.
    #[inline(always)]
    fn trilinear(&self, p: [f32; 3]) -> f32 {
        let [nx, ny, _] = self.dims;
        let mut base = [0usize; 3];
        let mut f = [0f32; 3];
        for a in 0..3 {
            let c = p[a].max(0.0).min((self.dims[a] - 1) as f32);
            let i = (c.floor() as usize).min(self.dims[a] - 2);
            base[a] = i;
            f[a] = c - i as f32;
        }
        let at = (base[2] * ny + base[1]) * nx + base[0];
        let (row, slab) = (nx, nx * ny);
        let cell = &self.voxels[at..at + slab + row + 2];
        let v = |o: usize| cell[o] as f32;
        let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
        let x00 = lerp(v(0), v(1), f[0]);
        let x10 = lerp(v(row), v(row + 1), f[0]);
        let x01 = lerp(v(slab), v(slab + 1), f[0]);
        let x11 = lerp(v(slab + row), v(slab + row + 1), f[0]);
        lerp(lerp(x00, x10, f[1]), lerp(x01, x11, f[1]), f[2]) * self.scale
    }
}

/// Where a ray enters and leaves the box of sample centres (the renderer's slab test), from the eye on.
fn clip(origin: [f32; 3], direction: [f32; 3], dims: [usize; 3]) -> Option<(f32, f32)> {
    let upper = DVec3::from_array(dims.map(|d| (d - 1) as f64));
    let (o, d) = (Vec3::from_array(origin).as_dvec3(), Vec3::from_array(direction).as_dvec3());
    let (t0, t1) = intersect_aabb(o, d, DVec3::ZERO, upper)?;
    Some((t0.max(0.0) as f32, t1 as f32))
}

struct Scene<'a> {
    volume: &'a Volume,
    table: &'a StepTable,
    frame: CameraFrame,
    size: u32,
    stop_below: f32,
}

impl Scene<'_> {
    fn ray(&self, x: u32, y: u32) -> ([f32; 3], [f32; 3]) {
        let d = self.frame.direction(x, y, self.size, self.size);
        (self.frame.eye.as_vec3().to_array(), d.as_vec3().to_array())
    }

    /// One ray at a time; returns the pixel and the samples taken.
    fn march_one(&self, x: u32, y: u32) -> ([f32; 4], u64) {
        let (o, d) = self.ray(x, y);
        let Some((t0, t1)) = clip(o, d, self.volume.dims) else { return ([0.0; 4], 0) };
        let count = ((t1 - t0 - 0.5 * STEP) / STEP).ceil().max(1.0) as u32;
        let start: [f32; 3] = std::array::from_fn(|a| o[a] + d[a] * (t0 + 0.5 * STEP));
        let delta: [f32; 3] = std::array::from_fn(|a| d[a] * STEP);
        let (mut color, mut transmittance, mut samples) = ([0f32; 3], 1f32, 0u64);
        for k in 0..count {
            let p: [f32; 3] = std::array::from_fn(|a| start[a] + k as f32 * delta[a]);
            if !self.volume.block_visible(p) {
                continue;
            }
            samples += 1;
            let e = self.table.lookup(self.volume.trilinear(p));
            for c in 0..3 {
                color[c] += transmittance * e[c];
            }
            transmittance *= 1.0 - e.w;
            if transmittance <= self.stop_below {
                break;
            }
        }
        ([color[0], color[1], color[2], 1.0 - transmittance], samples)
    }

    /// Eight rays (a 4×2 tile from `(x, y)`) in lock-step.
    #[inline(always)]
    fn march_packet(&self, x: u32, y: u32) -> ([[f32; 4]; LANES], u64) {
        let mut start = [[0f32; LANES]; 3];
        let mut delta = [[0f32; LANES]; 3];
        let mut count = [0u32; LANES];
        for j in 0..LANES {
            let (o, d) = self.ray(x + (j % 4) as u32, y + (j / 4) as u32);
            if let Some((t0, t1)) = clip(o, d, self.volume.dims) {
                count[j] = ((t1 - t0 - 0.5 * STEP) / STEP).ceil().max(1.0) as u32;
                for a in 0..3 {
                    start[a][j] = o[a] + d[a] * (t0 + 0.5 * STEP);
                    delta[a][j] = d[a] * STEP;
                }
            }
        }
        let steps = count.iter().copied().max().unwrap_or(0);
        let mut color = [[0f32; LANES]; 3];
        let mut transmittance = [1f32; LANES];
        let mut samples = 0u64;
        for k in 0..steps {
            let kf = k as f32;
            let mut live = [false; LANES];
            let mut p = [[0f32; LANES]; 3];
            for j in 0..LANES {
                for a in 0..3 {
                    p[a][j] = start[a][j] + kf * delta[a][j];
                }
                live[j] = k < count[j] && transmittance[j] > self.stop_below;
            }
            if !live.iter().any(|&l| l) {
                break;
            }
            let mut any = false;
            for j in 0..LANES {
                live[j] &= self.volume.block_visible([p[0][j], p[1][j], p[2][j]]);
                any |= live[j];
            }
            if !any {
                continue;
            }
            let values: [f32; LANES] = std::array::from_fn(|j| self.volume.trilinear([p[0][j], p[1][j], p[2][j]]));
            for j in 0..LANES {
                let e = self.table.lookup(values[j]);
                let w = if live[j] { 1.0 } else { 0.0 };
                for c in 0..3 {
                    color[c][j] += w * transmittance[j] * e[c];
                }
                transmittance[j] *= 1.0 - w * e.w;
                samples += live[j] as u64;
            }
        }
        (std::array::from_fn(|j| [color[0][j], color[1][j], color[2][j], 1.0 - transmittance[j]]), samples)
    }
}

struct PacketFrame<'s, 'a> {
    scene: &'s Scene<'a>,
}

impl pulp::WithSimd for PacketFrame<'_, '_> {
    type Output = (Vec<[f32; 4]>, u64);

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> Self::Output {
        let s = self.scene;
        let n = s.size as usize;
        let mut image = vec![[0f32; 4]; n * n];
        let samples = image
            .par_chunks_mut(2 * n)
            .enumerate()
            .map(|(band, rows)| {
                let mut samples = 0;
                for x in (0..n).step_by(4) {
                    let (pixels, taken) = s.march_packet(x as u32, 2 * band as u32);
                    samples += taken;
                    for (j, pixel) in pixels.iter().enumerate() {
                        let (px, py) = (x + j % 4, j / 4);
                        if px < n && py * n < rows.len() {
                            rows[py * n + px] = *pixel;
                        }
                    }
                }
                samples
            })
            .sum();
        (image, samples)
    }
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 3 {
        bail!("usage: flat_march_bound STORE TF.json CAMERA.json [SIZE] [FRAMES] [OUT.png]");
    }
    let reader = StoreReader::open(Path::new(&args[0])).context("opening the store")?;
    let size: u32 = args.get(3).map(|s| s.parse()).transpose().context("SIZE")?.unwrap_or(512);
    let frames: usize = args.get(4).map(|s| s.parse()).transpose().context("FRAMES")?.unwrap_or(5);
    if !size.is_multiple_of(4) || size == 0 {
        bail!("SIZE must be a positive multiple of 4");
    }
    let info = reader.info().clone();
    if info.spacing != [1.0; 3] || info.origin != [0.0; 3] {
        bail!("this bound maps voxel centres to integer world positions: the store needs spacing 1 and origin 0");
    }
    let dims = info.dims.map(|d| d as usize);
    let range = reader.attributes().value_range;
    let values = reader.read_region(0, [0; 3], info.dims).context("reading level 0")?;
    let voxels: Vec<u8> = values.iter().map(|&v| v.clamp(0.0, 255.0) as u8).collect();
    let text = std::fs::read_to_string(&args[1]).context("reading the transfer function")?;
    let tf = TransferFunction::from_json_or_paraview(&text, range)?;
    let lut = TransferLut::new(&tf, range[0] as f32, range[1] as f32, 1.0);
    let table = lut.step_table(StepLength::at_most(STEP as f64));
    let scale = 1.0 / (range[1] - range[0]) as f32;
    // One bit per block of 8³ cells: whether any value its cells can interpolate is visible.
    let blocks = dims.map(|d| (d - 1).div_ceil(BLOCK));
    let mut visible = vec![false; blocks[0] * blocks[1] * blocks[2]];
    for bz in 0..blocks[2] {
        for by in 0..blocks[1] {
            for bx in 0..blocks[0] {
                let (mut lo, mut hi) = (u8::MAX, u8::MIN);
                for z in bz * BLOCK..((bz + 1) * BLOCK + 1).min(dims[2]) {
                    for y in by * BLOCK..((by + 1) * BLOCK + 1).min(dims[1]) {
                        for x in bx * BLOCK..((bx + 1) * BLOCK + 1).min(dims[0]) {
                            let v = voxels[(z * dims[1] + y) * dims[0] + x];
                            lo = lo.min(v);
                            hi = hi.max(v);
                        }
                    }
                }
                visible[(bz * blocks[1] + by) * blocks[0] + bx] =
                    lut.is_visible_in(lo as f32 * scale, hi as f32 * scale);
            }
        }
    }
    let volume = Volume { dims, voxels, blocks, visible, scale };
    let camera = read_camera_path(Path::new(&args[2]))?[0];
    let scene = Scene { volume: &volume, table, frame: camera.frame(size, size)?, size, stop_below: 1.0 - 0.998 };
    let cores = rayon::current_num_threads() as f64;
    println!("{} ({}×{}×{}), {size}², {frames} frames, {cores} threads", args[0], dims[0], dims[1], dims[2]);
    println!("| march | frame (median) | samples per frame | ns per sample and core |");
    println!("|---|---:|---:|---:|");

    let mut times = Vec::new();
    let mut samples = 0;
    for _ in 0..frames {
        let start = Instant::now();
        samples = (0..size * size).into_par_iter().map(|i| scene.march_one(i % size, i / size).1).sum::<u64>();
        times.push(start.elapsed().as_secs_f64());
    }
    let t = median(&mut times);
    println!("| one ray at a time | {:.1} ms | {samples} | {:.2} |", t * 1e3, t * cores * 1e9 / samples as f64);

    let mut times = Vec::new();
    let mut image = Vec::new();
    for _ in 0..frames {
        let start = Instant::now();
        let (pixels, taken) = pulp::Arch::new().dispatch(PacketFrame { scene: &scene });
        times.push(start.elapsed().as_secs_f64());
        (image, samples) = (pixels, taken);
    }
    let t = median(&mut times);
    println!("| 8 rays in lock-step | {:.1} ms | {samples} | {:.2} |", t * 1e3, t * cores * 1e9 / samples as f64);
    if let Some(out) = args.get(5) {
        let bytes: Vec<u8> =
            image.iter().flat_map(|p| [p[0], p[1], p[2]].map(|c| (c.clamp(0.0, 1.0) * 255.0).round() as u8)).collect();
        write_rgb8_png(&bytes, size, size, Path::new(out))?;
    }
    Ok(())
}
