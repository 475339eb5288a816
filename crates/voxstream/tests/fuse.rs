//! `voxstream synth-rgbd` and `voxstream fuse` end to end (issue 49, Reichl ch. 8): a synthetic RGB-D orbit around
//! the CGAL bunny fused with ground-truth poses into binary bricks, whose stats, store (`info`, `render --iso 128`)
//! and surface points are checked against the true scene (a fusion of depths with the wrong scale fails the same
//! check); tracked poses (`--poses track`) against ground truth; `--overwrite`; and bad input refused in one line
//! with nothing written.

mod common;

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use common::{import_ball, real_data_dir, scratch, stderr, voxstream};
use glam::DVec3;
use voxstream_geometry::triangle_bvh::TriangleBvh;

/// The voxel edge the tests fuse at, metres.
const VOXEL: f64 = 0.01;

/// A 36-frame orbit (Kinect noise) around the bunny, rendered once for the tests that share it; `None` where the
/// real data is absent and may be skipped.
fn bunny_sequence() -> Option<&'static Path> {
    static SEQUENCE: OnceLock<Option<PathBuf>> = OnceLock::new();
    SEQUENCE
        .get_or_init(|| {
            let real = real_data_dir()?;
            let dir = scratch("fuse", "bunny");
            let mesh = real.join("bunny00.off");
            let output =
                voxstream(&["synth-rgbd", mesh.to_str().unwrap(), "--out", "seq", "--frames", "36", "--quiet"], &dir);
            assert!(output.status.success(), "synth-rgbd: {}", stderr(&output));
            Some(dir.join("seq"))
        })
        .as_deref()
}

/// Whether `dir` holds no `OUT.fusion-chunks-PID` scratch folder of `fuse --out OUT`.
fn no_chunk_folder(dir: &Path, out: &str) -> bool {
    let prefix = format!("{out}.fusion-chunks");
    std::fs::read_dir(dir).unwrap().all(|e| !e.unwrap().file_name().to_string_lossy().starts_with(&prefix))
}

fn stats(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).expect("stats written")).expect("stats are JSON")
}

/// Fraction of the image's pixels that are not the black background.
fn covered(png: &Path) -> f64 {
    let decoder = png::Decoder::new(std::fs::File::open(png).expect("png written"));
    let mut reader = decoder.read_info().expect("a png");
    let mut buffer = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buffer).expect("a frame");
    let channels = info.color_type.samples();
    let pixels = buffer[..info.buffer_size()].chunks(channels).filter(|p| p[..3].iter().any(|&c| c > 8)).count();
    pixels as f64 / (info.width * info.height) as f64
}

/// A binary little-endian PLY's header lines and the bytes after `end_header`.
fn ply_body(path: &Path) -> (Vec<String>, Vec<u8>) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let end = b"end_header\n";
    let at = bytes.windows(end.len()).position(|w| w == end).expect("a PLY header") + end.len();
    let header = String::from_utf8_lossy(&bytes[..at]).lines().map(str::to_string).collect::<Vec<_>>();
    assert!(header.iter().any(|l| l == "format binary_little_endian 1.0"), "{header:?}");
    (header, bytes[at..].to_vec())
}

/// The count of `element NAME n` in a PLY header.
fn element_count(header: &[String], name: &str) -> usize {
    let prefix = format!("element {name} ");
    let line = header.iter().find(|l| l.starts_with(&prefix)).unwrap_or_else(|| panic!("no {name}: {header:?}"));
    line[prefix.len()..].trim().parse().expect("a count")
}

fn f32_at(bytes: &[u8], at: usize) -> f64 {
    f64::from(f32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()))
}

/// The surface points `fuse --points` writes: float x, y, z, nx, ny, nz and uchar red, green, blue.
fn read_points(path: &Path) -> Vec<DVec3> {
    let (header, body) = ply_body(path);
    let properties: Vec<&str> = header.iter().filter(|l| l.starts_with("property ")).map(String::as_str).collect();
    assert_eq!(
        properties,
        [
            "property float x",
            "property float y",
            "property float z",
            "property float nx",
            "property float ny",
            "property float nz",
            "property uchar red",
            "property uchar green",
            "property uchar blue"
        ]
    );
    let n = element_count(&header, "vertex");
    assert_eq!(body.len(), n * 27, "27 bytes a point");
    body.chunks(27).map(|p| DVec3::new(f32_at(p, 0), f32_at(p, 4), f32_at(p, 8))).collect()
}

