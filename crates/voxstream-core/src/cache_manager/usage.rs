//! The LRU bookkeeping of the cache: after a frame, every tile and brick a ray used is refreshed in index order
//! (deterministic); during serving, what the frame's work stands on is pinned, so that no eviction in this frame
//! takes it. Allocation itself (a free slot, else the least recently used one not used in this frame) is the pools'
//! ([`crate::lru`]). GigaVoxels [P09] §5, "Cache management".

use crate::key::NodeKey;
use crate::node::NodeId;
use crate::producer::Producer;
use crate::restriction;

use super::CacheManager;

impl<P: Producer> CacheManager<P> {
    /// Refreshes, in index order, every tile and brick the rays marked used in this frame's feedback.
    pub(super) fn refresh_used(&mut self) {
        let frame = self.frame;
        for tile in self.feedback.used_tiles().collect::<Vec<_>>() {
            self.node_pool.touch(tile, frame);
        }
        for brick in self.feedback.used_bricks().collect::<Vec<_>>() {
            self.brick_pool.touch(brick, frame);
        }
    }

    /// Marks the tiles and bricks on the way to `key` used in this frame, so that no eviction in this frame takes
    /// them.
    pub(super) fn pin_path(&mut self, key: NodeKey) {
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
    pub(super) fn pin_neighbourhood(&mut self, key: NodeKey) {
        self.pin_path(key);
        if key.level >= 2 {
            for position in restriction::touching(&self.shape, key, key.level - 1) {
                self.pin_path(position);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_support::{request, root_children, smallest_with_root, with_root_children, Ramp};
    use super::*;
    use crate::feedback::RequestKind;
    use crate::node::{BrickSlot, NodeData};
    use crate::ServeOptions;

    #[test]
    fn a_full_pool_recycles_the_brick_least_recently_used() {
        // The smallest budget the planner accepts, filled breadth first by children produced with their tiles.
        let mut cache = smallest_with_root();
        let mut queue = std::collections::VecDeque::from([NodeId::ROOT]);
        let mut parent = NodeId::ROOT;
        while cache.brick_pool().free_slots() > 0 {
            parent = queue.pop_front().unwrap();
            request(&mut cache, parent, RequestKind::Subdivide, true);
            let tile = cache.node_pool().node(parent).child_tile().unwrap();
            queue.extend((1..8).map(|child| NodeId::new(tile, child, 8)));
        }
        // A child still missing: a node of the last tile, or else of a new one without room for its children.
        let tile = cache.node_pool().node(parent).child_tile().unwrap();
        let missing_in = |cache: &CacheManager<Ramp>, tile| {
            (1..8)
                .map(|child| NodeId::new(tile, child, 8))
                .find(|&n| cache.node_pool().node(n).data() == NodeData::Missing)
        };
        let missing = missing_in(&cache, tile).unwrap_or_else(|| {
            let parent = queue.pop_front().unwrap();
            assert_eq!(request(&mut cache, parent, RequestKind::Subdivide, false).tiles_evicted, 0);
            missing_in(&cache, cache.node_pool().node(parent).child_tile().unwrap()).unwrap()
        });
        let pool = cache.brick_pool();
        let in_use: Vec<BrickSlot> = (0..pool.allocated()).map(BrickSlot).filter(|&s| pool.is_in_use(s)).collect();
        let (old, recent) = (pool.owner(in_use[0]), pool.owner(in_use[1]));
        // Frame by frame, the rays use every brick but `old`, then every brick but `old` and `recent`.
        for spare in [&in_use[..1], &in_use[..2]] {
            cache.begin_frame();
            for slot in in_use.iter().filter(|slot| !spare.contains(slot)) {
                cache.feedback().mark_brick(*slot);
            }
            cache.end_frame(ServeOptions::ALL);
        }
        // With no slot free, a new brick takes the slot of `old`, used longest ago; `recent` keeps its own.
        let report = request(&mut cache, missing, RequestKind::Produce, false);
        assert_eq!(report.bricks_evicted, 1, "{report:?}");
        assert_eq!(cache.node_pool().node(old).brick(), None);
        assert_eq!(cache.node_pool().node(recent).brick(), Some(in_use[1]));
        assert_eq!(cache.node_pool().node(missing).brick(), Some(in_use[0]));
    }

    #[test]
    fn pinning_a_path_marks_its_tiles_used_in_this_frame() {
        let mut cache = with_root_children(16 << 20, false);
        let [first, second] = [root_children(&cache)[1], root_children(&cache)[2]];
        request(&mut cache, first, RequestKind::Subdivide, false);
        request(&mut cache, second, RequestKind::Subdivide, false);
        let (first_tile, second_tile) =
            (cache.node_pool().node(first).child_tile().unwrap(), cache.node_pool().node(second).child_tile().unwrap());
        let frame = cache.frame();
        assert!(cache.node_pool().stamp(first_tile) < frame && cache.node_pool().stamp(second_tile) < frame);
        let key = cache.node_pool().key(NodeId::new(first_tile, 3, 8));
        cache.pin_path(key);
        assert_eq!(cache.node_pool().stamp(first_tile), frame);
        assert!(cache.node_pool().stamp(second_tile) < frame, "off the path");
    }
}
