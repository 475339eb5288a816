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
//!   isovalue is intersected exactly by the renderer's own [`CellCubic`] (split at the cubic's extrema, regula
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

use std::ops::ControlFlow;
use std::path::Path;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use voxstream::camera_path::read_camera_path;
use voxstream::cli::parse_vec3;
use voxstream::png_output::write_rgb8_png;
use voxstream_render::cell_intersection::{cell_gradient, CellCubic};
use voxstream_render::lighting::LightingSettings;
use voxstream_render::traversal::intersect_aabb;
use voxstream_render::{CameraFrame, RenderSettings, Shading};
use voxstream_store::StoreReader;

/// Cells per occupancy block and axis: the renderer's.
const BLOCK: i64 = voxstream_core::BLOCK_CELLS as i64;
/// Blocks per macro-block and axis (the second level of culling: 32³ cells).
const MACRO: i64 = 4;

struct Volume {
    dims: [usize; 3],
    voxels: Vec<u8>,
    /// Blocks per axis.
    blocks: [i64; 3],
    /// Per block: whether some corner of its cells reaches the isovalue.
    active: Vec<bool>,
    /// Macro-blocks (`MACRO³` blocks) per axis, and per macro-block whether one of its blocks is active.
    macros: [i64; 3],
    macro_active: Vec<bool>,
    iso: f32,
}

impl Volume {
    #[inline(always)]
    fn corners(&self, cell: [i64; 3]) -> [f32; 8] {
        let [nx, ny, _] = self.dims;
        let at = (cell[2] as usize * ny + cell[1] as usize) * nx + cell[0] as usize;
        let (row, slab) = (nx, nx * ny);
        let v = &self.voxels[at..at + slab + row + 2];
        [v[0], v[1], v[row], v[row + 1], v[slab], v[slab + 1], v[slab + row], v[slab + row + 1]].map(f32::from)
    }
}

/// What one ray found: the hit's colour and opacity, and the cells it examined.
struct RayResult {
    rgba: [f32; 4],
    cells: u64,
    blocks: u64,
    macros: u64,
}

struct Scene<'a> {
    volume: &'a Volume,
    frame: CameraFrame,
    size: u32,
    lighting: LightingSettings,
    color: Vec3,
    /// The world position of voxel 0's centre, and the world size of a voxel.
    world_origin: DVec3,
    spacing: DVec3,
}

/// The lattice cells of size `unit` (in trilinear cells) that the ray `o + t·d` crosses over `[t_from, t_to)`,
/// within the cells `lo ..= hi` of that lattice, in order: an Amanatides–Woo DDA. `visit(cell, t_in, t_out)`
/// breaks to end the walk.
#[inline(always)]
fn dda<R>(
    ray: &RayLine,
    unit: i64,
    (t_from, t_to): (f64, f64),
    (lo, hi): ([i64; 3], [i64; 3]),
    mut visit: impl FnMut([i64; 3], f64, f64) -> ControlFlow<R>,
) -> ControlFlow<R> {
    let RayLine { o, d, inverse, step } = ray;
    let mut cell: [i64; 3] = std::array::from_fn(|a| ((o[a] + d[a] * t_from) as i64 / unit).clamp(lo[a], hi[a]));
    let plane_t =
        |a: usize, plane: i64| if d[a] != 0.0 { ((plane * unit) as f64 - o[a]) * inverse[a] } else { f64::INFINITY };
    let mut next: [f64; 3] = std::array::from_fn(|a| plane_t(a, cell[a] + i64::from(step[a] > 0)));
    let delta: [f64; 3] = inverse.map(|v| (v * unit as f64).abs());
    let mut t = t_from;
    // A ray crosses at most the sum of the extents; the cap only guards against a numerical stall.
    let most = (0..3).map(|a| hi[a] - lo[a] + 1).sum::<i64>() + 3;
    for _ in 0..most {
        let a = if next[0] <= next[1] && next[0] <= next[2] {
            0
        } else if next[1] <= next[2] {
            1
        } else {
            2
        };
        let t_out = next[a].min(t_to).max(t);
        visit(cell, t, t_out)?;
        if next[a] >= t_to {
            return ControlFlow::Continue(());
        }
        cell[a] += step[a];
        if cell[a] < lo[a] || cell[a] > hi[a] {
            return ControlFlow::Continue(());
        }
        t = t_out;
        next[a] += delta[a];
    }
    ControlFlow::Continue(())
}

