//! The built-in scenes: producer, default transfer function, camera and shading of each.
//!
//! The producers form a closed set, dispatched through an enum (no `dyn` call per brick).

use voxstream_core::{NodeKey, ProduceError, Produced, Producer, TreeShape, VoxelFormat};
use voxstream_procedural::{Hypertexture, MengerSponge, Shell};
use voxstream_render::{Camera, Shading, TransferFunction};

/// Names of the built-in scenes, in the order `voxstream scenes` lists them.
pub const SCENE_NAMES: [&str; 3] = ["sponge", "hypertexture", "shell"];

/// The scene rendered when no source is given.
pub const DEFAULT_SCENE: &str = "sponge";

/// A built-in producer.
#[derive(Clone, Copy, Debug)]
pub enum SceneProducer {
    /// Menger sponge, N = 3.
    Sponge(MengerSponge),
    /// Hypertextured torus, N = 2.
    Hypertexture(Hypertexture),
    /// Analytic shell, N = 2.
    Shell(Shell),
}

impl Producer for SceneProducer {
    fn shape(&self) -> TreeShape {
        match self {
            SceneProducer::Sponge(p) => p.shape(),
            SceneProducer::Hypertexture(p) => p.shape(),
            SceneProducer::Shell(p) => p.shape(),
        }
    }

    fn oracle(&self, key: NodeKey) -> Option<f32> {
        match self {
            SceneProducer::Sponge(p) => p.oracle(key),
            SceneProducer::Hypertexture(p) => p.oracle(key),
            SceneProducer::Shell(p) => p.oracle(key),
        }
    }

    fn produce(&self, key: NodeKey, voxels: &mut [u16]) -> Result<Produced, ProduceError> {
        match self {
            SceneProducer::Sponge(p) => p.produce(key, voxels),
            SceneProducer::Hypertexture(p) => p.produce(key, voxels),
            SceneProducer::Shell(p) => p.produce(key, voxels),
        }
    }

    fn voxel_format(&self) -> VoxelFormat {
        match self {
            SceneProducer::Sponge(p) => p.voxel_format(),
            SceneProducer::Hypertexture(p) => p.voxel_format(),
            SceneProducer::Shell(p) => p.voxel_format(),
        }
    }
}

/// A scene with its defaults.
#[derive(Clone, Debug)]
pub struct Scene {
    /// Name on the command line.
    pub name: &'static str,
    /// One-line description.
    pub description: &'static str,
    /// The producer.
    pub producer: SceneProducer,
    /// Default transfer function.
    pub transfer_function: TransferFunction,
    /// Default shading.
    pub shading: Shading,
    /// Default camera.
    pub camera: Camera,
    /// Default direction towards the light (`None`: a headlight).
    pub light: Option<[f64; 3]>,
}

/// The default camera: a three-quarter view of the unit cube, framed whole with a 40° field of view.
pub fn default_camera() -> Camera {
    Camera { eye: [1.95, 1.55, 2.35], target: [0.5, 0.5, 0.5], up: [0.0, 1.0, 0.0], fov: 40.0 }
}

/// The sponge's view: nearly facing its z = 1 face, so that the face's carpet of square tunnels shows (the central one
/// open to the background), with the top and right faces in view; lit from near the view direction but tilted, so
/// that the tunnels' walls are darker than the faces.
pub fn sponge_camera() -> Camera {
    Camera { eye: [1.0, 0.9, 3.2], target: [0.5, 0.5, 0.5], up: [0.0, 1.0, 0.0], fov: 30.0 }
}

/// The sponge's light: towards +z, tilted up and right.
pub const SPONGE_LIGHT: [f64; 3] = [0.2, 0.3, 0.93];

/// A closer three-quarter view for objects that do not fill the cube.
pub fn close_camera() -> Camera {
    Camera { eye: [1.46, 1.2, 1.73], target: [0.5, 0.5, 0.5], up: [0.0, 1.0, 0.0], fov: 40.0 }
}

fn tf(points: &[[f64; 5]], unit_distance: Option<f64>) -> TransferFunction {
    TransferFunction::new(points.to_vec(), unit_distance).expect("built-in transfer functions are valid")
}

/// Looks up a built-in scene by name.
pub fn builtin(name: &str) -> Option<Scene> {
    let scene = match name {
        "sponge" => Scene {
            name: "sponge",
            description: "Menger sponge, N=3, bricks 9^3, 25 levels (virtual resolution 3^25*9 per axis)",
            producer: SceneProducer::Sponge(MengerSponge::default()),
            transfer_function: tf(
                &[
                    [0.0, 0.0, 0.0, 0.0, 0.0],
                    [0.35, 0.0, 0.0, 0.0, 0.0],
                    [0.5, 0.95, 0.82, 0.6, 1.0],
                    [1.0, 0.95, 0.82, 0.6, 1.0],
                ],
                None,
            ),
            shading: Shading::Phong,
            camera: sponge_camera(),
            light: Some(SPONGE_LIGHT),
        },
        "hypertexture" => Scene {
            name: "hypertexture",
            description: "torus amplified by 16 octaves of fBm, N=2, bricks 8^3, virtual resolution 131072^3",
            producer: SceneProducer::Hypertexture(Hypertexture::default()),
            transfer_function: tf(
                &[
                    [0.0, 0.0, 0.0, 0.0, 0.0],
                    [0.2, 0.9, 0.45, 0.2, 0.0],
                    [0.6, 0.95, 0.7, 0.4, 0.9],
                    [1.0, 1.0, 0.95, 0.85, 1.0],
                ],
                Some(0.002),
            ),
            shading: Shading::Phong,
            camera: close_camera(),
            light: None,
        },
        "shell" => Scene {
            name: "shell",
            description: "analytic Gaussian shell exp(-((|x-c|-R)/s)^2), N=2, bricks 16^3, 256^3 (test reference)",
            producer: SceneProducer::Shell(Shell::default()),
            transfer_function: shell_transfer_function(),
            shading: Shading::None,
            camera: close_camera(),
            light: None,
        },
        _ => return None,
    };
    Some(scene)
}

/// The shell's default transfer function (also used by the image tests).
pub fn shell_transfer_function() -> TransferFunction {
    tf(
        &[[0.0, 0.0, 0.0, 0.0, 0.0], [0.2, 0.1, 0.3, 0.9, 0.04], [0.6, 0.3, 0.8, 0.9, 0.15], [1.0, 1.0, 0.9, 0.5, 0.3]],
        Some(0.1),
    )
}
