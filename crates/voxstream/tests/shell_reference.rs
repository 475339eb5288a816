//! Image test: the converged render of the analytic shell against an independent brute-force ray march of the same
//! closed-form field (no tree, no bricks, no LOD, no lookup table), with the same camera and transfer function.

mod common;

use glam::DVec3;
use voxstream::scenes::{builtin, shell_transfer_function};
use voxstream_procedural::Shell;
use voxstream_render::{psnr, Camera, Image};

/// The PSNR the converged render must reach against the brute-force reference.
const MIN_PSNR_DB: f64 = 40.0;

fn brute_force(camera: &Camera, size: u32) -> Image {
    let shell = Shell::default();
    let tf = shell_transfer_function();
    let unit = tf.unit_distance.expect("the shell's transfer function names its unit distance");
    let step = 1.0 / 4096.0;
    let eye = DVec3::from(camera.eye);
    let mut image = Image::new(size, size);
    for y in 0..size {
        for x in 0..size {
            let d = common::pixel_direction(camera, x, y, size, size);
            let mut color = [0.0f64; 3];
            let mut transmittance = 1.0f64;
            if let Some((t0, t1)) = common::ray_box(eye, d, DVec3::ZERO, 1.0) {
                let steps = ((t1 - t0) / step).ceil() as usize;
                let dt = (t1 - t0) / steps as f64;
                for i in 0..steps {
                    let p = eye + d * (t0 + (i as f64 + 0.5) * dt);
                    let [r, g, b, alpha] = tf.evaluate(shell.density(p));
                    // Opacity over dt from opacity over `unit`.
                    let a = 1.0 - (1.0 - alpha).powf(dt / unit);
                    for (c, v) in color.iter_mut().zip([r, g, b]) {
                        *c += transmittance * a * v;
                    }
                    transmittance *= 1.0 - a;
                }
            }
            image.pixels[(y * size + x) as usize] =
                [color[0] as f32, color[1] as f32, color[2] as f32, (1.0 - transmittance) as f32];
        }
    }
    image
}

#[test]
fn converged_shell_matches_brute_force_ray_march() {
    let size = 96;
    let camera = builtin("shell").unwrap().camera;
    let mut session = common::scene_session("shell", size, 64 << 20);
    let rendered = common::converged(&mut session, &camera);
    let reference = brute_force(&camera, size);
    let quality = psnr(&rendered.to_rgb8(), &reference.to_rgb8());
    println!("shell: PSNR {quality:.2} dB against the brute-force reference");
    assert!(quality >= MIN_PSNR_DB, "PSNR {quality:.2} dB < {MIN_PSNR_DB} dB");
    // The reference is not trivially black: the comparison means something.
    let lit = reference.pixels.iter().filter(|p| p[3] > 0.1).count();
    assert!(lit > (size * size / 4) as usize, "only {lit} covered pixels");
}

#[test]
fn a_wrong_image_fails_the_same_threshold() {
    // Guard against a threshold too loose to catch errors: shift the camera a little and the PSNR must drop.
    let size = 96;
    let camera = builtin("shell").unwrap().camera;
    let mut moved = camera;
    moved.eye[0] += 0.15;
    let mut session = common::scene_session("shell", size, 64 << 20);
    let rendered = common::converged(&mut session, &moved);
    let reference = brute_force(&camera, size);
    assert!(psnr(&rendered.to_rgb8(), &reference.to_rgb8()) < MIN_PSNR_DB);
}