/// A ray in voxel coordinates, with what its DDAs need.
struct RayLine {
    o: [f64; 3],
    d: [f64; 3],
    inverse: [f64; 3],
    step: [i64; 3],
}

impl Scene<'_> {
    /// The first crossing along one ray: a DDA over macro-blocks (with `MACRO` on), over the blocks of those that
    /// can hold it, over the cells of those blocks that can.
    #[inline(always)]
    fn trace(&self, x: u32, y: u32, two_levels: bool) -> RayResult {
        let vol = self.volume;
        let mut result = RayResult { rgba: [0.0; 4], cells: 0, blocks: 0, macros: 0 };
        let Some((ray, (t0, t1), direction)) = self.voxel_ray(x, y) else { return result };
        let last_cell: [i64; 3] = vol.dims.map(|n| n as i64 - 2);
        let (o, d) = (ray.o, ray.d);
        let cells_of_block = |block: [i64; 3], t_in: f64, t_out: f64, result: &mut RayResult| {
            result.blocks += 1;
            let index = (block[2] * vol.blocks[1] + block[1]) * vol.blocks[0] + block[0];
            if !vol.active[index as usize] {
                return ControlFlow::Continue(());
            }
            let first: [i64; 3] = std::array::from_fn(|a| block[a] * BLOCK);
            let last: [i64; 3] = std::array::from_fn(|a| (first[a] + BLOCK - 1).min(last_cell[a]));
            dda(&ray, 1, (t_in, t_out), (first, last), |cell, t_cell, t_exit| {
                result.cells += 1;
                let corners = vol.corners(cell);
                let (mut lo, mut hi) = (corners[0], corners[0]);
                for &v in &corners[1..] {
                    lo = lo.min(v);
                    hi = hi.max(v);
                }
                if lo < vol.iso && hi >= vol.iso {
                    if let Some(rgba) = self.cell_hit(&corners, cell, o, d, t_cell, t_exit, direction) {
                        return ControlFlow::Break(rgba);
                    }
                }
                ControlFlow::Continue(())
            })
        };
        let blocks_last = vol.blocks.map(|b| b - 1);
        let hit = if two_levels {
            let macros_last = vol.macros.map(|m| m - 1);
            dda(&ray, BLOCK * MACRO, (t0.max(0.0), t1), ([0; 3], macros_last), |m, t_in, t_out| {
                result.macros += 1;
                let index = (m[2] * vol.macros[1] + m[1]) * vol.macros[0] + m[0];
                if !vol.macro_active[index as usize] {
                    return ControlFlow::Continue(());
                }
                let first: [i64; 3] = m.map(|v| v * MACRO);
                let last: [i64; 3] = std::array::from_fn(|a| (first[a] + MACRO - 1).min(blocks_last[a]));
                dda(&ray, BLOCK, (t_in, t_out), (first, last), |b, t_in, t_out| {
                    cells_of_block(b, t_in, t_out, &mut result)
                })
            })
        } else {
            dda(&ray, BLOCK, (t0.max(0.0), t1), ([0; 3], blocks_last), |b, t_in, t_out| {
                cells_of_block(b, t_in, t_out, &mut result)
            })
        };
        if let ControlFlow::Break(rgba) = hit {
            result.rgba = rgba;
        }
        result
    }

    /// The ray of pixel `(x, y)` in voxel coordinates (voxel centres at integers; `t` stays the world distance),
    /// where it enters and leaves the box of voxel centres, and its world direction; `None` where it misses the box.
    #[inline(always)]
    fn voxel_ray(&self, x: u32, y: u32) -> Option<(RayLine, (f64, f64), DVec3)> {
        let direction = self.frame.direction(x, y, self.size, self.size);
        let origin = (self.frame.eye - self.world_origin) / self.spacing;
        let voxel_direction = direction / self.spacing;
        let upper = DVec3::from_array(self.volume.dims.map(|d| (d - 1) as f64));
        let (t0, t1) = intersect_aabb(origin, voxel_direction, DVec3::ZERO, upper)?;
        let d = voxel_direction.to_array();
        let ray = RayLine {
            o: origin.to_array(),
            d,
            inverse: d.map(|v| 1.0 / v),
            step: d.map(|v| {
                if v > 0.0 {
                    1
                } else if v < 0.0 {
                    -1
                } else {
                    0
                }
            }),
        };
        Some((ray, (t0, t1), direction))
    }

    /// The first crossing in the cell `cell` (its `corners`) of the ray `o + t·d` over `[t_in, t_out]`, shaded:
    /// its colour and opacity, or `None`. `direction` is the ray's in world units (for its light).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn cell_hit(
        &self,
        corners: &[f32; 8],
        cell: [i64; 3],
        o: [f64; 3],
        d: [f64; 3],
        t_in: f64,
        t_out: f64,
        direction: DVec3,
    ) -> Option<[f32; 4]> {
        let start: [f32; 3] = std::array::from_fn(|k| (o[k] + d[k] * t_in - cell[k] as f64) as f32);
        let rate: [f32; 3] = d.map(|v| v as f32);
        let cubic = CellCubic::new(corners, start, rate);
        let mut roots = [0.0f32; 3];
        if cubic.crossings(self.volume.iso, (t_out - t_in) as f32, &mut roots) == 0 {
            return None;
        }
        let p: [f32; 3] = std::array::from_fn(|k| start[k] + roots[0] * rate[k]);
        let g = Vec3::from(cell_gradient(corners, p)) * self.lighting.gradient_scale;
        let light = self.lighting.ray(direction).expect("phong");
        let c = light.shade(self.color, 1.0, g);
        Some([c.x, c.y, c.z, 1.0])
    }
}

