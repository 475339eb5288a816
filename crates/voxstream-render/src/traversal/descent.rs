//! The descent (GigaVoxels [P09] §6, step 2 of [`super`]'s walk): from the deepest node of the kept path that still
//! contains the point down towards the cone's level, marking the tiles and bricks used and requesting what is
//! missing (§5, the ray's feedback), and the path kept between segments and between a pass's rays (kd-restart with
//! a short stack; Knoll et al.'s shared descents, seed 002 §4).

use glam::DVec3;
use voxstream_core::{BrickBlend, BrickSlot, Node, NodeData, NodeId, Request, RequestKind, TreeView};

use super::{Traversal, MAX_TABLE_LEVELS};
use crate::integrand::Integrand;

/// Deepest level a descent path can hold.
pub(super) const MAX_PATH: usize = MAX_TABLE_LEVELS;

/// One node of the current descent.
#[derive(Clone, Copy, Debug)]
pub(super) struct PathEntry {
    pub(super) id: NodeId,
    pub(super) node: Node,
    pub(super) ijk: [u64; 3],
}

/// The nodes from the root to the last node reached, reused between segments so that a new descent restarts from
/// the deepest ancestor that still contains the point (a short-stack variant of kd-restart). One per thread, reused
/// from ray to ray.
///
/// A path made by `DescentPath::for_rays_of_one_view` (each pass of a frame makes its own) also keeps the nodes of
/// each ray's first descent, and the next ray starts from them rather than from the root: its first descent restarts
/// from the deepest of them that contains its first point (neighbouring rays of a tile mostly enter the volume in the
/// same nodes). These are the shared descents of Knoll et al.'s packets (seed 002 §4), shared in time rather than in
/// lock-step. A descent finds the same node from any kept ancestor of the point as from the root, so the rays'
/// results are the same bits: where N is a power of two (an ancestor's coordinates are then the point's, shifted,
/// with no rounding; other trees start every ray from the root), and with the kept nodes that an integrand's
/// min/max culling would have stopped at cut off. The nodes kept were marked used when they were first descended
/// to, in the same feedback buffer.
pub struct DescentPath {
    pub(super) entries: [PathEntry; MAX_PATH],
    pub(super) len: usize,
    /// Whether a new ray starts from the last ray's first descent (see `DescentPath::for_rays_of_one_view`).
    pub(super) kept_between_rays: bool,
    /// The nodes of the last ray's first descent, and how many.
    pub(super) first_descent: [PathEntry; MAX_PATH],
    pub(super) first_len: usize,
    /// Whether the next descent is a ray's first (its nodes are then kept in `first_descent`).
    pub(super) first_to_keep: bool,
}

impl DescentPath {
    /// A path holding only the root of `view`; every ray starts from the root.
    pub fn new(view: TreeView<'_>) -> DescentPath {
        let root = PathEntry { id: NodeId::ROOT, node: view.root(), ijk: [0; 3] };
        DescentPath {
            entries: [root; MAX_PATH],
            len: 1,
            kept_between_rays: false,
            first_descent: [root; MAX_PATH],
            first_len: 1,
            first_to_keep: false,
        }
    }

    /// A path that starts each ray from the nodes of the last ray's first descent. Only for rays traced through this
    /// `view` and written into one feedback buffer (one pass of a frame): its nodes would be stale in a later view,
    /// and their marks missing from another buffer. Crate-private for that reason: the frame makes these paths for
    /// each pass ([`RenderSettings::shared_descents`]); paths made by [`DescentPath::new`] can be reused freely.
    pub(crate) fn for_rays_of_one_view(view: TreeView<'_>) -> DescentPath {
        DescentPath { kept_between_rays: true, ..DescentPath::new(view) }
    }

    /// Readies the path for a new ray: the root, or with `DescentPath::for_rays_of_one_view` and `may_keep` the nodes
    /// of the last ray's first descent.
    #[inline(always)]
    pub(super) fn start_ray(&mut self, view: TreeView<'_>, may_keep: bool) {
        if self.kept_between_rays && may_keep {
            debug_assert!(self.first_descent[0].node == view.root(), "a kept path used with another tree view");
            self.entries[..self.first_len].copy_from_slice(&self.first_descent[..self.first_len]);
            self.len = self.first_len;
            self.first_to_keep = true;
        } else {
            self.entries[0] = PathEntry { id: NodeId::ROOT, node: view.root(), ijk: [0; 3] };
            self.len = 1;
        }
    }

