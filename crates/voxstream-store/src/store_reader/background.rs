//! Fetching ahead: bricks the cache manager defers are read into the brick cache in the background
//! ([`StoreReader::prefetch`]), and the frames of an interactive session over a remote store never wait on the
//! network ([`StoreReader::set_nonblocking`], [`StoreReader::region_ready`]) (Reichl's streaming supplier, seed 004
//! ch. 4).

use std::sync::{Arc, Mutex};

use super::StoreReader;

/// Bricks fetched behind the frames of an interactive session over a remote store.
#[derive(Default)]
pub(super) struct Background {
    /// Whether [`StoreReader::region_ready`] fetches in the background instead of answering "ready".
    pub(super) on: std::sync::atomic::AtomicBool,
    /// Threads fetching (as many as the remote store's concurrency).
    pub(super) pool: std::sync::OnceLock<Option<rayon::ThreadPool>>,
    /// Bricks being fetched.
    pub(super) fetching: Mutex<std::collections::HashSet<(usize, [u64; 3])>>,
    /// Bricks whose background fetch failed: produced in the foreground, which reports the failure.
    pub(super) failed: Mutex<std::collections::HashSet<(usize, [u64; 3])>>,
}

impl StoreReader {
    /// Sessions over a remote store: with `on`, [`StoreReader::region_ready`] starts fetching what is missing in
    /// the background and answers "not yet", so that interactive frames never wait on the network (converged
    /// frames do not ask: `ServeOptions::wait_for_data`). No effect on local stores.
    pub fn set_nonblocking(&self, on: bool) {
        self.background.on.store(on && self.remote.is_some(), std::sync::atomic::Ordering::Relaxed);
    }

    /// Whether the bricks of `[lower, lower + size)` of `level` can be read without waiting on the network: always
    /// for local stores and unless [`StoreReader::set_nonblocking`] is on; otherwise whether they are all in the
    /// cache (or known to hold only 0), the missing ones being fetched in the background when not.
    pub fn region_ready(self: &Arc<Self>, level: usize, lower: [u64; 3], size: [u64; 3]) -> bool {
        use std::sync::atomic::Ordering;
        if !self.background.on.load(Ordering::Relaxed) {
            return true;
        }
        let b = self.layout.brick_size;
        let first = lower.map(|v| v / b);
        let last = [0, 1, 2].map(|a| (lower[a] + size[a]).saturating_sub(1) / b);
        let mut missing = Vec::new();
        {
            let cache = self.brick_cache.lock().unwrap_or_else(|p| p.into_inner());
            for z in first[2]..=last[2] {
                for y in first[1]..=last[1] {
                    for x in first[0]..=last[0] {
                        let ijk = [x, y, z];
                        if !cache.contains(&(level, ijk)) && !self.holds_only_zero(level, ijk) {
                            missing.push(ijk);
                        }
                    }
                }
            }
        }
        if missing.is_empty() {
            return true;
        }
        let failed = self.background.failed.lock().unwrap_or_else(|p| p.into_inner());
        if missing.iter().any(|&ijk| failed.contains(&(level, ijk))) {
            return true;
        }
        drop(failed);
        // A region is fetched whole or not yet: started in the rays' order, regions complete one after another,
        // rather than every region of the frame getting a few of its bricks, which the cache would let go before the
        // rest arrive.
        let keys: Vec<(usize, [u64; 3])> = missing.into_iter().map(|ijk| (level, ijk)).collect();
        self.fetch_in_background(keys, true);
        false
    }

    /// Starts reading `bricks` on the remote store's fetch threads (each at most once at a time), so that no worker
    /// of the shared pool, which draws the frames, waits on the network; with `whole`, all of them or (when they
    /// would not fit under the bound of bricks in flight) none. Failures are remembered (see
    /// [`StoreReader::region_ready`]). Returns `false` when no thread could be made (nothing started).
    fn fetch_in_background(self: &Arc<Self>, bricks: Vec<(usize, [u64; 3])>, whole: bool) -> bool {
        let threads = self.remote.as_ref().map_or(1, |r| r.concurrency()).max(1);
        let pool = self.background.pool.get_or_init(|| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .thread_name(|i| format!("voxstream-prefetch-{i}"))
                .build()
                .ok()
        });
        let Some(pool) = pool.as_ref() else {
            return false;
        };
        // At most a quarter of the brick cache is fetched at a time: bricks fetched faster than frames use them
        // would push one another out of the cache before they are drawn.
        let capacity = self.brick_cache.lock().unwrap_or_else(|p| p.into_inner()).cap().get();
        let limit = (capacity / 4).max(1);
        let mut fetching = self.background.fetching.lock().unwrap_or_else(|p| p.into_inner());
        let new = bricks.iter().filter(|key| !fetching.contains(key)).count();
        if whole && !fetching.is_empty() && fetching.len() + new > limit {
            return true;
        }
        for key in bricks {
            if fetching.len() >= limit {
                break;
            }
            if fetching.insert(key) {
                let reader = Arc::clone(self);
                pool.spawn(move || {
                    if reader.brick(key.0, key.1).is_err() {
                        reader.background.failed.lock().unwrap_or_else(|p| p.into_inner()).insert(key);
                    }
                    reader.background.fetching.lock().unwrap_or_else(|p| p.into_inner()).remove(&key);
                });
            }
        }
        true
    }

    /// Reads `bricks` into the brick cache on a background worker (skipping those already cached or outside the
    /// level), at most one prefetch batch at a time; errors are left for `produce` to report.
    pub fn prefetch(self: &Arc<Self>, bricks: Vec<(usize, [u64; 3])>) {
        use std::sync::atomic::Ordering;
        // A remote store's bricks are fetched on its own threads, many at once: a worker of the shared pool waiting
        // on the network would hold up the frames drawn on it.
        if self.remote.is_some() {
            let cache = self.brick_cache.lock().unwrap_or_else(|p| p.into_inner());
            let wanted: Vec<(usize, [u64; 3])> = bricks
                .into_iter()
                .filter(|&(level, ijk)| {
                    let b = self.layout.bricks(level);
                    (0..3).all(|a| ijk[a] < b[a]) && !cache.contains(&(level, ijk)) && !self.holds_only_zero(level, ijk)
                })
                .collect();
            drop(cache);
            self.fetch_in_background(wanted, false);
            return;
        }
        if self.prefetching.swap(true, Ordering::AcqRel) {
            return;
        }
        let reader = Arc::clone(self);
        rayon::spawn(move || {
            for (level, ijk) in bricks {
                let b = reader.layout.bricks(level);
                let cached = reader.brick_cache.lock().unwrap_or_else(|p| p.into_inner()).contains(&(level, ijk));
                if !cached && (0..3).all(|a| ijk[a] < b[a]) {
                    let _ = reader.brick(level, ijk);
                }
            }
            reader.prefetching.store(false, Ordering::Release);
        });
    }
}