/// The lock-step row: x86-64 with AVX2 only.
#[cfg(target_arch = "x86_64")]
mod lock_step {
    use std::arch::x86_64::{__m256, __m256d, _CMP_GE_OQ, _CMP_LE_OQ, _CMP_LT_OQ, _CMP_NGE_UQ};

    use glam::DVec3;
    use pulp::x86::V3;
    use rayon::prelude::*;
    use voxstream_render::gathered_corners::CornerGather;

    use super::{Scene, BLOCK};

    /// Rays traced side by side in [`LockStep::run`].
    const LANES: usize = voxstream_render::sampler::LANES;

    /// [`LANES`] rays walking one-level culling (8³-cell blocks, then cells) in lock-step, on AVX2. Each step every
    /// lane takes one block or one cell of its own ray: the DDA arithmetic of all lanes in AVX2 registers (two of four
    /// `f64` lanes each, through pulp's safe wrappers of `std::arch`), the cells' corners by AVX2 gathers
    /// ([`CornerGather`]). Only lanes with an event (a block that can hold the surface is entered, a cell straddles the
    /// isovalue, a walk ends) are then handled one by one. Every quantity is kept in `f64` (lattice coordinates as whole
    /// numbers, exact) so that one mask serves all; the arithmetic of each lane is that of [`Scene::trace`] without
    /// macro-blocks, so the image is the same bits.
    struct LockStep {
        o: [[f64; LANES]; 3],
        d: [[f64; LANES]; 3],
        inverse: [[f64; LANES]; 3],
        step: [[f64; LANES]; 3],
        /// The DDA being walked (blocks or cells): lattice cell, next planes' `t`, `t`, end, bounds and plane spacing.
        c: [[f64; LANES]; 3],
        next: [[f64; LANES]; 3],
        t: [f64; LANES],
        to: [f64; LANES],
        lo: [[f64; LANES]; 3],
        hi: [[f64; LANES]; 3],
        delta: [[f64; LANES]; 3],
        /// Bit `j`: lane `j` walks the cells of a block (else the blocks); lane `j` has a ray.
        in_cells: u32,
        live: u32,
        /// The block DDA, kept while the cells of its block are walked, with the step it takes after them.
        saved_c: [[f64; LANES]; 3],
        saved_next: [[f64; LANES]; 3],
        saved_to: [f64; LANES],
        saved_axis: [usize; LANES],
        saved_nearest: [f64; LANES],
        saved_out: [f64; LANES],
        pixel: [usize; LANES],
        /// The ray's direction in world units (for its light).
        world_direction: [DVec3; LANES],
        cells: u64,
        blocks: u64,
    }

    /// The lane masks of four lanes, by their bits (all ones where set), for blends.
    const LANE_MASKS: [[u64; 4]; 16] = {
        let mut masks = [[0u64; 4]; 16];
        let mut bits = 0;
        while bits < 16 {
            let mut lane = 0;
            while lane < 4 {
                if bits & (1 << lane) != 0 {
                    masks[bits][lane] = u64::MAX;
                }
                lane += 1;
            }
            bits += 1;
        }
        masks
    };

