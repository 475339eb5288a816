//! Trilinear sampling and gradients inside one brick.
//!
//! A brick stores `(M+2)³` voxels: voxel index `i` is centred at `(i − ½)/M` of its node (index 0 and `M+1` are the
//! one-voxel border copied from the neighbours), so a position `u ∈ [0, 1]` of the node maps to the continuous index
//! `u·M + ½`, and trilinear filtering never reads outside the brick (GigaVoxels [P09] §4).

use voxstream_core::{Dequantize, Voxel, BLOCK_CELLS};

use crate::gathered_corners::CornerGather;

/// `⌊c⌋` capped at `last`, as an integer and as a float, for `c ∈ [0, 2²³)` (coordinates and table positions after
/// clamping): `floor` and `min`, then the integer read off the mantissa of `2²³ + ⌊c⌋`. The same integer as
/// `(c as u32).min(last)`, through float operations only, so it vectorises: Rust's saturating float→int conversion
/// is about five scalar instructions per lane (range and NaN fix-ups) before AVX-512.
#[inline(always)]
pub fn floor_index(c: f32, last: u32) -> (u32, f32) {
    const TWO_POW_23: f32 = 8_388_608.0;
    let f = c.floor().min(last as f32);
    ((f + TWO_POW_23).to_bits() - TWO_POW_23.to_bits(), f)
}

/// The cell of a brick that trilinear filtering reads for a continuous voxel index (clamped to the brick).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cell {
    /// Index of the cell's first voxel in the brick.
    base: usize,
    /// Position inside the cell, per axis in `[0, 1]`.
    fraction: [f32; 3],
    /// Integer coordinates of the cell.
    ijk: [usize; 3],
}

impl Cell {
    /// The cell holding continuous voxel index `x`, each axis clamped to `[0, B−1]` (`B = M + 2` stored voxels).
    #[inline(always)]
    pub fn locate(b: usize, x: [f32; 3]) -> Cell {
        let max = (b - 1) as f32;
        let last_cell = b as u32 - 2;
        let mut ijk = [0usize; 3];
        let mut fraction = [0f32; 3];
        for a in 0..3 {
            // `max`/`min` rather than `clamp`: NaN goes to 0.
            let c = x[a].max(0.0).min(max);
            let (i, floor) = floor_index(c, last_cell);
            ijk[a] = i as usize;
            fraction[a] = c - floor;
        }
        Cell { base: (ijk[2] * b + ijk[1]) * b + ijk[0], fraction, ijk }
    }

    /// The occupancy block (x fastest, `blocks` per axis, [`BLOCK_CELLS`] cells each) holding this cell: the
    /// block's value range bounds every sample taken in the cell.
    #[inline(always)]
    pub fn block(&self, blocks: usize) -> usize {
        let [i, j, k] = self.block_ijk();
        (k * blocks + j) * blocks + i
    }

    /// The coordinates of [`Cell::block`]'s block.
    #[inline(always)]
    pub fn block_ijk(&self) -> [usize; 3] {
        self.ijk.map(|v| v / BLOCK_CELLS)
    }

    /// The trilinear value in the cell (of a brick with `b` voxels per axis).
    #[inline(always)]
    pub fn value<V: Voxel>(&self, brick: &[V], b: usize, dq: Dequantize) -> f32 {
        let (row, slab) = (b, b * b);
        let f = self.fraction;
        let corners = &brick[self.base..self.base + slab + row + 2];
        // Interpolate the stored integers and normalise once.
        let v = |o: usize| corners[o].stored();
        let c00 = v(0) + (v(1) - v(0)) * f[0];
        let c10 = v(row) + (v(row + 1) - v(row)) * f[0];
        let c01 = v(slab) + (v(slab + 1) - v(slab)) * f[0];
        let c11 = v(slab + row) + (v(slab + row + 1) - v(slab + row)) * f[0];
        let c0 = c00 + (c10 - c00) * f[1];
        let c1 = c01 + (c11 - c01) * f[1];
        V::value(c0 + (c1 - c0) * f[2], dq)
    }

