//! Exact ray–isosurface intersection inside one trilinear cell (Knoll et al., seed 002 §3; Marmitt et al. 2004).
//!
//! Along a ray, the trilinear interpolant of a cell's eight corners is a cubic in the ray parameter. Its crossings
//! of an isovalue are found without sampling: the cubic's extrema (roots of its derivative, a quadratic) split the
//! cell's interval into at most three monotone pieces; a piece whose ends lie on different sides of the isovalue
//! holds exactly one crossing, refined by Illinois-modified regula falsi. So two crossings inside one cell (a ray
//! grazing a thin feature) are both found, in order, where a fixed-step scan would miss both
//! (`../shared/notes/knoll-isosurface.md`, "Ray–cell intersection"; Twinklebear's `marmitt_intersect`).
//!
//! "Inside" means `f ≥ iso` throughout: a crossing is a change of that predicate, so the same rule decides seams
//! between cells, levels and constant nodes in [`crate::isosurface`].

/// Regula-falsi iterations at most; each one at least halves the bracket's weight on the stale side (Illinois), so
/// a dozen reach f32 resolution on a monotone piece. The GPU's `cubic_refine` (voxstream-gpu's `cell_cubic.wgsl`)
/// mirrors it.
pub const REFINE_ITERATIONS: u32 = 16;

/// The field along a ray inside one cell: `f(u) = c[0] + u·(c[1] + u·(c[2] + u·c[3]))`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CellCubic {
    c: [f32; 4],
}

impl CellCubic {
    /// The cubic of the trilinear interpolant of `corners` (x fastest: `v000, v100, v010, v110, v001, v101, v011,
    /// v111`) along `start + u·direction`, both in cell-local coordinates (the cell is `[0, 1]³`).
    #[inline(always)]
    pub fn new(corners: &[f32; 8], start: [f32; 3], direction: [f32; 3]) -> CellCubic {
        let [sx, sy, sz] = start;
        let [dx, dy, dz] = direction;
        // Along z: each of the four (x, y) edges is linear in u: constant + slope·u.
        let edge = |i: usize| {
            let (a, b) = (corners[i], corners[i + 4]);
            (a + (b - a) * sz, (b - a) * dz)
        };
        let (e00, e10, e01, e11) = (edge(0), edge(1), edge(2), edge(3));
        // Along y: two quadratics (one per x side) = linear edge × linear weight, summed.
        let face = |lo: (f32, f32), hi: (f32, f32)| {
            // lo·(1 − sy − dy·u) + hi·(sy + dy·u)
            let (w0, w0u) = (1.0 - sy, -dy);
            let (w1, w1u) = (sy, dy);
            [lo.0 * w0 + hi.0 * w1, lo.0 * w0u + lo.1 * w0 + hi.0 * w1u + hi.1 * w1, lo.1 * w0u + hi.1 * w1u]
        };
        let (q0, q1) = (face(e00, e01), face(e10, e11));
        // Along x: cubic = quadratic × linear weight, summed.
        let (w0, w0u) = (1.0 - sx, -dx);
        let (w1, w1u) = (sx, dx);
        CellCubic {
            c: [
                q0[0] * w0 + q1[0] * w1,
                q0[0] * w0u + q0[1] * w0 + q1[0] * w1u + q1[1] * w1,
                q0[1] * w0u + q0[2] * w0 + q1[1] * w1u + q1[2] * w1,
                q0[2] * w0u + q1[2] * w1u,
            ],
        }
    }

    /// The coefficients `[c0, c1, c2, c3]` of `f(u) = c0 + c1·u + c2·u² + c3·u³` (what a GPU twin compares).
    pub fn coefficients(&self) -> [f32; 4] {
        self.c
    }

    /// The field at `u`.
    #[inline(always)]
    pub fn at(&self, u: f32) -> f32 {
        let c = self.c;
        c[0] + u * (c[1] + u * (c[2] + u * c[3]))
    }

