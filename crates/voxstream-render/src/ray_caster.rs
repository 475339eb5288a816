//! One ray through the N³-tree: cone-traced level of detail, kd-restart descent, brick marching, feedback.
//!
//! Implements GigaVoxels [P09] §6 ("Rendering": stackless descent from the root at every new segment, cone tracing
//! with quadrilinear mip filtering) and §5 (the ray's feedback), with [R08] §5's emission–absorption integration:
//!
//! 1. At the current distance `t`, the cone's footprint `w = t·spread` gives the continuous level
//!    `ℓ = log_N(1 / (M·w))`: the level whose voxel matches the pixel.
//! 2. Descend from the root to the node containing the point at level `⌈ℓ⌉`, marking each tile and brick used.
//!    Stop early at a constant node (integrated analytically), a terminal node, a node whose data is missing
//!    (request production; the deepest ancestor with data stands in) or a node without children (request a
//!    subdivision). A ray then goes on with the coarser data and may report further misses, up to
//!    `max_requests_per_ray` per frame (GigaVoxels allowed one, which makes translucent scenes converge slowly).
//! 3. Skip the box at once if the transfer function makes every value of its bricks invisible (per-brick min/max).
//!    Otherwise march the node's box with steps of `step_factor` voxels of level `ℓ` (the cone's footprint; of the
//!    sampled level where only coarser data exists), blending the trilinear samples
//!    of the two adjacent levels by `frac(ℓ)` (quadrilinear), correcting opacity for the step length, optionally
//!    Phong-shading with the gradient, and stop once opaque.
//! 4. Leave the box and descend again for the next point, from the deepest node of the previous path that still
//!    contains it (kd-restart from the root, shortened by keeping the path).
//!
//! Positions are `f64` in the unit cube and node coordinates are integers, so zooms far below `2⁻²⁰` stay exact
//! (GigaVoxels stopped at `2¹⁹` because of float32 precision).

use glam::DVec3;
use voxstream_core::{BrickSlot, FeedbackBuffer, Node, NodeData, NodeId, Request, RequestKind, TreeView, BLOCK_CELLS};

use crate::sampler::Cell;
use crate::settings::{PhongCoefficients, RenderSettings, Shading};
use crate::transfer_function::TransferLut;

/// Deepest level the precomputed scale table covers.
const MAX_TABLE_LEVELS: usize = 64;
/// A ray may not cross more segments than this (guards against any numerical stall).
const MAX_SEGMENTS: u32 = 1 << 20;

/// Counters of one ray batch.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RayStats {
    /// Rays traced.
    pub rays: u64,
    /// Brick samples taken plus constant segments integrated.
    pub samples: u64,
    /// Descents from the root.
    pub descents: u64,
}

impl RayStats {
    /// Adds another batch's counters.
    pub fn add(&mut self, other: &RayStats) {
        self.rays += other.rays;
        self.samples += other.samples;
        self.descents += other.descents;
    }
}

/// Deepest level a descent path can hold.
const MAX_PATH: usize = MAX_TABLE_LEVELS;

/// One node of the current descent.
#[derive(Clone, Copy, Debug)]
struct PathEntry {
    id: NodeId,
    node: Node,
    ijk: [u64; 3],
}

/// The nodes from the root to the last node reached, reused between segments so that a new descent restarts from
/// the deepest ancestor that still contains the point (a short-stack variant of kd-restart). One per thread, reused
/// from ray to ray.
pub struct DescentPath {
    entries: [PathEntry; MAX_PATH],
    len: usize,
}

impl DescentPath {
    /// A path holding only the root of `view`.
    pub fn new(view: TreeView<'_>) -> DescentPath {
        let root = PathEntry { id: NodeId::ROOT, node: view.root(), ijk: [0; 3] };
        DescentPath { entries: [root; MAX_PATH], len: 1 }
    }

    /// Back to the root, for a new ray.
    fn reset(&mut self, view: TreeView<'_>) {
        self.entries[0] = PathEntry { id: NodeId::ROOT, node: view.root(), ijk: [0; 3] };
        self.len = 1;
    }
}

/// A brick found on the descent: which slot and which node it belongs to.
#[derive(Clone, Copy, Debug)]
struct BrickRef {
    slot: BrickSlot,
    level: u32,
    ijk: [u64; 3],
}