    /// After a descent that kept the first `kept` nodes: if it was the ray's first, its new nodes are kept for the
    /// next ray.
    #[inline(always)]
    pub(super) fn descended(&mut self, kept: usize) {
        if self.first_to_keep {
            self.first_to_keep = false;
            self.first_descent[kept..self.len].copy_from_slice(&self.entries[kept..self.len]);
            self.first_len = self.len;
        }
    }
}

/// A brick found on the descent: which slot and which node it belongs to.
#[derive(Clone, Copy, Debug)]
pub(super) struct BrickRef {
    pub(super) slot: BrickSlot,
    pub(super) level: u32,
    pub(super) ijk: [u64; 3],
}

/// What the descent found for the current segment.
pub(super) enum SegmentData {
    /// Nothing resident at all (the root is missing): the segment is skipped.
    Nothing,
    /// A constant node: its samples are all the same value.
    Constant(f32),
    /// Bricks: the finest with data, and its parent for level blending; `stand_in` when finer data is wanted but not
    /// drawable yet (missing, not subdivided, or fading in).
    Bricks { fine: BrickRef, coarse: Option<BrickRef>, blend_level: bool, stand_in: bool },
}

impl<'a> Traversal<'a> {
    /// Descends towards `target_level` at `p`, restarting from the deepest node of the previous descent that still
    /// contains `p` (the root at worst, which is GigaVoxels' kd-restart); returns the data to use and the box of the
    /// deepest node visited (the segment to march).
    #[inline(always)]
    pub(super) fn descend<I: Integrand>(
        &self,
        p: DVec3,
        target_level: u32,
        path: &mut DescentPath,
        request: &mut RequestSink<'_>,
        integrand: &I,
        nodes_entered: &mut u64,
    ) -> (SegmentData, u32, [u64; 3]) {
        let n = self.n;
        let pa = [p.x, p.y, p.z];
        // Keep the ancestors that contain p, and no deeper than the target.
        let mut keep = path.len.min(target_level as usize + 1).max(1);
        if keep > 1 {
            // p's node coordinates at the deepest candidate level; through i64: one instruction (a u64 conversion
            // is a branchy sequence before AVX-512); positions are non-negative and node coordinates below 2⁶³.
            let s = self.scale[keep - 1];
            let deepest = [0, 1, 2].map(|a| (pa[a] * s) as i64 as u64);
            if let Some(shift) = self.n_shift {
                // N = 2^shift: multiplying by a power of two is exact, so an ancestor's coordinates are these
                // shifted, the same integers as computing them from p.
                let mut up = 0;
                while keep > 1 {
                    let ijk = path.entries[keep - 1].ijk;
                    if (0..3).all(|a| deepest[a] >> up == ijk[a]) {
                        break;
                    }
                    keep -= 1;
                    up += shift;
                }
            } else if deepest != path.entries[keep - 1].ijk {
                keep -= 1;
                while keep > 1 {
                    let s = self.scale[keep - 1];
                    if (0..3).all(|a| (pa[a] * s) as i64 as u64 == path.entries[keep - 1].ijk[a]) {
                        break;
                    }
                    keep -= 1;
                }
            }
        }
        if I::CULLS_SUBTREES
            && self.skip_empty_space
            && path.first_to_keep
            && !integrand.contributes_throughout(0.0, 1.0)
        {
            // A ray's first descent from another ray's nodes: a descent from the root would have stopped at the first
            // of them whose values cannot contribute for this ray (min/max culling, below), so keep none below it.
            // (Isosurfaces contribute anywhere before they have read data, as at a first descent: no test then.)
            if let Some(culled) = (0..keep - 1).find(|&level| {
                path.entries[level].node.brick().is_some_and(|slot| {
                    let [lo, hi] = self.view.brick_range(slot);
                    !integrand.can_contribute(lo, hi)
                })
            }) {
                keep = culled + 1;
            }
        }
        path.len = keep;
        let kept = keep;
        loop {
            let level = (path.len - 1) as u32;
            let PathEntry { id, node, ijk } = path.entries[path.len - 1];
            match node.data() {
                NodeData::Constant(value) => {
                    // Under a brick still fading in, the brick stands in (as for its other descendants).
                    if self.view.brick_blends.is_empty() || first_fading(path, self.view.brick_blends, level).is_none()
                    {
                        *nodes_entered += (path.len - kept) as u64;
                        path.descended(kept);
                        return (SegmentData::Constant(value), level, ijk);
                    }
                    break;
                }
                NodeData::Brick(_) => {}
                NodeData::Missing => {
                    // The parent stands in: drawn one level above this node.
                    let deficit = (target_level + 1).saturating_sub(level).min(u8::MAX as u32) as u8;
                    request.push(Request { node: id, kind: RequestKind::Produce, deficit });
                    break;
                }
            }
            if level >= target_level || node.is_terminal() {
                break;
            }
            // A subtree whose values cannot matter is one segment, skipped whole and never loaded deeper (Knoll et
            // al.'s min/max culling). Only for span integrands that place no samples: the sampled ones place their
            // samples by the step of each finer node, which skipping here would shift.
            if I::TAKES_SPANS && I::CULLS_SUBTREES && self.skip_empty_space {
                if let Some(slot) = node.brick() {
                    let [lo, hi] = self.view.brick_range(slot);
                    if !integrand.can_contribute(lo, hi) {
                        break;
                    }
                }
            }
            let Some(tile) = node.child_tile() else {
                let deficit = target_level.saturating_sub(level).min(u8::MAX as u32) as u8;
                request.push(Request { node: id, kind: RequestKind::Subdivide, deficit });
                break;
            };
            self.feedback.mark_tile(tile);
            let s = self.scale[level as usize + 1];
            let mut child_ijk = [0u64; 3];
            let mut child_index = 0u64;
            let mut stride = 1u64;
            for a in 0..3 {
                let lo = ijk[a] * n;
                // Positions are non-negative, so truncation is floor.
                let g = ((pa[a] * s) as i64 as u64).clamp(lo, lo + n - 1);
                child_ijk[a] = g;
                child_index += (g - lo) * stride;
                stride *= n;
            }
            let (child_id, child) = self.view.child(tile, child_index as u32);
            if let Some(slot) = child.brick() {
                self.feedback.mark_brick(slot);
            }
            path.entries[path.len] = PathEntry { id: child_id, node: child, ijk: child_ijk };
            path.len += 1;
        }
        *nodes_entered += (path.len - kept) as u64;
        path.descended(kept);
        // Every node on the path but the last holds a brick; find the two deepest bricks.
        let deepest = path.len - 1;
        let last = path.entries[deepest];
        let brick_at = |level: usize| {
            path.entries[level].node.brick().map(|slot| BrickRef {
                slot,
                level: level as u32,
                ijk: path.entries[level].ijk,
            })
        };
        let mut fine_level = if last.node.brick().is_some() { Some(deepest) } else { deepest.checked_sub(1) };
        if let (Some(fine), false) = (fine_level, self.view.brick_blends.is_empty()) {
            // Level blending: the first brick on the path that has not faded in completely is drawn (blended with
            // its parent), none below it (see `voxstream_core::level_blending`).
            if let Some(fading) = first_fading(path, self.view.brick_blends, fine as u32) {
                fine_level = Some(fading);
            }
        }
        // The data is final where the fine brick is the deepest node and either at the wanted level or terminal.
        let is_final = fine_level == Some(deepest) && (deepest as u32 >= target_level || last.node.is_terminal());
        let data = match fine_level.and_then(|l| brick_at(l).map(|b| (l, b))) {
            None => SegmentData::Nothing,
            Some((l, fine)) => SegmentData::Bricks {
                fine,
                coarse: l.checked_sub(1).and_then(brick_at),
                // Blend with the parent only when the finest data is at the level the cone asked for.
                blend_level: fine.level == target_level,
                stand_in: !is_final,
            },
        };
        (data, deepest as u32, last.ijk)
    }
}

