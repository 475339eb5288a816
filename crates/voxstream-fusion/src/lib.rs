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
//! - [`rgbd`]: where frames come from: TUM RGB-D benchmark folders (read and written), and synthetic orbits around a
//!   mesh with a Kinect v1 noise model (§8.2).

pub mod camera;
pub mod frame;
pub mod rgbd;

pub use camera::{Intrinsics, Pose};
pub use frame::RgbdFrame;

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
    /// The mesh of a synthetic sequence could not be read.
    #[error(transparent)]
    Geometry(#[from] voxstream_geometry::GeometryError),
}
