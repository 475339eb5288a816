//! The samples of one brick segment: positions stepped in `f32` brick coordinates along the ray, trilinear in the
//! finer brick and blended with its parent by a weight ramp (quadrilinear filtering, GigaVoxels [P09] §6; the caps
//! of Thiele et al.'s level blending), handed to the integrand one by one, eight at a time where the build allows.

use std::ops::ControlFlow;

use voxstream_core::{BrickSlot, PoolVoxels, Voxel};

use super::descent::BrickRef;
use super::segments::March;
use super::{Ray, RayStats, Traversal};
use crate::integrand::{BrickSpan, Integrand, Sample};
use crate::sampler::{values_along, values_and_gradients_along, Cell, LANES};

/// A brick sampled along a segment: its voxels and the ray's continuous voxel index there, `x_k = start + k·delta`
/// for sample `k` of the segment.
#[derive(Clone, Copy)]
pub(super) struct BrickLine<'v> {
    pub(super) voxels: PoolVoxels<'v>,
    pub(super) slot: BrickSlot,
    pub(super) start: [f32; 3],
    pub(super) delta: [f32; 3],
    /// The same line in `f64` over `t`, for block exits: `x(t) = origin + t·rate`.
    pub(super) origin: [f64; 3],
    pub(super) rate: [f64; 3],
    /// `1 / rate` (infinite along an axis the ray does not move on).
    pub(super) inverse_rate: [f64; 3],
}

impl BrickLine<'_> {
    #[inline(always)]
    pub(super) fn at(&self, k: f32) -> [f32; 3] {
        [self.start[0] + k * self.delta[0], self.start[1] + k * self.delta[1], self.start[2] + k * self.delta[2]]
    }
}

impl<'a> Traversal<'a> {
    /// Samples `count` points `first + k·dt` inside the bricks of one segment, skipping the runs that lie in
    /// occupancy blocks the integrand cannot use.
    #[inline(always)]
    pub(super) fn march_bricks<I: Integrand>(
        &self,
        ray: &Ray,
        march: March,
        integrand: &mut I,
        stats: &mut RayStats,
    ) -> ControlFlow<()> {
        let March { fine, coarse, first, dt, count, front_edge } = march;
        // Whether occupancy blocks are checked: not when every value of the bricks can contribute.
        let mut check_blocks = self.skip_empty_space;
        if self.skip_empty_space {
            // Empty-space skipping: nothing in the bricks (fine, and coarse if blended) can contribute.
            let [mut lo, mut hi] = self.view.brick_range(fine.slot);
            if let Some((c, _)) = coarse {
                let [clo, chi] = self.view.brick_range(c.slot);
                lo = lo.min(clo);
                hi = hi.max(chi);
            }
            if !integrand.can_contribute(lo, hi) {
                return ControlFlow::Continue(());
            }
            check_blocks = !integrand.contributes_throughout(lo, hi);
        }
        let fine_line = self.brick_line(ray, &fine, first, dt);
        let coarse_line = coarse.map(|(c, weight)| (self.brick_line(ray, &c, first, dt), weight));
        let gradient = integrand.wants_gradient();
        let count = count.min(u32::MAX as u64) as u32;
        let coarse_brick_line = coarse_line.as_ref().map(|(line, _)| line);
        let mut k = 0u32;
        while k < count {
            // The next run of samples in blocks that can contribute, and where the one after it may start.
            let (run_start, run_end, resume) = if check_blocks {
                match self.run_from(&fine_line, coarse_brick_line, (first, dt, count), k, 0, integrand) {
                    Some(run) => run,
                    None => break,
                }
            } else {
                (k, count, None)
            };
            let (mut run_start, mut run_end) = (run_start, run_end);
            if I::DILATED_RUNS {
                // The skipped sample on either side of the run too, and one step beyond the segment's ends.
                run_start = run_start.saturating_sub(1);
                run_end = (run_end + 1).min(count);
                if run_start == 0 && front_edge {
                    self.edge_sample(&fine_line, &coarse_line, (first, dt), -1.0, integrand);
                }
            }
            k = run_start;
            // One loop per combination, so that the loop itself holds no test of either.
            let (coarse, weight) = match &coarse_line {
                Some((line, weight)) => (line, *weight),
                None => (&fine_line, Blend::FINE),
            };
            let run = (first, dt, k, run_end);
            let blend_gradients = gradient && weight.gradient.is_some();
            let flow = match (gradient, coarse_line.is_some(), blend_gradients) {
                (false, false, _) => {
                    self.sample_run::<I, false, false, false>(&fine_line, coarse, weight, run, integrand)
                }
                (true, false, _) => {
                    self.sample_run::<I, true, false, false>(&fine_line, coarse, weight, run, integrand)
                }
                (false, true, _) => {
                    self.sample_run::<I, false, true, false>(&fine_line, coarse, weight, run, integrand)
                }
                (true, true, false) => {
                    self.sample_run::<I, true, true, false>(&fine_line, coarse, weight, run, integrand)
                }
                (true, true, true) => {
                    self.sample_run::<I, true, true, true>(&fine_line, coarse, weight, run, integrand)
                }
            };
            match flow {
                ControlFlow::Break(taken) => {
                    stats.samples += taken;
                    return ControlFlow::Break(());
                }
                ControlFlow::Continue(()) => stats.samples += (run_end - k) as u64,
            }
            if I::DILATED_RUNS && run_end == count {
                self.edge_sample(&fine_line, &coarse_line, (first, dt), count as f32, integrand);
            }
            k = resume.unwrap_or(run_end);
        }
        ControlFlow::Continue(())
    }

