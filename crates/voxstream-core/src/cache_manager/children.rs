//! Children produced with their tile ([`ServeOptions::prefetch_new_children`]): after every request of the frame is
//! served, the new tiles' children that the producer's oracle does not know to be constant are produced into free
//! brick slots, never evicting, as GigaVoxels [P09] §5 lets its cache manager load the children of a subdivided
//! node at once.

use crate::error::ProduceError;
use crate::feedback::{Request, RequestKind};
use crate::key::NodeKey;
use crate::node::{NodeData, NodeId, TileId};
use crate::producer::Producer;

use super::analysis::{produce_analysed, AnalysedBrick, AnalysedContent};
use super::production::produce_fetching;
use super::space_order::in_space_order;
use super::tree_updates::Eviction;
#[cfg(doc)]
use super::ServeOptions;
use super::{CacheManager, ServeReport, PREFETCH_LIMIT};

impl<P: Producer> CacheManager<P> {
    /// Produces the still-missing children of `new_tiles` (each with its parent's key) into free brick slots, in
    /// tile then child order, a batch at a time; stops when no slot is free. Nothing is evicted, and a failure
    /// leaves the child missing (a ray that needs it will request it, and the failure is reported then).
    pub(super) fn prefetch_children(&mut self, new_tiles: &[(TileId, NodeKey)], report: &mut ServeReport) {
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
                    && (!self.restricted || self.prerequisites(key).is_empty())
                {
                    candidates.push((node_id, key));
                }
            }
        }
        let batch_size = self.capacities.production_batch.max(1) as usize;
        let mut remaining = candidates.as_slice();
        let mut first = true;
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
            // A producer on a network fetches the first batch's data, then each next batch's while one is produced.
            let keys = |items: &[(NodeId, NodeKey)]| items.iter().map(|&(_, key)| key).collect::<Vec<_>>();
            let this = first.then(|| keys(batch));
            first = false;
            let next = if wait { keys(&rest[..rest.len().min(batch_size)]) } else { vec![] };
            let results: Vec<Option<Result<AnalysedBrick, ProduceError>>> =
                produce_fetching(producer, self.io_pool.as_ref(), wait, this.as_deref(), &next, produce_batch);
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
}

impl<P: Producer> CacheManager<P> {
    /// Converged passes: hints the producer ([`Producer::prefetch`]) at the level the rays of `asked` will want in
    /// the next pass, so that its data is on its way while this pass's result is drawn instead of being fetched only
    /// once the rays ask (one wait on slow storage per tree level otherwise). A ray that asked with a deficit of
    /// 2 or more still lacks a level below what was served: the children of a brick it asked to be produced, the
    /// grandchildren under a subdivision it asked for (under each child brick of the new tile). Only what the
    /// oracle does not know to be constant, and what has no tile yet, is hinted; at most [`PREFETCH_LIMIT`] nodes,
    /// in `asked`'s order (the queue's: largest deficit first). Hints change nothing resident or produced.
    pub(super) fn hint_next_level(&self, asked: &[(Request, NodeKey)], report: &mut ServeReport) {
        let per_tile = self.shape.nodes_per_tile();
        let mut hints: Vec<NodeKey> = Vec::new();
        for &(request, key) in asked {
            if hints.len() >= PREFETCH_LIMIT {
                break;
            }
            if request.deficit < 2 || !self.node_holds(request.node, key) {
                continue;
            }
            match request.kind {
                RequestKind::Produce => self.unknown_children(request.node, key, &mut hints),
                RequestKind::Subdivide => {
                    if let Some(tile) = self.node_pool.node(request.node).child_tile() {
                        for child in 0..per_tile {
                            let child_key = key.child(child, self.shape.n);
                            self.unknown_children(NodeId::new(tile, child, per_tile), child_key, &mut hints);
                        }
                    }
                }
            }
        }
        hints.truncate(PREFETCH_LIMIT);
        if !hints.is_empty() {
            report.next_level_hints += hints.len();
            self.producer.prefetch(&hints);
        }
    }

