//! One read at a time per key: threads that want the same brick (or shard index) while it is being read wait for
//! that read instead of starting their own, then find it in the cache it went into.
//!
//! Neighbouring nodes produced at once need the same bricks for their borders; from a local disk a duplicate read
//! costs a little time, over a network it costs a round trip and the bytes again (issue 43: no byte fetched twice).

use std::collections::HashMap;
use std::hash::Hash;
use std::sync::{Arc, Mutex};

/// The lock of one key, and the thread holding it.
type Turn = Arc<(Mutex<()>, Mutex<Option<std::thread::ThreadId>>)>;

/// Keys being worked on, each with the lock its workers take in turn.
#[derive(Debug, Default)]
pub struct SingleFlight<K> {
    working: Mutex<HashMap<K, Turn>>,
}

impl<K: Hash + Eq + Clone> SingleFlight<K> {
    /// An empty set.
    pub fn new() -> SingleFlight<K> {
        SingleFlight { working: Mutex::new(HashMap::new()) }
    }

    /// Runs `work` for `key` once no other thread is running work for the same key: `work` should look in the
    /// cache first (a thread that waited finds what the first one read there).
    pub fn run<T>(&self, key: &K, work: impl FnOnce() -> T) -> T {
        let lock = || self.working.lock().unwrap_or_else(|p| p.into_inner());
        let cell = lock().entry(key.clone()).or_default().clone();
        let me = std::thread::current().id();
        let holder = |cell: &Turn| cell.1.lock().map(|h| *h).unwrap_or(None);
        // A worker thread that took this key and, waiting inside its own work, was handed another job needing the
        // same key (rayon's work stealing) reads it itself rather than wait for itself.
        let result = if holder(&cell) == Some(me) {
            work()
        } else {
            let _turn = cell.0.lock().unwrap_or_else(|p| p.into_inner());
            *cell.1.lock().unwrap_or_else(|p| p.into_inner()) = Some(me);
            let result = work();
            *cell.1.lock().unwrap_or_else(|p| p.into_inner()) = None;
            result
        };
        let mut working = lock();
        // The map's handle and ours: nobody else waits, the key is done.
        if Arc::strong_count(&cell) == 2 {
            working.remove(key);
        }
        result
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};

    #[test]
    fn concurrent_requests_for_one_key_do_the_work_once() {
        let flight = SingleFlight::new();
        let done = Mutex::new(false);
        let reads = AtomicUsize::new(0);
        std::thread::scope(|scope| {
            for _ in 0..8 {
                scope.spawn(|| {
                    flight.run(&7u32, || {
                        let mut cached = done.lock().unwrap();
                        if !*cached {
                            reads.fetch_add(1, Ordering::SeqCst);
                            std::thread::sleep(std::time::Duration::from_millis(20));
                            *cached = true;
                        }
                    })
                });
            }
        });
        assert_eq!(reads.load(Ordering::SeqCst), 1);
        assert!(flight.working.lock().unwrap().is_empty(), "finished keys are forgotten");
    }
}
