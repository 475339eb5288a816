//! The eight corners of the rays' cells read with AVX2 gathers: four instructions for the [`LANES`] lanes instead
//! of sixty-four loads (issue: a ray caster faster than VTK's, item 3, "`std::arch` behind safe wrappers").
//!
//! Each gather reads one 32-bit word per lane at the byte where a pair of corners that are neighbours along `x`
//! begins (corners `0/1`, `2/3`, `4/5`, `6/7`): for `u8` voxels its bytes 0 and 1 are the two corners, for `u16` its
//! halves. The corners are converted to `f32` as [`Voxel::stored`] does (exactly: integers below 2²⁴), so the samples
//! are the same bits as the scalar reads' (a test compares them on every cell of a brick pool).
//!
//! This is the one module of the workspace with `unsafe` code. [`CornerGather::new`] checks once per frame that the
//! CPU has AVX2; [`CornerGather::read`] checks per call that the last word read lies inside the voxels and that
//! every byte offset fits the gathers' 32-bit indices, and reads through slices otherwise. The offsets
//! it is given are those of cells inside bricks (positions clamped into the brick), so the check fails only for the
//! last cells of the pool's last brick with `u8` voxels, whose last word reaches two bytes past the pool.

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
        #[cfg(target_arch = "x86_64")]
        if self.enabled && (size_of::<V>() == 1 || size_of::<V>() == 2) {
            let last = at.iter().copied().max().unwrap_or(0) as usize + slab + row;
            let bytes = size_of_val(voxels);
            // The word at the last pair's first voxel: 4 bytes from `last · size`.
            if last * size_of::<V>() + 4 <= bytes && bytes <= i32::MAX as usize {
                // SAFETY: `enabled` says the CPU has AVX2 (checked at run time in `new`), so the `avx2` function may
                // run. Every word read starts at byte `(at[j] + offset) · size ≤ last · size` and ends 4 bytes later,
                // inside `voxels` by the test above, and every byte offset fits `i32`.
                return unsafe { gather_avx2::<V>(voxels, at, row, slab) };
            }
        }
        scalar(voxels, at, row, slab)
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

/// Four gathers of 32-bit words, split into the eight corners.
///
/// # Safety
/// The CPU must have AVX2; `V` must be one or two bytes; every word read (4 bytes from byte `(at[j] + o) · size` for
/// `o` in `0, row, slab, slab + row`) must lie inside `voxels`, and those byte offsets must fit in `i32`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn gather_avx2<V: Voxel>(voxels: &[V], at: &[u32; LANES], row: usize, slab: usize) -> [[f32; LANES]; 8] {
    use std::arch::x86_64::*;
    const { assert!(LANES == 8) };
    let size = size_of::<V>() as i32;
    let base = voxels.as_ptr() as *const i32;
    // SAFETY: `at` is 8 `u32`s, an unaligned 256-bit load reads exactly them.
    let first =
        _mm256_mullo_epi32(unsafe { _mm256_loadu_si256(at.as_ptr() as *const __m256i) }, _mm256_set1_epi32(size));
    let word = |offset: usize| {
        let offsets = _mm256_add_epi32(first, _mm256_set1_epi32(offset as i32 * size));
        // SAFETY: the caller guarantees every word at these byte offsets lies inside `voxels`.
        unsafe { _mm256_i32gather_epi32::<1>(base, offsets) }
    };
    let (low, high) = if size == 1 {
        let mask = _mm256_set1_epi32(0xff);
        (mask, mask)
    } else {
        let mask = _mm256_set1_epi32(0xffff);
        (mask, mask)
    };
    let split = |w: __m256i| -> (__m256, __m256) {
        let first = _mm256_cvtepi32_ps(_mm256_and_si256(w, low));
        let second = if size == 1 {
            _mm256_cvtepi32_ps(_mm256_and_si256(_mm256_srli_epi32::<8>(w), high))
        } else {
            _mm256_cvtepi32_ps(_mm256_srli_epi32::<16>(w))
        };
        (first, second)
    };
    let mut corners = [[0f32; LANES]; 8];
    for (pair, offset) in [0, row, slab, slab + row].into_iter().enumerate() {
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

    fn check<V: Voxel + std::fmt::Debug>(pool: &[V], b: usize) {
        let gather = CornerGather::new(true);
        let (row, slab) = (b, b * b);
        let bricks = pool.len() / (b * b * b);
        // Every cell of every brick, eight at a time, lanes spread over the bricks.
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
            let mut at = [0u32; LANES];
            for j in 0..LANES {
                // Interleave: lane j reads cells from different parts of the pool.
                at[j] = chunk[(j * 3 + n) % chunk.len()];
            }
            let reference = scalar(pool, &at, row, slab);
            let read = gather.read(pool, &at, row, slab);
            assert_eq!(read.map(|c| c.map(f32::to_bits)), reference.map(|c| c.map(f32::to_bits)), "cells {at:?}");
            let last = at.iter().copied().max().unwrap_or(0) as usize + slab + row;
            gathered += (last * size_of::<V>() + 4 <= size_of_val(pool)) as u32;
        }
        // Most calls gathered (only the pool's last cells fall back for u8); on a CPU without AVX2, none did.
        if gather.is_enabled() {
            assert!(gathered as usize > cells.len() / LANES / 2, "{gathered} of {}", cells.len() / LANES);
        }
    }

    #[test]
    fn gathers_run_where_the_cpu_has_avx2() {
        assert_eq!(CornerGather::new(true).is_enabled(), has_avx2());
        assert!(!CornerGather::new(false).is_enabled() && !CornerGather::SCALAR.is_enabled());
    }

    #[test]
    fn gathered_corners_are_the_scalar_corners_bit_for_bit() {
        let b = 6;
        let narrow: Vec<u8> = (0..3 * b * b * b).map(|i| (i * 37 + 11) as u8).collect();
        let wide: Vec<u16> = (0..3 * b * b * b).map(|i| (i * 7919 + 13) as u16).collect();
        check(&narrow, b);
        check(&wide, b);
    }

    #[test]
    fn reads_past_the_pool_fall_back_to_slices() {
        // The last cell of a one-brick u8 pool: its last word would reach two bytes past the pool.
        let b = 4;
        let pool: Vec<u8> = (0..b * b * b).map(|i| i as u8).collect();
        let at = [((b - 2) * b * b + (b - 2) * b + (b - 2)) as u32; LANES];
        let corners = CornerGather::new(true).read(&pool, &at, b, b * b);
        assert_eq!(corners[7], [(b * b * b - 1) as f32; LANES]);
        assert_eq!(corners[0], [at[0] as f32; LANES]);
    }
}
