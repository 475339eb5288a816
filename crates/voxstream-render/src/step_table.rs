//! Transfer-function tables pre-corrected for the ray-march step: value → premultiplied colour and opacity of one
//! step, so the per-sample loop does a table lookup and no `exp`.
//!
//! A sample stands for a step of `Δt` world units; its opacity is `α = 1 − exp(−σ·Δt)` (the opacity correction of
//! GigaVoxels [P09] §6 and [R08] §5; VTK's fixed-point caster also tabulates it per sample distance). The traversal
//! ([`crate::traversal`]) only takes steps from a fixed geometric ladder `Δt_j = 2^(−j/4)` world units (each step a
//! quarter octave from the next, at most 19% shorter than asked for), so a handful of tables serve a whole frame, and
//! the correction stays exact where the step changes between segments: each sample reads the table of its own step.
//! Tables are built on first use and kept with the [`crate::TransferLut`] for the rest of the session.

use std::sync::OnceLock;

use glam::Vec4;

use crate::sampler::floor_index;
use crate::transfer_function::{LutEntry, LUT_SIZE};

/// Steps per octave of the ladder (the GPU's `choose_step` mirrors it, checked by voxstream-gpu's
/// `tests/shader_interface.rs`, as are the two below).
pub const STEPS_PER_OCTAVE: i32 = 4;
/// The ladder spans `2^±(LADDER_HALF / STEPS_PER_OCTAVE)` world units: `2^±128`, wider than any volume placement.
pub const LADDER_HALF: i32 = 512;
/// Ratio of consecutive rungs, `2^(1/4)`.
pub const RUNG_RATIO: f64 = 1.189_207_115_002_721;

/// One rung of the step ladder: the step length in world units and its index `j` (`Δt = 2^(−j/4)`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepLength {
    /// Index on the ladder.
    pub index: i32,
    /// World units per step.
    pub world: f64,
}

impl StepLength {
    /// The longest rung no longer than `desired` world units (`desired` positive and finite).
    #[inline]
    pub fn at_most(desired: f64) -> StepLength {
        let index = (-(STEPS_PER_OCTAVE as f64) * desired.log2()).ceil();
        let index = index.clamp(-(LADDER_HALF as f64), (LADDER_HALF - 1) as f64) as i32;
        StepLength { index, world: (-(index as f64) / STEPS_PER_OCTAVE as f64).exp2() }
    }

    /// The rung for `desired` as a ray's segments choose it: `current` while it still is the rung
    /// [`StepLength::at_most`] returns for `desired` (no logarithm), else that rung.
    #[inline]
    pub fn keep_or_at_most(current: Option<StepLength>, desired: f64) -> StepLength {
        match current {
            Some(current) if current.is_at_most(desired) => current,
            _ => StepLength::at_most(desired),
        }
    }

    /// Whether this rung is what [`StepLength::at_most`] returns for `desired` (cheap: no logarithm).
    #[inline]
    pub fn is_at_most(&self, desired: f64) -> bool {
        self.world <= desired && desired < self.world * RUNG_RATIO
    }
}

/// Premultiplied `[r·α, g·α, b·α, α]` of one step, tabulated like [`LutEntry`] (`LUT_SIZE` entries over the
/// normalised value range, linear between entries).
#[derive(Clone, Debug)]
pub struct StepTable {
    entries: Box<[Vec4; LUT_SIZE]>,
}

impl StepTable {
    /// The table for steps of `step` world units from the extinction table `lut`.
    pub fn new(lut: &[LutEntry], step: f64) -> StepTable {
        let mut entries = Box::new([Vec4::ZERO; LUT_SIZE]);
        for (entry, source) in entries.iter_mut().zip(lut) {
            let alpha = if source.sigma > 0.0 { -(-(source.sigma as f64) * step).exp_m1() as f32 } else { 0.0 };
            let [r, g, b] = source.color;
            *entry = Vec4::new(r * alpha, g * alpha, b * alpha, alpha);
        }
        StepTable { entries }
    }

