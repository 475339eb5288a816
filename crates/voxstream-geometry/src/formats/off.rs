//! OFF, Geomview's object file format (<http://www.geomview.org/docs/html/OFF.html>), ASCII: the `OFF` keyword
//! (also with the `ST`, `C` and `N` prefixes: `COFF`, `NOFF`, `STOFF`, `STCNOFF` …, whose extra per-vertex
//! columns are read past), a counts line `vertices faces [edges]` (also accepted on the keyword's line), one vertex
//! per line (`x y z …`), one face per line (`n i0 i1 … i(n-1) [colour]`, polygons into triangles by
//! [`super::polygon::triangulate`]). `#` starts a comment anywhere; blank lines are skipped.
//!
//! Not read: binary OFF (`OFF BINARY`), homogeneous (`4OFF`) and n-dimensional (`nOFF`) vertices, and files with
//! more than one vertex or face on a line. Colours and normals are read past.
//!
//! Hand-written: the format is a few lines of text, and reading it here lets the header's counts be checked against
//! the bytes that follow before anything is reserved for them, and every error name its line.

use std::path::Path;

use super::polygon::triangulate;
use super::words::{shown_bytes as shown, text};
use crate::error::GeometryError;
use crate::triangle_mesh::RawMesh;

/// Parses an OFF file.
pub fn parse(bytes: &[u8], path: &Path) -> Result<RawMesh, GeometryError> {
    let mut lines = Lines { bytes, pos: 0, number: 0 };
    let at = |line: u64, message: String| GeometryError::format(path, Some(line), message);
    let Some((first, keyword_line)) = lines.next() else {
        return Err(GeometryError::format(path, None, "not an OFF file: it is empty"));
    };
    let keyword = first.first().copied().unwrap_or_default();
    check_keyword(keyword, path, keyword_line)?;
    let mut counts_words = first.get(1..).unwrap_or_default().to_vec();
    if counts_words.first().is_some_and(|w| w.eq_ignore_ascii_case(b"BINARY")) {
        return Err(GeometryError::Unsupported { path: path.to_path_buf(), message: "binary OFF".into() });
    }
    let mut counts_line = keyword_line;
    if counts_words.is_empty() {
        let (words, number) =
            lines.next().ok_or_else(|| at(keyword_line, "the file ends before the counts line".into()))?;
        counts_words = words;
        counts_line = number;
    }
    let count = |k: usize| {
        let word = counts_words.get(k).copied().unwrap_or_default();
        text(word).parse::<u64>().map_err(|_| {
            at(counts_line, format!("'{}' is not a count: the counts line is 'vertices faces [edges]'", shown(word)))
        })
    };
    let (vertex_count, face_count) = (count(0)?, count(1)?);
    // Each vertex and face takes a line of at least one word and a line break (the last line may lack its break);
    // reservations assume the shortest valid lines, "0 0 0\n" and "3 0 1 2\n".
    let remaining = bytes.len().saturating_sub(lines.pos) as u64;
    let lines_needed = vertex_count.checked_add(face_count).and_then(|n| n.checked_mul(2));
    if lines_needed.is_none_or(|needed| needed > remaining.saturating_add(1)) {
        return Err(at(
            counts_line,
            format!(
                "header announces {vertex_count} vertices and {face_count} faces but only {remaining} bytes follow it"
            ),
        ));
    }
    let mut mesh = RawMesh {
        positions: Vec::with_capacity(vertex_count.min(remaining / 6) as usize),
        triangles: Vec::with_capacity(face_count.min(remaining / 8) as usize),
    };
    // One face's corners (bounded by its line).
    let mut corners: Vec<u32> = Vec::new();
    for index in 0..vertex_count {
        let Some((words, line)) = lines.next() else {
            return Err(GeometryError::format(
                path,
                None,
                format!("header announces {vertex_count} vertices but the file ends after {index}"),
            ));
        };
        if words.len() < 3 {
            return Err(at(line, format!("vertex {index} has {} coordinates: it needs 3", words.len())));
        }
        let mut position = [0.0f32; 3];
        for (c, word) in position.iter_mut().zip(&words) {
            *c = text(word)
                .parse()
                .map_err(|_| at(line, format!("vertex {index}: '{}' is not a number", shown(word))))?;
        }
        mesh.positions.push(position);
    }
    for index in 0..face_count {
        let Some((words, line)) = lines.next() else {
            return Err(GeometryError::format(
                path,
                None,
                format!("header announces {face_count} faces but the file ends after {index}"),
            ));
        };
        let Some((&n, rest)) = words.split_first() else {
            return Err(at(line, format!("face {index} is empty")));
        };
        let n: u64 =
            text(n).parse().map_err(|_| at(line, format!("face {index}: '{}' is not a vertex count", shown(n))))?;
        if n < 3 {
            return Err(at(line, format!("face {index} uses {n} vertices: a face needs at least 3")));
        }
        if (rest.len() as u64) < n {
            return Err(at(line, format!("face {index} announces {n} vertices but lists {}", rest.len())));
        }
        // The words after the n indices are a colour: read past.
        corners.clear();
        for word in rest.iter().take(n as usize) {
            corners.push(vertex_index(word).map_err(|problem| at(line, format!("face {index} {problem}")))?);
        }
        triangulate(&corners, &mut mesh.triangles);
    }
    Ok(mesh)
}

