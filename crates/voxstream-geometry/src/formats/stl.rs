//! STL (<https://www.fabbers.com/tech/STL_Format>), binary and ASCII.
//!
//! Binary: an 80-byte header, a little-endian `u32` triangle count, then 50 bytes per triangle (a normal, three
//! vertices as `f32` triples, a 2-byte attribute). ASCII: `solid name`, then per triangle `facet normal …`,
//! `outer loop`, three `vertex x y z`, `endloop`, `endfacet`, and `endsolid`; several solids may follow one another,
//! keywords are read in any case, and a loop of more than three vertices is fanned into triangles `(0, i, i+1)`.
//!
//! Binary files often begin with the word `solid` too, so the choice is made by length: a file of exactly
//! `84 + 50 × count` bytes is binary, any other that begins with `solid` is ASCII (unless its first kilobyte holds
//! control bytes, which only binary data does: then the length is what is wrong, and the error says so).
//!
//! STL repeats each vertex in every triangle that uses it; the reader welds bit-identical positions (`-0` and `+0`
//! alike) into one vertex, since the mesh producer's pseudo-normals come from the triangles that share a vertex.
//! The stored normals and attribute bytes (some tools' colours) are not read.
//!
//! Hand-written: both variants are a few lines, and reading them here lets the binary count be checked against the
//! file's length before anything is reserved, and every ASCII error name its line.

use std::collections::HashMap;
use std::path::Path;

use super::words::shown;
use crate::error::GeometryError;
use crate::triangle_mesh::RawMesh;

/// Bytes before a binary STL's triangles: the header and the count.
const BINARY_HEADER: usize = 84;
/// Bytes per triangle of a binary STL.
const BINARY_TRIANGLE: u64 = 50;

/// Parses a binary or ASCII STL file, welding repeated vertices.
pub fn parse(bytes: &[u8], path: &Path) -> Result<RawMesh, GeometryError> {
    let count = bytes.get(80..BINARY_HEADER).and_then(|c| c.first_chunk::<4>()).map(|c| u32::from_le_bytes(*c));
    let binary_len = count.map(|count| BINARY_HEADER as u64 + BINARY_TRIANGLE * u64::from(count));
    let len = bytes.len() as u64;
    if let (Some(count), Some(binary_len)) = (count, binary_len) {
        if binary_len == len {
            return read_binary(bytes, count, path);
        }
    }
    let solid = bytes.trim_ascii_start().get(..5).is_some_and(|w| w.eq_ignore_ascii_case(b"solid"));
    let control = bytes.iter().take(1024).any(|&b| (b < 0x20 && !b"\t\n\x0c\r".contains(&b)) || b == 0x7f);
    match (solid, count, binary_len) {
        (true, Some(count), Some(binary_len)) if control => Err(GeometryError::format(
            path,
            None,
            format!(
                "not an STL file: it begins with 'solid' but holds binary data, and a binary STL of {count} triangles \
                 is {binary_len} bytes long, not {len}"
            ),
        )),
        (true, ..) => read_ascii(bytes, path),
        (false, Some(count), Some(binary_len)) => Err(GeometryError::format(
            path,
            None,
            format!(
                "not an STL file: it does not begin with 'solid', and a binary STL of {count} triangles is \
                 {binary_len} bytes long, not {len}"
            ),
        )),
        (false, ..) => Err(GeometryError::format(
            path,
            None,
            format!("not an STL file: {len} bytes, and it does not begin with 'solid'"),
        )),
    }
}

/// Reads the `count` triangles of a binary STL whose length has been checked.
fn read_binary(bytes: &[u8], count: u32, path: &Path) -> Result<RawMesh, GeometryError> {
    let mut welder = Welder::with_capacity(count as usize);
    let triangles = bytes.get(BINARY_HEADER..).unwrap_or_default().chunks_exact(BINARY_TRIANGLE as usize);
    for (index, triangle) in triangles.enumerate() {
        let corner = |k: usize| {
            let at = 12 + 12 * k;
            let b = triangle.get(at..at + 12).unwrap_or_default();
            let c =
                |i: usize| b.get(i..).and_then(|b| b.first_chunk::<4>()).map_or(f32::NAN, |c| f32::from_le_bytes(*c));
            [c(0), c(4), c(8)]
        };
        welder
            .triangle([corner(0), corner(1), corner(2)])
            .map_err(|message| GeometryError::format(path, None, format!("triangle {index}: {message}")))?;
    }
    Ok(welder.mesh)
}

/// Where an ASCII STL reader stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum State {
    /// Before a `solid` or after an `endsolid`.
    Outside,
    /// Inside a solid, between facets.
    Solid,
    /// Inside a facet.
    Facet,
    /// Inside a facet's `outer loop`.
    Loop,
}

