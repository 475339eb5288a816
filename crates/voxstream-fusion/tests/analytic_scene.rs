//! Fusion of an analytic scene (a ball on a floor, depth rendered exactly and with Kinect-like noise) checked
//! against the true surface: the surface voxels' faces lie within a voxel of it, surface offsets place it within a
//! small share of a voxel, streaming chunks to disk changes no bit, and the ray-cast surface lands where the true
//! surface is.

use glam::{DMat3, DVec3};
use voxstream_fusion::caster::{self, Surface};
use voxstream_fusion::surface::surface_points;
use voxstream_fusion::{Fusion, FusionSettings, Intrinsics, Pose, RgbdFrame};

const BALL: DVec3 = DVec3::new(0.0, 0.0, 0.3);
const RADIUS: f64 = 0.3;
const FLOOR_HALF: f64 = 1.5;

fn intrinsics() -> Intrinsics {
    Intrinsics { width: 160, height: 120, fx: 131.25, fy: 131.25, cx: 79.5, cy: 59.5 }
}

/// Camera `i` of `n` on an orbit of radius 1.2 m, 0.6 m up, looking at the ball.
fn pose(i: usize, n: usize) -> Pose {
    let a = i as f64 / n as f64 * std::f64::consts::TAU;
    let position = DVec3::new(1.2 * a.cos(), 1.2 * a.sin(), 0.6);
    let forward = (DVec3::new(0.0, 0.0, 0.2) - position).normalize();
    let right = forward.cross(DVec3::Z).normalize();
    let down = forward.cross(right);
    Pose::from_mat3_translation(DMat3::from_cols(right, down, forward), position)
}

/// Distance from `p` to the true surface.
fn truth_distance(p: DVec3) -> f64 {
    let ball = ((p - BALL).length() - RADIUS).abs();
    let floor = if p.x.abs() <= FLOOR_HALF && p.y.abs() <= FLOOR_HALF { p.z.abs() } else { f64::INFINITY };
    ball.min(floor)
}

fn hash_normal(i: u64) -> f64 {
    let mix = |mut z: u64| {
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58476d1ce4e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d049bb133111eb);
        z ^ (z >> 31)
    };
    let a = (mix(i) >> 11) as f64 / (1u64 << 53) as f64;
    let b = (mix(i ^ 0x9e3779b97f4a7c15) >> 11) as f64 / (1u64 << 53) as f64;
    (-2.0 * (a.max(1e-300)).ln()).sqrt() * (std::f64::consts::TAU * b).cos()
}

/// The depth image of the scene from `pose`, with noise of `noise` times the Kinect model's σ.
fn frame(pose: &Pose, noise: f64, seed: u64) -> RgbdFrame {
    let k = intrinsics();
    let mut depth = vec![0.0f32; k.pixel_count()];
    let mut colour = vec![[0u8; 3]; k.pixel_count()];
    for v in 0..k.height {
        for u in 0..k.width {
            let d = pose.matrix3 * k.unproject(u as f64, v as f64, 1.0);
            let o = pose.translation;
            let mut best = f64::INFINITY;
            let mut rgb = [0u8; 3];
            if d.z < 0.0 {
                let t = -o.z / d.z;
                let p = o + d * t;
                if p.x.abs() <= FLOOR_HALF && p.y.abs() <= FLOOR_HALF {
                    best = t;
                    rgb = [90, 140, 60];
                }
            }
            let oc = o - BALL;
            let (a, b, c) = (d.dot(d), oc.dot(d), oc.dot(oc) - RADIUS * RADIUS);
            let disc = b * b - a * c;
            if disc > 0.0 {
                let t = (-b - disc.sqrt()) / a;
                if t > 0.0 && t < best {
                    best = t;
                    rgb = [200, 60, 40];
                }
            }
            if best.is_finite() {
                let i = (v * k.width + u) as usize;
                let sigma = voxstream_fusion::integrate::IntegrationSettings::sensor_sigma(best as f32) as f64;
                depth[i] = (best + noise * sigma * hash_normal(seed * 1_000_003 + i as u64)) as f32;
                colour[i] = rgb;
            }
        }
    }
    RgbdFrame { timestamp: 0.0, intrinsics: k, depth, colour, pose: Some(*pose) }
}

