//! The eight corners of the rays' cells read with AVX2 gathers: four instructions for the [`LANES`] lanes instead
//! of sixty-four loads (issue: a ray caster faster than VTK's, item 3, "`std::arch` behind safe wrappers").
//!
//! Each gather reads one 32-bit word per lane at the byte where a pair of corners that are neighbours along `x`
//! begins (corners `0/1`, `2/3`, `4/5`, `6/7`): for `u8` voxels its bytes 0 and 1 are the two corners, for `u16` its
//! halves. The corners are converted to `f32` as [`Voxel::stored`] does (exactly: integers below 2²⁴), so the samples
//! are the same bits as the scalar reads' (a test compares them on every cell of a brick pool).
//!
//! This is the one module of the workspace with `unsafe` code. [`CornerGather::new`] checks once per frame that the
//! CPU has AVX2. [`CornerGather::read`] checks per call that the voxels are `u8` or `u16` (by type, not size), that
//! the last word read lies inside them and that every byte offset fits the gathers' 32-bit indices (sums and
//! products that would overflow fail the check); otherwise it reads through slices. The offsets it is given are
//! those of cells inside bricks (positions clamped into the brick), so in the ray loop the check fails only for the
//! last cells of the pool's last brick with `u8` voxels, whose last word reaches two bytes past the pool, and for
//! pools over 2 GiB.

#![allow(unsafe_code)]

use voxstream_core::Voxel;

use crate::sampler::LANES;

/// Reads corners with gathers where the CPU and the pool allow it (see the module docs).
#[derive(Clone, Copy, Debug)]
pub struct CornerGather {
    /// Whether the gathers may run: AVX2 wanted and present.
    enabled: bool,
}

impl CornerGather {
    /// Gathers where `use_avx2` (the ray loop runs its AVX2 build) and the CPU has AVX2.
    pub fn new(use_avx2: bool) -> CornerGather {
        CornerGather { enabled: use_avx2 && has_avx2() }
    }

    /// Reads that never gather (the reference path).
    pub const SCALAR: CornerGather = CornerGather { enabled: false };

    /// Whether [`CornerGather::read`] gathers.
    pub fn is_enabled(self) -> bool {
        self.enabled
    }

    /// The corners (`[corner][lane]`, corner = x + 2y + 4z) of the cells whose first voxel is `at[j]` in `voxels`,
    /// with rows of `row` and slabs of `slab` voxels. Panics, as slice reads do, if a cell reaches past `voxels`.
    #[inline(always)]
    pub fn read<V: Voxel>(self, voxels: &[V], at: &[u32; LANES], row: usize, slab: usize) -> [[f32; LANES]; 8] {
        match self.try_gather(voxels, at, row, slab) {
            Some(corners) => corners,
            None => scalar(voxels, at, row, slab),
        }
    }

    /// [`CornerGather::read`] by gathers, or `None` where they may not run: gathers disabled, a voxel type other
    /// than `u8` and `u16`, a word that would reach past `voxels`, or offsets beyond `i32` (arithmetic that would
    /// overflow counts as beyond).
    #[inline(always)]
    fn try_gather<V: Voxel>(
        self,
        voxels: &[V],
        at: &[u32; LANES],
        row: usize,
        slab: usize,
    ) -> Option<[[f32; LANES]; 8]> {
        #[cfg(target_arch = "x86_64")]
        if self.enabled {
            use std::any::TypeId;
            let (narrow, wide) = (TypeId::of::<V>() == TypeId::of::<u8>(), TypeId::of::<V>() == TypeId::of::<u16>());
            let size = size_of::<V>();
            let bytes = size_of_val(voxels);
            // The word at the last pair's first voxel: 4 bytes from `last · size`; every other word starts before.
            let last = (at.iter().copied().max().unwrap_or(0) as usize).checked_add(slab)?.checked_add(row)?;
            let end = last.checked_mul(size)?.checked_add(4)?;
            if (narrow || wide) && end <= bytes && bytes <= i32::MAX as usize {
                // SAFETY: `enabled` says the CPU has AVX2 (checked at run time in `new`), so the `avx2` function may
                // run; `V` is `u8` or `u16` (type ids above), so every byte of `voxels` is initialised and a word's
                // bytes are two corners. Every word read starts at byte `(at[j] + o) · size ≤ last · size` for
                // `o ≤ slab + row` and ends 4 bytes later, inside `voxels` (`end ≤ bytes`), and every byte offset
                // is below `bytes ≤ i32::MAX`.
                return Some(unsafe { gather_avx2::<V>(voxels, at, row * size, slab * size) });
            }
        }
        let _ = (voxels, at, row, slab);
        None
    }
}

