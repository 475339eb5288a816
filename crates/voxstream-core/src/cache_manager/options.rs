//! What [`CacheManager::end_frame`](super::CacheManager::end_frame) is asked to do with one frame's requests: the
//! per-frame bound, producing the children of new tiles, waiting for data still on its way (GigaVoxels [P09] §5).

#[cfg(doc)]
use crate::producer::Producer;

/// How [`CacheManager::end_frame`] serves one frame's requests.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ServeOptions {
    /// Most requests served (all if `None`); the rest wait for a later frame.
    pub limit: Option<usize>,
    /// Also produce the children of each new tile into free brick slots, never evicting (see the module docs), and
    /// hint the producer at the level below what was served where rays are still short of two or more levels
    /// ([`Producer::prefetch`]), so that slow storage fetches it while the next pass is drawn: converged passes.
    pub prefetch_new_children: bool,
    /// Produce nodes whose data is still on its way ([`Producer::ready`] says no), waiting for it: converged frames
    /// do; interactive frames leave them to a later frame, so that a frame never waits on slow storage.
    pub wait_for_data: bool,
}

impl ServeOptions {
    /// Serve every request, nothing more.
    pub const ALL: ServeOptions = ServeOptions { limit: None, prefetch_new_children: false, wait_for_data: true };
}
