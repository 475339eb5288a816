//! The viewing tools of issue 42 from the command line: camera presets and turns (`--view`, `--azimuth`,
//! `--elevation`, `--zoom`), a full orbit, intensity projections, clipping planes and the crop box, and movies
//! (`--video`, through Debian's ffmpeg, which `.ci/run` installs).

mod common;

use std::path::Path;
use std::process::Command;

use common::{import_ball, read_png, scratch, stderr, voxstream};
use glam::DVec3;

/// The first camera a render used, from its `--stats` file.
fn stats_camera(stats: &Path) -> (DVec3, DVec3, DVec3) {
    let text = std::fs::read_to_string(stats).expect("stats written");
    let json: serde_json::Value = serde_json::from_str(&text).expect("stats JSON");
    let vector = |name: &str| {
        let v: Vec<f64> = json["camera"][name].as_array().expect(name).iter().map(|x| x.as_f64().unwrap()).collect();
        DVec3::new(v[0], v[1], v[2])
    };
    (vector("eye"), vector("target"), vector("up"))
}

fn run_ok(args: &[&str], dir: &Path) {
    let output = voxstream(args, dir);
    assert!(output.status.success(), "voxstream {args:?} failed: {}", stderr(&output));
}

fn run_fails(args: &[&str], dir: &Path, expected: &str) {
    let output = voxstream(args, dir);
    let message = stderr(&output);
    assert!(!output.status.success(), "voxstream {args:?} succeeded");
    assert!(message.contains(expected), "voxstream {args:?}: expected `{expected}` in: {message}");
    assert!(!message.contains("panicked"), "{message}");
}

