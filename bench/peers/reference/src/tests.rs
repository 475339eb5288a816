//! Tests of the reference renderer against closed-form answers (constant medium, linear fields, a sphere) and of
//! its invariants (block skipping changes nothing, bad inputs are errors rather than panics).

use serde_json::{json, Value};

use crate::integrate::Renderer;
use crate::scene::{Dtype, Scene, VolumeSpec};
use crate::tf::TransferFunction;
use crate::volume::Volume;

/// A scene with the given overrides applied on top of a minimal valid one.
fn scene(overrides: Value) -> Scene {
    let mut base = json!({
        "volume": {"path": "/nonexistent.raw", "dims": [5, 5, 5], "dtype": "f32", "spacing": [1, 1, 1], "origin": [0, 0, 0]},
        "camera": {"eye": [2, 2, -10], "target": [2, 2, 2], "up": [0, 1, 0], "fov": 30.0},
        "width": 1, "height": 1,
        "mode": "volume",
        "tf": {"points": [[0, 1, 1, 1, 0.5], [2, 1, 1, 1, 0.5]], "unit_distance": 1.0},
        "shading": "none",
        "background": [0, 0, 0],
        "supersample": 1,
        "step_voxels": 0.125
    });
    if let (Some(b), Some(o)) = (base.as_object_mut(), overrides.as_object()) {
        for (k, v) in o {
            b.insert(k.clone(), v.clone());
        }
    }
    Scene::parse(&base.to_string()).expect("test scene must be valid")
}

/// Deterministic pseudo-random numbers in [0, 1).
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

fn grid(dims: [usize; 3], spacing: [f64; 3], origin: [f64; 3], f: impl Fn([f64; 3]) -> f64) -> Volume {
    let mut data = Vec::with_capacity(dims[0] * dims[1] * dims[2]);
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let p = [0, 1, 2].map(|a| origin[a] + spacing[a] * [i, j, k][a] as f64);
                data.push(f(p) as f32);
            }
        }
    }
    Volume::new(dims, spacing, origin, data).expect("test volume must be valid")
}

fn temp_path(name: &str) -> std::path::PathBuf {
    std::env::temp_dir().join(format!("peers-reference-test-{}-{name}", std::process::id()))
}

// 1. Constant medium: colour 1, alpha 0.5 per unit length, ray length 4 ⇒ 1 - 0.5^4.
#[test]
fn constant_volume_matches_beer_lambert() {
    let vol = grid([5, 5, 5], [1.0; 3], [0.0; 3], |_| 1.0);
    let expected = 1.0 - 0.5f64.powi(4);
    // The whole pipeline: one pixel, its centre ray goes straight through the middle along +z.
    let (image, stats) = Renderer::new(&scene(json!({})), &vol).unwrap().render();
    assert_eq!(stats.rays, 1);
    assert_eq!(stats.samples, 32, "4 units at 0.125 voxel steps");
    for c in &image.rgb {
        assert!((f64::from(*c) - expected).abs() < 1e-3, "got {c}, expected {expected}");
    }
    // A step that does not divide the length (short last interval) and a grey background: C + T * bg.
    let r = Renderer::new(&scene(json!({"step_voxels": 0.3, "background": [0.5, 0.5, 0.5]})), &vol).unwrap();
    let c = r.trace([0.0, 0.0, 1.0], &mut 0);
    let want = expected + 0.5f64.powi(4) * 0.5;
    assert!((c[0] - want).abs() < 1e-9, "got {c:?}, expected {want}");
}

