//! Wavefront OBJ geometry (<http://paulbourke.net/dataformats/obj/>): `v x y z [w]` vertices (further numbers,
//! such as the vertex colours some tools append, are read past; `w` is ignored) and `f` faces whose corners are
//! `i`, `i/t`, `i//n` or `i/t/n`, with 1-based or negative (relative: `-1` is the latest vertex) indices; polygons
//! become triangles by [`super::polygon::triangulate`] (fanned `(0, i, i+1)` up to 16 corners, split in balanced
//! halves above). Every other statement (`vn`, `vt`, `g`, `o`, `usemtl`, `mtllib`, `s`,
//! `l`, `p`, curves and surfaces …) and every comment is ignored; materials are never opened.
//!
//! Not read: line continuations (`\` at a line's end), free-form geometry, texture coordinates and normals.
//!
//! Hand-written rather than the `tobj` crate: only positions and face corners are needed (a screenful of code), and
//! this reader has to meet the project's hostile-input rules itself: no panic on any input (tobj has panicked on an
//! out-of-range face index before, Twinklebear/tobj#18), errors that name the line (tobj's `LoadError` carries none),
//! no file opened besides the one given (tobj resolves `mtllib` through a loader that must be stubbed out), and one
//! mesh rather than tobj's per-object models to merge again.

use std::path::Path;

use super::polygon::triangulate;
use super::words::{shown_bytes as shown, text};
use crate::error::GeometryError;
use crate::triangle_mesh::RawMesh;

/// Parses an OBJ file's vertices and faces.
pub fn parse(bytes: &[u8], path: &Path) -> Result<RawMesh, GeometryError> {
    let mut mesh = RawMesh::default();
    let mut faces = 0u64;
    // One face's corners (a line's words: bounded by the file).
    let mut corners: Vec<u32> = Vec::new();
    for (number, line) in bytes.split(|&b| b == b'\n').enumerate() {
        let number = number as u64 + 1;
        let at = |message: String| GeometryError::format(path, Some(number), message);
        let mut words = line.split(|b| b.is_ascii_whitespace()).filter(|w| !w.is_empty());
        match words.next() {
            Some(b"v") => {
                let mut position = [0.0f32; 3];
                for (axis, c) in position.iter_mut().enumerate() {
                    let word = words.next().ok_or_else(|| {
                        at(format!("vertex {} has {axis} coordinates: it needs 3", mesh.positions.len()))
                    })?;
                    *c = text(word).parse().map_err(|_| {
                        at(format!("vertex {}: '{}' is not a number", mesh.positions.len(), shown(word)))
                    })?;
                }
                mesh.positions.push(position);
            }
            Some(b"f") => {
                let face = faces;
                faces += 1;
                corners.clear();
                for word in words {
                    let vertex =
                        corner(word, mesh.positions.len()).map_err(|problem| at(format!("face {face} {problem}")))?;
                    corners.push(vertex);
                }
                if corners.len() < 3 {
                    return Err(at(format!("face {face} uses {} vertices: a face needs at least 3", corners.len())));
                }
                triangulate(&corners, &mut mesh.triangles);
            }
            _ => {}
        }
    }
    Ok(mesh)
}

