//! The structural invariants of the cache (pointers both ways, reachability, the budget), checked by tests after
//! every frame.

use crate::node::NodeId;
use crate::producer::Producer;

use super::CacheManager;

impl<P: Producer> CacheManager<P> {
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
