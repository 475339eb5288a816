//! Tiny 3-vector helpers on `[f64; 3]`, kept local so the reference renderer has no maths dependency.

pub type V3 = [f64; 3];

#[inline]
pub fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

#[inline]
pub fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

#[inline]
pub fn scale(a: V3, s: f64) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

#[inline]
pub fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[inline]
pub fn cross(a: V3, b: V3) -> V3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

#[inline]
pub fn length(a: V3) -> f64 {
    dot(a, a).sqrt()
}

/// `a / |a|`, or `None` when `a` is (numerically) zero or not finite.
#[inline]
pub fn normalize(a: V3) -> Option<V3> {
    let l = length(a);
    if l.is_finite() && l > 1e-300 {
        Some(scale(a, 1.0 / l))
    } else {
        None
    }
}
