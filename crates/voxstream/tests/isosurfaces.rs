//! Exact isosurfaces (issue 11) on whole frames: hit distances against closed forms, culling that changes no bit,
//! surfaces that stay closed where the level of detail changes, images independent of the thread count, and one
//! descent per node crossed.

mod common;

use glam::DVec3;
use voxstream::scenes::builtin;
use voxstream_core::{NodeContent, NodeKey, ProduceError, Produced, Producer, TreeShape};
use voxstream_engine::{LoopLimits, Mode, Session};
use voxstream_procedural::brick_fill::fill_brick;
use voxstream_render::isosurface::{Isosurfaces, SurfaceSettings};
use voxstream_render::{
    Camera, DescentPath, Image, IsoSurface, Ray, RayStats, RenderSettings, Shading, TransferFunction, Traversal,
};

const SIZE: u32 = 64;

/// A field given in closed form, point-sampled into bricks of 16³ down to level 4 (256³).
struct Field<F: Fn(DVec3) -> f64 + Send + Sync> {
    density: F,
}

impl<F: Fn(DVec3) -> f64 + Send + Sync> Producer for Field<F> {
    fn shape(&self) -> TreeShape {
        TreeShape::new(2, 16, 4).expect("shape")
    }

    fn produce(&self, key: NodeKey, voxels: &mut [u16]) -> Result<Produced, ProduceError> {
        fill_brick(&self.shape(), &key, voxels, |p| (self.density)(p));
        Ok(Produced { content: NodeContent::Brick, is_terminal: key.level >= 4 })
    }
}

/// The finest voxel edge (volume units = world units here).
const FINEST_VOXEL: f64 = 1.0 / 256.0;

fn surface(value: f64) -> IsoSurface {
    IsoSurface { value, color: [0.9, 0.75, 0.65], opacity: 1.0 }
}

fn settings_for(surfaces: Vec<IsoSurface>) -> RenderSettings {
    RenderSettings { width: SIZE, height: SIZE, shading: Shading::Phong, surfaces, ..RenderSettings::default() }
}

fn session<P: Producer>(producer: P, settings: RenderSettings) -> Session<P> {
    let tf = TransferFunction::new(vec![[0.0, 0.0, 0.0, 0.0, 0.0], [1.0, 1.0, 1.0, 1.0, 0.0]], None).unwrap();
    Session::new(producer, &tf, settings, 256 << 20, LoopLimits::default()).expect("session")
}

/// Converges `camera`'s frame, then traces every pixel's ray again through the resident tree and returns the first
/// crossing's distance per pixel (row-major).
fn hit_distances<P: Producer>(session: &mut Session<P>, camera: &Camera) -> Vec<Option<f64>> {
    let result = session.render(camera, Mode::Converged).expect("render");
    assert!(result.is_converged(), "not converged after {} passes", result.passes);
    let settings = session.settings().clone();
    let surfaces = SurfaceSettings::new(&settings, |v| v);
    let view = session.cache().view();
    let traversal = Traversal::new(view, session.cache().feedback(), &settings);
    let frame = camera.frame(SIZE, SIZE).expect("camera");
    let mut path = DescentPath::new(view);
    let (mut stats, mut requests) = (RayStats::default(), Vec::new());
    let mut hits = Vec::new();
    for y in 0..SIZE {
        for x in 0..SIZE {
            let direction = common::pixel_direction(camera, x, y, SIZE, SIZE);
            let ray = Ray { origin: DVec3::from(camera.eye), direction, spread: frame.pixel_spread, start: 0.0 };
            let mut integrand = Isosurfaces::new(&surfaces, direction);
            traversal.trace(&ray, &mut integrand, &mut stats, &mut requests, &mut path);
            hits.push(integrand.first_hit());
        }
    }
    assert!(requests.is_empty(), "a converged frame's rays need nothing more");
    hits
}

