//! Ray casting the binary bricks (seed 004 §8.4.4): every pixel's ray steps voxel by voxel (Amanatides–Woo) through
//! the bricks it crosses, skipping absent bricks whole, until it enters a voxel behind the surface; the hit is
//! that voxel's cube, so the depth image is made of voxel faces. In views of the confident surface, where the voxel
//! and the one the ray came from keep surface offsets ([`crate::brick`]) that cross zero, the hit moves along the
//! ray to the crossing. (Not in the views tracking aligns to: there it made the trajectory worse, 2.8 → 4.8 mm ATE
//! on the bunny's orbit, see BENCHMARKS.md.) It is then smoothed in screen space by the
//! fluids' Rudin–Osher–Fatemi filter ([`voxstream_fluid::screen_space`], shared with ch. 6 as the thesis does), and
//! the smoothed depth is what is shaded and what tracking aligns new frames to (§8.2).

use glam::{DVec3, IVec3};
use rayon::prelude::*;
use voxstream_fluid::screen_space::{smooth_rof, DepthImage, RofSettings};

use crate::brick::{voxel_index, BinaryBrick, BRICK};
use crate::brick_map::BrickMap;
use crate::camera::{Intrinsics, Pose};

/// A rendered view of the fused surface.
#[derive(Clone, Debug, PartialEq)]
pub struct SurfaceView {
    pub intrinsics: Intrinsics,
    /// Depth along the optical axis, metres; 0 where the ray hit nothing.
    pub depth: Vec<f32>,
    /// The hit voxel's colour, where it has one.
    pub colour: Vec<Option<[u8; 3]>>,
}

/// Which voxels a ray stops at.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Surface {
    /// Confident voxels only: what saved scenes and final images show (§8.3.4).
    Confident,
    /// Every voxel behind the surface, also those only the sub-cache set: what tracking aligns to.
    Any,
}

/// Casts one ray from the camera (voxel units) and returns the camera depth of the first voxel behind the surface.
fn cast(map: &BrickMap, origin: DVec3, direction: DVec3, t_max: f64, surface: Surface) -> Option<(f64, IVec3)> {
    let voxel = map.voxel();
    let o = origin / voxel;
    let d = direction / voxel;
    let mut cell = o.floor().as_ivec3();
    let step = IVec3::new(sign(d.x), sign(d.y), sign(d.z));
    let inv = DVec3::new(1.0 / d.x, 1.0 / d.y, 1.0 / d.z);
    let boundary = |c: i32, s: i32, o: f64, inv: f64| {
        if s == 0 {
            f64::INFINITY
        } else {
            let next = if s > 0 { c + 1 } else { c } as f64;
            (next - o) * inv
        }
    };
    let mut t_next = DVec3::new(
        boundary(cell.x, step.x, o.x, inv.x),
        boundary(cell.y, step.y, o.y, inv.y),
        boundary(cell.z, step.z, o.z, inv.z),
    );
    let t_delta = DVec3::new(inv.x.abs(), inv.y.abs(), inv.z.abs());
    let mut t = 0.0f64;
    let mut current: Option<(IVec3, Option<&BinaryBrick>)> = None;
    // The axis of the last voxel step, while the ray walks voxel by voxel.
    let mut last_axis: Option<usize> = None;
    while t < t_max {
        let (key, local) = BrickMap::split(cell);
        let brick = match current {
            Some((k, b)) if k == key => b,
            _ => {
                let b = map.brick(key);
                current = Some((key, b));
                b
            }
        };
        match brick {
            Some(b) => {
                let i = voxel_index(local.x, local.y, local.z);
                let hit = b.inside.get(i) && (surface == Surface::Any || b.confident.get(i));
                if hit && t > 0.0 {
                    let t_hit = match last_axis {
                        Some(axis) if surface == Surface::Confident => {
                            t + crossing_shift(map, b, cell, local, axis, step) * t_delta[axis]
                        }
                        _ => t,
                    };
                    return Some((t_hit.max(0.0), cell));
                }
            }
            None => {
                // Jump to where the ray leaves this absent brick.
                let lo = (key * BRICK).as_dvec3();
                let hi = lo + DVec3::splat(f64::from(BRICK));
                let exit = [0, 1, 2]
                    .map(|a| {
                        if d[a] > 0.0 {
                            (hi[a] - o[a]) * inv[a]
                        } else if d[a] < 0.0 {
                            (lo[a] - o[a]) * inv[a]
                        } else {
                            f64::INFINITY
                        }
                    })
                    .into_iter()
                    .fold(f64::INFINITY, f64::min);
                // Re-enter the voxel walk just past the exit plane (1e-6 m further along the ray is a hundredth
                // of a voxel at the finest voxel allowed, and far above rounding).
                t = exit.max(t);
                last_axis = None;
                cell = (o + d * (t + 1e-6)).floor().as_ivec3();
                t_next = DVec3::new(
                    boundary(cell.x, step.x, o.x, inv.x),
                    boundary(cell.y, step.y, o.y, inv.y),
                    boundary(cell.z, step.z, o.z, inv.z),
                );
                continue;
            }
        }
        // Next voxel.
        let axis = if t_next.x < t_next.y {
            if t_next.x < t_next.z {
                0
            } else {
                2
            }
        } else if t_next.y < t_next.z {
            1
        } else {
            2
        };
        t = t_next[axis];
        cell[axis] += step[axis];
        t_next[axis] += t_delta[axis];
        last_axis = Some(axis);
    }
    None
}