    impl LockStep {
        fn new() -> LockStep {
            LockStep {
                o: [[0.0; LANES]; 3],
                d: [[0.0; LANES]; 3],
                inverse: [[0.0; LANES]; 3],
                step: [[0.0; LANES]; 3],
                c: [[0.0; LANES]; 3],
                next: [[0.0; LANES]; 3],
                t: [0.0; LANES],
                to: [0.0; LANES],
                lo: [[0.0; LANES]; 3],
                hi: [[0.0; LANES]; 3],
                delta: [[0.0; LANES]; 3],
                in_cells: 0,
                live: 0,
                saved_c: [[0.0; LANES]; 3],
                saved_next: [[0.0; LANES]; 3],
                saved_to: [0.0; LANES],
                saved_axis: [0; LANES],
                saved_nearest: [0.0; LANES],
                saved_out: [0.0; LANES],
                pixel: [0; LANES],
                world_direction: [DVec3::ZERO; LANES],
                cells: 0,
                blocks: 0,
            }
        }

        /// Sets lane `j`'s DDA to the lattice of `unit` cells within `lo ..= hi` from `t_from` to `t_to`, as [`dda`].
        #[inline(always)]
        fn start_dda(&mut self, j: usize, unit: i64, (t_from, t_to): (f64, f64), (lo, hi): ([i64; 3], [i64; 3])) {
            for a in 0..3 {
                let (o, d, inverse) = (self.o[a][j], self.d[a][j], self.inverse[a][j]);
                let c = ((o + d * t_from) as i64 / unit).clamp(lo[a], hi[a]);
                let plane = c + i64::from(self.step[a][j] > 0.0);
                self.c[a][j] = c as f64;
                self.next[a][j] = if d != 0.0 { ((plane * unit) as f64 - o) * inverse } else { f64::INFINITY };
                self.delta[a][j] = (inverse * unit as f64).abs();
                self.lo[a][j] = lo[a] as f64;
                self.hi[a][j] = hi[a] as f64;
            }
            self.t[j] = t_from;
            self.to[j] = t_to;
        }

        /// Lane `j`'s DDA step across its nearest plane (axis `a`, at `nearest`; `t_out` where the visited cell ended):
        /// as [`dda`]'s. Returns whether the walk has ended.
        #[inline(always)]
        fn advance(&mut self, j: usize, a: usize, nearest: f64, t_out: f64) -> bool {
            if nearest >= self.to[j] {
                return true;
            }
            self.c[a][j] += self.step[a][j];
            if self.c[a][j] < self.lo[a][j] || self.c[a][j] > self.hi[a][j] {
                return true;
            }
            self.t[j] = t_out;
            self.next[a][j] += self.delta[a][j];
            false
        }

        /// Gives lane `j` the next ray of `order` that enters the volume (writing the misses on the way); no ray once
        /// they have run out.
        fn refill(
            &mut self,
            j: usize,
            scene: &Scene<'_>,
            order: &mut impl Iterator<Item = (usize, u32, u32)>,
            image: &mut [[f32; 4]],
        ) {
            let vol = scene.volume;
            for (pixel, x, y) in order.by_ref() {
                image[pixel] = [0.0; 4];
                let Some((ray, (t0, t1), direction)) = scene.voxel_ray(x, y) else { continue };
                for a in 0..3 {
                    self.o[a][j] = ray.o[a];
                    self.d[a][j] = ray.d[a];
                    self.inverse[a][j] = ray.inverse[a];
                    self.step[a][j] = ray.step[a] as f64;
                }
                self.start_dda(j, BLOCK, (t0.max(0.0), t1), ([0; 3], vol.blocks.map(|b| b - 1)));
                self.in_cells &= !(1 << j);
                self.live |= 1 << j;
                self.pixel[j] = pixel;
                self.world_direction[j] = direction;
                return;
            }
            self.live &= !(1 << j);
        }

