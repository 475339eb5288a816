//! Synthetic RGB-D sequences with a known true surface, for measuring what the fusion recovers (seed 004 §8.2
//! evaluates on synthetic scans as well as on the TUM benchmark).
//!
//! A mesh is scaled so that its largest side is `object_size` metres and stood, centred, on a floor square (two
//! triangles) in a world whose z axis points up; the scene is the object and the floor. The camera orbits the object
//! at `radius` and `height` above the floor (bobbing up and down by `bob`), looking at the object's centre, over
//! `sweep_degrees`. Each frame's exact depth (along the optical axis) comes from ray casting the scene through a
//! [`TriangleBvh`], its colour from a procedural albedo (a checkerboard on the floor, hues over the object) lit by a
//! head light; then the [`NoiseModel`] makes the depth a Kinect's. Frames are 1/`frame_rate` apart and carry their
//! true pose.

use std::io::{BufWriter, Write};
use std::path::Path;

use glam::{DMat3, DQuat, DVec3};
use rayon::prelude::*;
use voxstream_geometry::formats::{read_geometry, RawGeometry};
use voxstream_geometry::triangle_bvh::TriangleBvh;
use voxstream_geometry::{GeometryError, TriangleMesh};

use super::noise::NoiseModel;
use super::tum::TumWriter;
use crate::camera::{Intrinsics, Pose};
use crate::frame::RgbdFrame;
use crate::FusionError;

/// How a synthetic sequence is made.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SyntheticSettings {
    /// The camera (default [`Intrinsics::TUM_DEFAULT`]).
    pub intrinsics: Intrinsics,
    /// Frames of the sequence, 1 to 100000 (default 300: ten seconds).
    pub frames: usize,
    /// The object's largest side, metres (0.5).
    pub object_size: f64,
    /// The side of the floor square under it, metres (3); at least `object_size`.
    pub floor_size: f64,
    /// Height of four walls around the floor (a room, as indoor scans see), metres; 0 (the default): no walls.
    pub walls: f64,
    /// The orbit's radius around the object's vertical axis, metres (1.2); more than `object_size / 2`.
    pub radius: f64,
    /// The camera's height above the floor, metres (0.5).
    pub height: f64,
    /// How far the camera bobs up and down around `height`, metres (0.05); less than `height`.
    pub bob: f64,
    /// The angle the orbit sweeps, degrees (360).
    pub sweep_degrees: f64,
    /// The mesh file's up axis, 0 = x, 1 = y, 2 = z (1: most scanned meshes stand along y).
    pub up_axis: usize,
    /// Frames per second (30).
    pub frame_rate: f64,
    /// The first frame's timestamp, seconds (0).
    pub start_time: f64,
    /// The depth noise (default [`NoiseModel::KINECT_V1`]).
    pub noise: NoiseModel,
    /// The noise's seed.
    pub seed: u64,
    /// Where the scene (floor at z = 0, object on it) and its cameras are placed in the world written to
    /// `groundtruth.txt` and `scene.ply` (default identity). A tilt and an offset keep the floor off the voxel
    /// faces of a fusion grid, which a real scan's floor never lies on either ([`SyntheticSettings::tilted_world`]).
    pub world: Pose,
}

impl Default for SyntheticSettings {
    fn default() -> SyntheticSettings {
        SyntheticSettings {
            intrinsics: Intrinsics::TUM_DEFAULT,
            frames: 300,
            object_size: 0.5,
            floor_size: 3.0,
            walls: 0.0,
            radius: 1.2,
            height: 0.5,
            bob: 0.05,
            sweep_degrees: 360.0,
            up_axis: 1,
            frame_rate: 30.0,
            start_time: 0.0,
            noise: NoiseModel::KINECT_V1,
            seed: 0x5EED,
            world: Pose::IDENTITY,
        }
    }
}

impl SyntheticSettings {
    /// A world 7° tilted about the axis (1, 2, 3) and moved by (12.3, 45.6, 37.1) mm: no plane of the scene on a
    /// voxel face or along a grid axis.
    pub fn tilted_world() -> Pose {
        Pose::from_rotation_translation(
            DQuat::from_axis_angle(DVec3::new(1.0, 2.0, 3.0).normalize(), 7f64.to_radians()),
            DVec3::new(0.0123, 0.0456, 0.0371),
        )
    }
}

