//! How fast the camera makes the wanted level of detail change: the pace that level blending's fades must keep.
//!
//! Thiele et al. (seed 003, `../shared/notes/thiele-lod-blending.md` §"Temporal blending") fade a brick in from its
//! parent over a fixed time. While the camera approaches the data, that time is a lag: each finer level is wanted
//! sooner than the one before finishes fading in, the image shows coarse data longer, and its detail then arrives
//! while the data covers more of the screen — more change than the same detail arriving at once. On a zoom into the
//! MNI152 ×4 store (128², 60 frames, 64 requests per frame), four-frame fades doubled the popping of no blending
//! (0.144 → 0.288); two-frame fades did not (BENCHMARKS.md, "Level blending"). Level blending therefore shortens the
//! fades while the camera approaches ([`voxstream_core::level_blending::FADES_PER_LEVEL`]), by the rate measured here.
//!
//! The wanted level at a point `p` is `log2` of the eye's distance to it (plus constants: the cone's footprint
//! grows linearly with distance). Between two cameras the level wanted at `p` changes by
//! `|log2(|p − eye₁| / |p − eye₀|) + log2(s₁ / s₀)|`, where `s` is the angle one pixel subtends (a narrower field of
//! view wants finer data too). [`level_rate`] takes the largest such change over probe points where the first
//! camera looks: the rays through a 3×3 grid of the image, at the distance of its target (the point the user looks
//! at, and where a viewer's zoom goes). An orbit around the target changes the target's distance not at all and the
//! other probes' little (0.006 levels per frame at 1° per frame with a 40° field of view, 0.05 at 8°); a zoom to
//! a thousandth of the distance over 60 frames gives `log2(1000) / 60 ≈ 0.17` levels per frame; flying along the
//! view by 3% of the distance per frame gives 0.04.

use voxstream_render::Camera;

/// Levels of detail per frame by which the wanted level changes between `previous` and `current` (the largest
/// change over the probe points `previous` sees, see the module docs); 0 for the same camera, and 0 if either camera
/// is degenerate (the renderer rejects those on its own).
pub fn level_rate(previous: &Camera, current: &Camera) -> f64 {
    // The aspect ratio does not matter for a 3×3 grid of directions, only the field of view.
    let (Ok(frame), Ok(current_frame)) = (previous.frame(3, 3), current.frame(3, 3)) else {
        return 0.0;
    };
    // A narrower field of view wants finer data at the same distance: the footprint is distance × pixel spread.
    let zoom = (current_frame.pixel_spread / frame.pixel_spread).log2();
    let eye = frame.eye;
    let distance = (glam::DVec3::from(previous.target) - eye).length();
    let mut rate: f64 = 0.0;
    for y in 0..3 {
        for x in 0..3 {
            let point = eye + frame.direction(x, y, 3, 3) * distance;
            let after = (point - current_frame.eye).length();
            if after > 0.0 {
                rate = rate.max(((after / distance).log2() + zoom).abs());
            }
        }
    }
    rate
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera(eye: [f64; 3], target: [f64; 3]) -> Camera {
        Camera { eye, target, up: [0.0, 1.0, 0.0], fov: 40.0 }
    }

    #[test]
    fn the_same_camera_and_an_orbit_want_no_level_change() {
        let view = camera([0.0, 0.0, 4.0], [0.0; 3]);
        assert!(level_rate(&view, &view) < 1e-12);
        // Turning about the target keeps the target's distance; points off-centre change distance a little.
        let angle = 1.5f64.to_radians();
        let orbit = camera([4.0 * angle.sin(), 0.0, 4.0 * angle.cos()], [0.0; 3]);
        let rate = level_rate(&view, &orbit);
        assert!(rate > 0.0 && rate < 0.03, "{rate}");
    }

    #[test]
    fn halving_the_distance_wants_one_level_finer() {
        let view = camera([0.0, 0.0, 4.0], [0.0; 3]);
        let closer = camera([0.0, 0.0, 2.0], [0.0; 3]);
        // The target is wanted a level finer; the probes off the axis a little less.
        let rate = level_rate(&view, &closer);
        assert!((rate - 1.0).abs() < 1e-12, "{rate}");
        // Backing away to twice the distance is the same pace the other way.
        assert!((level_rate(&closer, &view) - 1.0).abs() < 1e-12);
        // Halving the field of view's tangent at the same place wants a level finer too.
        let narrower = Camera { fov: 2.0 * (20f64.to_radians().tan() / 2.0).atan().to_degrees(), ..view };
        assert!((level_rate(&view, &narrower) - 1.0).abs() < 1e-9, "{}", level_rate(&view, &narrower));
        // A degenerate camera gives 0 rather than an error.
        let degenerate = camera([0.0; 3], [0.0; 3]);
        assert_eq!(level_rate(&view, &degenerate), 0.0);
    }
}
