//! The fluid's brick traverser: sphere ray casting from the bits (Reichl §6.5, §6.5.1, §6.5.2).
//!
//! A ray walks the grid front to back a brick at a time, at the level of detail whose cells are no larger than its
//! cone's footprint (GigaVoxels' screen-space error, `lod_error` pixels). In a brick it walks the cells with a 3D
//! DDA; a cell outside the brick's `near` mask holds no sphere's surface and is stepped over, and in a cell inside
//! it the ray is intersected with the spheres of every set cell within the reach (the thesis' "search, then
//! intersect": the set bits of the neighbourhood are gathered a row word at a time, then each is tested). Every
//! surface point lies in exactly one cell, and every sphere that can reach a cell is tested there, so the first
//! cell whose tests give a hit before the cell's exit holds the nearest hit. Foam blocks in front of the surface
//! add to a translucent foam opacity as the ray crosses them.
//!
//! Spheres sit at cell centres moved by a jitter that a hash of the cell, its level and the time step gives (the
//! thesis hashes with TEA; any good integer hash does), up to [`JITTER`] of a cell per axis: it breaks the grid's
//! regular look at no memory cost, and bounds how far a sphere reaches beyond its cell. A cell of a coarser level
//! stands for every particle in its `2^L`-cube and is drawn as a larger sphere ([`level_radius`]).
//!
//! A brick the ray needs that is not made yet is reported (the ray-guided request of §6.4.1); the ray goes on
//! through the nearest coarser brick that is made, or skips the brick, and the frame is marked incomplete.

use glam::DVec3;
use voxstream_render::traversal::intersect_aabb;

use crate::bit_brick::{span_mask, BitBrick, COARSE_BLOCK, SKIP_BLOCK};
use crate::grid::{BrickKey, FluidGrid, BRICK};

/// Largest jitter of a sphere's centre from its cell's centre, per axis, in cells.
pub const JITTER: f64 = 0.25;

/// Resident bricks, as the caster sees them.
pub trait Bricks: Sync {
    /// The brick if it is made.
    fn get(&self, key: BrickKey) -> Option<&BitBrick>;
    /// Whether the brick holds particles.
    fn is_occupied(&self, key: BrickKey) -> bool;
    /// Whether a sphere may reach into the brick (it or a neighbour holds particles): rays walk it.
    fn is_reached(&self, key: BrickKey) -> bool;
}

/// What the caster needs to know.
#[derive(Clone, Copy, Debug)]
pub struct CastSettings {
    /// The grid.
    pub grid: FluidGrid,
    /// Sphere radius at level 0, world units.
    pub radius: f64,
    /// Largest allowed footprint of a cell, in pixels (1: a cell no larger than a pixel).
    pub lod_error: f64,
    /// Time step (seeds the jitter).
    pub time_step: u32,
    /// Foam opacity per world unit at a fully foamed block.
    pub foam_extinction: f64,
}

/// A sphere's radius and reach (cells per axis a ray tests around its cell) at `level`: level 0 draws the
/// particles' own radius; a coarser cell is drawn at least ¾ of its edge across, so that a set cell covers it.
pub fn level_radius(grid: &FluidGrid, radius: f64, level: u8) -> (f64, i32) {
    let cell = grid.cell_size(level);
    let r = if level == 0 { radius } else { radius.max(0.75 * cell) };
    // A sphere of a cell `d` cells away (its centre within ½ + JITTER of its cell's centre) reaches this cell when
    // (|d| − ½ − JITTER)·cell ≤ r.
    let reach = (0.5 + JITTER + r / cell).floor() as i32;
    (r, reach.max(1))
}

/// What one ray found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RaySample {
    /// Distance along the ray to the surface, `f64::INFINITY` if none.
    pub t: f64,
    /// Unit normal of the sphere hit (world).
    pub normal: [f32; 3],
    /// Opacity of the foam in front of the surface (or along the whole ray).
    pub foam: f32,
    /// Level of detail of the brick hit.
    pub level: u8,
}

