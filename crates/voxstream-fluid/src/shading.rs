//! Deferred shading of the fluid (Reichl §6.5, Fig. 6.5): the caster's depth image, smoothed in screen space or
//! not, gives positions and normals (central differences, the one-sided difference across a depth jump); the
//! surface is lit by a headlight and the foam composited in front of it.

use glam::DVec3;
use voxstream_render::{CameraFrame, Image};

use crate::sphere_caster::RaySample;

/// Colour of the fluid's surface (linear RGB).
pub const WATER: [f64; 3] = [0.22, 0.48, 0.82];

/// Colour of foam.
pub const FOAM: [f64; 3] = [0.95, 0.97, 1.0];

/// The depth image of a frame: view depth (distance along the view direction) per pixel, `f32::INFINITY` where no
/// sphere was hit.
pub fn view_depth(samples: &[RaySample], frame: &CameraFrame, width: u32, height: u32) -> Vec<f32> {
    let mut depth = vec![f32::INFINITY; samples.len()];
    for y in 0..height {
        for x in 0..width {
            let i = (y * width + x) as usize;
            let s = samples[i];
            if s.t.is_finite() {
                let dir = frame.direction(x, y, width, height);
                depth[i] = (s.t * dir.dot(frame.forward)) as f32;
            }
        }
    }
    depth
}

/// The world position seen at pixel `(x, y)` at view depth `z` (the inverse of [`view_depth`]).
#[inline]
pub fn unproject(frame: &CameraFrame, x: i64, y: i64, z: f64, width: u32, height: u32) -> DVec3 {
    let sx = 2.0 * (x as f64 + 0.5) / f64::from(width) - 1.0;
    let sy = 1.0 - 2.0 * (y as f64 + 0.5) / f64::from(height);
    frame.eye + (frame.forward + frame.right * sx + frame.up * sy) * z
}

/// Normals from a depth image by central differences: along each axis the difference to the neighbour with the
/// smaller depth change (so a silhouette does not bend the normal), or the one neighbour in the foreground.
/// `None` where neither neighbour along an axis is foreground.
pub fn normals_from_depth(depth: &[f32], frame: &CameraFrame, width: u32, height: u32) -> Vec<Option<DVec3>> {
    let (w, h) = (i64::from(width), i64::from(height));
    let at = |x: i64, y: i64| -> Option<f64> {
        if x < 0 || y < 0 || x >= w || y >= h {
            return None;
        }
        let z = depth[(y * w + x) as usize];
        z.is_finite().then_some(f64::from(z))
    };
    let mut out = vec![None; depth.len()];
    for y in 0..h {
        for x in 0..w {
            let Some(z) = at(x, y) else { continue };
            let p = unproject(frame, x, y, z, width, height);
            let side = |dx: i64, dy: i64| -> Option<DVec3> {
                let forward =
                    at(x + dx, y + dy).map(|zz| (zz, unproject(frame, x + dx, y + dy, zz, width, height) - p));
                let back = at(x - dx, y - dy).map(|zz| (zz, p - unproject(frame, x - dx, y - dy, zz, width, height)));
                match (forward, back) {
                    (Some(f), Some(b)) => Some(if (f.0 - z).abs() <= (b.0 - z).abs() { f.1 } else { b.1 }),
                    (Some(f), None) => Some(f.1),
                    (None, Some(b)) => Some(b.1),
                    (None, None) => None,
                }
            };
            if let (Some(du), Some(dv)) = (side(1, 0), side(0, 1)) {
                let mut n = du.cross(dv).normalize_or_zero();
                if n.dot(frame.eye - p) < 0.0 {
                    n = -n;
                }
                if n != DVec3::ZERO {
                    out[(y * w + x) as usize] = Some(n);
                }
            }
        }
    }
    out
}

