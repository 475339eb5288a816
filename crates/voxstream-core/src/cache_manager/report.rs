//! What the cache reports: the counts of one frame's serving ([`ServeReport`]) and the residency of its pools
//! ([`Residency`]).

use crate::error::ProduceError;
use crate::producer::Producer;

use super::CacheManager;
#[cfg(doc)]
use super::ServeOptions;

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
    /// Nodes the producer was told the next pass will probably want ([`ServeOptions::prefetch_new_children`]: the
    /// level below what was served, for rays still short of two or more levels; see [`Producer::prefetch`]).
    pub next_level_hints: usize,
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

impl<P: Producer> CacheManager<P> {
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
}
