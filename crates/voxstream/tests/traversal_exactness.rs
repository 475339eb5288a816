//! The traversal's promises, checked on whole frames: skipping empty space changes no bit of the image, the image is
//! the same whatever the number of threads and the instruction set the CPU offers, and descents that start from the
//! last ray's nodes find what descents from the root find.

mod common;

use glam::DVec3;
use voxstream::scenes::builtin;
use voxstream_core::{BrickSlot, FeedbackBuffer, Request, TileId, TreeView};
use voxstream_engine::{LoopLimits, Mode, Session};
use voxstream_render::{
    render_pass, Camera, Image, InstructionSet, IsoSurface, PassInputs, ProgressiveImage, RayLoopBuild, RayStats,
    RenderSettings, Shading, TransferLut,
};

const SIZE: u32 = 64;

/// A converged frame of a built-in scene and the samples it took.
fn render(scene_name: &str, skip_empty_space: bool, threads: usize) -> (Image, u64) {
    render_with(scene_name, threads, |settings| settings.skip_empty_space = skip_empty_space)
}

/// A converged frame of a built-in scene with its own settings changed by `adjust`, and the samples it took.
fn render_with(scene_name: &str, threads: usize, adjust: impl FnOnce(&mut RenderSettings)) -> (Image, u64) {
    let scene = builtin(scene_name).expect("built-in scene");
    let mut settings = RenderSettings {
        width: SIZE,
        height: SIZE,
        shading: scene.shading,
        light_direction: scene.light,
        ..RenderSettings::default()
    };
    adjust(&mut settings);
    let camera = scene.camera;
    let mut session =
        Session::new(scene.producer, &scene.transfer_function, settings, 256 << 20, LoopLimits::default())
            .expect("session");
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("thread pool");
    let result = pool.install(|| session.render(&camera, Mode::Converged)).expect("render");
    assert!(result.is_converged(), "{scene_name}: not converged");
    (result.image, result.samples)
}

#[test]
fn skipping_empty_space_changes_no_bit() {
    // The sponge's bricks are all visible (its empty space is constant nodes): only the image is compared there.
    for (scene, has_hidden_blocks) in [("shell", true), ("hypertexture", true), ("sponge", false)] {
        let (skipped, samples_skipping) = render(scene, true, 2);
        let (marched, samples_marching) = render(scene, false, 2);
        let covered = marched.pixels.iter().filter(|p| p[3] > 0.01).count();
        assert!(covered > (SIZE * SIZE / 10) as usize, "{scene}: only {covered} pixels show anything");
        let differing = skipped.pixels.iter().zip(&marched.pixels).filter(|(a, b)| a != b).count();
        assert_eq!(differing, 0, "{scene}: {differing} pixels differ with skipping on");
        println!("{scene}: {samples_skipping} samples with skipping, {samples_marching} without");
        if has_hidden_blocks {
            assert!(samples_skipping < samples_marching, "{scene}: skipping skipped nothing");
        }
    }
}

#[test]
fn the_image_does_not_depend_on_the_thread_count() {
    for scene in ["shell", "sponge"] {
        let (one, _) = render(scene, true, 1);
        let (three, _) = render(scene, true, 3);
        assert!(one.pixels == three.pixels, "{scene}: 1 and 3 threads give different images");
    }
}

