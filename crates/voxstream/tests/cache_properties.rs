//! Property tests of the cache under random budgets and camera paths, through the whole loop (renderer, feedback,
//! cache manager, producers): the budget is never exceeded, no pointer to an evicted node or brick survives, nothing
//! panics, and a converged frame equals the fully resident render bit for bit. Also: producing the children of a
//! subdivided node at once (converged mode's `prefetch_new_children`) changes neither the image nor what is evicted,
//! only the number of passes.

mod common;

use proptest::prelude::*;
use voxstream::scenes::SCENE_NAMES;
use voxstream_engine::Mode;
use voxstream_render::Camera;

fn camera_strategy() -> impl Strategy<Value = Camera> {
    (0.0f64..1.0, 0.0f64..1.0, 0.0f64..1.0, -1.0f64..1.0, 0.0f64..std::f64::consts::TAU, 0.05f64..3.0, 10.0f64..70.0)
        .prop_map(|(tx, ty, tz, elevation, azimuth, distance, fov)| {
            let target = [tx, ty, tz];
            let (s, c) = (elevation.asin().cos(), elevation);
            let eye = [tx + distance * s * azimuth.cos(), ty + distance * c, tz + distance * s * azimuth.sin()];
            // Keep up away from the view direction.
            let up = if c.abs() > 0.9 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] };
            Camera { eye, target, up, fov }
        })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn budget_and_pointers_hold_on_random_paths(
        scene in 0usize..3,
        budget_kib in 200u64..3000,
        limit in 1usize..200,
        prefetch_new_children in any::<bool>(),
        path in proptest::collection::vec(camera_strategy(), 1..6),
    ) {
        let budget = budget_kib * 1024;
        let scene = SCENE_NAMES[scene];
        let scene_def = voxstream::scenes::builtin(scene).unwrap();
        let minimum = voxstream_core::PoolCapacities::plan(&voxstream_core::Producer::shape(&scene_def.producer), budget);
        prop_assume!(minimum.is_ok());
        let settings = voxstream_render::RenderSettings { width: 24, height: 24, ..Default::default() };
        let limits =
            voxstream_engine::LoopLimits { requests_per_frame: limit, max_passes: 60, prefetch_new_children, ..Default::default() };
        let mut session = voxstream_engine::Session::new(
            scene_def.producer, &scene_def.transfer_function, settings, budget, limits).unwrap();
        for camera in &path {
            for _ in 0..3 {
                session.render(camera, Mode::Interactive).unwrap();
                prop_assert!(session.residency().bytes <= budget);
                if let Err(violation) = session.cache().check_invariants() {
                    return Err(TestCaseError::fail(format!("{scene}: {violation}")));
                }
            }
        }
        let last = path.last().unwrap();
        let small = session.render(last, Mode::Converged).unwrap();
        prop_assert!(session.cache().check_invariants().is_ok());
        prop_assert!(session.residency().bytes <= budget);
        if small.is_converged() {
            // Exactness: whatever was evicted on the way, a converged frame is the fully resident image.
            let reference = voxstream_engine::Session::new(
                scene_def.producer, &scene_def.transfer_function,
                voxstream_render::RenderSettings { width: 24, height: 24, ..Default::default() },
                256 << 20, Default::default()).unwrap();
            let mut reference = reference;
            let full = reference.render(last, Mode::Converged).unwrap();
            prop_assert!(full.is_converged());
            prop_assert_eq!(small.image.pixels, full.image.pixels);
        }
    }
}

#[test]
fn interactive_frames_converge_to_the_converged_image() {
    // A fixed camera in interactive mode reaches zero requests within a bounded number of frames and then equals
    // the converged render exactly.
    let camera = voxstream::scenes::default_camera();
    let mut interactive = common::scene_session("sponge", 64, 64 << 20);
    let (frames, last) = interactive.render_until_converged_interactively(&camera, 200).unwrap();
    assert!(last.is_converged(), "not converged after {frames} frames");
    assert!(frames > 1, "the first frame cannot already be complete");
    let mut converged = common::scene_session("sponge", 64, 64 << 20);
    let exact = common::converged(&mut converged, &camera);
    assert_eq!(last.image.pixels, exact.pixels);
}

/// Where a resident brick lies: its level, its node's bounds and its parent's.
struct ResidentBrick {
    level: u32,
    lower: [f64; 3],
    size: f64,
    parent_lower: [f64; 3],
    parent_size: f64,
}