/// Accepts `OFF` with the optional prefixes `ST`, `C`, `N` in that order; refuses `4OFF` and `nOFF`.
fn check_keyword(keyword: &[u8], path: &Path, line: u64) -> Result<(), GeometryError> {
    let not_off =
        || GeometryError::format(path, Some(line), format!("not an OFF file: it begins with '{}'", shown(keyword)));
    let prefix = keyword.strip_suffix(b"OFF").ok_or_else(not_off)?;
    if prefix.contains(&b'4') || prefix.contains(&b'n') {
        return Err(GeometryError::Unsupported {
            path: path.to_path_buf(),
            message: format!("{} (homogeneous or n-dimensional vertices)", shown(keyword)),
        });
    }
    let prefix = prefix.strip_prefix(b"ST").unwrap_or(prefix);
    let prefix = prefix.strip_prefix(b"C").unwrap_or(prefix);
    let prefix = prefix.strip_prefix(b"N").unwrap_or(prefix);
    if prefix.is_empty() {
        Ok(())
    } else {
        Err(not_off())
    }
}

/// A face's vertex index, or what is wrong with it (to follow "face 12 ").
fn vertex_index(word: &[u8]) -> Result<u32, String> {
    let index: i64 = text(word).parse().map_err(|_| format!("uses '{}': not a vertex index", shown(word)))?;
    if index < 0 {
        return Err(format!("uses vertex {index}: vertex indices cannot be negative"));
    }
    u32::try_from(index).map_err(|_| format!("uses vertex {index}: voxstream reads at most 2^32 vertices"))
}

/// The non-blank lines of a file, comments (`#` to the end of the line) removed, split into words.
struct Lines<'a> {
    bytes: &'a [u8],
    /// Where the next line begins.
    pos: usize,
    /// The last line's number (1-based).
    number: u64,
}