fn read_ascii(bytes: &[u8], path: &Path) -> Result<RawMesh, GeometryError> {
    let mut welder = Welder::with_capacity(0);
    let mut state = State::Outside;
    let mut facets = 0u64;
    let mut corners: Vec<[f32; 3]> = Vec::new();
    let mut last_line = 0;
    for (number, line) in bytes.split(|&b| b == b'\n').enumerate() {
        let number = number as u64 + 1;
        last_line = number;
        let at = |message: String| GeometryError::format(path, Some(number), message);
        let mut words = line.split(|b| b.is_ascii_whitespace()).filter(|w| !w.is_empty());
        let Some(keyword) = words.next() else { continue };
        let keyword = String::from_utf8_lossy(keyword).to_ascii_lowercase();
        let expected = match state {
            State::Outside => "'solid'",
            State::Solid => "'facet' or 'endsolid'",
            State::Facet => "'outer loop', 'vertex' or 'endfacet'",
            State::Loop => "'vertex' or 'endloop'",
        };
        state = match (keyword.as_str(), state) {
            ("solid", State::Outside) => State::Solid,
            ("facet", State::Solid) => {
                corners.clear();
                State::Facet
            }
            ("outer", State::Facet) => State::Loop,
            ("vertex", State::Facet | State::Loop) => {
                let mut position = [0.0f32; 3];
                for (axis, c) in position.iter_mut().enumerate() {
                    let word = words
                        .next()
                        .ok_or_else(|| at(format!("facet {facets}: a vertex with {axis} coordinates, not 3")))?;
                    *c = std::str::from_utf8(word).ok().and_then(|w| w.parse().ok()).ok_or_else(|| {
                        at(format!("facet {facets}: '{}' is not a number", shown(&String::from_utf8_lossy(word))))
                    })?;
                }
                corners.push(position);
                state
            }
            ("endloop", State::Loop) => State::Facet,
            ("endfacet", State::Facet) => {
                if corners.len() < 3 {
                    return Err(at(format!("facet {facets} has {} vertices: a facet needs 3", corners.len())));
                }
                let first = corners.first().copied().unwrap_or_default();
                for pair in corners.get(1..).unwrap_or_default().windows(2) {
                    if let [b, c] = pair {
                        welder.triangle([first, *b, *c]).map_err(|m| at(format!("facet {facets}: {m}")))?;
                    }
                }
                facets += 1;
                State::Solid
            }
            ("endsolid", State::Solid) => State::Outside,
            (found, _) if state == State::Outside && facets == 0 => {
                return Err(at(format!("not an STL file: expected 'solid', found '{}'", shown(found))))
            }
            (found, _) => return Err(at(format!("expected {expected}, found '{}'", shown(found)))),
        };
    }
    if matches!(state, State::Facet | State::Loop) {
        return Err(GeometryError::format(path, Some(last_line), format!("the file ends inside facet {facets}")));
    }
    Ok(welder.mesh)
}

/// Builds a mesh from triangles given by their corners, one vertex per distinct position.
struct Welder {
    mesh: RawMesh,
    /// Vertex of each position, keyed by its coordinates' bits (`-0` as `+0`).
    vertices: HashMap<[u32; 3], u32>,
}

impl Welder {
    fn with_capacity(triangles: usize) -> Welder {
        // A closed mesh has about half as many vertices as triangles.
        let vertices = triangles / 2;
        Welder {
            mesh: RawMesh { positions: Vec::with_capacity(vertices), triangles: Vec::with_capacity(triangles) },
            vertices: HashMap::with_capacity(vertices),
        }
    }

