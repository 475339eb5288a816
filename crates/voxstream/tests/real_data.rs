//! Real volumes from package registries (fetched by `scripts/fetch-real-data.sh`, which `.ci/run` calls): each is
//! imported, its level 0 compared exactly with an array decoded independently (nibabel / numpy), and rendered
//! against a brute-force ray march of the dense array.

use std::path::{Path, PathBuf};
use std::sync::Arc;

mod common;

use common::{data_folder, real_data_dir, reference};
use glam::DVec3;
use voxstream::render_command::{default_store_transfer_function, store_camera, store_placement};
use voxstream_engine::{LoopLimits, Mode, Session};
use voxstream_render::{psnr, Camera, Image, RenderSettings, TransferFunction};
use voxstream_store::formats::{open_volume, Endian, RawLayout};
use voxstream_store::{import_volume, DType, ImportOptions, StoreProducer, StoreReader, VolumeInfo};

/// (file, reference name, raw layout for headerless files)
fn volumes() -> Vec<(&'static str, &'static str, Option<RawLayout>)> {
    vec![
        ("mni152_t1.nii.gz", "mni152_t1", None),
        ("liver.inr.gz", "liver", None),
        ("skull_2.9.inr", "skull_2", None),
        ("frog_tissues.vti", "frog_tissues", None),
        ("bunny_fog.vdb", "bunny_fog", None),
        ("bunny_ls.vdb", "bunny_ls", None),
        (
            "brainsmall.den",
            "brainsmall",
            Some(RawLayout {
                info: VolumeInfo {
                    dims: [128, 128, 84],
                    dtype: DType::U8,
                    spacing: [1.0; 3],
                    origin: [0.0; 3],
                    unit: None,
                    orientation: None,
                },
                file_type: None,
                endian: Endian::Little,
                header_bytes: 62,
            }),
        ),
    ]
}

/// The Python of the project's virtual environment (`data/venv`, made by `scripts/fetch-real-data.sh`), which has
/// zarr-python and numpy.
fn venv_python() -> PathBuf {
    let python = data_folder().join("venv/bin/python");
    assert!(python.exists(), "{} missing: run scripts/fetch-real-data.sh", python.display());
    python
}

