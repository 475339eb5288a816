//! # voxstream-api: the library facade
//!
//! What every front end (the `voxstream` CLI's `render`, `view` and `info`, the Python module, napari) does with a
//! source, in one place and with typed options instead of command-line flags:
//!
//! - [`source::open`] opens a built-in scene, a mesh or particle file, or a store (a folder or an `http(s)://`,
//!   `s3://`, `gs://`, `az://` URL) with [`SourceOptions`], and gives its producer and defaults ([`Source`]);
//! - [`view::prepare_view`] applies [`ViewOptions`] (transfer function, isosurfaces, shading, camera) over them;
//! - [`depth_fusion::fuse_dataset`] fuses an RGB-D sequence into binary bricks and saves them as a store;
//! - [`session::start_session`] builds the frame loop ([`voxstream_engine::Session`]) on the chosen backend within the
//!   memory budget; [`Volume`] keeps one per source and renders frames.
//!
//! Messages name the CLI's flags (`--iso`, `--budget-mb`): they are the one-line errors every front end shows.
//! Errors are `anyhow` chains whose root causes stay typed (`std::io::Error`, `voxstream_store::StoreError`, …).

pub use voxstream_render::annotations;
pub mod backend;
pub mod camera_path;
pub mod camera_presets;
pub mod defaults;
pub mod depth_fusion;
pub mod error_message;
pub mod fluid;
pub mod geometry_import;
pub mod geometry_source;
pub mod import_input;
pub mod loading_spinner;
pub mod near_names;
pub mod remote_output;
pub mod render_budget;
pub mod scenes;
pub mod session;
pub mod slices;
pub mod source;
pub mod source_path;
pub mod store_open;
pub mod view;

pub use backend::{open_renderer, Backend, GpuFilter};
pub use session::{start_session, FrameSession, SessionOptions, Volume};
pub use source::{open, BrickBits, Source, SourceMeta, SourceOptions};
pub use view::{prepare_view, CameraOptions, IsoOptions, PreparedView, TransferFunctionChoice, ViewOptions};
pub use voxstream_engine::{FrameResult, Mode, PassProgress};
pub use voxstream_render::{Camera, Image, Shading, TransferFunction};
