//! The traversal's promises, checked on whole frames: skipping empty space changes no bit of the image, the image is
//! the same whatever the number of threads and the instruction set the CPU offers, and descents that start from the
//! last ray's nodes find what descents from the root find.

mod common;

use glam::DVec3;
use voxstream::scenes::builtin;
use voxstream_core::FeedbackBuffer;
use voxstream_engine::{LoopLimits, Mode, Session};
use voxstream_render::{
    render_frame, Image, InstructionSet, IsoSurface, RayStats, RenderSettings, Shading, TransferLut,
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

#[test]
fn rays_that_keep_their_neighbours_descents_equal_rays_that_start_at_the_root() {
    // Each case converges the scene's own view, then renders it and a closer view (whose finer nodes are missing or
    // not subdivided: requests) through the resident tree twice, with the lanes' descent paths kept from ray to ray
    // and with every ray starting at the root. Everything a frame produces must be the same: the image, the
    // counters, the requests and the feedback's marks; only the nodes entered differ, and must be fewer.
    let cases: [(&str, Option<f64>, bool); 6] = [
        ("shell", None, true),
        ("sponge", None, true),
        ("hypertexture", None, true),
        ("hypertexture", None, false),
        ("shell", Some(0.5), true),
        ("hypertexture", Some(0.5), true),
    ];
    for (scene_name, iso, packets) in cases {
        let scene = builtin(scene_name).expect("built-in scene");
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
            settings.shading = Shading::Phong;
            settings.light_direction = Some([0.3, 0.8, 0.5]);
            settings.shadows = true;
        }
        let mut session =
            Session::new(scene.producer, &scene.transfer_function, settings.clone(), 256 << 20, LoopLimits::default())
                .expect("session");
        let result = session.render(&scene.camera, Mode::Converged).expect("render");
        assert!(result.is_converged(), "{scene_name}: not converged");
        let view = session.cache().view();
        let shape = view.shape;
        let lut = TransferLut::new(&scene.transfer_function, 0.0, 1.0, shape.voxel_size(shape.max_level));
        let closer = {
            let mut camera = scene.camera;
            let eye = DVec3::from(camera.eye);
            camera.eye = (DVec3::from(camera.target) + (eye - DVec3::from(camera.target)) * 0.45).to_array();
            camera
        };
        for (view_name, camera) in [("its view", scene.camera), ("closer", closer)] {
            let frame = |shared: bool| {
                let settings = RenderSettings { shared_descents: shared, ..settings.clone() };
                let mut feedback = FeedbackBuffer::new(view.capacity.tiles, view.capacity.bricks);
                let frame = render_frame(view, &feedback, &camera, &lut, &settings).expect("frame");
                let mut requests = feedback.take_requests();
                requests.sort();
                let tiles: Vec<_> = feedback.used_tiles().collect();
                let bricks: Vec<_> = feedback.used_bricks().collect();
                (frame, requests, tiles, bricks)
            };
            let (kept, kept_requests, kept_tiles, kept_bricks) = frame(true);
            let (root, root_requests, root_tiles, root_bricks) = frame(false);
            let case = format!("{scene_name} (iso {iso:?}, packets {packets}), {view_name}");
            println!(
                "{case}: {} rays, {} descents, nodes entered {} from the root, {} kept, {} requests",
                root.stats.rays,
                root.stats.descents,
                root.stats.nodes_entered,
                kept.stats.nodes_entered,
                root_requests.len()
            );
            let covered = root.image.pixels.iter().filter(|p| p[3] > 0.01).count();
            assert!(covered > (SIZE * SIZE / 10) as usize, "{case}: only {covered} pixels show anything");
            assert!(kept.image.pixels == root.image.pixels, "{case}: the images differ");
            let counters = |s: RayStats| (s.rays, s.samples, s.descents);
            assert_eq!(counters(kept.stats), counters(root.stats), "{case}: rays, samples or descents differ");
            assert_eq!(kept.raw_requests, root.raw_requests, "{case}: the request counts differ");
            assert_eq!(kept_requests, root_requests, "{case}: the requests differ");
            assert_eq!(kept_tiles, root_tiles, "{case}: the tiles marked used differ");
            assert_eq!(kept_bricks, root_bricks, "{case}: the bricks marked used differ");
            assert!(
                kept.stats.nodes_entered < root.stats.nodes_entered,
                "{case}: keeping the paths saved no descent ({} against {})",
                kept.stats.nodes_entered,
                root.stats.nodes_entered
            );
        }
    }
}
