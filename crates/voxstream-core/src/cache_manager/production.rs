//! Production: a batch of work produced on worker threads (rayon, or the producer's own I/O threads) with no lock
//! held, then applied by the calling thread in queue order, so that the final pools do not depend on scheduling.
//! GigaVoxels [P09] §5 and the producer side of [R08] §4.

use crate::error::ProduceError;
use crate::feedback::{Request, RequestKind};
use crate::key::NodeKey;
use crate::node::TileId;
use crate::producer::Producer;

use super::analysis::{produce_analysed, AnalysedBrick};
use super::space_order::in_space_order;
use super::tree_updates::Eviction;
use super::{CacheManager, ServeReport};

/// One step to serve: a ray's request, or a forced step of the restriction.
#[derive(Clone, Copy)]
pub(super) struct Work {
    pub(super) request: Request,
    pub(super) key: NodeKey,
    pub(super) forced: bool,
}

/// Runs `produce` (a batch) on the producer's own pool where it has one, else on the calling thread. With `fetch`,
/// a producer on a network brings in data while the batch is produced (see [`Producer::fetch`]): first `this` (the
/// batch's own keys, when nothing fetched them yet), then `next` (the following batch's) at the same time as the
/// batch is produced, so that its round trips overlap this batch's decoding instead of following it.
pub(super) fn produce_fetching<P: Producer, T: Send>(
    producer: &P,
    pool: Option<&rayon::ThreadPool>,
    fetch: bool,
    this: Option<&[NodeKey]>,
    next: &[NodeKey],
    produce: impl FnOnce() -> T + Send,
) -> T {
    let Some(pool) = pool else {
        return produce();
    };
    if !fetch {
        return pool.install(produce);
    }
    if let Some(this) = this.filter(|keys| !keys.is_empty()) {
        producer.fetch(this);
    }
    if next.is_empty() {
        return pool.install(produce);
    }
    std::thread::scope(|scope| {
        scope.spawn(|| producer.fetch(next));
        pool.install(produce)
    })
}

/// The keys of `work` whose data a batch would read (productions that are not premature).
fn produced_keys(work: &[Work], premature: impl Fn(&Work) -> bool) -> Vec<NodeKey> {
    work.iter()
        .filter(|item| item.request.kind == RequestKind::Produce && !premature(item))
        .map(|item| item.key)
        .collect()
}

pub(super) enum WorkResult {
    Produced(Result<AnalysedBrick, ProduceError>),
    Children(Vec<Option<f32>>),
    /// Not done: producing it would break the restricted working set.
    Premature,
}

