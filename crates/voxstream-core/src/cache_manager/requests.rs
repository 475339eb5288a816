//! Request collection: a frame's requests from the feedback buffer, deduplicated and prioritised
//! ([`RequestQueue`]), what is no longer wanted left out, and what waits past the per-frame bound handed to the
//! producer's background loading. GigaVoxels [P09] §5, "Ray-guided data requests".

use crate::feedback::{Request, RequestKind};
use crate::key::NodeKey;
use crate::node::{NodeData, NodeId};
use crate::producer::Producer;
use crate::request_queue::RequestQueue;

use super::{CacheManager, ServeReport, PREFETCH_LIMIT};

impl<P: Producer> CacheManager<P> {
    /// Takes the frame's requests from the feedback buffer: deduplicated and in priority order ([`RequestQueue`]:
    /// the largest level deficit first, then parents before children, then by how many rays asked), keeping what is
    /// still valid and not known to fail. The report starts with their counts.
    pub(super) fn take_work(&mut self) -> (Vec<(Request, NodeKey)>, ServeReport) {
        let raw = self.feedback.take_requests();
        let node_pool = &self.node_pool;
        let queue = RequestQueue::build(raw, None, |node| node_pool.key(node).level);
        let mut report = ServeReport { requests: queue.len(), ..ServeReport::default() };

        // Keep what is still valid and not known to fail (the caller applies the bound).
        let work: Vec<(Request, NodeKey)> = queue
            .requests
            .iter()
            .map(|queued| (queued.request, self.node_pool.key(queued.request.node)))
            .filter(|&(request, key)| self.still_wanted(request, key))
            .collect();
        report.pending = work.len();
        report.largest_deficit = work.iter().map(|(request, _)| request.deficit).max().unwrap_or(0);
        (work, report)
    }

    /// Whether `request` (for the node of `key`) still needs work: its node still holds `key` (no tile recycling
    /// reused it), and it is missing and not known to fail, or childless and subdividable.
    pub(super) fn still_wanted(&self, request: Request, key: NodeKey) -> bool {
        if !self.node_holds(request.node, key) {
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

    /// Whether `node`'s tile is in use and the node still holds `key` (no tile recycling reused it).
    pub(super) fn node_holds(&self, node: NodeId, key: NodeKey) -> bool {
        self.node_pool.is_in_use(node.tile(self.shape.nodes_per_tile())) && self.node_pool.key(node) == key
    }

    /// Lets the producer fetch the bricks of the `deferred` requests (the first [`PREFETCH_LIMIT`] to produce) in the
    /// background while the next frame renders ([`Producer::prefetch`]).
    pub(super) fn prefetch_deferred(&self, deferred: &[(Request, NodeKey)]) {
        let deferred: Vec<NodeKey> = deferred
            .iter()
            .filter(|(request, _)| request.kind == RequestKind::Produce)
            .take(PREFETCH_LIMIT)
            .map(|&(_, key)| key)
            .collect();
        if !deferred.is_empty() {
            self.producer.prefetch(&deferred);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_support::{root_children, with_root_children};
    use super::*;
    use crate::node::NodeId;

    #[test]
    fn requests_come_deduplicated_in_priority_order_without_what_is_no_longer_wanted() {
        let mut cache = with_root_children(16 << 20, false);
        let children = root_children(&cache);
        cache.begin_frame();
        let ask = |node: NodeId, kind: RequestKind, deficit: u8| Request { node, kind, deficit };
        cache.feedback().push_requests(&[
            ask(children[3], RequestKind::Produce, 1),
            // Asked once: after the same deficit and level asked twice.
            ask(children[2], RequestKind::Produce, 2),
            ask(children[1], RequestKind::Produce, 1),
            ask(children[1], RequestKind::Produce, 2),
            // Parents before children among equal deficits.
            ask(NodeId::ROOT, RequestKind::Subdivide, 1),
            // Known empty (Ramp's oracle): nothing to produce.
            ask(children[0], RequestKind::Produce, 3),
        ]);
        let (work, report) = cache.take_work();
        let nodes: Vec<(NodeId, RequestKind)> = work.iter().map(|(request, _)| (request.node, request.kind)).collect();
        // The root already has its children, so its subdivision is no longer wanted either.
        assert_eq!(
            nodes,
            [
                (children[1], RequestKind::Produce),
                (children[2], RequestKind::Produce),
                (children[3], RequestKind::Produce)
            ]
        );
        assert_eq!(work[0].1, cache.node_pool().key(children[1]));
        assert_eq!((report.requests, report.pending, report.largest_deficit), (5, 3, 2));
    }
}