/// The true scene `synth-rgbd` writes as scene.ply: float x, y, z vertices, faces of a uchar count and int indices.
fn read_scene(path: &Path) -> (Vec<DVec3>, Vec<[u32; 3]>) {
    let (header, body) = ply_body(path);
    assert!(header.iter().any(|l| l == "property list uchar int vertex_indices"), "{header:?}");
    let (vertices, faces) = (element_count(&header, "vertex"), element_count(&header, "face"));
    assert_eq!(body.len(), vertices * 12 + faces * 13, "float xyz vertices, triangles of uchar 3 and int indices");
    let positions =
        (0..vertices).map(|i| DVec3::new(f32_at(&body, 12 * i), f32_at(&body, 12 * i + 4), f32_at(&body, 12 * i + 8)));
    let triangles = body[vertices * 12..]
        .chunks(13)
        .map(|f| {
            assert_eq!(f[0], 3, "triangles");
            [1, 5, 9].map(|at| u32::try_from(i32::from_le_bytes(f[at..at + 4].try_into().unwrap())).unwrap())
        })
        .collect();
    (positions.collect(), triangles)
}

/// Distances (in voxels) of `points` to the scene in `scene_ply`, sorted; points farther than 10 voxels count as 10.
fn distances_to_scene(points: &[DVec3], scene_ply: &Path) -> Vec<f64> {
    let (positions, triangles) = read_scene(scene_ply);
    let bvh = TriangleBvh::build(&positions, &triangles);
    let mut distances: Vec<f64> = points
        .iter()
        .map(|&p| {
            bvh.closest_point(&positions, &triangles, p, 10.0 * VOXEL)
                .map_or(10.0, |c| c.distance_squared.sqrt() / VOXEL)
        })
        .collect();
    distances.sort_by(f64::total_cmp);
    distances
}

/// Mean and 95th percentile of sorted distances.
fn mean_and_p95(sorted: &[f64]) -> (f64, f64) {
    let mean = sorted.iter().sum::<f64>() / sorted.len() as f64;
    (mean, sorted[sorted.len() * 95 / 100])
}

/// Copies the dataset `from` into `to` with every depth scaled by `factor` (16-bit PNGs in units of 1/5000 m).
fn copy_with_depth_scale(from: &Path, to: &Path, factor: f64) {
    std::fs::create_dir_all(to.join("rgb")).unwrap();
    std::fs::create_dir_all(to.join("depth")).unwrap();
    for name in ["rgb.txt", "depth.txt", "groundtruth.txt"] {
        std::fs::copy(from.join(name), to.join(name)).unwrap();
    }
    for entry in std::fs::read_dir(from.join("rgb")).unwrap() {
        let entry = entry.unwrap();
        std::fs::copy(entry.path(), to.join("rgb").join(entry.file_name())).unwrap();
    }
    for entry in std::fs::read_dir(from.join("depth")).unwrap() {
        let entry = entry.unwrap();
        let decoder = png::Decoder::new(std::fs::File::open(entry.path()).unwrap());
        let mut reader = decoder.read_info().unwrap();
        let mut buffer = vec![0; reader.output_buffer_size()];
        let info = reader.next_frame(&mut buffer).unwrap();
        assert_eq!((info.color_type, info.bit_depth), (png::ColorType::Grayscale, png::BitDepth::Sixteen));
        let mut scaled = Vec::with_capacity(info.buffer_size());
        for sample in buffer[..info.buffer_size()].chunks(2) {
            let value = f64::from(u16::from_be_bytes([sample[0], sample[1]])) * factor;
            scaled.extend((value.round().min(65535.0) as u16).to_be_bytes());
        }
        let file = std::fs::File::create(to.join("depth").join(entry.file_name())).unwrap();
        let mut encoder = png::Encoder::new(file, info.width, info.height);
        encoder.set_color(png::ColorType::Grayscale);
        encoder.set_depth(png::BitDepth::Sixteen);
        encoder.write_header().unwrap().write_image_data(&scaled).unwrap();
    }
}

