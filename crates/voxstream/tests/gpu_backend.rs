//! The GPU renderer (`voxstream-gpu`) against its reference, the CPU ray caster: the same scenes, cameras, settings
//! and budget, drawn by the same frame loop, must give the same images within [`GPU_PSNR_DB`]. These tests need a
//! Vulkan adapter: CI installs Mesa's lavapipe (`mesa-vulkan-drivers libvulkan1`, adapter "llvmpipe"), which runs the
//! shader on the CPU. Without one they fail, naming the packages to install (they never skip silently).
//!
//! A failing comparison writes the actual (GPU), expected (CPU) and difference images to
//! `target/gpu-test-failures/`.
#![cfg(feature = "gpu")]

mod common;

use std::path::PathBuf;

use voxstream::png_output::write_rgb8_png;
use voxstream::scenes::{builtin, SceneProducer, SCENE_NAMES};
use voxstream_core::VoxelFormat;
use voxstream_engine::{FrameRenderer, LoopLimits, Mode, Session};
use voxstream_gpu::{BrickFiltering, GpuRenderer};
use voxstream_render::{psnr, Camera, Image, RenderSettings};

/// The PSNR a GPU image must reach against the CPU image of the same frame (8-bit RGB). The two differ only by
/// rounding: f32 positions on the GPU against f64 between segments on the CPU, `exp` per sample against tables.
const GPU_PSNR_DB: f64 = 40.0;

/// Image edge of the comparisons (lavapipe runs the shader on this machine's two cores).
const SIZE: u32 = 96;

fn open_gpu() -> GpuRenderer {
    GpuRenderer::new().unwrap_or_else(|e| {
        panic!("{e}\n(the GPU tests need a Vulkan driver; CI installs Mesa's lavapipe: apt-get install mesa-vulkan-drivers libvulkan1)")
    })
}

fn settings(name: &str, size: u32) -> (RenderSettings, SceneProducer, voxstream_render::TransferFunction, Camera) {
    let scene = builtin(name).expect("built-in scene");
    let settings = RenderSettings {
        width: size,
        height: size,
        shading: scene.shading,
        light_direction: scene.light,
        ..RenderSettings::default()
    };
    (settings, scene.producer, scene.transfer_function, scene.camera)
}

fn cpu_session(name: &str, size: u32, budget: u64, limits: LoopLimits) -> Session<SceneProducer> {
    let (settings, producer, tf, _) = settings(name, size);
    Session::new(producer, &tf, settings, budget, limits).expect("cpu session")
}

fn gpu_session(name: &str, size: u32, budget: u64, limits: LoopLimits) -> Session<SceneProducer, GpuRenderer> {
    let (settings, producer, tf, _) = settings(name, size);
    Session::with_renderer(open_gpu(), producer, &tf, settings, budget, limits, [0.0, 1.0]).expect("gpu session")
}

/// Asserts PSNR ≥ [`GPU_PSNR_DB`] of `actual` (GPU) against `expected` (CPU), writing both and their difference
/// as PNGs when it fails. Returns the PSNR.
fn assert_close(label: &str, actual: &Image, expected: &Image) -> f64 {
    let (a, e) = (actual.to_rgb8(), expected.to_rgb8());
    let quality = psnr(&a, &e);
    println!("{label}: PSNR {quality:.1} dB (GPU against CPU)");
    if quality < GPU_PSNR_DB {
        let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("../gpu-test-failures");
        std::fs::create_dir_all(&dir).expect("failure folder");
        let difference: Vec<u8> = a.iter().zip(&e).map(|(&x, &y)| x.abs_diff(y).saturating_mul(8)).collect();
        for (suffix, pixels) in [("actual", &a), ("expected", &e), ("difference", &difference)] {
            let path = dir.join(format!("{label}-{suffix}.png"));
            write_rgb8_png(pixels, actual.width, actual.height, &path).expect("write failure image");
        }
        panic!("{label}: PSNR {quality:.1} dB < {GPU_PSNR_DB} dB; images in {}", dir.display());
    }
    quality
}

#[test]
fn every_builtin_scene_matches_the_cpu_image() {
    for name in SCENE_NAMES {
        let (_, _, _, camera) = settings(name, SIZE);
        let mut cpu = cpu_session(name, SIZE, 64 << 20, LoopLimits::default());
        let expected = common::converged(&mut cpu, &camera);
        let mut gpu = gpu_session(name, SIZE, 64 << 20, LoopLimits::default());
        let frame = gpu.render(&camera, Mode::Converged).expect("gpu render");
        assert!(frame.is_converged(), "{name}: the GPU frame did not converge in {} passes", frame.passes);
        assert!(expected.pixels.iter().any(|p| p[3] > 0.5), "{name}: the reference shows nothing");
        assert_close(name, &frame.image, &expected);
        // The GPU's feedback drove the same loading as the CPU's: the same bricks became resident.
        assert_eq!(gpu.residency().bricks, cpu.residency().bricks, "{name}: resident bricks differ");
    }
}

