//! The lock-step row of `flat_isosurface_bound` (x86-64 with AVX2 only): the one-level walk of
//! [`Scene::trace`] for eight rays at once, its image the scalar row's bits.

use std::arch::x86_64::{__m256, __m256d, _CMP_GE_OQ, _CMP_LE_OQ, _CMP_LT_OQ, _CMP_NGE_UQ};

use glam::DVec3;
use pulp::x86::V3;
use rayon::prelude::*;
use voxstream_render::gathered_corners::CornerGather;

use crate::scene::{Scene, BLOCK};

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
        let mask = |bits: u32, half: usize| -> __m256d { pulp::cast(LANE_MASKS[((bits >> (4 * half)) & 15) as usize]) };
        let bits = |m: __m256d| avx._mm256_movemask_pd(m) as u32;
        let le = |a: __m256d, b: __m256d| avx._mm256_cmp_pd::<_CMP_LE_OQ>(a, b);
        // Not `>=` (true where NaN), as `dda`'s `next >= to` ends a walk only where it holds.
        let not_ge = |a: __m256d, b: __m256d| avx._mm256_cmp_pd::<_CMP_NGE_UQ>(a, b);
        let ge = |a: __m256d, b: __m256d| avx._mm256_cmp_pd::<_CMP_GE_OQ>(a, b);
        let and = |a: __m256d, b: __m256d| avx._mm256_and_pd(a, b);
        let andnot = |a: __m256d, b: __m256d| avx._mm256_andnot_pd(a, b);
        let or = |a: __m256d, b: __m256d| avx._mm256_or_pd(a, b);
        let select = |m: __m256d, yes: __m256d, no: __m256d| avx._mm256_blendv_pd(no, yes, m);
        let to_u32 =
            |v: Lanes| -> [u32; LANES] { pulp::cast([avx._mm256_cvttpd_epi32(v[0]), avx._mm256_cvttpd_epi32(v[1])]) };
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
            let straddle =
                avx._mm256_and_ps(avx._mm256_cmp_ps::<_CMP_LT_OQ>(lo, iso), avx._mm256_cmp_ps::<_CMP_GE_OQ>(hi, iso));
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
                    let lo_k: __m256d = pulp::cast::<[f64; 4], __m256d>(std::array::from_fn(|l| self.lo[k][4 * h + l]));
                    let hi_k: __m256d = pulp::cast::<[f64; 4], __m256d>(std::array::from_fn(|l| self.hi[k][4 * h + l]));
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
