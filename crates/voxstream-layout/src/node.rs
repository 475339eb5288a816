//! The node record of the N³-tree: two 32-bit words, GPU-uploadable as is.
//!
//! Implements the node layout of GigaVoxels [P09] §4 ("Node structure"; seed 000, notes `gigavoxels.md`,
//! "Structure"). There is no "valid" bit: the ray decides whether a node is fine enough.
//!
//! ```text
//! word 0 (child word)                     word 1 (data word)
//! ┌──┬──┬──────────────────────────────┐   ┌────────────────────────────────────┐
//! │31│30│ 29 … 0                       │   │ 31 … 0                             │
//! │C │T │ child tile index (0 = none)  │   │ C=1: constant value (f32 bits)     │
//! └──┴──┴──────────────────────────────┘   │ C=0: brick slot + 1 (0 = no brick) │
//!  C = constant node, T = terminal          └────────────────────────────────────┘
//! ```
//! A node is 8 bytes; `N³` sibling nodes form a contiguous tile in the node pool. Tile 0 is the root tile (only its
//! first node, the root, is used), so tile index 0 can mean "no children".
//!
//! | offset | bytes | field | WGSL |
//! |---|---|---|---|
//! | 0 | 4 | [`Node::child_word`] | `child_word: u32` |
//! | 4 | 4 | [`Node::data_word`] | `data_word: u32` |
//!
//! Size 8, alignment 4: a tile of `N³` nodes is `8·N³` bytes (64 for N = 2, 216 for N = 3).

use bytemuck::{Pod, Zeroable};

/// Bit 31 of the child word: the node holds a constant value instead of a brick.
pub const CONSTANT_BIT: u32 = 1 << 31;
/// Bit 30 of the child word: the producer has no finer data below this node.
pub const TERMINAL_BIT: u32 = 1 << 30;
/// Mask of the child-tile index in the child word (30 bits).
pub const CHILD_MASK: u32 = (1 << 30) - 1;
/// Largest tile index a node can point to.
pub const MAX_TILE_INDEX: u32 = CHILD_MASK;

/// Index of a tile of `N³` sibling nodes in the node pool.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct TileId(pub u32);

/// Index of a brick slot in the brick pool.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct BrickSlot(pub u32);

/// Index of one node in the node pool: `tile · N³ + child`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct NodeId(pub u32);

impl NodeId {
    /// The root node: first node of the root tile.
    pub const ROOT: NodeId = NodeId(0);

    /// The node `child` (0‥N³) of `tile`.
    #[inline]
    pub fn new(tile: TileId, child: u32, nodes_per_tile: u32) -> NodeId {
        NodeId(tile.0 * nodes_per_tile + child)
    }

    /// The tile holding this node.
    #[inline]
    pub fn tile(self, nodes_per_tile: u32) -> TileId {
        TileId(self.0 / nodes_per_tile)
    }

    /// This node's position among its siblings (0‥N³).
    #[inline]
    pub fn child_index(self, nodes_per_tile: u32) -> u32 {
        self.0 % nodes_per_tile
    }
}

/// One node of the N³-tree, exactly as the renderers read it.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct Node {
    /// Flags and child-tile index (see the module docs).
    pub child_word: u32,
    /// Constant value bits or brick slot + 1.
    pub data_word: u32,
}

/// What a node holds, decoded.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum NodeData {
    /// Homogeneous region: the value holds at every finer level too.
    Constant(f32),
    /// A resident brick.
    Brick(BrickSlot),
    /// Data not resident (never produced, or evicted): a ray reaching it requests production.
    Missing,
}

impl Node {
    /// A fresh node whose data has not been produced yet.
    pub const MISSING: Node = Node { child_word: 0, data_word: 0 };

    /// A constant node (never subdivided; terminal by construction).
    #[inline]
    pub fn constant(value: f32) -> Node {
        Node { child_word: CONSTANT_BIT | TERMINAL_BIT, data_word: value.to_bits() }
    }

    /// Whether the node holds a constant value.
    #[inline]
    pub fn is_constant(self) -> bool {
        self.child_word & CONSTANT_BIT != 0
    }

