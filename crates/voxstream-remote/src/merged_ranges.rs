//! Many byte ranges fetched at once, those that abut in a value merged into one request (issue 43: "adjacent ranges
//! of a shard merged where that saves round trips"). A shard stores its bricks one after another, so the bricks of a
//! view that neighbour each other in a shard's row are one request instead of one each; the requests of every value
//! asked for are in flight together, up to the store's concurrency (one bound shared by every call at once), on its
//! client's runtime (no thread waits per request).
//!
//! Each range asked for is answered with exactly its own bytes (cut from the merged body), or its error; a merged
//! request that fails fails only the ranges it held. Ranges already in the disk cache are not fetched, and every
//! range fetched is kept there under its own name, as a single read of it would be, so that a later run finds it
//! however the ranges were grouped then.

use std::ops::Range;

use bytes::Bytes;
use futures::StreamExt;
use object_store::GetRange;
use zarrs_storage::StorageError;

use crate::remote_store::{Fetched, RemoteStore};

/// The longest one merged request may be: long enough for a shard's whole row of bricks, short enough that a
/// failure and its retry cost little.
pub const MAX_MERGED_BYTES: u64 = 4 << 20;

/// Runs of `ranges` that abut (each starts where the one before ends), in order of their starts, each at most
/// `max_bytes` long unless one range alone is longer: the span of each run and the indices into `ranges` it covers.
/// Empty ranges and ranges that overlap another are runs of their own.
pub fn merge_runs(ranges: &[Range<u64>], max_bytes: u64) -> Vec<(Range<u64>, Vec<usize>)> {
    let mut order: Vec<usize> = (0..ranges.len()).collect();
    order.sort_by_key(|&i| (ranges[i].start, ranges[i].end));
    let mut runs: Vec<(Range<u64>, Vec<usize>)> = Vec::new();
    for i in order {
        let range = ranges[i].clone();
        if let Some((span, members)) = runs.last_mut() {
            let abuts = !range.is_empty() && span.end == range.start && !span.is_empty();
            if abuts && range.end - span.start <= max_bytes {
                span.end = range.end;
                members.push(i);
                continue;
            }
        }
        runs.push((range, vec![i]));
    }
    runs
}

/// A merged request answered: the value it was for, its span, the ranges it held, and what came back.
type Answered = (usize, Range<u64>, Vec<usize>, Result<Fetched, StorageError>);

impl RemoteStore {
    /// Fetches the byte ranges `wanted` asks for, per value (a key and its ranges): abutting ranges of a value in
    /// one request, all requests at once up to [`RemoteStore::concurrency`]. Returns, per value, `Ok(None)` where the
    /// value is not there, else each range's bytes or the error of the request that held it. A range whose end
    /// overflows is an error of its own; an empty range is answered with no bytes and no request.
    pub fn get_ranges(&self, wanted: &[(String, Vec<Range<u64>>)]) -> Vec<Result<Option<Vec<Bytes>>, StorageError>> {
        let mut answers: Vec<Vec<Option<Result<Bytes, StorageError>>>> =
            wanted.iter().map(|(_, ranges)| (0..ranges.len()).map(|_| None).collect()).collect();
        let mut requests = Vec::new();
        for (value, (key, ranges)) in wanted.iter().enumerate() {
            let mut to_fetch = Vec::new();
            for (index, range) in ranges.iter().enumerate() {
                let answer = &mut answers[value][index];
                if range.start > range.end {
                    *answer = Some(Err(self.error(key, format!("byte range {range:?} ends before it starts"))));
                } else if range.is_empty() {
                    *answer = Some(Ok(Bytes::new()));
                } else if let Some(bytes) = self.cached_on_disk(key, &Some(GetRange::Bounded(range.clone()))) {
                    *answer = Some(Ok(bytes));
                } else {
                    to_fetch.push(index);
                }
            }
            let spans: Vec<Range<u64>> = to_fetch.iter().map(|&i| ranges[i].clone()).collect();
            for (span, members) in merge_runs(&spans, MAX_MERGED_BYTES) {
                requests.push((value, span, members.into_iter().map(|m| to_fetch[m]).collect::<Vec<usize>>()));
            }
        }
        let deadline = self.deadline();
        let concurrency = self.concurrency().max(1);
        let fetched: Vec<Answered> = self.runtime.block_on(
            futures::stream::iter(requests)
                .map(|(value, span, members)| async move {
                    let key = wanted[value].0.as_str();
                    // Every call's requests share the store's bound (calls from several threads at once).
                    let _permit = self.permits.acquire().await;
                    let limit = span.end - span.start;
                    let fetch = self.fetch_uncached(key, Some(GetRange::Bounded(span.clone())), limit);
                    let result = match tokio::time::timeout(deadline, fetch).await {
                        Ok(result) => result,
                        Err(_) => Err(self.error(key, format!("no answer within {} s", deadline.as_secs()))),
                    };
                    (value, span, members, result)
                })
                .buffer_unordered(concurrency)
                .collect(),
        );
        let mut missing = vec![false; wanted.len()];
        for (value, span, members, result) in fetched {
            let (key, ranges) = &wanted[value];
            for index in members {
                let range = &ranges[index];
                answers[value][index] = Some(match &result {
                    Ok(Fetched::Bytes(body)) => {
                        let (from, to) = ((range.start - span.start) as usize, (range.end - span.start) as usize);
                        let bytes = body.slice(from..to);
                        self.keep_on_disk(key, &Some(GetRange::Bounded(range.clone())), &bytes);
                        Ok(bytes)
                    }
                    Ok(Fetched::Missing) => {
                        missing[value] = true;
                        Ok(Bytes::new())
                    }
                    Err(e) => Err(StorageError::Other(e.to_string())),
                });
            }
        }
        answers
            .into_iter()
            .zip(missing)
            .map(|(answers, missing)| {
                if missing {
                    return Ok(None);
                }
                let answers: Result<Vec<Bytes>, StorageError> =
                    answers.into_iter().map(|a| a.unwrap_or_else(|| Ok(Bytes::new()))).collect();
                answers.map(Some)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn abutting_ranges_merge_in_order_of_their_starts_up_to_the_bound() {
        // Given out of order: 10..20 and 20..25 abut, 0..10 abuts 10..20 too; 30..40 stands apart.
        let ranges = [10..20, 30..40, 0..10, 20..25];
        assert_eq!(merge_runs(&ranges, 100), vec![(0..25, vec![2, 0, 3]), (30..40, vec![1])]);
        // The bound splits a run where adding the next range would pass it.
        assert_eq!(merge_runs(&ranges, 20), vec![(0..20, vec![2, 0]), (20..25, vec![3]), (30..40, vec![1])]);
        // A range longer than the bound is a run of its own.
        assert_eq!(merge_runs(&[0..50, 50..60], 20), vec![(0..50, vec![0]), (50..60, vec![1])]);
    }

    #[test]
    fn overlapping_and_empty_ranges_are_never_merged() {
        assert_eq!(merge_runs(&[0..10, 5..15], 100), vec![(0..10, vec![0]), (5..15, vec![1])]);
        assert_eq!(
            merge_runs(&[0..10, 10..10, 10..20], 100),
            vec![(0..10, vec![0]), (10..10, vec![1]), (10..20, vec![2])]
        );
    }
}
