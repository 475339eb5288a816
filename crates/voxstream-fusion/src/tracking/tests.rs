//! ICP against analytic scenes: depth images ray-cast from planes and spheres at known poses.

use glam::{DAffine3, DQuat, DVec3};

use super::*;

/// A 160×120 camera: the TUM intrinsics at a quarter of the resolution.
const K: Intrinsics = Intrinsics { width: 160, height: 120, fx: 131.25, fy: 131.25, cx: 79.5, cy: 59.5 };

/// Planes `n · x = d` and spheres (centre, radius), world space.
struct Scene {
    planes: Vec<(DVec3, f64)>,
    spheres: Vec<(DVec3, f64)>,
}

impl Scene {
    /// A room corner (floor below the camera, a wall ahead, a wall to the left; y points down) with a ball.
    fn room() -> Scene {
        Scene {
            planes: vec![(DVec3::Y, 1.0), (DVec3::Z, 3.0), (DVec3::X, -0.9)],
            spheres: vec![(DVec3::new(0.2, 0.45, 2.0), 0.3)],
        }
    }

    /// The depth image seen from `pose` (metres along the optical axis, 0 beyond 6 m).
    fn render(&self, k: &Intrinsics, pose: &Pose) -> Vec<f32> {
        let origin = pose.translation;
        let mut depth = Vec::with_capacity(k.pixel_count());
        for v in 0..k.height {
            for u in 0..k.width {
                // The ray through the pixel, scaled so that its camera-space z is 1: the hit's t is its depth.
                let dir = pose.transform_vector3(k.unproject(u as f64, v as f64, 1.0));
                let planes = self.planes.iter().map(|&(n, d)| (d - n.dot(origin)) / n.dot(dir));
                let spheres = self.spheres.iter().map(|&(c, r)| {
                    let oc = origin - c;
                    let (a, b, cc) = (dir.dot(dir), dir.dot(oc), oc.dot(oc) - r * r);
                    let disc = b * b - a * cc;
                    if disc < 0.0 {
                        f64::INFINITY
                    } else {
                        (-b - disc.sqrt()) / a
                    }
                });
                let t = planes.chain(spheres).filter(|t| *t > 1e-6).fold(f64::INFINITY, f64::min);
                depth.push(if t < 6.0 { t as f32 } else { 0.0 });
            }
        }
        depth
    }
}

/// The reference camera: inside the room, turned a little left and down toward the corner.
fn reference_pose() -> Pose {
    DAffine3::from_rotation_translation(
        DQuat::from_rotation_y(-0.25) * DQuat::from_rotation_x(-0.2),
        DVec3::new(0.1, -0.1, 0.2),
    )
}

/// About 2 cm and 2°, camera space.
fn motion() -> DAffine3 {
    DAffine3::from_rotation_translation(
        DQuat::from_axis_angle(DVec3::new(0.3, 1.0, 0.2).normalize(), 2f64.to_radians()),
        DVec3::new(0.012, -0.008, 0.014),
    )
}