        /// Lane `j`'s walk has ended: back from a block's cells to the block DDA (which takes the step it put off), or
        /// the ray has left the volume without a crossing and the lane takes the next ray.
        fn walk_ended(
            &mut self,
            j: usize,
            scene: &Scene<'_>,
            order: &mut impl Iterator<Item = (usize, u32, u32)>,
            image: &mut [[f32; 4]],
        ) {
            let vol = scene.volume;
            if self.in_cells & (1 << j) != 0 {
                for a in 0..3 {
                    self.c[a][j] = self.saved_c[a][j];
                    self.next[a][j] = self.saved_next[a][j];
                    self.delta[a][j] = (self.inverse[a][j] * BLOCK as f64).abs();
                    self.lo[a][j] = 0.0;
                    self.hi[a][j] = (vol.blocks[a] - 1) as f64;
                }
                self.to[j] = self.saved_to[j];
                self.in_cells &= !(1 << j);
                if !self.advance(j, self.saved_axis[j], self.saved_nearest[j], self.saved_out[j]) {
                    return;
                }
            }
            self.refill(j, scene, order, image);
        }

        /// Traces the rays of `order` (pixel index, x, y), writing `image`.
        #[inline(always)]
        fn run(
            &mut self,
            simd: V3,
            scene: &Scene<'_>,
            gather: CornerGather,
            mut order: impl Iterator<Item = (usize, u32, u32)>,
            image: &mut [[f32; 4]],
        ) {
            type Lanes = [__m256d; 2];
            let avx = simd.avx;
            let vol = scene.volume;
            let [nx, ny, _] = vol.dims;
            let (row, slab) = (nx, nx * ny);
            let last_cell: [i64; 3] = vol.dims.map(|n| n as i64 - 2);
            for j in 0..LANES {
                self.refill(j, scene, &mut order, image);
            }
            let splat = |v: f64| avx._mm256_set1_pd(v);
            let (zero, one, two) = (splat(0.0), splat(1.0), splat(2.0));
            let (nx_v, ny_v) = (splat(nx as f64), splat(ny as f64));
            let (bx_v, by_v) = (splat(vol.blocks[0] as f64), splat(vol.blocks[1] as f64));
            let iso = avx._mm256_set1_ps(vol.iso);
            let mask =
                |bits: u32, half: usize| -> __m256d { pulp::cast(LANE_MASKS[((bits >> (4 * half)) & 15) as usize]) };
            let bits = |m: __m256d| avx._mm256_movemask_pd(m) as u32;
            let le = |a: __m256d, b: __m256d| avx._mm256_cmp_pd::<_CMP_LE_OQ>(a, b);
            // Not `>=` (true where NaN), as `dda`'s `next >= to` ends a walk only where it holds.
            let not_ge = |a: __m256d, b: __m256d| avx._mm256_cmp_pd::<_CMP_NGE_UQ>(a, b);
            let ge = |a: __m256d, b: __m256d| avx._mm256_cmp_pd::<_CMP_GE_OQ>(a, b);
            let and = |a: __m256d, b: __m256d| avx._mm256_and_pd(a, b);
            let andnot = |a: __m256d, b: __m256d| avx._mm256_andnot_pd(a, b);
            let or = |a: __m256d, b: __m256d| avx._mm256_or_pd(a, b);
            let select = |m: __m256d, yes: __m256d, no: __m256d| avx._mm256_blendv_pd(no, yes, m);
            let to_u32 = |v: Lanes| -> [u32; LANES] {
                pulp::cast([avx._mm256_cvttpd_epi32(v[0]), avx._mm256_cvttpd_epi32(v[1])])
            };
            while self.live != 0 {
                let (cells_bits, blocks_bits) = (self.live & self.in_cells, self.live & !self.in_cells);
                self.cells += u64::from(cells_bits.count_ones());
                self.blocks += u64::from(blocks_bits.count_ones());
                // Every lane's nearest plane, all at once.
                let next: [Lanes; 3] = self.next.map(pulp::cast);
                let c: [Lanes; 3] = self.c.map(pulp::cast);
                let (t, to): (Lanes, Lanes) = (pulp::cast(self.t), pulp::cast(self.to));
                let all = mask(u32::MAX, 0);
                let mut axis_masks = [[zero; 2]; 3];
                let mut nearest = [zero; 2];
                let mut t_out = [zero; 2];
                let mut axis_code = [zero; 2];
                let mut cell_index = [zero; 2];
                let mut block_index = [zero; 2];
                for h in 0..2 {
                    let (n0, n1, n2) = (next[0][h], next[1][h], next[2][h]);
                    let m0 = and(le(n0, n1), le(n0, n2));
                    let m1 = andnot(m0, le(n1, n2));
                    let m2 = andnot(or(m0, m1), all);
                    axis_masks[0][h] = m0;
                    axis_masks[1][h] = m1;
                    axis_masks[2][h] = m2;
                    axis_code[h] = select(m0, zero, select(m1, one, two));
                    let n = select(m0, n0, select(m1, n1, n2));
                    nearest[h] = n;
                    t_out[h] = avx._mm256_max_pd(avx._mm256_min_pd(n, to[h]), t[h]);
                    // Whole numbers below 2⁵³: exact in `f64`.
                    let cell = avx._mm256_add_pd(
                        avx._mm256_mul_pd(avx._mm256_add_pd(avx._mm256_mul_pd(c[2][h], ny_v), c[1][h]), nx_v),
                        c[0][h],
                    );
                    let block = avx._mm256_add_pd(
                        avx._mm256_mul_pd(avx._mm256_add_pd(avx._mm256_mul_pd(c[2][h], by_v), c[1][h]), bx_v),
                        c[0][h],
                    );
                    cell_index[h] = and(cell, mask(cells_bits, h));
                    block_index[h] = and(block, mask(blocks_bits, h));
                }
                // The cells' corners, all lanes at once (lanes not in cells read voxel 0 and ignore it).
                let corners = gather.read(&vol.voxels, &to_u32(cell_index), row, slab);
                let corners: [__m256; 8] = corners.map(pulp::cast);
                let (mut lo, mut hi) = (corners[0], corners[0]);
                for &corner in &corners[1..] {
                    lo = avx._mm256_min_ps(lo, corner);
                    hi = avx._mm256_max_ps(hi, corner);
                }
                let straddle = avx
                    ._mm256_and_ps(avx._mm256_cmp_ps::<_CMP_LT_OQ>(lo, iso), avx._mm256_cmp_ps::<_CMP_GE_OQ>(hi, iso));
                let straddles = avx._mm256_movemask_ps(straddle) as u32 & cells_bits;
                let block_at = to_u32(block_index);
                let mut enters = 0u32;
                for (j, &at) in block_at.iter().enumerate() {
                    enters |= u32::from(vol.active[at as usize]) << j;
                }
                enters &= blocks_bits;
                // Every other lane's step across its nearest plane, all at once; lanes whose walk ends are marked.
                let go_bits = self.live & !straddles & !enters;
                let mut ended = 0u32;
                let mut new_c = c;
                let mut new_next = next;
                let mut new_t = t;
                for h in 0..2 {
                    let mut inside = all;
                    let mut moved = [zero; 3];
                    for k in 0..3 {
                        let stepped = and(
                            axis_masks[k][h],
                            pulp::cast::<[f64; 4], __m256d>(std::array::from_fn(|l| self.step[k][4 * h + l])),
                        );
                        moved[k] = avx._mm256_add_pd(c[k][h], stepped);
                        let lo_k: __m256d =
                            pulp::cast::<[f64; 4], __m256d>(std::array::from_fn(|l| self.lo[k][4 * h + l]));
                        let hi_k: __m256d =
                            pulp::cast::<[f64; 4], __m256d>(std::array::from_fn(|l| self.hi[k][4 * h + l]));
                        inside = and(inside, and(ge(moved[k], lo_k), le(moved[k], hi_k)));
                    }
                    let go = mask(go_bits, h);
                    let ok = and(go, and(not_ge(nearest[h], to[h]), inside));
                    for k in 0..3 {
                        new_c[k][h] = select(ok, moved[k], c[k][h]);
                        let delta_k: __m256d =
                            pulp::cast::<[f64; 4], __m256d>(std::array::from_fn(|l| self.delta[k][4 * h + l]));
                        new_next[k][h] = avx._mm256_add_pd(next[k][h], and(and(ok, axis_masks[k][h]), delta_k));
                    }
                    new_t[h] = select(ok, t_out[h], t[h]);
                    ended |= (bits(andnot(ok, go))) << (4 * h);
                }
                self.c = new_c.map(pulp::cast);
                self.next = new_next.map(pulp::cast);
                self.t = pulp::cast(new_t);
                // The lanes with an event, one by one.
                let events = enters | straddles | ended;
                if events == 0 {
                    continue;
                }
                let axes: [f64; LANES] = pulp::cast(axis_code);
                let nearest: [f64; LANES] = pulp::cast(nearest);
                let t_out: [f64; LANES] = pulp::cast(t_out);
                let corners: [[f32; LANES]; 8] = corners.map(pulp::cast);
                let mut pending = events;
                while pending != 0 {
                    let j = pending.trailing_zeros() as usize;
                    pending &= pending - 1;
                    let axis = axes[j] as usize;
                    if enters & (1 << j) != 0 {
                        // Keep the block DDA and its step; walk the block's cells from `t` to its exit.
                        for a in 0..3 {
                            self.saved_c[a][j] = self.c[a][j];
                            self.saved_next[a][j] = self.next[a][j];
                        }
                        self.saved_to[j] = self.to[j];
                        self.saved_axis[j] = axis;
                        self.saved_nearest[j] = nearest[j];
                        self.saved_out[j] = t_out[j];
                        let first = [0, 1, 2].map(|a| self.c[a][j] as i64 * BLOCK);
                        let last: [i64; 3] = std::array::from_fn(|a| (first[a] + BLOCK - 1).min(last_cell[a]));
                        self.start_dda(j, 1, (self.t[j], t_out[j]), (first, last));
                        self.in_cells |= 1 << j;
                    } else if straddles & (1 << j) != 0 {
                        let v: [f32; 8] = std::array::from_fn(|k| corners[k][j]);
                        let (o, d) = ([0, 1, 2].map(|a| self.o[a][j]), [0, 1, 2].map(|a| self.d[a][j]));
                        let cell = [0, 1, 2].map(|a| self.c[a][j] as i64);
                        let direction = self.world_direction[j];
                        if let Some(rgba) = scene.cell_hit(&v, cell, o, d, self.t[j], t_out[j], direction) {
                            image[self.pixel[j]] = rgba;
                            self.refill(j, scene, &mut order, image);
                        } else if self.advance(j, axis, nearest[j], t_out[j]) {
                            self.walk_ended(j, scene, &mut order, image);
                        }
                    } else {
                        self.walk_ended(j, scene, &mut order, image);
                    }
                }
            }
        }
    }

