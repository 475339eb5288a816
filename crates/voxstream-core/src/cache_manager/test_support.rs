//! Test producers and helpers shared by the cache manager's tests.

use crate::error::ProduceError;
use crate::feedback::{Request, RequestKind};
use crate::key::{NodeKey, TreeShape};
use crate::node::NodeId;
use crate::producer::{NodeContent, Produced, Producer};

use super::{CacheManager, ServeOptions, ServeReport};

/// Every node a brick of varying voxels; the oracle knows that the first child of every tile (all of `ijk` even)
/// is empty.
pub(super) struct Ramp;
impl Producer for Ramp {
    fn shape(&self) -> TreeShape {
        TreeShape::new(2, 8, 3).unwrap()
    }
    fn oracle(&self, key: NodeKey) -> Option<f32> {
        (key.level > 0 && key.ijk.iter().all(|c| c % 2 == 0)).then_some(0.0)
    }
    fn produce(&self, key: NodeKey, voxels: &mut [u16]) -> Result<Produced, ProduceError> {
        for (index, v) in voxels.iter_mut().enumerate() {
            *v = (index as u16).wrapping_mul(7).wrapping_add(key.level as u16);
        }
        Ok(Produced { content: NodeContent::Brick, is_terminal: key.level == self.shape().max_level })
    }
}

pub(super) fn request(cache: &mut CacheManager<Ramp>, node: NodeId, kind: RequestKind, prefetch: bool) -> ServeReport {
    cache.begin_frame();
    cache.feedback().push_requests(&[Request { node, kind, deficit: 1 }]);
    let report = cache.end_frame(ServeOptions { limit: None, prefetch_new_children: prefetch, wait_for_data: true });
    assert_eq!(cache.check_invariants(), Ok(()));
    report
}

/// The nodes that own a brick, sorted.
pub(super) fn brick_owners(cache: &CacheManager<Ramp>) -> Vec<NodeId> {
    let pool = cache.brick_pool();
    let mut owners: Vec<NodeId> = (0..pool.allocated())
        .map(crate::node::BrickSlot)
        .filter(|&slot| pool.is_in_use(slot))
        .map(|slot| pool.owner(slot))
        .collect();
    owners.sort_by_key(|id| id.0);
    owners
}

pub(super) fn root_children(cache: &CacheManager<Ramp>) -> Vec<NodeId> {
    let tile = cache.node_pool().node(NodeId::ROOT).child_tile().unwrap();
    (0..8).map(|c| NodeId::new(tile, c, 8)).collect()
}

/// The blending caps of the node's brick in the current frame's view (all 1 when the view carries none).
pub(super) fn caps_of(cache: &CacheManager<Ramp>, node: NodeId) -> crate::BrickBlend {
    let slot = cache.node_pool().node(node).brick().expect("a brick");
    cache.view().brick_blends.get(slot.0 as usize).copied().unwrap_or(crate::BrickBlend::FULL)
}

/// A brick everywhere but at the level-1 node (1, 0, 0), whose production fails.
pub(super) struct FailsOnce;
impl Producer for FailsOnce {
    fn shape(&self) -> TreeShape {
        TreeShape::new(2, 8, 3).unwrap()
    }
    fn produce(&self, key: NodeKey, voxels: &mut [u16]) -> Result<Produced, ProduceError> {
        if key == (NodeKey { level: 1, ijk: [1, 0, 0] }) {
            return Err(ProduceError { level: key.level, ijk: key.ijk, message: "unreadable".into() });
        }
        Ramp.produce(key, voxels)
    }
}

/// A cache of `budget_bytes` for [`Ramp`] whose root has its brick and its tile of children (the children produced
/// with it when `prefetch`).
pub(super) fn with_root_children(budget_bytes: u64, prefetch: bool) -> CacheManager<Ramp> {
    let mut cache = CacheManager::new(Ramp, budget_bytes).unwrap();
    request(&mut cache, NodeId::ROOT, RequestKind::Produce, false);
    request(&mut cache, NodeId::ROOT, RequestKind::Subdivide, prefetch);
    cache
}

/// A cache of the smallest budget the planner accepts for [`Ramp`], holding the root's brick.
pub(super) fn smallest_with_root() -> CacheManager<Ramp> {
    let mut cache = (1..100_000u64).find_map(|step| CacheManager::new(Ramp, step * 64).ok()).unwrap();
    request(&mut cache, NodeId::ROOT, RequestKind::Produce, false);
    cache
}
