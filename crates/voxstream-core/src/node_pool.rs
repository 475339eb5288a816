//! The node pool: a flat array of tiles of `N³` sibling nodes, plus the CPU-side record of each tile.
//!
//! GigaVoxels [P09] §4 ("Node pool"): one pointer per node reaches all its children, stored contiguously. The
//! `nodes` array is what a renderer reads (CPU or GPU, as is); the tile records (parent, level, coordinates) are the
//! CPU-side mirror the cache manager needs to detach a recycled tile from its parent.
//!
//! ```text
//! nodes:  [ tile 0: root, unused… | tile 1: N³ nodes | tile 2: N³ nodes | … ]   8 bytes per node
//! tiles:  [ TileRecord 0          | TileRecord 1     | …                     ]  32 bytes per tile
//! ```

use bytemuck::{Pod, Zeroable};

use crate::key::{NodeKey, TreeShape};
use crate::lru::{Allocation, LruSlots};
use crate::node::{Node, NodeId, TileId};

/// CPU-side record of a tile: who points at it and where it is.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct TileRecord {
    /// The node whose child pointer names this tile (`u32::MAX` for the root tile).
    pub parent: u32,
    /// Level of the nodes in this tile.
    pub level: u32,
    /// Coordinates of the parent node; child `c` sits at `parent_ijk·N + offset(c)`.
    pub parent_ijk: [u64; 3],
}

/// Bytes of a tile record, counted in the budget.
pub const TILE_RECORD_BYTES: usize = std::mem::size_of::<TileRecord>();

/// The root tile; its first node is the root of the tree.
pub const ROOT_TILE: TileId = TileId(0);

/// Flat array of node tiles with LRU slot management.
#[derive(Debug, Clone)]
pub struct NodePool {
    shape: TreeShape,
    nodes: Vec<Node>,
    records: Vec<TileRecord>,
    /// LRU over tiles 1‥capacity (slot `s` is tile `s + 1`; the root tile is never recycled).
    lru: LruSlots,
}

impl NodePool {
    /// A pool of at most `capacity_tiles` tiles (root tile included), holding only the root. Memory grows with use.
    pub fn new(shape: TreeShape, capacity_tiles: u32) -> NodePool {
        let per_tile = shape.nodes_per_tile() as usize;
        // Memory grows with use: a large budget reserves nothing up front.
        let nodes = vec![Node::MISSING; per_tile];
        let records = vec![TileRecord { parent: u32::MAX, level: 0, parent_ijk: [0; 3] }];
        NodePool { shape, nodes, records, lru: LruSlots::new(capacity_tiles.saturating_sub(1)) }
    }

    /// The tree shape.
    pub fn shape(&self) -> &TreeShape {
        &self.shape
    }

    /// All nodes, tile after tile: the array renderers read.
    #[inline]
    pub fn nodes(&self) -> &[Node] {
        &self.nodes
    }

    /// One node.
    #[inline]
    pub fn node(&self, id: NodeId) -> Node {
        self.nodes[id.0 as usize]
    }

    /// One node, mutably.
    #[inline]
    pub fn node_mut(&mut self, id: NodeId) -> &mut Node {
        &mut self.nodes[id.0 as usize]
    }

    /// The record of `tile`.
    #[inline]
    pub fn record(&self, tile: TileId) -> &TileRecord {
        &self.records[tile.0 as usize]
    }

    /// Identity of a node.
    pub fn key(&self, id: NodeId) -> NodeKey {
        let per_tile = self.shape.nodes_per_tile();
        let tile = id.tile(per_tile);
        if tile == ROOT_TILE {
            return NodeKey::ROOT;
        }
        let record = self.records[tile.0 as usize];
        NodeKey { level: record.level - 1, ijk: record.parent_ijk }.child(id.child_index(per_tile), self.shape.n)
    }

    /// Tiles in use, the root tile included.
    pub fn tiles_in_use(&self) -> u32 {
        1 + self.lru.len()
    }

    /// Tiles ever allocated (memory actually touched), the root tile included.
    pub fn tiles_allocated(&self) -> u32 {
        1 + self.lru.high_water()
    }

    /// Maximum tiles, the root tile included.
    pub fn capacity(&self) -> u32 {
        1 + self.lru.capacity()
    }

    /// Whether `tile` currently holds nodes of the tree.
    pub fn is_in_use(&self, tile: TileId) -> bool {
        tile == ROOT_TILE || (tile.0 >= 1 && self.lru.is_in_use(tile.0 - 1))
    }

