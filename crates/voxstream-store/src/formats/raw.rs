//! Headerless raw volumes: geometry and type come from the command line (`--dims --dtype --endian --spacing
//! --origin --unit`), optionally after a fixed-size header (`--header-bytes`, e.g. 62 for volpack's `brainsmall.den`).
//! A `--dtype` the store does not keep (i8, i32, u32, f64) is converted as in every other format
//! ([`super::sample_type`]).

use std::path::Path;

use super::sample_stream::{Compression, Endian, SampleStream};
use super::sample_type::SampleType;
use crate::error::StoreError;
use crate::volume::VolumeInfo;

/// How to read a raw file.
#[derive(Clone, Debug, PartialEq)]
pub struct RawLayout {
    /// Geometry and type.
    pub info: VolumeInfo,
    /// The file's sample type when the store keeps another (`i8`, `i32`, `u32`, `f64`): it replaces `info`'s dtype,
    /// which becomes the type it is stored as. `None`: `info`'s dtype is the file's.
    pub file_type: Option<SampleType>,
    /// Byte order.
    pub endian: Endian,
    /// Bytes to skip before the samples.
    pub header_bytes: u64,
}

/// Opens a raw file; a file whose size does not match the layout is an error (too short: truncated; too long: the
/// dimensions or type are probably wrong).
pub fn open(path: &Path, layout: &RawLayout) -> Result<SampleStream, StoreError> {
    layout.info.validate(path)?;
    let file_type = layout.file_type.unwrap_or(layout.info.dtype.into());
    let size = std::fs::metadata(path).map_err(|e| StoreError::io(path, e))?.len();
    let expected = layout.header_bytes + layout.info.dims.iter().product::<u64>() * file_type.size() as u64;
    if size > expected {
        return Err(StoreError::format(
            path,
            format!(
                "file has {size} bytes but {:?} {} samples after {} header bytes need {expected}: check --dims, \
                 --dtype and --header-bytes",
                layout.info.dims,
                file_type.name(),
                layout.header_bytes
            ),
        ));
    }
    SampleStream::open(path, layout.header_bytes, Compression::None, 0, layout.info.clone(), file_type, layout.endian)
}
