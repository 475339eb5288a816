//! The cache manager: turns a frame's feedback into pool updates by asking the producer for what rays missed.
//!
//! Implements GigaVoxels [P09] §5 ("Cache management", "Ray-guided data requests") and the producer side of [R08] §4.
//!
//! # Design choices
//! - **One budget.** Node and brick pool capacities come from one byte budget ([`PoolCapacities::plan`]), every
//!   per-slot byte counted; memory grows with use and never passes the budget.
//! - **LRU order.** After a frame, every tile and brick a ray used is refreshed in index order (deterministic).
//!   Allocation takes a free slot, else the least recently used one, but never one used during the current frame:
//!   the renderer might point at it. When nothing can be recycled the request waits (it is counted as deferred).
//! - **No dangling pointers.** Recycling a brick clears its owner's brick pointer. Recycling a tile clears its
//!   parent's child pointer and frees its whole subtree (tiles and bricks), because descendants are never more
//!   recently used than their ancestors.
//! - **Dedup and priority.** [`RequestQueue`]: duplicates merged, the largest level deficit first, then parents
//!   before children, then by how many rays asked, bounded per frame in interactive mode.
//! - **Restricted working set** (optional, [`CacheManager::set_restricted`]; Thiele et al., [`crate::restriction`]):
//!   a request waits while forced steps complete its coarser neighbourhood, within the same bound; evictions that
//!   would leave neighbours two levels apart are passed over for the next oldest.
//! - **Threads.** Production runs on the rayon worker threads, outside any lock; results are applied by the
//!   calling thread in queue order, so the final pools do not depend on scheduling. Requests deferred past the
//!   per-frame bound are handed to [`Producer::prefetch`], which may read ahead in the background while the next
//!   frame renders (the store producer does); prefetching never changes what is produced.
//! - **Failures.** A producer error is recorded once; the node stays missing, its ancestor stands in, and it is
//!   not requested again.
//! - **Children produced with their tile** (optional, [`ServeOptions::prefetch_new_children`]). Without it a ray
//!   that reaches a childless node asks for a subdivision, sees the new children missing only in the next pass, and
//!   asks for their bricks then: two passes per tree level. With it, serving a subdivision also produces, in the
//!   same frame, every new child that the producer's oracle does not already know to be constant, as GigaVoxels
//!   [P09] §5 lets its cache manager load the children of a subdivided node at once. It only fills brick slots that
//!   are free (never used, or released) once every request of the frame is served, and never evicts for it, so a
//!   tight budget behaves as without it. It trades over-production (children no ray will need, e.g. off screen or
//!   occluded; none for the shell scene, 2.6× the bricks for the sponge's 27-child tiles) for fewer passes;
//!   converged frames turn it on, interactive frames keep their bounded work.
//!   A child whose production fails is left missing, to be requested, and its failure reported, if a ray needs it.
//!   Where a ray is short of two or more levels, the level below what was served (children of a produced brick,
//!   grandchildren under a new tile) is handed to [`Producer::prefetch`] as well: a remote store fetches it while
//!   the next pass is drawn, instead of each pass waiting a round trip for the level its rays just found they need.
//! - **Brick analysis.** A produced terminal brick whose voxels are all equal becomes a constant node (no brick
//!   slot). Non-terminal bricks stay bricks: only the producer knows whether finer levels are constant too.
//!
//! # Modules
//! - `options` and `report`: what a frame's serving is asked to do and what it did; residency figures.
//! - `requests`: the frame's requests from the feedback buffer, in priority order; deferred ones handed to the
//!   producer's background loading.
//! - `usage`: the LRU bookkeeping (what rays used, what this frame's work pins).
//! - `production`: producing a batch on worker threads and applying it in queue order; `analysis` of each
//!   produced brick; `space_order`, the order the workers take a batch in.
//! - `restricted`: serving under Thiele et al.'s restricted working set.
//! - `children`: producing the children of new tiles into free slots.
//! - `tree_updates`: storing bricks and tiles in the node tree, evicting and freeing subtrees.
//! - `blending`: the level-blending switches; `invariants`: the structural checks tests run.

