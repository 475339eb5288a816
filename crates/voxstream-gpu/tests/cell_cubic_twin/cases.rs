//! The cells of the twin test, by kind: random cells and rays, grazing rays, exact double roots, crossings at the
//! span's ends, isovalues outside the cell, degenerate rays and cells. Deterministic (a fixed seed).

use voxstream_render::cell_intersection::CellCubic;

use crate::Case;

/// SplitMix64: the cases are the same on every run.
pub struct Random(pub u64);

impl Random {
    pub fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
    /// A stored voxel, 0‥65535.
    fn voxel(&mut self) -> f32 {
        (self.next() % 65536) as f32
    }
    fn direction(&mut self) -> [f64; 3] {
        loop {
            let d = [0; 3].map(|_| self.range(-1.0, 1.0));
            let norm = dot(d, d).sqrt();
            if (0.1..=1.0).contains(&norm) {
                return d.map(|c| c / norm);
            }
        }
    }
    /// Corners: uniform, a flat cell (a base and small steps: smooth data), or a sharp one (0 or 65535).
    fn corners(&mut self) -> [f32; 8] {
        match self.next() % 3 {
            0 => [0; 8].map(|_| self.voxel()),
            1 => {
                let base = (self.next() % (65536 - 64)) as f32;
                [0; 8].map(|_| base + (self.next() % 65) as f32)
            }
            _ => [0; 8].map(|_| if self.next().is_multiple_of(2) { 0.0 } else { 65535.0 }),
        }
    }
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The trilinear interpolant at p and its gradient, in f64.
fn trilinear(v: &[f32; 8], p: [f64; 3]) -> (f64, [f64; 3]) {
    let v = v.map(f64::from);
    let [x, y, z] = p;
    let l = |a: f64, b: f64, t: f64| a + (b - a) * t;
    let value = l(l(l(v[0], v[1], x), l(v[2], v[3], x), y), l(l(v[4], v[5], x), l(v[6], v[7], x), y), z);
    let gx = l(l(v[1] - v[0], v[3] - v[2], y), l(v[5] - v[4], v[7] - v[6], y), z);
    let gy = l(l(v[2] - v[0], v[3] - v[1], x), l(v[6] - v[4], v[7] - v[5], x), z);
    let gz = l(l(v[4] - v[0], v[5] - v[1], x), l(v[6] - v[2], v[7] - v[3], x), y);
    (value, [gx, gy, gz])
}

/// The ray through `p` along `direction` across the whole cell, at `speed` cell units per world unit.
fn through(corners: [f32; 8], p: [f64; 3], direction: [f64; 3], speed: f64, iso: f32) -> Case {
    let (mut enter, mut exit) = (f64::NEG_INFINITY, f64::INFINITY);
    for a in 0..3 {
        if direction[a] != 0.0 {
            let (t0, t1) = ((0.0 - p[a]) / direction[a], (1.0 - p[a]) / direction[a]);
            enter = enter.max(t0.min(t1));
            exit = exit.min(t0.max(t1));
        }
    }
    let start = [0, 1, 2].map(|a| (p[a] + enter * direction[a]).clamp(0.0, 1.0) as f32);
    Case { corners, start, rate: direction.map(|d| (d * speed) as f32), iso, length: ((exit - enter) / speed) as f32 }
}

/// The cases, by kind.
pub fn cases() -> Vec<(&'static str, Case)> {
    let mut random = Random(46);
    let mut out = Vec::new();
    let speed = |r: &mut Random| 10f64.powf(r.range(-2.0, 3.0));
    for _ in 0..2000 {
        let corners = random.corners();
        let (lo, hi) = corners.iter().fold((f32::MAX, f32::MIN), |(lo, hi), &v| (lo.min(v), hi.max(v)));
        let iso = if random.next().is_multiple_of(5) {
            lo.max(hi.min(random.voxel()))
        } else {
            random.range(lo as f64, hi as f64) as f32
        };
        let p = [0; 3].map(|_| random.unit());
        let (direction, s) = (random.direction(), speed(&mut random));
        out.push(("random", through(corners, p, direction, s, iso)));
    }
    // Grazing: the direction tangent to the level set through p (a double root), then nearly so (two close roots
    // or none).
    for k in 0..1500 {
        let corners = random.corners();
        let p = [0; 3].map(|_| random.range(0.15, 0.85));
        let (value, gradient) = trilinear(&corners, p);
        if dot(gradient, gradient) < 1.0 {
            continue;
        }
        let other = random.direction();
        let g = gradient;
        let cross =
            [g[1] * other[2] - g[2] * other[1], g[2] * other[0] - g[0] * other[2], g[0] * other[1] - g[1] * other[0]];
        let norm = dot(cross, cross).sqrt();
        if norm == 0.0 {
            continue;
        }
        let direction = cross.map(|c| c / norm);
        let (kind, iso) = if k < 1000 {
            ("grazing", value)
        } else {
            ("nearly grazing", value + random.range(-1.0, 1.0) * 10f64.powf(random.range(-4.0, 1.0)))
        };
        out.push((kind, through(corners, p, direction, speed(&mut random), iso as f32)));
    }
    // Exact double roots: f = k·(x(1 − z) + (1 − x)z) along x = z = s is 2k·s(1 − s), touching k/2 at s = ½.
    for j in 1..16 {
        let k = (1u32 << j) as f32;
        for m in -3..=3 {
            let s = 2f32.powi(m);
            let corners = [0.0, k, 0.0, k, k, 0.0, k, 0.0];
            let y = [0.0, 0.25, 0.5, 1.0][(j as usize + m as usize) % 4];
            let case = Case { corners, start: [0.0, y, 0.0], rate: [s, 0.0, s], iso: 0.5 * k, length: 1.0 / s };
            out.push(("exact double root", case));
        }
    }
    // Crossings at the span's ends and a hair inside them, from the CPU's own values there.
    for k in 0..800 {
        let corners = random.corners();
        let mut case = through(corners, [0; 3].map(|_| random.unit()), random.direction(), speed(&mut random), 0.0);
        if k < 100 {
            // From a corner into the cell, the isovalue that corner's.
            let corner = (random.next() % 8) as usize;
            let at = [corner & 1, (corner >> 1) & 1, corner >> 2].map(|b| b as f64);
            let into = random.direction().map(f64::abs);
            let direction = [0, 1, 2].map(|a| if at[a] == 1.0 { -into[a] } else { into[a] });
            case = through(corners, at, direction, speed(&mut random), corners[corner]);
            case.start = at.map(|c| c as f32);
            out.push(("root at a corner", case));
            continue;
        }
        let cubic = CellCubic::new(&case.corners, case.start, case.rate);
        let (kind, u) = match k % 4 {
            0 => ("root at the start", 0.0),
            1 => ("root at the end", case.length),
            2 => ("root just after the start", case.length * 1e-6),
            _ => ("root just before the end", case.length * (1.0 - 1e-6)),
        };
        case.iso = cubic.at(u);
        out.push((kind, case));
    }
    // No root: the isovalue outside the cell's values.
    for k in 0..300 {
        let corners = random.corners();
        let (lo, hi) = corners.iter().fold((f32::MAX, f32::MIN), |(lo, hi), &v| (lo.min(v), hi.max(v)));
        let off = [0.5, 1.0, 1000.0][k % 3];
        let iso = if k % 2 == 0 { hi + off } else { lo - off };
        out.push(("outside the range", through(corners, [0; 3].map(|_| random.unit()), random.direction(), 1.0, iso)));
    }
    // Degenerate rays and cells.
    for k in 0..240 {
        let corners = random.corners();
        let mid =
            0.5 * (corners.iter().copied().fold(f32::MAX, f32::min) + corners.iter().copied().fold(f32::MIN, f32::max));
        let p = [0; 3].map(|_| random.unit());
        let axis = k % 3;
        let case = match k % 8 {
            0 => {
                let mut d = [0.0; 3];
                d[axis] = if k % 16 < 8 { 1.0 } else { -1.0 };
                ("axis-aligned", through(corners, p, d, 1.0, mid))
            }
            1 => {
                let mut d = random.direction();
                d[axis] = 0.0;
                let norm = dot(d, d).sqrt();
                ("in a plane", through(corners, p, d.map(|c| c / norm), 7.0, mid))
            }
            2 => {
                ("standing still", Case { corners, start: p.map(|c| c as f32), rate: [0.0; 3], iso: mid, length: 1.0 })
            }
            3 => {
                let v = random.voxel();
                let iso = if k % 16 < 8 { v } else { v + 0.5 };
                ("constant cell", through([v; 8], p, random.direction(), 1.0, iso))
            }
            4 => {
                let mut case = through(corners, p, random.direction(), 1.0, mid);
                case.length = case.length.min(1e-7);
                ("tiny span", case)
            }
            5 => ("fast ray", through(corners, p, random.direction(), 1e4, mid)),
            6 => ("slow ray", through(corners, p, random.direction(), 1e-3, mid)),
            _ => {
                // Three crossings in one cell (voxstream-render's own test), scaled.
                let scale = 1.0 + (k % 7) as f32;
                let corners = [0.0, 9.0, 9.0, -9.0, 9.0, -9.0, -9.0, 9.0].map(|v: f32| v * scale + 9.0 * scale);
                let (start, rate) = ([0.02, 0.03, 0.05], [0.95, 0.93, 0.9]);
                let iso = CellCubic::new(&corners, start, rate).at(0.5);
                ("three crossings", Case { corners, start, rate, iso, length: 1.0 })
            }
        };
        out.push(case);
    }
    out
}
