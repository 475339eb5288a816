//! The entropy stage: wavelet coefficients → tokens under a small context model → static rANS, plus raw extra bits.
//!
//! Reichl §5.5 ends the brick codec with a Huffman coder (after [TRAW12]). A static Huffman code spends at least one
//! bit per coefficient, and at the error bounds that matter (≈ 50 dB) most coefficients are zero, so the floor would
//! be 1 bit per voxel; rANS (Duda's asymmetric numeral systems, in the interleaved 32-bit form of Giesen's
//! `rans_word`) codes a zero at p = 0.95 in 0.07 bits and decodes table-driven as fast. The example
//! `rate_distortion` prints what Huffman on the same tokens and contexts would cost, and zstd of the coefficients
//! (see `planes.rs`), so the choice is measured, not assumed.
//!
//! * **Tokens.** A coefficient c is zigzag-mapped to v (0, -1, 1, -2 … → 0, 1, 2, 3 …); v < 16 is its own token,
//!   larger v is token `11 + bitlen(v)` followed by `bitlen(v) - 1` raw bits (JPEG-style magnitude classes): at most
//!   44 tokens.
//! * **Contexts.** The subband level (the coarsest low-pass, then each detail level) times four classes of the
//!   neighbourhood `tok(x, y-1, z) + tok(x, y, z-1)`. Neighbours come from earlier rows only, never from the same
//!   row, so consecutive decodes do not wait on each other and two interleaved rANS states overlap.
//! * **Tables.** Per brick and context, frequencies normalised to 2^SCALE_BITS, sent as varints (a few dozen bytes).
//!
//! Decoding checks every length and every table sum and returns [`Corrupt`] instead of panicking; the rANS final
//! states must come back to their initial value, which catches most corruption of the token stream.

use crate::lift::low_len;

/// What was wrong with a payload: the codec wraps it in its own error.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Corrupt(pub &'static str);

/// Probability resolution: 2^11 slots per context table.
const SCALE_BITS: u32 = 11;
const M: u32 = 1 << SCALE_BITS;
const RANS_L: u32 = 1 << 16;
/// Number of tokens (see the module doc).
pub const NSYM: usize = 44;
/// Neighbourhood classes per subband level.
const NB: usize = 4;

#[inline(always)]
pub(crate) fn zigzag(c: i32) -> u32 {
    ((c << 1) ^ (c >> 31)) as u32
}

#[inline(always)]
pub(crate) fn unzigzag(v: u32) -> i32 {
    ((v >> 1) as i32) ^ -((v & 1) as i32)
}

#[inline(always)]
fn token(v: u32) -> u8 {
    if v < 16 {
        v as u8
    } else {
        (11 + 32 - v.leading_zeros()) as u8
    }
}

/// Neighbourhood class of the sum of two tokens (≤ 86).
const fn nb_lut() -> [u8; 2 * NSYM] {
    let mut t = [0u8; 2 * NSYM];
    let mut i = 0;
    while i < 2 * NSYM {
        t[i] = if i == 0 {
            0
        } else if i <= 2 {
            1
        } else if i <= 6 {
            2
        } else {
            3
        };
        i += 1;
    }
    t
}
const NB_LUT: [u8; 2 * NSYM] = nb_lut();

/// Per-axis subband level of each coordinate: the largest l ≤ levels with `x < low_len(n, l)`.
fn band_levels(n: usize, levels: u32) -> Vec<u8> {
    (0..n).map(|x| (0..=levels).rev().find(|&l| x < low_len(n, l)).unwrap_or(0) as u8).collect()
}

/// Number of contexts for a transform of `levels` levels.
pub(crate) fn n_contexts(levels: u32) -> usize {
    (levels as usize + 1) * NB
}

/// Visits every voxel in raster order with its context, given the tokens decoded or computed so far.
/// `f(i, ctx)` must set `tok[i]` before returning.
#[inline(always)]
fn for_each_context(dims: [usize; 3], levels: u32, tok: &mut [u8], mut f: impl FnMut(usize, usize, &mut [u8])) {
    let [nx, ny, nz] = dims;
    let (lx, ly, lz) = (band_levels(nx, levels), band_levels(ny, levels), band_levels(nz, levels));
    let slice = nx * ny;
    let mut i = 0;
    for (z, &bz) in lz.iter().enumerate().take(nz) {
        for (y, &by) in ly.iter().enumerate().take(ny) {
            let myz = by.min(bz);
            for &bx in lx.iter() {
                let a = if y > 0 { tok[i - nx] } else { 0 };
                let b = if z > 0 { tok[i - slice] } else { 0 };
                let ctx = bx.min(myz) as usize * NB + NB_LUT[(a + b) as usize] as usize;
                f(i, ctx, tok);
                i += 1;
            }
        }
    }
}