#[test]
fn presets_and_turns_place_the_camera_where_they_say() {
    let dir = scratch("viewing_tools", "presets");
    import_ball(&dir, "ball.zarr");
    let size = ["--width", "48", "--height", "32"];
    // Looking along +x: the eye on the −x side of the ball's centre, at its height, +z up.
    let mut args = vec!["render", "ball.zarr", "--view", "+x", "--out", "x.png", "--stats", "x.json"];
    args.extend(size);
    run_ok(&args, &dir);
    let (eye, target, up) = stats_camera(&dir.join("x.json"));
    let along = (target - eye).normalize();
    assert!((along - DVec3::X).length() < 1e-9, "looks along {along}");
    assert!((up - DVec3::Z).length() < 1e-9, "up {up}");
    // Samples 0..47 along x at spacing 1: the centre is at 23.5.
    assert!((target.x - 23.5).abs() < 1e-9, "{target}");

    // The same preset turned 90° (the eye to its right: from −x to −y), raised 90° (straight down), and twice as
    // close: the eye above the centre, the image's top towards +y, at half the distance.
    let mut args = vec!["render", "ball.zarr", "--view", "+x", "--azimuth", "90", "--elevation", "90", "--zoom", "2"];
    args.extend(["--out", "top.png", "--stats", "top.json"]);
    args.extend(size);
    run_ok(&args, &dir);
    let (top_eye, top_target, top_up) = stats_camera(&dir.join("top.json"));
    assert!((top_target - target).length() < 1e-9);
    let offset = top_eye - top_target;
    assert!((offset.normalize() - DVec3::Z).length() < 1e-9, "eye at {top_eye}");
    assert!((offset.length() - (eye - target).length() / 2.0).abs() < 1e-6, "distance {}", offset.length());
    assert!((top_up - DVec3::Y).length() < 1e-9, "up {top_up}");
    assert_ne!(std::fs::read(dir.join("x.png")).unwrap(), std::fs::read(dir.join("top.png")).unwrap());

    run_fails(&["render", "ball.zarr", "--view", "top"], &dir, "+x, -x, +y, -y, +z, -z, iso");
    run_fails(&["render", "ball.zarr", "--view", "+z", "--eye", "1,2,3"], &dir, "drop --camera, --eye and --target");
    run_fails(&["render", "ball.zarr", "--elevation", "120"], &dir, "pass over the pole");
    run_fails(&["render", "ball.zarr", "--zoom", "-1"], &dir, "--zoom");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn projections_crops_and_planes_draw_and_refuse_as_they_say() {
    let dir = scratch("viewing_tools", "projections");
    import_ball(&dir, "ball.zarr");
    // Looking down −z with +y up (x grows to the right), from the camera `--view -z` frames the whole ball with:
    // a crop with --view would frame the crop box instead.
    run_ok(&["render", "ball.zarr", "--view", "-z", "--stats", "view.json", "--out", "view.png"], &dir);
    let (eye, target, up) = stats_camera(&dir.join("view.json"));
    let vector = |v: DVec3| format!("{},{},{}", v.x, v.y, v.z);
    let (eye, target, up) = (vector(eye), vector(target), vector(up));
    let size = ["--width", "40", "--height", "40", "--eye", &eye, "--target", &target, "--up", &up];
    for (name, extra) in [
        ("composite", vec![]),
        ("max", vec!["--projection", "max"]),
        ("min", vec!["--projection", "min"]),
        ("crop", vec!["--projection", "max", "--crop", "0,0,0,24,40,36"]),
        ("plane", vec!["--projection", "max", "--clip-plane", "23.5,0,0,-1,0,0"]),
    ] {
        let out = format!("{name}.png");
        let mut args = vec!["render", "ball.zarr", "--out", &out];
        args.extend(size);
        args.extend(extra);
        run_ok(&args, &dir);
    }
    let image = |name: &str| read_png(&dir.join(format!("{name}.png")));
    let bright = |img: &(u32, u32, Vec<u8>)| img.2.chunks(3).filter(|p| p[0] > 40).count();
    let lit = |img: &(u32, u32, Vec<u8>), columns: std::ops::Range<u32>, above: u8| {
        img.2.chunks(3).enumerate().filter(|(i, p)| columns.contains(&(*i as u32 % img.0)) && p[0] > above).count()
    };
    let (composite, max, min) = (image("composite"), image("max"), image("min"));
    assert_ne!(composite.2, max.2, "the maximum is not the composite");
    assert!(bright(&max) > 100, "the MIP shows the ball: {} bright pixels", bright(&max));
    // The crop (x < 24) and the plane (keeping x ≤ 23.5) leave the left half; the right half is the background.
    for name in ["crop", "plane"] {
        let cut = image(name);
        let (right, left) = (lit(&cut, 25..40, 10), lit(&cut, 0..16, 40));
        assert!(right == 0 && left > 50, "{name}: {right} lit pixels on the right, {left} on the left");
    }
    // The ball is brightest inside: its minimum along each ray through it (the samples outside are 0) is dark.
    assert!(bright(&min) < bright(&max) / 4, "min {} vs max {}", bright(&min), bright(&max));

    run_fails(&["render", "ball.zarr", "--projection", "max", "--iso", "1000"], &dir, "drop --iso or --projection");
    run_fails(&["render", "ball.zarr", "--crop", "0,0,0,100,40,36"], &dir, "beyond");
    run_fails(&["render", "ball.zarr", "--crop", "5,0,0,5,10,10"], &dir, "lower index must be below");
    run_fails(&["render", "shell", "--crop", "0,0,0,8,8,8"], &dir, "applies to stores");
    run_fails(&["render", "ball.zarr", "--clip-plane", "0,0,0,0,0,0"], &dir, "must not be zero");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Frames of a movie as raw RGB, by ffmpeg.
fn decoded_frames(movie: &Path, width: usize, height: usize) -> Vec<Vec<u8>> {
    let output = Command::new("ffmpeg")
        .args(["-hide_banner", "-loglevel", "error", "-i"])
        .arg(movie)
        .args(["-f", "rawvideo", "-pix_fmt", "rgb24", "pipe:1"])
        .output()
        .expect("ffmpeg runs (installed by .ci/run: apt-get install ffmpeg)");
    assert!(output.status.success(), "ffmpeg could not decode: {}", String::from_utf8_lossy(&output.stderr));
    output.stdout.chunks(width * height * 3).map(<[u8]>::to_vec).collect()
}

#[test]
fn a_full_orbit_becomes_a_movie_of_its_frames() {
    let dir = scratch("viewing_tools", "movie");
    let (width, height) = (64usize, 48usize);
    let common = ["--width", "64", "--height", "48", "--path", "orbit:6:360"];
    let mut args = vec!["render", "hypertexture", "--video", "spin.mp4", "--fps", "12"];
    args.extend(common);
    run_ok(&args, &dir);
    let mut args = vec!["render", "hypertexture", "--out", "still.png"];
    args.extend(common);
    run_ok(&args, &dir);
    let frames = decoded_frames(&dir.join("spin.mp4"), width, height);
    assert_eq!(frames.len(), 6, "six frames in the movie");
    assert!(frames.iter().all(|f| f.len() == width * height * 3));
    // Each frame is its PNG within the codec's loss; frames differ from each other (the orbit turns).
    for (index, frame) in frames.iter().enumerate() {
        let (_, _, still) = read_png(&dir.join(format!("still_{index:04}.png")));
        let error: f64 =
            frame.iter().zip(&still).map(|(a, b)| (*a as f64 - *b as f64).abs()).sum::<f64>() / frame.len() as f64;
        assert!(error < 3.0, "frame {index}: mean error {error:.2} against its PNG");
    }
    assert_ne!(frames[0], frames[3], "the orbit's opposite frames are the same");
    // No temporary left beside it, and no PNG written by the movie's run.
    let names: Vec<String> =
        std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert!(names.iter().all(|n| !n.contains("partial")), "{names:?}");
    assert_eq!(names.iter().filter(|n| n.ends_with(".png")).count(), 6, "{names:?}");

    // Without an ffmpeg: one line before any rendering, nothing written.
    let output = Command::new(env!("CARGO_BIN_EXE_voxstream"))
        .args(["render", "hypertexture", "--video", "none.mp4", "--path", "orbit:4:360"])
        .env("VOXSTREAM_FFMPEG", dir.join("no-such-ffmpeg"))
        .current_dir(&dir)
        .output()
        .unwrap();
    let message = stderr(&output);
    assert!(!output.status.success() && message.contains("--video needs ffmpeg"), "{message}");
    assert_eq!(message.trim().lines().count(), 1, "{message}");
    assert!(!dir.join("none.mp4").exists());
    run_fails(&["render", "hypertexture", "--video", "a.mp4"], &dir, "add --path");
    run_fails(&["render", "hypertexture", "--video", "a.avi", "--path", "orbit:4"], &dir, ".mp4");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue 42 item 9: a colour bar and a scale bar, off by default, drawn over the image where asked and nowhere
/// else: the picture itself is the same, pixel for pixel, outside their corners.
#[test]
fn colour_and_scale_bars_are_drawn_in_their_corners_only() {
    let dir = scratch("viewing_tools", "annotations");
    import_ball(&dir, "ball.zarr");
    let size = ["--width", "200", "--height", "160"];
    run_ok(&[&["render", "ball.zarr", "--out", "plain.png"][..], &size].concat(), &dir);
    run_ok(&[&["render", "ball.zarr", "--out", "bars.png", "--color-bar", "--scale-bar"][..], &size].concat(), &dir);
    let (w, h, plain) = read_png(&dir.join("plain.png"));
    let (_, _, bars) = read_png(&dir.join("bars.png"));
    let (w, h) = (w as usize, h as usize);
    let mut changed_bar = 0;
    let mut changed_scale = 0;
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) * 3;
            if plain[i..i + 3] == bars[i..i + 3] {
                continue;
            }
            // The colour bar and its labels: the right part, the middle three fifths; the scale bar: bottom left.
            if x >= w / 2 && y >= h / 5 - 2 && y <= h - h / 5 + 2 {
                changed_bar += 1;
            } else if x < w / 2 && y >= h - 30 {
                changed_scale += 1;
            } else {
                panic!("pixel ({x}, {y}) changed outside the bars' corners");
            }
        }
    }
    assert!(changed_bar > 500 && changed_scale > 100, "{changed_bar} {changed_scale}");
    // A colour bar of nothing: isosurfaces alone have no transfer function to show.
    run_fails(
        &["render", "ball.zarr", "--iso", "1500", "--color-bar", "--out", "iso.png"],
        &dir,
        "--color-bar shows the transfer function, and only isosurfaces are drawn",
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// Issue 42 item 8: orthogonal slices. The ball's cross-section at z = k is the ellipse
/// ((x − 24)/18)² + ((y − 20)/16)² < 1 − ((k − 18)/14)²: seen face-on, its area shrinks by that factor from the
/// centre plane (k = 18) to k = 28 (0.49) — times the perspective's magnification of the nearer plane, the square of
/// the ratio of the eye's distances to the two planes — and the slice shows nothing of the planes around it.
#[test]
fn a_slice_draws_the_plane_of_samples_it_names() {
    let dir = scratch("viewing_tools", "slices");
    import_ball(&dir, "ball.zarr");
    // Every value fully opaque, brightness proportional to the value: the lit pixels are the cross-section.
    std::fs::write(dir.join("grey.json"), r#"{"points": [[0, 0, 0, 0, 1], [3050, 1, 1, 1, 1]]}"#).unwrap();
    let lit = |name: &str, slice: &str| {
        let (out, stats) = (format!("{name}.png"), format!("{name}.json"));
        run_ok(
            &[
                "render",
                "ball.zarr",
                "--slice",
                slice,
                "--tf",
                "grey.json",
                "--width",
                "240",
                "--height",
                "240",
                "--out",
                &out,
                "--stats",
                &stats,
            ],
            &dir,
        );
        // The camera looks down z from above: the eye's height over the plane.
        let (eye, _, _) = stats_camera(&dir.join(&stats));
        let (_, _, pixels) = read_png(&dir.join(&out));
        (pixels.chunks_exact(3).filter(|p| p[0] > 2).count() as f64, eye.z)
    };
    let ((centre, eye_z), (off, _)) = (lit("centre", "z=18"), lit("off", "axial=28"));
    let ratio = off / centre;
    let magnification = ((eye_z - 18.0) / (eye_z - 28.0)).powi(2);
    let expected = (1.0 - (10.0f64 / 14.0).powi(2)) * magnification;
    assert!(centre > 5000.0, "the centre plane's disk: {centre} pixels");
    assert!((ratio - expected).abs() < 0.05, "area ratio {ratio}, the ellipses' {expected}");
    // Beyond the ball (its last plane with samples inside is z = 31): nothing lit.
    assert_eq!(lit("outside", "z=33").0, 0.0);
    // Planes that do not exist, and what a slice cannot be drawn with: one line each.
    run_fails(&["render", "ball.zarr", "--slice", "z=36", "--out", "x.png"], &dir, "has 36 samples along z (0 to 35)");
    run_fails(
        &["render", "ball.zarr", "--slice", "z=3", "--iso", "1500", "--out", "x.png"],
        &dir,
        "drop --iso or --slice",
    );
    run_fails(&["render", "sponge", "--slice", "z=3", "--out", "x.png"], &dir, "--slice applies to stores");
    run_fails(&["render", "ball.zarr", "--slice", "w=3", "--out", "x.png"], &dir, "not an axis");
    std::fs::remove_dir_all(&dir).ok();
}

/// `--slice … --with-volume` is the slab drawn over the volume beyond it, what lies between the eye and the plane cut
/// away: checked against that composition made of independent renders, the slice alone from the same camera (its
/// coverage from a second render over a white background) and the far part alone (a clipping plane at the slab's
/// face away from the eye): `with = plane + (1 − coverage) · far`, pixel by pixel, within the 8-bit images' rounding.
#[test]
fn a_slice_drawn_with_the_volume_is_the_plane_over_the_far_part() {
    let dir = scratch("viewing_tools", "slice-with-volume");
    import_ball(&dir, "ball.zarr");
    // Translucent, so that the volume shows through the plane where its values are low.
    std::fs::write(
        dir.join("tf.json"),
        r#"{"points": [[0, 0, 0, 0, 0], [400, 0.2, 0.5, 1, 0.05], [3050, 1, 0.9, 0.6, 0.3]]}"#,
    )
    .unwrap();
    let render = |name: &str, extra: &[&str]| {
        let (out, stats) = (format!("{name}.png"), format!("{name}.json"));
        let mut args = vec!["render", "ball.zarr", "--tf", "tf.json", "--width", "96", "--height", "96", "--out", &out];
        args.extend_from_slice(&["--stats", &stats]);
        args.extend_from_slice(extra);
        run_ok(&args, &dir);
        let pixels: Vec<f64> = read_png(&dir.join(&out)).2.into_iter().map(|b| b as f64 / 255.0).collect();
        (pixels, stats_camera(&dir.join(&stats)))
    };
    let (with, (eye, target, up)) = render("with", &["--slice", "z=18", "--with-volume"]);
    assert!(eye.z > 18.5, "the default view looks from above the plane: {eye}");
    // The slab is 17.5 ≤ z ≤ 18.5: beyond it from the eye is z ≤ 17.5.
    let (far, _) = render("far", &["--clip-plane", "0,0,17.5,0,0,-1"]);
    let vector = |v: DVec3| format!("{},{},{}", v.x, v.y, v.z);
    let (eye, target, up) = (vector(eye), vector(target), vector(up));
    let camera = ["--slice", "z=18", "--eye", &eye, "--target", &target, "--up", &up, "--fov", "30"];
    let (plane, _) = render("plane", &camera);
    let (plane_on_white, _) = render("plane-white", &[&camera[..], &["--background", "1,1,1"]].concat());
    let mut largest: f64 = 0.0;
    let mut total = 0.0;
    for i in 0..with.len() {
        let through = plane_on_white[i] - plane[i];
        let expected = plane[i] + through * far[i];
        largest = largest.max((with[i] - expected).abs());
        total += (with[i] - expected).abs();
    }
    let mean = total / with.len() as f64;
    assert!(
        largest <= 3.5 / 255.0 && mean < 0.3 / 255.0,
        "differs by {:.2}/255 at most, {:.3}/255 on average",
        largest * 255.0,
        mean * 255.0
    );
    // Both parts show: the plane changes the far part's image, the far part the plane's.
    let changed = |a: &[f64], b: &[f64]| a.iter().zip(b).filter(|(x, y)| (*x - *y).abs() > 0.02).count();
    assert!(changed(&far, &with) > 500, "the plane changes {} channels of the far part's image", changed(&far, &with));
    assert!(changed(&plane, &with) > 500, "the far part changes {} channels of the plane's", changed(&plane, &with));
    // What it cannot be drawn with: one line each.
    run_fails(&["render", "ball.zarr", "--with-volume", "--out", "x.png"], &dir, "--slice");
    run_fails(
        &["render", "ball.zarr", "--slice", "z=3", "--with-volume", "--projection", "max", "--out", "x.png"],
        &dir,
        "drop --projection or --with-volume",
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// A volume of one slice (a single DICOM image, a 2-D array stacked once) is drawn as a slab one sample thick: the
/// box of its sample centres would be flat and show nothing. Its slice alone shows its values as a thicker
/// volume's middle plane shows the same values.
#[test]
fn a_volume_of_one_slice_draws_as_a_slab_one_sample_thick() {
    let dir = scratch("viewing_tools", "one-slice");
    let (nx, ny) = (40usize, 32usize);
    let plane: Vec<u8> =
        (0..nx * ny).map(|i| if (i % nx).abs_diff(20) + (i / nx).abs_diff(16) < 12 { 200 } else { 0 }).collect();
    let npy = |depth: usize| {
        let data: Vec<u8> = (0..depth).flat_map(|_| plane.iter().copied()).collect();
        voxstream_store::formats::npy::npy_bytes("|u1", [depth as u64, ny as u64, nx as u64], &data)
    };
    std::fs::write(dir.join("one.npy"), npy(1)).unwrap();
    std::fs::write(dir.join("three.npy"), npy(3)).unwrap();
    run_ok(&["import", "one.npy", "--out", "one.zarr", "--quiet"], &dir);
    // The three-slice volume's middle plane at the one slice's place (z = 0).
    run_ok(&["import", "three.npy", "--out", "three.zarr", "--origin", "0,0,-1", "--quiet"], &dir);
    let render = |args: &[&str]| {
        run_ok(args, &dir);
        let (_, _, pixels) = read_png(&dir.join(args[args.iter().position(|a| *a == "--out").unwrap() + 1]));
        pixels
    };
    let lit = |pixels: &[u8]| pixels.chunks_exact(3).filter(|p| p.iter().any(|&v| v > 4)).count();
    let drawn = lit(&render(&["render", "one.zarr", "--width", "64", "--height", "64", "--out", "one.png"]));
    assert!(drawn > 100, "the default view of one slice: {drawn} pixels lit");
    // The same camera above both planes.
    let camera =
        ["--eye", "19.5,15.5,80", "--target", "19.5,15.5,0", "--up", "0,1,0", "--width", "64", "--height", "64"];
    let one = render(&[&["render", "one.zarr", "--slice", "z=0", "--out", "s1.png"], &camera[..]].concat());
    let middle = render(&[&["render", "three.zarr", "--slice", "z=1", "--out", "s3.png"], &camera[..]].concat());
    assert!(lit(&one) > 500, "the slice alone: {} pixels lit", lit(&one));
    let largest = one.iter().zip(&middle).map(|(a, b)| a.abs_diff(*b)).max().unwrap();
    assert!(largest <= 1, "the one slice differs from the same plane of a thicker volume by {largest}");
    std::fs::remove_dir_all(&dir).ok();
}
