//! Loading prioritised towards a point of the image (`RenderSettings::focus`: the viewer's centre of view or
//! cursor): with few requests per frame, the half of the image holding the focus gets its detail first, and the
//! final image does not depend on the focus.

mod common;

use common::scene_session_with;
use voxstream::scenes::builtin;
use voxstream_engine::{LoopLimits, Mode};
use voxstream_render::Image;

/// Mean absolute difference (0–255 scale) between `a` and `b` over the columns `columns`.
fn half_error(a: &Image, b: &Image, columns: std::ops::Range<u32>) -> f64 {
    let (a, b) = (a.to_rgb8(), b.to_rgb8());
    let width = 64usize;
    let mut sum = 0.0;
    let mut count = 0usize;
    for (index, (x, y)) in a.iter().zip(&b).enumerate() {
        let column = (index / 3 % width) as u32;
        if columns.contains(&column) {
            sum += (*x as f64 - *y as f64).abs();
            count += 1;
        }
    }
    sum / count as f64
}

/// Interactive frames with `requests_per_frame` requests, focus at `focus`; the image after `frames` frames and the
/// final one.
fn after_frames(focus: [f32; 2], frames: u32) -> (Image, Image) {
    let scene = builtin("hypertexture").unwrap();
    let limits = LoopLimits { requests_per_frame: 24, blending_fade_frames: None, ..LoopLimits::default() };
    let mut session = scene_session_with("hypertexture", 64, 64 << 20, limits);
    let mut settings = session.settings().clone();
    settings.focus = Some(focus);
    session.set_settings(settings).unwrap();
    let mut early = None;
    for frame in 1.. {
        let result = session.render(&scene.camera, Mode::Interactive).unwrap();
        if frame == frames {
            early = Some(result.image.clone());
        }
        if result.is_final() {
            assert!(frame > frames, "the view was final after {frame} frames: too few to compare");
            return (early.unwrap(), result.image);
        }
        assert!(frame < 2000, "no final frame");
    }
    unreachable!()
}

#[test]
fn the_focused_half_gets_its_detail_first_and_the_final_image_is_the_same() {
    let (left_early, left_final) = after_frames([0.15, 0.5], 12);
    let (right_early, right_final) = after_frames([0.85, 0.5], 12);
    assert_eq!(left_final.pixels, right_final.pixels, "the focus changes only the order of loading");
    let exact = &left_final;
    let (left_half, right_half) = (0..32, 32..64);
    let focused_left = half_error(&left_early, exact, left_half.clone());
    let unfocused_left = half_error(&right_early, exact, left_half);
    let focused_right = half_error(&right_early, exact, right_half.clone());
    let unfocused_right = half_error(&left_early, exact, right_half);
    eprintln!("left half {focused_left:.2} focused, {unfocused_left:.2} not; right half {focused_right:.2}, {unfocused_right:.2}");
    assert!(
        focused_left < unfocused_left && focused_right < unfocused_right,
        "error of the left half: {focused_left:.2} focused, {unfocused_left:.2} not; right half: {focused_right:.2} \
         focused, {unfocused_right:.2} not"
    );
}
