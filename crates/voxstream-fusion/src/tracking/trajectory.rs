//! Trajectory errors as the TUM RGB-D benchmark measures them (Sturm et al. 2012, "A benchmark for the evaluation of
//! RGB-D SLAM systems", §V): the absolute trajectory error after a rigid alignment, and the relative pose error over
//! a fixed step.

use glam::{DQuat, DVec3};

use super::linalg::symmetric_eigen;
use crate::camera::Pose;

/// The absolute trajectory error: the root-mean-square distance between the estimated and the true camera positions
/// after the rigid motion (no scale) that best aligns the estimated positions with the true ones, found in closed form
/// by Horn's quaternion method (Horn 1987). Pose `i` of each slice must be of the same frame; 0 for empty slices.
///
/// # Panics
/// When the slices differ in length.
pub fn ate_rmse(estimated: &[Pose], truth: &[Pose]) -> f64 {
    assert_eq!(estimated.len(), truth.len(), "one estimated pose per true pose");
    if estimated.is_empty() {
        return 0.0;
    }
    let p: Vec<DVec3> = estimated.iter().map(|pose| pose.translation).collect();
    let q: Vec<DVec3> = truth.iter().map(|pose| pose.translation).collect();
    let n = p.len() as f64;
    let (p_mean, q_mean) = (p.iter().sum::<DVec3>() / n, q.iter().sum::<DVec3>() / n);

    // The cross-covariance s[a][b] = Σ (p − p̄)_a (q − q̄)_b.
    let mut s = [[0.0; 3]; 3];
    for (pi, qi) in p.iter().zip(&q) {
        let (a, b) = ((*pi - p_mean).to_array(), (*qi - q_mean).to_array());
        for (row, ai) in s.iter_mut().zip(a) {
            for (x, bj) in row.iter_mut().zip(b) {
                *x += ai * bj;
            }
        }
    }
    // Horn's symmetric 4×4 matrix: its dominant eigenvector is the unit quaternion (w, x, y, z) of the rotation that
    // takes the centred estimated positions closest to the centred true ones.
    let [[sxx, sxy, sxz], [syx, syy, syz], [szx, szy, szz]] = s;
    let horn = [
        [sxx + syy + szz, syz - szy, szx - sxz, sxy - syx],
        [syz - szy, sxx - syy - szz, sxy + syx, szx + sxz],
        [szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy],
        [sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz],
    ];
    let (values, vectors) = symmetric_eigen(horn);
    let best = (0..4).max_by(|&i, &j| values[i].total_cmp(&values[j])).unwrap_or(0);
    let rotation = DQuat::from_xyzw(vectors[1][best], vectors[2][best], vectors[3][best], vectors[0][best]).normalize();

    let sum2: f64 = p.iter().zip(&q).map(|(pi, qi)| (rotation * (*pi - p_mean) + q_mean - *qi).length_squared()).sum();
    (sum2 / n).sqrt()
}

/// The relative pose error over a step of `delta` frames: the root-mean-square of the translations and of the
/// rotation angles of `(Q_i⁻¹ Q_{i+Δ})⁻¹ (P_i⁻¹ P_{i+Δ})`, estimated poses `P`, true poses `Q`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RelativePoseError {
    /// Metres.
    pub translation_rmse: f64,
    /// Radians.
    pub rotation_rmse: f64,
    /// The pose pairs compared.
    pub pairs: usize,
}