/// The shallowest level above `below` on the path whose brick has not faded in completely.
#[inline]
pub(super) fn first_fading(path: &DescentPath, blends: &[BrickBlend], below: u32) -> Option<usize> {
    (0..below as usize).find(|&level| {
        path.entries[level].node.brick().and_then(|slot| blends.get(slot.0 as usize)).is_some_and(|b| !b.is_in())
    })
}

/// Where a ray's requests go, with its remaining allowance for this frame.
pub(super) struct RequestSink<'v> {
    pub(super) requests: &'v mut Vec<Request>,
    pub(super) remaining: u32,
    /// Whether a request was pushed.
    pub(super) pushed: bool,
}

impl RequestSink<'_> {
    #[inline]
    pub(super) fn push(&mut self, request: Request) {
        if self.remaining > 0 {
            self.remaining -= 1;
            self.requests.push(request);
            self.pushed = true;
        }
    }
}

#[cfg(test)]
mod tests {
    use voxstream_core::TileId;

    use super::super::test_tree::{ray, Child, Record, TestTree};
    use super::super::RayStats;
    use super::*;
    use crate::settings::RenderSettings;

    /// A ray into a child that is not resident requests it (once) and is drawn from the parent's brick there; the
    /// nodes it passed are marked used.
    #[test]
    fn a_missing_child_is_requested_and_its_parent_stands_in() {
        let mut children = [Child::Brick; 8];
        children[1] = Child::Missing;
        let tree = TestTree::new(|_| 0.2, |_| 0.7, children);
        let feedback = tree.feedback();
        let traversal = tree.traversal(&feedback, &RenderSettings::default());
        let mut record = Record::default();
        let mut requests = Vec::new();
        let ray = ray([-0.5, 0.25, 0.25], [1.0, 0.0, 0.0]);
        traversal.trace(&ray, &mut record, &mut RayStats::default(), &mut requests, &mut DescentPath::new(tree.view()));
        assert_eq!(requests, [Request { node: NodeId(9), kind: RequestKind::Produce, deficit: 1 }]);
        assert_eq!(record.levels, [1, 0], "child 0's brick, then the root's standing in for child 1");
        let (near, far): (Vec<&(f64, f32, f64)>, Vec<_>) = record.samples.iter().partition(|s| s.0 < 1.0);
        assert!(near.iter().all(|s| (s.1 - 0.7).abs() < 1e-4) && far.iter().all(|s| (s.1 - 0.2).abs() < 1e-4));
        assert!(!near.is_empty() && !far.is_empty());
        assert_eq!(feedback.used_tiles().collect::<Vec<_>>(), [TileId(1)]);
        assert_eq!(feedback.used_bricks().collect::<Vec<_>>(), [BrickSlot(0), BrickSlot(1)]);
    }

