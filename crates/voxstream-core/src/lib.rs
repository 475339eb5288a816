//! # voxstream-core: the GigaVoxels cache, as flat data
//!
//! The bottom of voxstream's data flow:
//!
//! ```text
//! camera → renderer → feedback → cache manager → producers → pools → renderer
//!             ▲          (this crate: FeedbackBuffer, CacheManager, Producer, NodePool, BrickPool)
//! ```
//!
//! - [`Node`]: two 32-bit words (child tile + flags, brick slot or constant), GigaVoxels [P09] §4; defined in
//!   `voxstream-layout` (GPU-visible) and re-exported here.
//! - [`NodePool`]: tiles of `N³` siblings (N = 2, 3 or 4); [`BrickPool`]: bricks of `(M+2)³` voxels with a one-voxel
//!   border, 16-bit (`u16`) or, for sources of 8-bit integer samples, 8-bit (`u8`): see [`VoxelFormat`]. Producers
//!   always write 16-bit voxels; the pool narrows them when [`Producer::voxel_format`] says it is exact.
//! - [`PoolCapacities`]: both pools sized from one byte budget, never exceeded.
//! - [`FeedbackBuffer`]: what rays used and what they missed; [`RequestQueue`]: dedup, largest level deficit
//!   first, then parent-first, bounded.
//! - [`CacheManager`]: serves requests by calling a [`Producer`] on worker threads; LRU recycling.
//! - [`TreeView`]: the immutable flat view renderers read during a frame.
//! - [`LevelBlending`]: Thiele et al.'s fade-in of arriving bricks and caps towards coarser neighbours.
//! - [`restriction`]: Thiele et al.'s restricted working set (neighbouring data at most one level apart).
//! - [`json_limits`]: the size cap on every JSON file read (store metadata, transfer functions, cameras).
//!
//! ```
//! use voxstream_core::{CacheManager, NodeContent, NodeKey, Produced, Producer, ProduceError, ServeOptions, TreeShape};
//!
//! /// Everything is empty: the root turns out constant after one request.
//! struct Vacuum;
//! impl Producer for Vacuum {
//!     fn shape(&self) -> TreeShape { TreeShape::new(2, 8, 4).unwrap() }
//!     fn produce(&self, _: NodeKey, _: &mut [u16]) -> Result<Produced, ProduceError> {
//!         Ok(Produced { content: NodeContent::Empty, is_terminal: true })
//!     }
//! }
//! let mut cache = CacheManager::new(Vacuum, 1 << 20).unwrap();
//! cache.begin_frame();
//! // A renderer would write this request when its ray finds the root missing.
//! cache.feedback().push_requests(&[voxstream_core::Request {
//!     node: voxstream_core::NodeId::ROOT,
//!     kind: voxstream_core::RequestKind::Produce,
//!     deficit: 1,
//! }]);
//! let report = cache.end_frame(ServeOptions::ALL);
//! assert_eq!(report.constant_nodes, 1);
//! assert!(cache.view().root().is_constant());
//! ```

pub mod brick_pool;
pub mod budget;
pub mod cache_manager;
pub mod error;
pub mod feedback;
pub mod io_message;
pub mod json_limits;
pub mod key;
pub mod level_blending;
pub mod lru;
pub mod node;
pub mod node_pool;
pub mod noise;
pub mod producer;
pub mod request_queue;
pub mod restriction;
pub mod tree_view;
pub mod voxel_format;

pub use brick_pool::{dequantize, quantize, BrickPool, PreparedBrick, VOXEL_MAX};
pub use budget::PoolCapacities;
pub use cache_manager::{CacheManager, Residency, ServeOptions, ServeReport};
pub use error::{CoreError, ProduceError};
pub use feedback::{FeedbackBuffer, Request, RequestKind};
pub use key::{NodeKey, TreeShape, BLOCK_CELLS, BRICK_BORDER};
pub use level_blending::{BrickBlend, LevelBlending, DEFAULT_FADE_FRAMES};
pub use node::{BrickSlot, Node, NodeData, NodeId, TileId};
pub use node_pool::NodePool;
pub use producer::{NodeContent, Produced, Producer};
pub use request_queue::{QueuedRequest, RequestQueue};
pub use tree_view::{PoolCapacity, TreeView};
pub use voxel_format::{Dequantize, PoolVoxels, Voxel, VoxelFormat};