impl RaySample {
    /// Nothing on this ray.
    pub const MISS: RaySample = RaySample { t: f64::INFINITY, normal: [0.0; 3], foam: 0.0, level: 0 };
}

/// A 32-bit integer hash (a finaliser of Murmur3's shape).
#[inline]
fn hash(mut h: u32) -> u32 {
    h ^= h >> 16;
    h = h.wrapping_mul(0x7feb_352d);
    h ^= h >> 15;
    h = h.wrapping_mul(0x846c_a68b);
    h ^ (h >> 16)
}

/// The jitter of a cell's sphere, in cells, each axis in `[−JITTER, JITTER]`.
#[inline]
pub fn jitter(global: [i64; 3], level: u8, time_step: u32) -> DVec3 {
    let seed = hash(
        (global[0] as u32).wrapping_mul(73_856_093)
            ^ (global[1] as u32).wrapping_mul(19_349_663)
            ^ (global[2] as u32).wrapping_mul(83_492_791)
            ^ u32::from(level).wrapping_mul(2_654_435_761)
            ^ time_step.wrapping_mul(0x9e37_79b9),
    );
    let a = hash(seed);
    let b = hash(a);
    let c = hash(b);
    let unit = |v: u32| (f64::from(v) / f64::from(u32::MAX)) * 2.0 - 1.0;
    DVec3::new(unit(a), unit(b), unit(c)) * JITTER
}

/// Entry (clipped to `t ≥ 0`) and exit of the ray with a box: the renderer's slab test.
#[inline]
fn box_span(origin: DVec3, dir: DVec3, lower: DVec3, upper: DVec3) -> Option<(f64, f64)> {
    intersect_aabb(origin, dir, lower, upper).map(|(near, far)| (near.max(0.0), far))
}

/// First entry of the ray into a sphere, `None` if it misses or the sphere is behind.
#[inline]
fn sphere_entry(origin: DVec3, dir: DVec3, centre: DVec3, r: f64) -> Option<f64> {
    let oc = origin - centre;
    let b = oc.dot(dir);
    let c = oc.length_squared() - r * r;
    let disc = b * b - c;
    if disc < 0.0 {
        return None;
    }
    let root = disc.sqrt();
    let t = -b - root;
    if t >= 0.0 {
        Some(t)
    } else if -b + root >= 0.0 {
        // The origin is inside the sphere: the surface is where the ray starts.
        Some(0.0)
    } else {
        None
    }
}

/// The nearest sphere entry found so far.
#[derive(Clone, Copy, Debug)]
struct Hit {
    t: f64,
    centre: DVec3,
    radius: f64,
    level: u8,
}

impl Hit {
    fn sample(self, origin: DVec3, dir: DVec3, foam: f64) -> RaySample {
        let n = ((origin + dir * self.t - self.centre) / self.radius).normalize_or_zero();
        RaySample { t: self.t, normal: n.to_array().map(|v| v as f32), foam: foam as f32, level: self.level }
    }
}

/// A 3D DDA over the cells of one brick (Amanatides and Woo), with whole aligned blocks skipped in one step.
struct Dda {
    /// Current cell.
    c: [i32; 3],
    /// Ray distance to the next cell boundary per axis.
    next: [f64; 3],
    /// Ray distance across one cell per axis.
    delta: [f64; 3],
    /// Direction of travel per axis.
    step: [i32; 3],
}

impl Dda {
    /// Starts at `start` (brick cell units) at ray distance `t`.
    #[inline]
    fn new(start: DVec3, dir: DVec3, cell: f64, t: f64) -> Dda {
        let c = start.floor().as_ivec3().clamp(glam::IVec3::ZERO, glam::IVec3::splat(BRICK as i32 - 1));
        let step = dir.signum().as_ivec3().to_array();
        let delta = (cell / dir.abs()).to_array();
        let next = std::array::from_fn(|a| {
            if dir[a] > 0.0 {
                t + (f64::from(c[a] + 1) - start[a]) * delta[a]
            } else if dir[a] < 0.0 {
                t + (start[a] - f64::from(c[a])) * delta[a]
            } else {
                f64::INFINITY
            }
        });
        Dda { c: c.to_array(), next, delta, step }
    }

