//! Measuring popping and seams: how much an interactive image sequence changes for reasons the camera does not
//! explain, and how much its images differ from the exact ones at brick-like discontinuities.
//!
//! Thiele et al. (seed 003, `../shared/notes/thiele-lod-blending.md` §"Numbers and evaluation") show popping and
//! boundary artifacts as pictures; these two numbers make them comparable between runs:
//!
//! - **Popping** between interactive frames `k` and `k+1` at cameras `c_k`, `c_{k+1}`: per pixel
//!   `max(0, |I_{k+1} − I_k| − |C_{k+1} − C_k|)`, where `C` are the converged (exact) images at the same cameras, so
//!   that what camera motion explains is subtracted; averaged over pixels and the three colour channels. A sequence
//!   reports the mean over frame pairs and the 99th percentile.
//! - **Seams** of interactive frame `k`: the edges the interactive image has and the converged one does not, per
//!   pixel `max(0, |∂x I_k| − |∂x C_k|) + max(0, |∂y I_k| − |∂y C_k|)` (forward differences), averaged. A seam between
//!   bricks drawn at different levels is such an edge; so is a brick boundary where a finer brick meets a coarser
//!   stand-in. (It is taken over every pixel, not only those on projected brick boundaries: a spurious edge
//!   elsewhere is an artifact too.)
//!
//! - **Floor** of a sequence's popping: the least mean popping that any sequence with the same first image, the same
//!   number of frames and the same frame `S` from which on it shows the converged images (or, for a sequence that
//!   never settles, the same last image, with `S` its last frame) could have against the same converged images: per
//!   pixel
//!   `max(0, |I_S − I_first| − Σ_{k<S} |C_{k+1} − C_k|)`, summed over pixels and channels and divided by the same
//!   count as the mean. (By the triangle inequality,
//!   `Σ_{k<S} max(0, |ΔI_k| − |ΔC_k|) ≥ |I_S − I_first| − Σ_{k<S} |ΔC_k|` for every pixel, and the pairs after `S`
//!   pop no less than 0.) Blending spreads a change over frames but cannot undo it: a cold start must still get
//!   from its first image to the converged one, so the mean popping of a blended sequence that settles when it
//!   settles is bounded below by this floor, however the fades are shaped; only changes that reverse (a level's
//!   shading replaced by the next one's and back), and changes hidden in the camera's own, are above it and can be
//!   saved. Ending the sum at `S` rather than at the last frame leaves out the motion after the sequence settled,
//!   which no blending can hide anything in: on a camera path whose data all arrive in its first frames (an orbit
//!   of a cold start), the floor is that of the cold start alone, not about 0.
//!
//! All are in 8-bit levels (0–255) of the written images. A sequence is measured from its first image that shows
//! anything: a cold start's first frames are empty until the root arrives, and the root's arrival is the image
//! appearing, not a level changing.

/// An 8-bit RGB image as written: `width × height × 3` bytes, row-major.
#[derive(Clone, Copy, Debug)]
pub struct Rgb8<'a> {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// The bytes.
    pub bytes: &'a [u8],
}

/// Popping between two consecutive interactive frames, given the converged frames at the same cameras (8-bit
/// levels, averaged over pixels and channels).
pub fn frame_popping(previous: Rgb8<'_>, next: Rgb8<'_>, previous_exact: Rgb8<'_>, next_exact: Rgb8<'_>) -> f64 {
    let n = previous.bytes.len().min(next.bytes.len()).min(previous_exact.bytes.len()).min(next_exact.bytes.len());
    if n == 0 {
        return 0.0;
    }
    let mut total = 0u64;
    for i in 0..n {
        let seen = previous.bytes[i].abs_diff(next.bytes[i]);
        let explained = previous_exact.bytes[i].abs_diff(next_exact.bytes[i]);
        total += seen.saturating_sub(explained) as u64;
    }
    total as f64 / n as f64
}