#[test]
fn a_close_view_and_a_cut_transfer_function_match_too() {
    // Deeper levels (the hypertexture close up, N = 2) and a narrow, sharp transfer function on the shell.
    let camera = Camera { eye: [0.62, 0.58, 0.95], target: [0.5, 0.5, 0.5], up: [0.0, 1.0, 0.0], fov: 30.0 };
    let mut cpu = cpu_session("hypertexture", SIZE, 64 << 20, LoopLimits::default());
    let expected = common::converged(&mut cpu, &camera);
    let mut gpu = gpu_session("hypertexture", SIZE, 64 << 20, LoopLimits::default());
    let frame = gpu.render(&camera, Mode::Converged).expect("gpu render");
    assert!(frame.is_converged());
    assert_close("hypertexture-close", &frame.image, &expected);

    let tf = voxstream_render::TransferFunction::new(
        vec![
            [0.0, 0.0, 0.0, 0.0, 0.0],
            [0.55, 0.2, 0.6, 1.0, 0.0],
            [0.6, 1.0, 0.9, 0.2, 0.8],
            [0.65, 0.1, 0.1, 0.9, 0.0],
        ],
        None,
    )
    .expect("transfer function");
    let (settings, producer, _, camera) = settings("shell", SIZE);
    let mut cpu = Session::new(producer, &tf, settings.clone(), 64 << 20, LoopLimits::default()).expect("cpu");
    let expected = common::converged(&mut cpu, &camera);
    let mut gpu =
        Session::with_renderer(open_gpu(), producer, &tf, settings, 64 << 20, LoopLimits::default(), [0.0, 1.0])
            .expect("gpu");
    let frame = gpu.render(&camera, Mode::Converged).expect("gpu render");
    assert_close("shell-cut", &frame.image, &expected);
}

#[test]
fn bricks_filtered_by_the_texture_units_or_in_the_shader_both_match_the_cpu_image() {
    // Unshaded volumes, where samples are one filtered fetch with hardware filtering (shaded samples and isosurface
    // cells read the eight corners in both modes): the shell and the hypertexture, whole and close up.
    let close = Camera { eye: [0.62, 0.58, 0.95], target: [0.5, 0.5, 0.5], up: [0.0, 1.0, 0.0], fov: 30.0 };
    for (name, close_up) in [("shell", false), ("hypertexture", false), ("hypertexture", true)] {
        let (mut settings, producer, tf, camera) = settings(name, SIZE);
        settings.shading = voxstream_render::Shading::None;
        let camera = if close_up { close } else { camera };
        let mut cpu = Session::new(producer, &tf, settings.clone(), 64 << 20, LoopLimits::default()).expect("cpu");
        let expected = common::converged(&mut cpu, &camera);
        assert!(expected.pixels.iter().any(|p| p[3] > 0.1), "{name}: the reference shows nothing");
        let mut images = Vec::new();
        for filtering in [BrickFiltering::Hardware, BrickFiltering::Exact] {
            let renderer = GpuRenderer::with_filtering(Some(filtering)).unwrap_or_else(|e| {
                panic!("{e}\n(lavapipe, which CI installs, filters R16Unorm; a GPU test needs it)")
            });
            assert_eq!(renderer.filtering(), filtering);
            assert!(renderer.describe().contains(filtering.describe()), "{}", renderer.describe());
            let mut gpu = Session::with_renderer(
                renderer,
                producer,
                &tf,
                settings.clone(),
                64 << 20,
                LoopLimits::default(),
                [0.0, 1.0],
            )
            .expect("gpu session");
            let frame = gpu.render(&camera, Mode::Converged).expect("gpu render");
            assert!(frame.is_converged(), "{name} {filtering:?}: did not converge");
            let label = format!("{name}{}-{filtering:?}", if close_up { "-close" } else { "" });
            assert_close(&label, &frame.image, &expected);
            images.push(frame.image);
        }
        // The two modes against each other: the sampler ran (the images are not the same floats: its weights are
        // rounded differently from the shader's), and it filtered the same voxels at the same places (a half-texel
        // shift of the field would cost far more than 70 dB).
        let (hardware, exact) = (&images[0], &images[1]);
        assert_ne!(hardware.pixels, exact.pixels, "{name}: hardware filtering gave the exact image: no sampler ran?");
        let quality = psnr(&hardware.to_rgb8(), &exact.to_rgb8());
        println!("{name} close={close_up}: hardware against exact {quality:.1} dB");
        assert!(quality >= 70.0, "{name}: hardware against exact filtering {quality:.1} dB < 70 dB");
    }
}

