//! Level changes that never pop: per-brick caps on a brick's weight against its parent (temporal and spatial
//! blending).
//!
//! Implements Thiele et al. (seed 003; `../shared/notes/thiele-lod-blending.md` §"Temporal blending" and
//! §"Spatial (spatiotemporal) blending"), adapted to GigaVoxels' ray-guided cache:
//!
//! - **Temporal.** A brick that arrives in frame `f` does not replace its parent at once: in frame `f + k` its
//!   weight against the parent is at most `t = min(1, k / fade_frames)`, so it fades in over `fade_frames` frames.
//! - **Spatial.** Each brick has a cap at each of its eight corners ([`BrickBlend`]), interpolated trilinearly by the
//!   renderer: the minimum of `t` over the equal-level bricks sharing the corner, and 0 where a region the rays want
//!   at this brick's level is still coarser (a node whose brick is requested but not yet produced, or a node whose
//!   children are requested but not yet created). There the brick's weight goes to zero, i.e. it shows its parent,
//!   which is what the rays on the other side show: no seam.
//! - **The renderer** uses `min(cone weight, cap)` where the cone weight is its usual quadrilinear level blend. With
//!   every cap at 1 (nothing arriving, nothing pending) the view carries no caps at all and the renderer takes its
//!   usual path: a camera at rest converges to the same bytes with blending on and off.
//!
//! Differences from Thiele et al., on purpose:
//! - Their renderer samples one "cut" of the tree; here each ray's cone picks the level and already blends
//!   continuously between two levels wherever the *wanted* level changes (GigaVoxels [P09] §6). What pops here is
//!   what *arrives* (and seams are where the wanted level is not resident yet), so the caps are built from arrivals
//!   and pending requests rather than from the cut's depth differences.
//! - There is no fade-out before a collapse: nodes are recycled only when no ray used them in the current frame
//!   (the LRU never takes a brick the last frame drew), and a ray that stops wanting a level (the cone moves up)
//!   already reaches it with a level weight that went continuously to zero.

use crate::key::{NodeKey, TreeShape};
use crate::node::{BrickSlot, Node, NodeId};
use crate::node_pool::NodePool;

pub use voxstream_layout::BrickBlend;

/// The default fade-in, in frames.
pub const DEFAULT_FADE_FRAMES: u32 = 8;

/// Most pending regions kept per frame (the first ones in request priority; the rest get no spatial cap).
pub const MAX_PENDING_REGIONS: usize = 4096;

/// Bytes per brick slot of the blending state (its [`BrickBlend`] record), counted in the memory budget.
pub const BLEND_BYTES_PER_BRICK: usize = std::mem::size_of::<BrickBlend>();

/// What the blending state knows between frames.
#[derive(Clone, Debug)]
pub struct LevelBlending {
    fade_frames: u32,
    /// Bricks produced in the last `fade_frames` frames: slot, owner and the frame that produced them.
    arrivals: Vec<(BrickSlot, NodeId, u32)>,
    /// Regions the rays want finer than resident: a node and the level they want inside it.
    pending: Vec<(NodeKey, u32)>,
    /// Per brick slot: the caps of the current frame.
    caps: Vec<BrickBlend>,
    /// Whether some cap of the current frame is below 1.
    active: bool,
}

impl LevelBlending {
    /// Blending with a fade-in of `fade_frames` frames (at least 1: 1 is an immediate replacement, but the spatial
    /// caps still apply).
    pub fn new(fade_frames: u32) -> LevelBlending {
        LevelBlending {
            fade_frames: fade_frames.max(1),
            arrivals: Vec::new(),
            pending: Vec::new(),
            caps: Vec::new(),
            active: false,
        }
    }

    /// The fade-in length, frames.
    pub fn fade_frames(&self) -> u32 {
        self.fade_frames
    }

    /// Records that `owner`'s brick arrived in `slot` during `frame`.
    pub fn arrived(&mut self, slot: BrickSlot, owner: NodeId, frame: u32) {
        self.arrivals.push((slot, owner, frame));
    }

    /// Replaces the pending regions by `regions` (node, wanted level), the first [`MAX_PENDING_REGIONS`] of them.
    pub fn set_pending(&mut self, regions: impl IntoIterator<Item = (NodeKey, u32)>) {
        self.pending.clear();
        self.pending.extend(regions.into_iter().take(MAX_PENDING_REGIONS));
    }

    /// Forgets every arrival and pending region: what is resident now is shown as it is (after a converged frame,
    /// whose image is exact and final).
    pub fn settle(&mut self) {
        self.arrivals.clear();
        self.pending.clear();
        self.active = false;
    }

    /// The fade weight in `frame` of a brick produced in `arrival`.
    pub fn fade(&self, arrival: u32, frame: u32) -> f32 {
        (frame.saturating_sub(arrival) as f32 / self.fade_frames as f32).min(1.0)
    }