impl<'a> Lines<'a> {
    /// The next line that holds words, and its number.
    fn next(&mut self) -> Option<(Vec<&'a [u8]>, u64)> {
        loop {
            let rest = self.bytes.get(self.pos..).filter(|r| !r.is_empty())?;
            let end = rest.iter().position(|&b| b == b'\n').unwrap_or(rest.len());
            self.pos = self.pos.saturating_add(end + 1);
            self.number += 1;
            let line = rest.get(..end).unwrap_or_default();
            let content = line.split(|&b| b == b'#').next().unwrap_or_default();
            let words: Vec<&[u8]> = content.split(|b| b.is_ascii_whitespace()).filter(|w| !w.is_empty()).collect();
            if !words.is_empty() {
                return Some((words, self.number));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::damaged_input::{self, last_value_start, Truncation};
    use crate::formats::RawGeometry;

    fn path() -> &'static Path {
        Path::new("test.off")
    }

    fn error(text: &str) -> String {
        parse(text.as_bytes(), path()).unwrap_err().to_string()
    }

    const SQUARE: &str = "# a unit square and a triangle\nOFF\n\n# counts\n5 2 0\n0 0 0\n1 0 0 # corner\n1 1 0\n\
                          0 1 0\n0 0 1\n4 0 1 2 3 255 0 0\n3 0 1 4\n";

    #[test]
    fn reads_comments_quads_and_colours() {
        let mesh = parse(SQUARE.as_bytes(), path()).unwrap();
        assert_eq!(mesh.positions.len(), 5);
        assert_eq!(mesh.positions[1], [1.0, 0.0, 0.0]);
        assert_eq!(mesh.triangles, vec![[0, 1, 2], [0, 2, 3], [0, 1, 4]]);
    }

    #[test]
    fn prefixed_keywords_read_past_extra_columns() {
        let coff = "COFF\r\n3 1 3\r\n0 0 0 255 0 0 255\r\n1 0 0 0 255 0 255\r\n0 1 0 0 0 255 255\r\n3 0 1 2\r\n";
        let noff = "NOFF 3 1\n0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 0 0 1\n3 2 1 0\n";
        let stoff =
            "STCNOFF\n3 1 0\n0 0 0 0 0 1 1 1 1 1 0 0\n1 0 0 0 0 1 1 1 1 1 1 0\n0 1 0 0 0 1 1 1 1 1 0 1\n3 0 1 2\n";
        for (text, triangle) in [(coff, [0, 1, 2]), (noff, [2, 1, 0]), (stoff, [0, 1, 2])] {
            let mesh = parse(text.as_bytes(), path()).unwrap();
            assert_eq!(mesh.positions, vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], "{text}");
            assert_eq!(mesh.triangles, vec![triangle], "{text}");
        }
    }

    #[test]
    fn errors_name_the_line_and_problem() {
        let e = error("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n");
        assert!(e.ends_with("test.off line 6: face 0 uses 2 vertices: a face needs at least 3"), "{e}");
        let e = error("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n");
        assert!(e.ends_with("line 6: face 0 uses vertex -1: vertex indices cannot be negative"), "{e}");
        let e = error("OFF\n3 1 0\n0 0 0\n1 0 x\n0 1 0\n3 0 1 2\n");
        assert!(e.ends_with("line 4: vertex 1: 'x' is not a number"), "{e}");
        let e = error("OFF\n3 1 0\n0 0 0\n1 0\n0 1 0\n3 0 1 2\n");
        assert!(e.ends_with("line 4: vertex 1 has 2 coordinates: it needs 3"), "{e}");
        let e = error("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n4 0 1 2\n");
        assert!(e.ends_with("line 6: face 0 announces 4 vertices but lists 3"), "{e}");
        let e = error("OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
        assert!(e.ends_with("test.off: header announces 2 faces but the file ends after 1"), "{e}");
        let e = error("OFF\n1000000 1 0\n0 0 0\n");
        assert!(e.ends_with("line 2: header announces 1000000 vertices and 1 faces but only 6 bytes follow it"), "{e}");
        let e = error("OFF\n3 1\n0 0 0\n0 0 0\n");
        assert!(e.ends_with("test.off: header announces 3 vertices but the file ends after 2"), "{e}");
        let e = error("OFF\n18446744073709551615 18446744073709551615\n");
        assert!(e.contains("header announces 18446744073709551615 vertices"), "{e}");
        let e = error("OFF\n3 one 0\n");
        assert!(e.ends_with("line 2: 'one' is not a count: the counts line is 'vertices faces [edges]'"), "{e}");
        let e = error("PLY\n3 1 0\n");
        assert!(e.ends_with("line 1: not an OFF file: it begins with 'PLY'"), "{e}");
        assert!(error("# nothing\n").ends_with("not an OFF file: it is empty"));
        assert!(error("OFF BINARY\n").ends_with("unsupported: binary OFF"));
        assert!(error("4OFF\n").ends_with("unsupported: 4OFF (homogeneous or n-dimensional vertices)"));
    }

    #[test]
    fn no_input_panics() {
        // The header declares the counts: a prefix missing a declared value is an error (one cut inside the last
        // number is a shorter number, a valid file).
        let (file, replacements) = (SQUARE.as_bytes(), [0u8, b'\n', b' ', b'9', b'-', b'#', 0xff]);
        damaged_input::no_input_panics(
            |b| parse(b, path()),
            file,
            &replacements,
            Truncation::Through(last_value_start(file)),
        );
    }

    /// CGAL's bunny: its header says 37706 vertices and 75408 faces, all triangles.
    #[test]
    fn reads_cgal_bunny() {
        let bunny = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/real/bunny00.off");
        let RawGeometry::Mesh(mesh) = crate::formats::read_geometry(&bunny).unwrap() else { panic!("not a mesh") };
        assert_eq!(mesh.positions.len(), 37706);
        assert_eq!(mesh.triangles.len(), 75408);
        let mesh = crate::TriangleMesh::new(mesh).unwrap();
        assert_eq!(mesh.triangles().len() + mesh.degenerate_dropped, 75408);
    }
}