    /// The axis whose boundary the ray crosses next.
    #[inline]
    fn axis(&self) -> usize {
        let n = &self.next;
        if n[0] < n[1] {
            if n[0] < n[2] {
                0
            } else {
                2
            }
        } else if n[1] < n[2] {
            1
        } else {
            2
        }
    }

    /// Steps one cell along `a`; false when it leaves the brick.
    #[inline]
    fn advance(&mut self, a: usize) -> bool {
        self.c[a] += self.step[a];
        self.next[a] += self.delta[a];
        (0..BRICK as i32).contains(&self.c[a])
    }

    /// Cells to the far side of the aligned block of `size` along each axis, and the distances there.
    #[inline]
    fn block_crossings(&self, size: i32) -> ([i32; 3], [f64; 3]) {
        let mut cells = [0i32; 3];
        let mut crossing = [0.0f64; 3];
        for a in 0..3 {
            let within = self.c[a] & (size - 1);
            cells[a] = if self.step[a] > 0 { size - within } else { within + 1 };
            crossing[a] = self.next[a] + f64::from(cells[a] - 1) * self.delta[a];
        }
        (cells, crossing)
    }

    /// Ray distance where it leaves the aligned block of `size` holding the current cell.
    #[inline]
    fn block_exit(&self, size: i32) -> f64 {
        let (_, crossing) = self.block_crossings(size);
        crossing[0].min(crossing[1]).min(crossing[2])
    }

    /// Moves to the first cell past the aligned block of `size` (a power of two) holding the current one; the
    /// distance there, or `None` when that is past `t_exit` or outside the brick.
    #[inline]
    fn skip_block(&mut self, size: i32, t_exit: f64) -> Option<f64> {
        let (cells, crossing) = self.block_crossings(size);
        let a = if crossing[0] < crossing[1] {
            if crossing[0] < crossing[2] {
                0
            } else {
                2
            }
        } else if crossing[1] < crossing[2] {
            1
        } else {
            2
        };
        let t = crossing[a];
        if t >= t_exit {
            return None;
        }
        for b in 0..3 {
            if b != a && self.next[b] <= t {
                // The boundaries along `b` the ray crosses before `t`, at once (then exactly, by steps).
                let k = ((t - self.next[b]) / self.delta[b]).floor() as i32;
                self.c[b] += k * self.step[b];
                self.next[b] += f64::from(k) * self.delta[b];
                while self.next[b] <= t {
                    self.c[b] += self.step[b];
                    self.next[b] += self.delta[b];
                }
            }
        }
        self.c[a] += cells[a] * self.step[a];
        self.next[a] = t + self.delta[a];
        self.c.iter().all(|v| (0..BRICK as i32).contains(v)).then_some(t)
    }
}

/// One brick being walked, with its neighbours looked up once.
struct Walk<'a> {
    brick: &'a BitBrick,
    /// Neighbours by offset `(dx + 1) + 3·(dy + 1) + 9·(dz + 1)`: `None` not looked up yet, `Some(None)` absent.
    neighbours: [Option<Option<&'a BitBrick>>; 27],
}

/// Casts rays into the resident bricks.
pub struct SphereCaster<'a, B: Bricks> {
    settings: CastSettings,
    bricks: &'a B,
    /// Per level: sphere radius and reach.
    levels: Vec<(f64, i32)>,
}

impl<'a, B: Bricks> SphereCaster<'a, B> {
    /// A caster over `bricks`.
    pub fn new(settings: CastSettings, bricks: &'a B) -> Self {
        let levels = (0..settings.grid.levels).map(|l| level_radius(&settings.grid, settings.radius, l)).collect();
        SphereCaster { settings, bricks, levels }
    }

