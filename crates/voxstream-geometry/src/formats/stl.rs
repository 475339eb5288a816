//! (being written)

use std::path::Path;

use crate::error::GeometryError;
use crate::triangle_mesh::RawMesh;

/// Parses a `stl` file.
pub fn parse(_bytes: &[u8], path: &Path) -> Result<RawMesh, GeometryError> {
    Err(GeometryError::Unsupported { path: path.to_path_buf(), message: "not yet".into() })
}
