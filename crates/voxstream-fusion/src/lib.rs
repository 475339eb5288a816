//! voxstream's depth-camera fusion: RGB-D streams fused online into binary bricks (Reichl, seed 004 ch. 8;
//! `../shared/notes/reichl-framework.md` "Chapter 8").
//!
//! KinectFusion-style tools keep a signed distance and a weight per voxel for the whole scan. The thesis keeps two
//! bits: frames are cached in a ring, and every few frames a window of them is fused at once (deferred processing,
//! §8.3.2), so distances and weights live only while a window is processed; a voxel keeps the sign of its averaged
//! distance and whether that was confident (§8.3.4). World chunks in a hash map hold the bricks, so the scene has no
//! fixed extent (§8.3.1), and chunks far from the camera go to disk when the budget is reached (§8.6).
//!
//! - [`camera`]: pinhole intrinsics and camera-to-world poses.
//! - [`frame`]: one RGB-D frame in metres and 8-bit colour.
//! - [`brick`]: 8³ voxels of sign and confidence bits, with colours of surface voxels.
//! - [`brick_map`]: the bricks by coordinate, grouped in world chunks that stream to disk ([`spill`]).
//! - [`integrate`]: one brick from a set of cached frames (eq. 8.1–8.2).
//! - [`fusion`]: the ring buffer, allocation, sub-cache and windows.
//! - [`caster`]: rays through the bits, smoothed in screen space.
//! - [`surface`]: the surface as points, for measuring and for saving.
//! - [`export`]: the scene as a store `render` and `view` open.
//! - [`tracking`]: each frame's pose by point-to-plane ICP against the surface ray-cast from the reconstruction
//!   (§8.2, KinectFusion's frame-to-model tracking), and the benchmark's trajectory errors.
//! - [`rgbd`]: where frames come from: TUM RGB-D benchmark folders (read and written), and synthetic orbits around a
//!   mesh with a Kinect v1 noise model (§8.2).

pub mod brick;
pub mod brick_map;
pub mod camera;
pub mod caster;
pub mod export;
pub mod frame;
pub mod fusion;
pub mod integrate;
pub mod rgbd;
pub mod spill;
pub mod surface;
pub mod tracking;

pub use camera::{Intrinsics, Pose};
pub use frame::RgbdFrame;
pub use fusion::{Fusion, FusionSettings, FusionStats};

/// What can go wrong reading, generating or fusing RGB-D data.
#[derive(Debug, thiserror::Error)]
pub enum FusionError {
    /// A file of the dataset could not be read or written; the message names it.
    #[error("{path}: {message}")]
    File { path: std::path::PathBuf, message: String },
    /// The dataset is malformed (a line, an image size, a timestamp); the message names the file and the fix.
    #[error("{0}")]
    Dataset(String),
    /// A setting is out of range; the message names the flag.
    #[error("{0}")]
    Settings(String),
    /// The scene outgrew the memory budget with nowhere to stream chunks; the message names the flag.
    #[error("{0}")]
    Budget(String),
    /// The mesh of a synthetic sequence could not be read.
    #[error(transparent)]
    Geometry(#[from] voxstream_geometry::GeometryError),
}