    /// Whether some cap of the current frame is below 1 (the image is still blending towards its final state).
    pub fn is_active(&self) -> bool {
        self.active
    }

    /// The caps of the current frame, one per brick slot; empty when none is below 1 (no blending needed).
    pub fn caps(&self) -> &[BrickBlend] {
        if self.active {
            &self.caps
        } else {
            &[]
        }
    }

    /// Computes the caps for `frame` over the current pools; `slots` is the brick pool's allocated slot count and
    /// `owner_of` tells which node owns a slot in use (`None` if free).
    pub fn update(
        &mut self,
        frame: u32,
        pool: &NodePool,
        slots: u32,
        owner_of: impl Fn(BrickSlot) -> Option<NodeId>,
    ) {
        let shape = *pool.shape();
        // Forget finished fades and bricks recycled since they arrived.
        let fade_frames = self.fade_frames;
        self.arrivals.retain(|&(slot, owner, arrival)| {
            frame.saturating_sub(arrival) < fade_frames && owner_of(slot) == Some(owner)
        });
        self.active = false;
        if self.arrivals.is_empty() && self.pending.is_empty() {
            return;
        }
        self.caps.clear();
        self.caps.resize(slots as usize, BrickBlend::FULL);
        let mut caps = std::mem::take(&mut self.caps);
        let mut active = false;
        let mut lower = |slot: BrickSlot, corner: usize, cap: f32, caps: &mut Vec<BrickBlend>| {
            if let Some(blend) = caps.get_mut(slot.0 as usize) {
                let mut corners = blend.corners();
                if cap < corners[corner] {
                    corners[corner] = cap;
                    *blend = BrickBlend::from_corners(corners);
                    active = true;
                }
            }
        };
        // Temporal: an arriving brick's own corners, and the corners its equal-level neighbours share with it.
        for &(slot, owner, arrival) in &self.arrivals {
            let t = self.fade(arrival, frame);
            let key = pool.key(owner);
            for corner in 0..8 {
                lower(slot, corner, t, &mut caps);
            }
            for_each_touching(&shape, pool, key.ijk, 1, key.level, |neighbour_slot, corner| {
                lower(neighbour_slot, corner, t, &mut caps)
            });
        }
        // Spatial: bricks around a region the rays want at their level but which is still coarser go to 0 there.
        for &(key, wanted_level) in &self.pending {
            let scale = shape.n as u64;
            let span = scale.pow(wanted_level - key.level);
            let lower_corner = key.ijk.map(|c| c * span);
            for_each_touching(&shape, pool, lower_corner, span, wanted_level, |neighbour_slot, corner| {
                lower(neighbour_slot, corner, 0.0, &mut caps)
            });
        }
        self.caps = caps;
        self.active = active;
    }
}

/// Calls `visit(slot, corner)` for every corner of every brick at `level` outside the cube `[lower, lower + span)³`
/// (level coordinates) whose corner lies on the cube (its faces, edges or corners).
fn for_each_touching(
    shape: &TreeShape,
    pool: &NodePool,
    lower: [u64; 3],
    span: u64,
    level: u32,
    mut visit: impl FnMut(BrickSlot, usize),
) {
    let extent = shape.nodes_per_axis(level);
    let range = |a: usize| lower[a].saturating_sub(1)..(lower[a] + span + 1).min(extent);
    for k in range(2) {
        for j in range(1) {
            for i in range(0) {
                let m = [i, j, k];
                let inside = (0..3).all(|a| m[a] >= lower[a] && m[a] < lower[a] + span);
                if inside {
                    continue;
                }
                let Some(slot) = find_node(pool, shape, NodeKey { level, ijk: m }).and_then(|node| node.brick()) else {
                    continue;
                };
                for corner in 0..8 {
                    let on_cube = (0..3).all(|a| {
                        let c = m[a] + ((corner >> a) & 1) as u64;
                        c >= lower[a] && c <= lower[a] + span
                    });
                    if on_cube {
                        visit(slot, corner);
                    }
                }
            }
        }
    }
}

/// The node at `key` if the tree reaches it.
pub fn find_node(pool: &NodePool, shape: &TreeShape, key: NodeKey) -> Option<Node> {
    let n = shape.n as u64;
    let per_tile = shape.nodes_per_tile();
    let mut node = pool.node(NodeId::ROOT);
    for level in 1..=key.level {
        let tile = node.child_tile()?;
        let divisor = n.pow(key.level - level);
        let local = key.ijk.map(|c| (c / divisor) % n);
        let child = local[0] + n * (local[1] + n * local[2]);
        node = pool.node(NodeId::new(tile, child as u32, per_tile));
    }
    Some(node)
}
