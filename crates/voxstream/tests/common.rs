//! Helpers shared by the integration tests (included with `mod common;`).
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use glam::DVec3;
use voxstream::scenes::{builtin, SceneProducer};
use voxstream_engine::{LoopLimits, Mode, Session};
use voxstream_render::{Camera, Image, RenderSettings};

/// The repository's root folder (canonical).
pub fn repository_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").canonicalize().unwrap()
}

/// The repository's `data/` folder (the real data and the Python environment of `scripts/fetch-real-data.sh`).
pub fn data_folder() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data")
}

/// `data/real`, when `scripts/fetch-real-data.sh` has filled it; `None` (the test skips) where it is absent and
/// `VOXSTREAM_SKIP_REAL_DATA` is set; panics otherwise.
pub fn real_data_dir() -> Option<PathBuf> {
    let dir = data_folder().join("real");
    if dir.join("bunny_ls.reference.npy").exists() {
        return Some(dir);
    }
    if std::env::var_os("VOXSTREAM_SKIP_REAL_DATA").is_some() {
        eprintln!("real data absent and VOXSTREAM_SKIP_REAL_DATA set: skipping");
        return None;
    }
    panic!("real data missing: run scripts/fetch-real-data.sh (or set VOXSTREAM_SKIP_REAL_DATA=1)");
}

/// A session on a built-in scene at `size`², with the scene's transfer function and shading.
pub fn scene_session(name: &str, size: u32, budget_bytes: u64) -> Session<SceneProducer> {
    scene_session_with(name, size, budget_bytes, LoopLimits::default())
}

/// [`scene_session`] with the loop's limits and options.
pub fn scene_session_with(name: &str, size: u32, budget_bytes: u64, limits: LoopLimits) -> Session<SceneProducer> {
    let scene = builtin(name).expect("built-in scene");
    let settings = RenderSettings { width: size, height: size, shading: scene.shading, ..RenderSettings::default() };
    Session::new(scene.producer, &scene.transfer_function, settings, budget_bytes, limits).expect("session")
}

/// Renders a converged frame and checks it converged.
pub fn converged(session: &mut Session<SceneProducer>, camera: &Camera) -> Image {
    let result = session.render(camera, Mode::Converged).expect("render");
    assert!(result.is_converged(), "frame did not converge after {} passes", result.passes);
    result.image
}

/// Unit direction through pixel (x, y), computed independently of the renderer's camera code.
pub fn pixel_direction(camera: &Camera, x: u32, y: u32, width: u32, height: u32) -> DVec3 {
    let eye = DVec3::from(camera.eye);
    let forward = (DVec3::from(camera.target) - eye).normalize();
    let right = forward.cross(DVec3::from(camera.up)).normalize();
    let up = right.cross(forward);
    let half = (camera.fov.to_radians() / 2.0).tan();
    let aspect = width as f64 / height as f64;
    let sx = ((x as f64 + 0.5) / width as f64 * 2.0 - 1.0) * half * aspect;
    let sy = (1.0 - (y as f64 + 0.5) / height as f64 * 2.0) * half;
    (forward + right * sx + up * sy).normalize()
}

/// Slab test: entry and exit distances of a ray through the cube `[lower, lower + size]`.
pub fn ray_box(origin: DVec3, direction: DVec3, lower: DVec3, size: f64) -> Option<(f64, f64)> {
    let mut t0 = 0.0f64;
    let mut t1 = f64::INFINITY;
    for a in 0..3 {
        let inv = 1.0 / direction[a];
        let (mut near, mut far) = ((lower[a] - origin[a]) * inv, (lower[a] + size - origin[a]) * inv);
        if near > far {
            std::mem::swap(&mut near, &mut far);
        }
        if near.is_nan() || far.is_nan() {
            // Parallel to the slab: inside or never.
            if origin[a] < lower[a] || origin[a] > lower[a] + size {
                return None;
            }
            continue;
        }
        t0 = t0.max(near);
        t1 = t1.min(far);
    }
    (t0 <= t1).then_some((t0, t1))
}

/// Random cameras for property tests: a target inside the middle of the unit cube, an eye `min_distance`..2.5 away in
/// any direction but near the poles, a 40° field of view.
pub fn random_camera(min_distance: f64) -> impl proptest::strategy::Strategy<Value = Camera> {
    use proptest::strategy::Strategy;
    (0.2f64..0.8, 0.2f64..0.8, 0.2f64..0.8, 0.0f64..std::f64::consts::TAU, -0.8f64..0.8, min_distance..2.5).prop_map(
        |(tx, ty, tz, azimuth, elevation, distance)| {
            let (s, c) = ((1.0 - elevation * elevation).sqrt(), elevation);
            let eye = [tx + distance * s * azimuth.cos(), ty + distance * c, tz + distance * s * azimuth.sin()];
            Camera { eye, target: [tx, ty, tz], up: [0.0, 1.0, 0.0], fov: 40.0 }
        },
    )
}

/// Runs the `voxstream` binary with `args` in `dir`.
pub fn voxstream(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_voxstream")).args(args).current_dir(dir).output().expect("run voxstream")
}

/// An empty scratch folder for test `name` of the test file `file`, unique to this process.
pub fn scratch(file: &str, name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("voxstream-{file}-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch folder");
    dir
}

