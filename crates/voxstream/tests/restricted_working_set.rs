//! Thiele et al.'s restricted working set (issue: level changes that never pop), through the whole loop: on camera
//! paths started cold with bounded requests per frame, the data the rays can draw never differs by more than one
//! level between neighbours when the restriction is on; without it, it does.

mod common;

use proptest::prelude::*;
use voxstream::camera_path::{generated_path, PathKind};
use voxstream::scenes::{builtin, SceneProducer, SCENE_NAMES};
use voxstream_core::{CoreError, PoolCapacities, Producer};
use voxstream_engine::{LoopLimits, Mode, Session};
use voxstream_render::Camera;

/// A session whose budget is `budget_factor` times the smallest the scene's tree allows.
fn session(
    scene: &str,
    size: u32,
    requests_per_frame: usize,
    budget_factor: u64,
    restrict: bool,
) -> Session<SceneProducer> {
    let scene = builtin(scene).expect("a built-in scene");
    let minimum = match PoolCapacities::plan(&scene.producer.shape(), 0) {
        Err(CoreError::BudgetTooSmall { minimum_bytes, .. }) => minimum_bytes,
        other => panic!("no budget is too small? {other:?}"),
    };
    let limits = LoopLimits {
        requests_per_frame,
        blending_fade_frames: Some(voxstream_core::DEFAULT_FADE_FRAMES),
        restrict_working_set: restrict,
        ..LoopLimits::default()
    };
    common::scene_session_with(scene.name, size, minimum * budget_factor, limits)
}

/// Renders `path` interactively; after each frame checks the cache and the restriction. Returns the frames at
/// which the restriction was broken, the forced steps served, and the evictions that yielded to the budget.
fn run(session: &mut Session<SceneProducer>, path: &[Camera]) -> (Vec<usize>, u64, u64) {
    let (mut broken, mut forced, mut yielded) = (Vec::new(), 0, 0);
    for (index, camera) in path.iter().enumerate() {
        let frame = session.render(camera, Mode::Interactive).expect("a frame");
        forced += frame.forced_steps;
        yielded += frame.restriction_yielded;
        session.cache().check_invariants().expect("cache invariants");
        if session.cache().check_restricted().is_err() {
            broken.push(index);
        }
    }
    (broken, forced, yielded)
}

#[test]
fn a_zoom_from_a_cold_cache_stays_restricted_only_with_the_restriction() {
    // The hypertexture zoomed into from a cold cache, 32 requests per frame: rays near the eye ask for fine levels
    // while the rest of the view still holds coarse ones.
    let scene = builtin("hypertexture").unwrap();
    let path = generated_path(PathKind::Zoom, 40, &scene.camera);
    let (free_broken, free_forced, _) = run(&mut session("hypertexture", 48, 32, 1000, false), &path);
    assert!(!free_broken.is_empty(), "without the restriction this path leaves neighbours two levels apart");
    assert_eq!(free_forced, 0, "without the restriction nothing is forced");
    let (broken, forced, yielded) = run(&mut session("hypertexture", 48, 32, 1000, true), &path);
    assert_eq!(yielded, 0, "a large budget holds the path without breaking the restriction");
    assert!(broken.is_empty(), "restricted, yet broken at frames {broken:?}");
    assert!(forced > 0, "the restriction forced no split on this path");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, failure_persistence: None, ..ProptestConfig::default() })]

    /// On random paths, with pools small enough to recycle, the working set is restricted after every frame, as long
    /// as no eviction had to yield to the budget (counted, and required to be rare over all cases).
    #[test]
    fn the_working_set_stays_restricted_on_random_paths(
        scene in 0usize..SCENE_NAMES.len(),
        limit in 4usize..200,
        budget_factor in prop_oneof![Just(2u64), Just(4), Just(1000)],
        path in proptest::collection::vec(common::random_camera(0.05), 2..8),
        steps in 2usize..12,
    ) {
        let scene = SCENE_NAMES[scene];
        let mut moving = session(scene, 48, limit, budget_factor, true);
        let mut yielded_before = 0;
        // `steps` frames from each key camera to the next, eye and target moving linearly.
        let frames = path.windows(2).flat_map(|pair| {
            (0..steps).map(move |k| {
                let t = k as f64 / steps as f64;
                let mix = |a: [f64; 3], b: [f64; 3]| [0, 1, 2].map(|i| a[i] + t * (b[i] - a[i]));
                Camera { eye: mix(pair[0].eye, pair[1].eye), target: mix(pair[0].target, pair[1].target), ..pair[0] }
            })
        });
        for (index, camera) in frames.enumerate() {
            let frame = moving.render(&camera, Mode::Interactive).unwrap();
            yielded_before += frame.restriction_yielded;
            prop_assert!(moving.cache().check_invariants().is_ok());
            if yielded_before == 0 {
                let restricted = moving.cache().check_restricted();
                prop_assert!(restricted.is_ok(), "{} frame {}: {:?}", scene, index, restricted);
            }
        }
        prop_assert!(budget_factor < 1000 || yielded_before == 0, "{}: a large budget never needs to break it", scene);
    }
}
