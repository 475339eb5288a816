//! Rays against axis-aligned boxes: the slab test that clips a ray to the volume, and the exit from a node's cube
//! that ends a segment.

use glam::DVec3;

/// Distance at which a ray inside (or on) the cube `[lower, lower + size]` leaves it; `1/direction` precomputed.
#[inline]
pub(super) fn exit_distance(origin: DVec3, inverse_direction: DVec3, lower: DVec3, size: f64) -> f64 {
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
    fn box_intersection() {
        let hit = intersect_box(DVec3::new(-1.0, 0.5, 0.5), DVec3::X, DVec3::ZERO, 1.0).unwrap();
        assert_eq!(hit, (1.0, 2.0));
        assert!(intersect_box(DVec3::new(-1.0, 2.0, 0.5), DVec3::X, DVec3::ZERO, 1.0).is_none());
        assert!(intersect_box(DVec3::new(2.0, 0.5, 0.5), DVec3::X, DVec3::ZERO, 1.0).is_none(), "box behind");
        let inside = intersect_box(DVec3::splat(0.5), DVec3::Y, DVec3::ZERO, 1.0).unwrap();
        assert_eq!(inside.1, 0.5);
    }
}
