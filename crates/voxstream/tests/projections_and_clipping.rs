//! Intensity projections and clipping planes (issue 42, item 8) on whole frames: the maximum projection of the
//! analytic shell against its closed form (with and without a clipping plane), skipping that changes no bit, and a
//! plane that equals the crop box it describes.

mod common;

use common::{pixel_direction, ray_box};
use glam::DVec3;
use voxstream::scenes::builtin;
use voxstream_engine::{LoopLimits, Mode, Session};
use voxstream_procedural::Shell;
use voxstream_render::{Camera, ClipPlane, Image, Projection, RenderSettings, TransferFunction};

const SIZE: u32 = 64;

/// A converged frame of a built-in scene with `adjust`ed settings and transfer function `tf` (the scene's if
/// `None`), and the samples it took.
fn render(
    scene_name: &str,
    tf: Option<&TransferFunction>,
    adjust: impl FnOnce(&mut RenderSettings),
) -> (Image, u64, Camera) {
    let scene = builtin(scene_name).expect("built-in scene");
    let mut settings =
        RenderSettings { width: SIZE, height: SIZE, shading: scene.shading, ..RenderSettings::default() };
    adjust(&mut settings);
    let camera = scene.camera;
    let tf = tf.unwrap_or(&scene.transfer_function);
    let mut session = Session::new(scene.producer, tf, settings, 256 << 20, LoopLimits::default()).expect("session");
    let result = session.render(&camera, Mode::Converged).expect("render");
    assert!(result.is_converged(), "{scene_name}: not converged");
    (result.image, result.samples, camera)
}

/// Grey in proportion to the value and opaque everywhere: a pixel's red is its projected value.
fn grey_ramp() -> TransferFunction {
    TransferFunction::new(vec![[0.0, 0.0, 0.0, 0.0, 0.5], [1.0, 1.0, 1.0, 1.0, 0.5]], None).expect("valid")
}

/// The shell's largest density on the ray `origin + t·direction` over `[t0, t1]`, in closed form: the density
/// falls with the distance from the crest sphere, and the distance from the centre along a line is convex, so the
/// largest density is 1 where the segment crosses the crest, else at the segment's point nearest to the crest.
fn shell_maximum(shell: &Shell, origin: DVec3, direction: DVec3, t0: f64, t1: f64) -> f64 {
    let at = |t: f64| (origin + direction * t - shell.centre).length();
    let closest = (shell.centre - origin).dot(direction).clamp(t0, t1);
    let (nearest, farthest) = (at(closest), at(t0).max(at(t1)));
    let distance = if nearest <= shell.radius && shell.radius <= farthest {
        shell.radius
    } else if nearest > shell.radius {
        nearest
    } else {
        farthest
    };
    (-((distance - shell.radius) / shell.thickness).powi(2)).exp()
}

/// Every pixel's red against the shell's maximum along its ray (within the unit cube, and on the kept side of
/// `keep_x_above` if given); returns the largest and the mean error over the pixels whose rays cross the cube.
fn maximum_errors(image: &Image, camera: &Camera, keep_x_above: Option<f64>) -> (f64, f64, usize) {
    let shell = Shell::default();
    let eye = DVec3::from(camera.eye);
    let (mut worst, mut sum, mut count) = (0.0f64, 0.0f64, 0usize);
    for y in 0..SIZE {
        for x in 0..SIZE {
            let direction = pixel_direction(camera, x, y, SIZE, SIZE);
            let pixel = image.pixels[(y * SIZE + x) as usize];
            let Some((mut t0, mut t1)) = ray_box(eye, direction, DVec3::ZERO, 1.0) else { continue };
            if let Some(x0) = keep_x_above {
                let crossing = (x0 - eye.x) / direction.x;
                if direction.x > 0.0 {
                    t0 = t0.max(crossing);
                } else {
                    t1 = t1.min(crossing);
                }
            }
            // Rays that graze the cube's edge or the plane within a pixel are left out (their sample lattice
            // decides whether they see anything).
            if t1 - t0 < 0.05 {
                continue;
            }
            let expected = shell_maximum(&shell, eye, direction, t0, t1);
            let error = (pixel[0] as f64 - expected).abs();
            worst = worst.max(error);
            sum += error;
            count += 1;
        }
    }
    (worst, sum / count.max(1) as f64, count)
}

