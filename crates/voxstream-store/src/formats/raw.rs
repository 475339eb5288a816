//! Headerless raw volumes: geometry and type come from the command line (`--dims --dtype --endian --spacing
//! --origin`), optionally after a fixed-size header (`--header-bytes`, e.g. 62 for volpack's `brainsmall.den`).

use std::path::Path;

use super::sample_stream::{Compression, Endian, SampleStream};
use crate::error::StoreError;
use crate::volume::VolumeInfo;

/// How to read a raw file.
#[derive(Clone, Debug, PartialEq)]
pub struct RawLayout {
    /// Geometry and type.
    pub info: VolumeInfo,
    /// Byte order.
    pub endian: Endian,
    /// Bytes to skip before the samples.
    pub header_bytes: u64,
}

/// Opens a raw file; a file whose size does not match the layout is an error (too short: truncated; too long: the
/// dimensions or type are probably wrong).
pub fn open(path: &Path, layout: &RawLayout) -> Result<SampleStream, StoreError> {
    layout.info.validate(path)?;
    let size = std::fs::metadata(path).map_err(|e| StoreError::io(path, e))?.len();
    let expected = layout.header_bytes + layout.info.byte_len();
    if size > expected {
        return Err(StoreError::format(
            path,
            format!(
                "file has {size} bytes but {:?} {} samples after {} header bytes need {expected}: check --dims, \
                 --dtype and --header-bytes",
                layout.info.dims,
                layout.info.dtype.name(),
                layout.header_bytes
            ),
        ));
    }
    SampleStream::open(path, layout.header_bytes, Compression::None, 0, layout.info.clone(), layout.endian)
}
