//! The measured alternative to rANS: zstd of the zigzag-mapped coefficients split into byte planes (all low bytes,
//! then all second bytes, …), so zstd sees the mostly-zero high planes as long runs.
//!
//! Issue 47 asks to pick the entropy stage by measurement; the codec can write either ([`crate::Entropy`]) and
//! `examples/rate_distortion.rs` reports both.

use crate::rans::{unzigzag, zigzag, Corrupt};

/// Appends `nbytes` (u8), then the zstd frame length (u32 LE) and the frame.
pub fn encode(coef: &[i32], level: i32, out: &mut Vec<u8>) {
    let max = coef.iter().map(|&c| zigzag(c)).max().unwrap_or(0);
    let nbytes = (4 - max.leading_zeros() / 8).max(1) as usize;
    let mut planes = vec![0u8; coef.len() * nbytes];
    for (i, &c) in coef.iter().enumerate() {
        let v = zigzag(c);
        for b in 0..nbytes {
            planes[b * coef.len() + i] = (v >> (8 * b)) as u8;
        }
    }
    let z = zstd::bulk::compress(&planes, level).unwrap_or_default();
    out.push(nbytes as u8);
    out.extend_from_slice(&(z.len() as u32).to_le_bytes());
    out.extend_from_slice(&z);
}

/// Decodes what [`encode`] wrote at `b[*pos..]` into `coef`.
pub fn decode(b: &[u8], pos: &mut usize, coef: &mut [i32], buf: &mut Vec<u8>) -> Result<(), Corrupt> {
    let head = b.get(*pos..*pos + 5).ok_or(Corrupt("truncated plane header"))?;
    let nbytes = head[0] as usize;
    let len = u32::from_le_bytes([head[1], head[2], head[3], head[4]]) as usize;
    *pos += 5;
    if !(1..=4).contains(&nbytes) {
        return Err(Corrupt("bad plane count"));
    }
    let frame = b.get(*pos..).and_then(|r| r.get(..len)).ok_or(Corrupt("truncated zstd frame"))?;
    *pos += len;
    let want = coef.len() * nbytes;
    buf.clear();
    buf.reserve(want);
    // Bounded: zstd refuses to write more than the capacity we computed from the validated dims.
    let got = zstd::bulk::Decompressor::new()
        .and_then(|mut d| d.decompress_to_buffer(frame, buf))
        .map_err(|_| Corrupt("zstd frame does not decode"))?;
    if got != want {
        return Err(Corrupt("zstd frame has the wrong size"));
    }
    let n = coef.len();
    for (i, c) in coef.iter_mut().enumerate() {
        let mut v = 0u32;
        for b in 0..nbytes {
            v |= (buf[b * n + i] as u32) << (8 * b);
        }
        *c = unzigzag(v);
    }
    Ok(())
}
