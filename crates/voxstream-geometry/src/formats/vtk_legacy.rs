//! (being written)

use std::path::Path;

use crate::error::GeometryError;
use crate::particles::RawParticles;

/// Parses a `vtk_legacy` file.
pub fn parse(_bytes: &[u8], path: &Path) -> Result<RawParticles, GeometryError> {
    Err(GeometryError::Unsupported { path: path.to_path_buf(), message: "not yet".into() })
}
