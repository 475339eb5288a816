//! The comparator of Reichl §6.5.3: a depth-aware bilateral filter over the foreground (the classic screen-space
//! fluid smoothing), against which the ROF filter of [`super::smooth_rof`] is judged.
//!
//! Each foreground pixel becomes the weighted mean of the foreground pixels within `⌈2σ_s⌉` pixels (a disc),
//! weighted by `exp(−d²/2σ_s²) · exp(−Δz²/2σ_r²)`. Neighbours more than 3σ_r away in depth are skipped (their
//! weight would be below 1.1 %), so layers further apart than that are never blended; the background is neither
//! read nor written. Unlike ROF it has one fixed pixel footprint at every depth.

use rayon::prelude::*;

use super::DepthImage;

/// Neighbours further than this many range σ in depth are not blended at all.
const RANGE_CUTOFF_SIGMAS: f32 = 3.0;

/// The comparator the thesis uses: a depth-aware bilateral filter over the foreground (spatial σ in pixels, range
/// σ in depth units, radius ⌈2σ_s⌉), background untouched (bit for bit). A σ that is not positive and finite
/// returns the image unchanged.
///
/// # Panics
/// If the image is inconsistent (see [`DepthImage::new`]).
pub fn smooth_bilateral(image: &DepthImage, spatial_sigma_px: f32, range_sigma: f32) -> DepthImage {
    image.assert_consistent();
    let (w, h) = (image.width, image.height);
    let is_valid = |s: f32| s > 0.0 && s.is_finite();
    if w == 0 || h == 0 || !is_valid(spatial_sigma_px) || !is_valid(range_sigma) {
        return image.clone();
    }
    let radius = (2.0 * spatial_sigma_px).ceil() as isize;
    // The spatial weights of the disc, as (dx, dy, weight).
    let mut kernel = Vec::new();
    for dy in -radius..=radius {
        for dx in -radius..=radius {
            let d2 = (dx * dx + dy * dy) as f32;
            if d2 <= (radius * radius) as f32 {
                kernel.push((dx, dy, (-d2 / (2.0 * spatial_sigma_px * spatial_sigma_px)).exp()));
            }
        }
    }
    let range_scale = -1.0 / (2.0 * range_sigma * range_sigma);
    let max_dz = RANGE_CUTOFF_SIGMAS * range_sigma;
    let z = &image.depth;

    let mut depth = z.clone();
    depth.par_chunks_mut(w).enumerate().for_each(|(y, out)| {
        for (x, o) in out.iter_mut().enumerate() {
            let centre = z[y * w + x];
            if !centre.is_finite() {
                continue;
            }
            let (mut sum, mut weight_sum) = (0.0f32, 0.0f32);
            for &(dx, dy, spatial) in &kernel {
                let (nx, ny) = (x as isize + dx, y as isize + dy);
                if nx < 0 || ny < 0 || nx >= w as isize || ny >= h as isize {
                    continue;
                }
                let neighbour = z[ny as usize * w + nx as usize];
                let dz = neighbour - centre;
                // Also false for background (non-finite) neighbours.
                if dz.abs() <= max_dz {
                    let weight = spatial * (dz * dz * range_scale).exp();
                    // Accumulate the offset from the centre: keeps f32 precision at large depths.
                    sum += weight * dz;
                    weight_sum += weight;
                }
            }
            // The centre itself has weight 1, so weight_sum ≥ 1.
            *o = centre + sum / weight_sum;
        }
    });
    DepthImage { width: w, height: h, depth }
}

#[cfg(test)]
mod tests {
    use super::super::test_images::{image, noise, noisy_plane, rms_error};
    use super::super::total_variation;
    use super::*;

    #[test]
    fn reduces_plane_noise() {
        let (noisy, truth) = noisy_plane(64, 64, 0.05, 1);
        let smoothed = smooth_bilateral(&noisy, 2.0, 0.1);
        // Away from the image border, where the window is whole (the plane's slope biases a cut window).
        let inner = |x: usize, y: usize| (4..60).contains(&x) && (4..60).contains(&y);
        let (before, after) = (rms_error(&noisy, &truth, inner), rms_error(&smoothed, &truth, inner));
        // Measured: 0.0291 → 0.0079 (3.7×).
        assert!(after * 3.0 < before, "RMS error {before} → {after}");
        assert!(total_variation(&smoothed) * 2.0 < total_variation(&noisy));
    }

    #[test]
    fn keeps_a_step_and_the_background() {
        // Depth 2 left of x = 32, 3 right of it, ±0.05 noise, background in the top rows.
        let truth = |x: usize, _: usize| if x < 32 { 2.0 } else { 3.0 };
        let noisy = image(64, 64, |x, y| (y >= 8).then(|| truth(x, y) + 0.05 * noise(x, y, 2)));
        let smoothed = smooth_bilateral(&noisy, 2.0, 0.1);
        let far_from_edge = |x: usize, _: usize| !(29..35).contains(&x);
        let after = rms_error(&smoothed, truth, far_from_edge);
        // Measured: 0.0288 → 0.0057.
        assert!(after < 0.5 * rms_error(&noisy, truth, far_from_edge), "RMS error {after}");
        for (i, (&z, &input)) in smoothed.depth.iter().zip(&noisy.depth).enumerate() {
            let (x, y) = (i % 64, i / 64);
            if y < 8 {
                assert_eq!(z.to_bits(), input.to_bits());
            } else {
                assert!((z - truth(x, y)).abs() < 0.06, "pixel ({x}, {y}) at {z}");
            }
        }
    }

    #[test]
    fn constant_image_is_a_fixed_point() {
        let flat = image(16, 16, |x, y| (x * y > 3).then_some(7.5));
        assert_eq!(smooth_bilateral(&flat, 1.5, 0.01), flat);
    }
}
