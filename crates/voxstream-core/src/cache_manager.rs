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
//!   occluded; none for the shell scene, 2.6× the bricks for the sponge's 27-child tiles) for fewer passes; converged frames turn it on, interactive frames keep their bounded work.
//!   A child whose production fails is left missing, to be requested, and its failure reported, if a ray needs it.
//! - **Brick analysis.** A produced terminal brick whose voxels are all equal becomes a constant node (no brick
//!   slot). Non-terminal bricks stay bricks: only the producer knows whether finer levels are constant too.

use std::collections::HashSet;

use rayon::prelude::*;

use crate::brick_pool::{dequantize, BrickPool, PreparedBrick, VOXEL_MAX};
use crate::budget::PoolCapacities;
use crate::error::{CoreError, ProduceError};
use crate::feedback::{FeedbackBuffer, Request, RequestKind};
use crate::key::{NodeKey, TreeShape};
use crate::level_blending::LevelBlending;
use crate::node::{BrickSlot, Node, NodeData, NodeId, TileId};
use crate::node_pool::{NodePool, ROOT_TILE};
use crate::producer::{NodeContent, Produced, Producer};
use crate::request_queue::RequestQueue;
use crate::restriction::{self, reach, Reach};
use crate::tree_view::TreeView;
use crate::voxel_format::VoxelFormat;

/// Deferred requests passed to [`Producer::prefetch`] per frame.
pub const PREFETCH_LIMIT: usize = 1024;

/// Most requests produced concurrently before their results are applied (bounds transient memory; a small budget
/// gets smaller batches, [`PoolCapacities::production_batch`]).
pub const PRODUCTION_BATCH: usize = 256;

/// How [`CacheManager::end_frame`] serves one frame's requests.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ServeOptions {
    /// Most requests served (all if `None`); the rest wait for a later frame.
    pub limit: Option<usize>,
    /// Also produce the children of each new tile into free brick slots, never evicting (see the module docs).
    pub prefetch_new_children: bool,
    /// Produce nodes whose data is still on its way ([`Producer::ready`] says no), waiting for it: converged frames
    /// do; interactive frames leave them to a later frame, so that a frame never waits on slow storage.
    pub wait_for_data: bool,
}

impl ServeOptions {
    /// Serve every request, nothing more.
    pub const ALL: ServeOptions = ServeOptions { limit: None, prefetch_new_children: false, wait_for_data: true };
}

/// What serving one frame's requests did.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ServeReport {
    /// Distinct requests the rays made.
    pub requests: usize,
    /// Valid requests (still needing work) before the per-frame bound: 0 means the frame was complete.
    pub pending: usize,
    /// The largest level deficit among the valid requests (0 when there were none). At most 1, with every request
    /// served and the children of new tiles produced ([`ServeOptions::prefetch_new_children`]), means each ray that
    /// asked now finds the levels it wanted along the path it took.
    pub largest_deficit: u8,
    /// Requests served (some work done).
    pub served: usize,
    /// Requests left for a later frame (over the per-frame bound, or the pools were full of this frame's data).
    pub deferred: usize,
    /// Bricks produced and stored.
    pub bricks_produced: usize,
    /// Of `bricks_produced`, those stored for children of new tiles that no ray asked for yet
    /// ([`ServeOptions::prefetch_new_children`]).
    pub bricks_prefetched: usize,
    /// Children of new tiles left missing by [`ServeOptions::prefetch_new_children`] (no free slot, or their
    /// production failed).
    pub children_left_missing: usize,
    /// Nodes that turned out constant (oracle or brick analysis).
    pub constant_nodes: usize,
    /// Tiles created.
    pub tiles_created: usize,
    /// Bricks evicted to make room.
    pub bricks_evicted: usize,
    /// Tiles evicted (with their subtrees) to make room.
    pub tiles_evicted: usize,
    /// Of `served`, the forced ones: steps no ray asked for, served first so that what a ray asked for keeps the
    /// working set restricted ([`crate::restriction`]).
    pub forced: usize,
    /// Evictions that broke the restriction because every candidate the LRU looked at was needed to keep it: the
    /// memory budget won.
    pub restriction_yielded: usize,
    /// Producer failures recorded this frame.
    pub failures: Vec<ProduceError>,
}