/// What the descent found for the current segment.
enum SegmentData {
    /// Nothing resident at all (the root is missing): the segment is skipped.
    Nothing,
    /// A constant node: integrate analytically.
    Constant(f32),
    /// Bricks: the finest with data, and its parent for level blending.
    Bricks { fine: BrickRef, coarse: Option<BrickRef>, blend_level: bool },
}

/// Traces rays against one frame's tree view, writing feedback.
pub struct RayCaster<'a> {
    view: TreeView<'a>,
    feedback: &'a FeedbackBuffer,
    lut: &'a TransferLut,
    shading: Shading,
    phong: PhongCoefficients,
    light: Option<DVec3>,
    step_factor: f64,
    lod_bias: f64,
    world_per_volume: f64,
    gradient_scale: [f32; 3],
    clip_lower: DVec3,
    clip_upper: DVec3,
    opacity_cutoff: f32,
    max_requests_per_ray: u32,
    /// `N^d` for every level.
    scale: [f64; MAX_TABLE_LEVELS],
    n: u64,
    brick_size: f64,
    stored: usize,
    inv_ln_n: f64,
    ln_n: f64,
}

impl<'a> RayCaster<'a> {
    /// Prepares a ray caster for one frame.
    pub fn new(
        view: TreeView<'a>,
        feedback: &'a FeedbackBuffer,
        lut: &'a TransferLut,
        settings: &RenderSettings,
    ) -> RayCaster<'a> {
        let shape = view.shape;
        let mut scale = [1.0f64; MAX_TABLE_LEVELS];
        for d in 1..MAX_TABLE_LEVELS {
            scale[d] = scale[d - 1] * shape.n as f64;
        }
        RayCaster {
            view,
            feedback,
            lut,
            shading: settings.shading,
            phong: settings.phong,
            light: settings.light_direction.map(|l| DVec3::from(l).normalize()),
            step_factor: settings.step_factor,
            lod_bias: settings.lod_bias,
            world_per_volume: settings.placement.mean_scale(),
            gradient_scale: settings.placement.scale.map(|s| (1.0 / s) as f32),
            clip_lower: DVec3::from(settings.placement.clip_lower),
            clip_upper: DVec3::from(settings.placement.clip_upper),
            opacity_cutoff: settings.opacity_cutoff,
            max_requests_per_ray: settings.max_requests_per_ray,
            scale,
            n: shape.n as u64,
            brick_size: shape.brick_size as f64,
            stored: shape.stored_brick_size() as usize,
            inv_ln_n: 1.0 / (shape.n as f64).ln(),
            ln_n: (shape.n as f64).ln(),
        }
    }

    /// The tree view this caster reads.
    pub fn view(&self) -> TreeView<'a> {
        self.view
    }

    /// Continuous level of detail at distance `t` (world units) for a cone of `spread` per unit distance.
    #[inline]
    fn level_at(&self, t: f64, spread: f64) -> f64 {
        let footprint = (t * spread / self.world_per_volume).max(1e-300);
        let level = -(self.brick_size * footprint).ln() * self.inv_ln_n + self.lod_bias;
        level.clamp(0.0, self.view.shape.max_level as f64)
    }

    /// Traces one ray given in volume space with `t` in world units (`origin` in volume units, `direction` = the unit
    /// world direction divided by the placement's scale); returns premultiplied `[r, g, b]` and opacity.
    /// Appends at most `max_requests_per_ray` requests to `requests`.
    pub fn trace(
        &self,
        origin: DVec3,
        direction: DVec3,
        spread: f64,
        stats: &mut RayStats,
        requests: &mut Vec<Request>,
        path: &mut DescentPath,
    ) -> ([f32; 3], f32) {
        let mut sink = RequestSink { requests, remaining: self.max_requests_per_ray };
        let request = &mut sink;
        stats.rays += 1;
        let mut color = [0f32; 3];
        let mut transmittance = 1f32;
        let Some((t_enter, t_leave)) = intersect_aabb(origin, direction, self.clip_lower, self.clip_upper) else {
            return (color, 0.0);
        };
        // Volume units travelled per unit of t.
        let speed = direction.length();
        let mut t = t_enter.max(0.0);
        let inverse_direction = DVec3::ONE / direction;
        let world_direction = (direction * DVec3::from(self.gradient_scale.map(|g| 1.0 / g as f64))).normalize();
        let light = self.light.unwrap_or(-world_direction);
        path.reset(self.view);
        if let Some(slot) = path.entries[0].node.brick() {
            self.feedback.mark_brick(slot);
        }
        let mut segments = 0;
        while t < t_leave && 1.0 - transmittance < self.opacity_cutoff && segments < MAX_SEGMENTS {
            segments += 1;
            stats.descents += 1;
            let p = origin + direction * t;
            let level = self.level_at(t, spread);
            let (data, box_level, box_ijk) = self.descend(p, level.ceil() as u32, path, request);
            let node_size = 1.0 / self.scale[box_level as usize];
            let lower = DVec3::new(box_ijk[0] as f64, box_ijk[1] as f64, box_ijk[2] as f64) * node_size;
            let t_exit = exit_distance(origin, inverse_direction, lower, node_size).min(t_leave);
            // Never stall on a boundary: move at least a sliver of the node, and more than the rounding of p.
            let t_exit = t_exit.max(t + (node_size * 1e-7 + 8e-16 * p.abs().max_element()) / speed + 8e-16 * t);
            match data {
                SegmentData::Nothing => {}
                SegmentData::Constant(value) => {
                    stats.samples += 1;
                    let entry = self.lut.lookup(value);
                    if entry.sigma > 0.0 {
                        let alpha = 1.0 - (-(entry.sigma as f64) * (t_exit - t)).exp() as f32;
                        for c in 0..3 {
                            color[c] += transmittance * alpha * entry.color[c];
                        }
                        transmittance *= 1.0 - alpha;
                    }
                }
                SegmentData::Bricks { fine, coarse, blend_level } => {
                    // Empty-space skipping: nothing in the bricks (fine, and coarse if blended) is visible.
                    let [mut lo, mut hi] = self.view.brick_range(fine.slot);
                    if let (true, Some(c)) = (blend_level, coarse) {
                        let [clo, chi] = self.view.brick_range(c.slot);
                        lo = lo.min(clo);
                        hi = hi.max(chi);
                    }
                    if !self.lut.is_visible_in(lo, hi) {
                        t = t_exit;
                        continue;
                    }
                    // Step by the cone's footprint (the voxel of the continuous level ℓ), or by the sampled voxel
                    // where the data is coarser: a quadrilinear sample is filtered at the footprint, so finer steps
                    // would only re-sample the same filtered signal (GigaVoxels [P09] §6, cone tracing).
                    let sampled_voxel = 1.0 / (self.scale[fine.level as usize] * self.brick_size);
                    let footprint_voxel = (-level * self.ln_n).exp() / self.brick_size;
                    let voxel = sampled_voxel.max(footprint_voxel);
                    let length = t_exit - t;
                    let steps = (length * speed / (voxel * self.step_factor)).ceil().max(1.0);
                    let dt = length / steps;
                    let dt_world = dt;
                    let fine_brick = self.view.brick(fine.slot);
                    let shaded = self.shading == Shading::Phong;
                    // Brick coordinates are linear in t along the segment: x(t) = start + t·rate.
                    let (fine_start, fine_rate) = self.brick_line(origin, direction, &fine);
                    // The level changes by ~1% of a level across one node: one blend weight per segment.
                    let coarse_brick = coarse.filter(|_| blend_level).and_then(|c| {
                        let weight =
                            (self.level_at(0.5 * (t + t_exit), spread) - c.level as f64).clamp(0.0, 1.0) as f32;
                        (weight < 1.0)
                            .then(|| (self.view.brick(c.slot), self.brick_line(origin, direction, &c), weight))
                    });
                    let sigma_scale = -(dt_world as f32);
                    let blocks = self.view.shape.blocks_per_axis();
                    // The (fine, coarse) occupancy blocks of the previous sample, packed; visibility is checked on change.
                    let mut last_blocks = usize::MAX;
                    let mut step = 0u64;
                    let steps = steps as u64;
                    while step < steps {
                        let ts = t + (step as f64 + 0.5) * dt;
                        let x_fine = at(fine_start, fine_rate, ts);
                        // Occupancy blocks: skip the run of samples inside a block the transfer function hides.
                        let fine_cell = Cell::locate(self.stored, x_fine);
                        let fine_block = fine_cell.block(blocks);
                        let coarse_cell =
                            coarse_brick.map(|(_, (start, rate), _)| Cell::locate(self.stored, at(start, rate, ts)));
                        let coarse_block = coarse_cell.map(|c| c.block(blocks));
                        let blocks_here = fine_block ^ coarse_block.map_or(0, |c| c << 32);
                        if blocks_here != last_blocks {
                            last_blocks = blocks_here;
                            let [mut lo, mut hi] = self.view.block_range(fine.slot, fine_block);
                            if let (Some(c), Some(cb)) = (coarse, coarse_block) {
                                let [clo, chi] = self.view.block_range(c.slot, cb);
                                lo = lo.min(clo);
                                hi = hi.max(chi);
                            }
                            if !self.lut.is_visible_in(lo, hi) {
                                let mut exit = block_exit(fine_start, fine_rate, fine_block, blocks);
                                if let (Some((_, (start, rate), _)), Some(cb)) = (coarse_brick, coarse_block) {
                                    exit = exit.min(block_exit(start, rate, cb, blocks));
                                }
                                // Every sample before `exit` (less a margin above f32 rounding) is in the block.
                                let next = ((exit - 1e-3 * dt - t) / dt - 0.5).ceil();
                                step = if next > step as f64 { (next as u64).min(steps) } else { step + 1 };
                                continue;
                            }
                        }
                        step += 1;
                        let (mut value, g) = if shaded {
                            fine_cell.value_and_gradient(fine_brick, self.stored)
                        } else {
                            (fine_cell.value(fine_brick, self.stored), [0.0; 3])
                        };
                        if let (Some((brick, _, weight)), Some(cell)) = (coarse_brick, coarse_cell) {
                            let v_coarse = cell.value(brick, self.stored);
                            value = v_coarse + (value - v_coarse) * weight;
                        }
                        stats.samples += 1;
                        let entry = self.lut.lookup(value);
                        if entry.sigma <= 0.0 {
                            continue;
                        }
                        let alpha = 1.0 - (entry.sigma * sigma_scale).exp();
                        let mut sample_color = entry.color;
                        if shaded {
                            let g = [0, 1, 2].map(|a| g[a] * self.gradient_scale[a]);
                            sample_color = self.phong_shade(entry.color, g, light, -world_direction);
                        }
                        for c in 0..3 {
                            color[c] += transmittance * alpha * sample_color[c];
                        }
                        transmittance *= 1.0 - alpha;
                        if 1.0 - transmittance >= self.opacity_cutoff {
                            break;
                        }
                    }
                }
            }
            t = t_exit;
        }
        (color, 1.0 - transmittance)
    }

    /// The continuous voxel index in the brick of `node` along the ray, as `start + t·rate` per axis.
    #[inline]
    fn brick_line(&self, origin: DVec3, direction: DVec3, node: &BrickRef) -> ([f64; 3], [f64; 3]) {
        let s = self.scale[node.level as usize];
        let m = self.brick_size;
        let (o, d) = (origin.to_array(), direction.to_array());
        (std::array::from_fn(|a| (o[a] * s - node.ijk[a] as f64) * m + 0.5), std::array::from_fn(|a| d[a] * s * m))
    }

    /// Descends towards `target_level` at `p`, restarting from the deepest node of the previous descent that still
    /// contains `p` (the root at worst, which is GigaVoxels' kd-restart); returns the data to use and the box of the
    /// deepest node visited (the segment to march).
    fn descend(
        &self,
        p: DVec3,
        target_level: u32,
        path: &mut DescentPath,
        request: &mut RequestSink<'_>,
    ) -> (SegmentData, u32, [u64; 3]) {
        let n = self.n;
        let pa = [p.x, p.y, p.z];
        // Keep the ancestors that contain p, and no deeper than the target.
        let mut keep = path.len.min(target_level as usize + 1).max(1);
        while keep > 1 {
            let entry = &path.entries[keep - 1];
            let s = self.scale[keep - 1];
            if (0..3).all(|a| (pa[a] * s) as u64 == entry.ijk[a]) {
                break;
            }
            keep -= 1;
        }
        path.len = keep;
        loop {
            let level = (path.len - 1) as u32;
            let PathEntry { id, node, ijk } = path.entries[path.len - 1];
            match node.data() {
                NodeData::Constant(value) => return (SegmentData::Constant(value), level, ijk),
                NodeData::Brick(_) => {}
                NodeData::Missing => {
                    request.push(Request { node: id, kind: RequestKind::Produce });
                    break;
                }
            }
            if level >= target_level || node.is_terminal() {
                break;
            }
            let Some(tile) = node.child_tile() else {
                request.push(Request { node: id, kind: RequestKind::Subdivide });
                break;
            };
            self.feedback.mark_tile(tile);
            let s = self.scale[level as usize + 1];
            let mut child_ijk = [0u64; 3];
            let mut child_index = 0u64;
            let mut stride = 1u64;
            for a in 0..3 {
                let lo = ijk[a] * n;
                // Positions are non-negative, so truncation is floor.
                let g = ((pa[a] * s) as u64).clamp(lo, lo + n - 1);
                child_ijk[a] = g;
                child_index += (g - lo) * stride;
                stride *= n;
            }
            let (child_id, child) = self.view.child(tile, child_index as u32);
            if let Some(slot) = child.brick() {
                self.feedback.mark_brick(slot);
            }
            path.entries[path.len] = PathEntry { id: child_id, node: child, ijk: child_ijk };
            path.len += 1;
        }
        // Every node on the path but the last holds a brick; find the two deepest bricks.
        let deepest = path.len - 1;
        let last = path.entries[deepest];
        let brick_at = |level: usize| {
            path.entries[level].node.brick().map(|slot| BrickRef {
                slot,
                level: level as u32,
                ijk: path.entries[level].ijk,
            })
        };
        let fine_level = if last.node.brick().is_some() { Some(deepest) } else { deepest.checked_sub(1) };
        let data = match fine_level.and_then(|l| brick_at(l).map(|b| (l, b))) {
            None => SegmentData::Nothing,
            Some((l, fine)) => SegmentData::Bricks {
                fine,
                coarse: l.checked_sub(1).and_then(brick_at),
                // Blend with the parent only when the finest data is at the level the cone asked for.
                blend_level: fine.level == target_level,
            },
        };
        (data, deepest as u32, last.ijk)
    }

    /// Two-sided Phong with the density gradient as normal.
    #[inline]
    fn phong_shade(&self, color: [f32; 3], g: [f32; 3], light: DVec3, view: DVec3) -> [f32; 3] {
        let length = (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt();
        if length < 1e-6 {
            return color.map(|c| c * (self.phong.ambient + self.phong.diffuse));
        }
        // The normal points away from denser material.
        let normal = DVec3::new(-g[0] as f64, -g[1] as f64, -g[2] as f64) / length as f64;
        let diffuse = normal.dot(light).abs() as f32;
        let half = (light + view).normalize_or_zero();
        let specular = power(normal.dot(half).abs() as f32, self.phong.shininess);
        color.map(|c| c * (self.phong.ambient + self.phong.diffuse * diffuse) + self.phong.specular * specular)
    }
}