/// Seam error of an interactive frame against the converged frame at the same camera (8-bit levels per pixel and
/// channel).
pub fn seam_error(frame: Rgb8<'_>, exact: Rgb8<'_>) -> f64 {
    let (w, h) = (frame.width as usize, frame.height as usize);
    if w < 2 || h < 2 || frame.bytes.len() < w * h * 3 || exact.bytes.len() < w * h * 3 {
        return 0.0;
    }
    let at = |image: &[u8], x: usize, y: usize, c: usize| image[(y * w + x) * 3 + c];
    let mut total = 0u64;
    for y in 0..h - 1 {
        for x in 0..w - 1 {
            for c in 0..3 {
                let here = at(frame.bytes, x, y, c);
                let exact_here = at(exact.bytes, x, y, c);
                let dx = here.abs_diff(at(frame.bytes, x + 1, y, c));
                let dy = here.abs_diff(at(frame.bytes, x, y + 1, c));
                let exact_dx = exact_here.abs_diff(at(exact.bytes, x + 1, y, c));
                let exact_dy = exact_here.abs_diff(at(exact.bytes, x, y + 1, c));
                total += dx.saturating_sub(exact_dx) as u64 + dy.saturating_sub(exact_dy) as u64;
            }
        }
    }
    total as f64 / ((w - 1) * (h - 1) * 3) as f64
}

/// Popping and seams of a whole interactive sequence.
#[derive(Clone, Debug, Default, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct PoppingSummary {
    /// Leading frames left out because they show nothing (a cold start before the root arrived).
    pub empty_frames_skipped: usize,
    /// Frame pairs measured.
    pub frame_pairs: usize,
    /// Mean popping over frame pairs, 8-bit levels.
    pub popping_mean: f64,
    /// 99th percentile of popping over frame pairs.
    pub popping_p99: f64,
    /// Largest popping of a frame pair.
    pub popping_max: f64,
    /// The least mean popping any sequence of as many frames from the same first image, settled on the converged
    /// images from the same frame on (or ending at the same last image, if it never settles), could have against the
    /// same converged images (see the module docs), 8-bit levels.
    pub popping_floor: f64,
    /// The frame (counted after the empty ones) from which the sequence shows the converged images to its end, if
    /// it does.
    pub settled_from: Option<usize>,
    /// Mean seam error over frames, 8-bit levels.
    pub seam_mean: f64,
    /// Popping of each frame pair (`k−1`, `k`), in order.
    pub popping_per_frame: Vec<f64>,
    /// Seam error of each frame, in order.
    pub seam_per_frame: Vec<f64>,
}

impl PoppingSummary {
    /// Summarises an interactive sequence `frames` against the converged images `exact` at the same cameras (both
    /// in order; the shorter length counts).
    pub fn measure(frames: &[Rgb8<'_>], exact: &[Rgb8<'_>]) -> PoppingSummary {
        let count = frames.len().min(exact.len());
        let skipped = frames[..count].iter().take_while(|f| f.bytes.iter().all(|&b| b == 0)).count();
        let (frames, exact) = (&frames[skipped..count], &exact[skipped..count]);
        let count = count - skipped;
        let mut popping: Vec<f64> =
            (1..count).map(|k| frame_popping(frames[k - 1], frames[k], exact[k - 1], exact[k])).collect();
        let seams: Vec<f64> = (0..count).map(|k| seam_error(frames[k], exact[k])).collect();
        let mean =
            |values: &[f64]| if values.is_empty() { 0.0 } else { values.iter().sum::<f64>() / values.len() as f64 };
        let popping_mean = mean(&popping);
        let seam_mean = mean(&seams);
        let popping_per_frame = popping.clone();
        // A run that showed nothing has not settled.
        let settled_from = if count == 0 { None } else { settled_from(frames, exact) };
        let popping_floor = if count < 2 { 0.0 } else { popping_floor(frames, exact, settled_from) };
        popping.sort_by(f64::total_cmp);
        let percentile = |p: f64| {
            if popping.is_empty() {
                0.0
            } else {
                popping[((popping.len() - 1) as f64 * p).ceil() as usize]
            }
        };
        PoppingSummary {
            empty_frames_skipped: skipped,
            frame_pairs: popping.len(),
            popping_mean,
            popping_p99: percentile(0.99),
            popping_max: percentile(1.0),
            popping_floor,
            settled_from,
            seam_mean,
            popping_per_frame,
            seam_per_frame: seams,
        }
    }
}

