//! Thiele et al.'s restricted working set: neighbouring data differs by at most one level.
//!
//! Seed 003 (Thiele, Matthes, Froehlich), "Restricted working set" (`shared/notes/thiele-lod-blending.md`): a node
//! is split only when none of its face-, edge- or corner-neighbours is coarser than it, the blocking neighbours are
//! split first (forced splits), and a collapse never makes a neighbour two levels finer than its surroundings.
//! Level blending ([`crate::level_blending`]) can then always blend towards a parent that exists on both sides of a
//! brick boundary.
//!
//! # The rule, in GigaVoxels' tree
//! Rays draw, at each point, the deepest node on its path whose ancestors all hold data (a brick or a constant):
//! call such nodes *complete*. The working set is the set of complete nodes. It is **restricted** when every
//! complete node holding a brick at level `L ≥ 2` finds, at each position of level `L − 1` touching its box (face,
//! edge or corner, inside the volume), a complete node, or a complete constant or terminal ancestor of that position
//! (there is nothing finer to draw). Then the level drawn for lack of data changes by at most one across any
//! boundary. A constant node is exempt: it draws the same at any level (so the oracle's constant children of a
//! subdivision need no neighbourhood).
//!
//! The cache manager keeps it so ([`crate::CacheManager::set_restricted`]):
//! - **Splits:** producing a node's data makes it complete, so its touching positions one level up must be satisfied
//!   first. [`prerequisites`] names the first missing step on the way to each (a missing node to produce, a childless
//!   one to subdivide), coarser steps first; they are served as forced requests before the node, in the same frame if
//!   the per-frame bound allows, else later. Subdividing alone draws nothing new and needs nothing.
//! - **Collapses:** evicting a brick (the node stops being complete) or a tile (its nodes go) is vetoed while a
//!   complete node outside it touching it would be left two levels finer ([`finer_data_touches`]); the LRU takes the
//!   next oldest instead. Collapses are never forced: when every candidate is vetoed, the memory budget wins, the
//!   oldest goes all the same, and the frame's report counts it ([`crate::ServeReport::restriction_yielded`]).

use crate::key::{NodeKey, TreeShape};
use crate::node::{NodeData, NodeId};
use crate::node_pool::NodePool;

/// Where a walk from the root towards a position stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reach {
    /// The node at the position is complete.
    Complete(NodeId),
    /// A complete constant or terminal node above the position: nothing finer exists there.
    Final,
    /// The first node on the way without data: it must be produced.
    Missing(NodeId, NodeKey),
    /// The first complete node on the way without children: it must be subdivided.
    Childless(NodeId, NodeKey),
}

impl Reach {
    /// Whether the position needs no work to satisfy the restriction.
    pub fn is_satisfied(self) -> bool {
        matches!(self, Reach::Complete(_) | Reach::Final)
    }
}

/// Walks from the root towards `key` through nodes with data.
pub fn reach(pool: &NodePool, key: NodeKey) -> Reach {
    let shape = *pool.shape();
    let per_tile = shape.nodes_per_tile();
    let mut id = NodeId::ROOT;
    let mut here = NodeKey::ROOT;
    loop {
        let node = pool.node(id);
        match node.data() {
            NodeData::Missing => return Reach::Missing(id, here),
            NodeData::Constant(_) => return if here.level == key.level { Reach::Complete(id) } else { Reach::Final },
            NodeData::Brick(_) => {}
        }
        if here.level == key.level {
            return Reach::Complete(id);
        }
        if node.is_terminal() {
            return Reach::Final;
        }
        let Some(tile) = node.child_tile() else {
            return Reach::Childless(id, here);
        };
        let child = child_towards(here, key, shape.n);
        id = NodeId::new(tile, child, per_tile);
        here = here.child(child, shape.n);
    }
}

/// The index of the child of `here` on the way to `key` (deeper, inside `here`).
pub fn child_towards(here: NodeKey, key: NodeKey, n: u32) -> u32 {
    let n = n as u64;
    let div = n.pow(key.level - here.level - 1);
    let c = [0, 1, 2].map(|a| (key.ijk[a] / div) % n);
    (c[0] + n * (c[1] + n * c[2])) as u32
}

/// The nodes at `level` (at most `key.level`) whose closed boxes touch `key`'s, inside the volume: its ancestor at
/// that level and the ancestor's neighbours on the sides `key` reaches. At most 27.
pub fn touching(shape: &TreeShape, key: NodeKey, level: u32) -> Vec<NodeKey> {
    debug_assert!(level <= key.level);
    let scale = (shape.n as u64).pow(key.level - level);
    let last = shape.nodes_per_axis(level) - 1;
    let span = |x: u64| {
        // Nodes j at `level` with j·scale ≤ x + 1 and (j + 1)·scale ≥ x.
        let lo = x.div_ceil(scale).saturating_sub(1);
        let hi = ((x + 1) / scale).min(last);
        lo..=hi
    };
    let mut out = Vec::with_capacity(27);
    for k in span(key.ijk[2]) {
        for j in span(key.ijk[1]) {
            for i in span(key.ijk[0]) {
                out.push(NodeKey { level, ijk: [i, j, k] });
            }
        }
    }
    out
}