fn setting_error(name: &str, value: impl std::fmt::Display, range: &str) -> FusionError {
    FusionError::Settings(format!("{name} = {value} is out of range: give {range}"))
}

impl SyntheticSettings {
    /// Checks every setting; the error names the one out of range.
    pub fn validate(&self) -> Result<(), FusionError> {
        let k = &self.intrinsics;
        if !(1..=16384).contains(&k.width) || !(1..=16384).contains(&k.height) {
            return Err(setting_error("image size", format!("{}×{}", k.width, k.height), "1 to 16384 pixels a side"));
        }
        for (name, value) in [("fx", k.fx), ("fy", k.fy)] {
            if !(value.is_finite() && value > 0.0) {
                return Err(setting_error(name, value, "a finite focal length > 0 pixels"));
            }
        }
        for (name, value) in [("cx", k.cx), ("cy", k.cy)] {
            if !value.is_finite() {
                return Err(setting_error(name, value, "a finite principal point"));
            }
        }
        if !(1..=100_000).contains(&self.frames) {
            return Err(setting_error("frames", self.frames, "1 to 100000"));
        }
        let positive = [
            ("object_size", self.object_size),
            ("floor_size", self.floor_size),
            ("radius", self.radius),
            ("height", self.height),
            ("sweep_degrees", self.sweep_degrees),
            ("frame_rate", self.frame_rate),
        ];
        for (name, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(setting_error(name, value, "a finite value > 0"));
            }
        }
        if !(self.walls.is_finite() && (0.0..=100.0).contains(&self.walls)) {
            return Err(setting_error("walls", self.walls, "a height from 0 to 100 metres"));
        }
        if self.floor_size < self.object_size {
            return Err(setting_error("floor_size", self.floor_size, "at least object_size"));
        }
        if self.radius <= self.object_size / 2.0 {
            return Err(setting_error("radius", self.radius, "more than object_size / 2, so the camera is outside"));
        }
        if !(self.bob.is_finite() && self.bob >= 0.0 && self.bob < self.height) {
            return Err(setting_error("bob", self.bob, "a finite value ≥ 0 and below height"));
        }
        if self.sweep_degrees > 3600.0 {
            return Err(setting_error("sweep_degrees", self.sweep_degrees, "at most 3600 (ten turns)"));
        }
        if self.up_axis > 2 {
            return Err(setting_error("up_axis", self.up_axis, "0 (x), 1 (y) or 2 (z)"));
        }
        if !(self.start_time.is_finite() && self.start_time >= 0.0) {
            return Err(setting_error("start_time", self.start_time, "a finite time ≥ 0 seconds"));
        }
        self.noise.validate()
    }
}

/// Far limit of the ray cast, metres: beyond any sensor's range.
const FAR: f64 = 100.0;

/// The colour of pixels that see nothing.
const BACKGROUND: [u8; 3] = [0, 0, 0];

/// A synthetic sequence: the scene, its bounding volume hierarchy and the camera's path.
#[derive(Clone, Debug)]
pub struct SyntheticSequence {
    settings: SyntheticSettings,
    positions: Vec<DVec3>,
    triangles: Vec<[u32; 3]>,
    /// The first this many triangles are the object's, the rest the floor's.
    object_triangles: usize,
    bvh: TriangleBvh,
    centre: DVec3,
    poses: Vec<Pose>,
}

/// The exact image of the scene from one pose.
struct Cast {
    depth: Vec<f32>,
    incidence: Vec<f32>,
    colour: Vec<[u8; 3]>,
    /// The triangle each pixel sees, `u32::MAX` for none.
    #[cfg_attr(not(test), allow(dead_code))]
    triangle: Vec<u32>,
}