/// Shades a frame: `depth` (smoothed or not) gives the normals where it is smooth enough to, the spheres' own
/// normals elsewhere (or everywhere when `sphere_normals`).
pub fn shade(
    samples: &[RaySample],
    depth: &[f32],
    frame: &CameraFrame,
    width: u32,
    height: u32,
    sphere_normals: bool,
) -> Image {
    let normals =
        if sphere_normals { vec![None; depth.len()] } else { normals_from_depth(depth, frame, width, height) };
    let forward = frame.forward;
    let right = frame.right.normalize();
    let up = frame.up.normalize();
    // A headlight a little above and left of the eye.
    let light = (-forward + up * 0.35 - right * 0.25).normalize();
    let half = (light - forward).normalize();
    let mut image = Image::new(width, height);
    for (i, (s, pixel)) in samples.iter().zip(image.pixels.iter_mut()).enumerate() {
        let foam = f64::from(s.foam).clamp(0.0, 1.0);
        let mut colour = [0.0; 3];
        let mut coverage = 0.0;
        if depth[i].is_finite() {
            let n = normals[i].unwrap_or_else(|| DVec3::from(s.normal.map(f64::from)));
            let diffuse = n.dot(light).max(0.0);
            let specular = n.dot(half).max(0.0).powi(48);
            for c in 0..3 {
                colour[c] = WATER[c] * (0.22 + 0.78 * diffuse) + 0.45 * specular;
            }
            coverage = 1.0;
        }
        for c in 0..3 {
            colour[c] = foam * FOAM[c] + (1.0 - foam) * colour[c];
        }
        coverage = foam + (1.0 - foam) * coverage;
        *pixel = [colour[0] as f32, colour[1] as f32, colour[2] as f32, coverage as f32];
    }
    image
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxstream_render::Camera;

    #[test]
    fn a_plane_seen_at_an_angle_gets_its_own_normal_from_depth() {
        let camera = Camera { eye: [0.0, 0.0, 5.0], target: [0.0; 3], up: [0.0, 1.0, 0.0], fov: 40.0 };
        let (w, h) = (64u32, 48u32);
        let frame = camera.frame(w, h).unwrap();
        // The plane through the origin with normal (0, 0.6, 0.8) (facing the camera, tilted up).
        let normal = DVec3::new(0.0, 0.6, 0.8);
        let mut depth = vec![f32::INFINITY; (w * h) as usize];
        for y in 0..h {
            for x in 0..w {
                let dir = frame.direction(x, y, w, h);
                let t = -(frame.eye.dot(normal)) / dir.dot(normal);
                depth[(y * w + x) as usize] = (t * dir.dot(frame.forward)) as f32;
            }
        }
        // A hole: its neighbours fall back to one-sided differences.
        depth[(20 * w + 30) as usize] = f32::INFINITY;
        let normals = normals_from_depth(&depth, &frame, w, h);
        for (i, n) in normals.iter().enumerate() {
            if depth[i].is_finite() {
                let n = n.expect("every foreground pixel has a neighbour on each axis");
                assert!((n - normal).length() < 1e-3, "{i}: {n:?}");
            } else {
                assert!(n.is_none());
            }
        }
    }

    #[test]
    fn foam_is_composited_over_the_surface_and_alone_over_nothing() {
        let camera = Camera { eye: [0.0, 0.0, 5.0], target: [0.0; 3], up: [0.0, 1.0, 0.0], fov: 40.0 };
        let frame = camera.frame(2, 1).unwrap();
        let samples = [
            RaySample { t: 5.0, normal: [0.0, 0.0, 1.0], foam: 0.5, level: 0 },
            RaySample { t: f64::INFINITY, normal: [0.0; 3], foam: 0.5, level: 0 },
        ];
        let depth = view_depth(&samples, &frame, 2, 1);
        let image = shade(&samples, &depth, &frame, 2, 1, true);
        let [surface, air] = [image.pixels[0], image.pixels[1]];
        assert_eq!(surface[3], 1.0);
        assert_eq!(air[3], 0.5);
        assert!((air[0] - 0.5 * FOAM[0] as f32).abs() < 1e-6);
        // Half foam brightens the blue surface's red channel.
        assert!(surface[0] > 0.45 && surface[2] > surface[0]);
    }
}