/// Whether the closed boxes of `a` and `b` touch or overlap.
pub fn boxes_touch(shape: &TreeShape, a: NodeKey, b: NodeKey) -> bool {
    let (coarse, fine) = if a.level <= b.level { (a, b) } else { (b, a) };
    let scale = (shape.n as u64).pow(fine.level - coarse.level);
    (0..3).all(|axis| {
        let lo = coarse.ijk[axis] * scale;
        let hi = lo + scale;
        fine.ijk[axis] <= hi && fine.ijk[axis] + 1 >= lo
    })
}

/// What must be done before `key` may become complete: for each position one level up touching it that is not
/// satisfied, the first step on the way there. Empty at levels 0 and 1, and when the restriction already allows it.
/// A missing node whose production failed (`has_failed`) counts as satisfied: its ancestor stands in for good, and
/// nothing can be done for it.
pub fn prerequisites(pool: &NodePool, key: NodeKey, has_failed: impl Fn(NodeKey) -> bool) -> Vec<Reach> {
    if key.level < 2 {
        return Vec::new();
    }
    let mut steps: Vec<Reach> = Vec::new();
    for position in touching(pool.shape(), key, key.level - 1) {
        let step = reach(pool, position);
        let is_failed = matches!(step, Reach::Missing(_, missing) if has_failed(missing));
        if !step.is_satisfied() && !is_failed && !steps.contains(&step) {
            steps.push(step);
        }
    }
    steps
}

/// Whether some complete brick node outside `key`'s subtree, touching `key`'s box, is deeper than `level`: removing
/// `key`'s data at levels above `level + 1` would then break the restriction.
pub fn finer_data_touches(pool: &NodePool, key: NodeKey, level: u32) -> bool {
    let shape = *pool.shape();
    let per_tile = shape.nodes_per_tile();
    let mut stack: Vec<(NodeId, NodeKey)> = Vec::new();
    for neighbour in touching(&shape, key, key.level) {
        if neighbour == key {
            continue;
        }
        if let Reach::Complete(id) = reach(pool, neighbour) {
            stack.push((id, neighbour));
        }
    }
    while let Some((id, here)) = stack.pop() {
        if here.level > level && pool.node(id).brick().is_some() {
            return true;
        }
        let Some(tile) = pool.node(id).child_tile() else { continue };
        for child in 0..per_tile {
            let child_key = here.child(child, shape.n);
            let child_id = NodeId::new(tile, child, per_tile);
            if pool.node(child_id).data() != NodeData::Missing && boxes_touch(&shape, child_key, key) {
                stack.push((child_id, child_key));
            }
        }
    }
    false
}

/// Checks the restriction over every complete node (failed nodes count as satisfied, see [`prerequisites`]);
/// returns the first violation. Used by tests.
pub fn check(pool: &NodePool, has_failed: impl Fn(NodeKey) -> bool) -> Result<(), String> {
    let shape = *pool.shape();
    let per_tile = shape.nodes_per_tile();
    let mut stack = vec![(NodeId::ROOT, NodeKey::ROOT)];
    while let Some((id, key)) = stack.pop() {
        let node = pool.node(id);
        if node.data() == NodeData::Missing {
            continue;
        }
        if let (Some(_), Some(step)) = (node.brick(), prerequisites(pool, key, &has_failed).first()) {
            return Err(format!("complete node {key:?} has a coarser neighbour: {step:?}"));
        }
        if let Some(tile) = node.child_tile() {
            for child in 0..per_tile {
                stack.push((NodeId::new(tile, child, per_tile), key.child(child, shape.n)));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn touching_positions_are_the_ancestor_and_the_neighbours_on_the_near_sides() {
        let shape = TreeShape::new(2, 8, 6).unwrap();
        // A corner child inside its parent (3,3,3) at level 3: the parent and its neighbours towards -x, -y, -z.
        let key = NodeKey { level: 4, ijk: [6, 6, 6] };
        let up = touching(&shape, key, 3);
        assert_eq!(up.len(), 8);
        assert!(up.iter().all(|k| k.ijk.iter().all(|&c| c == 2 || c == 3)));
        // A node on the volume's boundary has no neighbours outside.
        let corner = NodeKey { level: 2, ijk: [0, 0, 0] };
        assert_eq!(touching(&shape, corner, 1), vec![NodeKey { level: 1, ijk: [0, 0, 0] }]);
        // Every position found touches, and every touching position is found (brute force at level 3).
        for level in 1..=4 {
            let found = touching(&shape, key, level);
            let side = shape.nodes_per_axis(level);
            for k in 0..side {
                for j in 0..side {
                    for i in 0..side {
                        let other = NodeKey { level, ijk: [i, j, k] };
                        assert_eq!(found.contains(&other), boxes_touch(&shape, other, key), "{other:?}");
                    }
                }
            }
        }
    }

    #[test]
    fn touching_works_for_n_three() {
        let shape = TreeShape::new(3, 8, 4).unwrap();
        let key = NodeKey { level: 2, ijk: [4, 0, 8] };
        let found = touching(&shape, key, 1);
        // x: 4 is the middle of parent 1 → only 1; y: 0 at the boundary → 0; z: 8 is the last of parent 2 → 2.
        assert_eq!(found, vec![NodeKey { level: 1, ijk: [1, 0, 2] }]);
        let key = NodeKey { level: 2, ijk: [3, 5, 6] };
        assert_eq!(touching(&shape, key, 1).len(), 8);
    }
}