#[test]
fn interactive_frames_converge_to_the_converged_image() {
    // A few requests served per frame, no blending: detail arrives over many frames, each drawn by the GPU from
    // whatever is resident, until a frame is final.
    let limits = LoopLimits { requests_per_frame: 64, blending_fade_frames: None, ..LoopLimits::default() };
    let (_, _, _, camera) = settings("shell", SIZE);
    let mut gpu = gpu_session("shell", SIZE, 64 << 20, limits);
    let mut frames = 0;
    let last = loop {
        let frame = gpu.render(&camera, Mode::Interactive).expect("interactive frame");
        frames += 1;
        if frame.is_final() || frames >= 400 {
            break frame;
        }
    };
    assert!(last.is_final(), "not final after {frames} interactive frames");
    assert!(frames > 3, "detail should arrive over several frames, not {frames}");
    let mut cpu = cpu_session("shell", SIZE, 64 << 20, LoopLimits::default());
    let expected = common::converged(&mut cpu, &camera);
    assert_close("shell-interactive", &last.image, &expected);
}

#[test]
fn a_source_of_byte_bricks_keeps_sixteen_bit_pools_on_the_gpu() {
    // The sponge's bricks are bytes on the CPU; the GPU atlas is 16-bit, so the session plans 16-bit bricks for it
    // and the atlas stays within the budget (with byte bricks the pool would hold twice the bricks the budget has
    // room for in the atlas).
    let budget = 6 << 20;
    let (_, _, _, camera) = settings("sponge", SIZE);
    let cpu = cpu_session("sponge", SIZE, budget, LoopLimits::default());
    assert!(
        matches!(cpu.cache().brick_pool().format(), VoxelFormat::Narrow { .. }),
        "the CPU session should keep the sponge's bricks as bytes"
    );
    let mut gpu = gpu_session("sponge", SIZE, budget, LoopLimits::default());
    assert_eq!(gpu.cache().brick_pool().format(), VoxelFormat::Wide, "the GPU session's pool");
    gpu.render(&camera, Mode::Converged).expect("sponge frame");
    let pool_bytes = gpu.renderer().pool_bytes().expect("pools were uploaded");
    assert!(pool_bytes <= budget, "GPU pools of {pool_bytes} bytes exceed the budget of {budget}");
}

#[test]
fn the_gpu_pools_stay_within_the_budget_and_upload_only_changes() {
    let budget = 6 << 20;
    let (_, _, _, camera) = settings("hypertexture", SIZE);
    let mut gpu = gpu_session("hypertexture", SIZE, budget, LoopLimits::default());
    let first = gpu.render(&camera, Mode::Converged).expect("first frame");
    let pool_bytes = gpu.renderer().pool_bytes().expect("pools were uploaded");
    assert!(pool_bytes <= budget, "GPU pools of {pool_bytes} bytes exceed the budget of {budget}");
    let uploaded = gpu.renderer().total_upload();
    assert!(uploaded.bricks > 0 && uploaded.tiles > 0, "nothing was uploaded: {uploaded:?}");
    // The same view again: everything it needs is resident and already on the GPU.
    let again = gpu.render(&camera, Mode::Converged).expect("second frame");
    assert_eq!(gpu.renderer().last_upload().bytes(), 0, "an unchanged pool was uploaded again");
    assert_eq!(again.image.pixels, first.image.pixels, "the same pools and camera gave another image");
    // A new view loads new bricks; only those (and the tiles that point at them) are uploaded.
    let before = gpu.renderer().total_upload();
    let other = Camera { eye: [-0.9, 1.3, 1.6], ..camera };
    let moved = gpu.render(&other, Mode::Converged).expect("third frame");
    let after = gpu.renderer().total_upload();
    let loaded = moved.bricks_produced + moved.bricks_prefetched;
    assert!(loaded > 0, "the new view should need new bricks");
    let written = after.bricks - before.bricks;
    assert!(written > 0 && written <= loaded, "{written} brick slots uploaded for {loaded} bricks loaded");
    // A smaller budget (the viewer's budget field): the GPU pools are allocated again at the new size, never kept
    // at the old one, and the image is the same.
    let smaller = 3 << 20;
    gpu.set_pool_budget(smaller).expect("a budget the tree fits");
    let shrunk = gpu.render(&other, Mode::Converged).expect("frame at the smaller budget");
    let pool_bytes = gpu.renderer().pool_bytes().expect("pools");
    assert!(pool_bytes <= smaller, "GPU pools of {pool_bytes} bytes after the budget fell to {smaller}");
    assert_eq!(shrunk.image.pixels, moved.image.pixels, "the budget changed the image");
    // And a larger one: allocated again (uploads start over), the same image.
    let uploaded = gpu.renderer().total_upload().bricks;
    gpu.set_pool_budget(budget * 2).expect("a larger budget");
    let grown = gpu.render(&other, Mode::Converged).expect("frame at the larger budget");
    let pool_bytes = gpu.renderer().pool_bytes().expect("pools");
    assert!(pool_bytes > budget && pool_bytes <= budget * 2, "GPU pools of {pool_bytes} bytes at {}", budget * 2);
    assert!(gpu.renderer().total_upload().bricks > uploaded, "the new pools were filled");
    assert_eq!(grown.image.pixels, moved.image.pixels, "the budget changed the image");
}