#[test]
fn the_image_does_not_depend_on_the_instruction_set() {
    println!("this CPU: {}", InstructionSet::detected());
    // Which build of the ray loop each setting runs: the baseline one always for `Baseline`; for `Detect`, the
    // x86-64-v3 one exactly where this CPU has what pulp's V3 needs (checked here independently of pulp).
    #[cfg(target_arch = "x86_64")]
    let v3 = std::is_x86_feature_detected!("sse4.2")
        && std::is_x86_feature_detected!("popcnt")
        && std::is_x86_feature_detected!("avx")
        && std::is_x86_feature_detected!("avx2")
        && std::is_x86_feature_detected!("bmi1")
        && std::is_x86_feature_detected!("bmi2")
        && std::is_x86_feature_detected!("fma")
        && std::is_x86_feature_detected!("lzcnt");
    #[cfg(not(target_arch = "x86_64"))]
    let v3 = false;
    let expected = if v3 { RayLoopBuild::X86_64V3 } else { RayLoopBuild::Baseline };
    assert_eq!(InstructionSet::Detect.build(), expected, "the detected instruction set runs the wrong build");
    assert_eq!(InstructionSet::Baseline.build(), RayLoopBuild::Baseline, "the baseline runs another build");
    assert_eq!(InstructionSet::Detect.gathers(), v3, "gathers follow the build");
    assert!(!InstructionSet::Baseline.gathers(), "the baseline never gathers");
    for scene in ["shell", "sponge", "hypertexture"] {
        let (detected, _) = render_with(scene, 2, |s| s.instruction_set = InstructionSet::Detect);
        let (baseline, _) = render_with(scene, 2, |s| s.instruction_set = InstructionSet::Baseline);
        assert!(detected.pixels == baseline.pixels, "{scene}: the baseline and detected instruction sets differ");
    }
}

#[test]
fn samples_taken_in_batches_equal_samples_taken_one_by_one() {
    // The shell is unshaded with bricks of 16³ (long runs); the hypertexture is shaded (gradients), blended across
    // levels.
    for scene in ["shell", "hypertexture"] {
        let (batched, samples_batched) = render_with(scene, 2, |s| s.sample_batches = true);
        let (single, samples_single) = render_with(scene, 2, |s| s.sample_batches = false);
        assert_eq!(samples_batched, samples_single, "{scene}: the sample counts differ");
        assert!(batched.pixels == single.pixels, "{scene}: batched and single samples give different images");
    }
}

#[test]
fn rays_traced_side_by_side_equal_rays_traced_one_by_one() {
    // Unshaded, brick segments go through the lanes: the shell (16³ bricks), and the sponge and the level-blended
    // hypertexture with their shading off (the hypertexture's blended segments are marched by their lane alone, so
    // its rays mix both). Shaded, every segment is marched by its lane alone: the hypertexture as it is. With and
    // without empty-space skipping, whose checks the lanes make for themselves.
    for (scene, unshaded) in [("shell", true), ("sponge", true), ("hypertexture", true), ("hypertexture", false)] {
        for skip in [true, false] {
            let render_packets = |packets: bool| {
                render_with(scene, 2, |s| {
                    s.ray_packets = packets;
                    s.skip_empty_space = skip;
                    if unshaded {
                        s.shading = Shading::None;
                    }
                })
            };
            let ((packets, samples_packets), (single, samples_single)) = (render_packets(true), render_packets(false));
            let case = format!("{scene} (unshaded {unshaded}, skipping {skip})");
            assert_eq!(samples_packets, samples_single, "{case}: the sample counts differ");
            let covered = single.pixels.iter().filter(|p| p[3] > 0.01).count();
            assert!(covered > (SIZE * SIZE / 10) as usize, "{case}: only {covered} pixels show anything");
            let differing = packets.pixels.iter().zip(&single.pixels).filter(|(a, b)| a != b).count();
            assert_eq!(differing, 0, "{case}: {differing} pixels differ with ray packets");
        }
    }
}