impl SyntheticSequence {
    /// Places `mesh` on the floor and plans the orbit; fails on settings out of range.
    pub fn new(mesh: &TriangleMesh, settings: SyntheticSettings) -> Result<SyntheticSequence, FusionError> {
        settings.validate()?;
        let up = [DVec3::X, DVec3::Y, DVec3::Z][settings.up_axis];
        let rotation = DQuat::from_rotation_arc(up, DVec3::Z);
        let mut positions: Vec<DVec3> =
            mesh.positions().iter().map(|p| rotation * DVec3::from(p.map(f64::from))).collect();
        let mut triangles = mesh.triangles().to_vec();
        let (mut lower, mut upper) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        for &i in triangles.iter().flatten() {
            lower = lower.min(positions[i as usize]);
            upper = upper.max(positions[i as usize]);
        }
        let side = (upper - lower).max_element();
        if !(side > 0.0 && side.is_finite()) {
            return Err(FusionError::Settings("the mesh has no extent: give a mesh with a non-zero size".into()));
        }
        let scale = settings.object_size / side;
        let shift = DVec3::new(-(lower.x + upper.x) / 2.0, -(lower.y + upper.y) / 2.0, -lower.z);
        for p in &mut positions {
            *p = (*p + shift) * scale;
        }
        let centre = DVec3::new(0.0, 0.0, (upper.z - lower.z) * scale / 2.0);
        let object_triangles = triangles.len();
        // The floor: a square at z = 0 facing up.
        let half = settings.floor_size / 2.0;
        let first = positions.len() as u32;
        positions.extend([
            DVec3::new(-half, -half, 0.0),
            DVec3::new(half, -half, 0.0),
            DVec3::new(half, half, 0.0),
            DVec3::new(-half, half, 0.0),
        ]);
        triangles.extend([[first, first + 1, first + 2], [first, first + 2, first + 3]]);
        if settings.walls > 0.0 {
            // Four walls on the floor's edges, each a quad from the floor corner i to corner i + 1, up to `walls`.
            for i in 0..4u32 {
                let (a, b) = (first + i, first + (i + 1) % 4);
                let top = positions.len() as u32;
                positions.push(positions[a as usize] + DVec3::Z * settings.walls);
                positions.push(positions[b as usize] + DVec3::Z * settings.walls);
                triangles.extend([[a, b, top + 1], [a, top + 1, top]]);
            }
        }
        let poses: Vec<Pose> =
            (0..settings.frames).map(|i| settings.world * orbit_pose(&settings, centre, i)).collect();
        for p in &mut positions {
            *p = settings.world.transform_point3(*p);
        }
        let centre = settings.world.transform_point3(centre);
        let bvh = TriangleBvh::build(&positions, &triangles);
        Ok(SyntheticSequence { settings, positions, triangles, object_triangles, bvh, centre, poses })
    }

    /// Reads a mesh file (PLY, OBJ, OFF, STL: those [`read_geometry`] reads) and makes its sequence.
    pub fn from_mesh_file(path: &Path, settings: SyntheticSettings) -> Result<SyntheticSequence, FusionError> {
        match read_geometry(path)? {
            RawGeometry::Mesh(raw) => {
                let mesh = TriangleMesh::new(raw)
                    .map_err(|error| FusionError::File { path: path.to_path_buf(), message: error.to_string() })?;
                SyntheticSequence::new(&mesh, settings)
            }
            RawGeometry::Particles(_) => Err(FusionError::Geometry(GeometryError::Unsupported {
                path: path.to_path_buf(),
                message: "holds points, not triangles: a synthetic sequence is ray cast from a mesh".into(),
            })),
        }
    }

    /// The settings.
    pub fn settings(&self) -> &SyntheticSettings {
        &self.settings
    }

    /// Frames of the sequence.
    pub fn len(&self) -> usize {
        self.poses.len()
    }

    /// Whether the sequence has no frames (never: settings ask for at least one).
    pub fn is_empty(&self) -> bool {
        self.poses.is_empty()
    }

    /// The true camera-to-world pose of frame `i` (panics past [`SyntheticSequence::len`]).
    pub fn pose(&self, i: usize) -> Pose {
        self.poses[i]
    }

    /// The timestamp of frame `i`, seconds.
    pub fn timestamp(&self, i: usize) -> f64 {
        self.settings.start_time + i as f64 / self.settings.frame_rate
    }

    /// The centre of the object's bounding box, which the camera looks at (world, metres).
    pub fn object_centre(&self) -> DVec3 {
        self.centre
    }

    /// The true scene in world coordinates (metres, z up): vertex positions and triangles, the object's first and
    /// the floor's (and walls') last.
    pub fn scene_triangles(&self) -> (&[DVec3], &[[u32; 3]]) {
        (&self.positions, &self.triangles)
    }

