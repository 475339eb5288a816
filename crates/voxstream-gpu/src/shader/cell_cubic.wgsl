// One trilinear cell along a ray (voxstream-render's cell_intersection.rs: `CellCubic`, `cell_gradient`): its
// interpolant and gradient, the cubic along the ray, its monotone pieces and its crossings of an isovalue.
//
// Pure arithmetic, reading no binding: tests/cell_cubic_twin/ compiles this file alone inside a small compute shader
// and checks its crossings against the CPU's on thousands of cells.

// Regula-falsi iterations at most (`REFINE_ITERATIONS`).
const REFINE_ITERATIONS: u32 = 16u;

// The trilinear interpolant of a cell's corners (x fastest) at cell-local p.
fn cell_value(v: array<f32, 8>, p: vec3<f32>) -> f32 {
    let front = mix(mix(v[0], v[1], p.x), mix(v[2], v[3], p.x), p.y);
    let back = mix(mix(v[4], v[5], p.x), mix(v[6], v[7], p.x), p.y);
    return mix(front, back, p.z);
}

// The cubic f(u) = c.x + u·(c.y + u·(c.z + u·c.w)) of the trilinear interpolant of `v` along start + u·rate
// (cell-local coordinates): `CellCubic::new`.
fn cell_cubic(v: array<f32, 8>, start: vec3<f32>, rate: vec3<f32>) -> vec4<f32> {
    var e: array<vec2<f32>, 4>;
    for (var i = 0u; i < 4u; i++) {
        let a = v[i];
        let b = v[i + 4u];
        e[i] = vec2<f32>(a + (b - a) * start.z, (b - a) * rate.z);
    }
    let w0 = 1.0 - start.y;
    let w0u = -rate.y;
    let w1 = start.y;
    let w1u = rate.y;
    // Along y: e00·(1 − y) + e01·y with x = 0 (edges 0, 2), the same with x = 1 (edges 1, 3).
    let q0 = vec3<f32>(e[0].x * w0 + e[2].x * w1, e[0].x * w0u + e[0].y * w0 + e[2].x * w1u + e[2].y * w1,
        e[0].y * w0u + e[2].y * w1u);
    let q1 = vec3<f32>(e[1].x * w0 + e[3].x * w1, e[1].x * w0u + e[1].y * w0 + e[3].x * w1u + e[3].y * w1,
        e[1].y * w0u + e[3].y * w1u);
    let x0 = 1.0 - start.x;
    let x0u = -rate.x;
    let x1 = start.x;
    let x1u = rate.x;
    return vec4<f32>(q0.x * x0 + q1.x * x1, q0.x * x0u + q0.y * x0 + q1.x * x1u + q1.y * x1,
        q0.y * x0u + q0.z * x0 + q1.y * x1u + q1.z * x1, q0.z * x0u + q1.z * x1u);
}

fn cubic_at(c: vec4<f32>, u: f32) -> f32 {
    return c.x + u * (c.y + u * (c.z + u * c.w));
}

// The crossing in [a, b] where fa = f(a) − iso and fb = f(b) − iso lie on different sides: Illinois-modified
// regula falsi (`CellCubic::refine`).
fn cubic_refine(c: vec4<f32>, iso: f32, a_in: f32, fa_in: f32, b_in: f32, fb_in: f32) -> f32 {
    var a = a_in;
    var fa = fa_in;
    var b = b_in;
    var fb = fb_in;
    let inside_a = fa >= 0.0;
    var side = 0;
    for (var k = 0u; k < REFINE_ITERATIONS; k++) {
        let denominator = fb - fa;
        var m = 0.5 * (a + b);
        if denominator != 0.0 {
            m = a - fa * (b - a) / denominator;
        }
        if !(m > a && m < b) {
            m = 0.5 * (a + b);
            if !(m > a && m < b) {
                break;
            }
        }
        let fm = cubic_at(c, m) - iso;
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
    return select(b, a, fa == 0.0);
}

// The ends of the cubic's monotone pieces over [0, length]: its extrema strictly inside (0, length), ascending,
// then `length` itself; `count` pieces, 1 to 3 (`CellCubic::extrema`).
struct CubicPieces {
    ends: array<f32, 3>,
    count: u32,
}

fn cubic_pieces(c: vec4<f32>, length: f32) -> CubicPieces {
    // f'(u) = c.y + 2·c.z·u + 3·c.w·u².
    let qa = 3.0 * c.w;
    let qb = 2.0 * c.z;
    let qc = c.y;
    var pieces = CubicPieces(array<f32, 3>(length, length, length), 0u);
    let scale = max(max(abs(qa), abs(qb)), abs(qc));
    if scale != 0.0 {
        var r = vec2<f32>(-1.0, -1.0);
        if abs(qa) <= 1e-6 * scale {
            if qb != 0.0 {
                r.x = -qc / qb;
            }
        } else {
            let discriminant = qb * qb - 4.0 * qa * qc;
            if discriminant > 0.0 {
                // The numerically stable pair (no cancellation).
                let q = -0.5 * (qb + select(-sqrt(discriminant), sqrt(discriminant), qb >= 0.0));
                let r0 = q / qa;
                let r1 = select(0.0, qc / q, q != 0.0);
                r = vec2<f32>(min(r0, r1), max(r0, r1));
                if r.y == r.x {
                    r.y = -1.0;
                }
            }
        }
        if r.x > 0.0 && r.x < length {
            pieces.ends[pieces.count] = r.x;
            pieces.count += 1u;
        }
        if r.y > 0.0 && r.y < length {
            pieces.ends[pieces.count] = r.y;
            pieces.count += 1u;
        }
    }
    pieces.ends[pieces.count] = length;
    pieces.count += 1u;
    return pieces;
}

// Every crossing of `iso` (where f ≥ iso changes) over the pieces, ascending, at most one per piece
// (`CellCubic::crossings`).
struct CubicCrossings {
    u: array<f32, 3>,
    count: u32,
}

fn cubic_crossings(c: vec4<f32>, iso: f32, pieces: CubicPieces) -> CubicCrossings {
    var found = CubicCrossings(array<f32, 3>(0.0, 0.0, 0.0), 0u);
    var a = 0.0;
    var fa = cubic_at(c, 0.0) - iso;
    for (var k = 0u; k < pieces.count; k++) {
        let b = pieces.ends[k];
        let fb = cubic_at(c, b) - iso;
        if (fa >= 0.0) != (fb >= 0.0) {
            found.u[found.count] = cubic_refine(c, iso, a, fa, b, fb);
            found.count += 1u;
        }
        a = b;
        fa = fb;
    }
    return found;
}

// The analytic gradient of the trilinear cell at cell-local p (`cell_gradient`).
fn cell_gradient(v: array<f32, 8>, p_in: vec3<f32>) -> vec3<f32> {
    let p = clamp(p_in, vec3<f32>(0.0), vec3<f32>(1.0));
    let gx = mix(mix(v[1] - v[0], v[3] - v[2], p.y), mix(v[5] - v[4], v[7] - v[6], p.y), p.z);
    let gy = mix(mix(v[2] - v[0], v[3] - v[1], p.x), mix(v[6] - v[4], v[7] - v[5], p.x), p.z);
    let gz = mix(mix(v[4] - v[0], v[5] - v[1], p.x), mix(v[6] - v[2], v[7] - v[3], p.x), p.y);
    return vec3<f32>(gx, gy, gz);
}
