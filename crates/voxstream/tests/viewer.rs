//! The viewer end to end, in a real X server (Xvfb) with Mesa's software OpenGL: a scripted session on a store
//! rotates the view and edits the transfer function, and the saved camera and transfer function reproduce its
//! images byte for byte with `voxstream render`; a real pointer drag (xdotool) turns the camera while the window
//! keeps answering; Esc, Ctrl+Q and SIGTERM close it with `--stats` written; errors are `render`'s, one line, before
//! any window.
//!
//! Needs `xvfb-run` and `xdotool` (Debian: `apt-get install xvfb xauth xdotool libgl1-mesa-dri`); `.ci/run` installs
//! them.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn voxstream(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_voxstream")).args(args).current_dir(dir).output().expect("run voxstream")
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("voxstream-viewer-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn require(tool: &str) {
    let found =
        Command::new("sh").args(["-c", &format!("command -v {tool}")]).output().is_ok_and(|o| o.status.success());
    assert!(
        found,
        "{tool} is needed for the viewer tests (Debian: apt-get install xvfb xauth xdotool libgl1-mesa-dri)"
    );
}

/// A 48×40×36 u16 NRRD: a large ball and a small one off to the side, so that turning the view changes the image.
fn write_two_balls(path: &Path) {
    common::write_nrrd(path, [48, 40, 36], "1 1 1", |i, j, k| {
        let ball = |c: [f64; 3], r: f64| {
            let d = ((i as f64 - c[0]).powi(2) + (j as f64 - c[1]).powi(2) + (k as f64 - c[2]).powi(2)).sqrt() / r;
            if d < 1.0 {
                1.0 - d * d
            } else {
                0.0
            }
        };
        (3000.0 * ball([18.0, 20.0, 18.0], 13.0) + 4000.0 * ball([38.0, 12.0, 26.0], 7.0)) as u16
    });
}

fn store(dir: &Path) -> PathBuf {
    write_two_balls(&dir.join("balls.nrrd"));
    let out = voxstream(&["import", "balls.nrrd", "--out", "balls.zarr", "--quiet"], dir);
    assert!(out.status.success(), "import: {}", String::from_utf8_lossy(&out.stderr));
    dir.join("balls.zarr")
}

fn pixels(path: &Path) -> Vec<u8> {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buffer = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buffer).unwrap();
    buffer.truncate(info.buffer_size());
    buffer
}

fn mean_difference(a: &[u8], b: &[u8]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(&x, &y)| (x as f64 - y as f64).abs()).sum::<f64>() / a.len() as f64
}

/// `voxstream render balls.zarr` at the viewer tests' 160×120 with `args`, into `out` (in `dir`): its pixels.
fn render_balls(dir: &Path, args: &[&str], out: &str) -> Vec<u8> {
    let mut all = vec!["render", "balls.zarr", "--width", "160", "--height", "120", "--out", out, "--quiet"];
    all.extend_from_slice(args);
    let result = voxstream(&all, dir);
    assert!(result.status.success(), "render {args:?}: {}", String::from_utf8_lossy(&result.stderr));
    pixels(&dir.join(out))
}