    /// Premultiplied colour and opacity of one step at normalised `value` (linear between entries; clamped).
    #[inline(always)]
    pub fn lookup(&self, value: f32) -> Vec4 {
        let x = (value * (LUT_SIZE - 1) as f32).max(0.0).min((LUT_SIZE - 1) as f32);
        // Float operations only (see `floor_index`), and the index provably in the table (no bounds check).
        let (i, floor) = floor_index(x, LUT_SIZE as u32 - 2);
        let f = x - floor;
        let i = i as usize;
        let (a, b) = (self.entries[i], self.entries[i + 1]);
        a + (b - a) * f
    }
}

/// The tables of every rung used so far, built on demand (thread-safe: rays of one frame share them).
#[derive(Debug, Default)]
pub struct StepTables {
    rungs: OnceLock<Box<[OnceLock<StepTable>]>>,
}

impl Clone for StepTables {
    /// A clone starts empty: tables are a cache of the extinction table.
    fn clone(&self) -> StepTables {
        StepTables::default()
    }
}

impl StepTables {
    /// The table of `step`, built from `lut` on first use.
    #[inline]
    pub fn get(&self, lut: &[LutEntry], step: StepLength) -> &StepTable {
        let rungs = self.rungs.get_or_init(|| (0..2 * LADDER_HALF).map(|_| OnceLock::new()).collect());
        let slot = (step.index + LADDER_HALF).clamp(0, 2 * LADDER_HALF - 1) as usize;
        rungs[slot].get_or_init(|| StepTable::new(lut, step.world))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ladder_never_exceeds_the_desired_step_and_stays_within_a_quarter_octave() {
        for desired in [1e-6, 0.00390625, 0.01, 0.5, 1.0, 1.3, 1000.0] {
            let step = StepLength::at_most(desired);
            assert!(step.world <= desired * (1.0 + 1e-12), "{desired}: {}", step.world);
            assert!(step.world > desired * 2f64.powf(-0.25) * (1.0 - 1e-12), "{desired}: {}", step.world);
        }
        assert_eq!(StepLength::at_most(1.0), StepLength { index: 0, world: 1.0 });
        assert_eq!(StepLength::at_most(0.5).index, 4);
        assert!((RUNG_RATIO - 2f64.powf(0.25)).abs() < 1e-15);
        for desired in [0.01, 0.3, 0.5, 0.59, 0.6, 2.0] {
            let rung = StepLength::at_most(desired);
            assert!(rung.is_at_most(desired));
            assert!(!rung.is_at_most(desired * 1.2) && !rung.is_at_most(desired * 0.8), "{desired}");
        }
    }

    #[test]
    fn entries_are_the_opacity_of_one_step() {
        let lut: Vec<LutEntry> = (0..LUT_SIZE)
            .map(|i| LutEntry { color: [1.0, 0.5, 0.0], sigma: i as f32 / (LUT_SIZE - 1) as f32 * 2.0 })
            .collect();
        let table = StepTable::new(&lut, 0.25);
        let top = table.lookup(1.0);
        let alpha = 1.0 - (-2.0f32 * 0.25).exp();
        assert!((top.w - alpha).abs() < 1e-6);
        assert!((top.x - alpha).abs() < 1e-6 && (top.y - 0.5 * alpha).abs() < 1e-6 && top.z == 0.0);
        assert_eq!(table.lookup(0.0), Vec4::ZERO, "zero extinction is exactly transparent");
        assert_eq!(table.lookup(-3.0), Vec4::ZERO, "clamped below");
        // Two steps of half the length compose to one of the full length.
        let half = StepTable::new(&lut, 0.125).lookup(1.0).w;
        assert!((1.0 - (1.0 - half) * (1.0 - half) - alpha).abs() < 1e-6);
    }

    #[test]
    fn tables_are_cached_per_rung() {
        let lut = vec![LutEntry { color: [1.0; 3], sigma: 1.0 }; LUT_SIZE];
        let tables = StepTables::default();
        let a = tables.get(&lut, StepLength::at_most(0.5)) as *const StepTable;
        let b = tables.get(&lut, StepLength::at_most(0.5)) as *const StepTable;
        let c = tables.get(&lut, StepLength::at_most(0.2)) as *const StepTable;
        assert_eq!(a, b);
        assert_ne!(a, c);
    }
}