fn import(dir: &Path, file: &str, raw: Option<&RawLayout>, store: &Path) -> Arc<StoreReader> {
    let mut source = open_volume(&dir.join(file), raw).unwrap();
    let options = ImportOptions { overwrite: true, ..ImportOptions::default() };
    import_volume(source.as_mut(), store, &options, &mut |_, _| {}).unwrap();
    Arc::new(StoreReader::open(store).unwrap())
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("voxstream-real-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn level_zero_equals_the_independently_decoded_source() {
    let Some(dir) = real_data_dir() else { return };
    let work = scratch("exact");
    for (file, name, raw) in volumes() {
        let reader = import(&dir, file, raw.as_ref(), &work.join(format!("{name}.zarr")));
        let (expected, meta) = reference(&dir, name);
        let dims: Vec<u64> = meta["dims"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap()).collect();
        assert_eq!(reader.info().dims.to_vec(), dims, "{file}");
        for a in 0..3 {
            let spacing = meta["spacing"][a].as_f64().unwrap();
            let origin = meta["origin"][a].as_f64().unwrap();
            assert!((reader.info().spacing[a] - spacing).abs() < 1e-5, "{file}: spacing {:?}", reader.info().spacing);
            assert!((reader.info().origin[a] - origin).abs() < 1e-4, "{file}: origin {:?}", reader.info().origin);
        }
        let level0 = reader.read_region(0, [0, 0, 0], reader.info().dims).unwrap();
        assert_eq!(level0.len(), expected.len(), "{file}");
        let differing = level0.iter().zip(&expected).filter(|(a, b)| a.to_bits() != b.to_bits()).count();
        assert_eq!(differing, 0, "{file}: {differing} samples differ from the reference");
    }
}

/// The dense array's cell holding world point `p` (clamped to the box of sample centres): its first sample's
/// indices and the position inside it.
fn dense_cell(info: &VolumeInfo, p: DVec3) -> ([usize; 3], [f64; 3]) {
    let c = [0, 1, 2].map(|a| ((p[a] - info.origin[a]) / info.spacing[a]).clamp(0.0, (info.dims[a] - 1) as f64));
    let i0 = [0, 1, 2].map(|a| (c[a].floor() as usize).min(info.dims[a] as usize - 2));
    (i0, [0, 1, 2].map(|a| c[a] - i0[a] as f64))
}

/// Sample `i0 + d` of the dense array (x fastest).
fn dense_at(values: &[f32], info: &VolumeInfo, i0: [usize; 3], d: [usize; 3]) -> f64 {
    let [nx, ny, _] = info.dims.map(|n| n as usize);
    values[((i0[2] + d[2]) * ny + i0[1] + d[1]) * nx + i0[0] + d[0]] as f64
}

/// Trilinear interpolation of the dense array at world point `p` (clamped to the box of sample centres).
fn dense_sample(values: &[f32], info: &VolumeInfo, p: DVec3) -> f64 {
    let (i0, f) = dense_cell(info, p);
    let v = |dx: usize, dy: usize, dz: usize| dense_at(values, info, i0, [dx, dy, dz]);
    let lerp = |a: f64, b: f64, t: f64| a + (b - a) * t;
    let x00 = lerp(v(0, 0, 0), v(1, 0, 0), f[0]);
    let x10 = lerp(v(0, 1, 0), v(1, 1, 0), f[0]);
    let x01 = lerp(v(0, 0, 1), v(1, 0, 1), f[0]);
    let x11 = lerp(v(0, 1, 1), v(1, 1, 1), f[0]);
    lerp(lerp(x00, x10, f[1]), lerp(x01, x11, f[1]), f[2])
}

/// The analytic gradient (per world unit) of the dense array's trilinear interpolant at `p`.
fn dense_gradient(values: &[f32], info: &VolumeInfo, p: DVec3) -> DVec3 {
    let (i0, f) = dense_cell(info, p);
    let mut g = [0.0; 3];
    for (a, component) in g.iter_mut().enumerate() {
        // d/da: the differences along a, weighted bilinearly over the other two axes.
        let (b, c2) = ((a + 1) % 3, (a + 2) % 3);
        for (ob, oc) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
            let w = (if ob == 1 { f[b] } else { 1.0 - f[b] }) * (if oc == 1 { f[c2] } else { 1.0 - f[c2] });
            let (mut lo, mut hi) = ([0usize; 3], [0usize; 3]);
            lo[b] = ob;
            lo[c2] = oc;
            hi[b] = ob;
            hi[c2] = oc;
            hi[a] = 1;
            *component += w * (dense_at(values, info, i0, hi) - dense_at(values, info, i0, lo));
        }
        *component /= info.spacing[a];
    }
    DVec3::from(g)
}

/// The camera's unit ray through pixel (x, y) of a square image.
fn camera_ray(camera: &Camera, x: u32, y: u32, size: u32) -> (DVec3, DVec3) {
    let eye = DVec3::from(camera.eye);
    let forward = (DVec3::from(camera.target) - eye).normalize();
    let right = forward.cross(DVec3::from(camera.up)).normalize();
    let up = right.cross(forward);
    let half = (camera.fov.to_radians() / 2.0).tan();
    let sx = ((x as f64 + 0.5) / size as f64 * 2.0 - 1.0) * half;
    let sy = (1.0 - (y as f64 + 0.5) / size as f64 * 2.0) * half;
    (eye, (forward + right * sx + up * sy).normalize())
}

/// Entry and exit of a ray through the box of sample centres.
fn ray_through_box(info: &VolumeInfo, eye: DVec3, d: DVec3) -> (f64, f64) {
    let lower = DVec3::from(info.origin);
    let upper = lower + DVec3::from([0, 1, 2].map(|a| (info.dims[a] as f64 - 1.0) * info.spacing[a]));
    let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
    for a in 0..3 {
        let (n, f) = ((lower[a] - eye[a]) / d[a], (upper[a] - eye[a]) / d[a]);
        t0 = t0.max(n.min(f));
        t1 = t1.min(n.max(f));
    }
    (t0, t1)
}

