//! Proving at open that every level array decodes as its metadata describes, so that `info` (which only opens the
//! store) fails exactly where `render` would.
//!
//! Opening a level's array checks that zarrs understands its `zarr.json`, not that the data decode: a codec, data
//! type, endianness or chunk-shape edit to a level's metadata passes the open and fails every brick read. Two
//! checks close that gap:
//!
//! - statically, every level array holds the store's sample type ([`check_level_dtype`]);
//! - by reading bricks of each level through the renderer's own read path (`StoreReader::probe_levels`): for a
//!   native store the first, middle and last bricks whose min/max says they hold data (so their bytes are on disk,
//!   and the samples are checked against the min/max, which catches an endianness edit), for a foreign store the
//!   level's central brick (a chunk absent there reads as the fill value and proves nothing more than the open did).
//!   The level is refused only when none of its probes reads: a metadata edit breaks every brick, while a damaged
//!   shard breaks only its own, and is still reported when a brick of it is needed (a warning and exit 3 in
//!   `render`).
//!
//! Probing costs at most three bricks per level (at most 20 levels), left in the brick cache for the renderer.

use std::path::Path;

use zarrs::array::Array;
use zarrs::storage::ReadableStorageTraits;

use crate::error::StoreError;
use crate::level_source::LevelSource;
use crate::store_reader::StoreReader;
use crate::volume::DType;

/// Bricks read per native level at open: a level is refused only when none of them reads, since an edit to its
/// metadata breaks every brick, while damage to one shard (reported when rendering) breaks only some.
pub const PROBES_PER_LEVEL: usize = 3;

/// Refuses a level array (`name`, its path in the store) whose data type is not the store's `dtype`.
pub(crate) fn check_level_dtype(
    path: &Path,
    name: &str,
    array: &Array<dyn ReadableStorageTraits>,
    dtype: DType,
) -> Result<(), StoreError> {
    if *array.data_type() != dtype.zarr_data_type() {
        return Err(StoreError::store(
            path,
            format!(
                "level array '{name}' holds {} samples, but the store's are {}: its zarr.json was edited or the \
                 store is mixed; import the volume again",
                array.data_type(),
                dtype.name()
            ),
        ));
    }
    Ok(())
}

impl StoreReader {
    /// Reads bricks of every stored level (see the module docs); a level none of whose probed bricks reads is the
    /// error, naming the level and the first failure.
    pub(crate) fn probe_levels(&self) -> Result<(), StoreError> {
        let levels = self.layout().levels();
        // A remote store's levels are probed at once (a round trip or two each); a folder's in turn. The first
        // level that fails, in level order, is reported either way.
        let results: Vec<Result<(), StoreError>> = if self.remote().is_some() {
            std::thread::scope(|scope| {
                let handles: Vec<_> = (0..levels).map(|level| scope.spawn(move || self.probe_level(level))).collect();
                handles
                    .into_iter()
                    .map(|h| h.join().unwrap_or_else(|_| Err(StoreError::store(self.path(), "a level probe panicked"))))
                    .collect()
            })
        } else {
            (0..levels).map(|level| self.probe_level(level)).collect()
        };
        results.into_iter().collect()
    }

    /// Probes one level (see [`StoreReader::probe_levels`]).
    fn probe_level(&self, level: usize) -> Result<(), StoreError> {
        let layout = self.layout();
        if !matches!(self.level_source(level), Some(LevelSource::Array { .. })) {
            return Ok(());
        }
        let probes =
            if self.is_native() { self.bricks_with_data(level) } else { vec![layout.bricks(level).map(|b| b / 2)] };
        let mut first_error = None;
        for ijk in probes {
            let b = layout.brick_size;
            let dims = layout.level_dims[level];
            let lower = ijk.map(|v| v * b);
            let size = [0, 1, 2].map(|a| (lower[a] + b).min(dims[a]) - lower[a]);
            match self.read_region(level, lower, size) {
                Ok(_) => {
                    first_error = None;
                    break;
                }
                Err(e) => {
                    first_error.get_or_insert(e);
                }
            }
        }
        match first_error {
            Some(e) => {
                let problem = match e {
                    StoreError::Store { message, .. } => message,
                    other => other.to_string(),
                };
                Err(StoreError::store(
                    self.path(),
                    format!(
                        "level {level} does not decode as its zarr.json describes ({problem}); import the volume \
                         again"
                    ),
                ))
            }
            None => Ok(()),
        }
    }

    /// Up to [`PROBES_PER_LEVEL`] bricks of a native `level` whose min/max is not `[0, 0]` (so their bytes are on
    /// disk), spread over the level: the first, the middle and the last such brick, x fastest.
    fn bricks_with_data(&self, level: usize) -> Vec<[u64; 3]> {
        let bricks = self.layout().bricks(level);
        let with_data = || {
            (0..bricks[2])
                .flat_map(move |z| (0..bricks[1]).flat_map(move |y| (0..bricks[0]).map(move |x| [x, y, z])))
                .filter(move |&ijk| self.brick_range(level, ijk).is_some_and(|range| range != [0.0, 0.0]))
        };
        let count = with_data().count();
        let mut picks: Vec<usize> =
            (0..PROBES_PER_LEVEL).map(|i| i * count.saturating_sub(1) / (PROBES_PER_LEVEL - 1)).collect();
        picks.dedup();
        picks.retain(|&n| n < count);
        picks.iter().filter_map(|&n| with_data().nth(n)).collect()
    }
}