    fn triangle(&mut self, corners: [[f32; 3]; 3]) -> Result<(), &'static str> {
        let [a, b, c] = corners;
        let triangle = [self.vertex(a)?, self.vertex(b)?, self.vertex(c)?];
        self.mesh.triangles.push(triangle);
        Ok(())
    }

    fn vertex(&mut self, position: [f32; 3]) -> Result<u32, &'static str> {
        let key = position.map(|c| if c == 0.0 { 0 } else { c.to_bits() });
        let next = u32::try_from(self.mesh.positions.len()).map_err(|_| "more than 2^32 distinct vertices")?;
        let positions = &mut self.mesh.positions;
        Ok(*self.vertices.entry(key).or_insert_with(|| {
            positions.push(position);
            next
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::damaged_input::{self, Truncation};

    fn path() -> &'static Path {
        Path::new("test.stl")
    }

    fn error(bytes: &[u8]) -> String {
        parse(bytes, path()).unwrap_err().to_string()
    }

    /// Two triangles of a unit square, sharing the edge (1,0,0)–(0,1,0); one corner is written as -0.
    const SQUARE: [[[f32; 3]; 3]; 2] =
        [[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], [[1.0, 0.0, -0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]]];

    fn binary(header: &[u8], triangles: &[[[f32; 3]; 3]]) -> Vec<u8> {
        let mut out = header.to_vec();
        out.resize(80, b' ');
        out.extend((triangles.len() as u32).to_le_bytes());
        for t in triangles {
            out.extend([0.0f32, 0.0, 1.0].iter().flat_map(|c| c.to_le_bytes()));
            out.extend(t.iter().flatten().flat_map(|c| c.to_le_bytes()));
            out.extend([0u8, 0]);
        }
        out
    }

    fn check_square(mesh: &RawMesh) {
        assert_eq!(mesh.positions, vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]]);
        assert_eq!(mesh.triangles, vec![[0, 1, 2], [1, 3, 2]]);
    }

    const ASCII: &str = "solid square\r\n  facet normal 0 0 1\r\n    outer loop\r\n      vertex 0 0 0\r\n\
                         vertex 1 0 0\r\n      vertex 0 1 0\r\n    endloop\r\n  endfacet\r\nendsolid square\r\n\
                         SOLID second\n FACET NORMAL 0 0 1\n OUTER LOOP\n VERTEX 1 0 -0\n VERTEX 1e0 1 0\n\
                         VERTEX 0 1 0\n ENDLOOP\n ENDFACET\nENDSOLID\n";

    #[test]
    fn reads_ascii_and_welds() {
        check_square(&parse(ASCII.as_bytes(), path()).unwrap());
    }

    #[test]
    fn reads_binary_and_welds() {
        check_square(&parse(&binary(b"exported by hand", &SQUARE), path()).unwrap());
    }

    #[test]
    fn binary_beginning_with_solid_is_binary() {
        check_square(&parse(&binary(b"solid square, binary", &SQUARE), path()).unwrap());
    }

    #[test]
    fn ascii_polygons_are_fanned() {
        let quad = "solid q\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 1 1 0\nvertex 0 1 0\n\
                    endloop\nendfacet\nendsolid q\n";
        let mesh = parse(quad.as_bytes(), path()).unwrap();
        assert_eq!(mesh.positions.len(), 4);
        assert_eq!(mesh.triangles, vec![[0, 1, 2], [0, 2, 3]]);
    }

    #[test]
    fn errors_name_the_problem() {
        let full = binary(b"exported by hand", &SQUARE);
        let e = error(&full[..full.len() - 1]);
        assert!(
            e.ends_with("test.stl: not an STL file: it does not begin with 'solid', and a binary STL of 2 triangles is 184 bytes long, not 183"),
            "{e}"
        );
        let mut huge = full.clone();
        huge[80..84].copy_from_slice(&u32::MAX.to_le_bytes());
        let e = error(&huge);
        assert!(e.contains("a binary STL of 4294967295 triangles is 214748364834 bytes long, not 184"), "{e}");
        let solid = binary(b"solid square, binary", &SQUARE);
        let e = error(&solid[..solid.len() - 10]);
        assert!(e.contains("not an STL file: it begins with 'solid' but holds binary data"), "{e}");
        assert!(error(b"").ends_with("not an STL file: 0 bytes, and it does not begin with 'solid'"));
        let e = error(b"solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nendloop\nendfacet\n");
        assert!(e.ends_with("line 7: facet 0 has 2 vertices: a facet needs 3"), "{e}");
        let e = error(b"solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 zero 0\n");
        assert!(e.ends_with("line 4: facet 0: 'zero' is not a number"), "{e}");
        let e = error(b"solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0\n");
        assert!(e.ends_with("line 4: facet 0: a vertex with 2 coordinates, not 3"), "{e}");
        let e = error(b"solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\n");
        assert!(e.ends_with("line 5: the file ends inside facet 0"), "{e}");
        let e = error(b"solid s\nvertex 0 0 0\n");
        assert!(e.ends_with("line 2: expected 'facet' or 'endsolid', found 'vertex'"), "{e}");
        let e = error(b"solidity\n");
        assert!(e.ends_with("line 1: not an STL file: expected 'solid', found 'solidity'"), "{e}");
    }

    #[test]
    fn no_input_panics() {
        let replacements = [0u8, b'\n', b' ', b'9', b'-', 0xff];
        // ASCII STL declares no count: a prefix ending between facets is a valid smaller mesh, so only "no panic".
        damaged_input::no_input_panics(|b| parse(b, path()), ASCII.as_bytes(), &replacements, Truncation::Undetectable);
        // Binary STL declares its triangles: every shorter prefix is an error; but one whose header begins with
        // 'solid', cut before its count (the header is text), may be an empty ASCII STL.
        let file = binary(b"x", &SQUARE);
        damaged_input::no_input_panics(|b| parse(b, path()), &file, &replacements, Truncation::EveryPrefix);
        let file = binary(b"solid x", &SQUARE);
        let past_the_text = Truncation::From(BINARY_HEADER);
        damaged_input::no_input_panics(|b| parse(b, path()), &file, &replacements, past_the_text);
    }
}
