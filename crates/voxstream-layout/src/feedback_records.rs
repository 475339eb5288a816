//! The feedback records: what the rays of a frame write for the cache manager, as a GPU would write them.
//!
//! GigaVoxels [P09] §5 ("Ray-guided data requests"): rays report the node tiles and bricks they used (so the LRU
//! keeps them) and at most a few nodes they needed but found missing. On a GPU this is three buffers, all reset to
//! zero before a frame:
//! - a [`UsageFlag`] per node tile and one per brick slot: any ray that uses the tile or brick stores 1 (a plain store
//!   suffices: every writer writes the same value; no atomics, as in `JolifantoBambla/volume-viewer`'s usage
//!   textures);
//! - a [`RequestRecord`] list, appended to by `atomicAdd` on [`FeedbackCounters::request_count`]; a ray whose slot
//!   lands beyond [`FeedbackCounters::request_capacity`] counts itself in
//!   [`FeedbackCounters::dropped_requests`] and writes nothing (it asks again next frame);
//! - the [`FeedbackCounters`] themselves.
//!
//! The CPU renderer keeps the same information in `voxstream_core::FeedbackBuffer` (flags as `AtomicBool`, requests
//! per image tile); `voxstream_core::Request` converts to and from [`RequestRecord`].
//!
//! | record | offset | bytes | field | meaning |
//! |---|---|---|---|---|
//! | [`FeedbackCounters`] | 0 | 4 | `request_count` | requests appended (may exceed the capacity) |
//! | | 4 | 4 | `request_capacity` | records the request buffer holds |
//! | | 8 | 4 | `dropped_requests` | requests that found the buffer full |
//! | | 12 | 4 | `padding` | zero |
//! | [`RayCounters`] | 0, 4, 8 | 4 each | `rays`, `samples`, `descents` | what a pass's rays counted |
//! | | 12 | 4 | `padding` | zero |
//! | [`UsageFlag`] | 0 | 4 | `used` | 0 = unused this frame, 1 = used |
//! | [`RequestRecord`] | 0 | 4 | `node` | the node's index in the node buffer |
//! | | 4 | 4 | `kind` | bits 0–7: [`REQUEST_PRODUCE`] or [`REQUEST_SUBDIVIDE`]; bits 8–15: the ray's level deficit |

use bytemuck::{Pod, Zeroable};

/// [`RequestRecord::kind`]: the node's data is not resident; produce its brick (or learn that it is constant).
pub const REQUEST_PRODUCE: u32 = 0;
/// [`RequestRecord::kind`]: the node is too coarse for the ray and has no children; create its child tile.
pub const REQUEST_SUBDIVIDE: u32 = 1;
/// [`RequestRecord::kind`]'s bits holding the kind.
pub const REQUEST_KIND_MASK: u32 = 0xff;
/// [`RequestRecord::kind`]'s shift to the level deficit (8 bits): how many levels coarser than it wanted the ray drew
/// for lack of this node (Thiele et al.'s ideal − actual level, the request's priority).
pub const REQUEST_DEFICIT_SHIFT: u32 = 8;
/// The largest level deficit a [`RequestRecord`] carries (8 bits: `voxstream_core::Request` keeps it in a `u8`); a
/// ray that lacks more levels writes this.
pub const REQUEST_MAX_DEFICIT: u32 = 0xff;

/// The fill level of the request buffer.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct FeedbackCounters {
    /// Requests appended this frame (an `atomic<u32>` in WGSL; may exceed `request_capacity`).
    pub request_count: u32,
    /// Records the request buffer holds.
    pub request_capacity: u32,
    /// Requests that found the buffer full (an `atomic<u32>` in WGSL).
    pub dropped_requests: u32,
    /// Zero; pads the counters to 16 bytes.
    pub padding: u32,
}

/// What the rays of one pass counted, for `--stats` (each an `atomic<u32>` in WGSL, added to once per ray; they
/// wrap past 2³², far above a pass's samples at the image sizes a GPU pass traces).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct RayCounters {
    /// Rays traced.
    pub rays: u32,
    /// Brick samples taken plus constant segments integrated.
    pub samples: u32,
    /// Descents from the root.
    pub descents: u32,
    /// Zero; pads the counters to 16 bytes.
    pub padding: u32,
}

/// Whether a node tile or a brick slot was used this frame.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct UsageFlag {
    /// 0 = unused this frame, 1 = used.
    pub used: u32,
}

/// One ray's request for one node.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct RequestRecord {
    /// The node's index in the node buffer.
    pub node: u32,
    /// [`REQUEST_PRODUCE`] or [`REQUEST_SUBDIVIDE`], with the level deficit at [`REQUEST_DEFICIT_SHIFT`].
    pub kind: u32,
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::mem::{align_of, offset_of, size_of};

    #[test]
    fn offsets_are_as_documented() {
        assert_eq!(size_of::<FeedbackCounters>(), 16);
        assert_eq!(align_of::<FeedbackCounters>(), 4);
        assert_eq!(offset_of!(FeedbackCounters, request_count), 0);
        assert_eq!(offset_of!(FeedbackCounters, request_capacity), 4);
        assert_eq!(offset_of!(FeedbackCounters, dropped_requests), 8);
        assert_eq!(offset_of!(FeedbackCounters, padding), 12);

        assert_eq!(size_of::<UsageFlag>(), 4);
        assert_eq!(align_of::<UsageFlag>(), 4);
        assert_eq!(offset_of!(UsageFlag, used), 0);

        assert_eq!(size_of::<RequestRecord>(), 8);
        assert_eq!(align_of::<RequestRecord>(), 4);
        assert_eq!(offset_of!(RequestRecord, node), 0);
        assert_eq!(offset_of!(RequestRecord, kind), 4);
    }

    #[test]
    fn the_two_request_kinds_differ() {
        assert_ne!(REQUEST_PRODUCE, REQUEST_SUBDIVIDE);
    }
}
