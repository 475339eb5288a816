//! Property tests of the cache under random budgets and camera paths, through the whole loop (renderer, feedback,
//! cache manager, producers): the budget is never exceeded, no pointer to an evicted node or brick survives, nothing
//! panics, and a converged frame equals the fully resident render bit for bit.

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
        path in proptest::collection::vec(camera_strategy(), 1..6),
    ) {
        let budget = budget_kib * 1024;
        let scene = SCENE_NAMES[scene];
        let scene_def = voxstream::scenes::builtin(scene).unwrap();
        let minimum = voxstream_core::PoolCapacities::plan(&voxstream_core::Producer::shape(&scene_def.producer), budget);
        prop_assume!(minimum.is_ok());
        let settings = voxstream_render::RenderSettings { width: 24, height: 24, ..Default::default() };
        let limits = voxstream_engine::LoopLimits { requests_per_frame: limit, max_passes: 60 };
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

/// Keys of every resident brick of a session.
fn resident_brick_bounds(
    session: &voxstream_engine::Session<voxstream::scenes::SceneProducer>,
) -> Vec<(u32, [f64; 3], f64)> {
    let cache = session.cache();
    let shape = *cache.shape();
    (0..cache.brick_pool().allocated())
        .map(voxstream_core::BrickSlot)
        .filter(|&slot| cache.brick_pool().is_in_use(slot))
        .map(|slot| {
            let key = cache.node_pool().key(cache.brick_pool().owner(slot));
            let (lower, size) = key.bounds(&shape);
            (key.level, lower, size)
        })
        .collect()
}

#[test]
fn off_screen_data_is_never_loaded() {
    // Ray-guided loading, no frustum pass: looking at the sponge's z = 1 face from close by, the cone of view
    // spans x, y in [0.15, 0.85] even at the back face; nodes entirely outside it must never be produced.
    let camera = Camera { eye: [0.5, 0.5, 1.3], target: [0.5, 0.5, 1.0], up: [0.0, 1.0, 0.0], fov: 30.0 };
    let mut session = common::scene_session("sponge", 64, 64 << 20);
    common::converged(&mut session, &camera);
    let bricks = resident_brick_bounds(&session);
    let outside = |lower: f64, size: f64| lower + size < 0.14 || lower > 0.86;
    let off_screen = bricks
        .iter()
        .filter(|(level, lower, size)| *level >= 2 && (outside(lower[0], *size) || outside(lower[1], *size)))
        .count();
    assert!(bricks.len() > 50);
    assert_eq!(off_screen, 0, "{off_screen} of {} bricks are off screen", bricks.len());
}

#[test]
fn occluded_data_is_never_loaded() {
    // Looking down at the hypertextured torus's tube: the opaque tube hides what lies under it.
    let camera = Camera { eye: [0.78, 0.5, 0.9], target: [0.78, 0.5, 0.5], up: [0.0, 1.0, 0.0], fov: 20.0 };
    let mut session = common::scene_session("hypertexture", 64, 64 << 20);
    common::converged(&mut session, &camera);
    let bricks = resident_brick_bounds(&session);
    let under = bricks
        .iter()
        .filter(|(level, lower, size)| {
            *level >= 4
                && lower[2] + size < 0.42
                && lower[0] > 0.74
                && lower[0] + size < 0.82
                && lower[1] > 0.46
                && lower[1] + size < 0.54
        })
        .count();
    let above = bricks.iter().filter(|(level, lower, _)| *level >= 4 && lower[2] > 0.55).count();
    assert!(above > 20, "the visible top of the tube is loaded ({above} bricks)");
    assert_eq!(under, 0, "{under} bricks under the opaque tube were loaded");
}
