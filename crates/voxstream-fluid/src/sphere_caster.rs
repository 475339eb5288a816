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

use crate::bit_brick::{span_mask, BitBrick};
use crate::grid::{BrickKey, FluidGrid, BRICK};

/// Largest jitter of a sphere's centre from its cell's centre, per axis, in cells.
pub const JITTER: f64 = 0.25;

/// Resident bricks, as the caster sees them.
pub trait Bricks: Sync {
    /// The brick if it is made.
    fn get(&self, key: BrickKey) -> Option<&BitBrick>;
    /// Whether the brick holds particles (it is worth asking for).
    fn is_occupied(&self, key: BrickKey) -> bool;
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

/// Entry and exit of the ray with a box, clipped to `t ≥ 0`.
#[inline]
fn box_span(origin: DVec3, inverse: DVec3, lower: DVec3, upper: DVec3) -> Option<(f64, f64)> {
    let a = (lower - origin) * inverse;
    let b = (upper - origin) * inverse;
    let near = a.min(b).max_element().max(0.0);
    let far = a.max(b).min_element();
    (near < far).then_some((near, far))
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
        let inverse = dir.recip();
        let (lower, upper) = grid.world_box();
        let Some((mut t, t_end)) = box_span(origin, inverse, lower.into(), upper.into()) else {
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
            let level = if footprint > finest {
                ((footprint / finest).log2().floor() as u8).min(grid.levels - 1)
            } else {
                0
            };
            let p = origin + dir * t;
            let edge = grid.cell_size(level) * BRICK as f64;
            let bricks = grid.bricks(level);
            let at: [u32; 3] = std::array::from_fn(|a| {
                let c = ((p[a] - grid.origin[a]) / edge).floor().max(0.0) as u32;
                c.min(bricks[a] - 1)
            });
            let key = BrickKey { level, at };
            let (bl, bu) = grid.brick_box(key);
            let exit = box_span(origin, inverse, bl.into(), bu.into()).map_or(t, |s| s.1);
            // Guard against a brick the ray only grazes: always move forward.
            let exit = exit.max(t + edge * 1e-9).min(t_end);
            if self.bricks.is_occupied(key) {
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
        let mut c = start.floor().as_ivec3().clamp(glam::IVec3::ZERO, glam::IVec3::splat(BRICK as i32 - 1));
        let step = dir.signum().as_ivec3();
        let delta = (cell / dir.abs()).to_array();
        let mut next = [0.0f64; 3];
        for a in 0..3 {
            next[a] = if dir[a] > 0.0 {
                t + ((f64::from(c[a] + 1)) - start[a]) * delta[a]
            } else if dir[a] < 0.0 {
                t + (start[a] - f64::from(c[a])) * delta[a]
            } else {
                f64::INFINITY
            };
        }
        let mut walk = Walk { brick, neighbours: [None; 27] };
        walk.neighbours[13] = Some(Some(brick));
        let mut t_cell = t;
        let extinction = self.settings.foam_extinction;
        loop {
            let a = if next[0] < next[1] { if next[0] < next[2] { 0 } else { 2 } } else if next[1] < next[2] { 1 } else { 2 };
            let t_out = next[a].min(t_exit);
            let [x, y, z] = c.to_array().map(|v| v as usize);
            if brick.is_near(x, y, z) {
                let f = brick.foam_at(x, y, z);
                if f > 0 && *foam < 0.99 {
                    let density = f64::from(f) / 64.0;
                    *foam += (1.0 - *foam) * (1.0 - (-extinction * density * (t_out - t_cell)).exp());
                }
                self.test_spheres(&mut walk, c.to_array(), origin, dir, radius, reach, best, requests);
                if best.is_some_and(|hit| hit.t <= t_out) {
                    return true;
                }
            }
            if next[a] >= t_exit {
                break;
            }
            t_cell = next[a];
            c[a] += step[a];
            if !(0..BRICK as i32).contains(&c[a]) {
                break;
            }
            next[a] += delta[a];
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
        for dz in -reach..=reach {
            for dy in -reach..=reach {
                let (y, z) = (c[1] + dy, c[2] + dz);
                let (by, bz) = (y.div_euclid(n), z.div_euclid(n));
                // The x window may span three bricks.
                for bx in (c[0] - reach).div_euclid(n)..=(c[0] + reach).div_euclid(n) {
                    let Some(source) = self.neighbour(walk, [bx, by, bz], requests) else { continue };
                    let offset = bx * n;
                    let word = source.surface[(y.rem_euclid(n) + n * z.rem_euclid(n)) as usize];
                    let mut bits = word & span_mask(c[0] - reach - offset, c[0] + reach - offset);
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