/// Normalises counts to frequencies summing to M (every seen token keeps at least 1).
fn normalise(counts: &[u32; NSYM]) -> [u32; NSYM] {
    let total: u64 = counts.iter().map(|&c| c as u64).sum();
    let mut f = [0u32; NSYM];
    if total == 0 {
        return f;
    }
    for (fi, &c) in f.iter_mut().zip(counts) {
        if c > 0 {
            *fi = (((c as u64 * M as u64) + total / 2) / total).max(1) as u32;
        }
    }
    let mut sum: i64 = f.iter().map(|&x| x as i64).sum();
    while sum != M as i64 {
        let big = (0..NSYM).max_by_key(|&s| f[s]).unwrap_or(0);
        if sum > M as i64 {
            let excess = (sum - M as i64).min(f[big] as i64 - 1).max(1);
            f[big] -= excess as u32;
            sum -= excess;
        } else {
            f[big] += (M as i64 - sum) as u32;
            sum = M as i64;
        }
    }
    f
}

fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// Reads a varint at `*pos`, advancing it.
pub(crate) fn get_varint(b: &[u8], pos: &mut usize) -> Result<u64, Corrupt> {
    let mut v = 0u64;
    for shift in (0..64).step_by(7) {
        let byte = *b.get(*pos).ok_or(Corrupt("truncated varint"))?;
        *pos += 1;
        v |= ((byte & 0x7f) as u64) << shift;
        if byte & 0x80 == 0 {
            return Ok(v);
        }
    }
    Err(Corrupt("varint too long"))
}

pub(crate) fn put_varint_pub(out: &mut Vec<u8>, v: u64) {
    put_varint(out, v)
}

struct BitWriter {
    bytes: Vec<u8>,
    acc: u64,
    n: u32,
}

impl BitWriter {
    fn put(&mut self, v: u32, bits: u32) {
        if bits == 0 {
            return;
        }
        self.acc |= (v as u64 & ((1u64 << bits) - 1)) << self.n;
        self.n += bits;
        while self.n >= 8 {
            self.bytes.push(self.acc as u8);
            self.acc >>= 8;
            self.n -= 8;
        }
    }
    fn finish(mut self) -> Vec<u8> {
        if self.n > 0 {
            self.bytes.push(self.acc as u8);
        }
        self.bytes
    }
}

struct BitReader<'a> {
    b: &'a [u8],
    pos: usize,
    acc: u64,
    n: u32,
}

impl BitReader<'_> {
    #[inline]
    fn get(&mut self, bits: u32) -> Result<u32, Corrupt> {
        while self.n < bits {
            let byte = *self.b.get(self.pos).ok_or(Corrupt("extra bits run out"))?;
            self.pos += 1;
            self.acc |= (byte as u64) << self.n;
            self.n += 8;
        }
        let v = (self.acc & ((1u64 << bits) - 1)) as u32;
        self.acc >>= bits;
        self.n -= bits;
        Ok(v)
    }
}

/// Sizes of one encoding, for the measurements.
#[derive(Debug, Default, Clone, Copy)]
pub struct Breakdown {
    /// Bytes of frequency tables.
    pub tables: usize,
    /// Bytes of the rANS stream.
    pub rans: usize,
    /// Bytes of raw extra bits.
    pub extra: usize,
    /// Bytes a static Huffman code of the same tokens and contexts would take instead of the rANS stream
    /// (code lengths by the textbook algorithm, tables not counted).
    pub huffman_estimate: usize,
}