/// Every resident brick of a session.
fn resident_bricks(session: &voxstream_engine::Session<voxstream::scenes::SceneProducer>) -> Vec<ResidentBrick> {
    let cache = session.cache();
    let shape = *cache.shape();
    (0..cache.brick_pool().allocated())
        .map(voxstream_core::BrickSlot)
        .filter(|&slot| cache.brick_pool().is_in_use(slot))
        .map(|slot| {
            let key = cache.node_pool().key(cache.brick_pool().owner(slot));
            let (lower, size) = key.bounds(&shape);
            let parent = voxstream_core::NodeKey {
                level: key.level.saturating_sub(1),
                ijk: if key.level == 0 { key.ijk } else { key.ijk.map(|c| c / shape.n as u64) },
            };
            let (parent_lower, parent_size) = parent.bounds(&shape);
            ResidentBrick { level: key.level, lower, size, parent_lower, parent_size }
        })
        .collect()
}

#[test]
fn off_screen_data_is_never_loaded() {
    // Ray-guided loading, no frustum pass: looking at the sponge's z = 1 face from close by, the cone of view
    // spans x, y in [0.15, 0.85] even at the back face; nodes entirely outside it must never be requested.
    let camera = Camera { eye: [0.5, 0.5, 1.3], target: [0.5, 0.5, 1.0], up: [0.0, 1.0, 0.0], fov: 30.0 };
    let is_off_screen = |lower: [f64; 3], size: f64| {
        let outside = |lower: f64| lower + size < 0.14 || lower > 0.86;
        outside(lower[0]) || outside(lower[1])
    };
    for prefetch_new_children in [false, true] {
        let limits = voxstream_engine::LoopLimits { prefetch_new_children, ..Default::default() };
        let mut session = common::scene_session_with("sponge", 64, 64 << 20, limits);
        common::converged(&mut session, &camera);
        let bricks = resident_bricks(&session);
        assert!(bricks.len() > 50);
        let off_screen: Vec<&ResidentBrick> =
            bricks.iter().filter(|brick| brick.level >= 2 && is_off_screen(brick.lower, brick.size)).collect();
        if prefetch_new_children {
            // Children produced with their tile may lie off screen, but only one level below what the rays used:
            // their parent was subdivided for a ray, so it is on screen.
            let stray = off_screen.iter().filter(|brick| is_off_screen(brick.parent_lower, brick.parent_size)).count();
            assert_eq!(stray, 0, "{stray} off-screen bricks have an off-screen parent");
        } else {
            assert!(off_screen.is_empty(), "{} of {} bricks are off screen", off_screen.len(), bricks.len());
        }
    }
}

#[test]
fn occluded_data_is_never_loaded() {
    // Looking down at the hypertextured torus's tube: the opaque tube hides what lies under it.
    let camera = Camera { eye: [0.78, 0.5, 0.9], target: [0.78, 0.5, 0.5], up: [0.0, 1.0, 0.0], fov: 20.0 };
    let mut session = common::scene_session("hypertexture", 64, 64 << 20);
    common::converged(&mut session, &camera);
    let bricks = resident_bricks(&session);
    let under = bricks
        .iter()
        .filter(|ResidentBrick { level, lower, size, .. }| {
            *level >= 4
                && lower[2] + size < 0.42
                && lower[0] > 0.74
                && lower[0] + size < 0.82
                && lower[1] > 0.46
                && lower[1] + size < 0.54
        })
        .count();
    let above = bricks.iter().filter(|brick| brick.level >= 4 && brick.lower[2] > 0.55).count();
    assert!(above > 20, "the visible top of the tube is loaded ({above} bricks)");
    assert_eq!(under, 0, "{under} bricks under the opaque tube were loaded");
}

/// A converged frame of `scene` at 64² from a cold cache of `budget_bytes`, with and without producing new children
/// at once.
fn converged_with_and_without_prefetch(
    scene: &str,
    budget_bytes: u64,
) -> (voxstream_engine::FrameResult, voxstream_engine::FrameResult) {
    let camera = voxstream::scenes::default_camera();
    let frame = |prefetch_new_children| {
        let limits = voxstream_engine::LoopLimits { prefetch_new_children, ..Default::default() };
        let mut session = common::scene_session_with(scene, 64, budget_bytes, limits);
        let result = session.render(&camera, Mode::Converged).unwrap();
        assert!(result.is_converged(), "{scene}: not converged after {} passes", result.passes);
        assert_eq!(session.cache().check_invariants(), Ok(()));
        result
    };
    (frame(true), frame(false))
}

#[test]
fn producing_new_children_at_once_keeps_the_image_and_saves_passes() {
    for scene in ["shell", "sponge"] {
        let (on, off) = converged_with_and_without_prefetch(scene, 64 << 20);
        println!(
            "{scene}: {} passes with new children produced at once ({} bricks ahead of the rays), {} without",
            on.passes, on.bricks_prefetched, off.passes
        );
        assert_eq!(on.image.pixels, off.image.pixels, "{scene}: the image changed");
        assert!(on.bricks_prefetched > 0, "{scene}: nothing was produced ahead of the rays");
        assert_eq!(off.bricks_prefetched, 0);
        if scene == "shell" {
            assert!(on.passes < off.passes, "shell: {} passes with, {} without", on.passes, off.passes);
        }
    }
}

