//! Trilinear sampling and gradients inside one brick.
//!
//! A brick stores `(M+2)³` voxels: voxel index `i` is centred at `(i − ½)/M` of its node (index 0 and `M+1` are the
//! one-voxel border copied from the neighbours), so a position `u ∈ [0, 1]` of the node maps to the continuous index
//! `u·M + ½`, and trilinear filtering never reads outside the brick (GigaVoxels [P09] §4).

use voxstream_core::{dequantize, BLOCK_CELLS};

/// The cell holding continuous voxel index `x` (clamped to the brick): index of its first voxel, and the fractions.
#[inline(always)]
fn cell(b: usize, x: [f32; 3]) -> (usize, [f32; 3]) {
    let max = (b - 1) as f32;
    let mut i0 = [0usize; 3];
    let mut f = [0f32; 3];
    for a in 0..3 {
        let c = x[a].clamp(0.0, max);
        let i = (c as usize).min(b - 2);
        i0[a] = i;
        f[a] = c - i as f32;
    }
    ((i0[2] * b + i0[1]) * b + i0[0], f)
}

/// The occupancy block (x fastest, `blocks` per axis, [`BLOCK_CELLS`] cells each) holding the cell that
/// [`trilinear`] reads for `x`: the block's value range bounds the sample.
#[inline(always)]
pub fn block_of(b: usize, blocks: usize, x: [f32; 3]) -> usize {
    let max = (b - 1) as f32;
    let axis = |v: f32| (v.clamp(0.0, max) as usize).min(b - 2) / BLOCK_CELLS;
    (axis(x[2]) * blocks + axis(x[1])) * blocks + axis(x[0])
}

/// Samples a brick at continuous voxel index `x` (each axis clamped to `[0, B−1]`, `B = M + 2`).
#[inline(always)]
pub fn trilinear(brick: &[u16], b: usize, x: [f32; 3]) -> f32 {
    let (base, f) = cell(b, x);
    let row = b;
    let slab = b * b;
    let v = |o: usize| dequantize(brick[base + o]);
    let c00 = v(0) + (v(1) - v(0)) * f[0];
    let c10 = v(row) + (v(row + 1) - v(row)) * f[0];
    let c01 = v(slab) + (v(slab + 1) - v(slab)) * f[0];
    let c11 = v(slab + row) + (v(slab + row + 1) - v(slab + row)) * f[0];
    let c0 = c00 + (c10 - c00) * f[1];
    let c1 = c01 + (c11 - c01) * f[1];
    c0 + (c1 - c0) * f[2]
}

/// Value and analytic gradient (value per voxel) of the trilinear field at `x`: one read of the 8 corners.
#[inline(always)]
pub fn trilinear_with_gradient(brick: &[u16], b: usize, x: [f32; 3]) -> (f32, [f32; 3]) {
    let (base, f) = cell(b, x);
    let (row, slab) = (b, b * b);
    let v = |o: usize| dequantize(brick[base + o]);
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
    let dx00 = v100 - v000;
    let dx10 = v110 - v010;
    let dx01 = v101 - v001;
    let dx11 = v111 - v011;
    let gx = lerp(lerp(dx00, dx10, f[1]), lerp(dx01, dx11, f[1]), f[2]);
    (value, [gx, gy, gz])
}

/// Central-difference gradient of the trilinear field at `x`, in value per voxel.
#[inline]
pub fn gradient(brick: &[u16], b: usize, x: [f32; 3]) -> [f32; 3] {
    std::array::from_fn(|a| {
        let mut lo = x;
        let mut hi = x;
        lo[a] -= 1.0;
        hi[a] += 1.0;
        (trilinear(brick, b, hi) - trilinear(brick, b, lo)) * 0.5
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxstream_core::quantize;

    /// A brick holding the linear ramp `value = x / (b − 1)`.
    fn ramp(b: usize) -> Vec<u16> {
        (0..b * b * b).map(|i| quantize((i % b) as f32 / (b - 1) as f32)).collect()
    }

    #[test]
    fn trilinear_reproduces_a_linear_ramp() {
        let b = 6;
        let brick = ramp(b);
        for x in [0.0f32, 0.3, 2.5, 4.99, 5.0] {
            let v = trilinear(&brick, b, [x, 2.2, 3.7]);
            assert!((v - x / 5.0).abs() < 1e-4, "at {x}: {v}");
        }
        // Outside: clamped to the border.
        assert!((trilinear(&brick, b, [-3.0, 0.0, 0.0])).abs() < 1e-4);
    }

    #[test]
    fn analytic_gradient_agrees_with_finite_differences() {
        let b = 6;
        let brick: Vec<u16> = (0..b * b * b).map(|i| quantize(((i * 7919) % 101) as f32 / 100.0)).collect();
        let x = [2.3f32, 1.6, 3.2];
        let (value, g) = trilinear_with_gradient(&brick, b, x);
        assert!((value - trilinear(&brick, b, x)).abs() < 1e-6);
        for a in 0..3 {
            let (mut lo, mut hi) = (x, x);
            lo[a] -= 0.01;
            hi[a] += 0.01;
            let numeric = (trilinear(&brick, b, hi) - trilinear(&brick, b, lo)) / 0.02;
            assert!((numeric - g[a]).abs() < 1e-3, "axis {a}: {numeric} vs {}", g[a]);
        }
    }

    #[test]
    fn gradient_of_a_ramp_points_along_x() {
        let b = 6;
        let g = gradient(&ramp(b), b, [2.5, 2.5, 2.5]);
        assert!((g[0] - 0.2).abs() < 1e-3 && g[1].abs() < 1e-4 && g[2].abs() < 1e-4);
    }
}