/// The relative pose error (drift) over a step of `delta` frames (the benchmark uses one second of frames); all zero
/// when there are no pairs that far apart.
///
/// # Panics
/// When the slices differ in length or `delta` is 0.
pub fn relative_pose_error(estimated: &[Pose], truth: &[Pose], delta: usize) -> RelativePoseError {
    assert_eq!(estimated.len(), truth.len(), "one estimated pose per true pose");
    assert!(delta > 0, "a step of at least one frame");
    let (mut t2, mut r2, mut pairs) = (0.0, 0.0, 0);
    for i in 0..estimated.len().saturating_sub(delta) {
        let moved = estimated[i].inverse() * estimated[i + delta];
        let truly = truth[i].inverse() * truth[i + delta];
        let error = truly.inverse() * moved;
        t2 += error.translation.length_squared();
        let angle = DQuat::from_mat3(&error.matrix3).normalize().angle_between(DQuat::IDENTITY);
        r2 += angle * angle;
        pairs += 1;
    }
    if pairs == 0 {
        return RelativePoseError { translation_rmse: 0.0, rotation_rmse: 0.0, pairs };
    }
    let n = pairs as f64;
    RelativePoseError { translation_rmse: (t2 / n).sqrt(), rotation_rmse: (r2 / n).sqrt(), pairs }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DAffine3;

    /// A camera on a helix, turning as it goes.
    fn helix(n: usize) -> Vec<Pose> {
        (0..n)
            .map(|i| {
                let s = i as f64 * 0.3;
                DAffine3::from_rotation_translation(
                    DQuat::from_euler(glam::EulerRot::YXZ, s, 0.1 * s.sin(), 0.05 * s),
                    DVec3::new(s.cos() * 1.5, 0.2 * s, s.sin() * 1.5),
                )
            })
            .collect()
    }

    fn rigid() -> DAffine3 {
        DAffine3::from_rotation_translation(
            DQuat::from_axis_angle(DVec3::new(1.0, -2.0, 0.5).normalize(), 2.3),
            DVec3::new(4.0, -1.0, 7.5),
        )
    }

    #[test]
    fn ate_of_a_rigidly_moved_copy_is_zero() {
        let truth = helix(40);
        let moved: Vec<Pose> = truth.iter().map(|p| rigid() * *p).collect();
        assert!(ate_rmse(&moved, &truth) < 1e-9, "{}", ate_rmse(&moved, &truth));
        assert!(ate_rmse(&truth, &moved) < 1e-9);
        // Without the alignment the copy is metres away: the zero is the alignment's doing.
        let unaligned =
            (moved.iter().zip(&truth).map(|(a, b)| (a.translation - b.translation).length_squared()).sum::<f64>()
                / 40.0)
                .sqrt();
        assert!(unaligned > 1.0);
    }

    #[test]
    fn ate_equals_a_perturbation_the_alignment_cannot_absorb() {
        // Every position twice, one copy pushed +δ along a direction, the other −δ: the perturbations cancel in the
        // mean and in the cross-covariance, so the best alignment is the identity and every position is δ off.
        let delta = 0.037;
        let direction = DVec3::new(0.3, -0.8, 0.5).normalize();
        let truth: Vec<Pose> = helix(20).into_iter().flat_map(|p| [p, p]).collect();
        let perturbed: Vec<Pose> = truth
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let sign = if i % 2 == 0 { 1.0 } else { -1.0 };
                DAffine3 { matrix3: p.matrix3, translation: p.translation + sign * delta * direction }
            })
            .collect();
        assert!((ate_rmse(&perturbed, &truth) - delta).abs() < 1e-9, "{}", ate_rmse(&perturbed, &truth));
        // Moving the whole perturbed trajectory rigidly changes nothing.
        let moved: Vec<Pose> = perturbed.iter().map(|p| rigid() * *p).collect();
        assert!((ate_rmse(&moved, &truth) - delta).abs() < 1e-9, "{}", ate_rmse(&moved, &truth));
        assert_eq!(ate_rmse(&[], &[]), 0.0);
    }

    #[test]
    fn rpe_measures_drift_per_step() {
        let truth = helix(30);
        let moved: Vec<Pose> = truth.iter().map(|p| rigid() * *p).collect();
        let same = relative_pose_error(&moved, &truth, 1);
        assert_eq!(same.pairs, 29);
        assert!(same.translation_rmse < 1e-9 && same.rotation_rmse < 1e-9, "{same:?}");

        // Each estimated step adds 5 mm along the camera's x axis and 0.5° about its y axis to the true step.
        let slip = DAffine3::from_rotation_translation(DQuat::from_rotation_y(0.5f64.to_radians()), DVec3::X * 0.005);
        let mut drifting = vec![truth[0]];
        for i in 0..29 {
            let step = truth[i].inverse() * truth[i + 1];
            drifting.push(drifting[i] * step * slip);
        }
        let rpe = relative_pose_error(&drifting, &truth, 1);
        assert!((rpe.translation_rmse - 0.005).abs() < 1e-9, "{rpe:?}");
        assert!((rpe.rotation_rmse - 0.5f64.to_radians()).abs() < 1e-9, "{rpe:?}");
        assert!(ate_rmse(&drifting, &truth) > 0.01, "drift accumulates into an absolute error");
    }
}