    /// Casts one ray (`dir` of unit length); `spread` is the cone's width per unit distance (one pixel's). Bricks
    /// the ray needs that are not made are pushed to `requests`.
    pub fn cast(&self, origin: DVec3, dir: DVec3, spread: f64, requests: &mut Vec<BrickKey>) -> RaySample {
        let grid = &self.settings.grid;
        let (lower, upper) = grid.world_box();
        let Some((mut t, t_end)) = box_span(origin, dir, lower.into(), upper.into()) else {
            return RaySample::MISS;
        };
        let mut foam = 0.0f64;
        // A hit found beyond the part of the ray a brick covered (a sphere reaching out of its brick): it stands
        // unless a brick walked later finds a nearer one.
        let mut best: Option<Hit> = None;
        let finest = f64::from(grid.cell as f32);
        while t < t_end {
            if let Some(hit) = best.filter(|h| h.t <= t) {
                return hit.sample(origin, dir, foam);
            }
            // Level: the coarsest whose cells fit the footprint here.
            let footprint = (t * spread * self.settings.lod_error).max(0.0);
            let level =
                if footprint > finest { ((footprint / finest).log2().floor() as u8).min(grid.levels - 1) } else { 0 };
            let p = origin + dir * t;
            let edge = grid.cell_size(level) * BRICK as f64;
            let bricks = grid.bricks(level);
            let at: [u32; 3] = std::array::from_fn(|a| {
                let c = ((p[a] - grid.origin[a]) / edge).floor().max(0.0) as u32;
                c.min(bricks[a] - 1)
            });
            let key = BrickKey { level, at };
            let (bl, bu) = grid.brick_box(key);
            let exit = box_span(origin, dir, bl.into(), bu.into()).map_or(t, |s| s.1);
            // Guard against a brick the ray only grazes: always move forward.
            let exit = exit.max(t + edge * 1e-9).min(t_end);
            if self.bricks.is_reached(key) {
                let mut used = None;
                for l in level..grid.levels {
                    let k = key.ancestor(l);
                    if let Some(brick) = self.bricks.get(k) {
                        used = Some(brick);
                        break;
                    }
                    if l == level {
                        requests.push(k);
                    }
                }
                if let Some(brick) = used {
                    if self.walk_brick(brick, origin, dir, t, exit, &mut foam, &mut best, requests) {
                        return best.map_or(RaySample::MISS, |hit| hit.sample(origin, dir, foam));
                    }
                }
            }
            t = exit;
        }
        match best {
            Some(hit) => hit.sample(origin, dir, foam),
            None => RaySample { foam: foam as f32, ..RaySample::MISS },
        }
    }

    /// Walks `brick` from `t` to `t_exit`, keeping the nearest sphere entry in `best`; true when that entry is
    /// known to be the ray's first (it lies in a cell already walked). Foam crossed adds to `foam`.
    #[allow(clippy::too_many_arguments)]
    fn walk_brick(
        &self,
        brick: &'a BitBrick,
        origin: DVec3,
        dir: DVec3,
        t: f64,
        t_exit: f64,
        foam: &mut f64,
        best: &mut Option<Hit>,
        requests: &mut Vec<BrickKey>,
    ) -> bool {
        let grid = &self.settings.grid;
        let level = brick.key.level;
        let cell = grid.cell_size(level);
        let (lower, _) = grid.brick_box(brick.key);
        let lower = DVec3::from(lower);
        let (radius, reach) = self.levels[usize::from(level)];
        // The DDA in cell units of this brick.
        let start = (origin + dir * t - lower) / cell;
        let mut dda = Dda::new(start, dir, cell, t);
        let mut walk = Walk { brick, neighbours: [None; 27] };
        walk.neighbours[13] = Some(Some(brick));
        let mut t_cell = t;
        let extinction = self.settings.foam_extinction;
        let add_foam = |foam: &mut f64, count: u8, length: f64| {
            let density = f64::from(count) / 64.0;
            *foam += (1.0 - *foam) * (1.0 - (-extinction * density * length).exp());
        };
        loop {
            let [x, y, z] = dda.c.map(|v| v as usize);
            // Regions no sphere reaches and no foam fills: a coarse block, then a fine one, skipped whole.
            if !brick.is_coarse_block_busy(x / COARSE_BLOCK, y / COARSE_BLOCK, z / COARSE_BLOCK) {
                match dda.skip_block(COARSE_BLOCK as i32, t_exit) {
                    Some(t) => {
                        t_cell = t;
                        continue;
                    }
                    None => break,
                }
            }
            let [bx, by, bz] = [x / SKIP_BLOCK, y / SKIP_BLOCK, z / SKIP_BLOCK];
            let block_foam = brick.foam_in_block(bx, by, bz);
            if !brick.is_block_near(bx, by, bz) {
                let exit = dda.block_exit(SKIP_BLOCK as i32);
                if block_foam > 0 && *foam < 0.99 {
                    add_foam(foam, block_foam, exit.min(t_exit) - t_cell);
                }
                match dda.skip_block(SKIP_BLOCK as i32, t_exit) {
                    Some(t) => {
                        t_cell = t;
                        continue;
                    }
                    None => break,
                }
            }
            let a = dda.axis();
            let t_out = dda.next[a].min(t_exit);
            if block_foam > 0 && *foam < 0.99 {
                add_foam(foam, block_foam, t_out - t_cell);
            }
            if brick.is_near(x, y, z) {
                self.test_spheres(&mut walk, dda.c, origin, dir, radius, reach, best, requests);
                if best.is_some_and(|hit| hit.t <= t_out) {
                    return true;
                }
            }
            if dda.next[a] >= t_exit {
                break;
            }
            t_cell = dda.next[a];
            if !dda.advance(a) {
                break;
            }
        }
        false
    }