#[test]
fn block_bits_give_the_image_of_the_range_tests() {
    // The samples found from block bits, eight at a time, against the range test of each block as a ray enters
    // it: the shell (16³ bricks, blocks hidden by its transfer function), the hypertexture shaded (level-blended
    // segments keep the range tests, so its rays mix both) and unshaded, rays side by side and one by one. Both take
    // the samples whose cells lie in blocks that can contribute; the range tests could also take one just past a
    // block's exit where the `f32` position rounds into the next block (it would add nothing), which these scenes
    // never meet, so the sample counts are equal too (and differ if a sample is located in a neighbouring block).
    for (scene, unshaded) in [("shell", true), ("hypertexture", false), ("hypertexture", true)] {
        for packets in [true, false] {
            let render_bits = |bits: bool| {
                render_with(scene, 2, |s| {
                    s.block_visibility_bits = bits;
                    s.ray_packets = packets;
                    if unshaded {
                        s.shading = Shading::None;
                    }
                })
            };
            let ((bits, samples_bits), (ranges, samples_ranges)) = (render_bits(true), render_bits(false));
            let case = format!("{scene} (unshaded {unshaded}, packets {packets})");
            println!("{case}: {samples_bits} samples with bits, {samples_ranges} with range tests");
            assert_eq!(samples_bits, samples_ranges, "{case}: the sample counts differ");
            let covered = ranges.pixels.iter().filter(|p| p[3] > 0.01).count();
            assert!(covered > (SIZE * SIZE / 10) as usize, "{case}: only {covered} pixels show anything");
            let differing = bits.pixels.iter().zip(&ranges.pixels).filter(|(a, b)| a != b).count();
            assert_eq!(differing, 0, "{case}: {differing} pixels differ with block bits");
        }
    }
}

/// What one pass of a frame produces: the image, which pixels are still pending, the counters, the raw request
/// count, the requests (sorted) and the feedback's marks.
type PassOutcome = (ProgressiveImage, RayStats, usize, Vec<Request>, Vec<TileId>, Vec<BrickSlot>);

/// One pass through `view` from `camera`, with a fresh feedback buffer.
fn one_pass(view: TreeView<'_>, camera: &Camera, lut: &TransferLut, settings: &RenderSettings) -> PassOutcome {
    let mut feedback = FeedbackBuffer::new(view.capacity.tiles, view.capacity.bricks);
    let mut progressive = ProgressiveImage::new(settings.width, settings.height);
    let (stats, raw_requests) =
        render_pass(PassInputs { view, feedback: &feedback, camera, lut, settings }, &mut progressive).expect("pass");
    let mut requests = feedback.take_requests();
    requests.sort();
    let (tiles, bricks) = (feedback.used_tiles().collect(), feedback.used_bricks().collect());
    (progressive, stats, raw_requests, requests, tiles, bricks)
}