#[test]
fn a_synthetic_orbit_fuses_into_a_store_that_info_and_render_open() {
    let Some(sequence) = bunny_sequence() else { return };
    let dir = scratch("fuse", "store");
    let output = voxstream(
        &[
            "fuse",
            sequence.to_str().unwrap(),
            "--out",
            "scene",
            "--points",
            "points.ply",
            "--stats",
            "stats.json",
            "--image",
            "bits.png",
        ],
        &dir,
    );
    assert!(output.status.success(), "{}", stderr(&output));
    // The surface drawn from the bits at the last frame's pose: the bunny and the floor before the camera.
    let drawn = covered(&dir.join("bits.png"));
    assert!(drawn > 0.3, "{drawn}");
    let err = stderr(&output);
    assert!(err.contains("fused 36 frames (0 lost)") && err.contains("saved scene"), "{err}");
    let s = stats(&dir.join("stats.json"));
    assert_eq!(s["frames"], 36);
    assert_eq!(s["frames_lost"], 0);
    assert_eq!(s["ate_rmse"], serde_json::Value::Null, "no ATE with ground-truth poses");
    // A window every 8 frames of 36 (and the rest at the end).
    let windows = s["windows"].as_u64().unwrap();
    assert!((4..=5).contains(&windows), "{windows}");
    let bricks = s["bricks"].as_u64().unwrap();
    let peak = s["peak_brick_bytes"].as_u64().unwrap();
    assert!(bricks > 100, "{bricks}");
    // Two bits a voxel and the colours of surface voxels: a float distance and weight a voxel (8 bytes, 4 KiB a
    // brick of 8³) would take many times more.
    assert!(peak > 0 && peak * 4 < bricks * 512 * 8, "peak {peak} bytes for {bricks} bricks");
    let points = s["surface_points"].as_u64().unwrap();
    assert!(points > 1000, "{points}");
    assert_eq!(read_points(&dir.join("points.ply")).len() as u64, points);
    assert!(s["store_levels"].as_u64().unwrap() >= 1, "{}", s["store_levels"]);
    assert!(no_chunk_folder(&dir, "scene"), "the chunk scratch folder is removed");

    let info = voxstream(&["info", "scene"], &dir);
    assert!(info.status.success(), "{}", stderr(&info));
    let text = String::from_utf8_lossy(&info.stdout);
    assert!(text.contains("type         u8") && text.contains("spacing      0.01 0.01 0.01"), "{text}");

    let render = voxstream(
        &["render", "scene", "--iso", "128", "--out", "scene.png", "--width", "160", "--height", "120"],
        &dir,
    );
    assert!(render.status.success(), "{}", stderr(&render));
    // The bunny and the floor show (measured: 9.8% of the pixels from the default camera, which frames the whole
    // 2.4 m store): the store holds the confident bits thickened into the unsure voxels behind them, so a floor one
    // voxel thick reaches 128 too (with a 3×3×3 box filter instead, 9 pixels of 19200 did).
    let coverage = covered(&dir.join("scene.png"));
    assert!(coverage > 0.05, "{coverage}");
}

#[test]
fn surface_points_lie_on_the_true_scene_and_a_wrong_depth_scale_does_not() {
    let Some(sequence) = bunny_sequence() else { return };
    let dir = scratch("fuse", "points");
    let output = voxstream(&["fuse", sequence.to_str().unwrap(), "--points", "points.ply", "--quiet"], &dir);
    assert!(output.status.success(), "{}", stderr(&output));
    assert!(stderr(&output).is_empty(), "--quiet: {}", stderr(&output));
    let points = read_points(&dir.join("points.ply"));
    assert!(points.len() > 1000, "{}", points.len());
    let (mean, p95) = mean_and_p95(&distances_to_scene(&points, &sequence.join("scene.ply")));
    // Measured: mean 0.19 voxel, 95% within 0.44 voxel (face centres of the voxels behind the surface).
    assert!(mean < 0.35 && p95 < 0.75, "mean {mean:.3} voxel, 95th percentile {p95:.3} voxel");

    // The thesis' two bits alone (--sign-only) put the surface on voxel faces: farther from the truth, in bricks
    // that take less memory.
    let output = voxstream(
        &["fuse", sequence.to_str().unwrap(), "--sign-only", "--points", "sign.ply", "--stats", "sign.json", "--quiet"],
        &dir,
    );
    assert!(output.status.success(), "{}", stderr(&output));
    let (sign_mean, sign_p95) =
        mean_and_p95(&distances_to_scene(&read_points(&dir.join("sign.ply")), &sequence.join("scene.ply")));
    eprintln!("offsets: mean {mean:.3} p95 {p95:.3} voxel; sign only: mean {sign_mean:.3} p95 {sign_p95:.3} voxel");
    assert!(mean < 0.75 * sign_mean, "mean {mean:.3} voxel with offsets, {sign_mean:.3} with --sign-only");
    let output = voxstream(&["fuse", sequence.to_str().unwrap(), "--stats", "offsets.json", "--quiet"], &dir);
    assert!(output.status.success(), "{}", stderr(&output));
    let peak = |name: &str| stats(&dir.join(name))["peak_brick_bytes"].as_u64().unwrap();
    let (with, without) = (peak("offsets.json"), peak("sign.json"));
    assert!(without < with && with < 2 * without, "peak brick bytes {with} with offsets, {without} without");

    // The same sequence with every depth 3% too far (3.6 cm at the orbit's 1.2 m; measured mean 1.6 voxels, 95%
    // within 2.8): the check must catch it.
    copy_with_depth_scale(sequence, &dir.join("scaled"), 1.03);
    let output = voxstream(&["fuse", "scaled", "--points", "scaled.ply", "--quiet"], &dir);
    assert!(output.status.success(), "{}", stderr(&output));
    let scaled = read_points(&dir.join("scaled.ply"));
    let (mean, p95) = mean_and_p95(&distances_to_scene(&scaled, &sequence.join("scene.ply")));
    assert!(mean > 0.35 || p95 > 0.75, "a wrong depth scale passed: mean {mean:.3}, 95th percentile {p95:.3}");
}

