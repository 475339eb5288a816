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
    /// Bricks whose background fetch failed: produced in the foreground, which reports the failure. An entry
    /// leaves the set as soon as a read of its brick succeeds (the foreground read from the store, or a later
    /// background fetch; see [`Background::forget_failure`]), so that a transient fault does not send the brick to
    /// the foreground for the rest of the session once the cache lets it go again.
    pub(super) failed: Mutex<std::collections::HashSet<(usize, [u64; 3])>>,
    /// Whether `failed` holds entries (changed only under its lock): while it is empty, reads and
    /// [`StoreReader::region_ready`] take no lock for it.
    pub(super) any_failed: std::sync::atomic::AtomicBool,
}

impl Background {
    /// Remembers that the background fetch of `key` failed.
    fn note_failure(&self, key: (usize, [u64; 3])) {
        let mut failed = self.failed.lock().unwrap_or_else(|p| p.into_inner());
        failed.insert(key);
        self.any_failed.store(true, std::sync::atomic::Ordering::Release);
    }

    /// A read of `key` succeeded: it leaves `failed`, so that [`StoreReader::region_ready`] fetches it in the
    /// background again once the cache lets it go. Takes no lock while `failed` is empty.
    pub(super) fn forget_failure(&self, key: (usize, [u64; 3])) {
        use std::sync::atomic::Ordering;
        if !self.any_failed.load(Ordering::Acquire) {
            return;
        }
        let mut failed = self.failed.lock().unwrap_or_else(|p| p.into_inner());
        if failed.remove(&key) && failed.is_empty() {
            self.any_failed.store(false, Ordering::Release);
        }
    }
}

/// Calls `work` on every item, from up to `threads` plain threads (each taking the next item), and returns when all
/// are done: for reads that wait on a network, where a rayon worker would steal other work while it waits.
pub(super) fn on_plain_threads<T: Sync>(items: &[T], threads: usize, work: impl Fn(&T) + Sync) {
    let next = std::sync::atomic::AtomicUsize::new(0);
    std::thread::scope(|scope| {
        for _ in 0..threads.clamp(1, items.len().max(1)) {
            scope.spawn(|| {
                while let Some(item) = items.get(next.fetch_add(1, std::sync::atomic::Ordering::Relaxed)) {
                    work(item);
                }
            });
        }
    });
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
        let mut missing = Vec::new();
        {
            let cache = self.brick_cache.lock().unwrap_or_else(|p| p.into_inner());
            self.uncached_bricks(&cache, level, lower, size, |ijk| missing.push(ijk));
        }
        if missing.is_empty() {
            return true;
        }
        // A brick whose background fetch failed (and that no read has got since) is produced in the foreground,
        // which reports the failure if it persists.
        if self.background.any_failed.load(Ordering::Acquire) {
            let failed = self.background.failed.lock().unwrap_or_else(|p| p.into_inner());
            if missing.iter().any(|&ijk| failed.contains(&(level, ijk))) {
                return true;
            }
        }
        // A region is fetched whole or not yet: started in the rays' order, regions complete one after another,
        // rather than every region of the frame getting a few of its bricks, which the cache would let go before the
        // rest arrive.
        let keys: Vec<(usize, [u64; 3])> = missing.into_iter().map(|ijk| (level, ijk)).collect();
        self.fetch_in_background(keys, true);
        false
    }

    /// Remote stores: brings every brick that these regions `(level, lower, size)` overlap within reach, and returns
    /// when all are there or have failed (failures are left to the read that needs the brick, which reports them).
    /// A native store's bricks come as byte ranges of their shards into the compressed-brick cache, abutting ones
    /// in one request (`fetch_bricks_by_range`); the others are read into the brick cache on `--concurrent-requests`
    /// plain threads. Reading region by region instead waits a round trip for each region's few uncached bricks in
    /// turn. Local stores: nothing (their reads do not wait on a network).
    pub fn fetch_regions(&self, regions: &[(usize, [u64; 3], [u64; 3])]) {
        if self.remote.is_none() {
            return;
        }
        let mut wanted = std::collections::BTreeSet::new();
        {
            let cache = self.brick_cache.lock().unwrap_or_else(|p| p.into_inner());
            for &(level, lower, size) in regions {
                self.uncached_bricks(&cache, level, lower, size, |ijk| {
                    wanted.insert((level, ijk));
                });
            }
        }
        // A native store's bricks as byte ranges of their shards, abutting ones in one request; the rest one by one
        // on plain threads: a rayon worker blocked on a round trip would steal other work while it waits and chain
        // the waits of unrelated reads.
        let wanted = self.fetch_bricks_by_range(wanted.into_iter().collect());
        let threads = self.remote.as_ref().map_or(1, |r| r.concurrency());
        on_plain_threads(&wanted, threads, |&(level, ijk)| {
            let _ = self.brick(level, ijk);
        });
    }

    /// Calls `found` with each brick of `[lower, lower + size)` of `level` that `cache` lacks and whose min/max does
    /// not say it holds only 0 (none for an empty region).
    fn uncached_bricks(
        &self,
        cache: &lru::LruCache<(usize, [u64; 3]), Arc<super::decoded_brick::DecodedBrick>>,
        level: usize,
        lower: [u64; 3],
        size: [u64; 3],
        mut found: impl FnMut([u64; 3]),
    ) {
        if size.contains(&0) {
            return;
        }
        let b = self.layout.brick_size;
        let first = lower.map(|v| v / b);
        let last = [0, 1, 2].map(|a| (lower[a] + size[a] - 1) / b);
        for z in first[2]..=last[2] {
            for y in first[1]..=last[1] {
                for x in first[0]..=last[0] {
                    let ijk = [x, y, z];
                    if !cache.contains(&(level, ijk)) && !self.holds_only_zero(level, ijk) {
                        found(ijk);
                    }
                }
            }
        }
    }

    /// Starts reading `bricks` on the remote store's fetch threads (each at most once at a time), so that no worker
    /// of the shared pool, which draws the frames, waits on the network; with `whole`, all of them or (when they
    /// would not fit under the bound of bricks in flight) none. Failures are remembered (see
    /// [`StoreReader::region_ready`]) until a read of the brick succeeds. Returns `false` when no thread could be
    /// made (nothing started).
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
        let mut started = Vec::new();
        for key in bricks {
            if fetching.len() >= limit {
                break;
            }
            if fetching.insert(key) {
                started.push(key);
            }
        }
        if started.is_empty() {
            return true;
        }
        // A native store's bricks as byte ranges of their shards first (abutting ones in one request), then each
        // brick decoded (or, where that could not take it, read) on a thread of its own.
        let reader = Arc::clone(self);
        pool.spawn(move || {
            reader.fetch_bricks_by_range(started.clone());
            for key in started {
                let reader = Arc::clone(&reader);
                rayon::spawn(move || {
                    match reader.brick(key.0, key.1) {
                        Ok(_) => reader.background.forget_failure(key),
                        Err(_) => reader.background.note_failure(key),
                    }
                    reader.background.fetching.lock().unwrap_or_else(|p| p.into_inner()).remove(&key);
                });
            }
        });
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

