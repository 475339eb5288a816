//! The seams of issue 46's two step options, on the hand-built tree: the traversal asks an adapting integrand for
//! each brick segment's step with the brick's value range, and the samples still tile the ray; and the
//! pre-integrating emission–absorption ray integrates a transfer-function peak its samples step over, runs closed
//! where blocks are skipped, against a brute-force integral of the same field.

use std::ops::ControlFlow;

use glam::DVec3;
use voxstream_core::FeedbackBuffer;

use super::test_tree::{ray, Child, Record, TestTree};
use super::{DescentPath, Ray, RayStats};
use crate::emission_absorption::{EmissionAbsorption, EmissionAbsorptionSettings};
use crate::integrand::{Integrand, Sample};
use crate::settings::RenderSettings;
use crate::step_table::StepLength;
use crate::transfer_function::{TransferFunction, TransferLut};

/// Records samples as [`Record`] does, and adapts: four times the fixed step in bricks whose values all lie below
/// `grow_below`, the fixed step elsewhere; keeps every range it was asked about.
#[derive(Default)]
struct Adapting {
    record: Record,
    grow_below: f32,
    /// Each range asked about, with the answer.
    asked: std::cell::RefCell<Vec<(f32, f32, f64)>>,
}

impl Integrand for Adapting {
    fn can_contribute(&self, lower: f32, upper: f32) -> bool {
        self.record.can_contribute(lower, upper)
    }
    fn wants_gradient(&self) -> bool {
        false
    }
    fn adapts_step(&self) -> bool {
        true
    }
    fn adapt_step(&self, lower: f32, upper: f32, base: f64) -> f64 {
        assert!(lower <= upper, "a range: {lower} {upper}");
        let step = if upper < self.grow_below { 4.0 * base } else { base };
        self.asked.borrow_mut().push((lower, upper, step));
        step
    }
    fn set_step(&mut self, step: StepLength) {
        self.record.set_step(step)
    }
    fn sample(&mut self, sample: Sample) -> ControlFlow<()> {
        self.record.sample(sample)
    }
    fn constant(&mut self, from: f64, to: f64, value: f32) -> ControlFlow<()> {
        self.record.constant(from, to, value)
    }
}

/// Traces `ray` through `tree` with `integrand`.
fn trace<I: Integrand>(tree: &TestTree, settings: &RenderSettings, ray: &Ray, integrand: &mut I) {
    let feedback: FeedbackBuffer = tree.feedback();
    let traversal = tree.traversal(&feedback, settings);
    let (mut stats, mut requests, mut path) = (RayStats::default(), Vec::new(), DescentPath::new(tree.view()));
    traversal.trace(ray, integrand, &mut stats, &mut requests, &mut path);
}

#[test]
fn adapted_steps_grow_only_in_bricks_whose_range_allows_and_still_tile_the_ray() {
    // Low values (below 0.4) where x < 0.6, high ones beyond: the children with x < 0.5 (border voxels included)
    // hold only low values, those beyond only high ones or both.
    let field = |p: DVec3| if p.x < 0.6 { 0.1 + 0.2 * p.x } else { 0.5 + 0.4 * p.x };
    let tree = TestTree::new(field, field, [Child::Brick; 8]);
    let mut integrand = Adapting { grow_below: 0.4, ..Adapting::default() };
    trace(&tree, &RenderSettings::default(), &ray([-0.5, 0.3, 0.3], [1.0, 0.0, 0.0]), &mut integrand);
    let samples = &integrand.record.samples;
    assert!(!samples.is_empty());
    let (fine, coarse): (Vec<(f64, f32, f64)>, Vec<(f64, f32, f64)>) = samples.iter().partition(|s| s.0 < 1.0);
    let base = coarse.iter().map(|s| s.2).fold(f64::INFINITY, f64::min);
    // Half a voxel of 1/16 on the ladder: at most 1/32, more than 1/64.
    assert!(base <= 1.0 / 32.0 && base > 1.0 / 64.0, "the fixed step in the high half: {base}");
    let x = |t: f64| -0.5 + t;
    for &(t, _, step) in &fine {
        if x(t) < 0.5 - 2.0 * step {
            assert!((step / base - 4.0).abs() < 1e-9, "the low half steps four times as far: {step} at x {}", x(t));
        }
    }
    for &(t, _, step) in &coarse {
        assert!(x(t) > 0.5 || step == base, "{t}");
        if x(t) > 0.5 {
            assert_eq!(step, base, "the high half keeps the fixed step");
        }
    }
    // Asked once per brick segment (two children along the ray), with the bricks' ranges.
    let asked = integrand.asked.borrow();
    assert_eq!(asked.len(), 2, "{asked:?}");
    assert!(asked[0].1 < 0.4 && asked[1].1 > 0.4, "{asked:?}");
    // Each sample's step starts where the last one's ended.
    for pair in samples.windows(2) {
        let ((t0, _, s0), (t1, _, s1)) = (pair[0], pair[1]);
        assert!((t1 - t0 - 0.5 * (s0 + s1)).abs() < 1e-9, "samples at {t0} and {t1} tile the ray");
    }
}