    /// Frame `i` as the noise model's sensor sees it, with its true pose (panics past [`SyntheticSequence::len`]).
    pub fn frame(&self, i: usize) -> RgbdFrame {
        let pose = self.poses[i];
        let cast = self.cast(&pose);
        let depth = if self.settings.noise == NoiseModel::NONE {
            cast.depth
        } else {
            let seed = super::hash64(self.settings.seed, i as u64);
            self.settings.noise.apply(&self.settings.intrinsics, &cast.depth, Some(&cast.incidence), seed)
        };
        RgbdFrame {
            timestamp: self.timestamp(i),
            intrinsics: self.settings.intrinsics,
            depth,
            colour: cast.colour,
            pose: Some(pose),
        }
    }

    /// The exact (noiseless) frame seen from `pose`, stamped `timestamp`.
    pub fn exact_frame(&self, pose: Pose, timestamp: f64) -> RgbdFrame {
        let cast = self.cast(&pose);
        RgbdFrame {
            timestamp,
            intrinsics: self.settings.intrinsics,
            depth: cast.depth,
            colour: cast.colour,
            pose: Some(pose),
        }
    }

    /// Ray casts the scene from `pose`, one row per task.
    fn cast(&self, pose: &Pose) -> Cast {
        let k = self.settings.intrinsics;
        let origin = pose.translation;
        let samples: Vec<(f32, f32, [u8; 3], u32)> = (0..k.height)
            .into_par_iter()
            .flat_map_iter(|v| {
                (0..k.width).map(move |u| {
                    // z = 1 in camera space, so the ray's parameter is the depth along the optical axis.
                    let camera = DVec3::new((f64::from(u) - k.cx) / k.fx, (f64::from(v) - k.cy) / k.fy, 1.0);
                    let direction = pose.matrix3 * camera;
                    let Some((t, triangle)) =
                        self.bvh.first_hit(&self.positions, &self.triangles, origin, direction, FAR)
                    else {
                        return (0.0, 0.0, BACKGROUND, u32::MAX);
                    };
                    let [a, b, c] = self.triangles[triangle as usize].map(|i| self.positions[i as usize]);
                    let normal = (b - a).cross(c - a);
                    let cosine = (normal.dot(direction).abs() / (normal.length() * direction.length())).min(1.0);
                    let point = origin + direction * t;
                    let albedo = self.albedo(point, triangle);
                    let light = 0.15 + 0.85 * cosine;
                    let colour = albedo.map(|channel| (channel * light * 255.0).round().clamp(0.0, 255.0) as u8);
                    (t as f32, cosine.acos() as f32, colour, triangle)
                })
            })
            .collect();
        let mut cast = Cast {
            depth: Vec::with_capacity(samples.len()),
            incidence: Vec::with_capacity(samples.len()),
            colour: Vec::with_capacity(samples.len()),
            triangle: Vec::with_capacity(samples.len()),
        };
        for (depth, incidence, colour, triangle) in samples {
            cast.depth.push(depth);
            cast.incidence.push(incidence);
            cast.colour.push(colour);
            cast.triangle.push(triangle);
        }
        cast
    }

    /// The procedural albedo at world point `p` of `triangle`: a 25 cm checkerboard on the floor, hue bands over the
    /// object.
    fn albedo(&self, p: DVec3, triangle: u32) -> [f64; 3] {
        if triangle as usize >= self.object_triangles {
            let cell = (p.x / 0.25).floor() as i64 + (p.y / 0.25).floor() as i64;
            if cell.rem_euclid(2) == 0 {
                [0.85, 0.8, 0.7]
            } else {
                [0.35, 0.4, 0.5]
            }
        } else {
            let hue = ((p.x * 1.7 + p.y * 2.3 + p.z * 3.1) / self.settings.object_size * 1.5).rem_euclid(1.0);
            hsv(hue, 0.55, 0.95)
        }
    }

    /// Writes the true scene as a binary little-endian PLY (float x, y, z; faces as a uchar count and int indices).
    pub fn write_ply(&self, path: &Path) -> Result<(), FusionError> {
        let fail = |error: std::io::Error| FusionError::File {
            path: path.to_path_buf(),
            message: format!("cannot write: {error}"),
        };
        let file = std::fs::File::create(path).map_err(fail)?;
        let mut out = BufWriter::new(file);
        let header = format!(
            "ply\nformat binary_little_endian 1.0\ncomment voxstream synthetic scene: object and floor, metres, z up\n\
             element vertex {}\nproperty float x\nproperty float y\nproperty float z\nelement face {}\n\
             property list uchar int vertex_indices\nend_header\n",
            self.positions.len(),
            self.triangles.len()
        );
        out.write_all(header.as_bytes()).map_err(fail)?;
        for p in &self.positions {
            for c in p.to_array() {
                out.write_all(&(c as f32).to_le_bytes()).map_err(fail)?;
            }
        }
        for t in &self.triangles {
            out.write_all(&[3u8]).map_err(fail)?;
            for &i in t {
                out.write_all(&(i as i32).to_le_bytes()).map_err(fail)?;
            }
        }
        out.flush().map_err(fail)
    }
}