#[test]
fn the_shader_counts_what_its_rays_did() {
    let (_, _, _, camera) = settings("shell", SIZE);
    let mut gpu = gpu_session("shell", SIZE, 64 << 20, LoopLimits::default());
    let frame = gpu.render(&camera, Mode::Converged).expect("gpu render");
    // Every pixel is traced in the first pass, and retraced only while it missed data.
    assert!(frame.rays >= (SIZE * SIZE) as u64, "{} rays for {} pixels", frame.rays, SIZE * SIZE);
    assert!(frame.samples > frame.rays, "{} samples for {} rays", frame.samples, frame.rays);
    assert!(frame.requests > 0, "the shell needs bricks, so the rays asked for some");
}

#[test]
fn the_command_line_names_the_adapter_or_says_why_there_is_none() {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("gpu-cli");
    std::fs::create_dir_all(&dir).expect("scratch folder");
    let (image, stats) = (dir.join("shell.png"), dir.join("shell.json"));
    let output = std::process::Command::new(env!("CARGO_BIN_EXE_voxstream"))
        .args(["render", "shell", "--backend", "gpu", "--width", "64", "--height", "64", "--quiet"])
        .arg("--out")
        .arg(&image)
        .arg("--stats")
        .arg(&stats)
        .output()
        .expect("run voxstream");
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let stats: serde_json::Value = serde_json::from_slice(&std::fs::read(&stats).expect("stats")).expect("json");
    let backend = stats["backend"].as_str().expect("backend named");
    assert!(backend.starts_with("gpu: "), "{backend}");
    assert!(stats["bytes_uploaded"].as_u64().is_some_and(|b| b > 0), "{stats}");

    // No Vulkan driver at all: one line naming the problem and the fix, exit status 1, no image.
    let missing = dir.join("missing.png");
    let output = std::process::Command::new(env!("CARGO_BIN_EXE_voxstream"))
        .args(["render", "shell", "--backend", "gpu", "--quiet"])
        .arg("--out")
        .arg(&missing)
        .env("VK_ICD_FILENAMES", dir.join("no-such-driver.json"))
        .env("VK_DRIVER_FILES", dir.join("no-such-driver.json"))
        .output()
        .expect("run voxstream");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(1), "{stderr}");
    let lines: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error: --backend gpu")).collect();
    assert_eq!(lines.len(), 1, "{stderr}");
    assert!(lines[0].contains("no GPU adapter") && lines[0].contains("--backend cpu"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(!missing.exists(), "no image without a renderer");
}

#[test]
fn the_gpu_backend_prints_no_wayland_line_and_says_when_the_adapter_is_a_cpu_emulation() {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("gpu-cli-environment");
    let _ = std::fs::remove_dir_all(&dir);
    let tmp = dir.join("tmp");
    std::fs::create_dir_all(&tmp).expect("scratch folder");
    let stats = dir.join("stats.json");
    // No XDG_RUNTIME_DIR, as under cron, ssh without a login session, or a container: Mesa's device-selection layer
    // made libwayland print "XDG_RUNTIME_DIR is invalid or not set in the environment" twice.
    let output = std::process::Command::new(env!("CARGO_BIN_EXE_voxstream"))
        .args(["render", "shell", "--backend", "gpu", "--width", "32", "--height", "32", "--quiet"])
        .arg("--out")
        .arg(dir.join("shell.png"))
        .arg("--stats")
        .arg(&stats)
        .env_remove("XDG_RUNTIME_DIR")
        .env("TMPDIR", &tmp)
        .output()
        .expect("run voxstream");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    assert!(!stderr.contains("XDG_RUNTIME_DIR"), "libwayland's line is gone: {stderr}");
    assert_eq!(std::fs::read_dir(&tmp).expect("tmp").count(), 0, "the private runtime folder is removed at exit");
    // A CPU emulation (lavapipe, "llvmpipe") is named once, with the CPU renderer suggested; a GPU is not.
    let stats: serde_json::Value = serde_json::from_slice(&std::fs::read(&stats).expect("stats")).expect("json");
    let backend = stats["backend"].as_str().expect("backend named");
    let warnings: Vec<&str> = stderr.lines().filter(|l| l.contains("CPU emulation")).collect();
    if backend.contains("(CPU emulation") {
        assert_eq!(warnings.len(), 1, "{stderr}");
        assert!(warnings[0].starts_with("warning: ") && warnings[0].ends_with("use --backend cpu"), "{stderr}");
        assert_eq!(stats["backend_warning"].as_str(), warnings[0].strip_prefix("warning: "), "{stats}");
    } else {
        assert!(warnings.is_empty(), "{backend}: {stderr}");
        assert!(stats.get("backend_warning").is_none(), "{stats}");
    }
    std::fs::remove_dir_all(&dir).expect("clean up");
}

#[test]
fn the_deep_sponge_zoom_stays_exact() {
    // Features of 3^-20 of the scene (crates/voxstream/tests/sponge_silhouette.rs checks the CPU's image against the
    // analytic Menger set there): far below f32's 2^-24 in unit-cube coordinates. The shader's positions are
    // relative to the anchor node at level 19 that holds the eye, so they stay exact; the CPU's are f64.
    let cell = 3f64.powi(-20);
    let target = [1.5 * cell, 1.5 * cell, 1.0];
    let camera = Camera {
        eye: [target[0] + 0.6 * cell, target[1] + 0.8 * cell, 1.0 + 4.0 * cell],
        target,
        up: [0.0, 1.0, 0.0],
        fov: 50.0,
    };
    let mut cpu = cpu_session("sponge", SIZE, 128 << 20, LoopLimits::default());
    let expected = common::converged(&mut cpu, &camera);
    let covered = expected.pixels.iter().filter(|p| p[3] > 0.5).count();
    let pixels = (SIZE * SIZE) as usize;
    assert!(covered > pixels / 5 && covered < pixels * 95 / 100, "the view must show solid and holes: {covered}");
    let mut gpu = gpu_session("sponge", SIZE, 128 << 20, LoopLimits::default());
    let frame = gpu.render(&camera, Mode::Converged).expect("gpu render");
    assert!(frame.is_converged());
    assert_close("sponge-deep-zoom", &frame.image, &expected);
}

#[test]
fn empty_space_skipping_takes_fewer_samples_and_changes_no_pixel() {
    // A transfer function that shows only values in (0.55, 0.65): the bricks of the shell's inside and outside
    // hold none, and are skipped.
    let tf = voxstream_render::TransferFunction::new(
        vec![
            [0.0, 0.0, 0.0, 0.0, 0.0],
            [0.55, 0.2, 0.6, 1.0, 0.0],
            [0.6, 1.0, 0.9, 0.2, 0.8],
            [0.65, 0.1, 0.1, 0.9, 0.0],
        ],
        None,
    )
    .expect("transfer function");
    let (settings, producer, _, camera) = settings("shell", SIZE);
    let render = |skip_empty_space: bool| {
        let settings = RenderSettings { skip_empty_space, ..settings.clone() };
        let mut gpu =
            Session::with_renderer(open_gpu(), producer, &tf, settings, 64 << 20, LoopLimits::default(), [0.0, 1.0])
                .expect("gpu session");
        gpu.render(&camera, Mode::Converged).expect("gpu render");
        // A warm frame: the same tree in both runs.
        gpu.render(&camera, Mode::Converged).expect("warm frame")
    };
    let (skipping, sampling_all) = (render(true), render(false));
    println!("samples: {} skipping, {} without", skipping.samples, sampling_all.samples);
    assert!(skipping.samples * 10 < sampling_all.samples * 9, "{} vs {}", skipping.samples, sampling_all.samples);
    assert_eq!(skipping.image.pixels, sampling_all.image.pixels, "skipping changed the image");
}

/// The error-bounded adaptive step (issue 46) on the GPU: the same steps as the CPU's, so the same image, with
/// fewer samples than the fixed step on the GPU itself.
#[test]
fn the_adaptive_step_matches_the_cpu_image_with_fewer_samples() {
    for name in ["shell", "hypertexture"] {
        let (settings, producer, tf, camera) = settings(name, SIZE);
        let adaptive = RenderSettings { adaptive_step: Some(0.05), ..settings.clone() };
        let mut cpu = Session::new(producer, &tf, adaptive.clone(), 64 << 20, LoopLimits::default()).expect("cpu");
        let expected = common::converged(&mut cpu, &camera);
        let gpu_frame = |settings: RenderSettings| {
            let mut gpu = Session::with_renderer(
                open_gpu(),
                producer,
                &tf,
                settings,
                64 << 20,
                LoopLimits::default(),
                [0.0, 1.0],
            )
            .expect("gpu session");
            gpu.render(&camera, Mode::Converged).expect("gpu render");
            gpu.render(&camera, Mode::Converged).expect("warm frame")
        };
        let (adapted, fixed) = (gpu_frame(adaptive), gpu_frame(settings));
        assert!(expected.pixels.iter().any(|p| p[3] > 0.5), "{name}: the reference shows nothing");
        assert_close(&format!("{name}-adaptive"), &adapted.image, &expected);
        println!("{name}: {} samples adaptive, {} fixed", adapted.samples, fixed.samples);
        // The shell's soft fog: a fraction of the samples (3.5 times fewer on the CPU at 512²); the
        // hypertexture's sharp transfer function: about as many.
        let fewer =
            if name == "shell" { adapted.samples * 2 < fixed.samples } else { adapted.samples <= fixed.samples };
        assert!(fewer, "{name}: {} vs {}", adapted.samples, fixed.samples);
    }
}

/// The isosurfaces of `name` with `surfaces`, Phong-shaded from a fixed light, `adjust`ed: the GPU's converged
/// frame against the CPU's (Knoll et al.'s exact crossings on both sides: the same cell walk, cubic and seams).
fn compare_isosurfaces(
    label: &str,
    name: &str,
    surfaces: Vec<voxstream_render::IsoSurface>,
    camera: Option<Camera>,
    adjust: impl Fn(&mut RenderSettings),
) -> (Image, Image) {
    let (mut settings, producer, tf, scene_camera) = settings(name, SIZE);
    let camera = camera.unwrap_or(scene_camera);
    settings.surfaces = surfaces;
    settings.shading = voxstream_render::Shading::Phong;
    settings.light_direction = Some([0.3, 0.8, 0.5]);
    adjust(&mut settings);
    let mut cpu = Session::new(producer, &tf, settings.clone(), 64 << 20, LoopLimits::default()).expect("cpu");
    let expected = common::converged(&mut cpu, &camera);
    let mut gpu =
        Session::with_renderer(open_gpu(), producer, &tf, settings, 64 << 20, LoopLimits::default(), [0.0, 1.0])
            .expect("gpu");
    let frame = gpu.render(&camera, Mode::Converged).expect("gpu render");
    assert!(frame.is_converged(), "{label}: the GPU frame did not converge in {} passes", frame.passes);
    let covered = expected.pixels.iter().filter(|p| p[3] > 0.3).count();
    assert!(covered > (SIZE * SIZE / 8) as usize, "{label}: the reference shows a surface in only {covered} pixels");
    let (a, e) = (frame.image.to_rgb8(), expected.to_rgb8());
    let differing = a.chunks(3).zip(e.chunks(3)).filter(|(x, y)| x.iter().zip(*y).any(|(p, q)| p.abs_diff(*q) > 16));
    println!("{label}: {} pixels differ by more than 16/255", differing.count());
    assert_close(label, &frame.image, &expected);
    // The subtrees culled while descending (never loaded) are the same on both sides.
    assert_eq!(gpu.residency().bricks, cpu.residency().bricks, "{label}: resident bricks differ");
    (frame.image, expected)
}

#[test]
fn isosurfaces_match_the_cpu_image() {
    use voxstream_render::{IsoSurface, SurfaceNormals};
    let opaque = |value| vec![IsoSurface { value, color: [0.9, 0.75, 0.65], opacity: 1.0 }];
    // The shell's density is exp(−r²): 0.5 is crossed twice (two nested spheres), 0.9 once more near the crest;
    // the outer surface is translucent, so the inner ones show through it.
    let nested = vec![
        IsoSurface { value: 0.5, color: [0.55, 0.7, 0.95], opacity: 0.4 },
        IsoSurface { value: 0.9, color: [0.95, 0.8, 0.6], opacity: 1.0 },
    ];
    compare_isosurfaces("iso-shell-nested", "shell", nested.clone(), None, |_| {});
    // The sponge seen closer, its holes several pixels wide.
    let sponge_close = Camera { eye: [0.8, 0.75, 1.6], target: [0.5, 0.5, 0.5], up: [0.0, 1.0, 0.0], fov: 30.0 };
    // The sponge's voxels are 0 or 1, so its ½ surface lies exactly on the faces of nodes, where a brick's last cell
    // and the seam into a solid constant node tie: both sides find the same hits (unshaded: the same image), but
    // f32 and f64 break the tie differently, and the seam's crossing has no gradient (shaded: 6% of the pixels
    // differ, 24 dB). Off the faces, at 0.3, the shaded images agree.
    let unshaded = |s: &mut RenderSettings| s.shading = voxstream_render::Shading::None;
    compare_isosurfaces("iso-sponge-unshaded", "sponge", opaque(0.5), Some(sponge_close), unshaded);
    compare_isosurfaces("iso-sponge", "sponge", opaque(0.3), Some(sponge_close), |_| {});
    compare_isosurfaces("iso-sponge-far", "sponge", opaque(0.3), None, |_| {});
    compare_isosurfaces("iso-hypertexture", "hypertexture", opaque(0.5), None, |_| {});
    compare_isosurfaces("iso-hypertexture-central", "hypertexture", opaque(0.5), None, |s| {
        s.surface_normals = SurfaceNormals::CentralDifferences
    });
    // Without culling, the same image: culling only skips what cannot change a ray's state.
    compare_isosurfaces("iso-shell-unculled", "shell", nested, None, |s| s.skip_empty_space = false);
}

#[test]
fn surfaces_inside_a_volume_match_the_cpu_image() {
    use voxstream_render::IsoSurface;
    // The scene's transfer function drawn around its isosurfaces, composited in depth order on both sides
    // (`SurfacesInVolume`): the volume's samples between crossings, the same steps, constant nodes integrated whole.
    let nested = vec![
        IsoSurface { value: 0.5, color: [0.55, 0.7, 0.95], opacity: 0.4 },
        IsoSurface { value: 0.9, color: [0.95, 0.8, 0.6], opacity: 1.0 },
    ];
    let inside = |s: &mut RenderSettings| s.surfaces_in_volume = true;
    let (with_volume, _) = compare_isosurfaces("iso-in-volume-shell", "shell", nested.clone(), None, inside);
    let (alone, _) = compare_isosurfaces("iso-alone-shell", "shell", nested, None, |_| {});
    let changed = with_volume.pixels.iter().zip(&alone.pixels).filter(|(a, b)| a != b).count();
    assert!(changed > (SIZE * SIZE / 8) as usize, "the volume changed only {changed} GPU pixels");
    let opaque = vec![IsoSurface { value: 0.5, color: [0.9, 0.75, 0.65], opacity: 1.0 }];
    compare_isosurfaces("iso-in-volume-hypertexture", "hypertexture", opaque.clone(), None, inside);
    // With shadows (the shadow rays see the surfaces only) and without culling.
    compare_isosurfaces("iso-in-volume-hypertexture-shadows", "hypertexture", opaque.clone(), None, |s| {
        s.surfaces_in_volume = true;
        s.shadows = true;
    });
    compare_isosurfaces("iso-in-volume-hypertexture-unculled", "hypertexture", opaque, None, |s| {
        s.surfaces_in_volume = true;
        s.skip_empty_space = false;
    });
}

#[test]
fn isosurface_shadows_match_the_cpu_image() {
    use voxstream_render::IsoSurface;
    let surfaces = vec![IsoSurface { value: 0.5, color: [0.9, 0.75, 0.65], opacity: 1.0 }];
    let (lit, _) = compare_isosurfaces("iso-hypertexture-lit", "hypertexture", surfaces.clone(), None, |_| {});
    let (shadowed, expected) =
        compare_isosurfaces("iso-hypertexture-shadows", "hypertexture", surfaces, None, |s| s.shadows = true);
    // The shadows are really drawn: some pixels darker than without them, none brighter, where the CPU has them.
    let darker = |image: &Image| {
        image.pixels.iter().zip(&lit.pixels).filter(|(a, b)| a[0] + a[1] + a[2] < b[0] + b[1] + b[2] - 0.05).count()
    };
    let (gpu_darker, cpu_darker) = (darker(&shadowed), darker(&expected));
    println!("shadowed pixels: GPU {gpu_darker}, CPU {cpu_darker}");
    assert!(cpu_darker > (SIZE * SIZE / 200) as usize, "the reference has almost no shadow: {cpu_darker} pixels");
    assert!(gpu_darker.abs_diff(cpu_darker) * 20 <= cpu_darker, "GPU {gpu_darker} vs CPU {cpu_darker} shadowed pixels");
}

#[test]
fn interactive_frames_blend_arriving_bricks_as_on_the_cpu() {
    // Thiele et al.'s level blending on the GPU (caps at brick corners, fade-in, a fading brick drawn instead of its
    // descendants). Every request is served each frame, so both backends load nearly the same bricks in the same
    // frames (a ray on a node boundary may ask for one more node in f32 than in f64). Every frame drawn from the same
    // resident bricks on both must match the CPU's, including frames with bricks fading in, and blending must change
    // the GPU's frames.
    let blending =
        |fade| LoopLimits { requests_per_frame: 1 << 20, blending_fade_frames: fade, ..LoopLimits::default() };
    let on = blending(Some(voxstream_core::DEFAULT_FADE_FRAMES));
    let (_, _, _, camera) = settings("hypertexture", SIZE);
    let mut cpu = cpu_session("hypertexture", SIZE, 64 << 20, on);
    let mut gpu = gpu_session("hypertexture", SIZE, 64 << 20, on);
    let mut unblended = gpu_session("hypertexture", SIZE, 64 << 20, blending(None));
    let (mut frames, mut compared_while_fading, mut differing_frames) = (0, 0, 0);
    loop {
        let fading = cpu.cache().view().brick_blends.iter().any(|b| !b.is_full() || !b.is_in());
        let same_bricks = cpu.residency().bricks == gpu.residency().bricks;
        let expected = cpu.render(&camera, Mode::Interactive).expect("cpu frame");
        let actual = gpu.render(&camera, Mode::Interactive).expect("gpu frame");
        let without = unblended.render(&camera, Mode::Interactive).expect("gpu frame without blending");
        if same_bricks {
            assert_close(&format!("blending-frame-{frames}"), &actual.image, &expected.image);
            compared_while_fading += fading as usize;
        } else {
            let quality = psnr(&actual.image.to_rgb8(), &expected.image.to_rgb8());
            println!("blending-frame-{frames}: PSNR {quality:.1} dB, not compared (resident bricks differ)");
        }
        differing_frames += (actual.image.pixels != without.image.pixels) as usize;
        frames += 1;
        if (expected.is_final() && actual.is_final()) || frames >= 100 {
            assert!(actual.is_final() && expected.is_final(), "not final after {frames} frames");
            break;
        }
    }
    println!(
        "{frames} frames; {compared_while_fading} compared with bricks fading in; {differing_frames} differ without"
    );
    assert!(compared_while_fading > 3, "only {compared_while_fading} compared frames had bricks fading in");
    assert!(differing_frames > 3, "blending changed only {differing_frames} GPU frames");
}

#[test]
fn interactive_isosurface_frames_blend_as_on_the_cpu() {
    // Level blending on the isosurface path: a brick still fading in stands in for its descendants (and for a
    // constant node below it) on both backends. As for volumes, frames drawn from the same resident bricks must match.
    let limits = LoopLimits {
        requests_per_frame: 1 << 20,
        blending_fade_frames: Some(voxstream_core::DEFAULT_FADE_FRAMES),
        ..LoopLimits::default()
    };
    let (mut settings, producer, tf, camera) = settings("hypertexture", SIZE);
    settings.surfaces = vec![voxstream_render::IsoSurface { value: 0.5, color: [0.9, 0.75, 0.65], opacity: 1.0 }];
    settings.shading = voxstream_render::Shading::Phong;
    settings.light_direction = Some([0.3, 0.8, 0.5]);
    let mut cpu = Session::new(producer, &tf, settings.clone(), 64 << 20, limits).expect("cpu");
    let mut gpu =
        Session::with_renderer(open_gpu(), producer, &tf, settings, 64 << 20, limits, [0.0, 1.0]).expect("gpu");
    let (mut frames, mut compared_while_fading) = (0, 0);
    loop {
        let fading = cpu.cache().view().brick_blends.iter().any(|b| !b.is_in());
        let same_bricks = cpu.residency().bricks == gpu.residency().bricks;
        let expected = cpu.render(&camera, Mode::Interactive).expect("cpu frame");
        let actual = gpu.render(&camera, Mode::Interactive).expect("gpu frame");
        if same_bricks {
            assert_close(&format!("iso-blending-frame-{frames}"), &actual.image, &expected.image);
            compared_while_fading += fading as usize;
        }
        frames += 1;
        if (expected.is_final() && actual.is_final()) || frames >= 100 {
            assert!(actual.is_final() && expected.is_final(), "not final after {frames} frames");
            break;
        }
    }
    println!("{frames} frames; {compared_while_fading} compared with a brick still fading in");
    assert!(compared_while_fading > 2, "only {compared_while_fading} compared frames had a brick fading in");
}
