//! Empty-space skipping inside a brick (step 4 of [`super`]'s walk): the runs of a segment's samples that lie in
//! occupancy blocks whose values can contribute, from the blocks' min/max ranges or from the integrand's per-block
//! bits ([`crate::block_visibility`]). Skipping never moves a sample: a run's samples are the segment's own.

use voxstream_core::BLOCK_CELLS;

use super::bricks::BrickLine;
use super::Traversal;
use crate::block_visibility::BrickBlocks;
use crate::integrand::Integrand;
use crate::sampler::{floor_index, Cell, LANES};

impl<'a> Traversal<'a> {
    /// Which occupancy blocks (fine, and coarse if blended) hold sample `k` of a segment (`first + k·dt`, `count`
    /// samples), whether the integrand can use their values, and the first sample past them: `(true, end)` when it
    /// can (samples up to the blocks' exit need no check; one past it would be harmless, it is sampled),
    /// `(false, next)` when it cannot (every sample before `next`, the exit less a margin above f32 rounding, is in
    /// these blocks). Always past `k`.
    #[inline(always)]
    pub(super) fn check_blocks<I: Integrand>(
        &self,
        fine: &BrickLine<'_>,
        coarse: Option<&BrickLine<'_>>,
        (first, dt, count): (f64, f64, u32),
        k: u32,
        integrand: &I,
    ) -> (bool, u32) {
        let blocks = self.view.shape.blocks_per_axis();
        let fine_cell = Cell::locate(self.stored, fine.at(k as f32));
        let [mut lo, mut hi] = self.view.block_range(fine.slot, fine_cell.block(blocks));
        let mut exit = block_exit(fine, fine_cell.block_ijk());
        if let Some(line) = coarse {
            let coarse_cell = Cell::locate(self.stored, line.at(k as f32));
            let [clo, chi] = self.view.block_range(line.slot, coarse_cell.block(blocks));
            lo = lo.min(clo);
            hi = hi.max(chi);
            exit = exit.min(block_exit(line, coarse_cell.block_ijk()));
        }
        let contributes = integrand.can_contribute(lo, hi);
        let boundary = if contributes { (exit - first) / dt } else { (exit - 1e-3 * dt - first) / dt }.ceil();
        // `boundary` is a whole number; below 2⁵², it is the mantissa of `2⁵² + boundary` (float operations only,
        // like `floor_index`: a saturating conversion is several instructions).
        const TWO_POW_52: f64 = 4_503_599_627_370_496.0;
        let past = if boundary > k as f64 {
            ((boundary.min(count as f64) + TWO_POW_52).to_bits() - TWO_POW_52.to_bits()) as u32
        } else {
            k + 1
        };
        (contributes, past)
    }

    /// The next run of samples at or after `k` of a segment whose blocks can contribute, as `(start, end, resume)`
    /// (see [`Traversal::next_run`]): from the integrand's block bits when it has them and the segment samples one
    /// brick ([`Traversal::visible_run`]: runs as long as the blocks allow, `long_run` does not apply), else from the
    /// blocks' ranges.
    #[inline(always)]
    pub(super) fn run_from<I: Integrand>(
        &self,
        fine: &BrickLine<'_>,
        coarse: Option<&BrickLine<'_>>,
        segment: (f64, f64, u32),
        k: u32,
        long_run: u32,
        integrand: &I,
    ) -> Option<(u32, u32, Option<u32>)> {
        match (coarse, integrand.block_visibility()) {
            (None, Some(visibility)) => {
                let bits = visibility.of_brick(&self.view, fine.slot, |lo, hi| integrand.can_contribute(lo, hi));
                self.visible_run(fine, bits, segment.2, k).map(|(start, end)| (start, end, None))
            }
            _ => self.next_run(fine, coarse, segment, k, long_run, integrand),
        }
    }

    /// The first run `start..end` of samples at or after `k` (of `count`) of a brick line whose cells lie in blocks
    /// whose bits say they can contribute: every sample of the run does, the one at `end` (if any) does not. Eight
    /// samples at a time ([`Traversal::visible_mask`]). `None` when no sample is left that can.
    #[inline(always)]
    pub(super) fn visible_run(
        &self,
        line: &BrickLine<'_>,
        bits: BrickBlocks<'_>,
        count: u32,
        mut k: u32,
    ) -> Option<(u32, u32)> {
        const ALL: u32 = (1 << LANES) - 1;
        let (start, mut cannot) = loop {
            if k >= count {
                return None;
            }
            let mask = self.visible_mask(line, bits, k, count);
            if mask != 0 {
                let offset = mask.trailing_zeros();
                // The samples of this eight from the start on that cannot contribute (or lie past `count`).
                break (k + offset, !mask & ALL & (ALL << offset));
            }
            k += LANES as u32;
        };
        // Samples past `count` read as "cannot", so the run ends at `count` at the latest.
        loop {
            if cannot != 0 {
                return Some((start, k + cannot.trailing_zeros()));
            }
            k += LANES as u32;
            cannot = !self.visible_mask(line, bits, k, count) & ALL;
        }
    }

