//! The fluid preview against the density isosurface of the same particles (issue 48's quality measure): for each
//! pixel, the depth and normal of the smoothed spheres against those of the SPH density's isosurface at half the
//! median density at the particles, found by marching the ray through the kernel sum (`ParticleProducer::density`,
//! no bricks) and bisecting, its normal the density's gradient.
//!
//! `cargo run --release -p voxstream-fluid --example versus_density -- data/real/dam_break_3d_fluid.vtu 2 256`
//! (file, the SPH kernel's reach in smoothing lengths — 2 for PySPH —, image size).

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;
use voxstream_fluid::scene::{FluidRenderSettings, FluidScene, Smoothing, DEFAULT_ROF_STRENGTH};
use voxstream_fluid::shading::normals_from_depth;
use voxstream_fluid::{FluidBins, FluidSettings};
use voxstream_geometry::formats::{read_geometry, RawGeometry};
use voxstream_geometry::{ParticleProducer, ParticleSet, ParticleTreeSettings};
use voxstream_render::Camera;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).map_or("data/real/dam_break_3d_fluid.vtu", String::as_str);
    let scale: f64 = args.get(2).map_or(2.0, |s| s.parse().expect("a kernel reach factor"));
    let size: u32 = args.get(3).map_or(256, |s| s.parse().expect("an image size"));
    let RawGeometry::Particles(raw) = read_geometry(std::path::Path::new(path)).expect("a particle file") else {
        panic!("{path} holds a mesh")
    };
    let particles = ParticleSet::new(raw).expect("valid particles");
    let settings = ParticleTreeSettings { smoothing_scale: scale, ..ParticleTreeSettings::default() };
    let producer = ParticleProducer::new(&particles, settings).expect("the density's index");
    let fit = producer.fit();
    let density = |p: DVec3| producer.density(fit.to_unit(p.to_array()), 0.0) / fit.size.powi(3);
    let mut at_particles: Vec<f64> = particles.positions().iter().map(|p| density(DVec3::from(*p))).collect();
    at_particles.sort_by(f64::total_cmp);
    let iso = 0.5 * at_particles[at_particles.len() / 2];
    let h = particles.smoothing().first().map_or(0.04, |&h| f64::from(h)) * scale;

    let bins = FluidBins::build(&particles, FluidSettings::default(), &mut |_| {}).expect("binned");
    let radius = bins.radius;
    let (lower, upper) = bins.bounds;
    let centre = (DVec3::from(lower) + DVec3::from(upper)) * 0.5;
    let extent = (DVec3::from(upper) - DVec3::from(lower)).length();
    let eye = centre + DVec3::new(0.55, 0.45, 0.7).normalize() * extent * 1.6;
    let camera = Camera { eye: eye.to_array(), target: centre.to_array(), up: [0.0, 1.0, 0.0], fov: 40.0 };
    let frame = camera.frame(size, size).expect("a camera");
    eprintln!("{path}: {} particles, radius {radius:.4}, kernel reach {h:.4}, iso {iso:.4}", particles.len());

    // The isosurface: march at an eighth of the kernel's reach from the padded box, bisect the crossing.
    let started = Instant::now();
    let pad = h * 1.5;
    let (box_lo, box_hi) = (DVec3::from(lower) - pad, DVec3::from(upper) + pad);
    let reference: Vec<Option<(f64, DVec3)>> = (0..size * size)
        .into_par_iter()
        .map(|i| {
            let (x, y) = (i % size, i / size);
            let dir = frame.direction(x, y, size, size);
            let inv = dir.recip();
            let a = (box_lo - frame.eye) * inv;
            let b = (box_hi - frame.eye) * inv;
            let (t0, t1) = (a.min(b).max_element().max(0.0), a.max(b).min_element());
            if t0 >= t1 {
                return None;
            }
            let step = h / 8.0;
            let mut t = t0;
            let mut previous = density(frame.eye + dir * t);
            while t < t1 {
                let next = t + step;
                let value = density(frame.eye + dir * next);
                if previous < iso && value >= iso {
                    let (mut lo, mut hi) = (t, next);
                    for _ in 0..30 {
                        let mid = 0.5 * (lo + hi);
                        if density(frame.eye + dir * mid) < iso {
                            lo = mid;
                        } else {
                            hi = mid;
                        }
                    }
                    let p = frame.eye + dir * hi;
                    let e = h / 16.0;
                    let gradient = DVec3::new(
                        density(p + DVec3::X * e) - density(p - DVec3::X * e),
                        density(p + DVec3::Y * e) - density(p - DVec3::Y * e),
                        density(p + DVec3::Z * e) - density(p - DVec3::Z * e),
                    );
                    return Some((hi * dir.dot(frame.forward), -gradient.normalize_or_zero()));
                }
                previous = value;
                t = next;
            }
            None
        })
        .collect();
    eprintln!("isosurface marched in {:.1} s", started.elapsed().as_secs_f64());

    println!("| smoothing | pixels (iso / fluid / both) | depth error, mean / 90th pct (radii) | normal error, mean / median (°) |");
    println!("|---|---|---|---|");
    for (name, smoothing) in [
        ("none", Smoothing::None),
        ("bilateral", Smoothing::Bilateral),
        ("rof (default)", Smoothing::Rof { iterations: 75, strength: DEFAULT_ROF_STRENGTH }),
    ] {
        let settings = FluidRenderSettings { smoothing, foam_fraction: 0.0, ..FluidRenderSettings::default() };
        let bins = FluidBins::build(&particles, FluidSettings::default(), &mut |_| {}).expect("binned");
        let mut scene = FluidScene::new(bins, 1 << 30, settings).expect("a scene");
        let rendered = scene.render(&camera, size, size).expect("a frame");
        let normals = normals_from_depth(&rendered.depth, &frame, size, size);
        let (mut depth_errors, mut angles) = (Vec::new(), Vec::new());
        let (mut iso_pixels, mut fluid_pixels) = (0, 0);
        for (i, r) in reference.iter().enumerate() {
            let z = f64::from(rendered.depth[i]);
            iso_pixels += usize::from(r.is_some());
            fluid_pixels += usize::from(z.is_finite());
            if let (Some((z_iso, n_iso)), true) = (r, z.is_finite()) {
                depth_errors.push((z - z_iso).abs() / radius);
                if let Some(n) = normals[i] {
                    angles.push(n.dot(*n_iso).clamp(-1.0, 1.0).acos().to_degrees());
                }
            }
        }
        depth_errors.sort_by(f64::total_cmp);
        angles.sort_by(f64::total_cmp);
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
        println!(
            "| {name} | {iso_pixels} / {fluid_pixels} / {} | {:.2} / {:.2} | {:.1} / {:.1} |",
            depth_errors.len(),
            mean(&depth_errors),
            depth_errors[depth_errors.len() * 9 / 10],
            mean(&angles),
            angles[angles.len() / 2],
        );
    }
}