/// Residency figures of the cache.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Residency {
    /// Bricks resident.
    pub bricks: u32,
    /// Nodes resident (tiles in use × N³).
    pub nodes: u64,
    /// Tiles in use.
    pub tiles: u32,
    /// Bytes of pool memory touched so far (high-water marks × per-slot bytes); never above the budget.
    pub bytes: u64,
    /// The budget.
    pub budget_bytes: u64,
}

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

    /// Turns level blending on with a fade-in of `fade_frames` frames (see [`crate::level_blending`]), or off with
    /// `None`. Off, the view carries no caps and frames are as without blending.
    pub fn set_blending(&mut self, fade_frames: Option<u32>) {
        self.blending = fade_frames.map(LevelBlending::new);
    }

    /// With blending on: how many levels per frame the camera's motion changes the wanted level by, for the next
    /// [`CacheManager::begin_frame`] (see [`LevelBlending::set_level_rate`]). Without blending it does nothing.
    pub fn set_blending_level_rate(&mut self, levels_per_frame: f64) {
        if let Some(blending) = &mut self.blending {
            blending.set_level_rate(levels_per_frame as f32);
        }
    }

    /// Keeps the working set restricted (Thiele et al.: neighbouring data at most one level apart, see
    /// [`crate::restriction`]) from the next frame on, or lets it free. Restricting a working set built free does
    /// not repair it at once: each ray request is served once its neighbourhood allows it, and the forced steps fill
    /// the gaps near what the rays ask for.
    pub fn set_restricted(&mut self, restricted: bool) {
        self.restricted = restricted;
    }

    /// Checks that the working set is restricted; returns the first violation. Used by tests.
    pub fn check_restricted(&self) -> Result<(), String> {
        restriction::check(&self.node_pool, |key| self.failed.contains(&key))
    }

    /// Ends any blending in progress: the next frame shows what is resident as it is (after an exact frame).
    pub fn settle_blending(&mut self) {
        if let Some(blending) = &mut self.blending {
            blending.settle();
        }
    }

    /// Whether the current frame's view blends some brick towards its parent (some brick is still in transition:
    /// fading in, or capped beside a region waiting for data): the image is not final yet.
    pub fn is_blending(&self) -> bool {
        self.blending.as_ref().is_some_and(LevelBlending::is_active)
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

    /// Residency figures.
    pub fn residency(&self) -> Residency {
        Residency {
            bricks: self.brick_pool.len(),
            nodes: self.node_pool.tiles_in_use() as u64 * self.shape.nodes_per_tile() as u64,
            tiles: self.node_pool.tiles_in_use(),
            bytes: self.capacities.bytes_for(self.node_pool.tiles_allocated(), self.brick_pool.allocated()),
            budget_bytes: self.capacities.budget_bytes,
        }
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
        let frame = self.frame;
        for tile in self.feedback.used_tiles().collect::<Vec<_>>() {
            self.node_pool.touch(tile, frame);
        }
        for brick in self.feedback.used_bricks().collect::<Vec<_>>() {
            self.brick_pool.touch(brick, frame);
        }
        let raw = self.feedback.take_requests();
        let node_pool = &self.node_pool;
        let queue = RequestQueue::build(raw, None, |node| node_pool.key(node).level);
        let mut report = ServeReport { requests: queue.len(), ..ServeReport::default() };

        // Keep what is still valid and not known to fail, up to the bound.
        let work: Vec<(Request, NodeKey)> = queue
            .requests
            .iter()
            .map(|queued| (queued.request, self.node_pool.key(queued.request.node)))
            .filter(|&(request, key)| self.still_wanted(request, key))
            .collect();
        report.pending = work.len();
        report.largest_deficit = work.iter().map(|(request, _)| request.deficit).max().unwrap_or(0);
        let take = limit.unwrap_or(work.len()).min(work.len());
        // (A bound of 0 serves nothing and fetches nothing ahead: the last pass of a converged frame the pools cannot
        // hold, after which nothing is rendered.)
        if take < work.len() && limit != Some(0) {
            // Let the producer fetch the deferred bricks in the background while the next frame renders.
            let deferred: Vec<NodeKey> = work[take..]
                .iter()
                .filter(|(request, _)| request.kind == RequestKind::Produce)
                .take(PREFETCH_LIMIT)
                .map(|&(_, key)| key)
                .collect();
            if !deferred.is_empty() {
                self.producer.prefetch(&deferred);
            }
        }
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

    /// Whether `request` (for the node of `key`) still needs work: its node still holds `key` (no tile recycling
    /// reused it), and it is missing and not known to fail, or childless and subdividable.
    fn still_wanted(&self, request: Request, key: NodeKey) -> bool {
        if !self.node_pool.is_in_use(request.node.tile(self.shape.nodes_per_tile()))
            || self.node_pool.key(request.node) != key
        {
            return false;
        }
        let node = self.node_pool.node(request.node);
        match request.kind {
            RequestKind::Produce => node.data() == NodeData::Missing && !self.failed.contains(&key),
            RequestKind::Subdivide => {
                !node.is_constant()
                    && !node.is_terminal()
                    && node.child_tile().is_none()
                    && key.level < self.shape.max_level
            }
        }
    }

    /// What must be served before the node of `key` may become complete ([`restriction::prerequisites`]; failed
    /// nodes count as satisfied).
    fn prerequisites(&self, key: NodeKey) -> Vec<Reach> {
        restriction::prerequisites(&self.node_pool, key, |k| self.failed.contains(&k))
    }

    /// Whether serving `request` now would break the restricted working set (when it is kept).
    fn is_premature(&self, request: Request, key: NodeKey) -> bool {
        self.restricted && request.kind == RequestKind::Produce && !self.prerequisites(key).is_empty()
    }

    /// Produces and subdivides `work` on worker threads, with no lock held, a batch at a time so that
    /// produced-but-unapplied bricks stay a bounded transient; applies each batch in order. What cannot be applied
    /// (no room, or the restriction no longer allows it) is counted deferred, and the rays' own requests among it
    /// go to `unserved`.
    fn serve(
        &mut self,
        work: &[Work],
        report: &mut ServeReport,
        new_tiles: &mut Vec<(TileId, NodeKey)>,
        unserved: &mut Vec<(Request, NodeKey)>,
    ) {
        for batch in work.chunks(self.capacities.production_batch.max(1) as usize) {
            // Under the restriction, what is premature already is not produced at all.
            let premature: Vec<bool> = batch.iter().map(|item| self.is_premature(item.request, item.key)).collect();
            let producer = &self.producer;
            let wait = self.wait_for_data;
            let (shape, format) = (self.shape, self.brick_pool.format());
            let produce_batch = || {
                in_space_order(
                    batch,
                    |item| item.key,
                    &shape,
                    |index| {
                        let item = &batch[index];
                        match item.request.kind {
                            _ if premature[index] => WorkResult::Premature,
                            // Data still on its way: asked again next frame, the frame does not wait for it.
                            RequestKind::Produce if !wait && !producer.ready(item.key) => WorkResult::Premature,
                            RequestKind::Produce => {
                                WorkResult::Produced(produce_analysed(producer, item.key, &shape, format))
                            }
                            RequestKind::Subdivide => WorkResult::Children(
                                (0..shape.nodes_per_tile())
                                    .map(|c| producer.oracle(item.key.child(c, shape.n)))
                                    .collect(),
                            ),
                        }
                    },
                )
            };
            let results: Vec<WorkResult> = match &self.io_pool {
                Some(pool) => pool.install(produce_batch),
                None => produce_batch(),
            };
            for (item, result) in batch.iter().zip(results) {
                let (request, key) = (item.request, item.key);
                // A forced step served earlier in the batch, or a recycled tile, may have made it moot; under the
                // restriction, an eviction earlier in the batch may have made it premature.
                if !self.still_wanted(request, key) {
                    continue;
                }
                let applied = !self.is_premature(request, key)
                    && match result {
                        WorkResult::Premature => false,
                        WorkResult::Produced(Ok(brick)) => {
                            self.apply_produced(request.node, brick, Eviction::Allowed, report)
                        }
                        WorkResult::Produced(Err(error)) => {
                            self.failed.insert(key);
                            report.failures.push(error);
                            true
                        }
                        WorkResult::Children(hints) => match self.apply_subdivide(request.node, &hints, report) {
                            Some(tile) => {
                                new_tiles.push((tile, key));
                                true
                            }
                            None => false,
                        },
                    };
                if applied {
                    report.served += 1;
                    report.forced += usize::from(item.forced);
                } else if !item.forced {
                    report.deferred += 1;
                    unserved.push((request, key));
                }
            }
        }
    }

    /// Serves the rays' `work` in rounds, keeping the working set restricted: a request to produce a node whose
    /// coarser neighbourhood is incomplete waits while the steps completing it are served (forced), coarsest first;
    /// everything served, forced or not, counts against `limit`. What is left waits for a later frame.
    fn serve_restricted(
        &mut self,
        work: Vec<(Request, NodeKey)>,
        mut limit: usize,
        report: &mut ServeReport,
        new_tiles: &mut Vec<(TileId, NodeKey)>,
        unserved: &mut Vec<(Request, NodeKey)>,
    ) {
        let mut waiting = work;
        while !waiting.is_empty() && limit > 0 {
            let mut round: Vec<Work> = Vec::new();
            // By node and kind: a forced step and a ray's request for the same node are one piece of work.
            let mut planned: HashSet<(NodeId, RequestKind)> = HashSet::new();
            let mut next: Vec<(Request, NodeKey)> = Vec::new();
            for (request, key) in waiting {
                if !self.still_wanted(request, key) {
                    continue;
                }
                if round.len() >= limit {
                    next.push((request, key));
                    continue;
                }
                let steps = if request.kind == RequestKind::Produce { self.forced_steps(key) } else { Vec::new() };
                if steps.is_empty() {
                    if planned.insert((request.node, request.kind)) {
                        if request.kind == RequestKind::Produce {
                            self.pin_neighbourhood(key);
                        }
                        round.push(Work { request, key, forced: false });
                    }
                    continue;
                }
                for (step, step_key) in steps {
                    if round.len() < limit && planned.insert((step.node, step.kind)) {
                        match step.kind {
                            RequestKind::Produce => self.pin_neighbourhood(step_key),
                            RequestKind::Subdivide => self.pin_path(step_key),
                        }
                        round.push(Work { request: step, key: step_key, forced: true });
                    }
                }
                next.push((request, key));
            }
            waiting = next;
            if round.is_empty() {
                break;
            }
            limit -= round.len();
            let served_before = report.served;
            self.serve(&round, report, new_tiles, unserved);
            if report.served == served_before {
                // Nothing could be applied (no room): later rounds would fare no better this frame.
                break;
            }
        }
        report.deferred += waiting.len();
        unserved.extend(waiting);
    }

    /// The steps that must be served before the node of `key` may be produced, each ready now (its own steps done):
    /// for every incomplete position one level up touching it, the first missing node on the way (or, if that one
    /// is not ready either, its own steps, recursively) or the first childless one. Failed nodes are never steps
    /// ([`CacheManager::prerequisites`]): their ancestors stand in, and nothing can be done for them.
    fn forced_steps(&self, key: NodeKey) -> Vec<(Request, NodeKey)> {
        fn visit<P: Producer>(
            cache: &CacheManager<P>,
            key: NodeKey,
            seen: &mut HashSet<NodeKey>,
            out: &mut Vec<(Request, NodeKey)>,
        ) {
            for step in cache.prerequisites(key) {
                match step {
                    Reach::Childless(node, step_key) => {
                        if seen.insert(step_key) {
                            out.push((Request { node, kind: RequestKind::Subdivide, deficit: 0 }, step_key));
                        }
                    }
                    Reach::Missing(node, step_key) => {
                        if !seen.insert(step_key) {
                            continue;
                        }
                        let before = out.len();
                        visit(cache, step_key, seen, out);
                        if out.len() == before {
                            out.push((Request { node, kind: RequestKind::Produce, deficit: 0 }, step_key));
                        }
                    }
                    Reach::Complete(_) | Reach::Final => {}
                }
            }
        }
        let mut out = Vec::new();
        visit(self, key, &mut HashSet::new(), &mut out);
        out
    }

    /// Marks the tiles and bricks on the way to `key` used in this frame, so that no eviction in this frame takes
    /// them.
    fn pin_path(&mut self, key: NodeKey) {
        let per_tile = self.shape.nodes_per_tile();
        let mut id = NodeId::ROOT;
        let mut here = NodeKey::ROOT;
        loop {
            let node = self.node_pool.node(id);
            if let Some(slot) = node.brick() {
                self.brick_pool.touch(slot, self.frame);
            }
            let (Some(tile), true) = (node.child_tile(), here.level < key.level) else { return };
            self.node_pool.touch(tile, self.frame);
            let child = restriction::child_towards(here, key, self.shape.n);
            id = NodeId::new(tile, child, per_tile);
            here = here.child(child, self.shape.n);
        }
    }

    /// Pins ([`CacheManager::pin_path`]) the node of `key` and every position one level up touching it: what keeps
    /// the working set restricted once the node is complete stays for this frame.
    fn pin_neighbourhood(&mut self, key: NodeKey) {
        self.pin_path(key);
        if key.level >= 2 {
            for position in restriction::touching(&self.shape, key, key.level - 1) {
                self.pin_path(position);
            }
        }
    }

    /// Produces the still-missing children of `new_tiles` (each with its parent's key) into free brick slots, in
    /// tile then child order, a batch at a time; stops when no slot is free. Nothing is evicted, and a failure
    /// leaves the child missing (a ray that needs it will request it, and the failure is reported then).
    fn prefetch_children(&mut self, new_tiles: &[(TileId, NodeKey)], report: &mut ServeReport) {
        let per_tile = self.shape.nodes_per_tile();
        let n = self.shape.n;
        let mut candidates: Vec<(NodeId, NodeKey)> = Vec::new();
        for &(tile, parent_key) in new_tiles {
            if !self.node_pool.is_in_use(tile) {
                continue;
            }
            for child in 0..per_tile {
                let node_id = NodeId::new(tile, child, per_tile);
                let key = parent_key.child(child, n);
                if self.node_pool.node(node_id).data() == NodeData::Missing
                    && !self.failed.contains(&key)
                    && !(self.restricted && !self.prerequisites(key).is_empty())
                {
                    candidates.push((node_id, key));
                }
            }
        }
        let batch_size = self.capacities.production_batch.max(1) as usize;
        let mut remaining = candidates.as_slice();
        while !remaining.is_empty() {
            // Produce no more than the free slots can take: constant children need no slot, so recount each time.
            let room = (self.brick_pool.free_slots() as usize).min(batch_size).min(remaining.len());
            if room == 0 {
                report.children_left_missing += remaining.len();
                break;
            }
            let (batch, rest) = remaining.split_at(room);
            remaining = rest;
            let producer = &self.producer;
            let wait = self.wait_for_data;
            let (shape, format) = (self.shape, self.brick_pool.format());
            // A child whose data is still on its way is left missing (its parent stands in; the rays ask for it).
            let produce_batch = || {
                in_space_order(
                    batch,
                    |&(_, key)| key,
                    &shape,
                    |index| {
                        let key = batch[index].1;
                        if wait || producer.ready(key) {
                            Some(produce_analysed(producer, key, &shape, format))
                        } else {
                            None
                        }
                    },
                )
            };
            let results: Vec<Option<Result<AnalysedBrick, ProduceError>>> = match &self.io_pool {
                Some(pool) => pool.install(produce_batch),
                None => produce_batch(),
            };
            for (&(node_id, _), result) in batch.iter().zip(results) {
                let Some(Ok(brick)) = result else {
                    report.children_left_missing += 1;
                    continue;
                };
                let is_brick = matches!(brick.content, AnalysedContent::Brick(_));
                if !self.apply_produced(node_id, brick, Eviction::Forbidden, report) {
                    report.children_left_missing += 1;
                } else if is_brick {
                    report.bricks_prefetched += 1;
                }
            }
        }
    }

    fn apply_produced(
        &mut self,
        node_id: NodeId,
        brick: AnalysedBrick,
        eviction: Eviction,
        report: &mut ServeReport,
    ) -> bool {
        match &brick.content {
            &AnalysedContent::Constant(value) => {
                // A constant node never has children: free any subtree it still has.
                if let Some(child) = self.node_pool.node(node_id).child_tile() {
                    self.free_subtree(child);
                }
                *self.node_pool.node_mut(node_id) = Node::constant(value);
                report.constant_nodes += 1;
                true
            }
            AnalysedContent::Brick(prepared) => {
                let inserted = match eviction {
                    Eviction::Allowed => {
                        let (pool, restricted) = (&self.node_pool, self.restricted);
                        let keep = |owner: NodeId| restricted && evicting_breaks_restriction(pool, owner);
                        self.brick_pool.insert_avoiding(node_id, prepared, self.frame, keep).map(
                            |(slot, evicted, yielded)| {
                                report.restriction_yielded += usize::from(yielded);
                                (slot, evicted)
                            },
                        )
                    }
                    Eviction::Forbidden => {
                        self.brick_pool.insert_if_free(node_id, prepared, self.frame).map(|slot| (slot, None))
                    }
                };
                let Some((slot, evicted)) = inserted else {
                    return false;
                };
                if let Some(previous_owner) = evicted {
                    self.node_pool.node_mut(previous_owner).set_brick(None);
                    report.bricks_evicted += 1;
                    // Restricted: a node without data keeps no children. Produced again later, it would otherwise
                    // make its cached subtree complete at once, unchecked against neighbours evicted meanwhile.
                    if self.restricted {
                        if let Some(children) = self.node_pool.node(previous_owner).child_tile() {
                            if !self.is_ancestor_tile(children, node_id) {
                                self.node_pool.node_mut(previous_owner).set_child_tile(None);
                                self.free_subtree(children);
                            }
                        }
                    }
                }
                if let Some(range) = brick.subtree_range {
                    self.brick_pool.widen_range(slot, range);
                }
                if let Some(blending) = &mut self.blending {
                    let parent = self.node_pool.record(node_id.tile(self.shape.nodes_per_tile())).parent;
                    let parent_brick =
                        (parent != u32::MAX).then(|| self.node_pool.node(NodeId(parent)).brick()).flatten();
                    blending.arrived(slot, node_id, parent_brick);
                }
                let node = self.node_pool.node_mut(node_id);
                node.set_brick(Some(slot));
                node.set_terminal(brick.is_terminal);
                report.bricks_produced += 1;
                true
            }
        }
    }

    /// Gives `node_id` a tile of children (constant where `hints` say so); returns the tile, `None` if every tile
    /// was used during this frame.
    fn apply_subdivide(&mut self, node_id: NodeId, hints: &[Option<f32>], report: &mut ServeReport) -> Option<TileId> {
        let (pool, restricted) = (&self.node_pool, self.restricted);
        let keep = |tile: TileId| restricted && freeing_breaks_restriction(pool, tile);
        if let Some((victim, yielded)) = self.node_pool.oldest_recyclable_avoiding(self.frame, keep) {
            report.restriction_yielded += usize::from(yielded);
            self.detach_and_free(victim);
            report.tiles_evicted += 1;
        }
        let (tile, _) = self.node_pool.allocate(node_id, self.frame)?;
        self.node_pool.node_mut(node_id).set_child_tile(Some(tile));
        let per_tile = self.shape.nodes_per_tile();
        for (child, hint) in hints.iter().enumerate() {
            if let Some(value) = hint {
                *self.node_pool.node_mut(NodeId::new(tile, child as u32, per_tile)) = Node::constant(*value);
                report.constant_nodes += 1;
            }
        }
        report.tiles_created += 1;
        Some(tile)
    }

    /// Whether `node` lies in the subtree rooted at `tile`.
    fn is_ancestor_tile(&self, tile: TileId, node: NodeId) -> bool {
        let per_tile = self.shape.nodes_per_tile();
        let mut current = node.tile(per_tile);
        loop {
            if current == tile {
                return true;
            }
            let parent = self.node_pool.record(current).parent;
            if current == ROOT_TILE || parent == u32::MAX {
                return false;
            }
            current = NodeId(parent).tile(per_tile);
        }
    }

    /// Clears the parent's pointer to `tile`, then frees the tile's subtree.
    fn detach_and_free(&mut self, tile: TileId) {
        let parent = self.node_pool.record(tile).parent;
        if parent != u32::MAX {
            self.node_pool.node_mut(NodeId(parent)).set_child_tile(None);
        }
        self.free_subtree(tile);
    }

    fn free_subtree(&mut self, tile: TileId) {
        let per_tile = self.shape.nodes_per_tile();
        let mut stack = vec![tile];
        while let Some(tile) = stack.pop() {
            for child in 0..per_tile {
                let node = self.node_pool.node(NodeId::new(tile, child, per_tile));
                if let Some(slot) = node.brick() {
                    self.brick_pool.release(slot);
                }
                if let Some(grandchildren) = node.child_tile() {
                    stack.push(grandchildren);
                }
            }
            if tile != ROOT_TILE {
                self.node_pool.release(tile);
            }
        }
    }

    /// Checks every structural invariant; returns the first violation. Used by tests.
    ///
    /// - every child pointer names a tile in use whose record points back at the node;
    /// - every brick pointer names a slot in use whose owner is the node;
    /// - every tile in use is reachable from the root, every brick in use is owned by a reachable node;
    /// - the touched memory is within the budget.
    pub fn check_invariants(&self) -> Result<(), String> {
        let per_tile = self.shape.nodes_per_tile();
        let mut reachable_tiles = 1u32;
        let mut reachable_bricks = 0u32;
        let mut stack: Vec<(NodeId, u32)> = vec![(NodeId::ROOT, 0)];
        while let Some((id, level)) = stack.pop() {
            let node = self.node_pool.node(id);
            if let Some(slot) = node.brick() {
                if !self.brick_pool.is_in_use(slot) {
                    return Err(format!("node {id:?} points at free brick {slot:?}"));
                }
                if self.brick_pool.owner(slot) != id {
                    return Err(format!("brick {slot:?} is owned by {:?}, not {id:?}", self.brick_pool.owner(slot)));
                }
                reachable_bricks += 1;
            }
            if let Some(tile) = node.child_tile() {
                if node.is_constant() {
                    return Err(format!("constant node {id:?} has children"));
                }
                if !self.node_pool.is_in_use(tile) {
                    return Err(format!("node {id:?} points at free tile {tile:?}"));
                }
                if self.node_pool.record(tile).parent != id.0 {
                    return Err(format!("tile {tile:?} does not point back at {id:?}"));
                }
                if self.node_pool.record(tile).level != level + 1 {
                    return Err(format!("tile {tile:?} has the wrong level"));
                }
                reachable_tiles += 1;
                for child in 0..per_tile {
                    stack.push((NodeId::new(tile, child, per_tile), level + 1));
                }
            }
        }
        if reachable_tiles != self.node_pool.tiles_in_use() {
            return Err(format!("{} tiles in use, {} reachable", self.node_pool.tiles_in_use(), reachable_tiles));
        }
        if reachable_bricks != self.brick_pool.len() {
            return Err(format!("{} bricks in use, {} reachable", self.brick_pool.len(), reachable_bricks));
        }
        let residency = self.residency();
        if residency.bytes > residency.budget_bytes {
            return Err(format!("{} bytes resident, budget {}", residency.bytes, residency.budget_bytes));
        }
        Ok(())
    }
}

/// One step to serve: a ray's request, or a forced step of the restriction.
#[derive(Clone, Copy)]
struct Work {
    request: Request,
    key: NodeKey,
    forced: bool,
}

/// Whether evicting the brick of `owner` would leave finer complete data beside it, two levels finer than what is
/// drawn there then ([`crate::restriction`]).
fn evicting_breaks_restriction(pool: &NodePool, owner: NodeId) -> bool {
    let key = pool.key(owner);
    reach(pool, key) == Reach::Complete(owner) && restriction::finer_data_touches(pool, key, key.level)
}

/// Whether freeing `tile` (its parent's children and their subtrees) would leave finer complete data beside the
/// parent, two levels finer than the parent drawn there then.
fn freeing_breaks_restriction(pool: &NodePool, tile: TileId) -> bool {
    let record = pool.record(tile);
    if record.parent == u32::MAX {
        return false;
    }
    let parent = NodeKey { level: record.level - 1, ijk: record.parent_ijk };
    // Below a node that is not complete nothing is drawn, so nothing depends on it.
    reach(pool, parent) == Reach::Complete(NodeId(record.parent))
        && restriction::finer_data_touches(pool, parent, record.level)
}

/// Whether storing a produced brick may recycle the least recently used slot.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Eviction {
    /// A ray asked for it: recycle if needed.
    Allowed,
    /// Speculative: free slots only.
    Forbidden,
}