fn fuse(frames: usize, noise: f64, settings: FusionSettings) -> Fusion {
    let mut fusion = Fusion::new(settings).unwrap();
    for i in 0..frames {
        let p = pose(i, 48);
        fusion.add_frame(&frame(&p, noise, i as u64), p).unwrap();
    }
    fusion.finish().unwrap();
    fusion
}

fn errors(fusion: &Fusion) -> (f64, f64, usize) {
    let points = surface_points(fusion.map());
    let mut d: Vec<f64> = points.iter().map(|p| truth_distance(p.position)).collect();
    d.sort_by(f64::total_cmp);
    let mean = d.iter().sum::<f64>() / d.len() as f64;
    (mean, d[d.len() * 95 / 100], d.len())
}

#[test]
fn exact_depth_fuses_to_within_half_a_voxel() {
    let fusion = fuse(48, 0.0, FusionSettings { window: 8, ..FusionSettings::default() });
    let (mean, p95, count) = errors(&fusion);
    eprintln!("exact: mean {mean} p95 {p95} count {count} {:?}", fusion.stats);
    assert!(count > 5_000, "{count} surface points");
    assert!(mean < 0.003 && p95 < 0.008, "mean {mean} m, p95 {p95} m at 1 cm voxels");
    assert!(fusion.stats.windows >= 48 / 4 - 1, "{:?}", fusion.stats);
    // The surface voxels carry the colour of what they are: the ball red, the floor green.
    let points = surface_points(fusion.map());
    let ball_red = points
        .iter()
        .filter(|p| (p.position - BALL).length() < RADIUS + 0.01 && p.position.z > 0.1)
        .filter_map(|p| p.colour)
        .filter(|c| c[0] > 150 && c[1] < 100)
        .count();
    assert!(ball_red > 500, "{ball_red} red ball points");
}

#[test]
fn kinect_noise_fuses_to_within_a_voxel() {
    let fusion = fuse(48, 1.0, FusionSettings { window: 8, ..FusionSettings::default() });
    let (mean, p95, _) = errors(&fusion);
    eprintln!("noisy: mean {mean} p95 {p95}");
    assert!(mean < 0.004 && p95 < 0.01, "mean {mean} m, p95 {p95} m at 1 cm voxels with noise");
}

fn sign_only() -> FusionSettings {
    let mut settings = FusionSettings { window: 8, ..FusionSettings::default() };
    settings.integration.surface_offsets = false;
    settings
}

/// Mean and 95th percentile distance to the ball of the surface points on it (the floor lies on voxel faces here,
/// where a sign bit is exact, so it would flatter the sign-only fusion), the share of them interpolated from
/// surface offsets, and the bricks' bytes.
fn ball_errors(fusion: &Fusion) -> (f64, f64, f64, usize) {
    let points: Vec<_> = surface_points(fusion.map())
        .into_iter()
        .filter(|p| p.position.z > 0.03 && (p.position - BALL).length() < RADIUS + 0.03)
        .collect();
    let mut d: Vec<f64> = points.iter().map(|p| ((p.position - BALL).length() - RADIUS).abs()).collect();
    d.sort_by(f64::total_cmp);
    let interpolated = points.iter().filter(|p| p.interpolated).count() as f64 / points.len() as f64;
    let bytes = fusion.map().iter().map(|(_, b)| b.bytes()).sum::<usize>();
    (d.iter().sum::<f64>() / d.len() as f64, d[d.len() * 95 / 100], interpolated, bytes)
}

