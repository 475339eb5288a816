//! What a new user meets first (issue "First use"): defaults that fit real data (an outlier sample, a transfer
//! function in the wrong units, the default camera, the default scene's view) and the exact text of the messages for
//! the usual mistakes.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use glam::DVec3;
use voxstream::render_command::store_camera;
use voxstream::scenes::builtin;
use voxstream_engine::{LoopLimits, Mode, Session};
use voxstream_render::RenderSettings;
use voxstream_store::{DType, VolumeInfo};

fn voxstream(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_voxstream")).args(args).current_dir(dir).output().expect("run voxstream")
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("voxstream-first-use-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

/// The lines of stderr that are errors or warnings (progress and summary lines excluded).
fn problems(output: &Output) -> Vec<String> {
    stderr(output).lines().filter(|l| l.starts_with("error") || l.starts_with("warning")).map(String::from).collect()
}

/// A 64×56×48 u16 raw volume: a ball with values 1000–3000 in an empty box, and one sample of 65535 in a corner
/// (a hot pixel, a marker, a stitching artefact).
fn write_ball_with_outlier(path: &Path) {
    let (nx, ny, nz) = (64usize, 56usize, 48usize);
    let mut bytes = Vec::with_capacity(nx * ny * nz * 2);
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let d = (((i as f64 - 32.0) / 24.0).powi(2)
                    + ((j as f64 - 28.0) / 21.0).powi(2)
                    + ((k as f64 - 24.0) / 18.0).powi(2))
                .sqrt();
                let v = if (i, j, k) == (1, 1, 1) {
                    u16::MAX
                } else if d < 1.0 {
                    (1000.0 + 2000.0 * (1.0 - d * d)) as u16
                } else {
                    0
                };
                bytes.extend(v.to_le_bytes());
            }
        }
    }
    std::fs::write(path, bytes).unwrap();
}

/// Fraction of pixels of a PNG whose colour is not black.
fn covered_fraction(path: &Path) -> f64 {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buffer = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buffer).unwrap();
    let pixels = &buffer[..info.buffer_size()];
    let channels = info.color_type.samples();
    let lit = pixels.chunks_exact(channels).filter(|p| p[..3].iter().any(|&c| c > 8)).count();
    lit as f64 / (pixels.len() / channels) as f64
}

fn import_ball(dir: &Path) {
    write_ball_with_outlier(&dir.join("ball.raw"));
    let output = voxstream(
        &["import", "ball.raw", "--dims", "64,56,48", "--dtype", "u16", "--out", "ball.zarr", "--quiet"],
        dir,
    );
    assert!(output.status.success(), "{}", stderr(&output));
}

#[test]
fn one_outlier_sample_does_not_blacken_the_default_render() {
    let dir = scratch("outlier");
    import_ball(&dir);
    let info = voxstream(&["info", "ball.zarr", "--json"], &dir);
    let info: serde_json::Value = serde_json::from_slice(&info.stdout).unwrap();
    assert_eq!(info["value_range"], serde_json::json!([0.0, 65535.0]));
    let percentiles = info["value_percentiles"].as_array().expect("percentiles kept at import");
    let p995 = percentiles.iter().find(|p| p[0] == 99.5).unwrap()[1].as_f64().unwrap();
    assert!((1000.0..=3000.0).contains(&p995), "99.5th percentile {p995}");

    let output = voxstream(&["render", "ball.zarr", "--width", "96", "--height", "96", "--out", "ball.png"], &dir);
    assert!(output.status.success(), "{}", stderr(&output));
    assert!(problems(&output).is_empty(), "{:?}", problems(&output));
    let covered = covered_fraction(&dir.join("ball.png"));
    assert!(covered > 0.1, "the ball covers only {:.1}% of the image", covered * 100.0);
}