    /// Appends the children of `node` (holding `key`) that a later subdivision would create and produce: none unless
    /// it holds a non-terminal brick and has no child tile; those the oracle does not know to be constant and that
    /// have not failed.
    fn unknown_children(&self, node: NodeId, key: NodeKey, hints: &mut Vec<NodeKey>) {
        let record = self.node_pool.node(node);
        if record.brick().is_none()
            || record.is_terminal()
            || record.child_tile().is_some()
            || key.level >= self.shape.max_level
        {
            return;
        }
        for child in 0..self.shape.nodes_per_tile() {
            let child_key = key.child(child, self.shape.n);
            if !self.failed.contains(&child_key) && self.producer.oracle(child_key).is_none() {
                hints.push(child_key);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_support::{brick_owners, request, root_children, smallest_with_root, Ramp};
    use super::*;
    use crate::budget::PoolCapacities;
    use crate::error::CoreError;
    use crate::feedback::RequestKind;

    #[test]
    fn children_without_room_are_reported_left_missing() {
        // The smallest budget the planner accepts: a few tiles of children fill its brick pool.
        let mut cache = smallest_with_root();
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

    /// [`Ramp`], remembering what it is told to prefetch.
    #[derive(Default)]
    struct Hinted(std::sync::Mutex<Vec<NodeKey>>);
    impl Producer for Hinted {
        fn shape(&self) -> crate::key::TreeShape {
            Ramp.shape()
        }
        fn oracle(&self, key: NodeKey) -> Option<f32> {
            Ramp.oracle(key)
        }
        fn produce(&self, key: NodeKey, voxels: &mut [u16]) -> Result<crate::producer::Produced, ProduceError> {
            Ramp.produce(key, voxels)
        }
        fn prefetch(&self, keys: &[NodeKey]) {
            self.0.lock().unwrap().extend_from_slice(keys);
        }
    }

    /// Serves one request of `deficit` and returns what the producer was told to prefetch, sorted.
    fn hints_after(
        cache: &mut CacheManager<Hinted>,
        node: NodeId,
        kind: RequestKind,
        deficit: u8,
        prefetch_new_children: bool,
    ) -> (ServeReport, Vec<NodeKey>) {
        cache.producer().0.lock().unwrap().clear();
        cache.begin_frame();
        cache.feedback().push_requests(&[Request { node, kind, deficit }]);
        let report = cache.end_frame(crate::ServeOptions { limit: None, prefetch_new_children, wait_for_data: true });
        assert_eq!(cache.check_invariants(), Ok(()));
        let mut hints = cache.producer().0.lock().unwrap().clone();
        hints.sort_by_key(|key| (key.level, key.ijk[2], key.ijk[1], key.ijk[0]));
        (report, hints)
    }

    #[test]
    fn rays_short_of_two_levels_get_the_level_below_what_was_served_hinted() {
        let unknown_children = |key: NodeKey| -> Vec<NodeKey> {
            let mut children: Vec<NodeKey> =
                (0..8).map(|c| key.child(c, 2)).filter(|k| Ramp.oracle(*k).is_none()).collect();
            children.sort_by_key(|key| (key.level, key.ijk[2], key.ijk[1], key.ijk[0]));
            children
        };
        let root = NodeKey { level: 0, ijk: [0; 3] };
        // Producing the root for a ray that wants level 1 or finer: its seven non-constant children are hinted
        // (a deficit of 2 for a missing node means the ray wants one level below it).
        let mut cache = CacheManager::new(Hinted::default(), 16 << 20).unwrap();
        let (report, hints) = hints_after(&mut cache, NodeId::ROOT, RequestKind::Produce, 2, true);
        assert_eq!(hints, unknown_children(root));
        assert_eq!(report.next_level_hints, 7);
        assert!(cache.node_pool().node(NodeId::ROOT).child_tile().is_none(), "a hint creates nothing");

        // A subdivision asked with a deficit of 1 is complete once its children are produced: no hints.
        let (report, hints) = hints_after(&mut cache, NodeId::ROOT, RequestKind::Subdivide, 1, true);
        assert_eq!((report.bricks_prefetched, report.next_level_hints, hints.len()), (7, 0, 0));

        // With a deficit of 2, the children of each new child brick are hinted (7 bricks, 7 unknown each), and
        // only in converged passes (`prefetch_new_children`).
        for converged in [false, true] {
            let mut cache = CacheManager::new(Hinted::default(), 16 << 20).unwrap();
            hints_after(&mut cache, NodeId::ROOT, RequestKind::Produce, 1, converged);
            let (report, hints) = hints_after(&mut cache, NodeId::ROOT, RequestKind::Subdivide, 2, converged);
            if !converged {
                assert_eq!((report.next_level_hints, hints.len()), (0, 0));
                continue;
            }
            let mut expected: Vec<NodeKey> = (0..8)
                .map(|c| root.child(c, 2))
                .filter(|k| Ramp.oracle(*k).is_none())
                .flat_map(unknown_children)
                .collect();
            expected.sort_by_key(|key| (key.level, key.ijk[2], key.ijk[1], key.ijk[0]));
            assert_eq!(hints.len(), 49);
            assert_eq!(hints, expected);
            assert_eq!(report.next_level_hints, 49);
        }
    }
}