#[test]
fn surface_offsets_place_the_surface_between_voxel_centres() {
    for noise in [0.0, 1.0] {
        let faces = ball_errors(&fuse(48, noise, sign_only()));
        let offsets = ball_errors(&fuse(48, noise, FusionSettings { window: 8, ..FusionSettings::default() }));
        eprintln!("noise {noise}: (mean, p95, interpolated, bytes) sign only {faces:?}, with offsets {offsets:?}");
        // Raw face centres (no smoothing here) lie a quarter of a voxel from a curved surface on average.
        assert!(offsets.0 < 0.5 * faces.0, "noise {noise}: mean {} m with offsets, {} m without", offsets.0, faces.0);
        assert!(offsets.1 < 0.6 * faces.1, "noise {noise}: p95 {} m with offsets, {} m without", offsets.1, faces.1);
        assert!(offsets.2 > 0.95, "noise {noise}: {} of the points interpolated", offsets.2);
        assert_eq!(faces.2, 0.0, "a sign-only fusion keeps no offsets");
        // The bricks hold more, but not many times more: two bytes for each voxel within two voxels of the surface,
        // in blocks of 32 voxels kept only where such voxels are (measured: 1.6× here).
        let ratio = offsets.3 as f64 / faces.3 as f64;
        assert!((1.0..2.5).contains(&ratio), "noise {noise}: offsets take {ratio}× the bytes");
    }
}

#[test]
fn streaming_chunks_out_changes_no_bit() {
    let whole = fuse(24, 1.0, FusionSettings { window: 8, ..FusionSettings::default() });
    let dir = std::env::temp_dir().join(format!("voxstream-fusion-stream-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let settings = FusionSettings {
        window: 8,
        memory_budget: 64 << 10,
        keep_radius: 0.0,
        spill_dir: Some(dir.clone()),
        ..FusionSettings::default()
    };
    let mut streamed = fuse(24, 1.0, settings);
    let map = streamed.map();
    assert!(map.chunks_written > 0 && map.chunks_read > 0, "{} written, {} read", map.chunks_written, map.chunks_read);
    streamed.map_mut().read_all_back().unwrap();
    let a = streamed.map();
    let b = whole.map();
    assert_eq!(a.len(), b.len());
    for (key, brick) in b.iter() {
        assert_eq!(a.brick(*key), Some(brick), "brick {key}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn the_ray_cast_surface_lies_on_the_true_one() {
    let fusion = fuse(48, 0.0, FusionSettings { window: 8, ..FusionSettings::default() });
    let k = intrinsics();
    let p = pose(5, 48);
    let view = caster::render(fusion.map(), &p, &k, Surface::Confident, 5.0);
    let smoothed = caster::smooth_depth(&view, 0.01, 40);
    let truth = frame(&p, 0.0, 0);
    let mut raw_errors = Vec::new();
    let mut smooth_errors = Vec::new();
    for ((&t, &raw), &smooth) in truth.depth.iter().zip(&view.depth).zip(&smoothed) {
        if t > 0.0 && raw > 0.0 {
            raw_errors.push((raw - t).abs());
            smooth_errors.push((smooth - t).abs());
        }
    }
    let hit = raw_errors.len() as f64 / truth.depth.iter().filter(|&&d| d > 0.0).count() as f64;
    assert!(hit > 0.9, "{hit} of the true surface's pixels hit");
    let mean = |e: &[f32]| e.iter().sum::<f32>() / e.len() as f32;
    eprintln!("hit {hit} raw {} smooth {}", mean(&raw_errors), mean(&smooth_errors));
    assert!(mean(&raw_errors) < 0.015, "raw {}", mean(&raw_errors));
    assert!(
        mean(&smooth_errors) < mean(&raw_errors),
        "smoothing moves voxel faces towards the surface: {} vs {}",
        mean(&smooth_errors),
        mean(&raw_errors)
    );
}
