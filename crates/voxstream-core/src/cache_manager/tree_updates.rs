//! Node-tree updates: a produced node stored (a constant, or a brick in a slot, evicting the least recently used one
//! when allowed), a node subdivided into a new tile (recycling the oldest tile with its subtree), and subtrees freed.
//! No dangling pointers: recycling a brick clears its owner's brick pointer, recycling a tile its parent's child
//! pointer. GigaVoxels [P09] §5, "Cache management".

use crate::node::{Node, NodeId, TileId};
use crate::node_pool::ROOT_TILE;
use crate::producer::Producer;

use super::analysis::{AnalysedBrick, AnalysedContent};
use super::restricted::{evicting_breaks_restriction, freeing_breaks_restriction};
use super::{CacheManager, ServeReport};

/// Whether storing a produced brick may recycle the least recently used slot.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(super) enum Eviction {
    /// A ray asked for it: recycle if needed.
    Allowed,
    /// Speculative: free slots only.
    Forbidden,
}

impl<P: Producer> CacheManager<P> {
    pub(super) fn apply_produced(
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
    pub(super) fn apply_subdivide(
        &mut self,
        node_id: NodeId,
        hints: &[Option<f32>],
        report: &mut ServeReport,
    ) -> Option<TileId> {
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
    pub(super) fn is_ancestor_tile(&self, tile: TileId, node: NodeId) -> bool {
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
    pub(super) fn detach_and_free(&mut self, tile: TileId) {
        let parent = self.node_pool.record(tile).parent;
        if parent != u32::MAX {
            self.node_pool.node_mut(NodeId(parent)).set_child_tile(None);
        }
        self.free_subtree(tile);
    }

    pub(super) fn free_subtree(&mut self, tile: TileId) {
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
}

#[cfg(test)]
mod tests {
    use super::super::test_support::{request, root_children, with_root_children};
    use super::*;
    use crate::feedback::RequestKind;

    #[test]
    fn freeing_a_tile_frees_its_subtree_and_clears_its_parents_pointer() {
        let mut cache = with_root_children(16 << 20, true);
        let child = root_children(&cache)[1];
        request(&mut cache, child, RequestKind::Subdivide, true);
        let tile = cache.node_pool().node(child).child_tile().unwrap();
        // The root's brick, its 7 children's and the 7 grandchildren's below `child` (the first of each tile is empty).
        assert_eq!((cache.node_pool().tiles_in_use(), cache.brick_pool().len()), (3, 15));
        assert!(cache.is_ancestor_tile(tile, NodeId::new(tile, 5, 8)));
        assert!(!cache.is_ancestor_tile(tile, root_children(&cache)[2]));
        let root_tile = cache.node_pool().node(NodeId::ROOT).child_tile().unwrap();
        cache.detach_and_free(root_tile);
        assert_eq!(cache.node_pool().node(NodeId::ROOT).child_tile(), None);
        assert_eq!((cache.node_pool().tiles_in_use(), cache.brick_pool().len()), (1, 1));
        assert_eq!(cache.check_invariants(), Ok(()));
    }
}