#[test]
fn tracked_poses_lose_no_frame_and_stay_near_the_ground_truth() {
    let Some(real) = real_data_dir() else { return };
    let dir = scratch("fuse", "track");
    let mesh = real.join("bunny00.off");
    let output = voxstream(
        &["synth-rgbd", mesh.to_str().unwrap(), "--out", "slow", "--frames", "24", "--sweep", "30", "--quiet"],
        &dir,
    );
    assert!(output.status.success(), "{}", stderr(&output));
    let output = voxstream(
        &["fuse", "slow", "--poses", "track", "--stats", "stats.json", "--trajectory", "poses.txt", "--quiet"],
        &dir,
    );
    assert!(output.status.success(), "{}", stderr(&output));
    let s = stats(&dir.join("stats.json"));
    assert_eq!(s["frames"], 24);
    assert_eq!(s["frames_lost"], 0);
    assert!(s["track_seconds"].as_f64().unwrap() > 0.0);
    let ate = s["ate_rmse"].as_f64().expect("an ATE with ground truth");
    // Measured 5 to 7 mm with the frames bilateral-filtered before tracking (16 to 24 mm without: the noisy
    // normals held ICP near its start). A tracker that stood still would be off by about 0.18 m over the 0.63 m the
    // camera travels.
    assert!(ate > 0.0 && ate < 0.02, "ATE RMSE {ate} m");
    let trajectory = std::fs::read_to_string(dir.join("poses.txt")).unwrap();
    let lines: Vec<&str> = trajectory.lines().collect();
    assert_eq!(lines.len(), 25, "a header and a line a frame: {trajectory}");
    assert!(lines[0].starts_with("# timestamp tx ty tz qx qy qz qw"), "{}", lines[0]);
    for (i, line) in lines[1..].iter().enumerate() {
        let values: Vec<f64> = line.split_whitespace().map(|v| v.parse().expect("a number")).collect();
        assert_eq!(values.len(), 8, "{line}");
        assert!((values[0] - i as f64 / 30.0).abs() < 1e-5, "frame {i} at {}", values[0]);
        let q = DVec3::new(values[4], values[5], values[6]).length_squared() + values[7] * values[7];
        assert!((q - 1.0).abs() < 1e-4, "a unit quaternion: {line}");
    }
    // The first frame starts at its ground truth.
    let truth = std::fs::read_to_string(dir.join("slow/groundtruth.txt")).unwrap();
    let first_truth = truth.lines().find(|l| !l.starts_with('#')).unwrap();
    let a: Vec<f64> = lines[1].split_whitespace().map(|v| v.parse().unwrap()).collect();
    let b: Vec<f64> = first_truth.split_whitespace().map(|v| v.parse().unwrap()).collect();
    assert!(a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 1e-5), "{a:?} vs {b:?}");
}

/// Runs `args` in `dir` and checks it fails with one line naming `expected`, without a panic.
fn refused(dir: &Path, args: &[&str], expected: &str) {
    let output = voxstream(args, dir);
    assert!(!output.status.success(), "{args:?} succeeded");
    let err = stderr(&output);
    assert!(err.contains(expected), "{args:?}: {err}");
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "one line: {err}");
}