/// Brute-force first-hit isosurface through the dense array: a scan every eighth of the smallest spacing for a
/// change of `f ≥ iso`, 40 bisections, then two-sided Phong (headlight: the light comes from the eye) with the
/// trilinear interpolant's analytic gradient; the same coefficients as `RenderSettings::default()`.
fn brute_force_isosurface(
    values: &[f32],
    info: &VolumeInfo,
    iso: f64,
    color: [f32; 3],
    camera: &Camera,
    size: u32,
) -> Image {
    let step = info.spacing.iter().cloned().fold(f64::INFINITY, f64::min) * 0.125;
    let phong = voxstream_render::PhongCoefficients::default();
    let mut image = Image::new(size, size);
    for y in 0..size {
        for x in 0..size {
            let (eye, d) = camera_ray(camera, x, y, size);
            let (t0, t1) = ray_through_box(info, eye, d);
            if t0 >= t1 {
                continue;
            }
            let inside = |t: f64| dense_sample(values, info, eye + d * t) >= iso;
            let steps = ((t1 - t0) / step).ceil() as usize;
            let first = inside(t0);
            let Some(k) = (1..=steps).find(|&k| inside((t0 + k as f64 * step).min(t1)) != first) else {
                continue;
            };
            let (mut a, mut b) = (t0 + (k - 1) as f64 * step, (t0 + k as f64 * step).min(t1));
            for _ in 0..40 {
                let m = 0.5 * (a + b);
                if inside(m) == first {
                    a = m;
                } else {
                    b = m;
                }
            }
            let g = dense_gradient(values, info, eye + d * b);
            let view = -d;
            let (diffuse, specular) = if g.length() < 1e-9 {
                (1.0, 0.0)
            } else {
                let n = g.normalize();
                (n.dot(view).abs(), n.dot(view).abs().powf(phong.shininess as f64))
            };
            let k = phong.ambient as f64 + phong.diffuse as f64 * diffuse;
            let s = phong.specular as f64 * specular;
            image.pixels[(y * size + x) as usize] = [
                (color[0] as f64 * k + s) as f32,
                (color[1] as f64 * k + s) as f32,
                (color[2] as f64 * k + s) as f32,
                1.0,
            ];
        }
    }
    image
}

/// Brute-force emission–absorption through the dense array: trilinear samples every quarter of the smallest
/// spacing, the transfer function evaluated directly, over the box of sample centres.
fn brute_force(values: &[f32], info: &VolumeInfo, tf: &TransferFunction, camera: &Camera, size: u32) -> Image {
    let sample = |p: DVec3| dense_sample(values, info, p);
    let unit = tf.unit_distance.unwrap_or((info.spacing[0] * info.spacing[1] * info.spacing[2]).cbrt());
    let step = info.spacing.iter().cloned().fold(f64::INFINITY, f64::min) * 0.25;
    let mut image = Image::new(size, size);
    for y in 0..size {
        for x in 0..size {
            let (eye, d) = camera_ray(camera, x, y, size);
            let (t0, t1) = ray_through_box(info, eye, d);
            let (mut color, mut transmittance) = ([0.0f64; 3], 1.0f64);
            if t0 < t1 {
                let steps = ((t1 - t0) / step).ceil() as usize;
                let dt = (t1 - t0) / steps as f64;
                for i in 0..steps {
                    let [r, g, b, alpha] = tf.evaluate(sample(eye + d * (t0 + (i as f64 + 0.5) * dt)));
                    let a = 1.0 - (1.0 - alpha).powf(dt / unit);
                    for (c, v) in color.iter_mut().zip([r, g, b]) {
                        *c += transmittance * a * v;
                    }
                    transmittance *= 1.0 - a;
                    if transmittance < 1e-4 {
                        break;
                    }
                }
            }
            image.pixels[(y * size + x) as usize] =
                [color[0] as f32, color[1] as f32, color[2] as f32, (1.0 - transmittance) as f32];
        }
    }
    image
}

/// PSNR the converged render of a real volume must reach against the brute-force dense reference.
const MIN_PSNR_DB: f64 = 35.0;

#[test]
fn renders_match_a_brute_force_march_of_the_dense_array() {
    let Some(dir) = real_data_dir() else { return };
    let work = scratch("render");
    let size = 96;
    for (file, name, raw) in volumes().into_iter().filter(|v| v.1 != "liver") {
        let reader = import(&dir, file, raw.as_ref(), &work.join(format!("{name}.zarr")));
        let range = reader.attributes().value_range;
        // The default transfer function of `render`, over the bulk of the values.
        let tf = default_store_transfer_function(reader.attributes().typical_range()).unwrap();
        let camera = store_camera(reader.info(), size, size);
        // Sample the finest level everywhere, as the dense reference does.
        let settings = RenderSettings {
            width: size,
            height: size,
            placement: store_placement(&reader),
            lod_bias: 8.0,
            ..RenderSettings::default()
        };
        let producer = StoreProducer::new(reader.clone()).unwrap();
        let mut session =
            Session::with_value_range(producer, &tf, settings, 256 << 20, LoopLimits::default(), range).unwrap();
        let frame = session.render(&camera, Mode::Converged).unwrap();
        assert!(frame.is_converged());
        let (values, _) = reference(&dir, name);
        let expected = brute_force(&values, reader.info(), &tf, &camera, size);
        let quality = psnr(&frame.image.to_rgb8(), &expected.to_rgb8());
        println!("{file}: PSNR {quality:.2} dB against the dense brute-force march");
        let covered = expected.pixels.iter().filter(|p| p[3] > 0.2).count();
        assert!(covered > (size * size / 10) as usize, "{file}: the reference is nearly empty");
        assert!(quality >= MIN_PSNR_DB, "{file}: PSNR {quality:.2} dB < {MIN_PSNR_DB}");
    }
}