/// Encodes the coefficients of a `levels`-level transform of a brick of `dims`, appending to `out`.
pub fn encode(coef: &[i32], dims: [usize; 3], levels: u32, tok: &mut Vec<u8>, out: &mut Vec<u8>) -> Breakdown {
    let n = coef.len();
    let nctx = n_contexts(levels);
    tok.clear();
    tok.resize(n, 0);
    let mut ctxs = vec![0u8; n];
    let mut counts = vec![[0u32; NSYM]; nctx];
    let mut extra = BitWriter { bytes: Vec::new(), acc: 0, n: 0 };
    for_each_context(dims, levels, tok, |i, ctx, tok| {
        let v = zigzag(coef[i]);
        let t = token(v);
        tok[i] = t;
        ctxs[i] = ctx as u8;
        counts[ctx][t as usize] += 1;
        if t >= 16 {
            let bits = t as u32 - 12;
            extra.put(v, bits);
        }
    });
    let freqs: Vec<[u32; NSYM]> = counts.iter().map(normalise).collect();
    let start = out.len();
    for f in &freqs {
        let used = f.iter().rposition(|&x| x > 0).map_or(0, |p| p + 1);
        out.push(used as u8);
        for &x in &f[..used] {
            put_varint(out, x as u64);
        }
    }
    let mut bd = Breakdown { tables: out.len() - start, ..Default::default() };
    let cum: Vec<[u32; NSYM]> = freqs
        .iter()
        .map(|f| {
            let mut c = [0u32; NSYM];
            for s in 1..NSYM {
                c[s] = c[s - 1] + f[s - 1];
            }
            c
        })
        .collect();
    // Interleaved rANS: symbol i goes to state i & 1; encode backwards, the decoder reads forwards.
    let mut words: Vec<u16> = Vec::with_capacity(n / 4 + 8);
    let mut st = [RANS_L; 2];
    for i in (0..n).rev() {
        let (ctx, t) = (ctxs[i] as usize, tok[i] as usize);
        let (freq, startf) = (freqs[ctx][t], cum[ctx][t]);
        let x = &mut st[i & 1];
        let x_max = (((RANS_L >> SCALE_BITS) as u64) << 16) * freq as u64;
        if *x as u64 >= x_max {
            words.push(*x as u16);
            *x >>= 16;
        }
        *x = ((*x / freq) << SCALE_BITS) + (*x % freq) + startf;
    }
    let rans_len = 8 + words.len() * 2;
    put_varint(out, rans_len as u64);
    out.extend_from_slice(&st[0].to_le_bytes());
    out.extend_from_slice(&st[1].to_le_bytes());
    for w in words.iter().rev() {
        out.extend_from_slice(&w.to_le_bytes());
    }
    bd.rans = rans_len;
    let extra = extra.finish();
    put_varint(out, extra.len() as u64);
    out.extend_from_slice(&extra);
    bd.extra = extra.len();
    bd.huffman_estimate = counts.iter().map(huffman_bits).sum::<u64>().div_ceil(8) as usize;
    bd
}

/// Total bits of a Huffman code for these counts (lengths from repeatedly merging the two lightest).
fn huffman_bits(counts: &[u32; NSYM]) -> u64 {
    let mut w: Vec<u64> = counts.iter().filter(|&&c| c > 0).map(|&c| c as u64).collect();
    if w.len() <= 1 {
        return w.first().copied().unwrap_or(0); // one symbol still costs a bit each in a Huffman coder
    }
    // The total code length equals the sum of all merged weights.
    let mut total = 0;
    while w.len() > 1 {
        w.sort_unstable_by(|a, b| b.cmp(a));
        let (a, b) = (w.pop().unwrap_or(0), w.pop().unwrap_or(0));
        total += a + b;
        w.push(a + b);
    }
    total
}

/// Reusable decoder state (tables and the token plane).
#[derive(Default)]
pub struct Scratch {
    table: Vec<u32>,
    tok: Vec<u8>,
}