/// Hit errors (in finest voxels) of rays against the plane through `c` with normal `n`, for the field
/// f = ½ + (p − c)·n / w, seen from `distance` along `n` with `lod_bias`.
fn plane_errors(w: f64, lod_bias: f64) -> (usize, f64) {
    let (c, n) = (DVec3::new(0.5, 0.45, 0.55), DVec3::new(1.0, 2.0, 3.0).normalize());
    let settings = RenderSettings { lod_bias, ..settings_for(vec![surface(0.5)]) };
    let mut session = session(Field { density: move |p: DVec3| 0.5 + (p - c).dot(n) / w }, settings);
    let eye = c + (n + DVec3::new(0.3, -0.2, 0.0)).normalize() * 0.9;
    let camera = Camera { eye: eye.to_array(), target: c.to_array(), up: [0.0, 0.0, 1.0], fov: 50.0 };
    let hits = hit_distances(&mut session, &camera);
    let (mut checked, mut worst) = (0, 0.0f64);
    for (index, hit) in hits.iter().enumerate() {
        let d = common::pixel_direction(&camera, index as u32 % SIZE, index as u32 / SIZE, SIZE, SIZE);
        let t = (c - eye).dot(n) / d.dot(n);
        let p = eye + d * t;
        // Only where the plane lies inside the data box (and not within two voxels of its faces).
        if !(0..3).all(|a| p[a] > 2.0 * FINEST_VOXEL && p[a] < 1.0 - 2.0 * FINEST_VOXEL) {
            continue;
        }
        let hit = hit.unwrap_or_else(|| panic!("pixel {index}: the plane at t = {t} was missed"));
        worst = worst.max((hit - t).abs() / FINEST_VOXEL);
        checked += 1;
    }
    assert!(checked > (SIZE * SIZE / 2) as usize, "only {checked} rays cross the plane inside the box");
    (checked, worst)
}

#[test]
fn a_plane_is_hit_at_its_closed_form_distance() {
    // f is linear, so trilinear interpolation reproduces it exactly at every level; the only error left is the
    // 16-bit quantisation of the bricks, ½/65535 in value, i.e. ½/65535·w in distance.
    // At the finest level (bias +8) with a steep field (w = 1/16 unit, f clamped 8 voxels from the plane): the
    // quantisation is 1.2e-4 finest voxel.
    let (checked, worst) = plane_errors(1.0 / 16.0, 8.0);
    println!("plane, finest level: {checked} rays, worst hit error {worst:.2e} finest voxel");
    assert!(worst < 1e-3, "worst hit error {worst} finest voxel");
    // With the cone's level of detail (levels 2–4, voxels up to 1/64) and a field that stays unclamped over the
    // whole cube (w = 1): quantisation 7.6e-6 unit = 2e-3 finest voxel = 3e-5 voxel of level 2.
    let (checked, worst) = plane_errors(1.0, 0.0);
    println!("plane, cone level of detail: {checked} rays, worst hit error {worst:.2e} finest voxel");
    assert!(worst < 4e-3, "worst hit error {worst} finest voxel");
}

/// A ball of radius `R` around `C`: f = ½ + (R − |p − C|)/W, so f ≥ ½ inside.
const C: DVec3 = DVec3::new(0.5, 0.5, 0.5);
const R: f64 = 0.3;
const W: f64 = 0.1;

fn ball(p: DVec3) -> f64 {
    0.5 + (R - (p - C).length()) / W
}

#[test]
fn a_sphere_stays_closed_where_the_level_of_detail_changes() {
    // A zoom path: near views put the sphere's front at fine levels and its sides at coarser ones (the cone widens
    // with distance, and the negative bias coarsens everything), so rays cross level seams near the surface. Every
    // ray that meets the analytic sphere must hit the surface at its front, within a voxel of the level it reads:
    // a crack at a seam would let the ray through to the far side (an error of up to 2R) or out of the sphere.
    for (distance, lod_bias) in [(0.75, 0.0), (1.2, -1.0), (2.5, -1.5), (5.0, -0.5)] {
        let settings = RenderSettings { lod_bias, ..settings_for(vec![surface(0.5)]) };
        let mut session = session(Field { density: ball }, settings);
        let eye = C + DVec3::new(0.6, -0.5, 0.62).normalize() * distance;
        // The sphere fills about half the image's height.
        let fov = (4.0 * (R / distance).asin()).to_degrees().min(100.0);
        let camera = Camera { eye: eye.to_array(), target: C.to_array(), up: [0.0, 0.0, 1.0], fov };
        let hits = hit_distances(&mut session, &camera);
        let (mut checked, mut worst) = (0, 0.0f64);
        for (index, hit) in hits.iter().enumerate() {
            let d = common::pixel_direction(&camera, index as u32 % SIZE, index as u32 / SIZE, SIZE, SIZE);
            // Closed-form front intersection with the sphere of radius R.
            let oc = eye - C;
            let b = oc.dot(d);
            let disc = b * b - (oc.length_squared() - R * R);
            // Rays grazing the silhouette (passing within 0.98 R of the centre) may leave through a coarse level's
            // slightly smaller sphere; every other ray must hit.
            if disc <= (0.2 * R).powi(2) {
                continue;
            }
            let t = -b - disc.sqrt();
            let hit = hit.unwrap_or_else(|| panic!("eye at {distance}: pixel {index} passed through the sphere"));
            worst = worst.max((hit - t).abs());
            checked += 1;
        }
        println!("sphere from {distance} (bias {lod_bias}): {checked} rays, worst |hit − closed form| {worst:.2e}");
        assert!(checked > 400, "only {checked} rays meet the sphere");
        // The coarsest level used here has voxels of 1/32: the surface moves by a fraction of one.
        assert!(worst < 1.0 / 32.0, "eye at {distance}: a hit is {worst} from the front of the sphere");
    }
}