/// PSNR the converged isosurface render of a real volume must reach against the dense brute-force search.
const MIN_ISO_PSNR_DB: f64 = 40.0;

#[test]
fn isosurfaces_match_a_brute_force_search_of_the_dense_array() {
    let Some(dir) = real_data_dir() else { return };
    let work = scratch("isosurface");
    let size = 96;
    // Scans and a level set; the isovalue halfway through the bulk of each one's values.
    for (file, name, raw) in volumes().into_iter().filter(|v| ["mni152_t1", "skull_2", "bunny_ls"].contains(&v.1)) {
        let reader = import(&dir, file, raw.as_ref(), &work.join(format!("{name}.zarr")));
        let range = reader.attributes().value_range;
        let [lo, hi] = reader.attributes().typical_range();
        let iso = 0.5 * (lo + hi);
        let color = [0.9f32, 0.75, 0.65];
        let tf = default_store_transfer_function([lo, hi]).unwrap();
        let camera = store_camera(reader.info(), size, size);
        let settings = RenderSettings {
            width: size,
            height: size,
            placement: store_placement(&reader),
            // The finest level everywhere, as the dense reference.
            lod_bias: 8.0,
            shading: voxstream_render::Shading::Phong,
            surfaces: vec![voxstream_render::IsoSurface { value: iso, color, opacity: 1.0 }],
            ..RenderSettings::default()
        };
        let producer = StoreProducer::new(reader.clone()).unwrap();
        let mut session =
            Session::with_value_range(producer, &tf, settings, 256 << 20, LoopLimits::default(), range).unwrap();
        let frame = session.render(&camera, Mode::Converged).unwrap();
        assert!(frame.is_converged());
        let (values, _) = reference(&dir, name);
        let expected = brute_force_isosurface(&values, reader.info(), iso, color, &camera, size);
        let quality = psnr(&frame.image.to_rgb8(), &expected.to_rgb8());
        let covered = expected.pixels.iter().filter(|p| p[3] > 0.5).count();
        println!("{file} at {iso}: PSNR {quality:.2} dB against the dense brute-force search, {covered} pixels hit");
        assert!(covered > (size * size / 10) as usize, "{file}: the surface covers only {covered} pixels");
        assert!(quality >= MIN_ISO_PSNR_DB, "{file}: PSNR {quality:.2} dB < {MIN_ISO_PSNR_DB}");
    }
}

#[test]
fn a_standard_zarr_reader_opens_the_store() {
    // zarr-python (installed by scripts/fetch-real-data.sh) reads the store: metadata, exact level 0, the pyramid.
    let Some(dir) = real_data_dir() else { return };
    let work = scratch("zarr-python");
    for (file, name, raw) in volumes().into_iter().filter(|v| v.1 == "mni152_t1" || v.1 == "skull_2") {
        let store = work.join(format!("{name}.zarr"));
        import(&dir, file, raw.as_ref(), &store);
        let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scripts/check_store_with_zarr_python.py");
        let output = std::process::Command::new(venv_python())
            .arg(&script)
            .arg(&store)
            .arg(dir.join(format!("{name}.reference.npy")))
            .output()
            .expect("python3");
        assert!(
            output.status.success(),
            "{file}: zarr-python failed:\n{}{}",
            String::from_utf8_lossy(&output.stdout),
            String::from_utf8_lossy(&output.stderr)
        );
    }
}