/// `base^exponent`, by repeated squaring when the exponent is a small whole number (the usual Phong case).
#[inline]
fn power(base: f32, exponent: f32) -> f32 {
    if exponent == exponent.trunc() && (0.0..=64.0).contains(&exponent) {
        let mut result = 1.0;
        let mut b = base;
        let mut e = exponent as u32;
        while e > 0 {
            if e & 1 == 1 {
                result *= b;
            }
            b *= b;
            e >>= 1;
        }
        result
    } else {
        base.powf(exponent)
    }
}

/// Where a ray's requests go, with its remaining allowance for this frame.
struct RequestSink<'v> {
    requests: &'v mut Vec<Request>,
    remaining: u32,
}

impl RequestSink<'_> {
    #[inline]
    fn push(&mut self, request: Request) {
        if self.remaining > 0 {
            self.remaining -= 1;
            self.requests.push(request);
        }
    }
}

/// A point of a brick line at distance `t`.
#[inline]
fn at(start: [f64; 3], rate: [f64; 3], t: f64) -> [f32; 3] {
    [(start[0] + rate[0] * t) as f32, (start[1] + rate[1] * t) as f32, (start[2] + rate[2] * t) as f32]
}

/// The `t` at which the line `start + t·rate` (continuous voxel index of a brick) leaves occupancy block `block`.
#[inline]
fn block_exit(start: [f64; 3], rate: [f64; 3], block: usize, blocks: usize) -> f64 {
    let ijk = [block % blocks, block / blocks % blocks, block / (blocks * blocks)];
    let mut exit = f64::INFINITY;
    for a in 0..3 {
        let edge = if rate[a] > 0.0 {
            ((ijk[a] + 1) * BLOCK_CELLS) as f64
        } else if rate[a] < 0.0 {
            (ijk[a] * BLOCK_CELLS) as f64
        } else {
            continue;
        };
        exit = exit.min((edge - start[a]) / rate[a]);
    }
    exit
}

