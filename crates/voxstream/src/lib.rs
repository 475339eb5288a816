//! # voxstream: the command-line application
//!
//! `voxstream render [SOURCE]` renders a built-in scene through the whole GigaVoxels loop (see
//! `docs/ARCHITECTURE.md`); `voxstream bench` measures it; `voxstream scenes` lists the scenes.
//!
//! The loop camera → renderer → feedback → cache manager → producers → pools closes in `voxstream-engine`
//! ([`voxstream_engine::Session`]), which also plans the memory budget; this crate parses flags and files, drives
//! the engine, and writes images and statistics.

// The facade's modules, where they were before it existed (the tests and benches name them so).
pub use voxstream_api::{
    backend, camera_path, error_message, geometry_source, render_budget, scenes, source_path, store_open,
};

pub mod bench;
pub mod cli;
pub mod exit_status;
pub mod fluid_command;
pub mod fuse_command;
pub mod import_command;
pub mod info_command;
pub mod iso_flags;
pub mod memory;
pub mod output_file;
pub mod png_output;
pub mod popping_bench;
pub mod popping_run;
pub mod render_command;
pub mod render_progress;
pub mod render_warnings;
#[cfg(unix)]
pub mod runtime_dir;
pub mod stats;
pub mod trilinear_bound;
pub mod video_output;
#[cfg(feature = "viewer")]
pub mod view_command;
pub mod view_flags;
