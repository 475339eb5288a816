//! PLY, the Stanford polygon format (<http://paulbourke.net/dataformats/ply/>): `format ascii 1.0`,
//! `binary_little_endian 1.0` and `binary_big_endian 1.0`; every scalar type under both its names (`char`/`int8`,
//! `uchar`/`uint8`, `short`/`int16`, `ushort`/`uint16`, `int`/`int32`, `uint`/`uint32`, `float`/`float32`,
//! `double`/`float64`); list properties with any count and item types; `comment` and `obj_info` lines.
//!
//! A file whose `face` element holds at least one face is a mesh: the `vertex` element's `x y z`, and the face
//! element's `vertex_indices` (or `vertex_index`) list with polygons into triangles by [`super::polygon::triangulate`]. Otherwise
//! the vertices are particles: `x y z`; `radius`, `h`, `smoothing_length` or `hsml` as the smoothing length; `mass`
//! or `m` as the mass; the first other scalar property (normals `nx ny nz`, colours `red green blue alpha` and
//! texture coordinates `u v s t` excepted) as the value. Every other element (edges, materials, a scanner's range
//! grid …) and every other property is read past, list properties included, in ASCII and binary bodies alike.
//!
//! Not read: triangle strips (a `tristrips` element is refused rather than shown as points), colours, normals and
//! texture coordinates; format versions other than 1.0.
//!
//! Hand-written rather than taken from a crate: the header is a handful of lines, and reading it here is what lets
//! each element count be checked against the bytes that follow the header before anything is allocated for it
//! (count × the element's smallest size in a binary body, count × its fewest words in an ASCII one), and every
//! error name the element, its number and, for ASCII, the line.//!
//! The reader's parts: `header` (the header, and the counts it declares checked against the body), `body` (the
//! reading plan and the ASCII and binary bodies: mesh faces and point elements) and `stream` (binary point files
//! read a chunk at a time, out of core).

mod body;
mod header;
mod stream;
#[cfg(test)]
mod tests;

use std::path::Path;

use super::RawGeometry;
use crate::error::GeometryError;
use body::{read_body, AsciiBody, BinaryBody, Plan};
use header::{check_counts, parse_header, Encoding};

pub use stream::{declared_points, PlyPointStream};

/// Parses a PLY file: a mesh if its `face` element holds faces, otherwise its vertices as particles.
pub fn parse(bytes: &[u8], path: &Path) -> Result<RawGeometry, GeometryError> {
    let header = parse_header(bytes, path)?;
    let body = bytes.get(header.body_start..).unwrap_or_default();
    let plan = Plan::new(&header, path)?;
    check_counts(&header, body.len(), path)?;
    let len = body.len();
    match header.encoding {
        Encoding::Ascii => {
            read_body(&mut AsciiBody { bytes: body, pos: 0, line: header.body_line }, len, &header, plan, path)
        }
        Encoding::BinaryLittle => {
            read_body(&mut BinaryBody { bytes: body, pos: 0, big: false }, len, &header, plan, path)
        }
        Encoding::BinaryBig => read_body(&mut BinaryBody { bytes: body, pos: 0, big: true }, len, &header, plan, path),
    }
}
