//! The PLY reader's tests: meshes and points in each encoding, skipped elements, the errors' messages, and the
//! streamed reader.

use super::*;
use crate::formats::damaged_input::{self, last_value_start, Truncation};
use crate::particles::RawParticles;
use crate::triangle_mesh::RawMesh;

fn path() -> &'static Path {
    Path::new("test.ply")
}

fn mesh(bytes: &[u8]) -> RawMesh {
    match parse(bytes, path()).unwrap() {
        RawGeometry::Mesh(mesh) => mesh,
        other => panic!("expected a mesh, got {other:?}"),
    }
}

fn particles(bytes: &[u8]) -> RawParticles {
    match parse(bytes, path()).unwrap() {
        RawGeometry::Particles(p) => p,
        other => panic!("expected particles, got {other:?}"),
    }
}

fn error(bytes: &[u8]) -> String {
    parse(bytes, path()).unwrap_err().to_string()
}

/// A unit square (a quad) and a triangle over 5 vertices, with a skipped element holding lists.
const ASCII_QUAD: &str = "ply\r\nformat ascii 1.0\ncomment made by hand\nobj_info nothing\n\
        element vertex 5\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\n\
        element material 2\nproperty list uchar float weights\nproperty int id\n\
        element face 2\nproperty list uchar int vertex_indices\nproperty uchar flags\nend_header\n\
        0 0 0 255\n1 0 0 255\n1 1 0 255\n0 1 0 255\n0 0 1 255\n\
        3 0.5 0.25 0.25 7\n0 8\n\
        4 0 1 2 3 9\n3 0 1 4 9\n";