#[test]
fn sparse_gathering_passes_keep_the_image_and_trace_fewer_rays() {
    let camera = voxstream::scenes::default_camera();
    for scene in ["shell", "sponge", "hypertexture"] {
        let frame = |gather_sparsely| {
            let limits = voxstream_engine::LoopLimits { gather_sparsely, ..Default::default() };
            let mut session = common::scene_session_with(scene, 64, 64 << 20, limits);
            let cold = session.render(&camera, Mode::Converged).unwrap();
            assert!(cold.is_converged(), "{scene}: not converged after {} passes", cold.passes);
            // A warm frame of the same view: dense from the start once the last frame needed nothing.
            let _ = session.render(&camera, Mode::Converged).unwrap();
            let warm = session.render(&camera, Mode::Converged).unwrap();
            (cold, warm)
        };
        let ((sparse, sparse_warm), (dense, dense_warm)) = (frame(true), frame(false));
        println!(
            "{scene}: cold frame {} rays in {} passes gathering sparsely, {} rays in {} passes densely",
            sparse.rays, sparse.passes, dense.rays, dense.passes
        );
        assert_eq!(sparse.image.pixels, dense.image.pixels, "{scene}: the image changed");
        assert!(sparse.rays < dense.rays, "{scene}: {} rays sparsely, {} densely", sparse.rays, dense.rays);
        assert_eq!(sparse_warm.image.pixels, dense_warm.image.pixels);
        assert_eq!((sparse_warm.passes, sparse_warm.rays), (1, dense_warm.rays), "{scene}: a warm frame is one pass");
    }
}

#[test]
fn producing_new_children_at_once_keeps_a_store_image() {
    use voxstream::render_command::{default_store_transfer_function, store_camera, store_placement};
    use voxstream_store::formats::{open_volume, Endian, RawLayout};
    use voxstream_store::{import_volume, DType, ImportOptions, StoreProducer, StoreReader, VolumeInfo};

    // A 72×60×50 u8 ball with a ripple, imported as a store with several levels of 32³ bricks.
    let dir = std::env::temp_dir().join(format!("voxstream-prefetch-store-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let dims = [72u64, 60, 50];
    let mut samples = Vec::with_capacity((dims[0] * dims[1] * dims[2]) as usize);
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let r = glam::DVec3::new(i as f64 - 36.0, j as f64 - 30.0, k as f64 - 25.0).length();
                let value = (1.0 - r / 28.0).max(0.0) * (200.0 + 50.0 * (i as f64 * 0.7).sin());
                samples.push(value as u8);
            }
        }
    }
    let raw = dir.join("ball.raw");
    std::fs::write(&raw, &samples).unwrap();
    let layout = RawLayout {
        info: VolumeInfo { dims, dtype: DType::U8, spacing: [1.0; 3], origin: [0.0; 3], unit: None, orientation: None },
        file_type: None,
        endian: Endian::Little,
        header_bytes: 0,
    };
    let store = dir.join("ball.zarr");
    let mut source = open_volume(&raw, Some(&layout)).unwrap();
    import_volume(source.as_mut(), &store, &ImportOptions::default(), &mut |_, _| {}).unwrap();
    let reader = std::sync::Arc::new(StoreReader::open(&store).unwrap());

    let tf = default_store_transfer_function(reader.attributes().typical_range()).unwrap();
    let camera = store_camera(reader.info(), 64, 64);
    let settings = voxstream_render::RenderSettings {
        width: 64,
        height: 64,
        placement: store_placement(&reader),
        ..Default::default()
    };
    let frame = |prefetch_new_children| {
        let limits = voxstream_engine::LoopLimits { prefetch_new_children, ..Default::default() };
        let producer = StoreProducer::new(reader.clone()).unwrap();
        let mut session = voxstream_engine::Session::with_value_range(
            producer,
            &tf,
            settings.clone(),
            64 << 20,
            limits,
            reader.attributes().value_range,
        )
        .unwrap();
        let result = session.render(&camera, Mode::Converged).unwrap();
        assert!(result.is_converged());
        result
    };
    let (on, off) = (frame(true), frame(false));
    let _ = std::fs::remove_dir_all(&dir);
    println!("store: {} passes with new children produced at once, {} without", on.passes, off.passes);
    assert!(on.image.pixels.iter().any(|&p| p != on.image.pixels[0]), "the ball is visible");
    assert_eq!(on.image.pixels, off.image.pixels, "the image changed");
    assert!(on.passes < off.passes, "store: {} passes with, {} without", on.passes, off.passes);
}
