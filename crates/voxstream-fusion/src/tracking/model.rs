//! Vertex and normal maps: the model's ([`ModelView`], world space, from the depth the fusion renders of its
//! surface) and the frame's (camera space, one per level of a depth pyramid).

use glam::DVec3;
use rayon::prelude::*;

use crate::camera::{Intrinsics, Pose};

/// The relative depth step between a pixel and a neighbour beyond which [`ModelView::from_depth`] takes them for
/// different surfaces and gives the pixel no normal.
pub const MODEL_DEPTH_JUMP: f64 = 0.1;

/// What the fusion renders of its surface from a reference camera (seed 004 §8.2: the ray-cast, screen-space-smoothed
/// surface that each new frame is aligned with): a vertex and a normal per pixel, in world space.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelView {
    /// The reference camera, camera to world.
    pub pose: Pose,
    pub intrinsics: Intrinsics,
    /// `vertices[v * width + u]`: the surface point seen through pixel `(u, v)`, world space; `None` where the ray
    /// hit nothing.
    pub vertices: Vec<Option<DVec3>>,
    /// `normals[v * width + u]`: the unit surface normal there, world space, facing the reference camera; `None`
    /// where it could not be estimated (no vertex, a missing neighbour, a depth discontinuity).
    pub normals: Vec<Option<DVec3>>,
}

impl ModelView {
    /// The view of a rendered depth image (metres along the optical axis; 0 or non-finite = nothing there) seen from
    /// `pose`: vertices by unprojection, normals by central differences of the neighbouring vertices, skipped where a
    /// neighbour is missing or its depth differs from the pixel's by more than [`MODEL_DEPTH_JUMP`] of it.
    ///
    /// # Panics
    /// When `depth` does not hold `intrinsics.pixel_count()` values.
    pub fn from_depth(depth: &[f32], intrinsics: Intrinsics, pose: Pose) -> ModelView {
        let (vertices_camera, normals_camera) = vertex_normal_maps(depth, &intrinsics, MODEL_DEPTH_JUMP);
        let vertices = vertices_camera.into_par_iter().map(|p| p.map(|p| pose.transform_point3(p))).collect();
        let normals =
            normals_camera.into_par_iter().map(|n| n.map(|n| pose.transform_vector3(n).normalize())).collect();
        ModelView { pose, intrinsics, vertices, normals }
    }
}

/// The valid depth at index `i` (metres), `None` for 0, negative or non-finite values.
fn valid(depth: &[f32], i: usize) -> Option<f64> {
    let z = depth[i];
    (z > 0.0 && z.is_finite()).then_some(z as f64)
}

/// Camera-space vertices and unit normals (facing the camera) of a depth image; a normal needs the four neighbours,
/// each within `max_jump × z` of the pixel's depth `z`.
///
/// # Panics
/// When `depth` does not hold `k.pixel_count()` values.
pub(crate) fn vertex_normal_maps(
    depth: &[f32],
    k: &Intrinsics,
    max_jump: f64,
) -> (Vec<Option<DVec3>>, Vec<Option<DVec3>>) {
    assert_eq!(depth.len(), k.pixel_count(), "a depth image of {}×{} pixels", k.width, k.height);
    let (w, h) = (k.width as usize, k.height as usize);
    let vertices: Vec<Option<DVec3>> = (0..w * h)
        .into_par_iter()
        .map(|i| valid(depth, i).map(|z| k.unproject((i % w) as f64, (i / w) as f64, z)))
        .collect();
    let normals = (0..w * h)
        .into_par_iter()
        .map(|i| {
            let (u, v) = (i % w, i / w);
            if u == 0 || v == 0 || u + 1 >= w || v + 1 >= h {
                return None;
            }
            let p = vertices[i]?;
            let neighbours = [vertices[i - 1]?, vertices[i + 1]?, vertices[i - w]?, vertices[i + w]?];
            if neighbours.iter().any(|q| (q.z - p.z).abs() > max_jump * p.z) {
                return None;
            }
            let n = (neighbours[1] - neighbours[0]).cross(neighbours[3] - neighbours[2]).try_normalize()?;
            // Face the camera, which sits at the origin.
            Some(if n.dot(p) > 0.0 { -n } else { n })
        })
        .collect();
    (vertices, normals)
}