// 2. Alpha is interpolated before the conversion to extinction.
#[test]
fn tf_interpolates_alpha_before_sigma() {
    let tf = TransferFunction::new(&[[0.0, 0.0, 0.0, 0.0, 0.0], [10.0, 1.0, 0.5, 0.0, 0.8]], 1.0).unwrap();
    assert!((tf.sigma(5.0) - (-(0.6f64).ln())).abs() < 1e-12, "sigma(5) = {}", tf.sigma(5.0));
    assert!((tf.alpha(5.0) - 0.4).abs() < 1e-12);
    assert_eq!(tf.rgba(-3.0), [0.0, 0.0, 0.0, 0.0], "clamped below");
    assert_eq!(tf.rgba(30.0), [1.0, 0.5, 0.0, 0.8], "clamped above");
    let tf2 = TransferFunction::new(&[[0.0, 0.0, 0.0, 0.0, 0.0], [10.0, 1.0, 0.5, 0.0, 0.8]], 2.0).unwrap();
    assert!((tf2.sigma(5.0) - (-(0.6f64).ln()) / 2.0).abs() < 1e-12, "unit distance scales sigma");
    assert!(TransferFunction::new(&[[1.0, 0.0, 0.0, 0.0, 0.0], [1.0, 1.0, 1.0, 1.0, 1.0]], 1.0).is_err());
    // Skip predicate: zero-alpha runs are invisible, touching a non-zero segment is visible.
    let tf3 =
        TransferFunction::new(&[[0.0, 1.0, 1.0, 1.0, 0.0], [5.0, 1.0, 1.0, 1.0, 0.0], [6.0, 1.0, 1.0, 1.0, 0.5]], 1.0)
            .unwrap();
    assert!(!tf3.may_be_visible(-4.0, 5.0));
    assert!(tf3.may_be_visible(4.0, 5.5));
    assert!(tf3.may_be_visible(7.0, 8.0));
}

// 3. Trilinear value and gradient are exact for linear fields, including non-unit spacing.
#[test]
fn trilinear_gradient_exact_for_linear_field() {
    let (a, b, c) = (2.0, -3.0, 0.5);
    let f = |p: [f64; 3]| a * p[0] + b * p[1] + c * p[2];
    let mut rng = Lcg(7);
    for (spacing, origin) in [([1.0, 1.0, 1.0], [0.0, 0.0, 0.0]), ([0.5, 2.0, 1.25], [-1.0, 2.0, 0.5])] {
        let dims = [6, 5, 7];
        let vol = grid(dims, spacing, origin, f);
        let hi = vol.box_max();
        for _ in 0..1000 {
            let p = [0, 1, 2].map(|i| origin[i] + rng.next() * (hi[i] - origin[i]));
            let (v, g) = vol.value_gradient(p);
            assert!((v - f(p)).abs() < 1e-9, "value at {p:?}: {v} vs {}", f(p));
            assert!((vol.value(p) - v).abs() == 0.0);
            for (got, want) in g.iter().zip([a, b, c]) {
                assert!((got - want).abs() < 1e-9, "gradient at {p:?} with spacing {spacing:?}: {g:?}");
            }
        }
    }
    // A non-linear (bilinear) term: d/dx (x y) = y inside a cell.
    let vol = grid([4, 4, 4], [0.5, 0.25, 1.0], [0.0; 3], |p| p[0] * p[1]);
    let (v, g) = vol.value_gradient([0.6, 0.3, 1.5]);
    assert!((v - 0.18).abs() < 1e-9 && (g[0] - 0.3).abs() < 1e-9 && (g[1] - 0.6).abs() < 1e-9 && g[2].abs() < 1e-12);
}

fn sphere_volume() -> Volume {
    grid([33, 33, 33], [1.0; 3], [0.0; 3], |p| {
        ((p[0] - 16.0).powi(2) + (p[1] - 16.0).powi(2) + (p[2] - 16.0).powi(2)).sqrt()
    })
}

fn sphere_scene(shading: &str) -> Scene {
    scene(json!({
        "volume": {"path": "/nonexistent.raw", "dims": [33, 33, 33], "dtype": "f32", "spacing": [1, 1, 1], "origin": [0, 0, 0]},
        "camera": {"eye": [16, 16, -40], "target": [16, 16, 16], "up": [0, 1, 0], "fov": 30.0},
        "width": 33, "height": 33,
        "mode": "isosurface",
        "iso": {"value": 10.0, "color": [0.8, 0.6, 0.4]},
        "shading": shading,
        "background": [0.1, 0.2, 0.3]
    }))
}