    /// One band of rows traced by [`LockStep`] (dispatched per band: a closure handed to rayon would not inherit the
    /// instruction set).
    struct LockStepBand<'s, 'a> {
        simd: V3,
        scene: &'s Scene<'a>,
        band: usize,
        rows: &'s mut [[f32; 4]],
    }

    /// Rows per band.
    const BAND_ROWS: usize = 4;

    impl pulp::WithSimd for LockStepBand<'_, '_> {
        type Output = (u64, u64);

        #[inline(always)]
        fn with_simd<S: pulp::Simd>(self, _simd: S) -> Self::Output {
            let n = self.scene.size as usize;
            let (band, height) = (self.band, self.rows.len() / n);
            // The rays of 4×BAND_ROWS tiles in turn, so that the lanes' rays are neighbours.
            let order = (0..n).step_by(4).flat_map(move |x0| {
                (0..height).flat_map(move |dy| {
                    (x0..(x0 + 4).min(n)).map(move |x| (dy * n + x, x as u32, (band * BAND_ROWS + dy) as u32))
                })
            });
            let mut lanes = LockStep::new();
            lanes.run(self.simd, self.scene, CornerGather::new(true), order, self.rows);
            (lanes.cells, lanes.blocks)
        }
    }

    /// Traces one frame into `image` with [`LockStep`] on every band of rows; the cells and blocks visited, or
    /// `None` where the CPU lacks AVX2 or the volume has more voxels than 32-bit offsets reach.
    pub fn frame(scene: &Scene<'_>, image: &mut [[f32; 4]]) -> Option<(u64, u64)> {
        let simd = V3::try_new()?;
        // The gathers read by 32-bit offsets, and the lanes' indices are converted to 32 bits.
        if scene.volume.voxels.len() > i32::MAX as usize {
            return None;
        }
        let n = scene.size as usize;
        Some(
            image
                .par_chunks_mut(BAND_ROWS * n)
                .enumerate()
                .map(|(band, rows)| pulp::Simd::vectorize(simd, LockStepBand { simd, scene, band, rows }))
                .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1)),
        )
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

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
        let t = median(times);
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
    let t = median(times);
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