#[test]
fn streaming_and_in_memory_producers_give_the_same_image() {
    let Some(dir) = real_data_dir() else { return };
    let work = scratch("in-memory");
    let reader = import(&dir, "mni152_t1.nii.gz", None, &work.join("mni.zarr"));
    let range = reader.attributes().value_range;
    let tf = default_store_transfer_function(range).unwrap();
    let camera = store_camera(reader.info(), 64, 64);
    let settings =
        RenderSettings { width: 64, height: 64, placement: store_placement(&reader), ..RenderSettings::default() };
    let streamed = {
        let producer = StoreProducer::new(reader.clone()).unwrap();
        let mut session =
            Session::with_value_range(producer, &tf, settings.clone(), 64 << 20, LoopLimits::default(), range).unwrap();
        session.render(&camera, Mode::Converged).unwrap()
    };
    let in_memory = {
        let volume = Arc::new(voxstream_store::InMemoryVolume::load(&reader).unwrap());
        let producer = StoreProducer::new(volume).unwrap();
        let mut session =
            Session::with_value_range(producer, &tf, settings, 64 << 20, LoopLimits::default(), range).unwrap();
        session.render(&camera, Mode::Converged).unwrap()
    };
    assert!(streamed.is_converged() && in_memory.is_converged());
    assert!(streamed.image.pixels == in_memory.image.pixels, "the two producers disagree");
}

#[test]
fn foreign_ome_zarr_v2_and_v3_render_like_the_native_store() {
    // OME-Zarr written by zarr-python (v3/0.5 and v2/0.4 with blosc, a pyramid that rounds down, no voxstream
    // attributes) renders like voxstream's own import of the same scan.
    let Some(dir) = real_data_dir() else { return };
    let work = scratch("foreign");
    let native = import(&dir, "mni152_t1.nii.gz", None, &work.join("native.zarr"));
    let native_orientation = native.info().orientation;
    assert_eq!(native_orientation.map(|o| o.code()).as_deref(), Some("RAS"), "the template's sform");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scripts/make_foreign_ome_zarr.py");
    let output = std::process::Command::new(venv_python())
        .arg(&script)
        .arg(dir.join("mni152_t1.reference.npy"))
        .arg(work.join("v3.zarr"))
        .arg(work.join("v2.zarr"))
        .args(["-98", "-134", "-72", "RAS"])
        .output()
        .expect("python3");
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    // The volume, and its isosurface at 100 at the finest level (foreign pyramids round their coarse levels
    // differently).
    let iso = RenderSettings {
        surfaces: vec![voxstream_render::IsoSurface { value: 100.0, color: [0.9, 0.75, 0.65], opacity: 1.0 }],
        shading: voxstream_render::Shading::Phong,
        lod_bias: 8.0,
        ..RenderSettings::default()
    };
    let render = |reader: Arc<StoreReader>, look: &RenderSettings| {
        let range = reader.attributes().value_range;
        let tf = default_store_transfer_function([0.0, 255.0]).unwrap();
        let settings = RenderSettings { width: 96, height: 96, placement: store_placement(&reader), ..look.clone() };
        let camera = store_camera(reader.info(), 96, 96);
        let producer = StoreProducer::new(reader).unwrap();
        let mut session =
            Session::with_value_range(producer, &tf, settings, 64 << 20, LoopLimits::default(), range).unwrap();
        let frame = session.render(&camera, Mode::Converged).unwrap();
        assert!(frame.is_converged());
        frame.image.to_rgb8()
    };
    let volume = RenderSettings::default();
    let (native_image, native_iso) = (render(native.clone(), &volume), render(native, &iso));
    let lit = native_iso.chunks(3).filter(|p| p.iter().any(|&c| c > 0)).count();
    assert!(lit > 96 * 96 / 10, "the isosurface covers only {lit} pixels");
    for name in ["v3.zarr", "v2.zarr"] {
        let reader = Arc::new(StoreReader::open(&work.join(name)).unwrap());
        assert!(!reader.is_native());
        assert_eq!(reader.info().dims, [197, 233, 189]);
        assert_eq!(reader.info().origin, [-98.0, -134.0, -72.0]);
        // The RFC-4 orientation zarr-python's metadata carries: the same default view as the native import's.
        assert_eq!(reader.info().orientation, native_orientation);
        let level0 = reader.read_region(0, [0, 0, 0], [197, 233, 189]).unwrap();
        let (expected, _) = reference(&dir, "mni152_t1");
        assert!(level0 == expected, "{name}: level 0 differs");
        let quality = psnr(&render(reader.clone(), &volume), &native_image);
        let iso_quality = psnr(&render(reader, &iso), &native_iso);
        println!("{name}: PSNR {quality:.1} dB (volume), {iso_quality:.1} dB (isosurface) against the native store");
        assert!(quality >= 45.0, "{name}: PSNR {quality:.1} dB");
        assert!(iso_quality >= 45.0, "{name}: isosurface PSNR {iso_quality:.1} dB");
    }
}

