//! The colour-by-level diagnostic (`RenderSettings::colour_by_level`, the viewer's L key): only the colours change,
//! to the palette of the levels the samples came from; opacity and the data loaded stay the same.

mod common;

use common::{converged, scene_session};
use voxstream::scenes::builtin;
use voxstream_render::level_colour;

#[test]
fn colouring_by_level_keeps_opacity_and_uses_the_palette() {
    let scene = builtin("shell").unwrap();
    let mut plain = scene_session("shell", 48, 64 << 20);
    let plain_image = converged(&mut plain, &scene.camera);
    let mut coloured = scene_session("shell", 48, 64 << 20);
    let mut settings = coloured.settings().clone();
    settings.colour_by_level = true;
    coloured.set_settings(settings).unwrap();
    let coloured_image = converged(&mut coloured, &scene.camera);
    let mut compared = 0;
    for (p, c) in plain_image.pixels.iter().zip(&coloured_image.pixels) {
        assert_eq!(p[3], c[3], "opacity is the same");
        if c[3] > 0.05 {
            compared += 1;
            // The shell is unshaded: premultiplied colour / opacity is a mix of palette colours, so each channel lies
            // within the palette's range of that channel.
            for channel in 0..3 {
                let value = c[channel] / c[3];
                let range = (0..8).map(|l| level_colour(l)[channel]);
                let (lo, hi) = range.fold((f32::MAX, f32::MIN), |(lo, hi), v| (lo.min(v), hi.max(v)));
                assert!(value >= lo - 1e-3 && value <= hi + 1e-3, "channel {channel}: {value} outside [{lo}, {hi}]");
            }
        }
    }
    assert!(compared > 100, "the shell covers part of the image");
    assert_ne!(plain_image.pixels, coloured_image.pixels, "the colours changed");
    assert_eq!(plain.residency().bricks, coloured.residency().bricks, "the same data was loaded");
}
