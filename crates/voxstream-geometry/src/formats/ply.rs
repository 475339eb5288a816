//! (being written)

use std::path::Path;

use super::RawGeometry;
use crate::error::GeometryError;

/// Parses a PLY file.
pub fn parse(_bytes: &[u8], path: &Path) -> Result<RawGeometry, GeometryError> {
    Err(GeometryError::Unsupported { path: path.to_path_buf(), message: "not yet".into() })
}