/// Decodes the coefficients written by [`encode`] from `b[*pos..]` into `coef` (length = product of `dims`).
pub fn decode(
    b: &[u8],
    pos: &mut usize,
    dims: [usize; 3],
    levels: u32,
    coef: &mut [i32],
    sc: &mut Scratch,
) -> Result<(), Corrupt> {
    let n = coef.len();
    let nctx = n_contexts(levels);
    // Slots of unused contexts must read as zero (freq 0 → caught); used contexts overwrite all their slots.
    sc.table.resize(nctx * M as usize, 0);
    for c in 0..nctx {
        let used = *b.get(*pos).ok_or(Corrupt("truncated tables"))? as usize;
        *pos += 1;
        if used > NSYM {
            return Err(Corrupt("table has too many tokens"));
        }
        if used == 0 {
            sc.table[c * M as usize..(c + 1) * M as usize].fill(0);
        }
        let mut start = 0u32;
        let t = &mut sc.table[c * M as usize..(c + 1) * M as usize];
        for s in 0..used {
            let f = get_varint(b, pos)?;
            if f > (M - start) as u64 {
                return Err(Corrupt("table frequencies exceed the total"));
            }
            let f = f as u32;
            for (k, e) in t[start as usize..(start + f) as usize].iter_mut().enumerate() {
                *e = s as u32 | (f << 6) | ((k as u32) << 19);
            }
            start += f;
        }
        if used > 0 && start != M {
            return Err(Corrupt("table frequencies do not sum to the total"));
        }
    }
    let rans_len = get_varint(b, pos)?;
    if rans_len < 8 || rans_len > (b.len() - *pos) as u64 || rans_len % 2 != 0 {
        return Err(Corrupt("bad rANS stream length"));
    }
    let rans = &b[*pos..*pos + rans_len as usize];
    *pos += rans_len as usize;
    let extra_len = get_varint(b, pos)?;
    if extra_len > (b.len() - *pos) as u64 {
        return Err(Corrupt("bad extra-bits length"));
    }
    let mut extra = BitReader { b: &b[*pos..*pos + extra_len as usize], pos: 0, acc: 0, n: 0 };
    *pos += extra_len as usize;

    let mut st = [
        u32::from_le_bytes([rans[0], rans[1], rans[2], rans[3]]),
        u32::from_le_bytes([rans[4], rans[5], rans[6], rans[7]]),
    ];
    let words = &rans[8..];
    let mut wp = 0usize;
    let mut bad = false;
    sc.tok.clear();
    sc.tok.resize(n, 0);
    let table = &sc.table;
    let mut err = Ok(());
    for_each_context(dims, levels, &mut sc.tok, |i, ctx, tok| {
        let x = &mut st[i & 1];
        let e = table[ctx * M as usize + (*x & (M - 1)) as usize];
        let (s, f, bias) = (e & 63, (e >> 6) & 0x1fff, e >> 19);
        // An empty context's slots are all zero (freq 0): corrupt input, caught below via `bad`.
        bad |= f == 0;
        *x = f.wrapping_mul(*x >> SCALE_BITS).wrapping_add(bias);
        if *x < RANS_L {
            if let Some(w) = words.get(wp..wp + 2) {
                *x = (*x << 16) | u16::from_le_bytes([w[0], w[1]]) as u32;
            } else {
                bad = true;
            }
            wp += 2;
        }
        tok[i] = s as u8;
        let v = if s < 16 {
            s
        } else {
            let bits = s - 12;
            match extra.get(bits) {
                Ok(r) => (1u32 << bits) | r,
                Err(e) => {
                    err = Err(e);
                    0
                }
            }
        };
        coef[i] = unzigzag(v);
    });
    err?;
    if bad || st != [RANS_L; 2] || wp != words.len() {
        return Err(Corrupt("rANS stream does not decode to its end state"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zigzag_round_trips_extremes() {
        for c in [0, 1, -1, 2, -2, 1000, -1000, i32::MAX, i32::MIN] {
            assert_eq!(unzigzag(zigzag(c)), c);
        }
        assert_eq!(token(u32::MAX) as usize, NSYM - 1);
    }

    #[test]
    fn coefficients_round_trip() {
        let dims = [7, 5, 9];
        let n = 7 * 5 * 9;
        let coef: Vec<i32> =
            (0..n).map(|i| if i % 3 == 0 { 0 } else { ((i * 2654435761usize) >> 7) as i32 % 70000 - 35000 }).collect();
        let mut out = Vec::new();
        encode(&coef, dims, 2, &mut Vec::new(), &mut out);
        let mut back = vec![0; n];
        let mut pos = 0;
        decode(&out, &mut pos, dims, 2, &mut back, &mut Scratch::default()).unwrap();
        assert_eq!(pos, out.len());
        assert_eq!(back, coef);
        let mut ext = vec![i32::MIN, i32::MAX, 0, -1];
        ext.resize(8, 5);
        out.clear();
        encode(&ext, [2, 2, 2], 1, &mut Vec::new(), &mut out);
        let mut back = vec![0; 8];
        decode(&out, &mut 0, [2, 2, 2], 1, &mut back, &mut Scratch::default()).unwrap();
        assert_eq!(back, ext);
    }
}