    /// Frame at which `tile` was last used.
    pub fn stamp(&self, tile: TileId) -> u32 {
        if tile == ROOT_TILE {
            u32::MAX
        } else {
            self.lru.stamp(tile.0 - 1)
        }
    }

    /// Marks `tile` used at `frame`.
    pub fn touch(&mut self, tile: TileId, frame: u32) {
        if tile != ROOT_TILE {
            self.lru.touch(tile.0 - 1, frame);
        }
    }

    /// Takes a tile for the children of `parent`, filled with missing nodes. A recycled tile is returned with
    /// `was_recycled = true`; its old subtree must already have been detached by the caller via
    /// [`NodePool::oldest_recyclable`]. Returns `None` when every tile was used during `frame`.
    pub fn allocate(&mut self, parent: NodeId, frame: u32) -> Option<(TileId, bool)> {
        let parent_key = self.key(parent);
        let allocation = self.lru.allocate(frame)?;
        let tile = TileId(allocation.slot() + 1);
        let per_tile = self.shape.nodes_per_tile() as usize;
        let start = tile.0 as usize * per_tile;
        if start >= self.nodes.len() {
            self.nodes.resize(start + per_tile, Node::MISSING);
            self.records.resize(tile.0 as usize + 1, TileRecord::default());
        } else {
            self.nodes[start..start + per_tile].fill(Node::MISSING);
        }
        self.records[tile.0 as usize] =
            TileRecord { parent: parent.0, level: parent_key.level + 1, parent_ijk: parent_key.ijk };
        Some((tile, matches!(allocation, Allocation::Recycled(_))))
    }

    /// The tile that the next allocation at `frame` would recycle, if the pool is full and one is old enough.
    pub fn oldest_recyclable(&self, frame: u32) -> Option<TileId> {
        // A tile never used, or released, is taken before any is recycled.
        if self.lru.len() < self.lru.capacity() {
            return None;
        }
        let oldest = self.lru.iter_oldest_first().next()?;
        (self.lru.stamp(oldest) < frame).then_some(TileId(oldest + 1))
    }

    /// As [`NodePool::oldest_recyclable`], but the oldest of the [`crate::lru::RECYCLE_SCAN`] least recently used
    /// tiles that `keep` lets go; the oldest all the same when `keep` holds for all, with `true` (the wish yielded).
    pub fn oldest_recyclable_avoiding(
        &self,
        frame: u32,
        mut keep: impl FnMut(TileId) -> bool,
    ) -> Option<(TileId, bool)> {
        let oldest = self.oldest_recyclable(frame)?;
        match self.lru.oldest_not_kept(frame, |slot| keep(TileId(slot + 1))) {
            Some(slot) => Some((TileId(slot + 1), false)),
            None => Some((oldest, true)),
        }
    }

    /// Returns `tile` to the free list (its nodes are cleared).
    pub fn release(&mut self, tile: TileId) {
        if tile == ROOT_TILE {
            return;
        }
        let per_tile = self.shape.nodes_per_tile() as usize;
        let start = tile.0 as usize * per_tile;
        self.nodes[start..start + per_tile].fill(Node::MISSING);
        self.records[tile.0 as usize].parent = u32::MAX;
        self.lru.release(tile.0 - 1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tile_record_layout_is_fixed() {
        assert_eq!(TILE_RECORD_BYTES, 32);
    }

    #[test]
    fn keys_follow_the_parent() {
        let shape = TreeShape::new(2, 8, 10).unwrap();
        let mut pool = NodePool::new(shape, 8);
        let (tile, recycled) = pool.allocate(NodeId::ROOT, 1).unwrap();
        assert!(!recycled);
        let child = NodeId::new(tile, 7, 8);
        assert_eq!(pool.key(child), NodeKey { level: 1, ijk: [1, 1, 1] });
        let (grand, _) = pool.allocate(child, 1).unwrap();
        assert_eq!(pool.key(NodeId::new(grand, 1, 8)), NodeKey { level: 2, ijk: [3, 2, 2] });
        assert_eq!(pool.tiles_in_use(), 3);
    }

    #[test]
    fn root_tile_is_never_recycled() {
        let shape = TreeShape::new(2, 8, 10).unwrap();
        let mut pool = NodePool::new(shape, 2);
        assert!(pool.allocate(NodeId::ROOT, 1).is_some());
        assert_eq!(pool.oldest_recyclable(1), None);
        assert_eq!(pool.oldest_recyclable(2), Some(TileId(1)));
        assert!(pool.is_in_use(ROOT_TILE));
    }
}