// 4. Isosurface of a distance field: the centre ray hits at |eye - centre| - r; rays missing it see the background.
#[test]
fn isosurface_sphere_hit_and_miss() {
    let vol = sphere_volume();
    let mut s = sphere_scene("none");
    s.step_voxels = 0.37; // the hit is not on a sample: bisection must find it
    let r = Renderer::new(&s, &vol).unwrap();
    let t = r.iso_hit_at(16.5, 16.5).expect("centre ray must hit");
    assert!((t - 46.0).abs() < 1e-6, "hit at {t}, expected 46");
    assert_eq!(r.iso_hit_at(0.5, 0.5), None, "corner ray passes through the box but misses the sphere");
    let (image, _) = r.render();
    let px = |x: usize, y: usize| &image.rgb[3 * (x + 33 * y)..3 * (x + 33 * y) + 3];
    assert_eq!(px(0, 0), &[0.1f32, 0.2, 0.3]);
    assert_eq!(px(16, 16), &[0.8f32, 0.6, 0.4]);
}

// Phong on a plane f = z (gradient exactly +z, so N = -z) with the light 45 degrees above the view direction:
// |N.L| = cos 45, |N.H| = cos 22.5.
#[test]
fn isosurface_phong_on_plane() {
    let vol = grid([33, 33, 33], [1.0; 3], [0.0; 3], |p| p[2]);
    let mut s = sphere_scene("phong");
    s.light = Some([0.0, 1.0, -1.0]);
    let (image, _) = Renderer::new(&s, &vol).unwrap().render();
    let c = &image.rgb[3 * (16 + 33 * 16)..3 * (16 + 33 * 16) + 3];
    let (nl, nh) = (45f64.to_radians().cos(), 22.5f64.to_radians().cos());
    for (got, base) in c.iter().zip([0.8, 0.6, 0.4]) {
        let want = base * (0.25 + 0.75 * nl) + 0.25 * nh.powi(16);
        assert!((f64::from(*got) - want).abs() < 1e-5, "phong {c:?}, want {want} for base {base}");
    }
    // The default light is the headlight: N = L = H ⇒ c (ambient + diffuse) + specular.
    let (image, _) = Renderer::new(&sphere_scene("phong"), &vol).unwrap().render();
    let c = &image.rgb[3 * (16 + 33 * 16)..3 * (16 + 33 * 16) + 3];
    for (got, base) in c.iter().zip([0.8, 0.6, 0.4]) {
        assert!((f64::from(*got) - (base + 0.25)).abs() < 1e-5, "headlight phong {c:?}");
    }
}

/// Noise on top of a ramp along x, so blocks have many different value ranges (some invisible, some partly).
fn random_volume() -> Volume {
    let dims = [40, 20, 18];
    let mut rng = Lcg(12345);
    let mut data = Vec::new();
    for _ in 0..dims[2] * dims[1] {
        for i in 0..dims[0] {
            data.push((0.8 * i as f64 / 39.0 + 0.25 * rng.next()) as f32);
        }
    }
    Volume::new(dims, [1.0, 1.25, 0.8], [-3.0, 1.0, 2.0], data).unwrap()
}

fn assert_skip_exact(s: &Scene, vol: &Volume) {
    let mut r = Renderer::new(s, vol).unwrap();
    assert!(r.skippable_blocks() > 0, "the test volume must have skippable blocks");
    let (with, stats_with) = r.render();
    r.set_skip(false);
    let (without, stats_without) = r.render();
    assert_eq!(stats_with, stats_without);
    let bits = |v: &[f32]| v.iter().map(|c| c.to_bits()).collect::<Vec<_>>();
    assert!(bits(&with.rgb) == bits(&without.rgb), "skipping changed the image");
    let bg = s.background.map(|c| c as f32);
    assert!(with.rgb.chunks(3).any(|p| p != bg), "image must not be all background");
}