    /// The cubic's extrema strictly inside `(0, length)`, ascending, and how many there are.
    #[inline(always)]
    fn extrema(&self, length: f32) -> ([f32; 2], usize) {
        // f'(u) = c1 + 2·c2·u + 3·c3·u².
        let (a, b, c) = (3.0 * self.c[3], 2.0 * self.c[2], self.c[1]);
        let mut roots = [0.0f32; 2];
        let mut count = 0;
        let mut push = |u: f32| {
            if u > 0.0 && u < length {
                roots[count] = u;
                count += 1;
            }
        };
        let scale = a.abs().max(b.abs()).max(c.abs());
        if scale == 0.0 {
            return (roots, 0);
        }
        if a.abs() <= 1e-6 * scale {
            if b != 0.0 {
                push(-c / b);
            }
        } else {
            let discriminant = b * b - 4.0 * a * c;
            if discriminant > 0.0 {
                // The numerically stable pair (no cancellation).
                let q = -0.5 * (b + discriminant.sqrt().copysign(b));
                let (r0, r1) = (q / a, if q != 0.0 { c / q } else { 0.0 });
                let (lo, hi) = if r0 < r1 { (r0, r1) } else { (r1, r0) };
                push(lo);
                if hi != lo {
                    push(hi);
                }
            }
        }
        (roots, count)
    }

    /// Every crossing of `iso` over `[0, length]`, ascending, written to `out`; returns how many (at most 3). A
    /// crossing is where `f ≥ iso` changes.
    #[inline]
    pub fn crossings(&self, iso: f32, length: f32, out: &mut [f32; 3]) -> usize {
        let (extrema, count) = self.extrema(length);
        let mut found = 0;
        let mut a = 0.0f32;
        let mut fa = self.at(0.0) - iso;
        for b in extrema[..count].iter().copied().chain([length]) {
            let fb = self.at(b) - iso;
            if (fa >= 0.0) != (fb >= 0.0) {
                out[found] = self.refine(iso, a, fa, b, fb);
                found += 1;
            }
            a = b;
            fa = fb;
        }
        found
    }

    /// The crossing in `[a, b]`, where `fa = f(a) − iso` and `fb = f(b) − iso` lie on different sides.
    #[inline]
    fn refine(&self, iso: f32, mut a: f32, mut fa: f32, mut b: f32, mut fb: f32) -> f32 {
        let inside_a = fa >= 0.0;
        // Which end was kept last time (Illinois: halve its value when it is kept twice).
        let mut side = 0i8;
        for _ in 0..REFINE_ITERATIONS {
            let denominator = fb - fa;
            let mut m = if denominator != 0.0 { a - fa * (b - a) / denominator } else { 0.5 * (a + b) };
            if !(m > a && m < b) {
                m = 0.5 * (a + b);
                if !(m > a && m < b) {
                    break;
                }
            }
            let fm = self.at(m) - iso;
            if (fm >= 0.0) == inside_a {
                a = m;
                fa = fm;
                if side == -1 {
                    fb *= 0.5;
                }
                side = -1;
            } else {
                b = m;
                fb = fm;
                if side == 1 {
                    fa *= 0.5;
                }
                side = 1;
            }
            if fm == 0.0 {
                break;
            }
        }
        // The predicate changes between a and b; b is the first point known on the other side.
        if fa == 0.0 {
            a
        } else {
            b
        }
    }
}