    /// Whether the producer has no finer data below this node.
    #[inline]
    pub fn is_terminal(self) -> bool {
        self.child_word & TERMINAL_BIT != 0
    }

    /// The child tile, if the node has been subdivided.
    #[inline]
    pub fn child_tile(self) -> Option<TileId> {
        let index = self.child_word & CHILD_MASK;
        (index != 0).then_some(TileId(index))
    }

    /// Decodes the data word.
    #[inline]
    pub fn data(self) -> NodeData {
        if self.is_constant() {
            NodeData::Constant(f32::from_bits(self.data_word))
        } else if self.data_word == 0 {
            NodeData::Missing
        } else {
            NodeData::Brick(BrickSlot(self.data_word - 1))
        }
    }

    /// The resident brick, if any.
    #[inline]
    pub fn brick(self) -> Option<BrickSlot> {
        match self.data() {
            NodeData::Brick(slot) => Some(slot),
            _ => None,
        }
    }

    /// Points the node at a child tile (keeps flags and data).
    #[inline]
    pub fn set_child_tile(&mut self, tile: Option<TileId>) {
        let index = tile.map_or(0, |t| t.0);
        debug_assert!(index <= MAX_TILE_INDEX);
        self.child_word = (self.child_word & !CHILD_MASK) | (index & CHILD_MASK);
    }

    /// Marks whether the producer has finer data below this node.
    #[inline]
    pub fn set_terminal(&mut self, is_terminal: bool) {
        if is_terminal {
            self.child_word |= TERMINAL_BIT;
        } else {
            self.child_word &= !TERMINAL_BIT;
        }
    }

    /// Attaches a resident brick (clears the constant flag).
    #[inline]
    pub fn set_brick(&mut self, slot: Option<BrickSlot>) {
        self.child_word &= !CONSTANT_BIT;
        self.data_word = slot.map_or(0, |s| s.0 + 1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::mem::{align_of, offset_of, size_of};

    #[test]
    fn node_is_two_words() {
        assert_eq!(size_of::<Node>(), 8);
        assert_eq!(align_of::<Node>(), 4);
        assert_eq!(offset_of!(Node, child_word), 0);
        assert_eq!(offset_of!(Node, data_word), 4);
        let bytes: &[u8] = bytemuck::bytes_of(&Node { child_word: 0x0403_0201, data_word: 0x0807_0605 });
        assert_eq!(bytes, &[1, 2, 3, 4, 5, 6, 7, 8]);
    }

    #[test]
    fn missing_node_decodes() {
        let node = Node::MISSING;
        assert_eq!(node.data(), NodeData::Missing);
        assert!(!node.is_constant() && !node.is_terminal());
        assert_eq!(node.child_tile(), None);
    }

    #[test]
    fn constant_round_trips_every_value() {
        for value in [0.0f32, 1.0, 0.25, -3.5, f32::MIN_POSITIVE] {
            let node = Node::constant(value);
            assert_eq!(node.data(), NodeData::Constant(value));
            assert!(node.is_terminal());
        }
    }

    #[test]
    fn brick_and_child_are_independent() {
        let mut node = Node::MISSING;
        node.set_brick(Some(BrickSlot(0)));
        assert_eq!(node.data(), NodeData::Brick(BrickSlot(0)));
        node.set_child_tile(Some(TileId(MAX_TILE_INDEX)));
        node.set_terminal(true);
        assert_eq!(node.child_tile(), Some(TileId(MAX_TILE_INDEX)));
        assert_eq!(node.brick(), Some(BrickSlot(0)));
        assert!(node.is_terminal());
        node.set_brick(None);
        assert_eq!(node.data(), NodeData::Missing);
        assert_eq!(node.child_tile(), Some(TileId(MAX_TILE_INDEX)));
        node.set_child_tile(None);
        node.set_terminal(false);
        assert_eq!(node, Node::MISSING);
    }

    #[test]
    fn node_id_splits_into_tile_and_child() {
        for per_tile in [8u32, 27] {
            let id = NodeId::new(TileId(5), per_tile - 1, per_tile);
            assert_eq!(id.tile(per_tile), TileId(5));
            assert_eq!(id.child_index(per_tile), per_tile - 1);
        }
    }
}