    /// Value and analytic gradient (value per voxel) of the trilinear field in the cell: one read of the 8 corners.
    #[inline(always)]
    pub fn value_and_gradient<V: Voxel>(&self, brick: &[V], b: usize, dq: Dequantize) -> (f32, [f32; 3]) {
        let (row, slab) = (b, b * b);
        let f = self.fraction;
        let corners = &brick[self.base..self.base + slab + row + 2];
        let v = |o: usize| corners[o].stored();
        let (v000, v100, v010, v110) = (v(0), v(1), v(row), v(row + 1));
        let (v001, v101, v011, v111) = (v(slab), v(slab + 1), v(slab + row), v(slab + row + 1));
        let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
        let c00 = lerp(v000, v100, f[0]);
        let c10 = lerp(v010, v110, f[0]);
        let c01 = lerp(v001, v101, f[0]);
        let c11 = lerp(v011, v111, f[0]);
        let c0 = lerp(c00, c10, f[1]);
        let c1 = lerp(c01, c11, f[1]);
        let value = lerp(c0, c1, f[2]);
        let gz = c1 - c0;
        let gy = lerp(c10 - c00, c11 - c01, f[2]);
        let gx = lerp(lerp(v100 - v000, v110 - v010, f[1]), lerp(v101 - v001, v111 - v011, f[1]), f[2]);
        (V::value(value, dq), [gx, gy, gz].map(|g| dq.slope(g)))
    }
}

/// Samples taken together by [`values_along`].
pub const LANES: usize = 8;

/// The trilinear values at `LANES` consecutive points `start + (k + j)·delta` (`j = 0..LANES`) of a line through a
/// brick with `b` voxels per axis: the same arithmetic as [`Cell::locate`] and [`Cell::value`] per point, so the
/// same bits, but arranged lane by lane (positions, cells and weights of all points, then their corners, then the
/// interpolation) so that the compiler turns all but the corner reads into SIMD instructions of the width the CPU
/// offers (see [`crate::InstructionSet`]). Seed 002 §4 (Knoll et al.) traces packets of rays for the same reason.
#[inline(always)]
pub fn values_along<V: Voxel>(
    brick: &[V],
    b: usize,
    start: [f32; 3],
    delta: [f32; 3],
    k: f32,
    dq: Dequantize,
    gather: CornerGather,
) -> [f32; LANES] {
    let (corners, fractions) = corners_along(brick, b, start, delta, k, gather);
    interpolate::<V>(&corners, &fractions, dq)
}

/// [`values_along`] with the analytic gradients of [`Cell::value_and_gradient`], bit for bit.
#[inline(always)]
pub fn values_and_gradients_along<V: Voxel>(
    brick: &[V],
    b: usize,
    start: [f32; 3],
    delta: [f32; 3],
    k: f32,
    dq: Dequantize,
    gather: CornerGather,
) -> ([f32; LANES], [[f32; 3]; LANES]) {
    let (corners, fractions) = corners_along(brick, b, start, delta, k, gather);
    interpolate_with_gradients::<V>(&corners, &fractions, dq)
}

/// Trilinear values from the corners and cell fractions of `LANES` points, lane by lane: [`Cell::value`]'s
/// arithmetic.
#[inline(always)]
fn interpolate<V: Voxel>(
    corners: &[[f32; LANES]; 8],
    [fx, fy, fz]: &[[f32; LANES]; 3],
    dq: Dequantize,
) -> [f32; LANES] {
    let mut out = [0f32; LANES];
    for j in 0..LANES {
        let v = |corner: usize| corners[corner][j];
        let c00 = v(0) + (v(1) - v(0)) * fx[j];
        let c10 = v(2) + (v(3) - v(2)) * fx[j];
        let c01 = v(4) + (v(5) - v(4)) * fx[j];
        let c11 = v(6) + (v(7) - v(6)) * fx[j];
        let c0 = c00 + (c10 - c00) * fy[j];
        let c1 = c01 + (c11 - c01) * fy[j];
        out[j] = V::value(c0 + (c1 - c0) * fz[j], dq);
    }
    out
}