    /// Intersects the ray with the spheres of the set cells within `reach` of cell `c`.
    #[allow(clippy::too_many_arguments)]
    fn test_spheres(
        &self,
        walk: &mut Walk<'a>,
        c: [i32; 3],
        origin: DVec3,
        dir: DVec3,
        radius: f64,
        reach: i32,
        best: &mut Option<Hit>,
        requests: &mut Vec<BrickKey>,
    ) {
        let grid = &self.settings.grid;
        let brick = walk.brick;
        let level = brick.key.level;
        let cell = grid.cell_size(level);
        let n = BRICK as i32;
        let base: [i64; 3] = std::array::from_fn(|a| i64::from(brick.key.at[a]) * BRICK as i64);
        let mut test = |bits: u64, offset: i32, y: i32, z: i32| {
            let mut bits = bits;
            while bits != 0 {
                let x = bits.trailing_zeros() as i32 + offset;
                bits &= bits - 1;
                let global = [base[0] + i64::from(x), base[1] + i64::from(y), base[2] + i64::from(z)];
                let centre_cells = DVec3::new(global[0] as f64, global[1] as f64, global[2] as f64)
                    + 0.5
                    + jitter(global, level, self.settings.time_step);
                let centre = DVec3::from(grid.origin) + centre_cells * cell;
                if let Some(t) = sphere_entry(origin, dir, centre, radius) {
                    if best.is_none_or(|b| t < b.t) {
                        *best = Some(Hit { t, centre, radius, level });
                    }
                }
            }
        };
        if c.iter().all(|&v| v >= reach && v < n - reach) {
            // The whole neighbourhood is in this brick (most cells): its rows, masked.
            let mask = span_mask(c[0] - reach, c[0] + reach);
            for z in c[2] - reach..=c[2] + reach {
                for y in c[1] - reach..=c[1] + reach {
                    let bits = brick.surface[(y + n * z) as usize] & mask;
                    if bits != 0 {
                        test(bits, 0, y, z);
                    }
                }
            }
            return;
        }
        for dz in -reach..=reach {
            for dy in -reach..=reach {
                let (y, z) = (c[1] + dy, c[2] + dz);
                let (by, bz) = (y.div_euclid(n), z.div_euclid(n));
                // The x window may span three bricks.
                for bx in (c[0] - reach).div_euclid(n)..=(c[0] + reach).div_euclid(n) {
                    let Some(source) = self.neighbour(walk, [bx, by, bz], requests) else { continue };
                    let offset = bx * n;
                    let word = source.surface[(y.rem_euclid(n) + n * z.rem_euclid(n)) as usize];
                    let bits = word & span_mask(c[0] - reach - offset, c[0] + reach - offset);
                    if bits != 0 {
                        test(bits, offset, y, z);
                    }
                }
            }
        }
    }