/// The ball's field with the bounds of each subtree known (what a store's per-brick min/max gives): the distance
/// from `C` over the node's box grown by one voxel of its level.
struct BoundedBall;

impl Producer for BoundedBall {
    fn shape(&self) -> TreeShape {
        Field { density: ball }.shape()
    }

    fn produce(&self, key: NodeKey, voxels: &mut [u16]) -> Result<Produced, ProduceError> {
        Field { density: ball }.produce(key, voxels)
    }

    fn subtree_range(&self, key: NodeKey) -> Option<[f32; 2]> {
        let (lower, size) = key.bounds(&self.shape());
        let margin = size / 16.0;
        let (lo, hi) = (DVec3::from(lower) - margin, DVec3::from(lower) + size + margin);
        let nearest = C.clamp(lo, hi);
        let farthest = DVec3::select(C.cmplt((lo + hi) * 0.5), hi, lo);
        let f = |p: DVec3| ball(p).clamp(0.0, 1.0) as f32;
        Some([f(farthest), f(nearest)])
    }
}

#[test]
fn subtrees_that_cannot_hold_the_surface_are_never_loaded() {
    // The surface at 0.55, just inside the ball's edge: nodes whose box (grown by a voxel) lies wholly outside the
    // ball (all 0) or wholly inside the 0.55 sphere need no finer bricks once the ray knows which side it is on.
    let camera = Camera { eye: [0.5, 0.5, 2.2], target: [0.5, 0.5, 0.5], up: [0.0, 1.0, 0.0], fov: 35.0 };
    let render = |skip: bool| {
        let settings = RenderSettings { skip_empty_space: skip, ..settings_for(vec![surface(0.55)]) };
        let mut session = session(BoundedBall, settings);
        let result = session.render(&camera, Mode::Converged).expect("render");
        assert!(result.is_converged());
        (result.image, result.bricks_produced)
    };
    let (culled, loaded_culled) = render(true);
    let (unculled, loaded_unculled) = render(false);
    println!("bounded ball: {loaded_culled} bricks loaded with culling, {loaded_unculled} without");
    let differing = culled.pixels.iter().zip(&unculled.pixels).filter(|(a, b)| a != b).count();
    assert_eq!(differing, 0, "{differing} pixels differ with culling on");
    assert!(culled.pixels.iter().filter(|p| p[3] > 0.5).count() > (SIZE * SIZE / 8) as usize);
    assert!(loaded_culled < loaded_unculled, "culling loaded {loaded_culled} bricks, {loaded_unculled} without");
}

/// A converged isosurface frame of the built-in shell with its settings changed by `adjust`.
fn shell_frame(threads: usize, adjust: impl FnOnce(&mut RenderSettings)) -> (Image, u64) {
    let scene = builtin("shell").expect("shell");
    // The shell's density is exp(−r²): 0.5 is crossed twice, inside and outside the crest (two nested spheres),
    // and 0.9 once more, nearer the crest; the outer surface is translucent so the inner ones show.
    let surfaces = vec![
        IsoSurface { value: 0.5, color: [0.55, 0.7, 0.95], opacity: 0.4 },
        IsoSurface { value: 0.9, color: [0.95, 0.8, 0.6], opacity: 1.0 },
    ];
    let mut settings = RenderSettings { light_direction: Some([0.3, 0.8, 0.5]), ..settings_for(surfaces) };
    adjust(&mut settings);
    let mut session = session(scene.producer, settings);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("thread pool");
    let result = pool.install(|| session.render(&scene.camera, Mode::Converged)).expect("render");
    assert!(result.is_converged());
    (result.image, result.samples)
}

