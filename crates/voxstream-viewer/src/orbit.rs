//! The viewer's camera controller: orbit around a target, pan, zoom (dolly) and fly, in the spherical coordinates
//! of the eye around the target, about the camera's own up axis (+y for the built-in scenes, +z for stores).
//!
//! It converts to and from the renderer's [`Camera`], so a view saved from the window is the `Camera` that
//! `voxstream render --camera` reads.

use glam::DVec3;
use voxstream_render::Camera;

/// Pitch is kept this far from the poles (degrees), where the orbit's frame would degenerate.
const MAX_PITCH_DEGREES: f64 = 89.0;

/// An orbiting camera: the eye at `distance` from `target`, in direction (`yaw`, `pitch`) about `up`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OrbitCamera {
    /// The point looked at and orbited.
    pub target: DVec3,
    /// Eye-to-target distance (world units), positive.
    pub distance: f64,
    /// Angle about `up`, radians, measured in the plane perpendicular to `up` from [`OrbitCamera::reference_axes`]'s
    /// first axis.
    pub yaw: f64,
    /// Angle above the plane perpendicular to `up`, radians, within ±89°.
    pub pitch: f64,
    /// The world's up axis (unit length).
    pub up: DVec3,
    /// Vertical field of view, degrees.
    pub fov: f64,
}

impl OrbitCamera {
    /// The orbit that reproduces `camera` (whose eye and target differ and whose up is not along the view).
    pub fn from_camera(camera: &Camera) -> OrbitCamera {
        let up = DVec3::from(camera.up).try_normalize().unwrap_or(DVec3::Y);
        let target = DVec3::from(camera.target);
        let offset = DVec3::from(camera.eye) - target;
        let distance = offset.length().max(1e-9);
        let direction = offset / distance;
        let (first, second) = reference_axes(up);
        let pitch = direction.dot(up).clamp(-1.0, 1.0).asin();
        let yaw = direction.dot(second).atan2(direction.dot(first));
        let limit = MAX_PITCH_DEGREES.to_radians();
        OrbitCamera { target, distance, yaw, pitch: pitch.clamp(-limit, limit), up, fov: camera.fov }
    }

    /// The renderer's camera.
    pub fn to_camera(&self) -> Camera {
        let eye = self.target + self.direction_to_eye() * self.distance;
        Camera { eye: eye.to_array(), target: self.target.to_array(), up: self.up.to_array(), fov: self.fov }
    }

    /// Unit vector from the target towards the eye.
    pub fn direction_to_eye(&self) -> DVec3 {
        let (first, second) = reference_axes(self.up);
        (first * self.yaw.cos() + second * self.yaw.sin()) * self.pitch.cos() + self.up * self.pitch.sin()
    }

    /// Turns the eye about the target: `yaw_degrees` about the up axis, `pitch_degrees` towards it.
    pub fn orbit(&mut self, yaw_degrees: f64, pitch_degrees: f64) {
        self.yaw = (self.yaw + yaw_degrees.to_radians()).rem_euclid(std::f64::consts::TAU);
        let limit = MAX_PITCH_DEGREES.to_radians();
        self.pitch = (self.pitch + pitch_degrees.to_radians()).clamp(-limit, limit);
    }

    /// Moves eye and target together across the view: `right` and `up` in fractions of the visible height at the
    /// target's depth (so a drag across the whole image height moves the scene by as much).
    pub fn pan(&mut self, right: f64, up: f64) {
        let (screen_right, screen_up) = self.screen_axes();
        let visible_height = 2.0 * self.distance * (self.fov.to_radians() * 0.5).tan();
        self.target += (screen_right * right + screen_up * up) * visible_height;
    }

    /// Moves the eye towards the target (`factor` < 1) or away (`factor` > 1); the target stays.
    pub fn zoom(&mut self, factor: f64) {
        if factor.is_finite() && factor > 0.0 {
            self.distance = (self.distance * factor).clamp(1e-9, 1e9);
        }
    }

    /// Moves eye and target together: `forward` along the view, `right` and `up` across it (world units).
    pub fn fly(&mut self, forward: f64, right: f64, up: f64) {
        let (screen_right, screen_up) = self.screen_axes();
        self.target += -self.direction_to_eye() * forward + screen_right * right + screen_up * up;
    }