// 5. Empty-space skipping is exact, bit for bit, for both modes: on a noisy volume, and on a ramp along x whose
// thresholds sit just inside a block's value range at its boundary samples (so a block range that misses its last
// sample, or a predicate that is slightly too eager, changes the image).
#[test]
fn block_skip_is_exact() {
    let camera = json!({"eye": [45, 35, -40], "target": [16, 12, 9], "up": [0, 1, 0], "fov": 45.0});
    let volume = json!({"path": "/x.raw", "dims": [40, 20, 18], "dtype": "f32", "spacing": [1, 1.25, 0.8], "origin": [-3, 1, 2]});
    let tf_points = |t: f64| json!([[0, 0, 0, 0, 0], [t, 1, 0, 0, 0], [0.7, 0, 1, 0, 0.3], [1, 0, 0, 1, 0.5]]);
    let common = json!({"volume": volume, "camera": camera, "width": 40, "height": 32, "supersample": 2,
        "shading": "phong", "background": [0.2, 0.1, 0.05]});
    let with = |extra: Value| {
        let mut v = common.clone();
        if let (Some(v), Some(e)) = (v.as_object_mut(), extra.as_object()) {
            v.extend(e.clone());
        }
        scene(v)
    };
    let noisy = random_volume();
    assert_skip_exact(&with(json!({"tf": {"points": tf_points(0.45), "unit_distance": 2.0}})), &noisy);
    assert_skip_exact(&with(json!({"mode": "isosurface", "iso": {"value": 0.7, "color": [1, 0.5, 0.25]}})), &noisy);

    // Sample i has value i / 39: block 1 spans samples 8..=16, i.e. values [0.205, 0.410].
    let ramp = Volume::new(
        [40, 20, 18],
        [1.0, 1.25, 0.8],
        [-3.0, 1.0, 2.0],
        (0..40 * 20 * 18).map(|n| (n % 40) as f32 / 39.0).collect(),
    )
    .unwrap();
    assert_skip_exact(&with(json!({"tf": {"points": tf_points(0.4), "unit_distance": 2.0}})), &ramp);
    // Block 2 spans [0.410, 0.615]: it contains 0.415 and must not be classified as all-above.
    assert_skip_exact(&with(json!({"mode": "isosurface", "iso": {"value": 0.415, "color": [1, 0.5, 0.25]}})), &ramp);
}

// 6. Bad inputs are errors, not panics.
#[test]
fn bad_inputs_are_errors() {
    let path = temp_path("short.raw");
    std::fs::write(&path, vec![0u8; 100]).unwrap();
    let spec =
        VolumeSpec { path: path.clone(), dims: [5, 5, 5], dtype: Dtype::U16, spacing: [1.0; 3], origin: [0.0; 3] };
    let err = format!("{:#}", Volume::load(&spec).unwrap_err());
    std::fs::remove_file(&path).unwrap();
    assert!(err.contains("has 100 bytes, expected 250"), "{err}");

    let missing = VolumeSpec { path: temp_path("missing.raw"), ..spec };
    assert!(format!("{:#}", Volume::load(&missing).unwrap_err()).contains("cannot open volume file"));

    let text = r#"{"volume": {"path": "/a.raw", "dims": [5,5,5], "dtype": "i64", "spacing": [1,1,1], "origin": [0,0,0]},
        "camera": {"eye": [0,0,-5], "target": [0,0,0], "up": [0,1,0], "fov": 30},
        "width": 8, "height": 8, "mode": "volume", "shading": "none", "background": [0,0,0],
        "tf": {"points": [[0,0,0,0,0]], "unit_distance": 1}}"#;
    let err = format!("{:#}", Scene::parse(text).unwrap_err());
    assert!(err.contains("unknown variant `i64`"), "{err}");
    assert!(Scene::parse(&text.replace("i64", "u8")).is_ok());
    assert!(Scene::parse(&text.replace("\"i64\"", "\"u8\", \"extra\": 1")).is_err(), "unknown field");
    assert!(
        Scene::parse(&text.replace("i64", "u8").replace("\"volume\", \"shading\"", "\"isosurface\", \"shading\""))
            .is_err(),
        "iso missing"
    );

    // A loaded file is checked for non-finite samples; the camera for degenerate geometry.
    let path = temp_path("nan.raw");
    let mut bytes = vec![0u8; 8 * 4];
    bytes[4..8].copy_from_slice(&f32::NAN.to_le_bytes());
    std::fs::write(&path, &bytes).unwrap();
    let spec =
        VolumeSpec { path: path.clone(), dims: [2, 2, 2], dtype: Dtype::F32, spacing: [1.0; 3], origin: [0.0; 3] };
    let result = Volume::load(&spec);
    std::fs::remove_file(&path).unwrap();
    assert!(format!("{:#}", result.unwrap_err()).contains("not finite"));
    let vol = grid([2, 2, 2], [1.0; 3], [0.0; 3], |_| 0.0);
    let bad = scene(json!({"camera": {"eye": [0, 0, 0], "target": [0, 0, 0], "up": [0, 1, 0], "fov": 30}}));
    assert!(Renderer::new(&bad, &vol).is_err());
}
