//! Turning a frame's raw requests into an ordered, bounded work list.
//!
//! GigaVoxels [P09] §5 compacts the per-ray request lists on the GPU (neighbour comparison + stream reduction) and
//! lets overflow wait for the next frame. voxstream does the same on the CPU: requests are deduplicated (counting how
//! many rays asked: the screen area waiting on the node, and keeping the largest level deficit any of them reported:
//! Thiele et al.'s feedback, the maximum over rays of ideal − actual level), ordered by that deficit (the region
//! drawn most levels too coarse first, Thiele et al.'s split priority), then parent before child (coarse levels
//! first, so every ray gets a usable ancestor quickly), then by the ray count, and cut to the per-frame bound. The
//! order is total, so the result never depends on thread scheduling.
//!
//! Thiele et al. distribute the priority over their working-set tree (top-down `P_child = max(F, P_parent − 1)`,
//! bottom-up `P = max(P_child + 1)`) because their feedback names the bricks drawn, not the ones missing. Here a ray
//! names the one node it lacks, at most one per path, so the deficit it reports already is that node's priority.

use crate::feedback::{Request, RequestKind};
use crate::node::NodeId;

/// A deduplicated request with its priority inputs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct QueuedRequest {
    /// The request.
    pub request: Request,
    /// Level of the node (parents first among equal deficits).
    pub level: u32,
    /// Number of rays that asked for it.
    pub ray_count: u32,
}

/// The ordered requests of one frame.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RequestQueue {
    /// Requests in serving order.
    pub requests: Vec<QueuedRequest>,
    /// Distinct requests before the bound was applied.
    pub distinct: usize,
}

impl RequestQueue {
    /// Deduplicates and orders `raw`, keeping at most `limit` requests. `level_of` gives a node's level.
    pub fn build(mut raw: Vec<Request>, limit: Option<usize>, level_of: impl Fn(NodeId) -> u32) -> RequestQueue {
        raw.sort_unstable();
        let mut requests: Vec<QueuedRequest> = Vec::new();
        for request in raw {
            match requests.last_mut() {
                Some(last) if (last.request.node, last.request.kind) == (request.node, request.kind) => {
                    // Thiele et al.: the maximum over rays, not the average (sorted, so the last is the largest).
                    last.request.deficit = request.deficit;
                    last.ray_count += 1;
                }
                _ => requests.push(QueuedRequest { request, level: level_of(request.node), ray_count: 1 }),
            }
        }
        // A node that needs producing cannot be subdivided in the same frame: its data comes first.
        let distinct = requests.len();
        requests.sort_unstable_by(|a, b| {
            b.request
                .deficit
                .cmp(&a.request.deficit)
                .then(a.level.cmp(&b.level))
                .then(kind_rank(a.request.kind).cmp(&kind_rank(b.request.kind)))
                .then(b.ray_count.cmp(&a.ray_count))
                .then(a.request.cmp(&b.request))
        });
        if let Some(limit) = limit {
            requests.truncate(limit);
        }
        RequestQueue { requests, distinct }
    }

    /// Number of requests to serve.
    pub fn len(&self) -> usize {
        self.requests.len()
    }

    /// Whether there is nothing to serve.
    pub fn is_empty(&self) -> bool {
        self.requests.is_empty()
    }
}

fn kind_rank(kind: RequestKind) -> u8 {
    match kind {
        RequestKind::Produce => 0,
        RequestKind::Subdivide => 1,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn req(node: u32, kind: RequestKind) -> Request {
        Request { node: NodeId(node), kind, deficit: 1 }
    }

    #[test]
    fn the_largest_deficit_of_any_ray_comes_first() {
        let with = |node: u32, deficit: u8| Request { node: NodeId(node), kind: RequestKind::Produce, deficit };
        // Node 30 (level 3) is wanted 3 levels finer by one ray of three; node 10 (level 1) one level finer.
        let raw = vec![with(10, 1), with(30, 1), with(30, 3), with(10, 1), with(30, 2)];
        let queue = RequestQueue::build(raw, None, |node| node.0 / 10);
        assert_eq!(queue.len(), 2);
        assert_eq!(queue.requests[0].request, with(30, 3));
        assert_eq!(queue.requests[0].ray_count, 3);
        assert_eq!(queue.requests[1].request, with(10, 1));
    }

    #[test]
    fn duplicates_collapse_and_count() {
        let raw = vec![
            req(9, RequestKind::Produce),
            req(9, RequestKind::Produce),
            req(2, RequestKind::Subdivide),
            req(9, RequestKind::Produce),
        ];
        let queue = RequestQueue::build(raw, None, |_| 1);
        assert_eq!(queue.len(), 2);
        assert_eq!(queue.requests[0].request, req(9, RequestKind::Produce));
        assert_eq!(queue.requests[0].ray_count, 3);
    }

    #[test]
    fn parents_come_before_children_and_the_bound_holds() {
        let raw = vec![req(30, RequestKind::Produce), req(10, RequestKind::Produce), req(20, RequestKind::Produce)];
        let queue = RequestQueue::build(raw, Some(2), |node| node.0 / 10);
        assert_eq!(queue.distinct, 3);
        let levels: Vec<u32> = queue.requests.iter().map(|q| q.level).collect();
        assert_eq!(levels, vec![1, 2]);
    }

    proptest! {
        #[test]
        fn order_is_independent_of_arrival(mut nodes in proptest::collection::vec((0u32..50, any::<bool>()), 0..100)) {
            let to_requests = |nodes: &[(u32, bool)]| nodes.iter().map(|&(n, s)| {
                req(n, if s { RequestKind::Subdivide } else { RequestKind::Produce })
            }).collect::<Vec<_>>();
            let a = RequestQueue::build(to_requests(&nodes), Some(20), |n| n.0 % 7);
            nodes.reverse();
            let b = RequestQueue::build(to_requests(&nodes), Some(20), |n| n.0 % 7);
            prop_assert_eq!(&a, &b);
            let mut seen = std::collections::HashSet::new();
            prop_assert!(a.requests.iter().all(|q| seen.insert(q.request)));
            prop_assert!(a.requests.windows(2).all(|w| w[0].level <= w[1].level));
        }
    }
}