#[test]
fn bad_input_is_refused_in_one_line_and_nothing_is_written() {
    let Some(sequence) = bunny_sequence() else { return };
    let real = real_data_dir().expect("the real data");
    let dir = scratch("fuse", "refused");
    let seq = sequence.to_str().unwrap();
    // A dataset without ground truth: the lists, no groundtruth.txt.
    std::fs::create_dir(dir.join("no-truth")).unwrap();
    for name in ["rgb.txt", "depth.txt"] {
        std::fs::copy(sequence.join(name), dir.join("no-truth").join(name)).unwrap();
    }
    let fuse_refused = |args: &[&str], expected: &str| {
        refused(&dir, args, expected);
        assert!(!dir.join("new").exists(), "{args:?} wrote --out");
        assert!(no_chunk_folder(&dir, "new"), "{args:?} left chunks");
        assert!(!dir.join("p.ply").exists() && !dir.join("s.json").exists(), "{args:?} wrote --points or --stats");
    };
    fuse_refused(&["fuse", "missing", "--out", "new"], "missing: does not exist");
    fuse_refused(
        &["fuse", "no-truth", "--out", "new", "--points", "p.ply"],
        "no groundtruth.txt; fuse with --poses track",
    );
    fuse_refused(&["fuse", seq, "--out", "new", "--window", "3"], "--window 3: give an even number of frames");
    fuse_refused(&["fuse", seq, "--out", "new", "--voxel", "0"], "--voxel 0: give an edge between");
    fuse_refused(
        &["fuse", seq, "--out", "new", "--intrinsics", "0,525,319.5,239.5"],
        "--intrinsics 0,525,319.5,239.5: give finite focal lengths above 0",
    );
    fuse_refused(&["fuse", seq, "--out", "new", "--intrinsics", "525,525,319.5"], "--intrinsics: give four numbers");
    // Six numbers name the image size; images of another size are refused from their header, naming the flag.
    fuse_refused(
        &["fuse", seq, "--out", "new", "--intrinsics", "262.5,262.5,159.5,119.5,320,240"],
        "the image is 640×480 but the intrinsics are 320×240",
    );
    fuse_refused(&["fuse", seq, "--out", "new", "--intrinsics", "525,525,319.5,239.5,640.5,480"], "whole numbers");
    fuse_refused(&["fuse", seq], "give --out SCENE (and/or --points, --trajectory, --image, --stats)");
    fuse_refused(&["fuse", seq, "--out", "new", "--stats", "s.json", "--memory-mb", "8"], "--memory-mb 8");

    // An existing store is left as it was without --overwrite.
    import_ball(&dir, "old");
    let before = std::fs::read_dir(dir.join("old")).unwrap().count();
    let info_before = voxstream(&["info", "old"], &dir).stdout;
    refused(&dir, &["fuse", seq, "--out", "old", "--stats", "s.json"], "old exists; give --overwrite to replace it");
    assert!(!dir.join("s.json").exists());
    assert_eq!(std::fs::read_dir(dir.join("old")).unwrap().count(), before);
    assert_eq!(voxstream(&["info", "old"], &dir).stdout, info_before, "the old store is untouched");

    let mesh = real.join("bunny00.off");
    let mesh = mesh.to_str().unwrap();
    let pdb = real.join("1hvr.pdb");
    let synth_refused = |args: &[&str], expected: &str| {
        refused(&dir, args, expected);
        assert!(!dir.join("synth").exists(), "{args:?} wrote --out");
    };
    synth_refused(&["synth-rgbd", pdb.to_str().unwrap(), "--out", "synth"], "holds points, not triangles");
    synth_refused(&["synth-rgbd", "missing.off", "--out", "synth"], "missing.off");
    synth_refused(&["synth-rgbd", mesh, "--out", "synth", "--frames", "0"], "frames = 0 is out of range");
    synth_refused(&["synth-rgbd", mesh, "--out", "synth", "--up", "w"], "--up w: give x, y or z");
}

#[test]
fn overwrite_replaces_an_existing_store_with_one_that_opens() {
    let Some(sequence) = bunny_sequence() else { return };
    let dir = scratch("fuse", "overwrite");
    import_ball(&dir, "scene");
    let info = voxstream(&["info", "scene"], &dir);
    assert!(
        String::from_utf8_lossy(&info.stdout).contains("48 x 40 x 36"),
        "{}",
        String::from_utf8_lossy(&info.stdout)
    );
    let output = voxstream(
        &["fuse", sequence.to_str().unwrap(), "--out", "scene", "--overwrite", "--frames", "16", "--quiet"],
        &dir,
    );
    assert!(output.status.success(), "{}", stderr(&output));
    let info = voxstream(&["info", "scene"], &dir);
    assert!(info.status.success(), "{}", stderr(&info));
    let text = String::from_utf8_lossy(&info.stdout).into_owned();
    assert!(!text.contains("48 x 40 x 36"), "still the ball: {text}");
    assert!(text.contains("type         u8") && text.contains("spacing      0.01 0.01 0.01"), "{text}");
    let render =
        voxstream(&["render", "scene", "--iso", "128", "--out", "s.png", "--width", "160", "--height", "120"], &dir);
    assert!(render.status.success(), "{}", stderr(&render));
    assert!(covered(&dir.join("s.png")) > 0.0);
}