const QUAD_POSITIONS: [[f32; 3]; 5] =
    [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
const QUAD_TRIANGLES: [[u32; 3]; 3] = [[0, 1, 2], [0, 2, 3], [0, 1, 4]];

/// The binary header and body of [`ASCII_QUAD`], in the byte order `put` writes.
fn binary_quad(format: &str, be: bool) -> Vec<u8> {
    let mut out = format!(
        "ply\nformat {format} 1.0\nelement vertex 5\nproperty float32 x\nproperty float32 y\nproperty float32 z\n\
             property uint8 red\nelement material 2\nproperty list uint8 float32 weights\nproperty int32 id\n\
             element face 2\nproperty list uint8 int32 vertex_indices\nproperty uint8 flags\nend_header\n"
    )
    .into_bytes();
    let f = |out: &mut Vec<u8>, v: f32| out.extend(if be { v.to_be_bytes() } else { v.to_le_bytes() });
    let i = |out: &mut Vec<u8>, v: i32| out.extend(if be { v.to_be_bytes() } else { v.to_le_bytes() });
    for p in QUAD_POSITIONS {
        p.iter().for_each(|&c| f(&mut out, c));
        out.push(255);
    }
    out.push(3);
    [0.5, 0.25, 0.25].iter().for_each(|&w| f(&mut out, w));
    i(&mut out, 7);
    out.push(0);
    i(&mut out, 8);
    out.push(4);
    [0, 1, 2, 3].iter().for_each(|&v| i(&mut out, v));
    out.push(9);
    out.push(3);
    [0, 1, 4].iter().for_each(|&v| i(&mut out, v));
    out.push(9);
    out
}

#[test]
fn ascii_mesh_fans_quads_and_skips_other_elements() {
    let mesh = mesh(ASCII_QUAD.as_bytes());
    assert_eq!(mesh.positions, QUAD_POSITIONS);
    assert_eq!(mesh.triangles, QUAD_TRIANGLES);
}

#[test]
fn binary_little_and_big_endian_read_as_ascii() {
    for (format, be) in [("binary_little_endian", false), ("binary_big_endian", true)] {
        let mesh = mesh(&binary_quad(format, be));
        assert_eq!(mesh.positions, QUAD_POSITIONS, "{format}");
        assert_eq!(mesh.triangles, QUAD_TRIANGLES, "{format}");
    }
}

#[test]
fn every_scalar_type_reads_in_both_byte_orders() {
    let types = ["char", "uchar", "short", "ushort", "int", "uint", "float", "double"];
    let aliases = ["int8", "uint8", "int16", "uint16", "int32", "uint32", "float32", "float64"];
    for names in [types, aliases] {
        for be in [false, true] {
            let format = if be { "binary_big_endian" } else { "binary_little_endian" };
            let mut header = format!("ply\nformat {format} 1.0\nelement vertex 1\n");
            for (k, ty) in names.iter().enumerate() {
                header += &format!("property {ty} p{k}\n");
            }
            header +=
                &format!("property {} x\nproperty {} y\nproperty {} z\nend_header\n", names[0], names[3], names[7]);
            let mut bytes = header.into_bytes();
            macro_rules! put {
                ($v:expr) => {
                    bytes.extend(if be { $v.to_be_bytes() } else { $v.to_le_bytes() })
                };
            }
            put!(-3i8);
            put!(200u8);
            put!(-3000i16);
            put!(60000u16);
            put!(-7i32);
            put!(4_000_000_000u32);
            put!(1.5f32);
            put!(-2.25f64);
            put!(-5i8);
            put!(65535u16);
            put!(0.125f64);
            let p = particles(&bytes);
            assert_eq!(p.positions, vec![[-5.0, 65535.0, 0.125]], "{names:?} {format}");
            // p0 is the first value-like property; the others are read past.
            assert_eq!((p.values.as_slice(), p.value_name.as_str()), ([-3.0f32].as_slice(), "p0"));
        }
    }
}

#[test]
fn points_become_particles_with_named_columns() {
    let file = "ply\nformat ascii 1.0\nelement vertex 2\nproperty double x\nproperty double y\nproperty double z\n\
                    property float nx\nproperty uchar red\nproperty list uchar int neighbours\nproperty float hsml\n\
                    property float m\nproperty float temperature\nproperty float pressure\nelement face 0\n\
                    property list uchar int vertex_indices\nend_header\n\
                    1 2 3 0 9 2 1 1 0.5 2 300 1\n4 5 6 0 9 0 0.25 3 310 1\n";
    let p = particles(file.as_bytes());
    assert_eq!(p.positions, vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
    assert_eq!(p.smoothing, vec![0.5, 0.25]);
    assert_eq!(p.masses, vec![2.0, 3.0]);
    assert_eq!(p.values, vec![300.0, 310.0]);
    assert_eq!(p.value_name, "temperature");
}

#[test]
fn dragon_like_vertices_with_confidence_and_intensity_make_a_mesh() {
    let file = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
                    property float confidence\nproperty float intensity\nelement face 1\n\
                    property list uchar int vertex_indices\nend_header\n\
                    -0.0378297 0.12794 0.00447467 0.850855 0.5 \n-0.0447794 0.128887 0.00190497 0.900159 0.5 \n\
                    -0.0680095 0.151244 0.0371953 0.398443 0.5 \n3 0 1 2 \n";
    let mesh = mesh(file.as_bytes());
    assert_eq!(mesh.positions.len(), 3);
    assert_eq!(mesh.triangles, vec![[0, 1, 2]]);
}

#[test]
fn truncated_binary_names_the_element() {
    let bytes = binary_quad("binary_little_endian", false);
    // Cut inside the faces: the header's minimum sizes still fit, the faces do not.
    let e = error(&bytes[..bytes.len() - 12]);
    assert!(e.ends_with("test.ply: header announces 2 faces but the file ends after 1"), "{e}");
    let e = error(&bytes[..bytes.len() - 20]);
    assert!(e.ends_with("test.ply: header announces 2 faces but the file ends after 0"), "{e}");
    // Cut inside the vertices: the minimum sizes no longer fit.
    let header_len = bytes.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    let short = error(&bytes[..header_len + 10]);
    assert!(short.contains("line 3: header announces 5 vertices but only 10 bytes follow the header"), "{short}");
}

#[test]
fn huge_counts_are_refused_before_allocating() {
    let huge = "ply\nformat binary_little_endian 1.0\nelement vertex 18446744073709551615\nproperty float x\n\
                    property float y\nproperty float z\nend_header\n0123";
    let e = error(huge.as_bytes());
    assert!(e.contains("line 3: header announces 18446744073709551615 vertices but only 4 bytes follow"), "{e}");
    let ascii = "ply\nformat ascii 1.0\nelement vertex 1000000\nproperty float x\nproperty float y\n\
                     property float z\nend_header\n0 0 0\n";
    let e = error(ascii.as_bytes());
    assert!(e.contains("header announces 1000000 vertices but only 6 bytes follow the header"), "{e}");
    // A list length far beyond the data ends the file, nothing is reserved for it.
    let mut list = b"ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty uchar x\nproperty uchar y\n\
                         property uchar z\nelement face 1\nproperty list uint uint vertex_indices\nend_header\n"
        .to_vec();
    list.extend([0, 0, 0, 1, 0, 0, 0, 1, 0]);
    list.extend(u32::MAX.to_be_bytes());
    list.extend([0u8; 12]);
    let e = error(&list);
    assert!(e.contains("header announces 1 faces but the file ends after 0"), "{e}");
    // A skipped element with no properties and a vast count costs nothing.
    let empty = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n\
                     element nothing 18446744073709551615\nend_header\n1 2 3\n";
    assert_eq!(particles(empty.as_bytes()).positions, vec![[1.0, 2.0, 3.0]]);
}

#[test]
fn bad_words_and_faces_are_named() {
    let with_body = |body: &str| {
        format!(
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
                 element face 1\nproperty list uchar int vertex_indices\nend_header\n{body}"
        )
    };
    let e = error(with_body("0 0 0\n1 0 0\n0 1 zero\n3 0 1 2\n").as_bytes());
    assert!(e.ends_with("line 12: vertex 2: 'zero' is not a number"), "{e}");
    let e = error(with_body("0 0 0\n1 0 0\n0 1 0\n2 0 1\n").as_bytes());
    assert!(e.ends_with("line 13: face 0 uses 2 vertices: a face needs at least 3"), "{e}");
    let e = error(with_body("0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n").as_bytes());
    assert!(e.ends_with("line 13: face 0 uses vertex -1: vertex indices cannot be negative"), "{e}");
    let e = error(with_body("0 0 0\n1 0 0\n0 1 0\n-3 0 1 2\n").as_bytes());
    assert!(e.ends_with("face 0: list length -3 is not a count"), "{e}");
    let e = error(with_body("0 0 0\n1 0 0\n0 1 0\n3 0 1 4294967296\n").as_bytes());
    assert!(e.ends_with("face 0 uses vertex 4294967296: voxstream reads at most 2^32 vertices"), "{e}");
}

#[test]
fn header_errors_are_named() {
    assert!(error(b"PLY\n").contains("not a PLY file"));
    assert!(error(b"").contains("not a PLY file"));
    let e = error(b"ply\nformat binary_middle_endian 1.0\nend_header\n");
    assert!(e.ends_with("line 2: unknown PLY format 'binary_middle_endian'"), "{e}");
    let e = error(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n");
    assert!(e.ends_with("the header has no 'end_header' line"), "{e}");
    let e = error(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty quad x\nend_header\n");
    assert!(e.ends_with("line 4: unknown PLY type 'quad'"), "{e}");
    let e = error(b"ply\nformat ascii 1.0\nelement vertex -1\nend_header\n");
    assert!(e.ends_with("element 'vertex': '-1' is not a count"), "{e}");
    let e = error(b"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nend_header\n");
    assert!(e.ends_with("line 3: the vertex element has no scalar 'z' property"), "{e}");
    let e = error(b"ply\nelement vertex 0\nend_header\n");
    assert!(e.ends_with("the header has no 'format' line"), "{e}");
    let e = error(b"ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n");
    assert!(e.ends_with("the header declares no 'vertex' element"), "{e}");
    let e = error(b"ply\nformat ascii 2.0\nend_header\n");
    assert!(e.ends_with("unsupported: PLY version 2.0 (only 1.0)"), "{e}");
}

#[test]
fn no_input_panics() {
    let replacements = [0u8, b'\n', b' ', b'9', b'-', 0xff];
    // The header declares every element's count. ASCII: a prefix missing a declared value is an error (a cut
    // inside the last number is a shorter number, a valid file); binary: every shorter prefix.
    let ascii = ASCII_QUAD.as_bytes();
    damaged_input::no_input_panics(
        |b| parse(b, path()),
        ascii,
        &replacements,
        Truncation::Through(last_value_start(ascii)),
    );
    for file in [binary_quad("binary_little_endian", false), binary_quad("binary_big_endian", true)] {
        damaged_input::no_input_panics(|b| parse(b, path()), &file, &replacements, Truncation::EveryPrefix);
    }
}

fn stream_file(name: &str, bytes: &[u8]) -> std::path::PathBuf {
    let path = std::env::temp_dir().join(format!("voxstream-ply-stream-{}-{name}.ply", std::process::id()));
    std::fs::write(&path, bytes).unwrap();
    path
}

fn streamed(stream: &PlyPointStream) -> RawParticles {
    let mut all = RawParticles { value_name: stream.value_name.clone(), ..RawParticles::default() };
    let mut next = 0;
    stream
        .for_each_chunk(&mut |first, run| {
            assert_eq!(first, next);
            next += run.positions.len() as u64;
            all.positions.extend(&run.positions);
            all.smoothing.extend(&run.smoothing);
            all.masses.extend(&run.masses);
            all.values.extend(&run.values);
            Ok(())
        })
        .unwrap();
    all
}

#[test]
fn a_binary_point_file_streams_the_particles_parse_reads() {
    // A leading element the stream reads past, then vertices with a skipped colour, in both byte orders; enough
    // vertices for several chunks.
    let count = 300_000u32;
    for big in [false, true] {
        let order = if big { "big" } else { "little" };
        let mut bytes = format!(
            "ply\nformat binary_{order}_endian 1.0\nelement camera 2\nproperty double f\nelement vertex {count}\n\
                 property float x\nproperty double y\nproperty float z\nproperty uchar red\nproperty float hsml\n\
                 property float temperature\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n"
        )
        .into_bytes();
        let put = |bytes: &mut Vec<u8>, v: &[u8]| {
            let mut v = v.to_vec();
            if big {
                v.reverse();
            }
            bytes.extend_from_slice(&v);
        };
        for _ in 0..2 {
            put(&mut bytes, &7.0f64.to_le_bytes());
        }
        for i in 0..count {
            let f = i as f32;
            put(&mut bytes, &(f * 0.5).to_le_bytes());
            put(&mut bytes, &(f64::from(f) * 0.25).to_le_bytes());
            put(&mut bytes, &(-f).to_le_bytes());
            bytes.push(200);
            put(&mut bytes, &(1.0 + f * 1e-6).to_le_bytes());
            put(&mut bytes, &(f * 2.0).to_le_bytes());
        }
        let path = stream_file(order, &bytes);
        let stream = PlyPointStream::open(&path).unwrap();
        assert_eq!(stream.count(), u64::from(count));
        assert_eq!(stream.columns(), [true, false, true]);
        let whole = match parse(&bytes, &path).unwrap() {
            RawGeometry::Particles(particles) => particles,
            RawGeometry::Mesh(_) => panic!("points expected"),
        };
        assert_eq!(streamed(&stream), whole);
        std::fs::remove_file(&path).ok();
    }
}

#[test]
fn files_the_stream_cannot_read_are_named() {
    let header = |format: &str, rest: &str| {
        format!("ply\nformat {format} 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n{rest}end_header\n")
    };
    let refused = |name: &str, bytes: Vec<u8>, needle: &str| {
        let path = stream_file(name, &bytes);
        let error = PlyPointStream::open(&path).unwrap_err().to_string();
        assert!(error.contains(needle), "{name}: {error}");
        std::fs::remove_file(&path).ok();
    };
    refused("ascii", header("ascii", "").into_bytes(), "write it as binary_little_endian");
    let mut mesh =
        header("binary_little_endian", "element face 1\nproperty list uchar int vertex_indices\n").into_bytes();
    mesh.extend([0u8; 24 + 13]);
    refused("mesh", mesh, "holds faces (a mesh)");
    let mut short = header("binary_little_endian", "").into_bytes();
    short.extend([0u8; 23]);
    refused("short", short, "header announces 2 vertices (12 bytes each");
    let mut list = header("binary_little_endian", "property list uchar float extra\n").into_bytes();
    list.extend([0u8; 40]);
    refused("list", list, "list property 'extra'");
    let mut huge = "ply\nformat binary_little_endian 1.0\nelement vertex 18446744073709551615\nproperty double x\n\
                        property double y\nproperty double z\nend_header\n"
        .as_bytes()
        .to_vec();
    huge.extend([0u8; 48]);
    refused("huge", huge, "header announces 18446744073709551615 vertices");
}