/// An 8-bit RGB PNG's width, height and pixels (row-major, top row first).
pub fn read_png(path: &Path) -> (u32, u32, Vec<u8>) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).expect("png written")));
    let mut reader = decoder.read_info().expect("a PNG");
    let mut buffer = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buffer).expect("a PNG frame");
    assert_eq!(info.color_type, png::ColorType::Rgb);
    buffer.truncate(info.buffer_size());
    (info.width, info.height, buffer)
}

/// A command's standard error, as text.
pub fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

/// Imports a 48×40×36 u16 ball into the store `name` in `dir`, with bricks of 16 (levels of 48, 24 and 12 samples:
/// several shards, empty bricks among them); the ball's samples fall from 3050 at its centre to 50 at its surface.
pub fn import_ball(dir: &Path, name: &str) {
    write_nrrd(&dir.join("ball.nrrd"), [48, 40, 36], "1 1 1", |i, j, k| {
        let d = (((i as f64 - 24.0) / 18.0).powi(2)
            + ((j as f64 - 20.0) / 16.0).powi(2)
            + ((k as f64 - 18.0) / 14.0).powi(2))
        .sqrt();
        if d < 1.0 {
            (3000.0 * (1.0 - d * d)) as u16 + 50
        } else {
            0
        }
    });
    let out = voxstream(&["import", "ball.nrrd", "--out", name, "--brick-size", "16", "--quiet"], dir);
    assert!(out.status.success(), "import: {}", stderr(&out));
}

/// A sample type of [`write_nrrd`]: its NRRD type name and its little-endian bytes.
pub trait NrrdSample: Copy {
    /// NRRD's name of the type.
    const TYPE: &'static str;
    /// Appends the sample's bytes, little-endian.
    fn push(self, bytes: &mut Vec<u8>);
}

impl NrrdSample for u8 {
    const TYPE: &'static str = "uchar";
    fn push(self, bytes: &mut Vec<u8>) {
        bytes.push(self);
    }
}

impl NrrdSample for u16 {
    const TYPE: &'static str = "ushort";
    fn push(self, bytes: &mut Vec<u8>) {
        bytes.extend(self.to_le_bytes());
    }
}

/// Writes a raw NRRD of `sizes` samples (x fastest) with `spacings` ("1 1 1.2"), the sample at `(i, j, k)` being
/// `sample(i, j, k)`: the synthetic volumes the tests import.
pub fn write_nrrd<V: NrrdSample>(
    path: &Path,
    sizes: [usize; 3],
    spacings: &str,
    sample: impl Fn(usize, usize, usize) -> V,
) {
    let [nx, ny, nz] = sizes;
    let endian = if std::mem::size_of::<V>() > 1 { "endian: little\n" } else { "" };
    let mut bytes = format!(
        "NRRD0004\ntype: {}\ndimension: 3\nsizes: {nx} {ny} {nz}\nspacings: {spacings}\nencoding: raw\n{endian}\n",
        V::TYPE
    )
    .into_bytes();
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                sample(i, j, k).push(&mut bytes);
            }
        }
    }
    std::fs::write(path, bytes).unwrap();
}

/// A NIfTI-1 header (352 bytes, little endian, `n+1`) for `dims` uint8 samples following it, `pixdim` being
/// `[qfac, dx, dy, dz]` and `units` the `xyzt_units` byte; no qform or sform (the caller sets them).
pub fn nifti_u8_header(dims: [usize; 3], pixdim: [f32; 4], units: u8) -> Vec<u8> {
    let mut h = vec![0u8; 352];
    h[0..4].copy_from_slice(&348i32.to_le_bytes());
    for (n, d) in [3i16, dims[0] as i16, dims[1] as i16, dims[2] as i16, 1, 1, 1, 1].iter().enumerate() {
        h[40 + 2 * n..42 + 2 * n].copy_from_slice(&d.to_le_bytes());
    }
    h[70..72].copy_from_slice(&2i16.to_le_bytes()); // uint8
    h[72..74].copy_from_slice(&8i16.to_le_bytes());
    for (n, p) in pixdim.iter().enumerate() {
        h[76 + 4 * n..80 + 4 * n].copy_from_slice(&p.to_le_bytes());
    }
    h[108..112].copy_from_slice(&352f32.to_le_bytes());
    h[123] = units;
    h[344..348].copy_from_slice(b"n+1\0");
    h
}

/// A reference array written by `scripts/make_references.py` (`NAME.reference.npy`, C order, uint8 or float32, as
/// f32) and its JSON geometry (`NAME.reference.json`), from the real-data folder `dir`.
pub fn reference(dir: &Path, name: &str) -> (Vec<f32>, serde_json::Value) {
    let bytes = std::fs::read(dir.join(format!("{name}.reference.npy"))).unwrap();
    let header_len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    let header = String::from_utf8_lossy(&bytes[10..10 + header_len]).into_owned();
    let body = &bytes[10 + header_len..];
    let values = if header.contains("'|u1'") {
        body.iter().map(|&b| b as f32).collect()
    } else if header.contains("'<f4'") {
        body.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect()
    } else {
        panic!("unexpected reference dtype in {header}");
    };
    let meta =
        serde_json::from_str(&std::fs::read_to_string(dir.join(format!("{name}.reference.json"))).unwrap()).unwrap();
    (values, meta)
}
