//! `cell_cubic.wgsl`'s solver transliterated to Rust, operation for operation, with the rounding a GPU may do where
//! the CPU does not: Vulkan lets `x / y` and `sqrt` be off by a few ulps (2.5 ulp for division, inherited from
//! `inversesqrt` for `sqrt`) and may fuse `a·b + c` into one rounding. With [`Rounding::gpu`] each such operation
//! rounds one of those ways at random; with [`Rounding::exact`] it is the CPU's arithmetic.
//!
//! What it is for: a twin test that runs on lavapipe (the CI adapter, bit-exact with the CPU) says nothing about
//! whether its tolerances pass a GPU that rounds differently. Compared with the CPU as the GPU is, this emulation must
//! pass them (they are not too tight); with a [`Defect`] it must fail them (they are not too loose).

use crate::cases::Random;
use crate::{Case, Found};

/// A deliberate defect in the emulated solver, for the test that the comparison fails it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Defect {
    None,
    /// Fewer regula-falsi iterations than `REFINE_ITERATIONS`.
    RefineIterations(u32),
    /// Plain regula falsi: no Illinois halving of a stale end.
    NoIllinois,
}

/// How the emulation rounds.
pub struct Rounding {
    random: Random,
    gpu: bool,
}

impl Rounding {
    /// The CPU's arithmetic: every operation rounded once, nothing fused.
    pub fn exact() -> Rounding {
        Rounding { random: Random(0), gpu: false }
    }

    /// A GPU's latitude, chosen at random per operation.
    pub fn gpu(seed: u64) -> Rounding {
        Rounding { random: Random(seed), gpu: true }
    }

    /// `x` moved by up to `ulps` ulps either way, at random.
    fn nudge(&mut self, x: f32, ulps: u64) -> f32 {
        if !self.gpu || !x.is_finite() || x == 0.0 {
            return x;
        }
        let step = (self.random.next() % (2 * ulps + 1)) as i64 - ulps as i64;
        let moved = f32::from_bits((x.to_bits() as i64 + step) as u32);
        if moved.is_finite() && moved.signum() == x.signum() {
            moved
        } else {
            x
        }
    }

    fn div(&mut self, x: f32, y: f32) -> f32 {
        self.nudge(x / y, 2)
    }

    fn sqrt(&mut self, x: f32) -> f32 {
        self.nudge(x.sqrt(), 2)
    }

    fn coin(&mut self) -> bool {
        self.gpu && self.random.next().is_multiple_of(2)
    }

    /// `a·b + c`, fused or not.
    fn mul_add(&mut self, a: f32, b: f32, c: f32) -> f32 {
        if self.coin() {
            a.mul_add(b, c)
        } else {
            a * b + c
        }
    }

    /// `a0·b0 + a1·b1 + …`, summed left to right, each addition maybe fused with its product.
    fn products(&mut self, terms: &[(f32, f32)]) -> f32 {
        let mut sum = terms[0].0 * terms[0].1;
        for &(a, b) in &terms[1..] {
            sum = self.mul_add(a, b, sum);
        }
        sum
    }
}

/// `cell_cubic`.
fn cell_cubic(r: &mut Rounding, v: &[f32; 8], start: [f32; 3], rate: [f32; 3]) -> [f32; 4] {
    let e: [(f32, f32); 4] = std::array::from_fn(|i| (v[i], v[i + 4]));
    let e = e.map(|(a, b)| (r.mul_add(b - a, start[2], a), (b - a) * rate[2]));
    let (w0, w0u, w1, w1u) = (1.0 - start[1], -rate[1], start[1], rate[1]);
    let mut face = |lo: (f32, f32), hi: (f32, f32)| {
        [
            r.products(&[(lo.0, w0), (hi.0, w1)]),
            r.products(&[(lo.0, w0u), (lo.1, w0), (hi.0, w1u), (hi.1, w1)]),
            r.products(&[(lo.1, w0u), (hi.1, w1u)]),
        ]
    };
    let (q0, q1) = (face(e[0], e[2]), face(e[1], e[3]));
    let (x0, x0u, x1, x1u) = (1.0 - start[0], -rate[0], start[0], rate[0]);
    [
        r.products(&[(q0[0], x0), (q1[0], x1)]),
        r.products(&[(q0[0], x0u), (q0[1], x0), (q1[0], x1u), (q1[1], x1)]),
        r.products(&[(q0[1], x0u), (q0[2], x0), (q1[1], x1u), (q1[2], x1)]),
        r.products(&[(q0[2], x0u), (q1[2], x1u)]),
    ]
}