/// What a produced node holds, ready to apply.
enum AnalysedContent {
    /// One value throughout (0 for an empty node).
    Constant(f32),
    /// Voxels, prepared for the pool on the worker that produced them.
    Brick(PreparedBrick),
}

enum WorkResult {
    Produced(Result<AnalysedBrick, ProduceError>),
    Children(Vec<Option<f32>>),
    /// Not done: producing it would break the restricted working set.
    Premature,
}

struct AnalysedBrick {
    content: AnalysedContent,
    is_terminal: bool,
    /// The producer's bounds of the whole subtree (stored units, rounded outwards), for a brick with children.
    subtree_range: Option<[u16; 2]>,
}

/// `work(i)` for every item of `batch`, on worker threads, computed in space-filling-curve order of the items' nodes
/// (the Morton code of each node's corner at the finest level, then the level) and returned in the batch's order.
///
/// Nodes near each other in space are then made by the same thread close together in time, so a producer reading
/// spatial bins (a store's chunks, out-of-core particle superbricks) finds them still cached: the batch's order is
/// the rays' priority, not space. What is produced and the order results are applied in do not change.
fn in_space_order<T: Sync, R: Send>(
    batch: &[T],
    key_of: impl Fn(&T) -> NodeKey,
    shape: &TreeShape,
    work: impl Fn(usize) -> R + Sync,
) -> Vec<R> {
    let mut order: Vec<(u64, u32, usize)> = batch
        .iter()
        .enumerate()
        .map(|(index, item)| {
            let key = key_of(item);
            // The node's corner in nodes of the finest level (N^(levels below) per node; an order, so an overflow
            // only costs locality).
            let scale = u64::from(shape.n).saturating_pow(shape.max_level.saturating_sub(key.level));
            let corner = key.ijk.map(|c| c.saturating_mul(scale));
            (morton_code(corner), key.level, index)
        })
        .collect();
    order.sort_unstable();
    let mut results: Vec<(usize, R)> = order.par_iter().map(|&(_, _, index)| (index, work(index))).collect();
    results.sort_unstable_by_key(|&(index, _)| index);
    results.into_iter().map(|(_, result)| result).collect()
}