#[test]
fn the_maximum_projection_of_the_shell_is_its_closed_form() {
    let tf = grey_ramp();
    // Finest level everywhere (the shell's tree stops at 256³, where its trilinear field is near the formula).
    let (image, _, camera) = render("shell", Some(&tf), |s| {
        s.projection = Projection::Maximum;
        s.lod_bias = 4.0;
    });
    let (worst, mean, count) = maximum_errors(&image, &camera, None);
    println!("maximum projection: {count} rays, largest error {worst:.4}, mean {mean:.5}");
    assert!(count > (SIZE * SIZE / 4) as usize, "only {count} rays cross the cube");
    assert!(worst < 0.03 && mean < 0.004, "largest error {worst}, mean {mean}");
    // Rays through the crest see exactly its peak; rays past the shell see its tail.
    let peak = image.pixels.iter().filter(|p| p[0] > 0.97).count();
    let tail = image.pixels.iter().filter(|p| p[0] > 0.05 && p[0] < 0.5).count();
    assert!(peak > 100 && tail > 10, "{peak} pixels at the peak, {tail} in the tail");

    // Cut open at x = 0.5, keeping +x: each ray's maximum over what is left.
    let plane = ClipPlane { point: [0.5, 0.0, 0.0], normal: [2.0, 0.0, 0.0] };
    let (clipped, _, _) = render("shell", Some(&tf), |s| {
        s.projection = Projection::Maximum;
        s.lod_bias = 4.0;
        s.clip_planes = vec![plane];
    });
    let (worst, mean, count) = maximum_errors(&clipped, &camera, Some(0.5));
    println!("clipped at x = 0.5: {count} rays, largest error {worst:.4}, mean {mean:.5}");
    assert!(count > (SIZE * SIZE / 8) as usize, "only {count} rays cross the kept half");
    assert!(worst < 0.03 && mean < 0.004, "largest error {worst}, mean {mean}");
    assert!(clipped.pixels != image.pixels, "the plane cut nothing away");
}

#[test]
fn projections_skip_exactly_and_take_fewer_samples() {
    for scene in ["shell", "hypertexture"] {
        for projection in [Projection::Maximum, Projection::Minimum, Projection::Mean] {
            let with = |skip: bool, shared: bool| {
                render(scene, None, |s| {
                    s.projection = projection;
                    s.skip_empty_space = skip;
                    s.shared_descents = shared;
                })
            };
            let (skipped, samples_skipping, _) = with(true, true);
            let (marched, samples_marching, _) = with(false, false);
            let differing = skipped.pixels.iter().zip(&marched.pixels).filter(|(a, b)| a != b).count();
            assert_eq!(differing, 0, "{scene} {projection:?}: {differing} pixels differ with skipping on");
            let shown = skipped.pixels.iter().filter(|p| p[3] > 0.01).count();
            println!(
                "{scene} {projection:?}: {samples_skipping} samples skipping, {samples_marching} not; {shown} shown"
            );
            if projection == Projection::Maximum {
                assert!(shown > (SIZE * SIZE / 10) as usize, "{scene}: only {shown} pixels show anything");
                assert!(samples_skipping < samples_marching, "{scene}: the maximum skipped nothing");
            }
        }
    }
}

#[test]
fn a_clipping_plane_on_a_box_face_draws_what_that_crop_box_draws() {
    // Keep z ≤ 0.625 by a plane (a tilted-in normal of length 3), and by the clip box: the same rays, the same
    // samples but for the rounding of where each ray starts.
    let plane = ClipPlane { point: [0.2, 0.9, 0.625], normal: [0.0, 0.0, -3.0] };
    let (by_plane, _, _) = render("shell", None, |s| s.clip_planes = vec![plane]);
    let (by_box, _, _) = render("shell", None, |s| s.placement.clip_upper[2] = 0.625);
    let (whole, _, _) = render("shell", None, |_| {});
    let largest = by_plane
        .pixels
        .iter()
        .zip(&by_box.pixels)
        .flat_map(|(a, b)| (0..4).map(move |c| (a[c] - b[c]).abs()))
        .fold(0.0f32, f32::max);
    assert!(largest < 2e-3, "plane and box differ by {largest}");
    let changed = by_plane.pixels.iter().zip(&whole.pixels).filter(|(a, b)| (a[3] - b[3]).abs() > 0.05).count();
    assert!(changed > (SIZE * SIZE / 20) as usize, "the cut changed only {changed} pixels");
}

#[test]
fn projections_and_planes_are_checked() {
    let mut settings = RenderSettings { projection: Projection::Maximum, ..RenderSettings::default() };
    settings.surfaces = vec![voxstream_render::IsoSurface { value: 0.5, color: [1.0; 3], opacity: 1.0 }];
    assert!(settings.validate().unwrap_err().to_string().contains("drop --iso"));
    let bad = ClipPlane { point: [0.0; 3], normal: [0.0; 3] };
    let settings = RenderSettings { clip_planes: vec![bad], ..RenderSettings::default() };
    assert!(settings.validate().unwrap_err().to_string().contains("non-zero finite normal"));
    let many = vec![ClipPlane { point: [0.0; 3], normal: [1.0, 0.0, 0.0] }; 7];
    let settings = RenderSettings { clip_planes: many, ..RenderSettings::default() };
    assert!(settings.validate().unwrap_err().to_string().contains("at most 6"));
}
