//! The fluid preview against an independent reference: particles filling a ball, whose true surface is a sphere
//! with normals pointing away from its centre. The spheres' surface must lie where the ball's is, and screen-space
//! smoothing (Reichl §6.5.3) must bring the surface's positions and normals closer to the sphere's than the bare
//! spheres are, total variation at least as well as the bilateral filter.

use glam::DVec3;
use voxstream_fluid::scene::{FluidRenderSettings, FluidScene, Smoothing, DEFAULT_ROF_STRENGTH};
use voxstream_fluid::shading::{normals_from_depth, unproject};
use voxstream_fluid::{FluidBins, FluidSettings};
use voxstream_geometry::{ParticleSet, RawParticles};
use voxstream_render::Camera;

/// A jittered lattice of spacing `h` inside the ball of radius `r` at the origin.
fn ball(r: f64, h: f64) -> Vec<[f64; 3]> {
    let n = (r / h).ceil() as i64;
    let mut state = 99u64;
    let mut random = || {
        state = state.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
        (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let mut out = Vec::new();
    for k in -n..=n {
        for j in -n..=n {
            for i in -n..=n {
                let p =
                    [(i as f64 + 0.3 * random()) * h, (j as f64 + 0.3 * random()) * h, (k as f64 + 0.3 * random()) * h];
                if p.iter().map(|v| v * v).sum::<f64>() <= r * r {
                    out.push(p);
                }
            }
        }
    }
    out
}

/// What a render of the ball looks like against the sphere: the spread of the surface points' distances from the
/// centre, their mean, the mean angle (degrees) between the normals from depth and the sphere's, and the
/// foreground pixels.
struct Fidelity {
    distance_spread: f64,
    mean_distance: f64,
    normal_degrees: f64,
    pixels: usize,
}

fn render(smoothing: Smoothing) -> (Fidelity, f64) {
    let particles = ParticleSet::new(RawParticles { positions: ball(1.0, 0.04), ..Default::default() }).unwrap();
    let bins = FluidBins::build(&particles, FluidSettings::default(), &mut |_| {}).unwrap();
    let radius = bins.radius;
    let settings = FluidRenderSettings { smoothing, foam_fraction: 0.0, ..FluidRenderSettings::default() };
    let mut scene = FluidScene::new(bins, 256 << 20, settings).unwrap();
    let camera = Camera { eye: [0.0, 0.8, 4.0], target: [0.0; 3], up: [0.0, 1.0, 0.0], fov: 40.0 };
    let (w, h) = (192u32, 192u32);
    let frame = scene.render(&camera, w, h).unwrap();
    assert!(frame.statistics.complete);
    let cam = camera.frame(w, h).unwrap();
    let normals = normals_from_depth(&frame.depth, &cam, w, h);
    let (mut distances, mut angles) = (Vec::new(), Vec::new());
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) as usize;
            let z = f64::from(frame.depth[i]);
            if !z.is_finite() {
                continue;
            }
            let p = unproject(&cam, i64::from(x), i64::from(y), z, w, h);
            distances.push(p.length());
            // Away from the silhouette, where the sphere's normal is well defined on screen.
            if let Some(n) = normals[i] {
                let true_normal = p.normalize();
                if true_normal.dot(-cam.forward) > 0.3 {
                    angles.push(n.dot(true_normal).clamp(-1.0, 1.0).acos().to_degrees());
                }
            }
        }
    }
    let mean = distances.iter().sum::<f64>() / distances.len() as f64;
    let spread = (distances.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / distances.len() as f64).sqrt();
    let normal_degrees = angles.iter().sum::<f64>() / angles.len() as f64;
    let fidelity = Fidelity { distance_spread: spread, mean_distance: mean, normal_degrees, pixels: distances.len() };
    (fidelity, radius)
}

#[test]
fn a_ball_of_particles_is_drawn_where_the_ball_is_and_smoothing_brings_it_closer() {
    let (none, radius) = render(Smoothing::None);
    let (rof, _) = render(Smoothing::Rof { iterations: 75, strength: DEFAULT_ROF_STRENGTH });
    let (bilateral, _) = render(Smoothing::Bilateral);
    for (name, f) in [("none", &none), ("rof", &rof), ("bilateral", &bilateral)] {
        eprintln!(
            "{name}: distance {:.4} ± {:.4}, normals off by {:.2}°, {} pixels (radius {radius:.4})",
            f.mean_distance, f.distance_spread, f.normal_degrees, f.pixels
        );
    }
    // The ball's silhouette: a disc of the sphere's angular radius (the outermost spheres add up to a radius).
    let distance = DVec3::new(0.0, 0.8, 4.0).length();
    let angular = |r: f64| (r / distance).asin();
    let pixels_of = |r: f64| {
        let half = (20f64).to_radians().tan();
        let disc = (angular(r).tan() / half * 96.0).powi(2) * std::f64::consts::PI;
        disc as usize
    };
    assert!(none.pixels > pixels_of(1.0) * 95 / 100 && none.pixels < pixels_of(1.0 + 2.0 * radius), "{}", none.pixels);
    // The surface lies on the ball's, outside by at most a sphere's radius on average.
    assert!(none.mean_distance > 1.0 - radius && none.mean_distance < 1.0 + radius, "{}", none.mean_distance);
    // The bare spheres are bumpy; total variation flattens them: positions and normals closer to the sphere's.
    assert!(rof.distance_spread < none.distance_spread, "{} vs {}", rof.distance_spread, none.distance_spread);
    assert!(rof.normal_degrees < none.normal_degrees / 2.0, "{} vs {}", rof.normal_degrees, none.normal_degrees);
    assert!(bilateral.normal_degrees < none.normal_degrees, "{} vs {}", bilateral.normal_degrees, none.normal_degrees);
    assert!(rof.normal_degrees <= bilateral.normal_degrees, "{} vs {}", rof.normal_degrees, bilateral.normal_degrees);
    // Smoothing keeps the ball where it is.
    assert!((rof.mean_distance - none.mean_distance).abs() < radius, "{} vs {}", rof.mean_distance, none.mean_distance);
}

/// The measurement behind [`DEFAULT_ROF_STRENGTH`]: `cargo test --release -p voxstream-fluid --test fluid_ball
/// sweep -- --ignored --nocapture`.
#[test]
#[ignore = "a measurement, not a check"]
fn sweep() {
    for s in [1.0f32, 2.0, 4.0, 8.0, 16.0, 32.0] {
        for it in [75u32, 200] {
            let (f, _) = render(Smoothing::Rof { iterations: it, strength: s });
            eprintln!("s {s} it {it}: ± {:.4}, {:.2}°", f.distance_spread, f.normal_degrees);
        }
    }
}
