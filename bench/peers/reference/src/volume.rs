//! The scalar volume: loading a headerless little-endian raw file into `f32`, the trilinear interpolant and its
//! analytic gradient in world units, and the 8x8x8-cell block table (min/max per block) for empty-space skipping.
//!
//! Geometry: sample `(i, j, k)` sits at `origin + spacing * (i, j, k)`; the field is defined on the box
//! `[origin, origin + spacing * (dims - 1)]`.

use anyhow::{bail, Context, Result};

use crate::math::V3;
use crate::scene::{Dtype, VolumeSpec};

#[derive(Debug, Clone)]
pub struct Volume {
    pub dims: [usize; 3],
    pub spacing: V3,
    pub origin: V3,
    data: Vec<f32>,
}

/// A point located in the grid: the cell (lower corner sample index) and the cell-local coordinates in `[0, 1]`.
#[derive(Debug, Clone, Copy)]
pub struct Located {
    pub cell: [usize; 3],
    pub frac: V3,
}

/// `a + t (b - a)`, clamped to `[min(a, b), max(a, b)]` so interpolated values never leave the range of the
/// corner samples (this is what makes the block skip exact under rounding).
#[inline]
fn lerp(a: f64, b: f64, t: f64) -> f64 {
    let r = a + t * (b - a);
    if a <= b {
        r.max(a).min(b)
    } else {
        r.max(b).min(a)
    }
}

/// Unclamped `a + t (b - a)`, for gradients.
#[inline]
fn mix(a: f64, b: f64, t: f64) -> f64 {
    a + t * (b - a)
}

impl Volume {
    /// Builds a volume from samples (x fastest, then y, then z) and checks geometry and values.
    pub fn new(dims: [usize; 3], spacing: V3, origin: V3, data: Vec<f32>) -> Result<Volume> {
        if dims.iter().any(|&d| d < 2) {
            bail!("volume dims must all be >= 2 (got {dims:?})");
        }
        if !spacing.iter().all(|s| s.is_finite() && *s > 0.0) {
            bail!("volume spacing must be finite and > 0 (got {spacing:?})");
        }
        if !origin.iter().all(|o| o.is_finite()) {
            bail!("volume origin must be finite (got {origin:?})");
        }
        let expected = sample_count(dims)?;
        if data.len() != expected {
            bail!("volume has {} samples, expected {expected} for dims {dims:?}", data.len());
        }
        if let Some(i) = data.iter().position(|v| !v.is_finite()) {
            bail!("volume sample {i} is not finite ({})", data[i]);
        }
        Ok(Volume { dims, spacing, origin, data })
    }

    /// Loads the raw file named by `spec`, checking its size against dims and dtype.
    pub fn load(spec: &VolumeSpec) -> Result<Volume> {
        let path = &spec.path;
        let count = sample_count(spec.dims)?;
        let expected = count
            .checked_mul(spec.dtype.bytes())
            .with_context(|| format!("volume dims {:?} are too large", spec.dims))?;
        let actual =
            std::fs::metadata(path).with_context(|| format!("cannot open volume file {}", path.display()))?.len();
        if actual != expected as u64 {
            bail!(
                "volume file {} has {actual} bytes, expected {expected} ({}x{}x{} {})",
                path.display(),
                spec.dims[0],
                spec.dims[1],
                spec.dims[2],
                spec.dtype.name()
            );
        }
        let bytes = std::fs::read(path).with_context(|| format!("cannot read volume file {}", path.display()))?;
        if bytes.len() != expected {
            bail!("volume file {} changed size while being read", path.display());
        }
        let data: Vec<f32> = match spec.dtype {
            Dtype::U8 => bytes.iter().map(|&b| f32::from(b)).collect(),
            Dtype::U16 => bytes.chunks_exact(2).map(|c| f32::from(u16::from_le_bytes([c[0], c[1]]))).collect(),
            Dtype::F32 => bytes.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect(),
        };
        Volume::new(spec.dims, spec.spacing, spec.origin, data)
            .with_context(|| format!("invalid volume file {}", path.display()))
    }

    #[inline]
    pub fn sample(&self, i: usize, j: usize, k: usize) -> f32 {
        self.data[i + self.dims[0] * (j + self.dims[1] * k)]
    }

    pub fn box_min(&self) -> V3 {
        self.origin
    }

    pub fn box_max(&self) -> V3 {
        std::array::from_fn(|a| self.origin[a] + self.spacing[a] * (self.dims[a] - 1) as f64)
    }

    /// Cell and cell-local coordinates of world point `p` (clamped into the box).
    #[inline]
    pub fn locate(&self, p: V3) -> Located {
        let mut cell = [0usize; 3];
        let mut frac = [0.0f64; 3];
        for a in 0..3 {
            let last = (self.dims[a] - 1) as f64;
            let u = ((p[a] - self.origin[a]) / self.spacing[a]).clamp(0.0, last);
            let i = (u.floor() as usize).min(self.dims[a] - 2);
            cell[a] = i;
            frac[a] = u - i as f64;
        }
        Located { cell, frac }
    }

