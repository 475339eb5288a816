//! Proving at open that every level array decodes as its metadata describes, so that `info` (which only opens the
//! store) fails exactly where `render` would.
//!
//! Opening a level's array checks that zarrs understands its `zarr.json`, not that the data decode: a codec, data
//! type, endianness or chunk-shape edit to a level's metadata passes the open and fails every brick read. Two
//! checks close that gap:
//!
//! - statically, every level array holds the store's sample type ([`check_level_dtype`]);
//! - by reading one brick of each level through the renderer's own read path ([`StoreReader::probe_levels`]): for a
//!   native store the first brick whose min/max says it holds data (so its bytes are on disk, and the samples are
//!   checked against the min/max, which catches an endianness edit), for a foreign store the level's central brick
//!   (a chunk absent there reads as the fill value and proves nothing more than the open did).
//!
//! A probe costs one brick per level (at most 20) and leaves it in the brick cache for the renderer. A damaged
//! shard elsewhere is still found only when a brick of it is needed (a warning and exit 3 in `render`).

use std::path::Path;

use zarrs::array::Array;
use zarrs::storage::ReadableStorageTraits;

use crate::error::StoreError;
use crate::level_source::LevelSource;
use crate::store_reader::StoreReader;
use crate::volume::DType;

/// The zarrs data type of samples of `dtype`.
fn zarr_data_type(dtype: DType) -> zarrs::array::DataType {
    match dtype {
        DType::U8 => zarrs::array::data_type::uint8(),
        DType::U16 => zarrs::array::data_type::uint16(),
        DType::I16 => zarrs::array::data_type::int16(),
        DType::F32 => zarrs::array::data_type::float32(),
    }
}

/// Refuses a level array (`name`, its path in the store) whose data type is not the store's `dtype`.
pub(crate) fn check_level_dtype(
    path: &Path,
    name: &str,
    array: &Array<dyn ReadableStorageTraits>,
    dtype: DType,
) -> Result<(), StoreError> {
    if *array.data_type() != zarr_data_type(dtype) {
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
    /// Reads one brick of every stored level (see the module docs); the first that fails is the error, naming the
    /// level.
    pub(crate) fn probe_levels(&self) -> Result<(), StoreError> {
        let layout = self.layout().clone();
        for level in 0..layout.levels() {
            if !matches!(self.level_source(level), Some(LevelSource::Array { .. })) {
                continue;
            }
            let bricks = layout.bricks(level);
            let probe =
                if self.is_native() { self.first_brick_with_data(level, bricks) } else { Some(bricks.map(|b| b / 2)) };
            let Some(ijk) = probe else { continue };
            let b = layout.brick_size;
            let dims = layout.level_dims[level];
            let lower = ijk.map(|v| v * b);
            let size = [0, 1, 2].map(|a| (lower[a] + b).min(dims[a]) - lower[a]);
            self.read_region(level, lower, size).map_err(|e| {
                let problem = match e {
                    StoreError::Store { message, .. } => message,
                    other => other.to_string(),
                };
                StoreError::store(
                    self.path(),
                    format!(
                        "level {level} does not decode as its zarr.json describes ({problem}); import the volume again"
                    ),
                )
            })?;
        }
        Ok(())
    }

    /// The first brick of `level` (x fastest) whose min/max is not `[0, 0]`: its bytes are on disk.
    fn first_brick_with_data(&self, level: usize, bricks: [u64; 3]) -> Option<[u64; 3]> {
        (0..bricks[2])
            .flat_map(|z| (0..bricks[1]).flat_map(move |y| (0..bricks[0]).map(move |x| [x, y, z])))
            .find(|&ijk| self.brick_range(level, ijk).is_some_and(|range| range != [0.0, 0.0]))
    }
}