/// The corners read one by one (the reference).
#[inline(always)]
fn scalar<V: Voxel>(voxels: &[V], at: &[u32; LANES], row: usize, slab: usize) -> [[f32; LANES]; 8] {
    let mut corners = [[0f32; LANES]; 8];
    let offsets = [0, 1, row, row + 1, slab, slab + 1, slab + row, slab + row + 1];
    for j in 0..LANES {
        let at = at[j] as usize;
        let cell = &voxels[at..at + slab + row + 2];
        for (corner, &offset) in offsets.iter().enumerate() {
            corners[corner][j] = cell[offset].stored();
        }
    }
    corners
}

fn has_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Four gathers of 32-bit words, split into the eight corners: lane `j`'s pairs start at byte
/// `first[j] · size_of::<V>()`, `+ row_bytes`, `+ slab_bytes` and `+ slab_bytes + row_bytes`.
///
/// # Safety
/// The CPU must have AVX2; `V` must be `u8` or `u16`; every word read (4 bytes from each of those byte offsets)
/// must lie inside `voxels`, and every such offset must be below `i32::MAX`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn gather_avx2<V: Voxel>(
    voxels: &[V],
    first: &[u32; LANES],
    row_bytes: usize,
    slab_bytes: usize,
) -> [[f32; LANES]; 8] {
    use std::arch::x86_64::*;
    const { assert!(LANES == 8) };
    let narrow = size_of::<V>() == 1;
    let base = voxels.as_ptr() as *const i32;
    // SAFETY: `first` is 8 `u32`s; an unaligned 256-bit load reads exactly them.
    let voxel = unsafe { _mm256_loadu_si256(first.as_ptr() as *const __m256i) };
    // In bytes: twice the voxel index for `u16`.
    let first = if narrow { voxel } else { _mm256_add_epi32(voxel, voxel) };
    let word = |offset: usize| {
        // Below `i32::MAX` by the caller's guarantee, as is each sum.
        let at = _mm256_add_epi32(first, _mm256_set1_epi32(offset as i32));
        // SAFETY: the caller guarantees every word at these byte offsets lies inside `voxels`.
        unsafe { _mm256_i32gather_epi32::<1>(base, at) }
    };
    // A word holds the pair's two voxels: bytes 0 and 1 (`u8`), or its two halves (`u16`), little-endian.
    let split = |w: __m256i| -> (__m256, __m256) {
        if narrow {
            let byte = _mm256_set1_epi32(0xff);
            (
                _mm256_cvtepi32_ps(_mm256_and_si256(w, byte)),
                _mm256_cvtepi32_ps(_mm256_and_si256(_mm256_srli_epi32::<8>(w), byte)),
            )
        } else {
            let half = _mm256_set1_epi32(0xffff);
            (_mm256_cvtepi32_ps(_mm256_and_si256(w, half)), _mm256_cvtepi32_ps(_mm256_srli_epi32::<16>(w)))
        }
    };
    let mut corners = [[0f32; LANES]; 8];
    for (pair, offset) in [0, row_bytes, slab_bytes, slab_bytes + row_bytes].into_iter().enumerate() {
        let (a, b) = split(word(offset));
        // SAFETY: each corner row is 8 `f32`s; unaligned stores write exactly them.
        unsafe {
            _mm256_storeu_ps(corners[2 * pair].as_mut_ptr(), a);
            _mm256_storeu_ps(corners[2 * pair + 1].as_mut_ptr(), b);
        }
    }
    corners
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every cell of every brick of `pool`, eight at a time with the lanes spread over the pool: gathered (where
    /// allowed) and read through slices, bit for bit. Returns how many reads gathered.
    fn check<V: Voxel + std::fmt::Debug>(pool: &[V], b: usize) -> usize {
        let gather = CornerGather::new(true);
        let (row, slab) = (b, b * b);
        let bricks = pool.len() / (b * b * b);
        let cells: Vec<u32> = (0..bricks)
            .flat_map(|brick| {
                (0..(b - 1).pow(3)).map(move |c| {
                    let (i, j, k) = (c % (b - 1), c / (b - 1) % (b - 1), c / (b - 1) / (b - 1));
                    (brick * b * b * b + (k * b + j) * b + i) as u32
                })
            })
            .collect();
        let mut gathered = 0;
        for (n, chunk) in cells.chunks(LANES).enumerate() {
            let at: [u32; LANES] = std::array::from_fn(|j| chunk[(j * 3 + n) % chunk.len()]);
            let reference = scalar(pool, &at, row, slab);
            assert_eq!(
                gather.read(pool, &at, row, slab).map(|c| c.map(f32::to_bits)),
                reference.map(|c| c.map(f32::to_bits)),
                "cells {at:?}"
            );
            if let Some(corners) = gather.try_gather(pool, &at, row, slab) {
                assert_eq!(corners.map(|c| c.map(f32::to_bits)), reference.map(|c| c.map(f32::to_bits)));
                gathered += 1;
            }
        }
        gathered
    }

    #[test]
    fn gathers_run_where_the_cpu_has_avx2() {
        assert_eq!(CornerGather::new(true).is_enabled(), has_avx2());
        assert!(!CornerGather::new(false).is_enabled() && !CornerGather::SCALAR.is_enabled());
    }

    #[test]
    fn gathered_corners_are_the_scalar_corners_bit_for_bit() {
        let b: usize = 6;
        let narrow: Vec<u8> = (0..3 * b * b * b).map(|i| (i * 37 + 11) as u8).collect();
        let wide: Vec<u16> = (0..3 * b * b * b).map(|i| (i * 7919 + 13) as u16).collect();
        let reads = (3 * (b - 1).pow(3)).div_ceil(LANES);
        let (narrow_gathered, wide_gathered) = (check(&narrow, b), check(&wide, b));
        if has_avx2() {
            // Every read of the 16-bit pool gathers; of the 8-bit pool, all but those whose cells include one of
            // the last brick's last cells (their last word would reach two bytes past the pool).
            assert_eq!(wide_gathered, reads);
            assert!(narrow_gathered > reads * 9 / 10 && narrow_gathered < reads, "{narrow_gathered} of {reads}");
        } else {
            assert_eq!((narrow_gathered, wide_gathered), (0, 0));
        }
    }

    #[test]
    fn reads_that_could_leave_the_voxels_do_not_gather() {
        let gather = CornerGather::new(true);
        // The last cell of a one-brick u8 pool: its last word would reach two bytes past the pool.
        let b = 4;
        let pool: Vec<u8> = (0..b * b * b).map(|i| i as u8).collect();
        let last = ((b - 2) * b * b + (b - 2) * b + (b - 2)) as u32;
        assert!(gather.try_gather(&pool, &[last; LANES], b, b * b).is_none());
        let corners = gather.read(&pool, &[last; LANES], b, b * b);
        assert_eq!(corners[7], [(b * b * b - 1) as f32; LANES]);
        assert_eq!(corners[0], [last as f32; LANES]);
        // Its neighbour's last word still reaches a byte past; the cell two before ends exactly at the pool's end,
        // and gathers where the CPU can.
        assert!(gather.try_gather(&pool, &[last - 1; LANES], b, b * b).is_none());
        assert_eq!(gather.try_gather(&pool, &[last - 2; LANES], b, b * b).is_some(), has_avx2());
        // Sizes whose sums or products wrap around never gather.
        assert!(gather.try_gather(&pool, &[0; LANES], 100, usize::MAX - 99).is_none());
        assert!(gather.try_gather(&pool, &[0; LANES], usize::MAX, 1).is_none());
        let wide: Vec<u16> = vec![0; 64];
        assert!(gather.try_gather(&wide, &[0; LANES], usize::MAX / 2, 1).is_none());
        // Only u8 and u16 voxels gather.
        #[derive(Clone, Copy)]
        struct Padded(u8);
        impl Voxel for Padded {
            fn stored(self) -> f32 {
                self.0 as f32
            }
            fn value(stored: f32, dq: voxstream_core::Dequantize) -> f32 {
                dq.value(stored)
            }
        }
        let odd = vec![Padded(1); 64];
        assert!(gather.try_gather(&odd, &[0; LANES], 4, 16).is_none());
    }
}