/// [`interpolate`] with the analytic gradients: [`Cell::value_and_gradient`]'s arithmetic.
#[inline(always)]
fn interpolate_with_gradients<V: Voxel>(
    corners: &[[f32; LANES]; 8],
    [fx, fy, fz]: &[[f32; LANES]; 3],
    dq: Dequantize,
) -> ([f32; LANES], [[f32; 3]; LANES]) {
    let mut values = [0f32; LANES];
    let mut gradients = [[0f32; 3]; LANES];
    let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
    for j in 0..LANES {
        let v = |corner: usize| corners[corner][j];
        let (v000, v100, v010, v110) = (v(0), v(1), v(2), v(3));
        let (v001, v101, v011, v111) = (v(4), v(5), v(6), v(7));
        let c00 = lerp(v000, v100, fx[j]);
        let c10 = lerp(v010, v110, fx[j]);
        let c01 = lerp(v001, v101, fx[j]);
        let c11 = lerp(v011, v111, fx[j]);
        let c0 = lerp(c00, c10, fy[j]);
        let c1 = lerp(c01, c11, fy[j]);
        values[j] = V::value(lerp(c0, c1, fz[j]), dq);
        let gz = c1 - c0;
        let gy = lerp(c10 - c00, c11 - c01, fz[j]);
        let gx = lerp(lerp(v100 - v000, v110 - v010, fy[j]), lerp(v101 - v001, v111 - v011, fy[j]), fz[j]);
        gradients[j] = [gx, gy, gz].map(|g| dq.slope(g));
    }
    (values, gradients)
}

/// The eight corners (`[corner][lane]`, corner = x + 2y + 4z) and the in-cell fractions (`[axis][lane]`) of the
/// `LANES` points `start + (k + j)·delta`, located like [`Cell::locate`].
#[inline(always)]
#[allow(clippy::type_complexity)]
fn corners_along<V: Voxel>(
    brick: &[V],
    b: usize,
    start: [f32; 3],
    delta: [f32; 3],
    k: f32,
    gather: CornerGather,
) -> ([[f32; LANES]; 8], [[f32; LANES]; 3]) {
    let max = (b - 1) as f32;
    let last_cell = b as u32 - 2;
    let (row, slab) = (b, b * b);
    let mut fraction = [[0f32; LANES]; 3];
    let mut base = [0u32; LANES];
    for j in 0..LANES {
        let kj = k + j as f32;
        let mut ijk = [0u32; 3];
        for a in 0..3 {
            let c = (start[a] + kj * delta[a]).max(0.0).min(max);
            let (i, floor) = floor_index(c, last_cell);
            ijk[a] = i;
            fraction[a][j] = c - floor;
        }
        base[j] = (ijk[2] * b as u32 + ijk[1]) * b as u32 + ijk[0];
    }
    (gather.read(brick, &base, row, slab), fraction)
}

/// One point on each of `LANES` independent lines, each through its own brick of the pool (`voxels`, `b` voxels
/// per axis, brick `j` starting at `bases[j]`): lane `j` samples `start[·][j] + k[j]·delta[·][j]`. The same
/// arithmetic as [`Cell::locate`] and [`Cell::value`] per lane, so the same bits as sampling each line alone, with
/// the lanes in SIMD registers: rays traced side by side (seed 002 §4, Knoll et al.'s packets) rather than points
/// along one ray. Every lane reads inside its brick whatever its position (positions are clamped), so unused lanes
/// are harmless; `bases[j] + b³ ≤ voxels.len()` is checked per lane.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub fn values_across<V: Voxel>(
    voxels: &[V],
    b: usize,
    bases: &[u32; LANES],
    start: &[[f32; LANES]; 3],
    delta: &[[f32; LANES]; 3],
    k: &[f32; LANES],
    dq: Dequantize,
    gather: CornerGather,
) -> [f32; LANES] {
    let (corners, fractions) = corners_across(voxels, b, bases, start, delta, k, gather);
    interpolate::<V>(&corners, &fractions, dq)
}