/// The camera of frame `i`: on the orbit, looking at `centre`, x right and y down in the image.
fn orbit_pose(settings: &SyntheticSettings, centre: DVec3, i: usize) -> Pose {
    let sweep = settings.sweep_degrees.to_radians();
    // A full turn ends one step before the start; a partial sweep ends at its last angle.
    let fraction = if settings.sweep_degrees >= 360.0 || settings.frames == 1 {
        i as f64 / settings.frames as f64
    } else {
        i as f64 / (settings.frames - 1) as f64
    };
    let angle = sweep * fraction;
    let eye = DVec3::new(
        settings.radius * angle.cos(),
        settings.radius * angle.sin(),
        settings.height + settings.bob * (2.0 * angle).sin(),
    );
    look_at(eye, centre)
}

/// The pose of a camera at `eye` looking at `target`, the world's z up in the image.
pub fn look_at(eye: DVec3, target: DVec3) -> Pose {
    let forward = (target - eye).normalize();
    let right = forward.cross(DVec3::Z).normalize();
    let down = forward.cross(right);
    Pose::from_mat3_translation(DMat3::from_cols(right, down, forward), eye)
}

fn hsv(hue: f64, saturation: f64, value: f64) -> [f64; 3] {
    let h = hue * 6.0;
    let f = h - h.floor();
    let (p, q, t) =
        (value * (1.0 - saturation), value * (1.0 - saturation * f), value * (1.0 - saturation * (1.0 - f)));
    match h.floor() as i64 % 6 {
        0 => [value, t, p],
        1 => [q, value, p],
        2 => [p, value, t],
        3 => [p, q, value],
        4 => [t, p, value],
        _ => [value, p, q],
    }
}