mod analysis;
mod blending;
mod children;
mod invariants;
mod options;
mod production;
mod report;
mod requests;
mod restricted;
mod space_order;
#[cfg(test)]
mod test_support;
mod tree_updates;
mod usage;

use std::collections::HashSet;

use crate::brick_pool::BrickPool;
use crate::budget::PoolCapacities;
use crate::error::CoreError;
use crate::feedback::{FeedbackBuffer, Request, RequestKind};
use crate::key::{NodeKey, TreeShape};
use crate::level_blending::LevelBlending;
use crate::node::{BrickSlot, NodeData, NodeId, TileId};
use crate::node_pool::NodePool;
use crate::producer::Producer;
use crate::tree_view::TreeView;
use crate::voxel_format::VoxelFormat;

pub use options::ServeOptions;
pub use report::{Residency, ServeReport};

use production::Work;

/// Deferred requests passed to [`Producer::prefetch`] per frame.
pub const PREFETCH_LIMIT: usize = 1024;

/// Most requests produced concurrently before their results are applied (bounds transient memory; a small budget
/// gets smaller batches, [`PoolCapacities::production_batch`]).
pub const PRODUCTION_BATCH: usize = 256;

/// Owns the pools and the producer; serves the rays' requests between frames.
pub struct CacheManager<P: Producer> {
    producer: P,
    shape: TreeShape,
    capacities: PoolCapacities,
    node_pool: NodePool,
    brick_pool: BrickPool,
    feedback: FeedbackBuffer,
    frame: u32,
    failed: HashSet<NodeKey>,
    /// Thiele et al.'s temporal and spatial blending, when on ([`CacheManager::set_blending`]).
    blending: Option<LevelBlending>,
    /// Whether the working set is kept restricted ([`CacheManager::set_restricted`]).
    restricted: bool,
    /// Threads that produce batches for a producer that waits on a network ([`Producer::concurrency`]).
    io_pool: Option<rayon::ThreadPool>,
    /// This frame's [`ServeOptions::wait_for_data`].
    wait_for_data: bool,
}

/// Pools of `capacities` holding only the root, and the feedback buffer sized for them.
fn empty_pools(
    shape: &TreeShape,
    capacities: &PoolCapacities,
    format: VoxelFormat,
) -> (NodePool, BrickPool, FeedbackBuffer) {
    let node_pool = NodePool::new(*shape, capacities.tiles);
    let brick_pool = BrickPool::with_format(shape, capacities.bricks, format);
    let feedback = FeedbackBuffer::new(node_pool.tiles_allocated(), 0);
    (node_pool, brick_pool, feedback)
}

impl<P: Producer> CacheManager<P> {
    /// A cache for `producer` within `budget_bytes`. Only the root exists; its data is requested by the first rays.
    pub fn new(producer: P, budget_bytes: u64) -> Result<CacheManager<P>, CoreError> {
        let format = producer.voxel_format();
        CacheManager::with_format(producer, budget_bytes, format)
    }

    /// [`CacheManager::new`] with 16-bit bricks whatever [`Producer::voxel_format`] allows: for renderers that keep
    /// their own copy of the bricks in 16 bits (the GPU atlas), so that the budget, planned in the pool's voxels,
    /// also bounds that copy.
    pub fn with_sixteen_bit_bricks(producer: P, budget_bytes: u64) -> Result<CacheManager<P>, CoreError> {
        CacheManager::with_format(producer, budget_bytes, VoxelFormat::Wide)
    }