    /// The inner loop: samples `k..end` of a segment (`run = (first, dt, k, end)`), with no skipping checks;
    /// values blended with `coarse` by `blend.value` when `COARSE`, gradients too (by `blend.gradient`) when
    /// `BLEND_GRADIENTS`.
    #[inline(always)]
    pub(super) fn sample_run<I: Integrand, const GRADIENT: bool, const COARSE: bool, const BLEND_GRADIENTS: bool>(
        &self,
        fine: &BrickLine<'_>,
        coarse: &BrickLine<'_>,
        blend: Blend,
        run: (f64, f64, u32, u32),
        integrand: &mut I,
    ) -> RunFlow {
        // Both bricks are in the one pool, so both are of its format.
        match (fine.voxels, coarse.voxels) {
            (PoolVoxels::Wide(f), PoolVoxels::Wide(c)) => self
                .sample_run_in::<_, I, GRADIENT, COARSE, BLEND_GRADIENTS>(
                    (f, fine),
                    (c, coarse),
                    blend,
                    run,
                    integrand,
                ),
            (PoolVoxels::Narrow(f), PoolVoxels::Narrow(c)) => self
                .sample_run_in::<_, I, GRADIENT, COARSE, BLEND_GRADIENTS>(
                    (f, fine),
                    (c, coarse),
                    blend,
                    run,
                    integrand,
                ),
            _ => unreachable!("the bricks of one pool have one voxel format"),
        }
    }

