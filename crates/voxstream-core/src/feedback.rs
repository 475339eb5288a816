//! Ray-guided feedback: what the rays of a frame used and what they found missing.
//!
//! GigaVoxels [P09] §5 ("Ray-guided data requests"): each ray reports the nodes it used, so the cache keeps them,
//! and at most one node it needed but found missing: a node whose brick is not resident (produce) or a node that is
//! too coarse and has no children yet (subdivide). Collapse is never signalled: what rays stop reaching is simply
//! not reported and the LRU recycles it. There is no CPU frustum or LOD pass; only these reports load data.
//!
//! Usage is a flag per tile and per brick slot, written with relaxed atomics by any render thread (a GPU would write
//! the same flags into a storage buffer). Requests are collected per image tile and merged after the frame.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;

use voxstream_layout::{
    RequestRecord, REQUEST_DEFICIT_SHIFT, REQUEST_KIND_MASK, REQUEST_MAX_DEFICIT, REQUEST_PRODUCE, REQUEST_SUBDIVIDE,
};

use crate::node::{BrickSlot, NodeId, TileId};

// A request's deficit is a `u8`: the most a record carries, and what a GPU ray writes at most, is its maximum.
const _: () = assert!(REQUEST_MAX_DEFICIT == u8::MAX as u32);

/// What a ray asks the cache manager to do for a node.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum RequestKind {
    /// The node's data is not resident: produce its brick (or learn that it is constant).
    Produce,
    /// The node is too coarse for the ray and has no children: create its child tile.
    Subdivide,
}

/// One ray's request.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Request {
    /// The node concerned.
    pub node: NodeId,
    /// What to do.
    pub kind: RequestKind,
    /// How many levels coarser than it wanted the ray drew for lack of this node (Thiele et al.'s ideal − actual
    /// level, at least 1): the request's priority ([`crate::RequestQueue`]).
    pub deficit: u8,
}

impl Request {
    /// The request as a GPU writes it ([`voxstream_layout::feedback_records`]).
    pub fn to_record(self) -> RequestRecord {
        let kind = match self.kind {
            RequestKind::Produce => REQUEST_PRODUCE,
            RequestKind::Subdivide => REQUEST_SUBDIVIDE,
        };
        RequestRecord { node: self.node.0, kind: kind | (self.deficit as u32) << REQUEST_DEFICIT_SHIFT }
    }

    /// A request read back from a GPU's request buffer; `None` for a kind no ray writes (a corrupt buffer).
    pub fn from_record(record: RequestRecord) -> Option<Request> {
        let kind = match record.kind & REQUEST_KIND_MASK {
            REQUEST_PRODUCE => RequestKind::Produce,
            REQUEST_SUBDIVIDE => RequestKind::Subdivide,
            _ => return None,
        };
        let deficit = (record.kind >> REQUEST_DEFICIT_SHIFT) as u8;
        (record.kind >> REQUEST_DEFICIT_SHIFT <= u8::MAX as u32).then_some(Request {
            node: NodeId(record.node),
            kind,
            deficit,
        })
    }
}

/// The feedback of one frame, written concurrently by the renderer's threads.
#[derive(Debug, Default)]
pub struct FeedbackBuffer {
    used_tiles: Vec<AtomicBool>,
    used_bricks: Vec<AtomicBool>,
    requests: Mutex<Vec<Request>>,
}

impl FeedbackBuffer {
    /// An empty buffer for pools of `tiles` tiles and `bricks` brick slots.
    pub fn new(tiles: u32, bricks: u32) -> FeedbackBuffer {
        let mut buffer = FeedbackBuffer::default();
        buffer.reset(tiles, bricks);
        buffer
    }