#[test]
fn culling_changes_no_bit() {
    let (culled, cells_culled) = shell_frame(2, |_| {});
    let (unculled, cells_unculled) = shell_frame(2, |s| s.skip_empty_space = false);
    let covered = unculled.pixels.iter().filter(|p| p[3] > 0.01).count();
    assert!(covered > (SIZE * SIZE / 4) as usize, "only {covered} pixels show a surface");
    let differing = culled.pixels.iter().zip(&unculled.pixels).filter(|(a, b)| a != b).count();
    assert_eq!(differing, 0, "{differing} pixels differ with culling on");
    println!("shell isosurfaces: {cells_culled} cells examined with culling, {cells_unculled} without");
    assert!(cells_culled * 2 < cells_unculled, "culling skipped too little: {cells_culled} vs {cells_unculled}");
    // With shadows too (the shadow rays are culled the same way).
    let (a, _) = shell_frame(2, |s| s.shadows = true);
    let (b, _) = shell_frame(2, |s| {
        s.shadows = true;
        s.skip_empty_space = false;
    });
    assert!(a.pixels == b.pixels, "culling changed a shadowed image");
}

#[test]
fn nested_translucent_surfaces_show_each_other() {
    let (both, _) = shell_frame(2, |_| {});
    let (outer_only, _) = shell_frame(2, |s| s.surfaces.truncate(1));
    // Through the centre, the ray crosses 0.5 four times (into the crest and out of it, on the near and the far
    // side; opacity 0.4 each): 1 − 0.6⁴ without the inner surface; with it, the opaque 0.9 surface ends the ray.
    let centre = ((SIZE / 2) * SIZE + SIZE / 2) as usize;
    assert!((outer_only.pixels[centre][3] - (1.0 - 0.6f32.powi(4))).abs() < 1e-4, "{:?}", outer_only.pixels[centre]);
    assert!(both.pixels[centre][3] > 0.999, "{:?}", both.pixels[centre]);
    assert!(both.pixels[centre] != outer_only.pixels[centre]);
}

#[test]
fn shadows_darken_only_what_a_surface_hides_from_the_light() {
    // The opaque surface alone, lit from the side (at right angles to the view): the half of it that faces away from
    // the light is in its own
    // shadow (two-sided Phong lights it otherwise).
    let opaque = |s: &mut RenderSettings| {
        s.surfaces.remove(0);
        s.light_direction = Some([-1.85, 0.0, 1.45]);
    };
    let (lit, _) = shell_frame(2, opaque);
    let (shadowed, _) = shell_frame(2, |s| {
        opaque(s);
        s.shadows = true;
    });
    let luminance = |p: &[f32; 4]| p[0] + p[1] + p[2];
    let darker = lit.pixels.iter().zip(&shadowed.pixels).filter(|(a, b)| luminance(b) < luminance(a) - 1e-3).count();
    let brighter = lit.pixels.iter().zip(&shadowed.pixels).filter(|(a, b)| luminance(b) > luminance(a) + 1e-6).count();
    println!("shadows: {darker} pixels darker");
    assert_eq!(brighter, 0, "a shadow never adds light");
    let covered = lit.pixels.iter().filter(|p| p[3] > 0.5).count();
    assert!(darker * 5 > covered, "only {darker} of {covered} pixels are in shadow");
    let coverage = |image: &Image| image.pixels.iter().map(|p| p[3]).sum::<f32>();
    assert_eq!(coverage(&lit), coverage(&shadowed), "shadows change colour, not coverage");
}

#[test]
fn the_image_does_not_depend_on_the_thread_count() {
    let (one, _) = shell_frame(1, |s| s.shadows = true);
    let (three, _) = shell_frame(3, |s| s.shadows = true);
    assert!(one.pixels == three.pixels);
}