/// The next-coarser level of a depth pyramid: each 2×2 block becomes the mean of its valid depths that lie within
/// `max_jump` (relative) of the block's nearest one, so a block across a silhouette keeps the near surface instead of
/// a point floating between the two. The intrinsics are halved, keeping integer coordinates at pixel centres: the
/// coarse pixel `U` covers fine pixels `2U` and `2U + 1`, centred at `2U + 0.5`.
pub(crate) fn downsample(depth: &[f32], k: &Intrinsics, max_jump: f64) -> (Vec<f32>, Intrinsics) {
    let (w, h) = (k.width as usize, k.height as usize);
    let coarse = Intrinsics {
        width: k.width / 2,
        height: k.height / 2,
        fx: k.fx / 2.0,
        fy: k.fy / 2.0,
        cx: (k.cx - 0.5) / 2.0,
        cy: (k.cy - 0.5) / 2.0,
    };
    let (cw, ch) = (coarse.width as usize, coarse.height as usize);
    let out = (0..cw * ch)
        .into_par_iter()
        .map(|j| {
            let (u, v) = (2 * (j % cw), 2 * (j / cw));
            let block = [v * w + u, v * w + u + 1, (v + 1) * w + u, (v + 1) * w + u + 1];
            let zs = block.map(|i| valid(depth, i));
            let Some(nearest) = zs.iter().flatten().copied().reduce(f64::min) else { return 0.0 };
            let (sum, count) = zs
                .iter()
                .flatten()
                .filter(|&&z| z - nearest <= max_jump * nearest)
                .fold((0.0, 0), |(s, c), &z| (s + z, c + 1));
            (sum / count as f64) as f32
        })
        .collect();
    debug_assert!(h >= 2 * ch);
    (out, coarse)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DAffine3, DQuat};

    /// A 64×48 camera.
    const K: Intrinsics = Intrinsics { width: 64, height: 48, fx: 52.5, fy: 52.5, cx: 31.5, cy: 23.5 };

    /// The depth image of the plane `n · x = d` (camera space) seen by `k`.
    fn plane_depth(k: &Intrinsics, n: DVec3, d: f64) -> Vec<f32> {
        let mut depth = Vec::with_capacity(k.pixel_count());
        for v in 0..k.height {
            for u in 0..k.width {
                let ray = k.unproject(u as f64, v as f64, 1.0);
                depth.push((d / n.dot(ray)) as f32);
            }
        }
        depth
    }

    #[test]
    fn a_plane_gives_its_normal_facing_the_camera() {
        let n = DVec3::new(0.2, -0.3, -1.0).normalize();
        let depth = plane_depth(&K, -n, 2.0);
        let pose = DAffine3::from_rotation_translation(DQuat::from_rotation_y(0.4), DVec3::new(1.0, 2.0, 3.0));
        let view = ModelView::from_depth(&depth, K, pose);
        let n_world = pose.transform_vector3(n);
        let mut with_normal = 0;
        for (p, m) in view.vertices.iter().zip(&view.normals) {
            let p = p.expect("the plane fills the image");
            let p_camera = pose.inverse().transform_point3(p);
            assert!((-n.dot(p_camera) - 2.0).abs() < 1e-5, "vertex off the plane");
            if let Some(m) = m {
                with_normal += 1;
                assert!(m.dot(n_world) > 1.0 - 1e-9, "{m} vs {n_world}");
                assert!(m.dot(p - pose.translation) < 0.0, "faces the camera");
            }
        }
        assert_eq!(with_normal, (64 - 2) * (48 - 2), "every pixel off the border has a normal");
    }

    #[test]
    fn depth_jumps_and_holes_have_no_normal() {
        let mut depth = vec![1.0_f32; K.pixel_count()];
        for v in 0..48 {
            for u in 32..64 {
                depth[v * 64 + u] = 2.0;
            }
        }
        depth[10 * 64 + 10] = 0.0;
        let (vertices, normals) = vertex_normal_maps(&depth, &K, MODEL_DEPTH_JUMP);
        assert!(vertices[10 * 64 + 10].is_none());
        for i in [10 * 64 + 10, 10 * 64 + 9, 10 * 64 + 11, 9 * 64 + 10, 11 * 64 + 10, 20 * 64 + 31, 20 * 64 + 32] {
            assert!(normals[i].is_none(), "pixel {i}");
        }
        assert!(normals[20 * 64 + 30].is_some() && normals[20 * 64 + 33].is_some());
    }

    #[test]
    fn the_pyramid_keeps_points_on_the_surface() {
        let n = DVec3::new(0.1, 0.4, -1.0).normalize();
        let depth = plane_depth(&K, -n, 1.5);
        let (coarse, kc) = downsample(&depth, &K, MODEL_DEPTH_JUMP);
        assert_eq!((kc.width, kc.height, kc.cx, kc.cy), (32, 24, 15.5, 11.5));
        for v in 0..24 {
            for u in 0..32 {
                let p = kc.unproject(u as f64, v as f64, coarse[v * 32 + u] as f64);
                // Averaging depths of a slanted plane bends it by the curvature of 1/z only: far below a millimetre.
                assert!((-n.dot(p) - 1.5).abs() < 2e-4, "({u},{v}) is {} off", -n.dot(p) - 1.5);
            }
        }
        // A block across a silhouette keeps the near surface; an empty block stays empty.
        let mut edge = vec![0.0_f32; K.pixel_count()];
        edge[0] = 1.0;
        edge[1] = 3.0;
        edge[64] = 1.02;
        let (coarse, _) = downsample(&edge, &K, MODEL_DEPTH_JUMP);
        assert!((coarse[0] - 1.01).abs() < 1e-6, "{}", coarse[0]);
        assert_eq!(coarse[1], 0.0);
    }
}
