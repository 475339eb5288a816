//! The producer interface: where bricks come from (procedural generators, files, converters).
//!
//! GigaVoxels [R08] §4 ("Producers") and [P09] §5: given a node (level and integer coordinates), a producer yields
//! an empty region, a constant value, or a brick of `(M+2)³` voxels including the one-voxel border; an oracle
//! answers conservatively, without producing, whether a region is known to be empty or constant. Reichl's framework
//! (seed 004, ch. 4) calls the same role a data supplier. Producers run on worker threads, hence `Send + Sync`.

use crate::error::ProduceError;
use crate::key::{NodeKey, TreeShape};
use crate::voxel_format::VoxelFormat;

/// What a node turned out to hold.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum NodeContent {
    /// Nothing (value 0) here and below.
    Empty,
    /// The same value everywhere here and below.
    Constant(f32),
    /// The voxels were written to the output brick.
    Brick,
}

/// The result of producing one node.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Produced {
    /// What the node holds.
    pub content: NodeContent,
    /// Whether the source has no finer data below this node.
    pub is_terminal: bool,
}

/// A source of bricks for an N³-tree.
pub trait Producer: Send + Sync {
    /// Shape of the tree this producer feeds (N, brick size, deepest level).
    fn shape(&self) -> TreeShape;

    /// A conservative a-priori answer: `Some(value)` if the whole node is known to hold `value` (0 = empty) without
    /// producing it, `None` if unknown. Must be cheap; called for every child of a subdivided node.
    fn oracle(&self, key: NodeKey) -> Option<f32> {
        let _ = key;
        None
    }

    /// Produces the node `key`. For [`NodeContent::Brick`], `voxels` (length `(M+2)³`, x fastest) receives the
    /// brick with its border: voxel `(i, j, k)` of the array is centred at `lower + (i − 1 + ½, …)·voxel_size`.
    fn produce(&self, key: NodeKey, voxels: &mut [u16]) -> Result<Produced, ProduceError>;

    /// How the brick pool may store this producer's voxels: [`VoxelFormat::Narrow`] when every voxel it writes
    /// is the 16-bit quantisation of `byte · scale + offset` for some byte (see [`crate::voxel_format`]). The
    /// default, [`VoxelFormat::Wide`], keeps 16 bits.
    fn voxel_format(&self) -> VoxelFormat {
        VoxelFormat::Wide
    }

    /// Normalised bounds of every value the tree can hold in `key`'s box at `key`'s level and every finer one,
    /// including the trilinear values near its faces (which read the neighbours' voxels), or `None` if unknown.
    /// Renderers use it to skip a whole subtree without loading it (Knoll et al.'s min/max hierarchy); it must be
    /// conservative. The default knows nothing.
    fn subtree_range(&self, key: NodeKey) -> Option<[f32; 2]> {
        let _ = key;
        None
    }

    /// A hint that these nodes will probably be requested soon (requests deferred past this frame's bound, or, in
    /// converged passes, the level below what the rays still lack: [`crate::ServeOptions::prefetch_new_children`]):
    /// a producer that reads from slow storage may start fetching them in the background. It must not change what
    /// `produce` returns. The default does nothing.
    fn prefetch(&self, keys: &[NodeKey]) {
        let _ = keys;
    }
    /// Brings the data of `keys` within reach and returns when it is there: called on the producer's own pool (see
    /// [`Producer::concurrency`]) before a batch whose frame waits for its data is produced, so that a producer
    /// reading a network has every request of the batch in flight at once, rather than the few of each `produce`
    /// call one after another. Failures are left to `produce`, which reports them. The default does nothing.
    fn fetch(&self, keys: &[NodeKey]) {
        let _ = keys;
    }
    /// How many nodes this producer should be asked for at once: a producer whose reads wait on a network (a remote
    /// store) serves a batch fastest with that many requests in flight, so the cache manager produces its batches on
    /// a pool of that many threads of its own. The default, 0, uses the shared worker pool (one thread per core).
    fn concurrency(&self) -> usize {
        0
    }
    /// Whether producing `key` now would return without waiting on slow storage. A producer that fetches in the
    /// background (a remote store in interactive mode) answers `false` while the node's data is on its way, and
    /// starts fetching it; the cache manager then leaves the request to a later frame (the rays ask again, ancestors
    /// stand in) instead of holding the frame until it arrives. Producing a node that is not ready must still work
    /// (it waits). The default: always ready.
    fn ready(&self, key: NodeKey) -> bool {
        let _ = key;
        true
    }
}

/// A boxed producer is a producer: front ends that open sources of several kinds (a scene, a store, a mesh) hold
/// them as `Box<dyn Producer>`. Every method forwards, so the inner producer's overrides stay in force.
impl<P: Producer + ?Sized> Producer for Box<P> {
    fn shape(&self) -> TreeShape {
        (**self).shape()
    }
    fn oracle(&self, key: NodeKey) -> Option<f32> {
        (**self).oracle(key)
    }
    fn produce(&self, key: NodeKey, voxels: &mut [u16]) -> Result<Produced, ProduceError> {
        (**self).produce(key, voxels)
    }
    fn voxel_format(&self) -> VoxelFormat {
        (**self).voxel_format()
    }
    fn subtree_range(&self, key: NodeKey) -> Option<[f32; 2]> {
        (**self).subtree_range(key)
    }
    fn prefetch(&self, keys: &[NodeKey]) {
        (**self).prefetch(keys)
    }
    fn fetch(&self, keys: &[NodeKey]) {
        (**self).fetch(keys)
    }
    fn concurrency(&self) -> usize {
        (**self).concurrency()
    }
    fn ready(&self, key: NodeKey) -> bool {
        (**self).ready(key)
    }
}