/// The 0-based vertex index of a face corner (`i`, `i/t`, `i//n`, `i/t/n`), given the vertices read so far, or what
/// is wrong with it (to follow "face 12 ").
fn corner(word: &[u8], vertices: usize) -> Result<u32, String> {
    let index = word.split(|&b| b == b'/').next().unwrap_or_default();
    let index: i64 =
        text(index).parse().map_err(|_| format!("has the corner '{}': not a vertex index", shown(word)))?;
    let zero_based = match index {
        0 => return Err("uses vertex 0: OBJ indices start at 1 (or count back from -1)".into()),
        1.. => index - 1,
        _ => {
            let back = index.unsigned_abs();
            if back > vertices as u64 {
                return Err(format!("uses vertex {index}: only {vertices} vertices precede it"));
            }
            vertices as i64 - back as i64
        }
    };
    u32::try_from(zero_based).map_err(|_| format!("uses vertex {index}: voxstream reads at most 2^32 vertices"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::damaged_input::{self, Truncation};

    fn path() -> &'static Path {
        Path::new("test.obj")
    }

    fn error(text: &str) -> String {
        parse(text.as_bytes(), path()).unwrap_err().to_string()
    }

    const SQUARE: &str =
        "# a unit square and a triangle\r\nmtllib missing.mtl\r\no square\r\nv 0 0 0\r\nv 1 0 0 1.0\r\n\
                          vt 0 0\r\nvn 0 0 1\r\nv 1 1 0 0.5 0.5 0.5\r\nv 0 1 0\r\ng top\r\nusemtl red\r\ns off\r\n\
                          f 1/1/1 2/1/1 3//1 4/1\r\nv 0 0 1\r\nf -5 -4 -1\r\nl 1 2\r\np 3\r\n";

    #[test]
    fn reads_slashed_and_negative_indices() {
        let mesh = parse(SQUARE.as_bytes(), path()).unwrap();
        assert_eq!(
            mesh.positions,
            vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
        );
        assert_eq!(mesh.triangles, vec![[0, 1, 2], [0, 2, 3], [0, 1, 4]]);
    }

    #[test]
    fn errors_name_the_line_and_problem() {
        let e = error("v 0 0 0\nv 1 0 0\nf 1 2\n");
        assert!(e.ends_with("test.obj line 3: face 0 uses 2 vertices: a face needs at least 3"), "{e}");
        let e = error("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf -1 -2 -4\n");
        assert!(e.ends_with("line 5: face 1 uses vertex -4: only 3 vertices precede it"), "{e}");
        let e = error("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n");
        assert!(e.ends_with("line 4: face 0 uses vertex 0: OBJ indices start at 1 (or count back from -1)"), "{e}");
        let e = error("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 /3\n");
        assert!(e.ends_with("line 4: face 0 has the corner '/3': not a vertex index"), "{e}");
        let e = error("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4294967297\n");
        assert!(e.ends_with("face 0 uses vertex 4294967297: voxstream reads at most 2^32 vertices"), "{e}");
        let e = error("v 0 0 0\nv 1 zero 0\n");
        assert!(e.ends_with("line 2: vertex 1: 'zero' is not a number"), "{e}");
        let e = error("v 0 0\n");
        assert!(e.ends_with("line 1: vertex 0 has 2 coordinates: it needs 3"), "{e}");
        let e = error("v 0 0 0\nf -9223372036854775808 1 1\n");
        assert!(e.ends_with("uses vertex -9223372036854775808: only 1 vertices precede it"), "{e}");
    }

    #[test]
    fn no_input_panics() {
        // OBJ declares no counts: any prefix that ends between lines is a valid smaller mesh, so only "no panic".
        let replacements = [0u8, b'\n', b' ', b'9', b'-', b'/', 0xff];
        damaged_input::no_input_panics(
            |b| parse(b, path()),
            SQUARE.as_bytes(),
            &replacements,
            Truncation::Undetectable,
        );
    }

    /// Issue 41: a 1.1 MB OBJ with one 200,000-corner face took 203 s to render.
    #[test]
    fn a_face_of_200000_corners_makes_no_fan_of_slivers_and_no_pile_of_copies() {
        const CORNERS: usize = 200_000;
        // Corners on a circle: a fan put all 199,998 triangles on corner 1, whose boxes all overlapped there.
        let mut text = String::new();
        for i in 0..CORNERS {
            let angle = std::f64::consts::TAU * i as f64 / CORNERS as f64;
            text.push_str(&format!("v {:.6} {:.6} 0\n", angle.cos(), angle.sin()));
        }
        text.push('f');
        (1..=CORNERS).for_each(|i| text.push_str(&format!(" {i}")));
        let mesh = parse(text.as_bytes(), path()).unwrap();
        assert_eq!(mesh.triangles.len(), CORNERS - 2);
        let mut uses = vec![0u32; CORNERS];
        mesh.triangles.iter().flatten().for_each(|&c| uses[c as usize] += 1);
        let most = uses.iter().max().copied().unwrap();
        assert!(most <= 40, "{most} triangles meet at one corner");
        // Four corners listed over and over: 100,000 copies of two triangles, which no hierarchy splits.
        let mut text = String::from("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf");
        (0..CORNERS).for_each(|i| text.push_str(&format!(" {}", 1 + i % 4)));
        let mesh = crate::TriangleMesh::new(parse(text.as_bytes(), path()).unwrap()).unwrap();
        assert!(mesh.triangles().len() <= 8, "{} triangles", mesh.triangles().len());
        assert!(mesh.repeated_dropped > 100_000, "{}", mesh.repeated_dropped);
    }
}