    /// The brick at offset `d` (−1..=1 per axis) of the walked one, looked up once per walk; a missing one that
    /// holds particles is requested.
    fn neighbour(&self, walk: &mut Walk<'a>, d: [i32; 3], requests: &mut Vec<BrickKey>) -> Option<&'a BitBrick> {
        let index = ((d[0] + 1) + 3 * (d[1] + 1) + 9 * (d[2] + 1)) as usize;
        if let Some(found) = walk.neighbours[index] {
            return found;
        }
        let key = walk.brick.key;
        let bricks = self.settings.grid.bricks(key.level);
        let at: [i64; 3] = std::array::from_fn(|a| i64::from(key.at[a]) + i64::from(d[a]));
        let found = if (0..3).all(|a| at[a] >= 0 && at[a] < i64::from(bricks[a])) {
            let neighbour = BrickKey { level: key.level, at: at.map(|v| v as u32) };
            if self.bricks.is_occupied(neighbour) {
                let got = self.bricks.get(neighbour);
                if got.is_none() {
                    requests.push(neighbour);
                }
                got
            } else {
                None
            }
        } else {
            None
        };
        walk.neighbours[index] = Some(found);
        found
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::binning::{FluidBins, FluidSettings};
    use crate::bit_brick::BrickSettings;
    use std::collections::HashMap;
    use voxstream_geometry::{ParticleSet, RawParticles};

    struct All<'a> {
        bins: &'a FluidBins,
        made: HashMap<BrickKey, BitBrick>,
    }

    impl Bricks for All<'_> {
        fn get(&self, key: BrickKey) -> Option<&BitBrick> {
            self.made.get(&key)
        }
        fn is_occupied(&self, key: BrickKey) -> bool {
            self.bins.is_occupied(key)
        }
        fn is_reached(&self, key: BrickKey) -> bool {
            self.bins.is_reached(key)
        }
    }

    fn bins(positions: Vec<[f64; 3]>, radius: f64, cell: f64) -> FluidBins {
        let set = ParticleSet::new(RawParticles { positions, ..Default::default() }).unwrap();
        FluidBins::build(&set, FluidSettings { radius: Some(radius), cell: Some(cell) }, &mut |_| {}).unwrap()
    }

    /// Casts until no brick is asked for, making what is asked.
    fn cast(all: &mut All, settings: CastSettings, origin: DVec3, dir: DVec3) -> RaySample {
        loop {
            let mut requests = Vec::new();
            let sample = SphereCaster::new(settings, &*all).cast(origin, dir, 0.0, &mut requests);
            if requests.is_empty() {
                return sample;
            }
            for key in requests {
                let (_, reach) = level_radius(&all.bins.grid, all.bins.radius, key.level);
                all.made.insert(key, BitBrick::build(all.bins, key, BrickSettings { reach, foam_below: 0 }));
            }
        }
    }

    fn settings(bins: &FluidBins) -> CastSettings {
        CastSettings { grid: bins.grid, radius: bins.radius, lod_error: 1.0, time_step: 3, foam_extinction: 0.0 }
    }

    /// The sphere the caster draws for the particle at `p` (level 0).
    fn drawn_centre(bins: &FluidBins, p: [f64; 3], time_step: u32) -> DVec3 {
        let cell = bins.grid.cell_of(p).unwrap().map(i64::from);
        let c = DVec3::new(cell[0] as f64, cell[1] as f64, cell[2] as f64) + 0.5 + jitter(cell, 0, time_step);
        DVec3::from(bins.grid.origin) + c * bins.grid.cell
    }

