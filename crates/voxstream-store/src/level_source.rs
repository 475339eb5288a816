//! Where the samples of one pyramid level come from, and reading them as f32: the concept shared by the store reader
//! (which reads bricks through it) and the foreign-image opener (which maps foreign datasets onto it).
//!
//! Both [`crate::store_reader`] and [`crate::foreign`] depend on this module, and it depends on neither, so the
//! read side's module graph stays a DAG: `level_source ← foreign ← store_reader`.

use zarrs::array::{Array, ArraySubset};
use zarrs::storage::ReadableStorageTraits;

use crate::image_planes::LeadingIndex;
use crate::volume::DType;

/// Where the samples of one level come from.
pub(crate) enum LevelSource {
    /// An array of shape `[.., z, y, x]`; leading axes (time, channel) are read at `leading`'s indices
    /// ([`crate::image_planes`]). Its last three dimensions may differ from the level's by one sample (foreign
    /// pyramids that halve rounding down): missing samples repeat the edge.
    Array { array: Array<dyn ReadableStorageTraits>, leading: LeadingIndex, shape: [u64; 3] },
    /// Averaged from the level below.
    Synthesized,
}

/// Reads `subset` of `array`, whose samples are of type `dtype`, as f32.
pub(crate) fn retrieve_f32(
    array: &Array<dyn ReadableStorageTraits>,
    subset: &ArraySubset,
    dtype: DType,
) -> Result<Vec<f32>, zarrs::array::ArrayError> {
    Ok(match dtype {
        DType::U8 => array.retrieve_array_subset::<Vec<u8>>(subset)?.into_iter().map(f32::from).collect(),
        DType::U16 => array.retrieve_array_subset::<Vec<u16>>(subset)?.into_iter().map(f32::from).collect(),
        DType::I16 => array.retrieve_array_subset::<Vec<i16>>(subset)?.into_iter().map(f32::from).collect(),
        DType::F32 => array.retrieve_array_subset::<Vec<f32>>(subset)?,
    })
}