    /// Clears every flag and request and sizes the flags for the pools' current high-water marks.
    pub fn reset(&mut self, tiles: u32, bricks: u32) {
        self.used_tiles.iter_mut().for_each(|f| *f.get_mut() = false);
        self.used_bricks.iter_mut().for_each(|f| *f.get_mut() = false);
        self.used_tiles.resize_with(tiles as usize, AtomicBool::default);
        self.used_bricks.resize_with(bricks as usize, AtomicBool::default);
        self.requests.get_mut().unwrap_or_else(|poisoned| poisoned.into_inner()).clear();
    }

    /// Records that a ray descended through `tile`.
    #[inline]
    pub fn mark_tile(&self, tile: TileId) {
        if let Some(flag) = self.used_tiles.get(tile.0 as usize) {
            // Read first: most tiles are already marked, and a read keeps the cache line shared between threads.
            if !flag.load(Ordering::Relaxed) {
                flag.store(true, Ordering::Relaxed);
            }
        }
    }

    /// Records that a ray sampled `brick`.
    #[inline]
    pub fn mark_brick(&self, brick: BrickSlot) {
        if let Some(flag) = self.used_bricks.get(brick.0 as usize) {
            if !flag.load(Ordering::Relaxed) {
                flag.store(true, Ordering::Relaxed);
            }
        }
    }

    /// Appends the requests of a batch of rays (one image tile).
    pub fn push_requests(&self, requests: &[Request]) {
        if !requests.is_empty() {
            self.requests.lock().unwrap_or_else(|poisoned| poisoned.into_inner()).extend_from_slice(requests);
        }
    }

    /// Tiles used during the frame.
    pub fn used_tiles(&self) -> impl Iterator<Item = TileId> + '_ {
        self.used_tiles.iter().enumerate().filter(|(_, f)| f.load(Ordering::Relaxed)).map(|(i, _)| TileId(i as u32))
    }

    /// Brick slots used during the frame.
    pub fn used_bricks(&self) -> impl Iterator<Item = BrickSlot> + '_ {
        self.used_bricks.iter().enumerate().filter(|(_, f)| f.load(Ordering::Relaxed)).map(|(i, _)| BrickSlot(i as u32))
    }

    /// Takes the raw (not yet deduplicated) requests of the frame.
    pub fn take_requests(&mut self) -> Vec<Request> {
        std::mem::take(self.requests.get_mut().unwrap_or_else(|poisoned| poisoned.into_inner()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flags_are_set_and_reset() {
        let mut feedback = FeedbackBuffer::new(4, 4);
        feedback.mark_tile(TileId(2));
        feedback.mark_brick(BrickSlot(3));
        feedback.mark_brick(BrickSlot(99)); // beyond the pool: ignored, never a panic
        assert_eq!(feedback.used_tiles().collect::<Vec<_>>(), vec![TileId(2)]);
        assert_eq!(feedback.used_bricks().collect::<Vec<_>>(), vec![BrickSlot(3)]);
        feedback.push_requests(&[Request { node: NodeId(1), kind: RequestKind::Produce, deficit: 1 }]);
        assert_eq!(feedback.take_requests().len(), 1);
        feedback.reset(8, 8);
        assert_eq!(feedback.used_tiles().count(), 0);
        assert_eq!(feedback.used_bricks().count(), 0);
    }

    #[test]
    fn requests_round_trip_through_the_gpu_record() {
        for kind in [RequestKind::Produce, RequestKind::Subdivide] {
            for deficit in [1, 7, 255] {
                let request = Request { node: NodeId(41), kind, deficit };
                assert_eq!(Request::from_record(request.to_record()), Some(request));
            }
        }
        assert_ne!(
            Request { node: NodeId(1), kind: RequestKind::Produce, deficit: 1 }.to_record(),
            Request { node: NodeId(1), kind: RequestKind::Subdivide, deficit: 1 }.to_record()
        );
        assert_eq!(Request::from_record(RequestRecord { node: 1, kind: 7 }), None);
        assert_eq!(Request::from_record(RequestRecord { node: 1, kind: 1 << 16 }), None);
    }
}
