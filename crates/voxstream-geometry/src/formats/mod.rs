//! Readers for the mesh and particle files voxstream renders directly.
//!
//! Every reader parses a byte slice (`parse(bytes, path)`), so that the fuzz targets exercise exactly what users
//! run; [`read_geometry`] reads the file (gzip-compressed when its name ends in `.gz`) and dispatches on the file
//! name's ending. Counts that a header announces are checked against the bytes present before anything is
//! allocated for them, and every error names the file, the line for text formats, and the problem.
//!
//! | ending | reader | gives |
//! |---|---|---|
//! | `.ply` | [`ply`] (ASCII, binary little- and big-endian) | a mesh if it has faces, otherwise particles |
//! | `.obj` | [`obj`] | a mesh |
//! | `.off` | [`off`] | a mesh |
//! | `.stl` | [`stl`] (ASCII and binary) | a mesh |
//! | `.xyz`, `.csv`, `.txt` | [`xyz`] | particles (`x y z [h] [value]`) |
//! | `.gro` | [`gro`] | atoms as particles with per-element radii |
//! | `.pdb` | [`pdb`] | atoms as particles with per-element radii |
//! | `.vtk` | [`vtk_legacy`] (ASCII and binary `POLYDATA`/`UNSTRUCTURED_GRID` points) | particles |
//! | `.vtp` | [`vtp`] (VTK XML PolyData points) | particles |
//! | `.vtu` | [`vtp`] (VTK XML UnstructuredGrid points, e.g. PySPH's `dump_vtk`) | particles |

use std::io::Read;
use std::path::Path;

use crate::error::GeometryError;
use crate::particles::RawParticles;
use crate::triangle_mesh::RawMesh;

#[cfg(test)]
pub(crate) mod damaged_input;
pub mod elements;
pub mod gro;
pub mod obj;
pub mod off;
pub mod pdb;
pub mod ply;
pub mod polygon;
pub mod stl;
pub mod vtk_legacy;
pub mod vtp;
pub mod words;
pub mod xyz;

/// The largest file read, after decompression: geometry files are parsed whole in memory.
pub const MAX_FILE_BYTES: u64 = 16 << 30;

/// What a geometry file holds.
#[derive(Clone, Debug, PartialEq)]
pub enum RawGeometry {
    /// Triangles.
    Mesh(RawMesh),
    /// Points.
    Particles(RawParticles),
}

/// File-name endings (lower case, `.gz` excluded) that [`read_geometry`] reads.
pub const GEOMETRY_FILE_ENDINGS: [&str; 12] =
    [".ply", ".obj", ".off", ".stl", ".xyz", ".csv", ".txt", ".gro", ".pdb", ".vtk", ".vtp", ".vtu"];

/// Whether `path`'s name ends in one of [`GEOMETRY_FILE_ENDINGS`] (optionally followed by `.gz`).
pub fn is_geometry_file_name(path: &Path) -> bool {
    ending(path).is_some()
}

fn ending(path: &Path) -> Option<&'static str> {
    let name = path.file_name()?.to_string_lossy().to_lowercase();
    let name = name.strip_suffix(".gz").unwrap_or(&name);
    GEOMETRY_FILE_ENDINGS.iter().copied().find(|e| name.ends_with(e))
}

/// Reads a whole file (decompressing `.gz`), up to [`MAX_FILE_BYTES`].
pub fn read_file_bytes(path: &Path) -> Result<Vec<u8>, GeometryError> {
    let io = |error| GeometryError::Io { path: path.to_path_buf(), error };
    let file = std::fs::File::open(path).map_err(io)?;
    let len = file.metadata().map_err(io)?.len();
    let gz = path.to_string_lossy().to_lowercase().ends_with(".gz");
    if !gz && len > MAX_FILE_BYTES {
        return Err(GeometryError::Unsupported {
            path: path.to_path_buf(),
            message: format!("{len} bytes: geometry files are read whole, up to {MAX_FILE_BYTES} bytes"),
        });
    }
    let mut bytes = Vec::new();
    if gz {
        let mut decoder = flate2::read::MultiGzDecoder::new(std::io::BufReader::new(file)).take(MAX_FILE_BYTES + 1);
        decoder
            .read_to_end(&mut bytes)
            .map_err(|error| GeometryError::format(path, None, format!("not a valid gzip file ({error})")))?;
        if bytes.len() as u64 > MAX_FILE_BYTES {
            return Err(GeometryError::Unsupported {
                path: path.to_path_buf(),
                message: format!("decompresses to more than {MAX_FILE_BYTES} bytes: geometry files are read whole"),
            });
        }
    } else {
        let mut file = file;
        bytes.reserve(len as usize);
        file.read_to_end(&mut bytes).map_err(io)?;
    }
    Ok(bytes)
}

/// Reads a mesh or particle file, dispatching on its name's ending.
pub fn read_geometry(path: &Path) -> Result<RawGeometry, GeometryError> {
    let Some(ending) = ending(path) else {
        return Err(GeometryError::Unsupported {
            path: path.to_path_buf(),
            message: format!("not a geometry file name: expected one of {}", GEOMETRY_FILE_ENDINGS.join(", ")),
        });
    };
    let bytes = read_file_bytes(path)?;
    parse_geometry(&bytes, ending, path)
}

/// Parses `bytes` as the format of `ending` (one of [`GEOMETRY_FILE_ENDINGS`]).
pub fn parse_geometry(bytes: &[u8], ending: &str, path: &Path) -> Result<RawGeometry, GeometryError> {
    Ok(match ending {
        ".ply" => ply::parse(bytes, path)?,
        ".obj" => RawGeometry::Mesh(obj::parse(bytes, path)?),
        ".off" => RawGeometry::Mesh(off::parse(bytes, path)?),
        ".stl" => RawGeometry::Mesh(stl::parse(bytes, path)?),
        ".xyz" | ".csv" | ".txt" => RawGeometry::Particles(xyz::parse(bytes, path)?),
        ".gro" => RawGeometry::Particles(gro::parse(bytes, path)?),
        ".pdb" => RawGeometry::Particles(pdb::parse(bytes, path)?),
        ".vtk" => RawGeometry::Particles(vtk_legacy::parse(bytes, path)?),
        ".vtp" => RawGeometry::Particles(vtp::parse(bytes, path)?),
        ".vtu" => RawGeometry::Particles(vtp::parse_dataset(bytes, path, vtp::Dataset::UnstructuredGrid)?),
        other => {
            return Err(GeometryError::Unsupported {
                path: path.to_path_buf(),
                message: format!("no reader for {other}"),
            })
        }
    })
}
