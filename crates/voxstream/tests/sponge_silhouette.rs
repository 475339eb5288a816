//! Image test: the sponge's converged silhouette against the analytic Menger set, ray-cast independently.
//!
//! The reference intersects each pixel's ray with the exact sponge by recursive ray–cube tests (the 20 solid
//! sub-cubes of every cube), refining while a cube is larger than the pixel's footprint at its entry point: the
//! Menger set resolved to the pixel, which is what cone tracing shows. No tree, brick or transfer function involved.

mod common;

use glam::DVec3;
use voxstream_render::Camera;

/// Whether the pixel's ray hits the sponge resolved to `spread` (footprint per unit distance).
fn hits_sponge(eye: DVec3, direction: DVec3, lower: DVec3, size: f64, spread: f64, depth: u32) -> bool {
    let Some((t0, _)) = common::ray_box(eye, direction, lower, size) else {
        return false;
    };
    if size <= spread * t0 || depth >= 40 {
        return true;
    }
    let third = size / 3.0;
    let mut children: Vec<(f64, DVec3)> = Vec::with_capacity(20);
    for k in 0..3 {
        for j in 0..3 {
            for i in 0..3 {
                let ones = (i == 1) as u32 + (j == 1) as u32 + (k == 1) as u32;
                if ones >= 2 {
                    continue;
                }
                let child = lower + DVec3::new(i as f64, j as f64, k as f64) * third;
                if let Some((t, _)) = common::ray_box(eye, direction, child, third) {
                    children.push((t, child));
                }
            }
        }
    }
    children.sort_by(|a, b| a.0.total_cmp(&b.0));
    children.into_iter().any(|(_, child)| hits_sponge(eye, direction, child, third, spread, depth + 1))
}

/// Fraction of pixels where the rendered coverage and the analytic silhouette disagree.
fn mismatch(camera: &Camera, size: u32, reference_spread_scale: f64) -> (f64, usize) {
    let mut session = common::scene_session("sponge", size, 128 << 20);
    let image = common::converged(&mut session, camera);
    let spread = 2.0 * (camera.fov.to_radians() / 2.0).tan() / size as f64 * reference_spread_scale;
    let eye = DVec3::from(camera.eye);
    let mut wrong = 0;
    let mut covered = 0;
    for y in 0..size {
        for x in 0..size {
            let d = common::pixel_direction(camera, x, y, size, size);
            let expected = hits_sponge(eye, d, DVec3::ZERO, 1.0, spread, 0);
            let rendered = image.pixel(x, y)[3] > 0.5;
            covered += expected as usize;
            wrong += (expected != rendered) as usize;
        }
    }
    (wrong as f64 / (size * size) as f64, covered)
}

/// Largest fraction of disagreeing pixels: edges of pixel-sized holes, where the trilinear filter and the exact
/// set may round differently.
const MAX_MISMATCH: f64 = 0.01;

#[test]
fn default_view_matches_the_menger_set() {
    let camera = voxstream::scenes::default_camera();
    let (wrong, covered) = mismatch(&camera, 160, 1.0);
    println!("default view: {:.2}% of pixels differ, {covered} covered", wrong * 100.0);
    assert!(covered > 160 * 160 / 4);
    assert!(wrong < MAX_MISMATCH, "{:.2}% of pixels differ", wrong * 100.0);
}

#[test]
fn face_on_view_shows_the_carpet() {
    // Looking straight at a face from far away (nearly parallel rays): the silhouette is the Sierpinski carpet.
    let camera = Camera { eye: [0.5, 0.5, 40.0], target: [0.5, 0.5, 0.5], up: [0.0, 1.0, 0.0], fov: 1.6 };
    let (wrong, covered) = mismatch(&camera, 162, 1.0);
    println!("face-on: {:.2}% of pixels differ, {covered} covered", wrong * 100.0);
    // Nearly parallel rays see through the tunnels: the carpet covers well under the square's area.
    assert!(covered < 162 * 162 * 3 / 4, "{covered} pixels covered");
    assert!(wrong < MAX_MISMATCH, "{:.2}% of pixels differ", wrong * 100.0);
}

#[test]
fn a_coarser_reference_is_detected() {
    // The threshold must catch a sponge resolved at the wrong scale (27 times coarser: three iterations fewer).
    let camera = Camera { eye: [0.5, 0.5, 40.0], target: [0.5, 0.5, 0.5], up: [0.0, 1.0, 0.0], fov: 1.6 };
    let (wrong, _) = mismatch(&camera, 162, 27.0);
    println!("coarse reference: {:.2}% of pixels differ", wrong * 100.0);
    assert!(wrong > MAX_MISMATCH, "only {:.2}% of pixels differ", wrong * 100.0);
}

#[test]
fn zoom_to_features_of_three_to_the_minus_twenty() {
    // Features of 3^-20 of the scene: beyond float32 (GigaVoxels stopped at 2^-19). A hole of edge 3^-20 lies at
    // [3^-20, 2·3^-20]² on the z = 1 face near the corner; frame it from close by.
    let cell = 3f64.powi(-20);
    let target = [1.5 * cell, 1.5 * cell, 1.0];
    let camera = Camera {
        eye: [target[0] + 0.6 * cell, target[1] + 0.8 * cell, 1.0 + 4.0 * cell],
        target,
        up: [0.0, 1.0, 0.0],
        fov: 50.0,
    };
    let (wrong, covered) = mismatch(&camera, 96, 1.0);
    println!("deep zoom: {:.2}% of pixels differ, {covered} covered", wrong * 100.0);
    assert!(covered > 96 * 96 / 5 && covered < 96 * 96 * 95 / 100, "the view must show solid and holes");
    assert!(wrong < MAX_MISMATCH, "{:.2}% of pixels differ", wrong * 100.0);
}