    /// Bit `j` set when sample `k + j` (`j < LANES`, `k + j < count`) of a brick line lies in a cell whose block can
    /// contribute. The cells are located as [`Cell::locate`] and the samplers locate them (the position
    /// `start + k·delta` in `f32`, clamped to the brick), so a sample's bit is the bit of the block it reads. Written
    /// out lane by lane in `u32`, as `sampler::corners_across` is, rather than through `Cell::locate(..).block(..)`
    /// (`usize` indices): that version computes the same blocks but made the frame 1.4× slower (mni-soft 240 →
    /// 344 ms).
    #[inline(always)]
    pub(super) fn visible_mask(&self, line: &BrickLine<'_>, bits: BrickBlocks<'_>, k: u32, count: u32) -> u32 {
        let b = self.stored;
        let max = (b - 1) as f32;
        let last_cell = b as u32 - 2;
        let blocks = self.blocks_per_axis as u32;
        let kf = k as f32;
        let mut block = [0u32; LANES];
        for (j, block) in block.iter_mut().enumerate() {
            // `k + j` as a float: exact below 2²⁴, the same bits as the samplers' counters.
            let kj = kf + j as f32;
            let mut index = 0;
            for a in (0..3).rev() {
                let c = (line.start[a] + kj * line.delta[a]).max(0.0).min(max);
                let (i, _) = floor_index(c, last_cell);
                index = index * blocks + i / BLOCK_CELLS as u32;
            }
            *block = index;
        }
        let mut mask = 0;
        for (j, &block) in block.iter().enumerate() {
            if k + (j as u32) < count && bits.contributes(block as usize) {
                mask |= 1 << j;
            }
        }
        mask
    }

    /// The next run of samples at or after `k` whose blocks can contribute, as `(start, end, resume)`: one run
    /// through the following blocks that can contribute too, until it holds `long_run` samples, and `resume`, where the next run may start when this one ends at blocks that
    /// cannot contribute (already checked). `None` when no sample is left.
    #[inline(always)]
    pub(super) fn next_run<I: Integrand>(
        &self,
        fine: &BrickLine<'_>,
        coarse: Option<&BrickLine<'_>>,
        segment: (f64, f64, u32),
        mut k: u32,
        long_run: u32,
        integrand: &I,
    ) -> Option<(u32, u32, Option<u32>)> {
        let count = segment.2;
        while k < count {
            let (contributes, past) = self.check_blocks(fine, coarse, segment, k, integrand);
            if !contributes {
                k = past;
                continue;
            }
            let mut end = past;
            while end < count && end - k < long_run {
                let (contributes, past) = self.check_blocks(fine, coarse, segment, end, integrand);
                if !contributes {
                    return Some((k, end, Some(past)));
                }
                end = past;
            }
            return Some((k, end, None));
        }
        None
    }
}

/// The `t` at which a brick line leaves the occupancy block at `ijk` (block coordinates).
#[inline]
pub(super) fn block_exit(line: &BrickLine<'_>, ijk: [usize; 3]) -> f64 {
    let mut exit = f64::INFINITY;
    for (a, &block) in ijk.iter().enumerate() {
        let rate = line.rate[a];
        let edge = if rate > 0.0 {
            ((block + 1) * BLOCK_CELLS) as f64
        } else if rate < 0.0 {
            (block * BLOCK_CELLS) as f64
        } else {
            continue;
        };
        exit = exit.min((edge - line.origin[a]) * line.inverse_rate[a]);
    }
    exit
}

#[cfg(test)]
mod tests {
    use super::super::test_tree::{ray, Child, Record, TestTree};
    use super::super::{DescentPath, RayStats};
    use crate::settings::RenderSettings;

    /// Skipping bricks and blocks whose values cannot contribute drops exactly such samples: every sample kept is
    /// the same bits as without skipping, at the same place.
    #[test]
    fn skipping_drops_only_samples_that_cannot_contribute() {
        let ramp = |p: glam::DVec3| (2.5 * (p.x - 0.6)).max(0.0);
        let tree = TestTree::new(ramp, ramp, [Child::Brick; 8]);
        let threshold = 0.05;
        let trace = |skip_empty_space: bool| {
            let settings = RenderSettings { skip_empty_space, ..RenderSettings::default() };
            let feedback = tree.feedback();
            let traversal = tree.traversal(&feedback, &settings);
            let mut record = Record { threshold: Some(threshold), ..Record::default() };
            let ray = ray([-0.5, 0.3, 0.6], [1.0, 0.02, -0.03]);
            traversal.trace(
                &ray,
                &mut record,
                &mut RayStats::default(),
                &mut Vec::new(),
                &mut DescentPath::new(tree.view()),
            );
            record.samples
        };
        let (all, kept) = (trace(false), trace(true));
        assert!(kept.len() < all.len(), "part of the ray is skipped: {} of {}", kept.len(), all.len());
        assert!(kept.iter().any(|s| s.1 > 0.5), "samples that contribute are taken");
        let mut rest = kept.iter().peekable();
        for sample in &all {
            if rest.peek() == Some(&sample) {
                rest.next();
            } else {
                assert!(sample.1 <= threshold, "a sample that could contribute was skipped: {sample:?}");
            }
        }
        assert!(rest.next().is_none(), "every sample kept is one of the samples taken without skipping");
    }
}
