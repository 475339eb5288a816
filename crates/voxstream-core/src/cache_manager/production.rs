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
        for batch in work.chunks(self.capacities.production_batch.max(1) as usize) {
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
            let results: Vec<WorkResult> = match &self.io_pool {
                Some(pool) => pool.install(produce_batch),
                None => produce_batch(),
            };
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