    /// The image's right and up directions in the world.
    fn screen_axes(&self) -> (DVec3, DVec3) {
        let forward = -self.direction_to_eye();
        let right = forward.cross(self.up).try_normalize().unwrap_or(DVec3::X);
        (right, right.cross(forward))
    }
}

/// Two unit axes perpendicular to `up` and to each other, chosen the same way for the same `up`: the yaw's zero and
/// quarter turn.
pub fn reference_axes(up: DVec3) -> (DVec3, DVec3) {
    // The world axis least aligned with `up`, projected into the plane perpendicular to it.
    let candidates = [DVec3::X, DVec3::Y, DVec3::Z];
    let least = candidates.into_iter().min_by(|a, b| a.dot(up).abs().total_cmp(&b.dot(up).abs())).unwrap_or(DVec3::X);
    let first = (least - up * least.dot(up)).normalize();
    let second = up.cross(first);
    (first, second)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: [f64; 3], b: [f64; 3]) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-9)
    }

    fn scene_camera() -> Camera {
        Camera { eye: [1.95, 1.55, 2.35], target: [0.5, 0.5, 0.5], up: [0.0, 1.0, 0.0], fov: 40.0 }
    }

    #[test]
    fn a_camera_round_trips_through_the_orbit() {
        for camera in
            [scene_camera(), Camera { eye: [3.0, -4.0, 2.0], target: [0.2, 0.1, 0.4], up: [0.0, 0.0, 1.0], fov: 30.0 }]
        {
            let back = OrbitCamera::from_camera(&camera).to_camera();
            assert!(close(back.eye, camera.eye), "{:?} != {:?}", back.eye, camera.eye);
            assert_eq!(back.target, camera.target);
            assert_eq!(back.fov, camera.fov);
        }
    }

    #[test]
    fn a_full_turn_returns_and_a_half_turn_mirrors_the_eye_about_the_up_axis() {
        let start = OrbitCamera::from_camera(&scene_camera());
        let mut turned = start;
        for _ in 0..8 {
            turned.orbit(45.0, 0.0);
        }
        assert!(close(turned.to_camera().eye, start.to_camera().eye));
        let mut half = start;
        half.orbit(180.0, 0.0);
        let (a, b) = (start.to_camera().eye, half.to_camera().eye);
        // About +y through the target (0.5, 0.5, 0.5): x and z mirror, y stays.
        assert!((a[0] + b[0] - 1.0).abs() < 1e-9 && (a[2] + b[2] - 1.0).abs() < 1e-9 && (a[1] - b[1]).abs() < 1e-9);
    }

    #[test]
    fn pitch_stops_short_of_the_pole() {
        let mut orbit = OrbitCamera::from_camera(&scene_camera());
        orbit.orbit(0.0, 500.0);
        assert!((orbit.pitch.to_degrees() - MAX_PITCH_DEGREES).abs() < 1e-9);
        assert!(orbit.to_camera().frame(8, 8).is_ok(), "the camera stays valid at the limit");
    }

    #[test]
    fn pan_moves_target_and_eye_together_across_the_view_and_zoom_keeps_the_target() {
        let start = OrbitCamera::from_camera(&scene_camera());
        let mut panned = start;
        panned.pan(0.25, -0.1);
        let moved = panned.target - start.target;
        assert!(moved.length() > 0.0);
        assert!(moved.dot(start.direction_to_eye()).abs() < 1e-9, "pan stays in the image plane");
        assert!((panned.distance - start.distance).abs() < 1e-12);
        let mut zoomed = start;
        zoomed.zoom(0.5);
        assert_eq!(zoomed.target, start.target);
        assert!((zoomed.distance - start.distance * 0.5).abs() < 1e-12);
        zoomed.zoom(f64::NAN);
        zoomed.zoom(-1.0);
        assert!((zoomed.distance - start.distance * 0.5).abs() < 1e-12, "bad factors are ignored");
    }

    #[test]
    fn flying_forward_moves_along_the_view() {
        let start = OrbitCamera::from_camera(&scene_camera());
        let mut flown = start;
        flown.fly(0.1, 0.0, 0.0);
        let step = DVec3::from(flown.to_camera().eye) - DVec3::from(start.to_camera().eye);
        assert!((step + start.direction_to_eye() * 0.1).length() < 1e-9);
    }
}