fn camera(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// Yaw and pitch (degrees) of a camera's eye around its target, about +z (the up axis of store views).
fn yaw_pitch(c: &serde_json::Value) -> (f64, f64) {
    assert_eq!(c["up"], serde_json::json!([0.0, 0.0, 1.0]), "store views have +z up");
    let v: Vec<f64> = (0..3).map(|i| c["eye"][i].as_f64().unwrap() - c["target"][i].as_f64().unwrap()).collect();
    let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
    (v[1].atan2(v[0]).to_degrees(), (v[2] / n).asin().to_degrees())
}

/// The change of yaw and pitch from camera `a` to camera `b`, yaw wrapped into (−180°, 180°].
fn turn(a: &serde_json::Value, b: &serde_json::Value) -> (f64, f64) {
    let ((yaw_a, pitch_a), (yaw_b, pitch_b)) = (yaw_pitch(a), yaw_pitch(b));
    let mut yaw = yaw_b - yaw_a;
    while yaw > 180.0 {
        yaw -= 360.0;
    }
    while yaw <= -180.0 {
        yaw += 360.0;
    }
    (yaw, pitch_b - pitch_a)
}

fn under_xvfb(dir: &Path, command: &str) -> Output {
    Command::new("xvfb-run")
        .args(["-a", "-s", "-screen 0 1280x900x24", "bash", "-c", command])
        .current_dir(dir)
        .output()
        .expect("run xvfb-run")
}

#[test]
fn a_scripted_session_rotates_edits_and_saves_what_render_reproduces() {
    require("xvfb-run");
    let dir = scratch("script");
    store(&dir);
    std::fs::write(
        dir.join("session.txt"),
        "wait-final 600\nscreenshot a.png\nsave-camera a.json\nsave-tf tf-a.json\n\
         orbit 40 10\nwait-final 600\nscreenshot b.png\nsave-camera b.json\n\
         tf-point 1500 1 0.1 0.1 0.4\nwait-final 600\nscreenshot c.png\nsave-tf tf-c.json\n\
         levels on\nwait-final 600\nscreenshot levels.png\nlevels off\n\
         iso 1500\nwait-final 600\nscreenshot d.png\n\
         iso-volume on\nwait-final 600\nscreenshot d-volume.png\nquit\n",
    )
    .unwrap();
    let viewer = env!("CARGO_BIN_EXE_voxstream");
    let out = under_xvfb(
        &dir,
        &format!("{viewer} view balls.zarr --width 160 --height 120 --budget-mb 64 --script session.txt"),
    );
    assert!(
        out.status.success(),
        "viewer: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let (a, b, c) = (pixels(&dir.join("a.png")), pixels(&dir.join("b.png")), pixels(&dir.join("c.png")));
    assert_eq!(a.len(), 160 * 120 * 3, "screenshots are at the render size");
    assert!(a.iter().any(|&v| v > 20), "the volume is visible");
    assert!(mean_difference(&a, &b) > 1.0, "the orbit changed the image");
    assert!(mean_difference(&b, &c) > 1.0, "the transfer-function edit changed the image");
    // The camera turned as the script said: 40° about the up axis and 10° towards it.
    let (yaw, pitch) = turn(&camera(&dir.join("a.json")), &camera(&dir.join("b.json")));
    assert!((yaw - 40.0).abs() < 1e-6 && (pitch - 10.0).abs() < 1e-6, "turned by yaw {yaw}°, pitch {pitch}°");
    // `render` with the saved files draws the same bytes.
    for (image, camera, tf) in
        [("a", "a.json", "tf-a.json"), ("b", "b.json", "tf-a.json"), ("c", "b.json", "tf-c.json")]
    {
        let rendered = render_balls(&dir, &["--camera", camera, "--tf", tf], &format!("render-{image}.png"));
        assert_eq!(
            rendered,
            pixels(&dir.join(format!("{image}.png"))),
            "the viewer's final image {image} and render's differ"
        );
    }
    // The level overlay is `render --colour-by-level`'s image, and not the plain one.
    let rendered_levels =
        render_balls(&dir, &["--camera", "b.json", "--tf", "tf-c.json", "--colour-by-level"], "render-levels.png");
    let levels = pixels(&dir.join("levels.png"));
    assert_eq!(rendered_levels, levels, "the viewer's level colours and render's differ");
    assert!(mean_difference(&c, &levels) > 1.0, "the level overlay did not change the image");
    // The isosurface is the same integrand of the same loop as `render --iso`.
    let rendered_iso =
        render_balls(&dir, &["--camera", "b.json", "--iso", "1500", "--iso-color", "0.9,0.8,0.7"], "render-d.png");
    assert_eq!(rendered_iso, pixels(&dir.join("d.png")), "the viewer's isosurface and render's differ");
    assert!(mean_difference(&c, &pixels(&dir.join("d.png"))) > 1.0, "the isosurface replaced the volume");
    // And inside the volume: `render --iso … --tf …`.
    let rendered_inside = render_balls(
        &dir,
        &["--camera", "b.json", "--iso", "1500", "--iso-color", "0.9,0.8,0.7", "--tf", "tf-c.json"],
        "render-d-volume.png",
    );
    let inside = pixels(&dir.join("d-volume.png"));
    assert_eq!(rendered_inside, inside, "the viewer's surface inside the volume and render's differ");
    assert!(
        mean_difference(&pixels(&dir.join("d.png")), &inside) > 1.0,
        "the volume around the surface changed nothing"
    );
    // Refined by blended interactive frames instead of converged passes: the same final image.
    std::fs::write(dir.join("blended.txt"), "orbit 40 10\nwait-final 600\nscreenshot e.png\nquit\n").unwrap();
    let out = under_xvfb(
        &dir,
        &format!(
            "{viewer} view balls.zarr --width 160 --height 120 --budget-mb 64 --refine blended --script blended.txt"
        ),
    );
    assert!(out.status.success(), "viewer --refine blended: {}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(
        pixels(&dir.join("e.png")),
        pixels(&dir.join("render-b.png")),
        "blended refinement ends at render's image"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_pointer_drag_turns_the_camera_while_frames_render_in_the_background() {
    require("xvfb-run");
    require("xdotool");
    let dir = scratch("drag");
    store(&dir);
    // The script saves the camera once the first image is final, waits while xdotool drags, then saves it again.
    std::fs::write(
        dir.join("session.txt"),
        "wait-final 600\nsave-camera before.json\nwait 8\nwait-final 600\nsave-camera after.json\nscreenshot after.png\nquit\n",
    )
    .unwrap();
    let viewer = env!("CARGO_BIN_EXE_voxstream");
    let harness = format!(
        r#"{viewer} view balls.zarr --width 320 --height 240 --budget-mb 64 --script session.txt & pid=$!
for i in $(seq 600); do [ -f before.json ] && break; sleep 0.1; done
[ -f before.json ] || {{ echo "the first image never became final"; kill $pid; exit 1; }}
window=$(xdotool search --sync --name "voxstream view" | head -1)
xdotool windowactivate --sync $window 2>/dev/null || true
eval $(xdotool getwindowgeometry --shell $window)
x=$((X + 100)); y=$((Y + HEIGHT / 2))
xdotool mousemove $x $y mousedown 1
for step in $(seq 1 20); do xdotool mousemove $((x + step * 5)) $y; sleep 0.02; done
xdotool mouseup 1
wait $pid"#
    );
    let out = under_xvfb(&dir, &harness);
    assert!(
        out.status.success(),
        "viewer: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    // 100 pixels dragged to the right at 0.4° per point: the eye goes about 40° the other way about the up axis (the
    // first pixels start the drag), and no pitch.
    let (yaw, pitch) = turn(&camera(&dir.join("before.json")), &camera(&dir.join("after.json")));
    assert!(
        (-45.0..-25.0).contains(&yaw) && pitch.abs() < 1e-9,
        "the drag turned the camera by yaw {yaw}°, pitch {pitch}°"
    );
    assert_eq!(pixels(&dir.join("after.png")).len(), 320 * 240 * 3, "the full-size image came back after the drag");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn view_errors_are_one_line_before_any_window() {
    let dir = scratch("errors");
    // A broken script names its line, without a display.
    std::fs::write(dir.join("bad.txt"), "wait-final\norbt 30 0\n").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_voxstream"))
        .args(["view", "shell", "--script", "bad.txt"])
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .current_dir(&dir)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr.contains("bad.txt line 2: unknown command `orbt`"), "{stderr}");
    assert_eq!(stderr.trim_end().lines().count(), 1, "{stderr}");
    // A missing store: the same message as render's.
    let view = Command::new(env!("CARGO_BIN_EXE_voxstream"))
        .args(["view", "missing.zarr"])
        .env_remove("DISPLAY")
        .current_dir(&dir)
        .output()
        .unwrap();
    let render = voxstream(&["render", "missing.zarr"], &dir);
    assert_eq!(view.status.code(), Some(1));
    let first_line = |o: &Output| String::from_utf8_lossy(&o.stderr).lines().next().unwrap_or("").to_string();
    assert_eq!(first_line(&view), first_line(&render));
    // No display: one line saying what to do.
    let out = Command::new(env!("CARGO_BIN_EXE_voxstream"))
        .args(["view", "shell"])
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .current_dir(&dir)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr.contains("no display") && stderr.contains("xvfb-run"), "{stderr}");
    // A malformed transfer function: render's message.
    std::fs::write(dir.join("tf.json"), "{\"points\": [[0, 0, 0]]}").unwrap();
    let view = Command::new(env!("CARGO_BIN_EXE_voxstream"))
        .args(["view", "shell", "--tf", "tf.json"])
        .env_remove("DISPLAY")
        .current_dir(&dir)
        .output()
        .unwrap();
    let render = voxstream(&["render", "shell", "--tf", "tf.json"], &dir);
    assert_eq!(view.status.code(), Some(1));
    assert_eq!(first_line(&view), first_line(&render));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// PSNR (dB) of `actual` against `expected`, 8-bit channels.
fn psnr(actual: &[u8], expected: &[u8]) -> f64 {
    assert_eq!(actual.len(), expected.len());
    let mse =
        actual.iter().zip(expected).map(|(&a, &b)| (a as f64 - b as f64).powi(2)).sum::<f64>() / actual.len() as f64;
    if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (255.0f64 * 255.0 / mse).log10()
    }
}

#[test]
fn with_the_gpu_backend_the_viewer_shows_what_render_on_the_gpu_draws() {
    require("xvfb-run");
    let dir = scratch("gpu");
    store(&dir);
    std::fs::write(
        dir.join("session.txt"),
        "orbit 40 10\nwait-final 600\nscreenshot b.png\nsave-camera b.json\nsave-tf tf-b.json\n\
         iso 1500\nwait-final 600\nscreenshot d.png\nquit\n",
    )
    .unwrap();
    let viewer = env!("CARGO_BIN_EXE_voxstream");
    let out = under_xvfb(
        &dir,
        &format!(
            "env -u XDG_RUNTIME_DIR {viewer} view balls.zarr --width 160 --height 120 --budget-mb 64 --backend gpu \
             --script session.txt --stats stats.json"
        ),
    );
    // No libwayland line about XDG_RUNTIME_DIR (Mesa's device-selection layer looked for a compositor).
    assert!(
        !String::from_utf8_lossy(&out.stderr).contains("XDG_RUNTIME_DIR"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        out.status.success(),
        "viewer --backend gpu: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let stats = camera(&dir.join("stats.json"));
    let renderer = stats["renderer"].as_str().unwrap_or("");
    assert!(renderer.starts_with("gpu:"), "the frame log names the GPU renderer: {renderer}");
    // A CPU emulation (lavapipe) is warned of, in the log as on stderr; a GPU is not.
    let warning = stats["renderer_warning"].as_str();
    assert_eq!(warning.is_some(), renderer.contains("(CPU emulation"), "{stats}");
    if let Some(warning) = warning {
        assert!(String::from_utf8_lossy(&out.stderr).contains(&format!("warning: {warning}")), "on stderr too");
    }
    // `render` on either backend with the saved camera and transfer function.
    let render = |backend: &str, iso: bool, out: &str| {
        let what: &[&str] = if iso { &["--iso", "1500", "--iso-color", "0.9,0.8,0.7"] } else { &["--tf", "tf-b.json"] };
        render_balls(&dir, &[&["--camera", "b.json", "--backend", backend], what].concat(), out)
    };
    let (volume, surface) = (pixels(&dir.join("b.png")), pixels(&dir.join("d.png")));
    assert!(volume.iter().any(|&v| v > 20), "the volume is visible");
    assert!(mean_difference(&volume, &surface) > 1.0, "the isosurface replaced the volume");
    // The same renderer over the same loop: the same bytes as `render --backend gpu`.
    assert_eq!(render("gpu", false, "gpu-b.png"), volume, "the viewer's GPU volume and render's differ");
    assert_eq!(render("gpu", true, "gpu-d.png"), surface, "the viewer's GPU isosurface and render's differ");
    // And the CPU image is its reference, as in the GPU backend's tests (40 dB).
    for (image, iso, name) in [(&volume, false, "cpu-b.png"), (&surface, true, "cpu-d.png")] {
        let db = psnr(image, &render("cpu", iso, name));
        assert!(db >= 40.0, "{name}: the viewer's GPU image is {db:.1} dB from the CPU's");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_budget_set_from_the_window_holds_and_leaves_the_image_as_render_draws_it() {
    require("xvfb-run");
    let dir = scratch("budget");
    store(&dir);
    std::fs::write(
        dir.join("session.txt"),
        "wait-final 600\nbudget 3\nwait-final 600\nscreenshot small.png\nsave-camera small.json\n\
         window-screenshot window.png\nquit\n",
    )
    .unwrap();
    let viewer = env!("CARGO_BIN_EXE_voxstream");
    let out = under_xvfb(
        &dir,
        &format!(
            "{viewer} view balls.zarr --width 160 --height 120 --budget-mb 64 --script session.txt --stats stats.json"
        ),
    );
    assert!(out.status.success(), "viewer: {}", String::from_utf8_lossy(&out.stderr));
    let stats = camera(&dir.join("stats.json"));
    let frames = stats["frames"].as_array().expect("frame log");
    let (first, last) = (&frames[0], &frames[frames.len() - 1]);
    assert!(first["budget_bytes"].as_u64().unwrap() > 3 << 20, "the session started at --budget-mb's share");
    assert_eq!(last["budget_bytes"].as_u64(), Some(3 << 20), "the last frame ran within the new budget");
    let resident = last["resident_bytes"].as_u64().unwrap();
    assert!(resident > 0 && resident <= 3 << 20, "resident {resident} bytes");
    assert_eq!(last["final"], serde_json::json!(true));
    // The pools refilled within the new budget; the image is still the one `render` draws.
    let rendered = render_balls(&dir, &["--camera", "small.json"], "r.png");
    assert_eq!(rendered, pixels(&dir.join("small.png")), "the image changed with the budget");
    // The whole window as drawn: larger than the image (the panels and the status line), and not blank.
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(dir.join("window.png")).unwrap()));
    let info = decoder.read_info().unwrap().info().clone();
    assert!(info.width > 160 + 200 && info.height > 120, "window {}x{}", info.width, info.height);
    let window = pixels(&dir.join("window.png"));
    assert!(window.iter().any(|&v| v > 200) && window.iter().any(|&v| v < 50), "the window capture is blank");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn esc_ctrl_q_and_sigterm_close_the_window_and_write_the_stats() {
    require("xvfb-run");
    require("xdotool");
    let dir = scratch("close");
    store(&dir);
    // The script only waits for the first final image and says so; then the window stays open until closed.
    std::fs::write(dir.join("session.txt"), "wait-final 600\nsave-camera ready.json\n").unwrap();
    let viewer = env!("CARGO_BIN_EXE_voxstream");
    for (name, close) in [
        ("escape", "xdotool windowfocus --sync $window; xdotool key Escape"),
        ("ctrl-q", "xdotool windowfocus --sync $window; xdotool key ctrl+q"),
        ("sigterm", "kill -TERM $pid"),
    ] {
        let _ = std::fs::remove_file(dir.join("ready.json"));
        let harness = format!(
            r#"{viewer} view balls.zarr --width 160 --height 120 --budget-mb 64 --script session.txt --stats {name}.json & pid=$!
for i in $(seq 600); do [ -f ready.json ] && break; sleep 0.1; done
[ -f ready.json ] || {{ echo "the first image never became final"; kill -KILL $pid; exit 1; }}
window=$(xdotool search --sync --name "voxstream view" | head -1)
{close}
for i in $(seq 300); do kill -0 $pid 2>/dev/null || break; sleep 0.1; done
kill -0 $pid 2>/dev/null && {{ echo "the window is still open 30 s later"; kill -KILL $pid; exit 1; }}
wait $pid"#
        );
        let out = under_xvfb(&dir, &harness);
        assert!(
            out.status.success(),
            "{name}: {}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        // The frame log of a normal close: every frame up to the final one.
        let stats = camera(&dir.join(format!("{name}.json")));
        let frames = stats["frames"].as_array().map_or(0, Vec::len);
        assert!(frames > 0 && stats["first_final_ms"].is_number(), "{name}: {stats}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Issue 42 item 9 in the viewer: `view --color-bar --scale-bar` draws over its frames the bars `render` draws, and a
/// script's screenshot (the image as shown) is `render`'s image with the same camera, transfer function and flags.
#[test]
fn the_viewer_draws_the_bars_render_draws() {
    require("xvfb-run");
    let dir = scratch("bars");
    store(&dir);
    std::fs::write(
        dir.join("bars.txt"),
        "wait-final 600\nscreenshot a.png\nsave-camera a.json\nsave-tf tf.json\nquit\n",
    )
    .unwrap();
    let viewer = env!("CARGO_BIN_EXE_voxstream");
    let out = under_xvfb(
        &dir,
        &format!(
            "{viewer} view balls.zarr --width 160 --height 120 --budget-mb 64 --color-bar --scale-bar --script bars.txt"
        ),
    );
    assert!(out.status.success(), "viewer: {}", String::from_utf8_lossy(&out.stderr));
    let shown = pixels(&dir.join("a.png"));
    let rendered =
        render_balls(&dir, &["--camera", "a.json", "--tf", "tf.json", "--color-bar", "--scale-bar"], "render-bars.png");
    assert_eq!(shown, rendered, "the viewer's bars and render's differ");
    let plain = render_balls(&dir, &["--camera", "a.json", "--tf", "tf.json"], "render-plain.png");
    assert!(mean_difference(&plain, &shown) > 0.5, "no bars were drawn");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Issue 42 items 7 and 8 in the viewer: with `--projection max`, a clipping plane, a slice alone and a slice drawn
/// with the volume, each script's screenshot (the image as shown) is `render`'s image with the same camera, transfer
/// function and flags.
#[test]
fn the_viewer_draws_projections_planes_and_slices_as_render_does() {
    require("xvfb-run");
    let dir = scratch("tools");
    store(&dir);
    let viewer = env!("CARGO_BIN_EXE_voxstream");
    let cases: [&[&str]; 4] = [
        &["--projection", "max"],
        &["--clip-plane", "20,0,0,1,0,0"],
        &["--slice", "z=18"],
        &["--slice", "z=18", "--with-volume"],
    ];
    let mut images = Vec::new();
    for (n, flags) in cases.iter().enumerate() {
        let script = format!("wait-final 600\nscreenshot v{n}.png\nsave-camera c{n}.json\nsave-tf t{n}.json\nquit\n");
        std::fs::write(dir.join(format!("s{n}.txt")), script).unwrap();
        let command = format!(
            "{viewer} view balls.zarr --width 160 --height 120 --budget-mb 64 {} --script s{n}.txt",
            flags.join(" ")
        );
        let out = under_xvfb(&dir, &command);
        assert!(out.status.success(), "viewer {flags:?}: {}", String::from_utf8_lossy(&out.stderr));
        let shown = pixels(&dir.join(format!("v{n}.png")));
        let (camera, tf) = (format!("c{n}.json"), format!("t{n}.json"));
        let args = [&["--camera", camera.as_str(), "--tf", tf.as_str()][..], flags].concat();
        let rendered = render_balls(&dir, &args, &format!("r{n}.png"));
        assert_eq!(shown, rendered, "{flags:?}: the viewer's image and render's differ");
        images.push(shown);
    }
    // Four different pictures: each flag changed what was drawn.
    for a in 0..images.len() {
        for b in a + 1..images.len() {
            assert!(mean_difference(&images[a], &images[b]) > 0.5, "{:?} and {:?} draw alike", cases[a], cases[b]);
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