#[test]
fn a_stores_subtree_ranges_bound_every_value_below_them() {
    use voxstream_store::formats::{open_volume, Endian, RawLayout};
    use voxstream_store::{import_volume, DType, ImportOptions, StoreProducer, StoreReader, VolumeInfo};

    // A 72×60×50 u8 volume with structure at every scale (a ball, a ripple, four isolated spikes of 255, one next to a brick face), imported with
    // 8³ bricks: five levels.
    let dir = std::env::temp_dir().join(format!("voxstream-subtree-ranges-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let dims = [72u64, 60, 50];
    let mut samples = Vec::new();
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let r = DVec3::new(i as f64 - 36.0, j as f64 - 30.0, k as f64 - 25.0).length();
                let mut value = (1.0 - r / 28.0).max(0.0) * (150.0 + 50.0 * (i as f64 * 0.7).sin());
                if [[5, 5, 5], [70, 3, 48], [40, 33, 27], [8, 58, 20]].contains(&[i, j, k]) {
                    value = 255.0;
                }
                samples.push(value as u8);
            }
        }
    }
    let raw = dir.join("volume.raw");
    std::fs::write(&raw, &samples).unwrap();
    let layout = RawLayout {
        info: VolumeInfo { dims, dtype: DType::U8, spacing: [1.0; 3], origin: [0.0; 3], unit: None, orientation: None },
        file_type: None,
        endian: Endian::Little,
        header_bytes: 0,
    };
    let store = dir.join("volume.zarr");
    let mut source = open_volume(&raw, Some(&layout)).unwrap();
    let options = ImportOptions { brick_size: 8, ..ImportOptions::default() };
    import_volume(source.as_mut(), &store, &options, &mut |_, _| {}).unwrap();
    let producer = StoreProducer::new(std::sync::Arc::new(StoreReader::open(&store).unwrap())).unwrap();
    let shape = producer.shape();
    assert!(shape.max_level >= 3);

    // Every brick (borders included) of a node and of all its descendants lies within the node's subtree range.
    let mut voxels = vec![0u16; shape.voxels_per_brick()];
    let mut checked = 0;
    let mut tight = 0;
    let mut stack = vec![(NodeKey::ROOT, None::<[f32; 2]>)];
    while let Some((key, mut bounds)) = stack.pop() {
        // (None only for nodes wholly outside the volume, which are empty.)
        if let Some(own) = producer.subtree_range(key).filter(|_| key.level < shape.max_level) {
            // A node's bound also holds for its children's values: check against the tightest ancestor's bound
            // and its own.
            if own[1] - own[0] < 0.9 {
                tight += 1;
            }
            bounds = Some(bounds.map_or(own, |b: [f32; 2]| [b[0].max(own[0]), b[1].min(own[1])]));
        }
        let produced = producer.produce(key, &mut voxels).unwrap();
        if produced.content == NodeContent::Brick {
            if let Some([lo, hi]) = bounds {
                let (lo, hi) = ((lo * 65535.0).floor() as u16, (hi * 65535.0).ceil() as u16);
                let outside = voxels.iter().filter(|&&v| v < lo || v > hi).count();
                assert_eq!(outside, 0, "{key:?}: {outside} voxels outside its ancestors' subtree range");
                checked += 1;
            }
            if key.level < shape.max_level {
                for child in 0..8 {
                    stack.push((key.child(child, 2), bounds));
                }
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
    println!("{checked} bricks checked, {tight} subtree ranges narrower than the data's range");
    assert!(checked > 100, "only {checked} bricks checked");
    assert!(tight > 10, "the ranges bound nothing: only {tight} are narrower than the data's");
}

#[test]
fn a_ray_takes_one_descent_per_node_whichever_way_it_crosses_their_faces() {
    // At the finest level (bias +8) a ray along x crosses the 16 nodes of level 4 on its line: 16 segments, one
    // descent each, in either direction. A face crossed towards lower coordinates must not round back into the
    // node just left (that cost an empty sliver segment, and a descent, per face). No culling and no crossing (a
    // ramp from 0.2 to 0.3, a surface at 0.9), so that every node on the line is a segment.
    let settings = RenderSettings { lod_bias: 8.0, skip_empty_space: false, ..settings_for(vec![surface(0.9)]) };
    let mut session = session(Field { density: |p: DVec3| 0.2 + 0.1 * p.x }, settings);
    let (y, z) = (0.53, 0.47);
    let camera = Camera { eye: [1.6, y, z], target: [0.0, y, z], up: [0.0, 0.0, 1.0], fov: 10.0 };
    let result = session.render(&camera, Mode::Converged).expect("render");
    assert!(result.is_converged(), "not converged after {} passes", result.passes);
    let settings = session.settings().clone();
    let surfaces = SurfaceSettings::new(&settings, |v| v);
    let view = session.cache().view();
    let traversal = Traversal::new(view, session.cache().feedback(), &settings);
    let spread = camera.frame(SIZE, SIZE).expect("camera").pixel_spread;
    let mut path = DescentPath::new(view);
    for (origin, direction) in [(DVec3::new(1.6, y, z), DVec3::NEG_X), (DVec3::new(-0.6, y, z), DVec3::X)] {
        let (mut stats, mut requests) = (RayStats::default(), Vec::new());
        let ray = Ray { origin, direction, spread, start: 0.0 };
        let mut integrand = Isosurfaces::new(&surfaces, direction);
        traversal.trace(&ray, &mut integrand, &mut stats, &mut requests, &mut path);
        assert!(requests.is_empty(), "the line's nodes are resident");
        assert_eq!(integrand.first_hit(), None);
        assert_eq!(stats.descents, 16, "direction {direction}: {} descents for 16 nodes", stats.descents);
    }
}
