//! Serving under the restricted working set (Thiele et al., [`crate::restriction`]): a request waits while the
//! forced steps completing its coarser neighbourhood are served, within the same per-frame bound; evictions that
//! would leave neighbours two levels apart are passed over for the next oldest.

use std::collections::HashSet;

use crate::feedback::{Request, RequestKind};
use crate::key::NodeKey;
use crate::node::{NodeId, TileId};
use crate::node_pool::NodePool;
use crate::producer::Producer;
use crate::restriction::{self, reach, Reach};

use super::production::Work;
use super::{CacheManager, ServeReport};

impl<P: Producer> CacheManager<P> {
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

    /// What must be served before the node of `key` may become complete ([`restriction::prerequisites`]; failed
    /// nodes count as satisfied).
    pub(super) fn prerequisites(&self, key: NodeKey) -> Vec<Reach> {
        restriction::prerequisites(&self.node_pool, key, |k| self.failed.contains(&k))
    }

    /// Whether serving `request` now would break the restricted working set (when it is kept).
    pub(super) fn is_premature(&self, request: Request, key: NodeKey) -> bool {
        self.restricted && request.kind == RequestKind::Produce && !self.prerequisites(key).is_empty()
    }

    /// Serves the rays' `work` in rounds, keeping the working set restricted: a request to produce a node whose
    /// coarser neighbourhood is incomplete waits while the steps completing it are served (forced), coarsest first;
    /// everything served, forced or not, counts against `limit`. What is left waits for a later frame.
    pub(super) fn serve_restricted(
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
    pub(super) fn forced_steps(&self, key: NodeKey) -> Vec<(Request, NodeKey)> {
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
}

/// Whether evicting the brick of `owner` would leave finer complete data beside it, two levels finer than what is
/// drawn there then ([`crate::restriction`]).
pub(super) fn evicting_breaks_restriction(pool: &NodePool, owner: NodeId) -> bool {
    let key = pool.key(owner);
    reach(pool, key) == Reach::Complete(owner) && restriction::finer_data_touches(pool, key, key.level)
}

/// Whether freeing `tile` (its parent's children and their subtrees) would leave finer complete data beside the
/// parent, two levels finer than the parent drawn there then.
pub(super) fn freeing_breaks_restriction(pool: &NodePool, tile: TileId) -> bool {
    let record = pool.record(tile);
    if record.parent == u32::MAX {
        return false;
    }
    let parent = NodeKey { level: record.level - 1, ijk: record.parent_ijk };
    // Below a node that is not complete nothing is drawn, so nothing depends on it.
    reach(pool, parent) == Reach::Complete(NodeId(record.parent))
        && restriction::finer_data_touches(pool, parent, record.level)
}
#[cfg(test)]
mod tests {
    use super::super::test_support::FailsOnce;
    use super::*;
    use crate::ServeOptions;

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
}
