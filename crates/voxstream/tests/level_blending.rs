//! Level blending (Thiele et al., issue: level changes that never pop), through the whole loop: a camera at rest
//! converges to the same bytes with blending on and off (and as a converged frame), on random camera paths too; and
//! on a cold start at rest, the largest frame-to-frame pop is smaller with blending.

mod common;

use proptest::prelude::*;
use voxstream::popping_run::FrameRecorder;
use voxstream::scenes::{builtin, SceneProducer, SCENE_NAMES};
use voxstream_engine::{LoopLimits, Mode, PoppingSummary, Session};
use voxstream_render::{Camera, RenderSettings};

fn session(scene: &str, size: u32, requests_per_frame: usize, fade_frames: Option<u32>) -> Session<SceneProducer> {
    let scene = builtin(scene).expect("a built-in scene");
    let settings = RenderSettings {
        width: size,
        height: size,
        shading: scene.shading,
        light_direction: scene.light,
        ..RenderSettings::default()
    };
    let limits = LoopLimits { requests_per_frame, blending_fade_frames: fade_frames, ..LoopLimits::default() };
    Session::new(scene.producer, &scene.transfer_function, settings, 64 << 20, limits).expect("a session")
}

/// Interactive frames at `camera` until one is final; returns them and the last.
fn frames_at_rest(session: &mut Session<SceneProducer>, camera: &Camera, size: u32) -> (FrameRecorder, Vec<u8>) {
    let mut recorder = FrameRecorder::new(size, size, 400).expect("a small recorder");
    for _ in 0..400 {
        let frame = session.render(camera, Mode::Interactive).expect("a frame");
        recorder.record(camera, &frame.image);
        if frame.is_final() {
            return (recorder, frame.image.to_rgb8());
        }
    }
    panic!("no final frame within 400 frames");
}

#[test]
fn a_camera_at_rest_converges_to_the_same_bytes_with_blending_on_and_off() {
    for scene in SCENE_NAMES {
        let camera = builtin(scene).unwrap().camera;
        let converged = session(scene, 48, 1024, None).render(&camera, Mode::Converged).unwrap().image.to_rgb8();
        let (off_frames, off) = frames_at_rest(&mut session(scene, 48, 32, None), &camera, 48);
        let (on_frames, on) = frames_at_rest(&mut session(scene, 48, 32, Some(4)), &camera, 48);
        assert!(off == converged, "{scene}: interactive without blending ends at the converged image");
        assert!(on == converged, "{scene}: interactive with blending ends at the converged image");
        // Blending takes longer to get there, but not forever.
        assert!(on_frames.frames().count() >= off_frames.frames().count(), "{scene}");
    }
}

#[test]
fn a_cold_start_at_rest_pops_less_with_blending() {
    // The shell at rest from a cold cache, bounded production: without blending each level replaces its parent at
    // once; with it, each fades in over four frames.
    let camera = builtin("shell").unwrap().camera;
    let measure = |fade_frames: Option<u32>| -> PoppingSummary {
        let mut session = session("shell", 64, 64, fade_frames);
        let (recorder, _) = frames_at_rest(&mut session, &camera, 64);
        recorder.measure(&mut session).unwrap()
    };
    let (off, on) = (measure(None), measure(Some(4)));
    assert!(off.frame_pairs > 1 && on.frame_pairs > off.frame_pairs, "{off:?}\n{on:?}");
    assert!(on.popping_max * 2.0 < off.popping_max, "largest pop: off {} on {}", off.popping_max, on.popping_max);
    assert!(on.popping_p99 < off.popping_p99, "p99: off {} on {}", off.popping_p99, on.popping_p99);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 12, failure_persistence: None, ..ProptestConfig::default() })]

    /// Whatever path came before, blending always finishes: at rest the frames end at the converged image, with the
    /// cache's invariants intact on the way.
    #[test]
    fn blending_finishes_at_the_converged_image_after_any_path(
        scene in 0usize..SCENE_NAMES.len(),
        limit in 4usize..200,
        fade_frames in 1u32..6,
        path in proptest::collection::vec(common::random_camera(0.3), 1..6),
    ) {
        let scene = SCENE_NAMES[scene];
        let mut moving = session(scene, 24, limit, Some(fade_frames));
        for camera in &path {
            moving.render(camera, Mode::Interactive).unwrap();
            prop_assert!(moving.cache().check_invariants().is_ok());
        }
        let last = path.last().unwrap();
        let (_, at_rest) = frames_at_rest(&mut moving, last, 24);
        let converged = session(scene, 24, 1024, None).render(last, Mode::Converged).unwrap().image.to_rgb8();
        prop_assert!(at_rest == converged, "{}: the frames at rest end at the converged image", scene);
    }
}