/// A transfer function transparent but for a thin opaque peak at value 0.5 (a twentieth of the field's range).
fn peak_lut() -> TransferLut {
    let tf = TransferFunction::new(
        vec![
            [0.0, 1.0, 0.6, 0.2, 0.0],
            [0.49, 1.0, 0.6, 0.2, 0.0],
            [0.5, 1.0, 0.6, 0.2, 0.95],
            [0.51, 1.0, 0.6, 0.2, 0.0],
            [1.0, 1.0, 0.6, 0.2, 0.0],
        ],
        Some(0.01),
    )
    .expect("valid");
    TransferLut::new(&tf, 0.0, 1.0, 0.01)
}

/// Opacity of a ray along x through the field `v = x` by brute force: 200 000 point samples.
fn brute_force_opacity(lut: &TransferLut) -> f64 {
    let n = 200_000;
    let dt = 1.0 / n as f64;
    let depth: f64 = (0..n).map(|k| lut.lookup(((k as f64 + 0.5) * dt) as f32).sigma as f64 * dt).sum();
    1.0 - (-depth).exp()
}

fn render_opacity<const PRE: bool>(tree: &TestTree, lut: &TransferLut, settings: &RenderSettings) -> f32 {
    let direction = DVec3::X;
    let mut integrand = EmissionAbsorption::<PRE>::new(lut, &EmissionAbsorptionSettings::new(settings), direction);
    trace(tree, settings, &ray([-0.5, 0.3, 0.3], [1.0, 0.0, 0.0]), &mut integrand);
    integrand.result().1
}

#[test]
fn preintegrated_rays_integrate_a_peak_their_samples_step_over() {
    // v = x: the peak sits at x = 0.5, one hundredth of the volume wide, a sixth of a voxel of 1/16.
    let tree = TestTree::new(|p| p.x, |p| p.x, [Child::Brick; 8]);
    let lut = peak_lut();
    let want = brute_force_opacity(&lut) as f32;
    assert!(want > 0.5, "the peak is opaque enough to matter: {want}");
    for step_factor in [0.5, 1.3, 2.0] {
        for skip_empty_space in [true, false] {
            let settings = RenderSettings { step_factor, skip_empty_space, ..RenderSettings::default() };
            let point = render_opacity::<false>(&tree, &lut, &settings);
            let pre = render_opacity::<true>(&tree, &lut, &RenderSettings { preintegrated: true, ..settings.clone() });
            assert!(
                (pre - want).abs() < 0.01,
                "step {step_factor}, skipping {skip_empty_space}: pre-integrated {pre} against {want}"
            );
            if step_factor >= 1.3 {
                assert!((point - want).abs() > 0.05, "point samples step over the peak: {point} against {want}");
            }
        }
    }
}

#[test]
fn a_smooth_field_and_function_render_as_point_samples_do() {
    // Where the transfer function is linear over a smooth field, pre-integration changes next to nothing.
    let tree = TestTree::new(|p| 0.2 + 0.3 * p.x + 0.1 * p.y, |p| 0.2 + 0.3 * p.x + 0.1 * p.y, [Child::Brick; 8]);
    let tf =
        TransferFunction::new(vec![[0.0, 0.9, 0.5, 0.1, 0.0], [1.0, 0.2, 0.4, 0.9, 0.3]], Some(0.05)).expect("valid");
    let lut = TransferLut::new(&tf, 0.0, 1.0, 0.05);
    let settings = RenderSettings::default();
    let direction = DVec3::new(1.0, 0.4, 0.2).normalize();
    let ray = ray([-0.5, 0.1, 0.2], direction.to_array());
    let mut point = EmissionAbsorption::<false>::new(&lut, &EmissionAbsorptionSettings::new(&settings), direction);
    trace(&tree, &settings, &ray, &mut point);
    let settings = RenderSettings { preintegrated: true, ..settings };
    let mut pre = EmissionAbsorption::<true>::new(&lut, &EmissionAbsorptionSettings::new(&settings), direction);
    trace(&tree, &settings, &ray, &mut pre);
    let ((point_colour, point_alpha), (pre_colour, pre_alpha)) = (point.result(), pre.result());
    assert!(point_alpha > 0.2, "{point_alpha}");
    assert!((pre_alpha - point_alpha).abs() < 2e-3, "{pre_alpha} against {point_alpha}");
    for c in 0..3 {
        assert!((pre_colour[c] - point_colour[c]).abs() < 2e-3, "{pre_colour:?} against {point_colour:?}");
    }
}