/// The analytic gradient of the trilinear interpolant of `corners` at cell-local `p` (per cell edge, cell axes).
#[inline(always)]
pub fn cell_gradient(corners: &[f32; 8], p: [f32; 3]) -> [f32; 3] {
    let [x, y, z] = p.map(|v| v.clamp(0.0, 1.0));
    let v = |i: usize| corners[i];
    let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
    // d/dx: the x-differences of the four edges, interpolated in y and z.
    let gx = lerp(lerp(v(1) - v(0), v(3) - v(2), y), lerp(v(5) - v(4), v(7) - v(6), y), z);
    let gy = lerp(lerp(v(2) - v(0), v(3) - v(1), x), lerp(v(6) - v(4), v(7) - v(5), x), z);
    let gz = lerp(lerp(v(4) - v(0), v(5) - v(1), x), lerp(v(6) - v(2), v(7) - v(3), x), y);
    [gx, gy, gz]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The trilinear interpolant evaluated directly, in f64.
    fn trilinear(c: &[f32; 8], p: [f64; 3]) -> f64 {
        let [x, y, z] = p;
        let v = |i: usize| c[i] as f64;
        let l = |a: f64, b: f64, t: f64| a + (b - a) * t;
        l(l(l(v(0), v(1), x), l(v(2), v(3), x), y), l(l(v(4), v(5), x), l(v(6), v(7), x), y), z)
    }

    #[test]
    fn the_cubic_is_the_trilinear_interpolant_along_the_ray() {
        let corners = [3.0, -1.0, 2.5, 7.0, 0.5, 4.0, -2.0, 1.0];
        let start = [0.1f32, 0.7, 0.3];
        let direction = [0.5f32, -0.4, 0.6];
        let cubic = CellCubic::new(&corners, start, direction);
        for k in 0..=10 {
            let u = k as f64 * 0.1;
            let p = std::array::from_fn(|a| start[a] as f64 + u * direction[a] as f64);
            assert!((cubic.at(u as f32) as f64 - trilinear(&corners, p)).abs() < 1e-5, "u = {u}");
        }
    }

    #[test]
    fn two_crossings_in_one_cell_are_both_found_in_order() {
        // f = x·(1 − z) + (1 − x)·z is trilinear (corners x fastest, then y, then z). Along x = z = s it is
        // 2s(1 − s): it rises from 0 to ½ and falls back, so iso 0.3 is crossed twice inside the cell.
        let corners = [0.0, 1.0, 0.0, 1.0, 1.0, 0.0, 1.0, 0.0];
        let cubic = CellCubic::new(&corners, [0.0, 0.5, 0.0], [1.0, 0.0, 1.0]);
        let mut out = [0.0; 3];
        let n = cubic.crossings(0.3, 1.0, &mut out);
        assert_eq!(n, 2, "{out:?}");
        // 2s(1 − s) = 0.3 → s = (1 ∓ √0.4)/2.
        let (s0, s1) = ((1.0 - 0.4f64.sqrt()) / 2.0, (1.0 + 0.4f64.sqrt()) / 2.0);
        assert!((out[0] as f64 - s0).abs() < 1e-5, "{} vs {s0}", out[0]);
        assert!((out[1] as f64 - s1).abs() < 1e-5, "{} vs {s1}", out[1]);
        // Both ends are outside: a scan that only compares the ends sees nothing.
        assert!(cubic.at(0.0) < 0.3 && cubic.at(1.0) < 0.3);
    }

    #[test]
    fn three_crossings_of_a_cubic_are_found() {
        // f(u) = (u − 0.2)(u − 0.5)(u − 0.8) + 1: pick corners so that the ray's cubic is general, then compare
        // with a dense scan of the same cubic.
        let corners = [0.0, 9.0, 9.0, -9.0, 9.0, -9.0, -9.0, 9.0];
        let cubic = CellCubic::new(&corners, [0.02, 0.03, 0.05], [0.95, 0.93, 0.9]);
        let iso = cubic.at(0.5);
        let mut scan = Vec::new();
        let steps = 200_000;
        for k in 0..steps {
            let (a, b) = (k as f32 / steps as f32, (k + 1) as f32 / steps as f32);
            if (cubic.at(a) >= iso) != (cubic.at(b) >= iso) {
                scan.push(b);
            }
        }
        let mut out = [0.0; 3];
        let n = cubic.crossings(iso, 1.0, &mut out);
        assert_eq!(n, scan.len(), "solver {:?} scan {scan:?}", &out[..n]);
        assert!(n == 3, "this cubic crosses three times: {scan:?}");
        for (found, expected) in out.iter().zip(&scan) {
            assert!((found - expected).abs() < 1e-4, "{found} vs {expected}");
        }
    }

    #[test]
    fn a_plane_is_hit_exactly() {
        // f = x + 2y + 3z is trilinear: its crossing along any ray is closed-form.
        let corners: [f32; 8] = std::array::from_fn(|i| ((i & 1) + 2 * ((i >> 1) & 1) + 3 * (i >> 2)) as f32);
        let (start, direction) = ([0.1f32, 0.2, 0.1], [0.3f32, 0.2, 0.25]);
        let iso = 2.0f32;
        let closed = (iso - (start[0] + 2.0 * start[1] + 3.0 * start[2]))
            / (direction[0] + 2.0 * direction[1] + 3.0 * direction[2]);
        let mut out = [0.0; 3];
        assert_eq!(CellCubic::new(&corners, start, direction).crossings(iso, 2.0, &mut out), 1);
        assert!((out[0] - closed).abs() < 1e-6, "{} vs {closed}", out[0]);
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let corners = [3.0, -1.0, 2.5, 7.0, 0.5, 4.0, -2.0, 1.0];
        let p = [0.3, 0.6, 0.2];
        let g = cell_gradient(&corners, p.map(|v| v as f32));
        for a in 0..3 {
            let h = 1e-6;
            let (mut lo, mut hi) = (p, p);
            lo[a] -= h;
            hi[a] += h;
            let fd = (trilinear(&corners, hi) - trilinear(&corners, lo)) / (2.0 * h);
            assert!((g[a] as f64 - fd).abs() < 1e-4, "axis {a}: {} vs {fd}", g[a]);
        }
    }
}
