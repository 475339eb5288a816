//! The reversible integer CDF 5/3 wavelet on a 3-D brick, by lifting (Reichl §5.5: "a 2-level 3D reversible integer
//! DWT using the CDF 5/3 wavelet ... by applying the lifting scheme [Swe98]").
//!
//! Written by hand rather than taken from a crate: the Rust wavelet crates we know of (`dwt`, `omni-wave`, the
//! JPEG 2000 bindings) transform floats, or 1-D / 2-D images through C, and none lifts integers over the three axes
//! of a small brick with arbitrary (odd, non-power-of-two) edge lengths. The transform is forty lines; what matters
//! for speed is the memory order, which is ours to choose:
//!
//! * x is lifted line by line (contiguous);
//! * y and z are lifted a whole x-row at a time (`row[k] -= (row[k-1] + row[k+1]) >> 1` over the row), so the inner
//!   loops are contiguous, auto-vectorise, and no strided gathers cross 4 KiB strides.
//!
//! Each pass writes its output in subband order (the ⌈n/2⌉ low-pass samples first, then the ⌊n/2⌋ high-pass ones);
//! the next level transforms the low-pass corner `[0, ⌈nx/2⌉) × [0, ⌈ny/2⌉) × [0, ⌈nz/2⌉)`. Ends are whole-sample
//! symmetric (x[-1] = x[1], x[n] = x[n-2]), as in JPEG 2000, so any length ≥ 1 works (length 1 is the identity).
//!
//! All arithmetic wraps: lifting is exactly invertible in ℤ/2³² because the inverse recomputes the very same
//! predictions from the very same values, so the round trip is exact even where a coefficient overflows, and a
//! hostile payload cannot make the inverse panic.

/// Predict (high-pass) of the 5/3 lifting: `d = odd - floor((left + right) / 2)`.
#[inline(always)]
fn pred(l: i32, r: i32) -> i32 {
    l.wrapping_add(r) >> 1
}

/// Update (low-pass) of the 5/3 lifting: `s = even + floor((dl + dr + 2) / 4)`.
#[inline(always)]
fn upd(l: i32, r: i32) -> i32 {
    l.wrapping_add(r).wrapping_add(2) >> 2
}

/// The low-pass corner's edge length after `level` halvings of `n`.
pub(crate) fn low_len(n: usize, level: u32) -> usize {
    let mut n = n;
    for _ in 0..level {
        n = n.div_ceil(2);
    }
    n
}

/// Forward 5/3 of one contiguous line of `n` samples, in place, output in subband order.
fn fwd_line(line: &mut [i32], s: &mut Vec<i32>) {
    let n = line.len();
    if n < 2 {
        return;
    }
    s.clear();
    s.extend_from_slice(line);
    let mut k = 1;
    while k < n {
        let r = if k + 1 < n { s[k + 1] } else { s[k - 1] };
        s[k] = s[k].wrapping_sub(pred(s[k - 1], r));
        k += 2;
    }
    let mut k = 0;
    while k < n {
        let l = if k > 0 { s[k - 1] } else { s[1] };
        let r = if k + 1 < n { s[k + 1] } else { s[k - 1] };
        s[k] = s[k].wrapping_add(upd(l, r));
        k += 2;
    }
    let h = n.div_ceil(2);
    for (i, v) in s.iter().enumerate() {
        line[if i & 1 == 0 { i / 2 } else { h + i / 2 }] = *v;
    }
}

/// Inverse of [`fwd_line`]: undoes the update into the even samples and the predict into the odd ones, reading
/// the subband halves directly (no separate de-interleave pass).
fn inv_line(line: &mut [i32], s: &mut Vec<i32>) {
    let n = line.len();
    if n < 2 {
        return;
    }
    let (h, nd) = (n.div_ceil(2), n / 2);
    s.clear();
    s.resize(n, 0);
    let (lo, d) = line.split_at(h);
    for i in 0..h {
        let dl = d[i.saturating_sub(1)];
        let dr = d[i.min(nd - 1)];
        s[2 * i] = lo[i].wrapping_sub(upd(dl, dr));
    }
    for i in 0..nd {
        let r = s[2 * (i + 1).min(h - 1)];
        s[2 * i + 1] = d[i].wrapping_add(pred(s[2 * i], r));
    }
    line.copy_from_slice(s);
}

/// `dst[i] ±= pred|upd(a[i], b[i])` over rows; the vectorised kernel of the y and z passes.
#[inline(always)]
fn rows_apply<const SUB: bool, const UPD: bool>(dst: &mut [i32], a: &[i32], b: &[i32]) {
    let n = dst.len().min(a.len()).min(b.len());
    let (dst, a, b) = (&mut dst[..n], &a[..n], &b[..n]);
    for i in 0..n {
        let f = if UPD { upd(a[i], b[i]) } else { pred(a[i], b[i]) };
        dst[i] = if SUB { dst[i].wrapping_sub(f) } else { dst[i].wrapping_add(f) };
    }
}

/// Row `k` of `s` (rows of width `w`) as the target, rows `l` and `r` (≠ k) as sources.
#[inline(always)]
fn split3(s: &mut [i32], w: usize, k: usize, l: usize, r: usize) -> (&mut [i32], &[i32], &[i32]) {
    let (lo, hi) = s.split_at_mut(k * w);
    let (tgt, rest) = hi.split_at_mut(w);
    let get = |j: usize| -> &[i32] {
        if j < k {
            &lo[j * w..(j + 1) * w]
        } else {
            &rest[(j - k - 1) * w..(j - k) * w]
        }
    };
    let (a, b) = (get(l), get(r));
    (tgt, a, b)
}