    fn with_format(producer: P, budget_bytes: u64, format: VoxelFormat) -> Result<CacheManager<P>, CoreError> {
        let shape = producer.shape();
        let capacities = PoolCapacities::plan_for(&shape, format, budget_bytes)?;
        let (node_pool, brick_pool, feedback) = empty_pools(&shape, &capacities, format);
        // A producer that waits on a network gets threads of its own, as many as it wants requests in flight (a
        // pool that cannot be made leaves it on the shared one).
        let io_pool = match producer.concurrency() {
            0 | 1 => None,
            threads => rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .thread_name(|i| format!("voxstream-fetch-{i}"))
                .build()
                .ok(),
        };
        Ok(CacheManager {
            producer,
            shape,
            capacities,
            node_pool,
            brick_pool,
            feedback,
            frame: 1,
            failed: HashSet::new(),
            blending: None,
            restricted: false,
            io_pool,
            wait_for_data: true,
        })
    }

    /// Moves the cache to a new budget: the pools are planned for `budget_bytes` and start empty (what was resident
    /// is produced again as rays ask for it), level blending keeps its setting, failed nodes are forgotten. A budget
    /// too small for the tree leaves the cache as it was and says so.
    pub fn set_budget(&mut self, budget_bytes: u64) -> Result<(), CoreError> {
        let format = self.brick_pool.format();
        let capacities = PoolCapacities::plan_for(&self.shape, format, budget_bytes)?;
        (self.node_pool, self.brick_pool, self.feedback) = empty_pools(&self.shape, &capacities, format);
        self.capacities = capacities;
        self.frame = 1;
        self.failed.clear();
        self.blending = self.blending.as_ref().map(|b| LevelBlending::new(b.fade_frames()));
        Ok(())
    }

    /// The producer.
    pub fn producer(&self) -> &P {
        &self.producer
    }

    /// The tree shape.
    pub fn shape(&self) -> &TreeShape {
        &self.shape
    }

    /// The planned capacities.
    pub fn capacities(&self) -> &PoolCapacities {
        &self.capacities
    }

    /// The node pool (read-only).
    pub fn node_pool(&self) -> &NodePool {
        &self.node_pool
    }

    /// The brick pool (read-only).
    pub fn brick_pool(&self) -> &BrickPool {
        &self.brick_pool
    }

    /// Current frame number (starts at 1).
    pub fn frame(&self) -> u32 {
        self.frame
    }

    /// Starts a frame: clears the feedback buffer. Then render with [`CacheManager::view`] and
    /// [`CacheManager::feedback`], and finish with [`CacheManager::end_frame`].
    pub fn begin_frame(&mut self) {
        self.feedback.reset(self.node_pool.tiles_allocated(), self.brick_pool.allocated());
        if let Some(blending) = &mut self.blending {
            let bricks = &self.brick_pool;
            let owner_of = |slot: BrickSlot| bricks.is_in_use(slot).then(|| bricks.owner(slot));
            blending.update(&self.node_pool, bricks.allocated(), owner_of);
        }
    }