#[test]
fn rays_that_keep_their_neighbours_descents_equal_rays_that_start_at_the_root() {
    // Each case renders the resident tree twice per camera, with the lanes' descent paths kept from ray to ray and
    // with every ray starting at the root, and compares everything a pass produces: the image, the pixels still
    // pending, the counters, the requests and the feedback's marks. The cameras: the scene's own view once
    // converged, a closer one whose finer nodes are missing or not subdivided (requests), and, for the blending
    // case, the scene's view after a few interactive frames, while bricks are still fading in (level blending's
    // stand-ins). Only the nodes entered may differ: fewer where N is a power of two, the same for the sponge (N = 3,
    // whose rays always start at the root).
    struct Case {
        scene: &'static str,
        iso: Option<f64>,
        in_volume: bool,
        packets: bool,
        blending: bool,
    }
    let case = |scene, iso, in_volume, packets, blending| Case { scene, iso, in_volume, packets, blending };
    let cases = [
        case("shell", None, false, true, false),
        case("sponge", None, false, true, false),
        case("hypertexture", None, false, true, false),
        case("hypertexture", None, false, false, false),
        case("hypertexture", None, false, true, true),
        case("shell", Some(0.5), false, true, false),
        case("hypertexture", Some(0.5), false, true, false),
        case("hypertexture", Some(0.5), true, true, false),
        case("hypertexture", Some(0.5), false, true, true),
    ];
    for Case { scene: scene_name, iso, in_volume, packets, blending } in cases {
        let scene = builtin(scene_name).expect("built-in scene");
        let shares = scene_name != "sponge";
        let mut settings = RenderSettings {
            width: SIZE,
            height: SIZE,
            shading: scene.shading,
            light_direction: scene.light,
            ray_packets: packets,
            ..RenderSettings::default()
        };
        if let Some(value) = iso {
            settings.surfaces = vec![IsoSurface { value, color: [0.9, 0.75, 0.65], opacity: 1.0 }];
            settings.surfaces_in_volume = in_volume;
            settings.shading = Shading::Phong;
            settings.light_direction = Some([0.3, 0.8, 0.5]);
            settings.shadows = !in_volume;
        }
        let limits = LoopLimits { requests_per_frame: 24, ..LoopLimits::default() };
        let mut session = Session::new(scene.producer, &scene.transfer_function, settings.clone(), 256 << 20, limits)
            .expect("session");
        let closer = {
            let mut camera = scene.camera;
            let eye = DVec3::from(camera.eye);
            camera.eye = (DVec3::from(camera.target) + (eye - DVec3::from(camera.target)) * 0.45).to_array();
            camera
        };
        let cameras = if blending {
            for _ in 0..6 {
                session.render(&scene.camera, Mode::Interactive).expect("interactive frame");
            }
            assert!(!session.cache().view().brick_blends.is_empty(), "{scene_name}: nothing is fading in");
            vec![("fading in", scene.camera)]
        } else {
            let result = session.render(&scene.camera, Mode::Converged).expect("render");
            assert!(result.is_converged(), "{scene_name}: not converged");
            vec![("its view", scene.camera), ("closer", closer)]
        };
        let view = session.cache().view();
        let shape = view.shape;
        let lut = TransferLut::new(&scene.transfer_function, 0.0, 1.0, shape.voxel_size(shape.max_level));
        for (view_name, camera) in cameras {
            let pass = |shared: bool| {
                let settings = RenderSettings { shared_descents: shared, ..settings.clone() };
                one_pass(view, &camera, &lut, &settings)
            };
            let (kept, kept_stats, kept_raw, kept_requests, kept_tiles, kept_bricks) = pass(true);
            let (root, root_stats, root_raw, root_requests, root_tiles, root_bricks) = pass(false);
            let case = format!("{scene_name} (iso {iso:?}, in volume {in_volume}, packets {packets}), {view_name}");
            println!(
                "{case}: {} rays, {} descents, nodes entered {} from the root, {} kept, {} requests, {} pending",
                root_stats.rays,
                root_stats.descents,
                root_stats.nodes_entered,
                kept_stats.nodes_entered,
                root_requests.len(),
                root.pending_count()
            );
            let covered = root.image.pixels.iter().filter(|p| p[3] > 0.01).count();
            assert!(covered > (SIZE * SIZE / 10) as usize, "{case}: only {covered} pixels show anything");
            assert!(kept.image.pixels == root.image.pixels, "{case}: the images differ");
            assert!(kept.pending == root.pending, "{case}: the pending pixels differ");
            let counters = |s: RayStats| (s.rays, s.samples, s.descents);
            assert_eq!(counters(kept_stats), counters(root_stats), "{case}: rays, samples or descents differ");
            assert_eq!(kept_raw, root_raw, "{case}: the request counts differ");
            assert_eq!(kept_requests, root_requests, "{case}: the requests differ");
            assert_eq!(kept_tiles, root_tiles, "{case}: the tiles marked used differ");
            assert_eq!(kept_bricks, root_bricks, "{case}: the bricks marked used differ");
            if shares {
                assert!(
                    kept_stats.nodes_entered < root_stats.nodes_entered,
                    "{case}: keeping the paths saved no descent ({} against {})",
                    kept_stats.nodes_entered,
                    root_stats.nodes_entered
                );
            } else {
                assert_eq!(kept_stats.nodes_entered, root_stats.nodes_entered, "{case}: N = 3 shared descents");
            }
        }
    }
}