/// [`values_across`] with the analytic gradients of [`Cell::value_and_gradient`], bit for bit.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub fn values_and_gradients_across<V: Voxel>(
    voxels: &[V],
    b: usize,
    bases: &[u32; LANES],
    start: &[[f32; LANES]; 3],
    delta: &[[f32; LANES]; 3],
    k: &[f32; LANES],
    dq: Dequantize,
    gather: CornerGather,
) -> ([f32; LANES], [[f32; 3]; LANES]) {
    let (corners, fractions) = corners_across(voxels, b, bases, start, delta, k, gather);
    interpolate_with_gradients::<V>(&corners, &fractions, dq)
}

/// The corners and cell fractions of [`values_across`]'s points.
#[inline(always)]
fn corners_across<V: Voxel>(
    voxels: &[V],
    b: usize,
    bases: &[u32; LANES],
    start: &[[f32; LANES]; 3],
    delta: &[[f32; LANES]; 3],
    k: &[f32; LANES],
    gather: CornerGather,
) -> ([[f32; LANES]; 8], [[f32; LANES]; 3]) {
    let max = (b - 1) as f32;
    let last_cell = b as u32 - 2;
    let (row, slab) = (b, b * b);
    let mut fraction = [[0f32; LANES]; 3];
    let mut index = [0u32; LANES];
    for j in 0..LANES {
        let mut ijk = [0u32; 3];
        for a in 0..3 {
            let c = (start[a][j] + k[j] * delta[a][j]).max(0.0).min(max);
            let (i, floor) = floor_index(c, last_cell);
            ijk[a] = i;
            fraction[a][j] = c - floor;
        }
        index[j] = (ijk[2] * b as u32 + ijk[1]) * b as u32 + ijk[0];
    }
    // In `u32`: the lanes run only on pools of at most `u32::MAX` voxels (`RayCaster::new`).
    let at: [u32; LANES] = std::array::from_fn(|j| bases[j] + index[j]);
    (gather.read(voxels, &at, row, slab), fraction)
}

/// Samples a brick at continuous voxel index `x` (each axis clamped to `[0, B−1]`, `B = M + 2`).
#[inline(always)]
pub fn trilinear<V: Voxel>(brick: &[V], b: usize, x: [f32; 3], dq: Dequantize) -> f32 {
    Cell::locate(b, x).value(brick, b, dq)
}

/// Value and analytic gradient (value per voxel) of the trilinear field at `x`: one read of the 8 corners.
#[inline(always)]
pub fn trilinear_with_gradient<V: Voxel>(brick: &[V], b: usize, x: [f32; 3], dq: Dequantize) -> (f32, [f32; 3]) {
    Cell::locate(b, x).value_and_gradient(brick, b, dq)
}

