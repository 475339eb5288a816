//! The flat volume and the scalar walks of `flat_isosurface_bound`: the store's finest level in one array with its
//! occupancy bits, and one ray at a time through 8³-cell blocks (and 32³-cell macro-blocks), its crossing found by
//! the renderer's [`CellCubic`] and shaded by its `RayLight`.

use std::ops::ControlFlow;

use glam::{DVec3, Vec3};
use voxstream_render::cell_intersection::{cell_gradient, CellCubic};
use voxstream_render::lighting::LightingSettings;
use voxstream_render::traversal::intersect_aabb;
use voxstream_render::CameraFrame;

/// Cells per occupancy block and axis: the renderer's.
pub(crate) const BLOCK: i64 = voxstream_core::BLOCK_CELLS as i64;
/// Blocks per macro-block and axis (the second level of culling: 32³ cells).
pub(crate) const MACRO: i64 = 4;

pub(crate) struct Volume {
    pub(crate) dims: [usize; 3],
    pub(crate) voxels: Vec<u8>,
    /// Blocks per axis.
    pub(crate) blocks: [i64; 3],
    /// Per block: whether some corner of its cells reaches the isovalue.
    pub(crate) active: Vec<bool>,
    /// Macro-blocks (`MACRO³` blocks) per axis, and per macro-block whether one of its blocks is active.
    pub(crate) macros: [i64; 3],
    pub(crate) macro_active: Vec<bool>,
    pub(crate) iso: f32,
}

impl Volume {
    #[inline(always)]
    pub(crate) fn corners(&self, cell: [i64; 3]) -> [f32; 8] {
        let [nx, ny, _] = self.dims;
        let at = (cell[2] as usize * ny + cell[1] as usize) * nx + cell[0] as usize;
        let (row, slab) = (nx, nx * ny);
        let v = &self.voxels[at..at + slab + row + 2];
        [v[0], v[1], v[row], v[row + 1], v[slab], v[slab + 1], v[slab + row], v[slab + row + 1]].map(f32::from)
    }
}

/// What one ray found: the hit's colour and opacity, and the cells it examined.
pub(crate) struct RayResult {
    pub(crate) rgba: [f32; 4],
    pub(crate) cells: u64,
    pub(crate) blocks: u64,
    pub(crate) macros: u64,
}

pub(crate) struct Scene<'a> {
    pub(crate) volume: &'a Volume,
    pub(crate) frame: CameraFrame,
    pub(crate) size: u32,
    pub(crate) lighting: LightingSettings,
    pub(crate) color: Vec3,
    /// The world position of voxel 0's centre, and the world size of a voxel.
    pub(crate) world_origin: DVec3,
    pub(crate) spacing: DVec3,
}

/// The lattice cells of size `unit` (in trilinear cells) that the ray `o + t·d` crosses over `[t_from, t_to)`,
/// within the cells `lo ..= hi` of that lattice, in order: an Amanatides–Woo DDA. `visit(cell, t_in, t_out)`
/// breaks to end the walk.
#[inline(always)]
pub(crate) fn dda<R>(
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
pub(crate) struct RayLine {
    pub(crate) o: [f64; 3],
    pub(crate) d: [f64; 3],
    pub(crate) inverse: [f64; 3],
    pub(crate) step: [i64; 3],
}

impl Scene<'_> {
    /// The first crossing along one ray: a DDA over macro-blocks (with `MACRO` on), over the blocks of those that
    /// can hold it, over the cells of those blocks that can.
    #[inline(always)]
    pub(crate) fn trace(&self, x: u32, y: u32, two_levels: bool) -> RayResult {
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
    pub(crate) fn voxel_ray(&self, x: u32, y: u32) -> Option<(RayLine, (f64, f64), DVec3)> {
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
    pub(crate) fn cell_hit(
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