/// Writes `sequence` into `dir` in the TUM layout (see [`TumWriter`]) with its true scene as `scene.ply`, calling
/// `progress(done, total)` after each frame.
pub fn write_sequence(
    sequence: &SyntheticSequence,
    dir: &Path,
    overwrite: bool,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(), FusionError> {
    let mut writer = TumWriter::create(dir, overwrite)?;
    let total = sequence.len();
    for i in 0..total {
        writer.write_frame(&sequence.frame(i))?;
        progress(i + 1, total);
    }
    sequence.write_ply(&dir.join("scene.ply"))?;
    writer.finish()
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxstream_geometry::RawMesh;

    /// A box 2 × 2 × 2 (up along y in the file) as 12 outward triangles.
    fn cube() -> TriangleMesh {
        let mut positions = Vec::new();
        for i in 0..8u32 {
            positions.push([
                (i & 1) as f32 * 2.0 - 1.0,
                ((i >> 1) & 1) as f32 * 2.0,
                ((i >> 2) & 1) as f32 * 2.0 - 1.0,
            ]);
        }
        let quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
        let triangles = quads.iter().flat_map(|&[a, b, c, d]| [[a, b, c], [a, c, d]]).collect();
        TriangleMesh::new(RawMesh { positions, triangles }).unwrap()
    }

    fn small() -> Intrinsics {
        // Odd size: the principal point is the centre of pixel (31, 23).
        Intrinsics { width: 63, height: 47, fx: 50.0, fy: 50.0, cx: 31.0, cy: 23.0 }
    }

    fn settings() -> SyntheticSettings {
        SyntheticSettings { intrinsics: small(), frames: 8, noise: NoiseModel::NONE, ..SyntheticSettings::default() }
    }

    #[test]
    fn the_scene_stands_on_the_floor_at_its_size() {
        let sequence = SyntheticSequence::new(&cube(), settings()).unwrap();
        let (positions, triangles) = sequence.scene_triangles();
        assert_eq!(triangles.len(), 14);
        let object: Vec<DVec3> = positions[..8].to_vec();
        let lower = object.iter().fold(DVec3::INFINITY, |a, &b| a.min(b));
        let upper = object.iter().fold(DVec3::NEG_INFINITY, |a, &b| a.max(b));
        assert!((lower - DVec3::new(-0.25, -0.25, 0.0)).length() < 1e-12, "{lower}");
        assert!((upper - DVec3::new(0.25, 0.25, 0.5)).length() < 1e-12, "{upper}");
        assert!((sequence.object_centre() - DVec3::new(0.0, 0.0, 0.25)).length() < 1e-12);
        assert!(positions[8..].iter().all(|p| p.z == 0.0 && p.x.abs() == 1.5 && p.y.abs() == 1.5));
        // Every camera is on the orbit and looks at the centre, which projects to the principal point.
        for i in 0..sequence.len() {
            let pose = sequence.pose(i);
            let eye = pose.translation;
            assert!((eye.truncate().length() - 1.2).abs() < 1e-12 && (eye.z - 0.5).abs() <= 0.05 + 1e-12);
            let centre = pose.inverse().transform_point3(sequence.object_centre());
            let uv = small().project(centre).unwrap();
            assert!((uv.x - 31.0).abs() < 1e-9 && (uv.y - 23.0).abs() < 1e-9, "frame {i}: {uv}");
            // Up in the world is up in the image (smaller v).
            let above = pose.inverse().transform_point3(sequence.object_centre() + DVec3::Z * 0.1);
            assert!(small().project(above).unwrap().y < 23.0);
        }
        assert!((sequence.timestamp(3) - 0.1).abs() < 1e-12);
    }

    #[test]
    fn noiseless_depth_is_the_analytic_depth() {
        let sequence = SyntheticSequence::new(&cube(), settings()).unwrap();
        let k = small();
        // Looking at the floor away from the object: depth to the plane z = 0 where the ray lands on the square.
        let pose = look_at(DVec3::new(0.6, 0.1, 0.8), DVec3::new(1.2, 0.4, 0.0));
        let cast = sequence.cast(&pose);
        let (mut floor, mut missed) = (0, 0);
        for v in 0..k.height {
            for u in 0..k.width {
                let pixel = (v * k.width + u) as usize;
                let direction =
                    pose.matrix3 * DVec3::new((f64::from(u) - k.cx) / k.fx, (f64::from(v) - k.cy) / k.fy, 1.0);
                let t = -pose.translation.z / direction.z;
                let hit = pose.translation + direction * t;
                let depth = f64::from(cast.depth[pixel]);
                if direction.z < 0.0 && hit.x.abs() < 1.5 - 1e-9 && hit.y.abs() < 1.5 - 1e-9 {
                    assert!((depth - t).abs() < 1e-6 * t.max(1.0), "pixel {u},{v}: {depth} vs {t}");
                    assert!(cast.triangle[pixel] >= 12);
                    assert_ne!(cast.colour[pixel], BACKGROUND);
                    floor += 1;
                } else if direction.z >= 0.0 || hit.x.abs() > 1.5 + 1e-9 || hit.y.abs() > 1.5 + 1e-9 {
                    assert_eq!(depth, 0.0, "pixel {u},{v} sees nothing");
                    assert_eq!(cast.colour[pixel], BACKGROUND);
                    missed += 1;
                }
            }
        }
        assert!(floor > 1000 && missed > 100, "{floor} floor, {missed} missed");
        // From the orbit: the centre pixel sees the cube's face x = 0.25 on the line to the centre; every floor
        // pixel has the plane's depth.
        let frame = sequence.frame(0);
        let eye = sequence.pose(0).translation;
        let to_centre = sequence.object_centre() - eye;
        let expected = (0.25 - eye.x) / to_centre.x * to_centre.length();
        let centre_depth = f64::from(frame.depth_at(31, 23).unwrap());
        assert!((centre_depth - expected).abs() < 1e-6, "{centre_depth} vs {expected}");
        let pose = sequence.pose(0);
        let cast = sequence.cast(&pose);
        let mut checked = 0;
        for (pixel, &triangle) in cast.triangle.iter().enumerate() {
            if triangle >= 12 && triangle != u32::MAX {
                let (u, v) = ((pixel % 63) as f64, (pixel / 63) as f64);
                let direction = pose.matrix3 * DVec3::new((u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0);
                let t = -pose.translation.z / direction.z;
                assert!((f64::from(cast.depth[pixel]) - t).abs() < 1e-6 * t.max(1.0));
                checked += 1;
            }
        }
        assert!(checked > 500, "{checked}");
        assert_eq!(frame.depth, cast.depth, "NONE leaves the cast depth");
    }

    #[test]
    fn noisy_frames_are_deterministic_and_near_the_truth() {
        let noisy =
            SyntheticSequence::new(&cube(), SyntheticSettings { noise: NoiseModel::KINECT_V1, ..settings() }).unwrap();
        let exact = SyntheticSequence::new(&cube(), settings()).unwrap();
        let (a, b, truth) = (noisy.frame(2), noisy.frame(2), exact.frame(2));
        assert_eq!(a, b);
        let measured: Vec<(f32, f32)> =
            a.depth.iter().zip(&truth.depth).filter(|(m, t)| **m > 0.0 && **t > 0.0).map(|(m, t)| (*m, *t)).collect();
        assert!(measured.len() > 1000 && measured.len() < a.depth.len());
        let close = measured.iter().filter(|(m, t)| (m - t).abs() < 0.05).count();
        assert!(close as f64 > 0.9 * measured.len() as f64, "{close} of {}", measured.len());
        assert!(measured.iter().any(|(m, t)| m != t), "noise was added");
        assert_eq!(a.colour, truth.colour);
    }

    #[test]
    fn settings_out_of_range_are_named() {
        let cases: [(SyntheticSettings, &str); 6] = [
            (SyntheticSettings { frames: 0, ..settings() }, "frames"),
            (SyntheticSettings { frames: 100_001, ..settings() }, "frames"),
            (SyntheticSettings { object_size: f64::NAN, ..settings() }, "object_size"),
            (SyntheticSettings { radius: 0.2, ..settings() }, "radius"),
            (SyntheticSettings { bob: 0.6, ..settings() }, "bob"),
            (SyntheticSettings { up_axis: 3, ..settings() }, "up_axis"),
        ];
        for (bad, name) in cases {
            let error = SyntheticSequence::new(&cube(), bad).unwrap_err().to_string();
            assert!(error.starts_with(name), "{name}: {error}");
        }
    }

    #[test]
    fn sequences_are_written_in_the_tum_layout_with_their_scene() {
        let dir = std::env::temp_dir().join(format!("voxstream-synth-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let sequence = SyntheticSequence::new(
            &cube(),
            SyntheticSettings { frames: 3, noise: NoiseModel::KINECT_V1, ..settings() },
        )
        .unwrap();
        let mut calls = Vec::new();
        write_sequence(&sequence, &dir, false, &mut |done, total| calls.push((done, total))).unwrap();
        assert_eq!(calls, [(1, 3), (2, 3), (3, 3)]);
        let dataset = super::super::TumDataset::open(&dir).unwrap().with_intrinsics(small());
        assert_eq!(dataset.len(), 3);
        for i in 0..3 {
            let read = dataset.frame(i).unwrap();
            let written = sequence.frame(i);
            assert!(read.pose.unwrap().abs_diff_eq(written.pose.unwrap(), 1e-6));
            assert_eq!(read.colour, written.colour);
            assert!(read.depth.iter().zip(&written.depth).all(|(r, w)| (r - w).abs() < 2e-4));
        }
        let ply = std::fs::read(dir.join("scene.ply")).unwrap();
        let end = ply.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
        let header = std::str::from_utf8(&ply[..end]).unwrap();
        assert!(header.contains("element vertex 12\n") && header.contains("element face 14\n"), "{header}");
        assert_eq!(ply.len() - end, 12 * 12 + 14 * 13);
        let x0 = f32::from_le_bytes(ply[end..end + 4].try_into().unwrap());
        assert_eq!(x0, -0.25);
        // The mesh read from a file gives the same scene.
        let obj = dir.join("cube.obj");
        let mut text = String::new();
        for p in cube().positions() {
            text += &format!("v {} {} {}\n", p[0], p[1], p[2]);
        }
        for t in cube().triangles() {
            text += &format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
        }
        std::fs::write(&obj, text).unwrap();
        let from_file = SyntheticSequence::from_mesh_file(&obj, settings()).unwrap();
        assert_eq!(
            from_file.scene_triangles().0,
            SyntheticSequence::new(&cube(), settings()).unwrap().scene_triangles().0
        );
        assert!(SyntheticSequence::from_mesh_file(&dir.join("none.obj"), settings()).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