/// Zero-mean Gaussian noise of deviation `sigma` per pixel, from a hash of the pixel index (Box–Muller).
fn add_noise(depth: &mut [f32], sigma: f64) {
    let uniform = |x: u64| {
        let mut h = x.wrapping_mul(0x9E37_79B9_7F4A_7C15);
        h ^= h >> 31;
        h = h.wrapping_mul(0xBF58_476D_1CE4_E5B9);
        h ^= h >> 29;
        ((h >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    };
    for (i, z) in depth.iter_mut().enumerate().filter(|(_, z)| **z > 0.0) {
        let (u1, u2) = (uniform(2 * i as u64 + 1), uniform(2 * i as u64 + 2));
        let g = (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
        *z = (*z as f64 + sigma * g) as f32;
    }
}

/// The translation (metres) and rotation (degrees) between two poses.
fn pose_error(a: &Pose, b: &Pose) -> (f64, f64) {
    let d = a.inverse() * *b;
    let angle = DQuat::from_mat3(&d.matrix3).normalize().angle_between(DQuat::IDENTITY);
    ((a.translation - b.translation).length(), angle.to_degrees())
}

#[test]
fn the_room_shows_every_surface() {
    // The scene the other tests rely on: each plane and the ball fill a good part of the image.
    let depth = Scene::room().render(&K, &reference_pose());
    let pose = reference_pose();
    let mut counts = [0usize; 5];
    for (i, z) in depth.iter().enumerate() {
        if *z == 0.0 {
            counts[4] += 1;
            continue;
        }
        let p = pose.transform_point3(K.unproject((i % 160) as f64, (i / 160) as f64, *z as f64));
        let which = if (p.y - 1.0).abs() < 1e-4 {
            0
        } else if (p.z - 3.0).abs() < 1e-4 {
            1
        } else if (p.x + 0.9).abs() < 1e-4 {
            2
        } else {
            3
        };
        counts[which] += 1;
    }
    let n = K.pixel_count();
    assert!(counts[..4].iter().all(|&c| c > n / 20), "floor, back wall, left wall, ball, none: {counts:?}");
    assert_eq!(counts[4], 0);
}

#[test]
fn identity_motion_converges_to_identity() {
    let scene = Scene::room();
    let pose = reference_pose();
    let depth = scene.render(&K, &pose);
    let model = ModelView::from_depth(&depth, K, pose);
    let result = track(&depth, &K, &model, pose, &TrackingSettings::default()).expect("tracked");
    let (dt, dr) = pose_error(&result.pose, &pose);
    assert!(dt < 1e-6 && dr < 1e-5, "{dt} m, {dr}°");
    assert!(result.rms_residual < 1e-5, "{}", result.rms_residual);
    // The finest level starts where the frame lies and stops after an update of nothing (coarse levels, whose
    // averaged depths bend the surfaces a little, may wander by a fraction of a millimetre first).
    let most: usize = TrackingSettings::default().iterations.iter().sum();
    assert!(result.iterations < most, "stops early: {} iterations", result.iterations);
    assert!(result.inliers > K.pixel_count() / 2, "{} inliers", result.inliers);
}

#[test]
fn a_small_motion_is_recovered() {
    let scene = Scene::room();
    let (from, to) = (reference_pose(), reference_pose() * motion());
    let model = ModelView::from_depth(&scene.render(&K, &from), K, from);
    let frame = scene.render(&K, &to);
    let (t0, r0) = pose_error(&from, &to);
    assert!(t0 > 0.015 && r0 > 1.9, "the motion is {t0} m, {r0}°");
    let result = track(&frame, &K, &model, from, &TrackingSettings::default()).expect("tracked");
    let (dt, dr) = pose_error(&result.pose, &to);
    eprintln!(
        "noise-free: {:.4} mm, {:.5}°, rms {:.2e} m, {} inliers, {} iterations",
        dt * 1e3,
        dr,
        result.rms_residual,
        result.inliers,
        result.iterations
    );
    assert!(dt < 1e-3 && dr < 0.1, "{dt} m, {dr}° off");
    assert!(result.rms_residual < 1e-3);
}

#[test]
fn a_small_motion_is_recovered_from_noisy_depth() {
    let scene = Scene::room();
    let (from, to) = (reference_pose(), reference_pose() * motion());
    let model = ModelView::from_depth(&scene.render(&K, &from), K, from);
    let mut frame = scene.render(&K, &to);
    add_noise(&mut frame, 0.002);
    let result = track(&frame, &K, &model, from, &TrackingSettings::default()).expect("tracked");
    let (dt, dr) = pose_error(&result.pose, &to);
    eprintln!(
        "σ = 2 mm: {:.4} mm, {:.5}°, rms {:.2e} m, {} inliers, {} iterations",
        dt * 1e3,
        dr,
        result.rms_residual,
        result.inliers,
        result.iterations
    );
    assert!(dt < 3e-3 && dr < 0.3, "{dt} m, {dr}° off");
    // The residual is the noise itself, not a misalignment.
    assert!(result.rms_residual > 1e-3 && result.rms_residual < 4e-3, "{}", result.rms_residual);
}

#[test]
fn a_single_plane_loses_tracking() {
    // A wall alone lets the camera slide along it and turn about its normal.
    let wall = Scene { planes: vec![(DVec3::new(0.1, 0.2, 1.0).normalize(), 2.5)], spheres: vec![] };
    let (from, to) = (reference_pose(), reference_pose() * motion());
    let model = ModelView::from_depth(&wall.render(&K, &from), K, from);
    let frame = wall.render(&K, &to);
    let lost = track(&frame, &K, &model, from, &TrackingSettings::default()).expect_err("a plane cannot be tracked");
    assert!(matches!(lost, TrackingLost::IllConditioned { .. }), "{lost}");
    assert!(lost.to_string().contains("single plane"), "{lost}");
}

#[test]
fn an_empty_frame_or_model_loses_tracking() {
    let scene = Scene::room();
    let pose = reference_pose();
    let depth = scene.render(&K, &pose);
    let model = ModelView::from_depth(&depth, K, pose);
    let empty = vec![0.0_f32; K.pixel_count()];
    let settings = TrackingSettings::default();
    let lost = track(&empty, &K, &model, pose, &settings).expect_err("nothing to track");
    assert!(matches!(lost, TrackingLost::TooFewInliers { inliers: 0, candidates: 0, .. }), "{lost}");
    let no_model = ModelView::from_depth(&empty, K, pose);
    let lost = track(&depth, &K, &no_model, pose, &settings).expect_err("nothing to track against");
    assert!(matches!(lost, TrackingLost::TooFewInliers { inliers: 0, .. }), "{lost}");
    let lost = track(&depth[1..], &K, &model, pose, &settings).expect_err("wrong size");
    assert!(matches!(lost, TrackingLost::SizeMismatch { .. }), "{lost}");
}

#[test]
fn a_frame_from_elsewhere_loses_tracking() {
    // The camera turned round to face away from the corner: too few of its points meet the model, wherever ICP
    // drifts.
    let scene = Scene::room();
    let pose = reference_pose();
    let model = ModelView::from_depth(&scene.render(&K, &pose), K, pose);
    let away = DAffine3::from_rotation_translation(DQuat::from_rotation_y(2.2), DVec3::new(0.0, 0.3, 1.0));
    let frame = scene.render(&K, &away);
    assert!(track(&frame, &K, &model, pose, &TrackingSettings::default()).is_err());
}

#[test]
fn a_corridor_loses_tracking() {
    // Floor and two parallel walls, open ahead: nothing fixes the motion along the corridor.
    let corridor = Scene { planes: vec![(DVec3::Y, 1.0), (DVec3::X, -1.0), (DVec3::X, 1.0)], spheres: vec![] };
    let from = DAffine3::from_rotation_translation(DQuat::from_rotation_x(-0.3), DVec3::ZERO);
    let model = ModelView::from_depth(&corridor.render(&K, &from), K, from);
    let frame = corridor.render(&K, &(from * motion()));
    let lost = track(&frame, &K, &model, from, &TrackingSettings::default()).expect_err("the corridor slides");
    assert!(matches!(lost, TrackingLost::IllConditioned { .. }), "{lost}");
}

#[test]
fn a_wider_motion_needs_the_coarse_levels() {
    // 6 cm and 5°: the full pyramid finds it.
    let scene = Scene::room();
    let wide = DAffine3::from_rotation_translation(
        DQuat::from_axis_angle(DVec3::new(-0.5, 1.0, 0.3).normalize(), 5f64.to_radians()),
        DVec3::new(0.04, 0.03, -0.03),
    );
    let (from, to) = (reference_pose(), reference_pose() * wide);
    let model = ModelView::from_depth(&scene.render(&K, &from), K, from);
    let frame = scene.render(&K, &to);
    let result = track(&frame, &K, &model, from, &TrackingSettings::default()).expect("tracked");
    let (dt, dr) = pose_error(&result.pose, &to);
    assert!(dt < 1e-3 && dr < 0.1, "{dt} m, {dr}° off");
    // The finest level alone pairs too few surfaces within its 10 cm (the back wall): it says so, and gives no pose.
    let fine_only = TrackingSettings { iterations: [10, 0, 0], ..TrackingSettings::default() };
    let lost = track(&frame, &K, &model, from, &fine_only).expect_err("too far for the finest level");
    assert!(matches!(lost, TrackingLost::IllConditioned { level: 0, .. }), "{lost}");
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(12))]
    #[test]
    fn small_motions_are_recovered(
        t in proptest::array::uniform3(-0.015f64..0.015),
        axis in proptest::array::uniform3(-1.0f64..1.0),
        degrees in 0.0f64..2.5,
    ) {
        let axis = DVec3::from(axis).try_normalize().unwrap_or(DVec3::Y);
        let motion = DAffine3::from_rotation_translation(
            DQuat::from_axis_angle(axis, degrees.to_radians()),
            DVec3::from(t),
        );
        let scene = Scene::room();
        let (from, to) = (reference_pose(), reference_pose() * motion);
        let model = ModelView::from_depth(&scene.render(&K, &from), K, from);
        let result = track(&scene.render(&K, &to), &K, &model, from, &TrackingSettings::default());
        let result = result.map_err(|e| proptest::test_runner::TestCaseError::fail(e.to_string()))?;
        let (dt, dr) = pose_error(&result.pose, &to);
        proptest::prop_assert!(dt < 1e-3 && dr < 0.1, "{} m, {}° off", dt, dr);
    }
}