    /// [`Traversal::sample_run`] for the pool's voxel type.
    #[inline(always)]
    pub(super) fn sample_run_in<
        V: Voxel,
        I: Integrand,
        const GRADIENT: bool,
        const COARSE: bool,
        const BLEND_GRADIENTS: bool,
    >(
        &self,
        (fine_voxels, fine): (&[V], &BrickLine<'_>),
        (coarse_voxels, coarse): (&[V], &BrickLine<'_>),
        blend: Blend,
        (first, dt, k, end): (f64, f64, u32, u32),
        integrand: &mut I,
    ) -> RunFlow {
        let b = self.stored;
        let dq = self.dequantize;
        let (weight, gradient_weight) = (blend.value, blend.gradient.unwrap_or(WeightRamp::FINE));
        // A coarse gradient per coarse voxel, in fine voxels.
        let coarse_scale = 1.0 / self.n as f32;
        let blend_gradient = |fine: [f32; 3], coarse: [f32; 3], w: f32| {
            std::array::from_fn(|a| coarse[a] * coarse_scale + (fine[a] - coarse[a] * coarse_scale) * w)
        };
        // A float counter (exact below 2²⁴) instead of converting the index per sample: positions are the same
        // bits whichever sample a run starts at.
        let mut kf = k as f32;
        let mut s = k;
        // LANES samples at a time (the same values, bit for bit: see `values_along`); the integrand still takes
        // them one by one, in order. (A run's last few samples are taken one at a time: a padded batch costs more
        // where rays turn opaque within a few samples, as in the sponge.)
        if self.sample_batches {
            while s + LANES as u32 <= end {
                let (mut values, mut gradients) = if GRADIENT {
                    values_and_gradients_along(fine_voxels, b, fine.start, fine.delta, kf, dq, self.gather)
                } else {
                    (values_along(fine_voxels, b, fine.start, fine.delta, kf, dq, self.gather), [[0.0; 3]; LANES])
                };
                if BLEND_GRADIENTS {
                    let (coarse_values, coarse_gradients) =
                        values_and_gradients_along(coarse_voxels, b, coarse.start, coarse.delta, kf, dq, self.gather);
                    for j in 0..LANES {
                        let x = kf + j as f32;
                        values[j] = coarse_values[j] + (values[j] - coarse_values[j]) * weight.at(x);
                        gradients[j] = blend_gradient(gradients[j], coarse_gradients[j], gradient_weight.at(x));
                    }
                } else if COARSE {
                    let coarse_values = values_along(coarse_voxels, b, coarse.start, coarse.delta, kf, dq, self.gather);
                    for (j, (value, coarse_value)) in values.iter_mut().zip(coarse_values).enumerate() {
                        *value = coarse_value + (*value - coarse_value) * weight.at(kf + j as f32);
                    }
                }
                for (j, (&value, &gradient)) in values.iter().zip(&gradients).enumerate() {
                    let sample = Sample { t: first + (s + j as u32) as f64 * dt, value, gradient };
                    if integrand.sample(sample).is_break() {
                        return ControlFlow::Break(u64::from(s - k) + j as u64 + 1);
                    }
                }
                s += LANES as u32;
                kf += LANES as f32;
            }
        }
        for s in s..end {
            let cell = Cell::locate(b, fine.at(kf));
            let (mut value, mut gradient) = if GRADIENT {
                cell.value_and_gradient(fine_voxels, b, dq)
            } else {
                (cell.value(fine_voxels, b, dq), [0.0; 3])
            };
            if BLEND_GRADIENTS {
                let (coarse_value, coarse_gradient) =
                    Cell::locate(b, coarse.at(kf)).value_and_gradient(coarse_voxels, b, dq);
                value = coarse_value + (value - coarse_value) * weight.at(kf);
                gradient = blend_gradient(gradient, coarse_gradient, gradient_weight.at(kf));
            } else if COARSE {
                let coarse_value = Cell::locate(b, coarse.at(kf)).value(coarse_voxels, b, dq);
                value = coarse_value + (value - coarse_value) * weight.at(kf);
            }
            let sample = Sample { t: first + s as f64 * dt, value, gradient };
            if integrand.sample(sample).is_break() {
                return ControlFlow::Break(u64::from(s - k + 1));
            }
            kf += 1.0;
        }
        ControlFlow::Continue(())
    }

    /// With [`Integrand::DILATED_RUNS`]: the [`Integrand::edge`] sample `k` of a segment, −1 or the segment's count,
    /// one step beyond its start or end, evaluated in its bricks (clamped to them: within the border voxels for steps of up to
    /// a voxel), blended as the segment's samples are (the weight ramp held within `[0, 1]`).
    #[inline(never)]
    pub(super) fn edge_sample<I: Integrand>(
        &self,
        fine: &BrickLine<'_>,
        coarse: &Option<(BrickLine<'_>, Blend)>,
        (first, dt): (f64, f64),
        k: f32,
        integrand: &mut I,
    ) {
        // No further than the fine brick's stored voxels reach (its border voxels, half a voxel beyond its box):
        // a longer step takes the edge where the brick's data ends, nearer the segment's end sample.
        let reach = self.stored as f32 - 1.0;
        let (before, end) = (k < 0.0, k);
        let mut k = k;
        for a in 0..3 {
            let (start, delta) = (fine.start[a], fine.delta[a]);
            if delta != 0.0 {
                let (at_zero, at_reach) = (-start / delta, (reach - start) / delta);
                k = if before { k.max(at_zero.min(at_reach)) } else { k.min(at_zero.max(at_reach)) };
            }
        }
        // Never past the segment's own end sample (a ray grazing the brick's corner).
        let k = if before { k.min(0.0) } else { k.max(end - 1.0) };
        let gradient = integrand.wants_gradient();
        let (value, gradient) = match (fine.voxels, coarse.as_ref().map(|(c, _)| c.voxels)) {
            (PoolVoxels::Wide(f), Some(PoolVoxels::Wide(c))) => self.edge_value(f, fine, Some(c), coarse, k, gradient),
            (PoolVoxels::Narrow(f), Some(PoolVoxels::Narrow(c))) => {
                self.edge_value(f, fine, Some(c), coarse, k, gradient)
            }
            (PoolVoxels::Wide(f), None) => self.edge_value::<u16>(f, fine, None, coarse, k, gradient),
            (PoolVoxels::Narrow(f), None) => self.edge_value::<u8>(f, fine, None, coarse, k, gradient),
            _ => unreachable!("the bricks of one pool have one voxel format"),
        };
        integrand.edge(Sample { t: first + k as f64 * dt, value, gradient }, before);
    }

    /// The value (and gradient when `gradient`) at sample `k` of a segment, for [`Traversal::edge_sample`].
    #[inline(always)]
    fn edge_value<V: Voxel>(
        &self,
        fine_voxels: &[V],
        fine: &BrickLine<'_>,
        coarse_voxels: Option<&[V]>,
        coarse: &Option<(BrickLine<'_>, Blend)>,
        k: f32,
        gradient: bool,
    ) -> (f32, [f32; 3]) {
        let (b, dq) = (self.stored, self.dequantize);
        let cell = Cell::locate(b, fine.at(k));
        let (value, grad) = if gradient {
            cell.value_and_gradient(fine_voxels, b, dq)
        } else {
            (cell.value(fine_voxels, b, dq), [0.0; 3])
        };
        let (Some(coarse_voxels), Some((line, blend))) = (coarse_voxels, coarse) else { return (value, grad) };
        let cell = Cell::locate(b, line.at(k));
        let (coarse_value, coarse_grad) = if gradient {
            cell.value_and_gradient(coarse_voxels, b, dq)
        } else {
            (cell.value(coarse_voxels, b, dq), [0.0; 3])
        };
        let w = blend.value.at(k).clamp(0.0, 1.0);
        let value = coarse_value + (value - coarse_value) * w;
        let grad = match blend.gradient {
            Some(ramp) => {
                let (w, scale) = (ramp.at(k).clamp(0.0, 1.0), 1.0 / self.n as f32);
                std::array::from_fn(|a| coarse_grad[a] * scale + (grad[a] - coarse_grad[a] * scale) * w)
            }
            None => grad,
        };
        (value, grad)
    }

    /// The continuous voxel index in the brick of `node` along the ray, from sample `first` on in steps of `dt`.
    #[inline(always)]
    pub(super) fn brick_line(&self, ray: &Ray, node: &BrickRef, first: f64, dt: f64) -> BrickLine<'a> {
        let s = self.scale[node.level as usize];
        let m = self.brick_size;
        let (o, d) = (ray.origin.to_array(), ray.direction.to_array());
        let origin: [f64; 3] = std::array::from_fn(|a| (o[a] * s - node.ijk[a] as i64 as f64) * m + 0.5);
        let rate: [f64; 3] = std::array::from_fn(|a| d[a] * s * m);
        BrickLine {
            voxels: self.view.brick(node.slot),
            slot: node.slot,
            start: std::array::from_fn(|a| (origin[a] + rate[a] * first) as f32),
            delta: std::array::from_fn(|a| (rate[a] * dt) as f32),
            origin,
            rate,
            inverse_rate: rate.map(|r| 1.0 / r),
        }
    }

    /// The brick of `node` along the ray over `[from, to)`, for integrands that take spans.
    #[inline(always)]
    pub(super) fn brick_span(&self, ray: &Ray, node: &BrickRef, from: f64, to: f64, step: f64) -> BrickSpan<'a> {
        let s = self.scale[node.level as usize];
        let m = self.brick_size;
        let (o, d) = (ray.origin.to_array(), ray.direction.to_array());
        let blocks = self.view.shape.blocks_per_brick();
        BrickSpan {
            voxels: self.view.brick(node.slot),
            dequantize: self.dequantize,
            stored: self.stored,
            origin: std::array::from_fn(|a| (o[a] * s - node.ijk[a] as i64 as f64) * m + 0.5),
            rate: std::array::from_fn(|a| d[a] * s * m),
            from,
            to,
            block_ranges: &self.view.block_ranges[node.slot.0 as usize * blocks..(node.slot.0 as usize + 1) * blocks],
            blocks: self.view.shape.blocks_per_axis(),
            cull_blocks: self.skip_empty_space,
            step,
        }
    }
}

/// The fine brick's weight against its parent along a segment: `first + k·step` at sample `k` (a constant when
/// `step` is 0, the same bits as a plain weight).
#[derive(Clone, Copy, Debug)]
pub(super) struct WeightRamp {
    pub(super) first: f32,
    pub(super) step: f32,
}

impl WeightRamp {
    /// The fine brick alone.
    const FINE: WeightRamp = WeightRamp { first: 1.0, step: 0.0 };

    /// From `first` at sample 0 to `last` at sample `count − 1`.
    #[inline]
    pub(super) fn between(first: f32, last: f32, count: u64) -> WeightRamp {
        let step = if count > 1 { (last - first) / (count - 1) as f32 } else { 0.0 };
        WeightRamp { first, step }
    }

    /// Whether the ramp is the fine brick alone everywhere.
    #[inline]
    pub(super) fn is_fine(self) -> bool {
        self.first >= 1.0 && self.first + self.step >= 1.0
    }

    #[inline(always)]
    pub(super) fn at(self, k: f32) -> f32 {
        self.first + k * self.step
    }
}

/// How a segment's samples blend the fine brick with its parent: values by `value` (the cone's level weight, capped
/// by level blending), gradients by `gradient` when level blending caps the brick (else the fine brick's).
#[derive(Clone, Copy, Debug)]
pub(super) struct Blend {
    pub(super) value: WeightRamp,
    pub(super) gradient: Option<WeightRamp>,
}

impl Blend {
    /// The fine brick alone.
    const FINE: Blend = Blend { value: WeightRamp::FINE, gradient: None };
}

/// How a run of samples ended: `Break(n)` after `n` samples when the integrand stopped the ray.
pub(super) type RunFlow = ControlFlow<u64>;

#[cfg(test)]
mod tests {
    use glam::DVec3;
    use voxstream_core::BrickBlend;

    use super::super::test_tree::{ray, Child, Record, TestTree};
    use super::super::DescentPath;
    use super::*;
    use crate::settings::RenderSettings;

    fn samples(tree: &TestTree, ray: &Ray) -> Vec<(f64, f32, f64)> {
        let feedback = tree.feedback();
        let traversal = tree.traversal(&feedback, &RenderSettings::default());
        let mut record = Record::default();
        let mut path = DescentPath::new(tree.view());
        traversal.trace(ray, &mut record, &mut RayStats::default(), &mut Vec::new(), &mut path);
        record.samples
    }

    /// Samples are trilinear in the finest brick: a linear field comes back exactly (to its 16-bit rounding), at
    /// the step of half the finest voxel.
    #[test]
    fn samples_interpolate_the_finest_bricks() {
        let field = |p: DVec3| 0.1 + 0.3 * p.x + 0.2 * p.y + 0.25 * p.z;
        let tree = TestTree::new(|_| 0.0, field, [Child::Brick; 8]);
        let ray = ray([-0.2, 0.1, 0.05], [1.0, 0.6, 0.7]);
        let samples = samples(&tree, &ray);
        assert!(samples.len() > 20);
        for &(t, value, step) in &samples {
            let expected = field(ray.origin + ray.direction * t) as f32;
            assert!((value - expected).abs() < 2e-5, "at t = {t}: {value} vs {expected}");
            assert!(step <= 1.0 / 32.0 && step > 1.0 / 64.0, "half a voxel of 1/16, on the step ladder: {step}");
        }
    }

    /// A brick still fading in is blended with its parent by its cap (Thiele et al.), sample by sample.
    #[test]
    fn a_fading_brick_blends_with_its_parent_by_its_cap() {
        let mut tree = TestTree::new(|_| 0.2, |_| 0.6, [Child::Brick; 8]);
        let ray = ray([-0.5, 0.4, 0.7], [1.0, 0.1, -0.1]);
        let full = samples(&tree, &ray);
        assert!(full.iter().all(|s| (s.1 - 0.6).abs() < 1e-4), "without blending, the children's values");
        for blend in &mut tree.blends[1..] {
            *blend = BrickBlend::uniform(0.5);
        }
        let blended = samples(&tree, &ray);
        assert_eq!(blended.len(), full.len(), "blending moves no sample");
        assert!(blended.iter().all(|s| (s.1 - 0.4).abs() < 1e-4), "halfway between parent and child: {blended:?}");
    }
}