/// Lifts `n` rows of width `w` held contiguously in `s` (row k at `s[k*w..]`), forward or backward. `s` is in
/// interleaved order here; the caller (de)interleaves.
fn lift_rows(s: &mut [i32], n: usize, w: usize, inverse: bool) {
    let right = |k: usize| if k + 1 < n { k + 1 } else { k - 1 };
    let left = |k: usize| if k > 0 { k - 1 } else { 1 };
    if inverse {
        for k in (0..n).step_by(2) {
            let (t, a, b) = split3(s, w, k, left(k), right(k));
            rows_apply::<true, true>(t, a, b);
        }
        for k in (1..n).step_by(2) {
            let (t, a, b) = split3(s, w, k, k - 1, right(k));
            rows_apply::<false, false>(t, a, b);
        }
    } else {
        for k in (1..n).step_by(2) {
            let (t, a, b) = split3(s, w, k, k - 1, right(k));
            rows_apply::<true, false>(t, a, b);
        }
        for k in (0..n).step_by(2) {
            let (t, a, b) = split3(s, w, k, left(k), right(k));
            rows_apply::<false, true>(t, a, b);
        }
    }
}

/// Forward or inverse pass along y (`axis == 1`) or z (`axis == 2`) over the corner `[cx, cy, cz]` of a brick of
/// row length `nx` and slice size `nx * ny`.
fn pass_rows(data: &mut [i32], dims: [usize; 3], corner: [usize; 3], axis: usize, inverse: bool, s: &mut Vec<i32>) {
    let [nx, ny, _] = dims;
    let [cx, cy, cz] = corner;
    let (n, stride, outer, outer_stride) = if axis == 1 { (cy, nx, cz, nx * ny) } else { (cz, nx * ny, cy, nx) };
    if n < 2 {
        return;
    }
    let h = n.div_ceil(2);
    s.clear();
    s.resize(n * cx, 0);
    for o in 0..outer {
        let base = o * outer_stride;
        for k in 0..n {
            // Forward: gather in natural order, scatter to subband order. Inverse: the other way round.
            let src_k = if inverse {
                if k & 1 == 0 {
                    k / 2
                } else {
                    h + k / 2
                }
            } else {
                k
            };
            let at = base + src_k * stride;
            s[k * cx..(k + 1) * cx].copy_from_slice(&data[at..at + cx]);
        }
        lift_rows(s, n, cx, inverse);
        for k in 0..n {
            let dst_k = if inverse {
                k
            } else if k & 1 == 0 {
                k / 2
            } else {
                h + k / 2
            };
            let at = base + dst_k * stride;
            data[at..at + cx].copy_from_slice(&s[k * cx..(k + 1) * cx]);
        }
    }
}

/// Forward or inverse x pass over the corner.
fn pass_x(data: &mut [i32], dims: [usize; 3], corner: [usize; 3], inverse: bool, s: &mut Vec<i32>) {
    let [nx, ny, _] = dims;
    let [cx, cy, cz] = corner;
    if cx < 2 {
        return;
    }
    for z in 0..cz {
        for y in 0..cy {
            let at = (z * ny + y) * nx;
            let line = &mut data[at..at + cx];
            if inverse {
                inv_line(line, s);
            } else {
                fwd_line(line, s);
            }
        }
    }
}

/// Forward `levels`-level 3-D transform of `data` (x fastest, `dims[0] * dims[1] * dims[2]` samples), in place.
pub fn forward(data: &mut [i32], dims: [usize; 3], levels: u32, scratch: &mut Vec<i32>) {
    debug_assert_eq!(data.len(), dims[0] * dims[1] * dims[2]);
    for level in 0..levels {
        let corner = dims.map(|n| low_len(n, level));
        pass_x(data, dims, corner, false, scratch);
        pass_rows(data, dims, corner, 1, false, scratch);
        pass_rows(data, dims, corner, 2, false, scratch);
    }
}

/// Inverse of [`forward`].
pub fn inverse(data: &mut [i32], dims: [usize; 3], levels: u32, scratch: &mut Vec<i32>) {
    debug_assert_eq!(data.len(), dims[0] * dims[1] * dims[2]);
    for level in (0..levels).rev() {
        let corner = dims.map(|n| low_len(n, level));
        pass_rows(data, dims, corner, 2, true, scratch);
        pass_rows(data, dims, corner, 1, true, scratch);
        pass_x(data, dims, corner, true, scratch);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_odd_dims_and_levels() {
        let mut s = Vec::new();
        for dims in [[1, 1, 1], [2, 1, 1], [3, 5, 7], [34, 34, 34], [8, 1, 9], [17, 2, 3]] {
            let n = dims[0] * dims[1] * dims[2];
            let orig: Vec<i32> = (0..n).map(|i| ((i * 7919) % 1013) as i32 - 300).collect();
            for levels in 0..=3 {
                let mut d = orig.clone();
                forward(&mut d, dims, levels, &mut s);
                inverse(&mut d, dims, levels, &mut s);
                assert_eq!(d, orig, "dims {dims:?} levels {levels}");
            }
        }
    }

    #[test]
    fn smooth_data_concentrates_in_the_low_pass() {
        let dims = [16, 16, 16];
        let mut d: Vec<i32> = (0..4096i32).map(|i| (i % 16 + (i / 16) % 16 + i / 256) * 4).collect();
        forward(&mut d, dims, 1, &mut Vec::new());
        // A linear ramp is predicted exactly by the 5/3 predict step: the high-pass is zero away from the ends.
        let (x, y, z) = (9, 3, 3);
        assert_eq!(d[(z * 16 + y) * 16 + x], 0);
    }
}