/// How far (in voxel steps along `axis`) the surface lies past the face the ray entered the hit voxel by: the zero
/// crossing of the surface offsets of the voxel before it and of the hit voxel, between their centres, less the
/// face's half step; 0 where either keeps none.
fn crossing_shift(map: &BrickMap, hit: &BinaryBrick, cell: IVec3, local: IVec3, axis: usize, step: IVec3) -> f64 {
    let Some(inside) = hit.offset(local.x, local.y, local.z) else { return 0.0 };
    let mut before = cell;
    before[axis] -= step[axis];
    let (key, before_local) = BrickMap::split(before);
    let Some(outside) = map.brick(key).and_then(|b| b.offset(before_local.x, before_local.y, before_local.z)) else {
        return 0.0;
    };
    if outside <= inside {
        return 0.0;
    }
    f64::from(outside / (outside - inside)) - 0.5
}

fn sign(x: f64) -> i32 {
    if x > 0.0 {
        1
    } else if x < 0.0 {
        -1
    } else {
        0
    }
}

/// One image row: depths and colours.
type Row = (Vec<f32>, Vec<Option<[u8; 3]>>);

/// Renders the surface from `pose` as seen by a camera of `intrinsics`, up to depth `max_depth`.
pub fn render(map: &BrickMap, pose: &Pose, intrinsics: &Intrinsics, surface: Surface, max_depth: f64) -> SurfaceView {
    let (w, h) = (intrinsics.width as usize, intrinsics.height as usize);
    let origin = pose.translation;
    let rows: Vec<Row> = (0..h)
        .into_par_iter()
        .map(|v| {
            let mut depth = vec![0.0f32; w];
            let mut colour = vec![None; w];
            for u in 0..w {
                // With the direction's camera z equal to 1, the ray parameter is the camera depth.
                let direction = pose.matrix3 * intrinsics.unproject(u as f64, v as f64, 1.0);
                if let Some((t, cell)) = cast(map, origin, direction, max_depth, surface) {
                    depth[u] = t as f32;
                    let (key, local) = BrickMap::split(cell);
                    colour[u] = map.brick(key).and_then(|b| b.colour(local.x, local.y, local.z));
                }
            }
            (depth, colour)
        })
        .collect();
    let mut view =
        SurfaceView { intrinsics: *intrinsics, depth: Vec::with_capacity(w * h), colour: Vec::with_capacity(w * h) };
    for (d, c) in rows {
        view.depth.extend(d);
        view.colour.extend(c);
    }
    view
}