impl<P: Producer> CacheManager<P> {
    /// Produces and subdivides `work` on worker threads, with no lock held, a batch at a time so that
    /// produced-but-unapplied bricks stay a bounded transient; applies each batch in order. What cannot be applied
    /// (no room, or the restriction no longer allows it) is counted deferred, and the rays' own requests among it
    /// go to `unserved`.
    pub(super) fn serve(
        &mut self,
        work: &[Work],
        report: &mut ServeReport,
        new_tiles: &mut Vec<(TileId, NodeKey)>,
        unserved: &mut Vec<(Request, NodeKey)>,
    ) {
        let batch_size = self.capacities.production_batch.max(1) as usize;
        for (index, batch) in work.chunks(batch_size).enumerate() {
            // Under the restriction, what is premature already is not produced at all.
            let premature: Vec<bool> = batch.iter().map(|item| self.is_premature(item.request, item.key)).collect();
            let producer = &self.producer;
            let wait = self.wait_for_data;
            let (shape, format) = (self.shape, self.brick_pool.format());
            let produce_batch = || {
                in_space_order(
                    batch,
                    |item| item.key,
                    &shape,
                    |index| {
                        let item = &batch[index];
                        match item.request.kind {
                            _ if premature[index] => WorkResult::Premature,
                            // Data still on its way: asked again next frame, the frame does not wait for it.
                            RequestKind::Produce if !wait && !producer.ready(item.key) => WorkResult::Premature,
                            RequestKind::Produce => {
                                WorkResult::Produced(produce_analysed(producer, item.key, &shape, format))
                            }
                            RequestKind::Subdivide => WorkResult::Children(
                                (0..shape.nodes_per_tile())
                                    .map(|c| producer.oracle(item.key.child(c, shape.n)))
                                    .collect(),
                            ),
                        }
                    },
                )
            };
            // A producer on a network fetches the first batch's data, then each next batch's while one is produced.
            let this = (index == 0).then(|| {
                batch
                    .iter()
                    .zip(&premature)
                    .filter(|(item, &premature)| item.request.kind == RequestKind::Produce && !premature)
                    .map(|(item, _)| item.key)
                    .collect::<Vec<_>>()
            });
            let next = work.get((index + 1) * batch_size..).map_or(&[][..], |rest| &rest[..rest.len().min(batch_size)]);
            let next =
                if wait { produced_keys(next, |item| self.is_premature(item.request, item.key)) } else { vec![] };
            let results: Vec<WorkResult> =
                produce_fetching(producer, self.io_pool.as_ref(), wait, this.as_deref(), &next, produce_batch);
            for (item, result) in batch.iter().zip(results) {
                let (request, key) = (item.request, item.key);
                // A forced step served earlier in the batch, or a recycled tile, may have made it moot; under the
                // restriction, an eviction earlier in the batch may have made it premature.
                if !self.still_wanted(request, key) {
                    continue;
                }
                let applied = !self.is_premature(request, key)
                    && match result {
                        WorkResult::Premature => false,
                        WorkResult::Produced(Ok(brick)) => {
                            self.apply_produced(request.node, brick, Eviction::Allowed, report)
                        }
                        WorkResult::Produced(Err(error)) => {
                            self.failed.insert(key);
                            report.failures.push(error);
                            true
                        }
                        WorkResult::Children(hints) => match self.apply_subdivide(request.node, &hints, report) {
                            Some(tile) => {
                                new_tiles.push((tile, key));
                                true
                            }
                            None => false,
                        },
                    };
                if applied {
                    report.served += 1;
                    report.forced += usize::from(item.forced);
                } else if !item.forced {
                    report.deferred += 1;
                    unserved.push((request, key));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_support::Ramp;
    use super::*;
    use crate::key::TreeShape;
    use crate::node::NodeId;
    use crate::producer::Produced;
    use crate::ServeOptions;

    /// [`Ramp`], whose data is never ready before it is waited for.
    struct Slow;
    impl Producer for Slow {
        fn shape(&self) -> TreeShape {
            Ramp.shape()
        }
        fn produce(&self, key: NodeKey, voxels: &mut [u16]) -> Result<Produced, ProduceError> {
            Ramp.produce(key, voxels)
        }
        fn ready(&self, _: NodeKey) -> bool {
            false
        }
    }

    /// [`Ramp`] on "a network": its own pool of threads, and a record of what was fetched and what was produced
    /// without having been fetched first.
    #[derive(Default)]
    struct Fetching {
        fetched: std::sync::Mutex<Vec<Vec<NodeKey>>>,
        unfetched: std::sync::Mutex<Vec<NodeKey>>,
    }
    impl Producer for Fetching {
        fn shape(&self) -> TreeShape {
            Ramp.shape()
        }
        fn oracle(&self, key: NodeKey) -> Option<f32> {
            Ramp.oracle(key)
        }
        fn produce(&self, key: NodeKey, voxels: &mut [u16]) -> Result<Produced, ProduceError> {
            if !self.fetched.lock().unwrap().iter().flatten().any(|&k| k == key) {
                self.unfetched.lock().unwrap().push(key);
            }
            Ramp.produce(key, voxels)
        }
        fn concurrency(&self) -> usize {
            4
        }
        fn fetch(&self, keys: &[NodeKey]) {
            self.fetched.lock().unwrap().push(keys.to_vec());
        }
    }

    #[test]
    fn a_producer_on_a_network_fetches_each_batch_before_it_is_produced_and_only_when_frames_wait() {
        // A budget whose production batches are 3 bricks: the root's 7 non-constant children take 3 batches.
        let mut cache = CacheManager::new(Fetching::default(), 100_000).unwrap();
        assert_eq!(cache.capacities().production_batch, 3);
        let serve = |cache: &mut CacheManager<Fetching>, kind, wait_for_data| {
            cache.begin_frame();
            cache.feedback().push_requests(&[Request { node: NodeId::ROOT, kind, deficit: 1 }]);
            cache.end_frame(ServeOptions { limit: None, prefetch_new_children: true, wait_for_data })
        };
        // A frame that does not wait fetches nothing (its producer fetches in the background, see `ready`).
        serve(&mut cache, RequestKind::Produce, false);
        assert!(cache.producer().fetched.lock().unwrap().is_empty());
        cache.producer().unfetched.lock().unwrap().clear();
        let report = serve(&mut cache, RequestKind::Subdivide, true);
        assert_eq!(report.bricks_prefetched, 7, "{report:?}");
        let producer = cache.producer();
        assert_eq!(producer.unfetched.lock().unwrap().as_slice(), &[], "produced before it was fetched");
        // The first batch, then each next one while the one before is produced.
        let batches: Vec<usize> = producer.fetched.lock().unwrap().iter().map(|keys| keys.len()).collect();
        assert_eq!(batches, [3, 3, 1], "{batches:?}");
    }

    #[test]
    fn data_still_on_its_way_is_produced_only_by_frames_that_wait_for_it() {
        let mut cache = CacheManager::new(Slow, 16 << 20).unwrap();
        for wait_for_data in [false, true] {
            cache.begin_frame();
            cache.feedback().push_requests(&[Request { node: NodeId::ROOT, kind: RequestKind::Produce, deficit: 1 }]);
            let report = cache.end_frame(ServeOptions { limit: None, prefetch_new_children: false, wait_for_data });
            assert_eq!((report.served, report.deferred), if wait_for_data { (1, 0) } else { (0, 1) });
        }
        assert!(cache.node_pool().node(NodeId::ROOT).brick().is_some());
    }
}