    #[test]
    fn rays_hit_a_particles_sphere_where_the_sphere_is() {
        // Particles spread over several bricks; the ray towards each hits its sphere at the analytic entry.
        let positions: Vec<[f64; 3]> =
            (0..12).map(|i| [i as f64 * 7.3, (i % 3) as f64 * 5.1, (i % 5) as f64 * 3.7]).collect();
        let bins = bins(positions.clone(), 0.4, 0.4);
        let mut all = All { bins: &bins, made: HashMap::new() };
        let settings = settings(&bins);
        for (i, p) in positions.iter().enumerate() {
            let centre = drawn_centre(&bins, *p, 3);
            // From a point off to the side, aimed a little off the centre.
            let origin = centre + DVec3::new(-3.0, 40.0, 25.0);
            let aim = centre + DVec3::new(0.1, -0.15, 0.05);
            let dir = (aim - origin).normalize();
            let sample = cast(&mut all, settings, origin, dir);
            let expected = sphere_entry(origin, dir, centre, 0.4).unwrap();
            // Another particle's sphere may be in front only if on the way; these are far apart.
            assert!((sample.t - expected).abs() < 1e-9, "particle {i}: {} vs {expected}", sample.t);
            let n = DVec3::from(sample.normal.map(f64::from));
            let exact = (origin + dir * expected - centre).normalize();
            assert!((n - exact).length() < 1e-5);
        }
        // A ray that passes between them hits nothing.
        let miss = cast(&mut all, settings, DVec3::new(-100.0, -100.0, -100.0), DVec3::new(1.0, 0.0, 0.0));
        assert!(miss.t.is_infinite());
    }

    #[test]
    fn a_sphere_reaching_into_an_empty_brick_is_drawn_whole() {
        // One particle just inside the last cell of a brick along +x: its sphere reaches into the next brick,
        // which holds no particle. The grid's origin is at −(r + cell) = −2, so x = 61.9 is in cell 63.
        let positions = vec![[0.0, 5.5, 5.5], [61.9, 5.5, 5.5], [200.0, 5.5, 5.5]];
        let bins = bins(positions, 1.0, 1.0);
        let cell = bins.grid.cell_of([61.9, 5.5, 5.5]).unwrap();
        assert_eq!(cell[0], 63);
        assert!(!bins.is_occupied(BrickKey { level: 0, at: [1, 0, 0] }));
        let mut all = All { bins: &bins, made: HashMap::new() };
        let centre = drawn_centre(&bins, [61.9, 5.5, 5.5], 3);
        // A ray along −y through the part of the sphere beyond x = 62 (the face), from above.
        let face_x = bins.grid.origin[0] + 64.0;
        let x = face_x + 0.5 * (centre.x + 1.0 - face_x);
        assert!(x > face_x && x < centre.x + 1.0);
        let origin = DVec3::new(x, 30.0, centre.z);
        let dir = DVec3::new(0.0, -1.0, 0.0);
        let sample = cast(&mut all, settings(&bins), origin, dir);
        let expected = sphere_entry(origin, dir, centre, 1.0).expect("the ray crosses the sphere");
        assert!((sample.t - expected).abs() < 1e-9, "{} vs {expected}", sample.t);
    }

    #[test]
    fn a_brick_not_made_is_asked_for_and_a_coarser_one_stands_in() {
        let positions: Vec<[f64; 3]> =
            (0..200).map(|i| [(i % 10) as f64, (i / 10 % 10) as f64, (i / 100) as f64]).collect();
        let bins = bins(positions, 0.05, 0.05);
        assert!(bins.grid.levels >= 3);
        let origin = DVec3::new(4.0, 4.0, -30.0);
        let dir = DVec3::new(0.0, 0.0, 1.0);
        let coarse = BrickKey { level: bins.grid.levels - 1, at: [0, 0, 0] };
        let (_, reach) = level_radius(&bins.grid, bins.radius, coarse.level);
        let mut made = HashMap::new();
        made.insert(coarse, BitBrick::build(&bins, coarse, BrickSettings { reach, foam_below: 0 }));
        let all = All { bins: &bins, made };
        let mut requests = Vec::new();
        let sample = SphereCaster::new(settings(&bins), &all).cast(origin, dir, 0.0, &mut requests);
        assert!(!requests.is_empty() && requests.iter().all(|k| k.level == 0), "{requests:?}");
        assert_eq!(sample.level, coarse.level, "the coarse brick stood in");
        assert!(sample.t.is_finite());
        // The coarse sphere (radius ≥ ¾ of its cell) is hit no later than the fine ones would be, roughly.
        let mut all = all;
        let fine = cast(&mut all, settings(&bins), origin, dir);
        assert_eq!(fine.level, 0);
        assert!(sample.t <= fine.t + 1e-9, "{} {}", sample.t, fine.t);
    }