#[cfg(feature = "gpu")]
#[test]
fn the_gpu_renders_real_stores_and_a_foreign_ome_zarr_like_the_cpu() {
    // The GPU renderer (crates/voxstream-gpu) against its reference, the CPU ray caster, on real scans: voxstream's
    // own stores (MRI, shaded CT) and an OME-Zarr written by zarr-python. PSNR ≥ 40 dB, as for the built-in scenes
    // (crates/voxstream/tests/gpu_backend.rs). Needs a Vulkan driver (CI installs Mesa's lavapipe).
    let Some(dir) = real_data_dir() else { return };
    let work = scratch("gpu");
    let native = import(&dir, "mni152_t1.nii.gz", None, &work.join("mni.zarr"));
    let frog = import(&dir, "frog_tissues.vti", None, &work.join("frog.zarr"));
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scripts/make_foreign_ome_zarr.py");
    let output = std::process::Command::new(venv_python())
        .arg(&script)
        .arg(dir.join("mni152_t1.reference.npy"))
        .arg(work.join("v3.zarr"))
        .arg(work.join("v2.zarr"))
        .args(["-98", "-134", "-72", "RAS"])
        .output()
        .expect("python3");
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let foreign = Arc::new(StoreReader::open(&work.join("v3.zarr")).unwrap());
    assert!(!foreign.is_native());
    let size = 96;
    // The frog's tissue labels with the peers' transfer function (bench/peers), shaded.
    let frog_tf = TransferFunction::from_json(include_str!("../../../docs/examples/frog-tf.json")).unwrap();
    // The brain's isosurface at 70 (README's example), Phong-shaded with hard shadows: Knoll et al.'s exact crossings.
    let iso = vec![voxstream_render::IsoSurface { value: 70.0, color: [0.9, 0.75, 0.65], opacity: 1.0 }];
    let phong = voxstream_render::Shading::Phong;
    for (name, reader, shading, tf, surfaces) in [
        ("mni152_t1", native.clone(), voxstream_render::Shading::None, None, vec![]),
        ("frog_tissues (Phong)", frog, phong, Some(frog_tf), vec![]),
        ("mni152_t1 as zarr-python's OME-Zarr v3", foreign, voxstream_render::Shading::None, None, vec![]),
        ("mni152_t1's isosurface at 70 with shadows", native, phong, None, iso),
    ] {
        let range = reader.attributes().value_range;
        let tf = tf.unwrap_or_else(|| default_store_transfer_function(reader.attributes().typical_range()).unwrap());
        let settings = RenderSettings {
            width: size,
            height: size,
            shading,
            placement: store_placement(&reader),
            shadows: !surfaces.is_empty(),
            light_direction: Some([0.3, 0.8, 0.5]).filter(|_| !surfaces.is_empty()),
            surfaces,
            ..RenderSettings::default()
        };
        let camera = store_camera(reader.info(), size, size);
        let producer = StoreProducer::new(reader.clone()).unwrap();
        let mut cpu =
            Session::with_value_range(producer, &tf, settings.clone(), 64 << 20, LoopLimits::default(), range).unwrap();
        let expected = cpu.render(&camera, Mode::Converged).unwrap();
        let gpu_renderer = voxstream_gpu::GpuRenderer::new().unwrap_or_else(|e| panic!("{e}"));
        let producer = StoreProducer::new(reader).unwrap();
        let mut gpu =
            Session::with_renderer(gpu_renderer, producer, &tf, settings, 64 << 20, LoopLimits::default(), range)
                .unwrap();
        let actual = gpu.render(&camera, Mode::Converged).unwrap();
        assert!(expected.is_converged() && actual.is_converged(), "{name}: not converged");
        let covered = expected.image.pixels.iter().filter(|p| p[3] > 0.05).count();
        assert!(covered > (size * size / 10) as usize, "{name}: the reference is nearly empty ({covered} pixels)");
        let quality = psnr(&actual.image.to_rgb8(), &expected.image.to_rgb8());
        println!("{name}: PSNR {quality:.1} dB (GPU against CPU)");
        assert!(quality >= 40.0, "{name}: GPU PSNR {quality:.1} dB < 40 against the CPU image");
    }
}