/// The Morton (Z-order) code of `ijk`'s low 21 bits per axis.
fn morton_code(ijk: [u64; 3]) -> u64 {
    fn spread(v: u64) -> u64 {
        let mut x = v & 0x1f_ffff;
        x = (x | x << 32) & 0x1f00000000ffff;
        x = (x | x << 16) & 0x1f0000ff0000ff;
        x = (x | x << 8) & 0x100f00f00f00f00f;
        x = (x | x << 4) & 0x10c30c30c30c30c3;
        (x | x << 2) & 0x1249249249249249
    }
    spread(ijk[0]) | spread(ijk[1]) << 1 | spread(ijk[2]) << 2
}

/// Asks `producer` for the brick of `key`, then analyses it.
fn produce_analysed<P: Producer>(
    producer: &P,
    key: NodeKey,
    shape: &TreeShape,
    format: VoxelFormat,
) -> Result<AnalysedBrick, ProduceError> {
    let mut voxels = vec![0u16; shape.voxels_per_brick()];
    let produced = producer.produce(key, &mut voxels)?;
    let mut analysed = analyse(produced, &voxels, key, shape, format);
    if matches!(analysed.content, AnalysedContent::Brick(_)) && !analysed.is_terminal {
        analysed.subtree_range = producer.subtree_range(key).map(|[lo, hi]| {
            let stored = |v: f32| (v.clamp(0.0, 1.0) * VOXEL_MAX as f32) as f64;
            [stored(lo).floor() as u16, stored(hi).ceil() as u16]
        });
    }
    Ok(analysed)
}