/// The first frame from which every frame of `frames` is its converged image in `exact`, if any (the same length).
fn settled_from(frames: &[Rgb8<'_>], exact: &[Rgb8<'_>]) -> Option<usize> {
    let unsettled = frames.iter().zip(exact).rposition(|(frame, exact)| frame.bytes != exact.bytes);
    match unsettled {
        None => Some(0),
        Some(k) if k + 1 < frames.len() => Some(k + 1),
        Some(_) => None,
    }
}

/// The floor of a sequence's mean popping (module docs): `frames` and `exact` of the same length, at least 2;
/// `settled` is [`settled_from`] of them.
fn popping_floor(frames: &[Rgb8<'_>], exact: &[Rgb8<'_>], settled: Option<usize>) -> f64 {
    // The frame the sum ends at: where the sequence settles, else its last.
    let end = settled.unwrap_or(frames.len() - 1);
    let (first, settled) = (frames[0].bytes, frames[end].bytes);
    let n = first.len();
    // Images of different sizes have no common per-pixel path: 0 is a floor still (a trivial one).
    if n == 0 || frames.iter().chain(exact).any(|f| f.bytes.len() != n) {
        return 0.0;
    }
    let mut total = 0u64;
    for i in 0..n {
        let explained: u64 =
            exact[..=end].windows(2).map(|pair| pair[0].bytes[i].abs_diff(pair[1].bytes[i]) as u64).sum();
        total += (first[i].abs_diff(settled[i]) as u64).saturating_sub(explained);
    }
    total as f64 / (n as f64 * (frames.len() - 1) as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(bytes: &[u8], width: u32) -> Rgb8<'_> {
        Rgb8 { width, height: (bytes.len() / 3) as u32 / width, bytes }
    }

    #[test]
    fn change_explained_by_the_camera_is_not_popping() {
        let a = [10u8, 10, 10, 200, 200, 200];
        let b = [20u8, 20, 20, 200, 200, 200];
        // The exact images change the same way: nothing unexplained.
        assert_eq!(frame_popping(image(&a, 2), image(&b, 2), image(&a, 2), image(&b, 2)), 0.0);
        // The exact images do not change: the whole change is popping, 10 levels on half of the values.
        assert_eq!(frame_popping(image(&a, 2), image(&b, 2), image(&a, 2), image(&a, 2)), 5.0);
        // Less change than the camera explains is not negative popping.
        let c = [0u8, 0, 0, 255, 255, 255];
        assert_eq!(frame_popping(image(&a, 2), image(&a, 2), image(&a, 2), image(&c, 2)), 0.0);
    }

    #[test]
    fn a_spurious_edge_is_a_seam_and_an_exact_edge_is_not() {
        // 3×2 images: the exact one is flat, the interactive one has a step between columns 0 and 1.
        let flat = [50u8; 18];
        let mut step = flat;
        for y in 0..2 {
            for c in 0..3 {
                step[(y * 3) * 3 + c] = 110;
            }
        }
        let seam = seam_error(image(&step, 3), image(&flat, 3));
        // (w−1)(h−1)·3 = 6 terms; the step shows in the x difference at (0,0) for three channels: 3·60 / 6.
        assert_eq!(seam, 30.0);
        assert_eq!(seam_error(image(&step, 3), image(&step, 3)), 0.0);
        assert_eq!(seam_error(image(&flat, 3), image(&step, 3)), 0.0, "a missing edge is not a seam");
    }

    #[test]
    fn the_summary_reports_mean_and_tail() {
        // Two empty frames (left out), then 0 → 30 → 30 → 0 against an exact image that stays at 0.
        let frames: Vec<[u8; 3]> = vec![[0; 3], [0; 3], [1; 3], [31; 3], [31; 3], [1; 3]];
        let exact = [[1u8; 3]; 6];
        let views: Vec<Rgb8<'_>> = frames.iter().map(|f| image(f, 1)).collect();
        let exact_views: Vec<Rgb8<'_>> = exact.iter().map(|f| image(f, 1)).collect();
        let summary = PoppingSummary::measure(&views, &exact_views);
        assert_eq!(summary.empty_frames_skipped, 2);
        assert_eq!(summary.frame_pairs, 3);
        assert_eq!(summary.popping_mean, 20.0);
        assert_eq!(summary.popping_max, 30.0);
        assert_eq!(summary.popping_p99, 30.0);
        // It ends where it began: a sequence could have stayed put.
        assert_eq!(summary.popping_floor, 0.0);
    }

    #[test]
    fn the_floor_is_the_straight_way_from_first_to_last_image() {
        // 10 → 40 → 20 → 30 at rest: 30 + 20 + 10 over three pairs; going straight from 10 to 30 would pop 20.
        let at_rest = |values: &[u8]| {
            let frames: Vec<[u8; 3]> = values.iter().map(|&v| [v; 3]).collect();
            let exact = vec![[30u8; 3]; values.len()];
            let views: Vec<Rgb8<'_>> = frames.iter().map(|f| image(f, 1)).collect();
            let exact_views: Vec<Rgb8<'_>> = exact.iter().map(|f| image(f, 1)).collect();
            PoppingSummary::measure(&views, &exact_views)
        };
        let wandering = at_rest(&[10, 40, 20, 30]);
        assert_eq!(wandering.popping_mean, 20.0);
        assert!((wandering.popping_floor - 20.0 / 3.0).abs() < 1e-12);
        // A monotone sequence between the same images reaches the floor: it cannot be beaten.
        let straight = at_rest(&[10, 17, 24, 30]);
        assert_eq!(straight.popping_mean, straight.popping_floor);
        // Change the camera explains lowers the floor: the exact images move by 15 and back.
        let frames = [[10u8; 3], [30; 3], [30; 3]];
        let exact = [[0u8; 3], [15; 3], [0; 3]];
        let views: Vec<Rgb8<'_>> = frames.iter().map(|f| image(f, 1)).collect();
        let exact_views: Vec<Rgb8<'_>> = exact.iter().map(|f| image(f, 1)).collect();
        let moving = PoppingSummary::measure(&views, &exact_views);
        assert_eq!(moving.popping_mean, 2.5);
        assert_eq!(moving.popping_floor, 0.0, "20 levels of change, 30 explained");
        // A sequence that settles before the camera moves: the motion after it settled hides nothing. 10 → 30 at
        // rest, then the exact images move by 40 and back; the floor over the whole path would be 0.
        let settling_frames = [[10u8; 3], [20; 3], [30; 3], [70; 3], [30; 3]];
        let settling_exact = [[30u8; 3], [30; 3], [30; 3], [70; 3], [30; 3]];
        let settling_views: Vec<Rgb8<'_>> = settling_frames.iter().map(|f| image(f, 1)).collect();
        let settling_exact_views: Vec<Rgb8<'_>> = settling_exact.iter().map(|f| image(f, 1)).collect();
        let settling = PoppingSummary::measure(&settling_views, &settling_exact_views);
        assert_eq!(settling.settled_from, Some(2));
        assert_eq!(settling.popping_mean, 20.0 / 4.0);
        assert_eq!(settling.popping_floor, 20.0 / 4.0, "the straight way from 10 to 30, over the four pairs");
        assert_eq!(moving.settled_from, None);
        // Exact from the first frame: settled at once, nothing to bound. Nothing shown: not settled.
        let exact_all = PoppingSummary::measure(&settling_exact_views, &settling_exact_views);
        assert_eq!((exact_all.settled_from, exact_all.popping_floor), (Some(0), 0.0));
        let empty = [[0u8; 3]; 3];
        let empty_views: Vec<Rgb8<'_>> = empty.iter().map(|f| image(f, 1)).collect();
        assert_eq!(PoppingSummary::measure(&empty_views, &settling_exact_views[..3]).settled_from, None);
        // Images of different sizes: only the trivial floor.
        let small = [9u8; 3];
        let mixed = [image(&frames[0], 1), image(&frames[1], 1), Rgb8 { width: 1, height: 1, bytes: &small[..2] }];
        assert_eq!(popping_floor(&mixed, &views, None), 0.0);
    }
}