    /// At most `max_requests_per_ray` requests per ray and pass.
    #[test]
    fn a_ray_makes_at_most_its_allowance_of_requests() {
        let mut children = [Child::Missing; 8];
        children[0] = Child::Brick;
        let tree = TestTree::new(|_| 0.2, |_| 0.7, children);
        for (allowance, expected) in [(1, 1), (4, 3)] {
            let settings = RenderSettings { max_requests_per_ray: allowance, ..RenderSettings::default() };
            let feedback = tree.feedback();
            let traversal = tree.traversal(&feedback, &settings);
            let mut requests = Vec::new();
            // Through children 1, 3 and 7 (all missing).
            let ray = ray([0.75, -0.5, -0.4], [0.0, 1.0, 0.85]);
            let mut path = DescentPath::new(tree.view());
            traversal.trace(&ray, &mut Record::default(), &mut RayStats::default(), &mut requests, &mut path);
            assert_eq!(requests.len(), expected, "allowance {allowance}: {requests:?}");
        }
    }

    /// A path kept between rays (shared descents) finds the same nodes as descents from the root, so the rays get
    /// the same samples, but it enters fewer nodes.
    #[test]
    fn a_kept_path_finds_what_a_descent_from_the_root_finds() {
        let mut children = [Child::Brick; 8];
        children[6] = Child::Constant(0.4);
        let tree = TestTree::new(|p| 0.3 * p.z, |p| 0.2 + 0.5 * p.x * p.y, children);
        let feedback = tree.feedback();
        let traversal = tree.traversal(&feedback, &RenderSettings::default());
        let run = |mut path: DescentPath| {
            let mut stats = RayStats::default();
            let records: Vec<Record> = (0..6)
                .map(|i| {
                    let mut record = Record::default();
                    let ray = ray([0.2 + 0.01 * i as f64, 0.3, -1.0], [0.1, 0.05, 1.0]);
                    traversal.trace(&ray, &mut record, &mut stats, &mut Vec::new(), &mut path);
                    record
                })
                .collect();
            (records, stats)
        };
        let (from_root, root_stats) = run(DescentPath::new(tree.view()));
        let (kept, kept_stats) = run(DescentPath::for_rays_of_one_view(tree.view()));
        assert_eq!(from_root, kept);
        assert_eq!(root_stats.descents, kept_stats.descents);
        assert!(kept_stats.nodes_entered < root_stats.nodes_entered, "{kept_stats:?} vs {root_stats:?}");
    }
}