/// Central-difference gradient of the trilinear field at `x`, in value per voxel.
#[inline]
pub fn gradient<V: Voxel>(brick: &[V], b: usize, x: [f32; 3], dq: Dequantize) -> [f32; 3] {
    std::array::from_fn(|a| {
        let mut lo = x;
        let mut hi = x;
        lo[a] -= 1.0;
        hi[a] += 1.0;
        (trilinear(brick, b, hi, dq) - trilinear(brick, b, lo, dq)) * 0.5
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxstream_core::{quantize, VoxelFormat};

    const DQ: Dequantize = Dequantize { scale: 1.0 / 65535.0, offset: 0.0 };

    #[test]
    fn floor_index_is_the_saturating_conversion_capped() {
        // Every float from 0 up to past the cap in a 34-voxel brick, and around the largest table position.
        for (top, last) in [(40.0f32, 32u32), (4100.0, 4094)] {
            let mut c = 0.0f32;
            while c <= top {
                let (i, floor) = floor_index(c, last);
                assert_eq!(i, (c as u32).min(last), "{c}");
                assert_eq!(floor.to_bits(), ((c as u32).min(last) as f32).to_bits(), "{c}");
                c = if c < 1.0 { c + 1.0 / 4096.0 } else { f32::from_bits(c.to_bits() + 97) };
            }
        }
    }

    /// A brick holding the linear ramp `value = x / (b − 1)`.
    fn ramp(b: usize) -> Vec<u16> {
        (0..b * b * b).map(|i| quantize((i % b) as f32 / (b - 1) as f32)).collect()
    }

    #[test]
    fn trilinear_reproduces_a_linear_ramp() {
        let b = 6;
        let brick = ramp(b);
        for x in [0.0f32, 0.3, 2.5, 4.99, 5.0] {
            let v = trilinear(&brick, b, [x, 2.2, 3.7], DQ);
            assert!((v - x / 5.0).abs() < 1e-4, "at {x}: {v}");
        }
        // Outside: clamped to the border.
        assert!((trilinear(&brick, b, [-3.0, 0.0, 0.0], DQ)).abs() < 1e-4);
    }

    #[test]
    fn analytic_gradient_agrees_with_finite_differences() {
        let b = 6;
        let brick: Vec<u16> = (0..b * b * b).map(|i| quantize(((i * 7919) % 101) as f32 / 100.0)).collect();
        let x = [2.3f32, 1.6, 3.2];
        let (value, g) = trilinear_with_gradient(&brick, b, x, DQ);
        assert!((value - trilinear(&brick, b, x, DQ)).abs() < 1e-6);
        for a in 0..3 {
            let (mut lo, mut hi) = (x, x);
            lo[a] -= 0.01;
            hi[a] += 0.01;
            let numeric = (trilinear(&brick, b, hi, DQ) - trilinear(&brick, b, lo, DQ)) / 0.02;
            assert!((numeric - g[a]).abs() < 1e-3, "axis {a}: {numeric} vs {}", g[a]);
        }
    }

    #[test]
    fn values_across_lines_of_different_bricks_are_the_single_point_values_bit_for_bit() {
        let b = 10;
        let per_brick = b * b * b;
        // Three bricks in one pool; lanes read them in turn, each along its own line at its own sample index.
        let pool: Vec<u16> = (0..3 * per_brick).map(|i| ((i * 7919 + 13) % 65536) as u16).collect();
        let bases: [u32; LANES] = std::array::from_fn(|j| ((j % 3) * per_brick) as u32);
        let mut start = [[0f32; LANES]; 3];
        let mut delta = [[0f32; LANES]; 3];
        for j in 0..LANES {
            for a in 0..3 {
                start[a][j] = ((j * 3 + a) as f32 * 1.37) % 11.0 - 1.0;
                delta[a][j] = ((j + 2 * a) as f32 * 0.29) % 1.3 - 0.6;
            }
        }
        let gathers = [CornerGather::SCALAR, CornerGather::new(true)];
        for (k, gather) in [[0f32; LANES], std::array::from_fn(|j| (j * j) as f32), [40.0; LANES]]
            .into_iter()
            .flat_map(|k| gathers.map(|gather| (k, gather)))
        {
            let values = values_across(&pool, b, &bases, &start, &delta, &k, DQ, gather);
            let (with_gradients, gradients) =
                values_and_gradients_across(&pool, b, &bases, &start, &delta, &k, DQ, gather);
            for j in 0..LANES {
                let x: [f32; 3] = std::array::from_fn(|a| start[a][j] + k[j] * delta[a][j]);
                let brick = &pool[bases[j] as usize..bases[j] as usize + per_brick];
                assert_eq!(values[j].to_bits(), trilinear(brick, b, x, DQ).to_bits(), "lane {j} at {x:?}");
                let (value, gradient) = trilinear_with_gradient(brick, b, x, DQ);
                assert_eq!(with_gradients[j].to_bits(), value.to_bits(), "lane {j} at {x:?}");
                assert_eq!(gradients[j].map(f32::to_bits), gradient.map(f32::to_bits), "lane {j} at {x:?}");
            }
        }
    }

    #[test]
    fn values_along_a_line_are_the_single_point_values_bit_for_bit() {
        let b = 10;
        let brick: Vec<u16> = (0..b * b * b).map(|i| ((i * 7919 + 13) % 65536) as u16).collect();
        for (start, delta) in [
            ([0.3f32, 8.7, 4.1], [0.41f32, -0.37, 0.05]),
            ([-2.0, 4.5, 9.5], [0.5, 0.0, -0.02]),
            ([8.9, 0.01, 3.3], [-1.1, 0.6, 0.7]),
        ] {
            for (k, gather) in [0.0f32, 3.0, 17.0]
                .into_iter()
                .flat_map(|k| [CornerGather::SCALAR, CornerGather::new(true)].map(|gather| (k, gather)))
            {
                let values = values_along(&brick, b, start, delta, k, DQ, gather);
                let (with_gradient, gradients) = values_and_gradients_along(&brick, b, start, delta, k, DQ, gather);
                for (j, value) in values.iter().enumerate() {
                    let kj = k + j as f32;
                    let x = [start[0] + kj * delta[0], start[1] + kj * delta[1], start[2] + kj * delta[2]];
                    assert_eq!(value.to_bits(), trilinear(&brick, b, x, DQ).to_bits(), "lane {j} at {x:?}");
                    let (single, gradient) = trilinear_with_gradient(&brick, b, x, DQ);
                    assert_eq!(with_gradient[j].to_bits(), single.to_bits(), "lane {j} at {x:?}");
                    assert_eq!(gradients[j].map(f32::to_bits), gradient.map(f32::to_bits), "lane {j} at {x:?}");
                }
            }
        }
    }

    #[test]
    fn gradient_of_a_ramp_points_along_x() {
        let b = 6;
        let g = gradient(&ramp(b), b, [2.5, 2.5, 2.5], DQ);
        assert!((g[0] - 0.2).abs() < 1e-3 && g[1].abs() < 1e-4 && g[2].abs() < 1e-4);
    }

    #[test]
    fn narrow_bricks_sample_the_values_of_their_wide_twins() {
        // A u8 volume of range [12, 200]: the same brick as bytes (8-bit pool) and as quantised values (16-bit).
        let b = 8;
        let Some(VoxelFormat::Narrow { scale, offset }) = VoxelFormat::for_bytes([12.0, 200.0]) else {
            panic!("a byte range")
        };
        let narrow = Dequantize { scale, offset };
        let bytes: Vec<u8> = (0..b * b * b).map(|i| (12 + (i * 37) % 189) as u8).collect();
        let wide: Vec<u16> = bytes.iter().map(|&v| quantize((v as f32 - 12.0) / 188.0)).collect();
        for x in [[0.3f32, 1.7, 2.2], [5.5, 0.0, 6.99], [3.25, 3.5, 3.75], [-1.0, 9.0, 4.4]] {
            let (v8, g8) = trilinear_with_gradient(&bytes, b, x, narrow);
            let (v16, g16) = trilinear_with_gradient(&wide, b, x, DQ);
            // Each 16-bit voxel is within half a step of its byte's value; interpolation keeps that bound.
            assert!((v8 - v16).abs() <= 0.5 / 65535.0 + 1e-6, "at {x:?}: {v8} vs {v16}");
            for a in 0..3 {
                assert!((g8[a] - g16[a]).abs() <= 2.0 / 65535.0 + 1e-6, "at {x:?}, axis {a}: {g8:?} vs {g16:?}");
            }
            assert_eq!(
                values_along(&bytes, b, x, [0.25, -0.5, 0.125], 0.0, narrow, CornerGather::new(true))[0].to_bits(),
                v8.to_bits()
            );
        }
    }
}