/// The view's depth smoothed by ROF total variation with a strength suited to voxel faces of edge `voxel`
/// (`iterations` Chambolle steps; 0 returns the depth as it is).
pub fn smooth_depth(view: &SurfaceView, voxel: f64, iterations: u32) -> Vec<f32> {
    let k = &view.intrinsics;
    let image = DepthImage::new(
        k.width as usize,
        k.height as usize,
        view.depth.iter().map(|&d| if d > 0.0 { d } else { f32::INFINITY }).collect(),
    );
    let mut settings = RofSettings::for_radius(voxel as f32, k.fy as f32);
    settings.iterations = iterations;
    let smoothed = smooth_rof(&image, &settings);
    smoothed.depth.into_iter().map(|d| if d.is_finite() { d } else { 0.0 }).collect()
}

/// Shades a view for display (§8.4.4: deferred shading with normals from finite differences of the smoothed
/// depth): each pixel's colour is its voxel's (grey where it has none) lit by a light at the camera, the
/// background black. Returns RGB8 pixels, row by row.
pub fn shade(view: &SurfaceView, smoothed: &[f32]) -> Vec<u8> {
    let k = &view.intrinsics;
    let (w, h) = (k.width as i64, k.height as i64);
    let point = |x: i64, y: i64| -> Option<DVec3> {
        if x < 0 || y < 0 || x >= w || y >= h {
            return None;
        }
        let d = smoothed[(y * w + x) as usize];
        (d > 0.0).then(|| k.unproject(x as f64, y as f64, f64::from(d)))
    };
    let mut pixels = vec![0u8; (w * h * 3) as usize];
    for y in 0..h {
        for x in 0..w {
            let Some(p) = point(x, y) else { continue };
            // Central differences where both neighbours are on the same surface, one-sided otherwise.
            let near = |a: Option<DVec3>| a.filter(|q| (q.z - p.z).abs() < 0.05 * p.z);
            let dx = match (near(point(x + 1, y)), near(point(x - 1, y))) {
                (Some(a), Some(b)) => a - b,
                (Some(a), None) => a - p,
                (None, Some(b)) => p - b,
                (None, None) => continue,
            };
            let dy = match (near(point(x, y + 1)), near(point(x, y - 1))) {
                (Some(a), Some(b)) => a - b,
                (Some(a), None) => a - p,
                (None, Some(b)) => p - b,
                (None, None) => continue,
            };
            let normal = dy.cross(dx).normalize_or_zero();
            let lambert = normal.dot(-p.normalize()).abs();
            let albedo = view.colour[(y * w + x) as usize].unwrap_or([190, 190, 190]);
            let i = ((y * w + x) * 3) as usize;
            for c in 0..3 {
                pixels[i + c] = (f64::from(albedo[c]) * (0.15 + 0.85 * lambert)).round().clamp(0.0, 255.0) as u8;
            }
        }
    }
    pixels
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brick::BinaryBrick;

    /// A map whose voxels with `z >= wall` are inside and confident, in the bricks of `x, y ∈ -4..4`.
    fn wall_map(wall: i32) -> BrickMap {
        let mut map = BrickMap::new(0.01, None);
        let keys = (-4..4).flat_map(|x| (-4..4).flat_map(move |y| (0..6).map(move |z| IVec3::new(x, y, z))));
        for key in keys {
            let mut brick = BinaryBrick::default();
            for z in 0..BRICK {
                for y in 0..BRICK {
                    for x in 0..BRICK {
                        if key.z * BRICK + z >= wall {
                            let i = voxel_index(x, y, z);
                            brick.inside.set(i, true);
                            brick.confident.set(i, true);
                        }
                    }
                }
            }
            map.put(key, brick);
        }
        map
    }

    #[test]
    fn a_wall_of_voxels_renders_at_its_face() {
        let map = wall_map(30);
        let k = Intrinsics { width: 32, height: 24, fx: 80.0, fy: 80.0, cx: 15.5, cy: 11.5 };
        // Camera at z = -0.5 m looking +z: the wall's face is at z = 0.30 m, depth 0.80.
        let pose = Pose::from_translation(DVec3::new(0.003, -0.002, -0.5));
        let view = render(&map, &pose, &k, Surface::Confident, 5.0);
        assert!(view.depth.iter().all(|&d| (d - 0.8).abs() < 1e-5), "{:?}", &view.depth[..4]);
        // Tilted, the depth still lands on the face plane z = 0.30 (within a voxel's rounding).
        let pose = Pose::from_rotation_translation(glam::DQuat::from_rotation_y(0.1), DVec3::new(0.0, 0.0, -0.5));
        let view = render(&map, &pose, &k, Surface::Confident, 5.0);
        for v in 0..k.height {
            for u in 0..k.width {
                let d = view.depth[(v * k.width + u) as usize] as f64;
                assert!(d > 0.0, "every ray hits the wall");
                let p = pose.transform_point3(k.unproject(u as f64, v as f64, d));
                assert!((p.z - 0.30).abs() < 1e-6 || p.x.abs() > 0.3, "pixel {u},{v} hit at {p}");
            }
        }
        // From behind the camera's far limit, nothing.
        let view = render(&map, &Pose::from_translation(DVec3::new(0.0, 0.0, -5.0)), &k, Surface::Confident, 1.0);
        assert!(view.depth.iter().all(|&d| d == 0.0));
        assert!(shade(&view, &view.depth).iter().all(|&c| c == 0), "nothing hit: all background");
    }

    #[test]
    fn a_wall_seen_head_on_is_lit_fully_and_tilted_less() {
        let map = wall_map(30);
        let k = Intrinsics { width: 32, height: 24, fx: 80.0, fy: 80.0, cx: 15.5, cy: 11.5 };
        let head_on = render(&map, &Pose::from_translation(DVec3::new(0.0, 0.0, -0.5)), &k, Surface::Confident, 5.0);
        let lit = shade(&head_on, &head_on.depth);
        // The centre pixel: grey (no colours stored) at full light.
        let centre = ((12 * 32 + 16) * 3) as usize;
        assert!(lit[centre] >= 185, "{}", lit[centre]);
        let pose = Pose::from_rotation_translation(glam::DQuat::from_rotation_y(0.1), DVec3::new(0.0, 0.0, -0.5));
        let tilted = render(&map, &pose, &k, Surface::Confident, 5.0);
        let smoothed = smooth_depth(&tilted, 0.01, 75);
        let dim = shade(&tilted, &smoothed);
        assert!(dim[centre] < lit[centre] && dim[centre] > 150, "{} vs {}", dim[centre], lit[centre]);
    }

    #[test]
    fn rays_cross_absent_bricks_and_negative_coordinates() {
        let mut map = BrickMap::new(0.01, None);
        let mut brick = BinaryBrick::default();
        brick.inside.set(voxel_index(3, 4, 5), true);
        map.put(IVec3::new(-3, -2, 7), brick);
        // Aim at voxel (-21, -12, 61)'s centre from far away along a skew direction.
        let target = map.centre(IVec3::new(-24 + 3, -16 + 4, 56 + 5));
        let origin = DVec3::new(0.4, 0.3, -0.2);
        let direction = (target - origin) / (target - origin).z;
        let hit = cast(&map, origin, direction, 10.0, Surface::Any).expect("the ray reaches the voxel");
        assert_eq!(hit.1, IVec3::new(-21, -12, 61));
        assert!(hit.0 <= (target - origin).z + 1e-9);
        assert!(cast(&map, origin, direction, 10.0, Surface::Confident).is_none(), "not confident");
    }
}