/// `cubic_at`.
fn cubic_at(r: &mut Rounding, c: [f32; 4], u: f32) -> f32 {
    let inner = r.mul_add(u, c[3], c[2]);
    let middle = r.mul_add(u, inner, c[1]);
    r.mul_add(u, middle, c[0])
}

/// `cubic_refine`.
fn cubic_refine(r: &mut Rounding, defect: Defect, c: [f32; 4], iso: f32, ends: [f32; 2], values: [f32; 2]) -> f32 {
    let ([mut a, mut b], [mut fa, mut fb]) = (ends, values);
    let inside_a = fa >= 0.0;
    let mut side = 0;
    let iterations = match defect {
        Defect::RefineIterations(n) => n,
        _ => voxstream_render::cell_intersection::REFINE_ITERATIONS,
    };
    let halving = if defect == Defect::NoIllinois { 1.0 } else { 0.5 };
    for _ in 0..iterations {
        let denominator = fb - fa;
        let mut m = 0.5 * (a + b);
        if denominator != 0.0 {
            m = a - r.div(fa * (b - a), denominator);
        }
        if !(m > a && m < b) {
            m = 0.5 * (a + b);
            if !(m > a && m < b) {
                break;
            }
        }
        let fm = cubic_at(r, c, m) - iso;
        if (fm >= 0.0) == inside_a {
            a = m;
            fa = fm;
            if side == -1 {
                fb *= halving;
            }
            side = -1;
        } else {
            b = m;
            fb = fm;
            if side == 1 {
                fa *= halving;
            }
            side = 1;
        }
        if fm == 0.0 {
            break;
        }
    }
    if fa == 0.0 {
        a
    } else {
        b
    }
}

/// `cubic_pieces`: the ends of the monotone pieces and how many.
fn cubic_pieces(r: &mut Rounding, c: [f32; 4], length: f32) -> ([f32; 3], usize) {
    let (qa, qb, qc) = (3.0 * c[3], 2.0 * c[2], c[1]);
    let mut ends = [length; 3];
    let mut count = 0;
    let scale = qa.abs().max(qb.abs()).max(qc.abs());
    if scale != 0.0 {
        let mut roots = [-1.0f32, -1.0];
        if qa.abs() <= 1e-6 * scale {
            if qb != 0.0 {
                roots[0] = r.div(-qc, qb);
            }
        } else {
            // qb·qb − 4·qa·qc: either product may be fused with the subtraction.
            let discriminant = match (r.coin(), r.coin()) {
                (true, _) => qb.mul_add(qb, -(4.0 * qa * qc)),
                (false, true) => (-(4.0 * qa)).mul_add(qc, qb * qb),
                (false, false) => qb * qb - 4.0 * qa * qc,
            };
            if discriminant > 0.0 {
                let root = r.sqrt(discriminant);
                let q = -0.5 * (qb + if qb >= 0.0 { root } else { -root });
                let r0 = r.div(q, qa);
                let r1 = if q != 0.0 { r.div(qc, q) } else { 0.0 };
                roots = [r0.min(r1), r0.max(r1)];
                if roots[1] == roots[0] {
                    roots[1] = -1.0;
                }
            }
        }
        for u in roots {
            if u > 0.0 && u < length {
                ends[count] = u;
                count += 1;
            }
        }
    }
    ends[count] = length;
    (ends, count + 1)
}

/// `cell_cubic`, `cubic_pieces` and `cubic_crossings` on one case.
pub fn crossings(r: &mut Rounding, defect: Defect, case: &Case) -> Found {
    let c = cell_cubic(r, &case.corners, case.start, case.rate);
    let (ends, pieces) = cubic_pieces(r, c, case.length);
    let mut found = Found { count: 0, roots: [0.0; 3], coefficients: c };
    let (mut a, mut fa) = (0.0, cubic_at(r, c, 0.0) - case.iso);
    for &b in &ends[..pieces] {
        let fb = cubic_at(r, c, b) - case.iso;
        if (fa >= 0.0) != (fb >= 0.0) {
            found.roots[found.count] = cubic_refine(r, defect, c, case.iso, [a, b], [fa, fb]);
            found.count += 1;
        }
        a = b;
        fa = fb;
    }
    found
}