/// Distance at which a ray inside (or on) the cube `[lower, lower + size]` leaves it; `1/direction` precomputed.
#[inline]
fn exit_distance(origin: DVec3, inverse_direction: DVec3, lower: DVec3, size: f64) -> f64 {
    let mut exit = f64::INFINITY;
    for a in 0..3 {
        let inv = inverse_direction[a];
        if inv.is_finite() {
            let bound = if inv > 0.0 { lower[a] + size } else { lower[a] };
            exit = exit.min((bound - origin[a]) * inv);
        }
    }
    exit
}

/// Slab test against the box `[lower, upper]`; returns `(t_enter, t_exit)` when hit ahead.
#[inline]
pub fn intersect_aabb(origin: DVec3, direction: DVec3, lower: DVec3, upper: DVec3) -> Option<(f64, f64)> {
    let size = upper - lower;
    // Scale to a unit cube so one slab test serves both.
    let o = (origin - lower) / size;
    let d = direction / size;
    intersect_box(o, d, DVec3::ZERO, 1.0)
}

/// Slab test against the axis-aligned cube `[lower, lower + size]`; returns `(t_enter, t_exit)` when hit ahead.
#[inline]
pub fn intersect_box(origin: DVec3, direction: DVec3, lower: DVec3, size: f64) -> Option<(f64, f64)> {
    let upper = lower + DVec3::splat(size);
    let mut t0 = f64::NEG_INFINITY;
    let mut t1 = f64::INFINITY;
    for a in 0..3 {
        let (o, d) = (origin[a], direction[a]);
        if d == 0.0 {
            if o < lower[a] || o > upper[a] {
                return None;
            }
            continue;
        }
        let inv = 1.0 / d;
        let (mut near, mut far) = ((lower[a] - o) * inv, (upper[a] - o) * inv);
        if near > far {
            std::mem::swap(&mut near, &mut far);
        }
        t0 = t0.max(near);
        t1 = t1.min(far);
    }
    (t1 >= t0.max(0.0)).then_some((t0, t1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exit_distance_matches_the_slab_test() {
        let origin = DVec3::new(0.3, 0.2, 0.9);
        let direction = DVec3::new(0.5, -0.3, 0.2).normalize();
        let (_, exit) = intersect_box(origin, direction, DVec3::ZERO, 1.0).unwrap();
        assert!((exit_distance(origin, DVec3::ONE / direction, DVec3::ZERO, 1.0) - exit).abs() < 1e-12);
        let axis = DVec3::new(0.0, 0.0, -1.0);
        assert!((exit_distance(origin, DVec3::ONE / axis, DVec3::ZERO, 1.0) - 0.9).abs() < 1e-12);
    }

    #[test]
    fn power_matches_powf() {
        for (b, e) in [(0.5f32, 16.0f32), (0.9, 3.0), (0.7, 2.5), (0.0, 0.0)] {
            assert!((power(b, e) - b.powf(e)).abs() < 1e-6);
        }
    }

    #[test]
    fn box_intersection() {
        let hit = intersect_box(DVec3::new(-1.0, 0.5, 0.5), DVec3::X, DVec3::ZERO, 1.0).unwrap();
        assert_eq!(hit, (1.0, 2.0));
        assert!(intersect_box(DVec3::new(-1.0, 2.0, 0.5), DVec3::X, DVec3::ZERO, 1.0).is_none());
        assert!(intersect_box(DVec3::new(2.0, 0.5, 0.5), DVec3::X, DVec3::ZERO, 1.0).is_none(), "box behind");
        let inside = intersect_box(DVec3::splat(0.5), DVec3::Y, DVec3::ZERO, 1.0).unwrap();
        assert_eq!(inside.1, 0.5);
    }
}