    /// The 8 corner samples of a cell, index `dx + 2 dy + 4 dz`.
    #[inline]
    pub fn corners(&self, cell: [usize; 3]) -> [f64; 8] {
        let [i, j, k] = cell;
        let nx = self.dims[0];
        let nxy = nx * self.dims[1];
        let base = i + nx * j + nxy * k;
        let d = &self.data;
        [
            f64::from(d[base]),
            f64::from(d[base + 1]),
            f64::from(d[base + nx]),
            f64::from(d[base + nx + 1]),
            f64::from(d[base + nxy]),
            f64::from(d[base + nxy + 1]),
            f64::from(d[base + nxy + nx]),
            f64::from(d[base + nxy + nx + 1]),
        ]
    }

    /// Trilinear value from a cell's corners.
    #[inline]
    pub fn value_of(c: &[f64; 8], f: V3) -> f64 {
        let c00 = lerp(c[0], c[1], f[0]);
        let c10 = lerp(c[2], c[3], f[0]);
        let c01 = lerp(c[4], c[5], f[0]);
        let c11 = lerp(c[6], c[7], f[0]);
        lerp(lerp(c00, c10, f[1]), lerp(c01, c11, f[1]), f[2])
    }

    /// Analytic gradient of the trilinear interpolant, in world units (per unit length along each axis).
    #[inline]
    pub fn gradient_of(&self, c: &[f64; 8], f: V3) -> V3 {
        let [fx, fy, fz] = f;
        // d/dfx: x-differences at the four (y, z) edges, interpolated in y then z.
        let gx = mix(mix(c[1] - c[0], c[3] - c[2], fy), mix(c[5] - c[4], c[7] - c[6], fy), fz);
        // d/dfy: y-differences at the four (x, z) edges, interpolated in x then z.
        let gy = mix(mix(c[2] - c[0], c[3] - c[1], fx), mix(c[6] - c[4], c[7] - c[5], fx), fz);
        // d/dfz: z-differences at the four (x, y) edges, interpolated in x then y.
        let gz = mix(mix(c[4] - c[0], c[5] - c[1], fx), mix(c[6] - c[2], c[7] - c[3], fx), fy);
        [gx / self.spacing[0], gy / self.spacing[1], gz / self.spacing[2]]
    }

    /// Trilinear value at world point `p`.
    #[cfg(test)]
    pub fn value(&self, p: V3) -> f64 {
        let l = self.locate(p);
        Volume::value_of(&self.corners(l.cell), l.frac)
    }

    /// Trilinear value and world-space gradient at world point `p`.
    #[cfg(test)]
    pub fn value_gradient(&self, p: V3) -> (f64, V3) {
        let l = self.locate(p);
        let c = self.corners(l.cell);
        (Volume::value_of(&c, l.frac), self.gradient_of(&c, l.frac))
    }
}

fn sample_count(dims: [usize; 3]) -> Result<usize> {
    dims.iter()
        .try_fold(1usize, |acc, &d| acc.checked_mul(d))
        .with_context(|| format!("volume dims {dims:?} are too large"))
}

/// Min/max of the samples of each block of `CELLS`^3 cells (a block's cells touch `(CELLS + 1)`^3 samples; the
/// last block along an axis may be smaller).
#[derive(Debug, Clone)]
pub struct BlockGrid {
    pub counts: [usize; 3],
    pub min: Vec<f32>,
    pub max: Vec<f32>,
}

impl BlockGrid {
    pub const CELLS: usize = 8;

    pub fn new(vol: &Volume) -> BlockGrid {
        let counts: [usize; 3] = std::array::from_fn(|a| (vol.dims[a] - 1).div_ceil(Self::CELLS));
        let total = counts[0] * counts[1] * counts[2];
        let mut min = vec![f32::INFINITY; total];
        let mut max = vec![f32::NEG_INFINITY; total];
        for bz in 0..counts[2] {
            for by in 0..counts[1] {
                for bx in 0..counts[0] {
                    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
                    let range = |b: usize, a: usize| b * Self::CELLS..=((b + 1) * Self::CELLS).min(vol.dims[a] - 1);
                    for k in range(bz, 2) {
                        for j in range(by, 1) {
                            for i in range(bx, 0) {
                                let v = vol.sample(i, j, k);
                                lo = lo.min(v);
                                hi = hi.max(v);
                            }
                        }
                    }
                    let b = bx + counts[0] * (by + counts[1] * bz);
                    min[b] = lo;
                    max[b] = hi;
                }
            }
        }
        BlockGrid { counts, min, max }
    }

    pub fn len(&self) -> usize {
        self.min.len()
    }

    /// Block containing `cell`.
    #[inline]
    pub fn index(&self, cell: [usize; 3]) -> usize {
        let c = Self::CELLS;
        cell[0] / c + self.counts[0] * (cell[1] / c + self.counts[1] * (cell[2] / c))
    }
}