#[test]
fn a_transfer_function_in_other_units_is_warned_about() {
    let dir = scratch("tf-units");
    import_ball(&dir);
    // The README's example transfer function, values in 0–1, on a u16 store.
    std::fs::write(
        dir.join("unit.json"),
        r#"{"points": [[0.0, 0, 0, 0, 0], [0.3, 0.2, 0.4, 1.0, 0.0], [1.0, 1.0, 0.9, 0.7, 0.8]]}"#,
    )
    .unwrap();
    let output = voxstream(
        &["render", "ball.zarr", "--tf", "unit.json", "--width", "64", "--height", "64", "--out", "u.png"],
        &dir,
    );
    assert!(output.status.success(), "{}", stderr(&output));
    let info = voxstream(&["info", "ball.zarr", "--json"], &dir);
    let info: serde_json::Value = serde_json::from_slice(&info.stdout).unwrap();
    let p995 =
        info["value_percentiles"].as_array().unwrap().iter().find(|p| p[0] == 99.5).unwrap()[1].as_f64().unwrap();
    assert_eq!(
        problems(&output),
        [format!(
            "warning: the transfer function's values span 0 to 1, but the data's lie between 0 and {p995} (all of \
             them: 0 to 65535): its values are in the data's units (see `voxstream info`), so the image will be one \
             colour"
        )]
    );
    assert!(covered_fraction(&dir.join("u.png")) > 0.1, "the image is still written, and shows the box");

    // A transfer function whose opaque part lies above every value: nothing shows, and the user is told.
    std::fs::write(dir.join("high.json"), r#"{"points": [[0, 0,0,0,0], [60000, 0,0,0,0], [65535, 1,1,1,1]]}"#).unwrap();
    let output = voxstream(
        &["render", "ball.zarr", "--tf", "high.json", "--width", "64", "--height", "64", "--out", "h.png"],
        &dir,
    );
    assert!(output.status.success(), "{}", stderr(&output));
    assert_eq!(
        problems(&output),
        ["warning: h.png: the image is empty: nothing is visible under the transfer function from this camera \
             (compare --tf's values with `voxstream info`'s value range, or check --eye and --target)"]
    );
}

/// Where the ray through pixel centres would hit: the pixel `(column, row)` a world point projects to, computed
/// independently of the renderer (pinhole, vertical field of view, y down).
fn project(camera: &voxstream_render::Camera, point: DVec3, width: u32, height: u32) -> (f64, f64) {
    let eye = DVec3::from(camera.eye);
    let forward = (DVec3::from(camera.target) - eye).normalize();
    let right = forward.cross(DVec3::from(camera.up)).normalize();
    let up = right.cross(forward);
    let v = point - eye;
    let depth = v.dot(forward);
    assert!(depth > 0.0, "{point} is behind the eye");
    let half = (camera.fov.to_radians() / 2.0).tan();
    let aspect = width as f64 / height as f64;
    let sx = v.dot(right) / depth / (half * aspect);
    let sy = v.dot(up) / depth / half;
    ((sx + 1.0) / 2.0 * width as f64, (1.0 - sy) / 2.0 * height as f64)
}

#[test]
fn the_default_store_camera_frames_all_eight_corners() {
    let volumes = [
        ([197, 233, 189], [1.0, 1.0, 1.0], [-98.0, -134.0, -72.0]),
        ([500, 470, 136], [1.0, 1.0, 1.5], [0.0, 0.0, 0.0]),
        ([2048, 64, 64], [0.5, 0.5, 0.5], [10.0, 0.0, -5.0]),
        ([32, 32, 900], [2.0, 2.0, 0.3], [0.0, 0.0, 0.0]),
    ];
    for (dims, spacing, origin) in volumes {
        let info = VolumeInfo { dims, dtype: DType::U8, spacing, origin, unit: None, orientation: None };
        for (width, height) in [(512, 512), (1024, 256), (200, 700)] {
            let camera = store_camera(&info, width, height);
            let mut widest: f64 = 0.0;
            for corner in 0..8 {
                let point =
                    DVec3::from([0, 1, 2].map(|a| {
                        origin[a] + if corner >> a & 1 == 1 { (dims[a] - 1) as f64 * spacing[a] } else { 0.0 }
                    }));
                let (x, y) = project(&camera, point, width, height);
                assert!(
                    (0.0..=width as f64).contains(&x) && (0.0..=height as f64).contains(&y),
                    "{dims:?} at {width}x{height}: corner {point} projects to ({x:.1}, {y:.1})"
                );
                widest = widest.max((x / width as f64 - 0.5).abs()).max((y / height as f64 - 0.5).abs());
            }
            // Framed, not lost in the distance: some corner comes near an edge.
            assert!(widest > 0.4, "{dims:?} at {width}x{height}: the box fills only {:.0}%", widest * 200.0);
        }
    }
}

#[test]
fn the_default_sponge_view_shows_its_central_tunnel() {
    // Rays that stay inside the central tunnel along z (x and y in (1/3, 2/3) at both z = 1 and z = 0) cross no
    // material: their pixels must show the background, and the default view must have such pixels.
    let scene = builtin("sponge").unwrap();
    let size = 192;
    let settings = RenderSettings {
        width: size,
        height: size,
        shading: scene.shading,
        light_direction: scene.light,
        ..RenderSettings::default()
    };
    let mut session =
        Session::new(scene.producer, &scene.transfer_function, settings, 256 << 20, LoopLimits::default()).unwrap();
    let image = session.render(&scene.camera, Mode::Converged).unwrap().image;
    let eye = DVec3::from(scene.camera.eye);
    let inside = |p: DVec3| (0.34..0.66).contains(&p.x) && (0.34..0.66).contains(&p.y);
    let (mut through, mut open) = (0, 0);
    let mut solid = 0;
    for y in 0..size {
        for x in 0..size {
            let d = common::pixel_direction(&scene.camera, x, y, size, size);
            let coverage = image.pixels[(y * size + x) as usize][3];
            let at = |z: f64| eye + d * ((z - eye.z) / d.z);
            if d.z < 0.0 && inside(at(1.0)) && inside(at(0.0)) {
                through += 1;
                open += usize::from(coverage < 0.01);
            } else if coverage > 0.99 {
                solid += 1;
            }
        }
    }
    let pixels = (size * size) as usize;
    assert!(through * 100 > pixels, "the tunnel is seen through by only {through} of {pixels} pixels");
    assert_eq!(open, through, "pixels looking through the tunnel must show the background");
    assert!(solid * 3 > pixels, "the sponge covers only {solid} of {pixels} pixels");
}

#[test]
fn sources_that_are_not_stores_are_explained() {
    let dir = scratch("sources");
    std::fs::write(dir.join("vol.npy"), b"\x93NUMPY").unwrap();
    std::fs::write(dir.join("notes.txt"), b"x").unwrap();
    std::fs::write(dir.join("tiny.raw"), [7u8; 8]).unwrap();
    let cases: [(&[&str], &str); 8] = [
        (
            &["render", "nosuch.zarr"],
            "error: store nosuch.zarr not found: expected a folder made by `voxstream import` (check the path)",
        ),
        (
            &["info", "nosuch.zarr"],
            "error: store nosuch.zarr not found: expected a folder made by `voxstream import` (check the path)",
        ),
        (
            &["render", "vol.npy"],
            "error: vol.npy is a volume file, not a store: run `voxstream import vol.npy --out vol.zarr` first, then \
             `voxstream render vol.zarr`",
        ),
        (
            &["info", "vol.npy"],
            "error: vol.npy is a volume file, not a store: run `voxstream import vol.npy --out vol.zarr` first, then \
             `voxstream info vol.zarr`",
        ),
        (
            &["render", "spnge"],
            "error: unknown source 'spnge' (did you mean `sponge`?): expected a built-in scene (sponge, hypertexture, \
             shell) or a store folder made by `voxstream import`",
        ),
        (
            &["info", "sponge"],
            "error: sponge is a built-in scene, not a store: `voxstream info` describes stores made by `voxstream import`",
        ),
        (
            // An OS error is said once, without its number.
            &["import", "notes.txt/vol.nrrd", "--out", "v.zarr"],
            "error: notes.txt/vol.nrrd: not found",
        ),
        (
            &["import", "tiny.raw", "--dims", "2,2,2", "--dtype", "u8", "--out", "notes.txt/v.zarr"],
            "error: notes.txt: is a file, not a folder: name an --out inside a folder",
        ),
    ];
    for (args, expected) in cases {
        let output = voxstream(args, &dir);
        assert_eq!(output.status.code(), Some(1), "{args:?}");
        assert_eq!(stderr(&output).trim_end(), expected, "{args:?}");
    }
}

#[test]
fn mistakes_in_flags_and_files_are_named_in_the_user_s_terms() {
    let dir = scratch("flags");
    import_ball(&dir);
    std::fs::write(dir.join("path.json"), r#"[{"eye": [0, 0, 3], "target": [0, 0, 0]}]"#).unwrap();
    let path_file = dir.join("path.json");
    let cases: [(Vec<&str>, String); 3] = [
        (
            vec!["render", "--path", "path.json", "--out", "f.png"],
            format!("error: invalid camera path {}: camera 0: missing field `up`", Path::new("path.json").display()),
        ),
        (
            // A 64x64 image (160 KiB of the budget): the pools are what does not fit.
            vec!["render", "ball.zarr", "--budget-mb", "1", "--width", "64", "--height", "64", "--out", "f.png"],
            "error: --budget-mb 1 is too small for this source: the node and brick pools need at least 2 MiB (use \
             --budget-mb 2 or more)"
                .into(),
        ),
        (
            // numpy's shape order (z, y, x) passed as --dims for a NumPy file.
            vec!["import", "numpy.npy", "--dims", "48,56,64", "--dtype", "u16", "--out", "n.zarr"],
            "error: --dims 48,56,64 is numpy.npy's dimensions reversed (numpy's shape order z,y,x): voxstream's --dims \
             is x,y,z, i.e. --dims 64,56,48; better, drop --dims and --dtype: the NumPy header gives them"
                .into(),
        ),
    ];
    assert!(path_file.exists());
    // A NumPy file of shape (48, 56, 64), C order: x = 64 varies fastest.
    let raw = std::fs::read(dir.join("ball.raw")).unwrap();
    let npy = voxstream_store::formats::npy::npy_bytes("<u2", [48, 56, 64], &raw);
    std::fs::write(dir.join("numpy.npy"), npy).unwrap();
    for (args, expected) in cases {
        let output = voxstream(&args, &dir);
        assert_eq!(output.status.code(), Some(1), "{args:?}: {}", stderr(&output));
        assert_eq!(stderr(&output).trim_end(), expected, "{args:?}");
    }
    assert!(!dir.join("n.zarr").exists() && !dir.join("n.zarr.partial").exists());
}

#[test]
fn render_reports_what_it_wrote() {
    let dir = scratch("summary");
    let output = voxstream(&["render", "shell", "--width", "48", "--height", "40", "--out", "s.png"], &dir);
    assert!(output.status.success(), "{}", stderr(&output));
    let text = stderr(&output);
    let line = text.lines().last().unwrap();
    assert!(line.starts_with("wrote s.png (48x40, complete, "), "{text}");
    assert!(line.contains(" bricks loaded) in ") && line.ends_with(" s"), "{text}");

    std::fs::write(
        dir.join("path.json"),
        r#"[{"eye":[1.5,1.2,1.7],"target":[0.5,0.5,0.5],"up":[0,1,0]},{"eye":[1.6,1.2,1.6],"target":[0.5,0.5,0.5],"up":[0,1,0]}]"#,
    )
    .unwrap();
    let output = voxstream(
        &["render", "shell", "--width", "32", "--height", "32", "--path", "path.json", "--out", "p.png"],
        &dir,
    );
    assert!(output.status.success(), "{}", stderr(&output));
    let lines: Vec<String> = stderr(&output).lines().map(String::from).collect();
    assert_eq!(lines[..2], ["wrote p_0000.png", "wrote p_0001.png"], "{lines:?}");
    assert!(lines[2].starts_with("wrote 2 frames, p_0000.png … p_0001.png (32x32, complete, "), "{lines:?}");

    let output = voxstream(&["render", "shell", "--width", "32", "--height", "32", "--quiet", "--out", "q.png"], &dir);
    assert!(output.status.success() && output.stderr.is_empty(), "--quiet prints nothing: {}", stderr(&output));
    assert!(dir.join("q.png").exists());
}