    /// The pools as renderers read them.
    pub fn view(&self) -> TreeView<'_> {
        TreeView {
            shape: self.shape,
            nodes: self.node_pool.nodes(),
            voxels: self.brick_pool.voxels(),
            voxel_format: self.brick_pool.format(),
            brick_ranges: self.brick_pool.ranges(),
            block_ranges: self.brick_pool.block_ranges(),
            brick_blends: self.blending.as_ref().map_or(&[], LevelBlending::caps),
            capacity: crate::tree_view::PoolCapacity {
                tiles: self.node_pool.capacity(),
                bricks: self.brick_pool.capacity(),
            },
        }
    }

    /// The feedback buffer the renderer writes into.
    pub fn feedback(&self) -> &FeedbackBuffer {
        &self.feedback
    }

    /// Produces the root now if it is missing, as a frame without rays whose one request is the root: every view of
    /// the volume needs it, so a cold frame's first pass need not be traced only to find it missing. `None` when
    /// the root is not missing.
    pub fn serve_root(&mut self, options: ServeOptions) -> Option<ServeReport> {
        if self.node_pool.node(NodeId::ROOT).data() != NodeData::Missing {
            return None;
        }
        self.begin_frame();
        self.feedback.push_requests(&[Request { node: NodeId::ROOT, kind: RequestKind::Produce, deficit: 1 }]);
        Some(self.end_frame(options))
    }

    /// Ends the frame: refreshes what the rays used, then serves their requests as `options` say.
    pub fn end_frame(&mut self, options: ServeOptions) -> ServeReport {
        let limit = options.limit;
        self.wait_for_data = options.wait_for_data;
        self.refresh_used();
        let (work, mut report) = self.take_work();
        let take = limit.unwrap_or(work.len()).min(work.len());
        // (A bound of 0 serves nothing and fetches nothing ahead: the last pass of a converged frame the pools cannot
        // hold, after which nothing is rendered.)
        if take < work.len() && limit != Some(0) {
            self.prefetch_deferred(&work[take..]);
        }
        // Rays still short of two or more levels: the level below what this frame serves is hinted to the producer
        // once it is served (converged passes, see `hint_next_level`).
        let short: Vec<(Request, NodeKey)> = if options.prefetch_new_children {
            work[..take].iter().filter(|(request, _)| request.deficit >= 2).copied().collect()
        } else {
            Vec::new()
        };
        // What this frame leaves unserved: past the bound, or deferred for want of room.
        let mut unserved: Vec<(Request, NodeKey)> = Vec::new();
        let mut new_tiles: Vec<(TileId, NodeKey)> = Vec::new();
        if self.restricted {
            self.serve_restricted(work, limit.unwrap_or(usize::MAX), &mut report, &mut new_tiles, &mut unserved);
        } else {
            unserved.extend_from_slice(&work[take..]);
            report.deferred += work.len() - take;
            let batch: Vec<Work> =
                work[..take].iter().map(|&(request, key)| Work { request, key, forced: false }).collect();
            self.serve(&batch, &mut report, &mut new_tiles, &mut unserved);
        }
        if options.prefetch_new_children {
            self.prefetch_children(&new_tiles, &mut report);
            self.hint_next_level(&short, &mut report);
        }
        if let Some(blending) = &mut self.blending {
            // The regions the rays want finer than resident: a missing node at its level, a childless one a level
            // below it.
            blending.set_pending(unserved.iter().map(|&(request, key)| match request.kind {
                RequestKind::Produce => (key, key.level),
                RequestKind::Subdivide => (key, key.level + 1),
            }));
        }
        self.frame += 1;
        report
    }
}

#[cfg(test)]
mod tests {
    use super::test_support::{request, root_children, Ramp};
    use super::*;

    #[test]
    fn the_root_is_served_without_rays_once_and_reports_say_what_the_rays_lacked() {
        let mut cache = CacheManager::new(Ramp, 16 << 20).unwrap();
        let report = cache.serve_root(ServeOptions::ALL).expect("a cold cache lacks its root");
        assert_eq!((report.requests, report.served, report.bricks_produced), (1, 1, 1));
        assert!(cache.node_pool().node(NodeId::ROOT).brick().is_some());
        assert!(cache.serve_root(ServeOptions::ALL).is_none(), "the root is there");
        assert_eq!(cache.check_invariants(), Ok(()));

        // The largest deficit among the frame's requests, and children a tile's subdivision left missing.
        cache.begin_frame();
        cache.feedback().push_requests(&[
            Request { node: NodeId::ROOT, kind: RequestKind::Subdivide, deficit: 1 },
            Request { node: NodeId::ROOT, kind: RequestKind::Subdivide, deficit: 3 },
        ]);
        let report = cache.end_frame(ServeOptions { limit: None, prefetch_new_children: true, wait_for_data: true });
        assert_eq!((report.largest_deficit, report.children_left_missing), (3, 0));
        // Ramp's oracle knows the first child constant; the other seven are produced with the tile.
        assert_eq!(report.bricks_prefetched, 7);
        let child = root_children(&cache)[1];
        let quiet = request(&mut cache, child, RequestKind::Subdivide, false);
        assert_eq!(quiet.largest_deficit, 1);
        cache.begin_frame();
        let idle = cache.end_frame(ServeOptions::ALL);
        assert_eq!((idle.pending, idle.largest_deficit), (0, 0));
    }
}