#[cfg(test)]
mod tests {
    use std::sync::Arc;
    use std::time::Duration;

    use crate::import::{import_volume, ImportOptions};
    use crate::store_reader::StoreReader;
    use crate::volume::{DType, VolumeInfo, VolumeSource};

    /// 16×16×8 u16 samples in 100..150 (no brick holds only 0): bricks of 8, two by two per shard.
    struct Ramp {
        info: VolumeInfo,
        z: u64,
    }

    impl VolumeSource for Ramp {
        fn info(&self) -> &VolumeInfo {
            &self.info
        }

        fn read_slices(&mut self, count: usize, out: &mut Vec<f32>) -> Result<(), crate::StoreError> {
            let [nx, ny, _] = self.info.dims;
            for z in self.z..self.z + count as u64 {
                for i in 0..nx * ny {
                    out.push((100 + (i + z * 7) % 50) as f32);
                }
            }
            self.z += count as u64;
            Ok(())
        }
    }

    /// Polls `done` every 10 ms for at most 30 s (a bound on a background read of one small brick, generous for
    /// a loaded machine); whether it came true.
    fn eventually(mut done: impl FnMut() -> bool) -> bool {
        for _ in 0..3000 {
            if done() {
                return true;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        done()
    }

    #[test]
    fn a_brick_read_after_a_failed_background_fetch_is_fetched_in_the_background_again() {
        let dir = std::env::temp_dir().join(format!("voxstream-background-failed-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let store = dir.join("ramp.zarr");
        let info = VolumeInfo {
            dims: [16, 16, 8],
            dtype: DType::U16,
            spacing: [1.0; 3],
            origin: [0.0; 3],
            unit: None,
            orientation: None,
        };
        let mut source = Ramp { info, z: 0 };
        let options = ImportOptions { brick_size: 8, shard_bricks: 2, ..ImportOptions::default() };
        import_volume(&mut source, &store, &options, &mut |_, _| {}).unwrap();
        let reader = Arc::new(StoreReader::open(&store).unwrap());
        // `set_nonblocking` turns on for remote stores only: a local one stands in for it here.
        reader.background.on.store(true, std::sync::atomic::Ordering::Relaxed);

        // Brick (1, 0, 0) of level 0 (not read yet, so cached nowhere) lies in the shard of bricks (0..2, 0..2, 0):
        // without it the read fails (its min/max says it holds data).
        let key = (0, [1, 0, 0]);
        let (lower, size) = ([8, 0, 0], [8, 8, 8]);
        let shard = store.join("0/c/0/0/0");
        let bytes = std::fs::read(&shard).unwrap();
        std::fs::remove_file(&shard).unwrap();

        assert!(!reader.region_ready(0, lower, size), "a missing brick is fetched in the background first");
        let background = &reader.background;
        let finished = eventually(|| !background.fetching.lock().unwrap().contains(&key));
        assert!(finished, "the background fetch did not finish");
        assert!(background.failed.lock().unwrap().contains(&key), "the failed fetch is remembered");
        assert!(reader.region_ready(0, lower, size), "a brick whose fetch failed is produced in the foreground");
        assert!(reader.brick(key.0, key.1).is_err(), "the foreground read reports the failure");
        assert!(background.failed.lock().unwrap().contains(&key), "a failed read leaves it in the set");

        // The fault passes: a foreground read succeeds, and the brick leaves the set.
        std::fs::write(&shard, &bytes).unwrap();
        assert!(reader.brick(key.0, key.1).is_ok(), "the repaired brick reads");
        assert!(!background.failed.lock().unwrap().contains(&key), "a successful read clears the failure");

        // Once the cache lets the brick go, it is fetched in the background again, not in the foreground.
        assert!(reader.brick_cache.lock().unwrap().pop(&key).is_some(), "the brick was cached");
        assert!(!reader.region_ready(0, lower, size), "the brick is fetched in the background again");
        let finished = eventually(|| reader.brick_cache.lock().unwrap().contains(&key));
        assert!(finished, "the background fetch did not bring the brick");
        assert!(reader.region_ready(0, lower, size), "the fetched brick is ready");
        assert!(!background.failed.lock().unwrap().contains(&key));

        let _ = std::fs::remove_dir_all(&dir);
    }
}
