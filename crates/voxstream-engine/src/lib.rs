//! # voxstream-engine: the frame loop, behind a renderer interface, within one memory budget
//!
//! The loop camera → renderer → feedback → cache manager → producers → pools closes here, in
//! [`Session::render`], for every front end (the `voxstream` CLI today; a viewer and Python bindings later):
//!
//! - [`Session`]: a producer, its [`CacheManager`](voxstream_core::CacheManager) and a renderer; renders frames in
//!   GigaVoxels' two display modes ([`Mode`]: converged, interactive) within [`LoopLimits`], and reports each
//!   [`FrameResult`] and, pass by pass, [`PassProgress`].
//! - [`PassPolicy`](pass_policy::PassPolicy): how one frame's passes go in its mode: how sparsely each traces, what
//!   is produced after it, and when the frame ends.
//! - [`FrameRenderer`]: what the loop needs from a renderer (one pass over a `TreeView`, writing the feedback);
//!   [`CpuRenderer`] is the CPU ray caster of `voxstream-render`; a GPU backend implements the same trait.
//! - [`MemoryBudget`] / [`MemoryPlan`]: one budget split among the image, a store's host cache and the pools.
//! - [`OutputFile`] / [`write_output`]: outputs written through a temporary file and a rename, or straight into a
//!   FIFO or character device, never over a folder or a disk ([`output_target`]).
//! - [`PoppingSummary`]: how much an interactive sequence pops and shows seams against the exact images (Thiele
//!   et al.'s evaluation made a number).
//!
//! No command-line parsing here: the optional `clap` and `serde` features derive `ValueEnum` and `Serialize` on
//! [`Mode`] (and `Serialize` on [`PoppingSummary`]) for front ends that want them.
//!
//! ```
//! use voxstream_core::{NodeContent, NodeKey, ProduceError, Produced, Producer, TreeShape};
//! use voxstream_engine::{LoopLimits, MemoryBudget, Mode, Session};
//! use voxstream_render::{Camera, RenderSettings, TransferFunction};
//!
//! /// Empty space everywhere.
//! struct Vacuum;
//! impl Producer for Vacuum {
//!     fn shape(&self) -> TreeShape { TreeShape::new(2, 8, 4).unwrap() }
//!     fn produce(&self, _: NodeKey, _: &mut [u16]) -> Result<Produced, ProduceError> {
//!         Ok(Produced { content: NodeContent::Empty, is_terminal: true })
//!     }
//! }
//! let settings = RenderSettings { width: 32, height: 32, ..RenderSettings::default() };
//! let plan = MemoryBudget::new(16, 32, 32, None).unwrap().plan(&Vacuum.shape(), 0).unwrap();
//! let tf = TransferFunction::new(vec![[0.0, 1.0, 1.0, 1.0, 0.0], [1.0, 1.0, 1.0, 1.0, 1.0]], None).unwrap();
//! let mut session = Session::new(Vacuum, &tf, settings, plan.pool_bytes, LoopLimits::default()).unwrap();
//! let camera = Camera { eye: [0.5, 0.5, 3.0], target: [0.5, 0.5, 0.5], up: [0.0, 1.0, 0.0], fov: 30.0 };
//! let frame = session.render(&camera, Mode::Converged).unwrap();
//! assert!(frame.is_converged());
//! ```

pub mod error;
pub mod frame_renderer;
pub mod level_pace;
pub mod memory_budget;
pub mod output_file;
pub mod pass_policy;
pub mod popping;
pub mod session;

pub use error::EngineError;
pub use frame_renderer::{CpuRenderer, FrameRenderer};
pub use level_pace::level_rate;
pub use memory_budget::{
    machine_memory_bytes, BudgetError, MemoryBudget, MemoryPlan, MAX_BUDGET_MB, STORE_CACHE_SHARE,
};
pub use output_file::{output_target, temporary_path, write_output, OutputError, OutputFile, OutputTarget};
pub use popping::{frame_popping, seam_error, PoppingSummary, Rgb8};
pub use session::{FrameResult, LoopLimits, Mode, PassProgress, Session, CONVERGED_REQUESTS_PER_RAY};