    #[test]
    fn rays_find_the_nearest_sphere_of_a_dense_cloud_across_brick_faces() {
        // A slab of particles straddling the faces between bricks, and random rays through it: the caster's hit
        // is the nearest entry into any particle's drawn sphere (brute force over all of them).
        let mut state = 12345u64;
        let mut random = || {
            state = state.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        // A dense slab (spacing 1.6, spheres of 0.7: rays stop within a few cells), the thickness along z broken by
        // random gaps so that rays also graze inside.
        let mut positions = Vec::new();
        for k in 0..4 {
            for j in 0..44 {
                for i in 0..50 {
                    if random() < 0.7 {
                        positions.push([i as f64 * 1.6 + random(), j as f64 * 1.6 + random(), 29.0 + k as f64 * 1.6]);
                    }
                }
            }
        }
        let bins = bins(positions.clone(), 0.7, 0.5);
        assert_eq!(bins.grid.bricks(0), [3, 3, 1]);
        let mut all = All { bins: &bins, made: HashMap::new() };
        let settings = settings(&bins);
        let centres: Vec<DVec3> = positions.iter().map(|p| drawn_centre(&bins, *p, 3)).collect();
        let mut hits = 0;
        for _ in 0..400 {
            // Grazing: from the side, low over the slab.
            let origin = DVec3::new(random() * 80.0, -30.0, 22.0 + random() * 4.0);
            // Near the faces between bricks (x, y ≈ 30.3 and 62.3 here) most of the time.
            let face = |r: f64| if r < 0.5 { 30.3 } else { 62.3 };
            let aim = DVec3::new(face(random()) + random() * 4.0 - 2.0, face(random()) + random() * 4.0 - 2.0, 31.0);
            let dir = (aim - origin).normalize();
            let sample = cast(&mut all, settings, origin, dir);
            let expected =
                centres.iter().filter_map(|&c| sphere_entry(origin, dir, c, 0.7)).fold(f64::INFINITY, f64::min);
            assert!(
                (sample.t == expected) || (sample.t - expected).abs() < 1e-9,
                "{origin:?} → {dir:?}: {} vs {expected}",
                sample.t
            );
            hits += usize::from(expected.is_finite());
        }
        assert!(hits > 300, "{hits}");
    }

    #[test]
    fn the_level_follows_the_footprint() {
        let bins = bins((0..100).map(|i| [i as f64 * 0.5, 0.0, 0.0]).collect(), 0.05, 0.05);
        let mut all = All { bins: &bins, made: HashMap::new() };
        let origin = DVec3::new(25.0, 0.0, -100.0);
        let dir = DVec3::new(0.0, 0.0, 1.0);
        // A footprint of 0.2 per unit at distance 100 is 20 units: cells of 0.05·2^L ≤ 20 → L = 8 or coarser.
        let mut settings = settings(&bins);
        settings.lod_error = 1.0;
        let sample = loop {
            let mut requests = Vec::new();
            let s = SphereCaster::new(settings, &all).cast(origin, dir, 0.2, &mut requests);
            if requests.is_empty() {
                break s;
            }
            for key in requests {
                let (_, reach) = level_radius(&bins.grid, bins.radius, key.level);
                all.made.insert(key, BitBrick::build(&bins, key, BrickSettings { reach, foam_below: 0 }));
            }
        };
        assert!(sample.t.is_finite());
        assert_eq!(sample.level, (bins.grid.levels - 1).min(8));
    }
}