/// Brick analysis before upload ([R08] §4): a terminal brick of equal voxels is a constant node. A non-terminal one
/// stays a brick: equal voxels at a coarse level (an average) say nothing of the finer levels, and a constant node
/// is never subdivided; only the producer may declare a whole subtree constant. A brick is prepared for a pool of
/// `format` here, on the producing thread.
fn analyse(produced: Produced, voxels: &[u16], key: NodeKey, shape: &TreeShape, format: VoxelFormat) -> AnalysedBrick {
    let is_terminal = produced.is_terminal || key.level >= shape.max_level;
    let content = match produced.content {
        NodeContent::Brick if is_terminal && voxels.iter().all(|&v| v == voxels[0]) => {
            AnalysedContent::Constant(dequantize(voxels[0]))
        }
        NodeContent::Brick => AnalysedContent::Brick(PreparedBrick::new(shape, format, voxels)),
        NodeContent::Empty => AnalysedContent::Constant(0.0),
        NodeContent::Constant(value) => AnalysedContent::Constant(value),
    };
    AnalysedBrick { content, is_terminal, subtree_range: None }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every node a brick of varying voxels; the oracle knows that the first child of every tile (all of `ijk` even)
    /// is empty.
    struct Ramp;
    impl Producer for Ramp {
        fn shape(&self) -> TreeShape {
            TreeShape::new(2, 8, 3).unwrap()
        }
        fn oracle(&self, key: NodeKey) -> Option<f32> {
            (key.level > 0 && key.ijk.iter().all(|c| c % 2 == 0)).then_some(0.0)
        }
        fn produce(&self, key: NodeKey, voxels: &mut [u16]) -> Result<Produced, ProduceError> {
            for (index, v) in voxels.iter_mut().enumerate() {
                *v = (index as u16).wrapping_mul(7).wrapping_add(key.level as u16);
            }
            Ok(Produced { content: NodeContent::Brick, is_terminal: key.level == self.shape().max_level })
        }
    }

    fn request(cache: &mut CacheManager<Ramp>, node: NodeId, kind: RequestKind, prefetch: bool) -> ServeReport {
        cache.begin_frame();
        cache.feedback().push_requests(&[Request { node, kind, deficit: 1 }]);
        let report =
            cache.end_frame(ServeOptions { limit: None, prefetch_new_children: prefetch, wait_for_data: true });
        assert_eq!(cache.check_invariants(), Ok(()));
        report
    }

    /// The nodes that own a brick, sorted.
    fn brick_owners(cache: &CacheManager<Ramp>) -> Vec<NodeId> {
        let pool = cache.brick_pool();
        let mut owners: Vec<NodeId> = (0..pool.allocated())
            .map(crate::node::BrickSlot)
            .filter(|&slot| pool.is_in_use(slot))
            .map(|slot| pool.owner(slot))
            .collect();
        owners.sort_by_key(|id| id.0);
        owners
    }

    fn root_children(cache: &CacheManager<Ramp>) -> Vec<NodeId> {
        let tile = cache.node_pool().node(NodeId::ROOT).child_tile().unwrap();
        (0..8).map(|c| NodeId::new(tile, c, 8)).collect()
    }

    /// The blending caps of the node's brick in the current frame's view (all 1 when the view carries none).
    fn caps_of(cache: &CacheManager<Ramp>, node: NodeId) -> crate::BrickBlend {
        let slot = cache.node_pool().node(node).brick().expect("a brick");
        cache.view().brick_blends.get(slot.0 as usize).copied().unwrap_or(crate::BrickBlend::FULL)
    }

    #[test]
    fn fades_keep_pace_with_a_camera_that_approaches() {
        let mut cache = CacheManager::new(Ramp, 16 << 20).unwrap();
        cache.set_blending(Some(4));
        request(&mut cache, NodeId::ROOT, RequestKind::Produce, false);
        request(&mut cache, NodeId::ROOT, RequestKind::Subdivide, false);
        let [first, second] = [root_children(&cache)[1], root_children(&cache)[2]];
        // The root is in at once: nothing blends.
        assert!(!cache.is_blending());
        // At rest: a quarter per frame.
        request(&mut cache, first, RequestKind::Produce, false);
        cache.set_blending_level_rate(0.0);
        cache.begin_frame();
        assert_eq!(caps_of(&cache, first).fade, 0.25);
        cache.end_frame(ServeOptions::ALL);
        // The camera now wants a level finer every 16 frames: eight fades in 16 frames, half a fade per frame.
        cache.set_blending_level_rate(1.0 / 16.0);
        cache.begin_frame();
        assert_eq!(caps_of(&cache, first).fade, 0.75);
        cache.end_frame(ServeOptions::ALL);
        // Slower than the fade-in itself asks for: the fade-in's own pace; nonsense rates count as rest.
        request(&mut cache, second, RequestKind::Produce, false);
        for rate in [0.01, f64::NAN, -1.0] {
            cache.set_blending_level_rate(rate);
            cache.begin_frame();
            cache.end_frame(ServeOptions::ALL);
        }
        assert_eq!(caps_of(&cache, second).fade, 0.75, "{:?}", caps_of(&cache, second));
        // An infinite pace ends the fade at once.
        let third = root_children(&cache)[3];
        request(&mut cache, third, RequestKind::Produce, false);
        cache.set_blending_level_rate(f64::INFINITY);
        cache.begin_frame();
        assert_eq!(caps_of(&cache, third).fade, 1.0);
        cache.end_frame(ServeOptions::ALL);
        // Without blending the rate does nothing.
        cache.set_blending(None);
        cache.set_blending_level_rate(1.0);
        cache.begin_frame();
        assert!(cache.view().brick_blends.is_empty());
    }

    #[test]
    fn the_root_is_in_at_once_and_its_children_fade_in_from_the_next_frame() {
        let mut cache = CacheManager::new(Ramp, 16 << 20).unwrap();
        cache.set_blending(Some(4));
        request(&mut cache, NodeId::ROOT, RequestKind::Produce, false);
        // The next frame's caps: the root has no parent brick to fade from, so nothing blends.
        request(&mut cache, NodeId::ROOT, RequestKind::Subdivide, false);
        assert!(cache.view().brick_blends.is_empty());
        assert!(!cache.is_blending());
        let child = root_children(&cache)[1];
        request(&mut cache, child, RequestKind::Produce, false);
        // The next frame draws the child a quarter in: it does not wait for the root.
        cache.begin_frame();
        assert_eq!(caps_of(&cache, child).fade, 0.25);
        assert_eq!(caps_of(&cache, NodeId::ROOT), crate::BrickBlend::FULL);
        cache.end_frame(ServeOptions::ALL);
    }

    #[test]
    fn an_arriving_brick_fades_in_to_1_its_children_wait_for_it_and_speed_it_up() {
        let mut cache = CacheManager::new(Ramp, 16 << 20).unwrap();
        cache.set_blending(Some(4));
        request(&mut cache, NodeId::ROOT, RequestKind::Produce, false);
        request(&mut cache, NodeId::ROOT, RequestKind::Subdivide, false);
        let parent = root_children(&cache)[1];
        request(&mut cache, parent, RequestKind::Produce, false);
        request(&mut cache, parent, RequestKind::Subdivide, false);
        assert_eq!(caps_of(&cache, parent).fade, 0.25, "a quarter per frame");
        let tile = cache.node_pool().node(parent).child_tile().unwrap();
        let child = NodeId::new(tile, 1, 8);
        // The child arrives while its parent is at 0.5.
        request(&mut cache, child, RequestKind::Produce, false);
        let mut parent_fades = Vec::new();
        let mut child_fades = Vec::new();
        for _ in 0..7 {
            cache.begin_frame();
            parent_fades.push(caps_of(&cache, parent).fade);
            child_fades.push(caps_of(&cache, child).fade);
            cache.end_frame(ServeOptions::ALL);
        }
        // With a generation waiting below it, the parent rises by two quarters: in at once.
        assert_eq!(parent_fades, [1.0; 7]);
        // The child waited at 0 while its parent was below 1, then rises by a quarter per frame to 1.
        assert_eq!(child_fades[..5], [0.0, 0.25, 0.5, 0.75, 1.0]);
        assert!(!cache.is_blending(), "all in: the view carries no caps");
        assert!(cache.view().brick_blends.is_empty());
    }

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

    #[test]
    fn children_without_room_are_reported_left_missing() {
        // The smallest budget the planner accepts: a few tiles of children fill its brick pool.
        let mut cache = (1..100_000u64).find_map(|step| CacheManager::new(Ramp, step * 64).ok()).unwrap();
        request(&mut cache, NodeId::ROOT, RequestKind::Produce, false);
        let mut parents = vec![NodeId::ROOT];
        let mut subdivided = 0;
        loop {
            let parent = parents[subdivided];
            subdivided += 1;
            let free = cache.brick_pool().free_slots() as usize;
            let report = request(&mut cache, parent, RequestKind::Subdivide, true);
            // Seven children to produce (Ramp's oracle knows the first of each tile constant).
            assert_eq!(report.bricks_prefetched + report.children_left_missing, 7);
            assert_eq!(report.bricks_prefetched, free.min(7));
            if report.children_left_missing > 0 {
                assert_eq!(cache.brick_pool().free_slots(), 0, "children are left missing only without room");
                break;
            }
            let tile = cache.node_pool().node(parent).child_tile().unwrap();
            parents.extend((1..8).map(|child| NodeId::new(tile, child, 8)));
        }
        assert!(subdivided > 1, "the pool holds the root's children");
    }

    /// A brick everywhere but at the level-1 node (1, 0, 0), whose production fails.
    struct FailsOnce;
    impl Producer for FailsOnce {
        fn shape(&self) -> TreeShape {
            TreeShape::new(2, 8, 3).unwrap()
        }
        fn produce(&self, key: NodeKey, voxels: &mut [u16]) -> Result<Produced, ProduceError> {
            if key == (NodeKey { level: 1, ijk: [1, 0, 0] }) {
                return Err(ProduceError { level: key.level, ijk: key.ijk, message: "unreadable".into() });
            }
            Ramp.produce(key, voxels)
        }
    }

    #[test]
    fn morton_codes_interleave_the_axes() {
        assert_eq!(morton_code([1, 0, 0]), 1);
        assert_eq!(morton_code([0, 1, 0]), 2);
        assert_eq!(morton_code([0, 0, 1]), 4);
        assert_eq!(morton_code([3, 5, 6]), 0b110_101_011);
        assert_eq!(morton_code([(1 << 21) - 1; 3]), (1 << 63) - 1);
        // Results come back in the batch's order whatever the order of work.
        let shape = TreeShape::new(2, 8, 4).unwrap();
        let keys: Vec<NodeKey> =
            (0..50u64).map(|i| NodeKey { level: (i % 5) as u32, ijk: [i % 3, (i * 7) % 5, i % 2] }).collect();
        let results = in_space_order(&keys, |k| *k, &shape, |i| keys[i]);
        assert_eq!(results, keys);
    }

    #[test]
    fn the_restriction_forces_coarser_neighbours_first_and_passes_over_failed_ones() {
        let mut cache = CacheManager::new(FailsOnce, 16 << 20).unwrap();
        cache.set_restricted(true);
        let serve = |cache: &mut CacheManager<FailsOnce>, node: NodeId, kind: RequestKind| {
            cache.begin_frame();
            cache.feedback().push_requests(&[Request { node, kind, deficit: 1 }]);
            let report = cache.end_frame(ServeOptions::ALL);
            assert_eq!(cache.check_invariants(), Ok(()));
            assert_eq!(cache.check_restricted(), Ok(()));
            report
        };
        serve(&mut cache, NodeId::ROOT, RequestKind::Produce);
        serve(&mut cache, NodeId::ROOT, RequestKind::Subdivide);
        let tile = cache.node_pool().node(NodeId::ROOT).child_tile().unwrap();
        let level1 = |c: u32| NodeId::new(tile, c, 8);
        // (0, 0, 0) gets data and children; its children's level-1 neighbours have none yet.
        serve(&mut cache, level1(0), RequestKind::Produce);
        serve(&mut cache, level1(0), RequestKind::Subdivide);
        let grandchildren = cache.node_pool().node(level1(0)).child_tile().unwrap();
        // The level-2 node (1, 1, 0) touches the level-1 nodes (0 or 1, 0 or 1, 0): three of them still missing. Its
        // request waits while they are produced (forced), then it is served in the same frame.
        let corner = NodeId::new(grandchildren, 1 + 2, 8);
        assert_eq!(cache.node_pool().key(corner), NodeKey { level: 2, ijk: [1, 1, 0] });
        let report = serve(&mut cache, corner, RequestKind::Produce);
        assert_eq!(report.forced, 3, "{report:?}");
        assert_eq!(report.failures.len(), 1, "(1, 0, 0) fails");
        assert!(
            cache.node_pool().node(level1(2)).brick().is_some() && cache.node_pool().node(level1(3)).brick().is_some()
        );
        // Beside the failed node the request is served all the same: its ancestor stands in for good.
        assert!(cache.node_pool().node(corner).brick().is_some(), "{report:?}");
        assert_eq!(report.deferred, 0);
    }

    #[test]
    fn a_brick_drawn_in_full_is_never_taken_back_by_an_arriving_neighbour() {
        let mut cache = CacheManager::new(Ramp, 16 << 20).unwrap();
        cache.set_blending(Some(4));
        request(&mut cache, NodeId::ROOT, RequestKind::Produce, false);
        request(&mut cache, NodeId::ROOT, RequestKind::Subdivide, false);
        let children = root_children(&cache);
        request(&mut cache, children[1], RequestKind::Produce, false);
        for _ in 0..6 {
            cache.begin_frame();
            cache.end_frame(ServeOptions::ALL);
        }
        assert!(!cache.is_blending());
        // Child 3 is child 1's neighbour along y: it arrives, and child 1 (drawn in full) keeps its caps at 1.
        request(&mut cache, children[3], RequestKind::Produce, false);
        cache.begin_frame();
        assert!(caps_of(&cache, children[1]).is_full() && caps_of(&cache, children[1]).is_in());
        let arriving = caps_of(&cache, children[3]);
        assert_eq!((arriving.fade, arriving.corners()), (0.25, [0.25; 8]));
        cache.end_frame(ServeOptions::ALL);
    }

    #[test]
    fn corners_touching_a_region_still_waiting_for_data_stay_at_0_unless_the_camera_outpaces_the_fades() {
        let mut cache = CacheManager::new(Ramp, 16 << 20).unwrap();
        cache.set_blending(Some(2));
        request(&mut cache, NodeId::ROOT, RequestKind::Produce, false);
        request(&mut cache, NodeId::ROOT, RequestKind::Subdivide, false);
        for _ in 0..3 {
            cache.begin_frame();
            cache.end_frame(ServeOptions::ALL);
        }
        let children = root_children(&cache);
        // Child 1 (x = 1, y = 0, z = 0) and child 3 (x = 1, y = 1, z = 0) share a face; both are asked for in a
        // frame that serves one request: the other waits, and the served one's corners on that face stay at 0.
        cache.begin_frame();
        cache.feedback().push_requests(&[
            Request { node: children[1], kind: RequestKind::Produce, deficit: 1 },
            Request { node: children[3], kind: RequestKind::Produce, deficit: 1 },
        ]);
        cache.end_frame(ServeOptions { limit: Some(1), prefetch_new_children: false, wait_for_data: true });
        let first_served = cache.node_pool().node(children[1]).brick().is_some();
        let (served, waiting) = if first_served { (children[1], children[3]) } else { (children[3], children[1]) };
        // Corner c has y = (c >> 1) & 1; the shared face is y = 1 of child 1, y = 0 of child 3.
        let touches = |c: usize| ((c >> 1) & 1 == 1) == first_served;
        for _ in 0..3 {
            cache.begin_frame();
            let corners = caps_of(&cache, served).corners();
            for c in (0..8).filter(|&c| touches(c)) {
                assert_eq!(corners[c], 0.0, "corner {c}");
            }
            // The other child is still wanted: asked for again, served never.
            cache.feedback().push_requests(&[Request { node: waiting, kind: RequestKind::Produce, deficit: 1 }]);
            cache.end_frame(ServeOptions { limit: Some(0), prefetch_new_children: false, wait_for_data: true });
        }
        let corners = caps_of(&cache, served).corners();
        assert!((0..8).filter(|&c| !touches(c)).all(|c| corners[c] == 1.0), "the other corners are in: {corners:?}");
        assert!(cache.is_blending(), "the served brick is not drawn in full while its neighbour waits");
        // A camera that approaches a hair slower than a fade per frame: the waiting region still caps the corners.
        let outpacing = 1.0 / crate::level_blending::FADES_PER_LEVEL as f64;
        cache.set_blending_level_rate(outpacing * 0.99);
        cache.begin_frame();
        assert!((0..8).filter(|&c| touches(c)).all(|c| caps_of(&cache, served).corners()[c] == 0.0));
        cache.feedback().push_requests(&[Request { node: waiting, kind: RequestKind::Produce, deficit: 1 }]);
        cache.end_frame(ServeOptions { limit: Some(0), prefetch_new_children: false, wait_for_data: true });
        // One so fast that a fade ends within the frame (FADES_PER_LEVEL fades in the frames it takes to want the
        // next level): the region still waiting caps nothing, and the served brick is drawn in full.
        cache.set_blending_level_rate(outpacing);
        cache.begin_frame();
        assert_eq!(caps_of(&cache, served), crate::BrickBlend::FULL);
        cache.feedback().push_requests(&[Request { node: waiting, kind: RequestKind::Produce, deficit: 1 }]);
        cache.end_frame(ServeOptions { limit: Some(0), prefetch_new_children: false, wait_for_data: true });
        // At rest again the waiting region does not take it back (it left the transitions, drawn in full).
        cache.set_blending_level_rate(0.0);
        cache.begin_frame();
        assert_eq!(caps_of(&cache, served), crate::BrickBlend::FULL);
        cache.end_frame(ServeOptions::ALL);
    }

    #[test]
    fn a_subdivision_produces_the_children_the_oracle_does_not_know_when_asked_to() {
        for prefetch in [false, true] {
            let mut cache = CacheManager::new(Ramp, 16 << 20).unwrap();
            request(&mut cache, NodeId::ROOT, RequestKind::Produce, prefetch);
            let report = request(&mut cache, NodeId::ROOT, RequestKind::Subdivide, prefetch);
            let children = root_children(&cache);
            assert_eq!(report.tiles_created, 1);
            assert_eq!(report.constant_nodes, 1, "child 0 is known empty");
            assert!(cache.node_pool().node(children[0]).is_constant());
            let expected = if prefetch { 7 } else { 0 };
            assert_eq!(report.bricks_prefetched, expected);
            assert_eq!(report.bricks_produced, expected);
            let with_bricks = children.iter().filter(|&&child| cache.node_pool().node(child).brick().is_some()).count();
            assert_eq!(with_bricks, expected);
        }
    }

    #[test]
    fn prefetching_fills_only_free_slots_and_never_evicts() {
        // The smallest budget: a few more brick slots than the root and its children need.
        let minimum = match PoolCapacities::plan(&Ramp.shape(), 0) {
            Err(CoreError::BudgetTooSmall { minimum_bytes, .. }) => minimum_bytes,
            other => panic!("expected BudgetTooSmall, got {other:?}"),
        };
        let mut cache = (0..1000)
            .find_map(|step| CacheManager::new(Ramp, minimum + step * 1024).ok())
            .expect("a budget a little above the minimum plans");
        let capacity = cache.brick_pool().capacity();
        request(&mut cache, NodeId::ROOT, RequestKind::Produce, true);
        request(&mut cache, NodeId::ROOT, RequestKind::Subdivide, true);
        // Subdivide the root's children one by one until the pool is full, then once more.
        let mut was_full = false;
        for child in root_children(&cache).into_iter().skip(1) {
            let free_before = cache.brick_pool().free_slots() as usize;
            let owners_before = brick_owners(&cache);
            let report = request(&mut cache, child, RequestKind::Subdivide, true);
            assert_eq!(report.tiles_created, 1);
            assert_eq!(report.bricks_evicted, 0);
            assert_eq!(report.tiles_evicted, 0);
            assert_eq!(report.bricks_prefetched, free_before.min(7), "7 unknown children, {free_before} free slots");
            let owners_after = brick_owners(&cache);
            assert!(owners_before.iter().all(|owner| owners_after.contains(owner)), "a resident brick was evicted");
            assert!(cache.brick_pool().len() <= capacity);
            if free_before == 0 {
                was_full = true;
                assert_eq!(owners_after, owners_before);
            }
        }
        assert!(was_full, "the pool of {capacity} bricks never filled up");
    }
}
