//! The `.vtp` and `.vtu` reader's tests: each encoding, pieces, shared appended data, and the errors' messages.

use std::io::Write;

use base64::Engine;

use super::*;

fn parse_bytes(bytes: &[u8]) -> Result<RawParticles, GeometryError> {
    parse(bytes, Path::new("p.vtp"))
}

fn error(bytes: &[u8]) -> String {
    parse_bytes(bytes).unwrap_err().to_string()
}

const ASCII: &str = r#"<?xml version="1.0"?>
<VTKFile type="PolyData" version="0.1" byte_order="LittleEndian">
  <PolyData>
    <Piece NumberOfPoints="3" NumberOfVerts="0" NumberOfLines="0" NumberOfStrips="0" NumberOfPolys="0">
      <PointData Scalars="density">
        <DataArray type="Float32" Name="velocity" NumberOfComponents="3" format="ascii">0 0 0 1 1 1 2 2 2</DataArray>
        <DataArray type="Float64" Name="density" format="ascii">
          1.5 2.5 3.5
        </DataArray>
        <DataArray type="Float32" Name="Mass" format="ascii">1 2 3</DataArray>
        <DataArray type="Int32" Name="id" format="ascii">7 8 9</DataArray>
      </PointData>
      <Points>
        <DataArray type="Float32" Name="Points" NumberOfComponents="3" format="ascii">
          0 0 0 1 0 0 0 1 0.5
        </DataArray>
      </Points>
      <Verts><DataArray type="Int64" Name="connectivity" format="ascii">0 1 2</DataArray></Verts>
    </Piece>
  </PolyData>
</VTKFile>
"#;

#[test]
fn ascii_polydata() {
    let p = parse_bytes(ASCII.as_bytes()).unwrap();
    assert_eq!(p.positions, vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.5]]);
    assert_eq!(p.values, vec![1.5, 2.5, 3.5]);
    assert_eq!(p.value_name, "density");
    assert_eq!(p.masses, vec![1.0, 2.0, 3.0]);
    assert!(p.smoothing.is_empty());
}

fn zlib(bytes: &[u8]) -> Vec<u8> {
    let mut e = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
    e.write_all(bytes).unwrap();
    e.finish().unwrap()
}

fn b64(bytes: &[u8]) -> String {
    base64::engine::general_purpose::STANDARD.encode(bytes)
}

/// A zlib-compressed array as VTK writes it inline: the block header (UInt64 or UInt32 entries) and the blocks,
/// two base64 runs. `block` bytes a block.
fn compressed_inline_with(data: &[u8], block: usize, header_u64: bool) -> String {
    let blocks: Vec<Vec<u8>> = data.chunks(block).map(zlib).collect();
    let last = data.len() - (blocks.len() - 1) * block;
    let entries = [blocks.len(), block, if last == block { 0 } else { last }];
    let entries = entries.into_iter().chain(blocks.iter().map(Vec::len));
    let header: Vec<u8> = if header_u64 {
        entries.flat_map(|v| (v as u64).to_le_bytes()).collect()
    } else {
        entries.flat_map(|v| (v as u32).to_le_bytes()).collect()
    };
    format!("{}{}", b64(&header), b64(&blocks.concat()))
}

fn compressed_inline(data: &[u8], block: usize) -> String {
    compressed_inline_with(data, block, true)
}

fn le_bytes<T: Copy, const N: usize>(values: &[T], f: fn(T) -> [u8; N]) -> Vec<u8> {
    values.iter().flat_map(|&v| f(v)).collect()
}

#[test]
fn binary_zlib_compressed() {
    let points = le_bytes(&[0.0f64, 0.0, 0.0, 1.0, 2.0, 3.0, -1.0, 0.5, 9.0], f64::to_le_bytes);
    let hsml = le_bytes(&[0.1f32, 0.2, 0.3], f32::to_le_bytes);
    let text = format!(
        r#"<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian" header_type="UInt64" compressor="vtkZLibDataCompressor">
<PolyData><Piece NumberOfPoints="3">
<PointData><DataArray type="Float32" Name="hsml" format="binary">
  {}
</DataArray></PointData>
<Points><DataArray type="Float64" NumberOfComponents="3" format="binary">{}</DataArray></Points>
</Piece></PolyData></VTKFile>"#,
        compressed_inline(&hsml, 12),
        compressed_inline(&points, 32)
    );
    let p = parse_bytes(text.as_bytes()).unwrap();
    assert_eq!(p.positions, vec![[0.0; 3], [1.0, 2.0, 3.0], [-1.0, 0.5, 9.0]]);
    assert_eq!(p.smoothing, vec![0.1, 0.2, 0.3]);
    // A block header announcing a size the point count does not need.
    let lying = text.replace("NumberOfPoints=\"3\"", "NumberOfPoints=\"2\"");
    let e = error(lying.as_bytes());
    let expected = "line 6: DataArray 'Points': the compression header (3 blocks of 32 bytes, the last 8) does not \
                        add up to the 48 bytes";
    assert!(e.contains(expected), "{e}");
    // UInt32 block headers.
    let text32 = format!(
        r#"<VTKFile type="PolyData" compressor="vtkZLibDataCompressor"><PolyData><Piece NumberOfPoints="3">
<Points><DataArray type="Float64" NumberOfComponents="3" format="binary">{}</DataArray></Points>
</Piece></PolyData></VTKFile>"#,
        compressed_inline_with(&points, 40, false)
    );
    assert_eq!(parse_bytes(text32.as_bytes()).unwrap().positions, p.positions);
    // A zlib bomb: a consistent header announcing 12 MB from 10 compressed bytes is refused before inflating.
    let mut header = Vec::new();
    for v in [1u32, 12_000_000, 0, 10] {
        header.extend(v.to_le_bytes());
    }
    let bomb = format!(
        r#"<VTKFile type="PolyData" compressor="vtkZLibDataCompressor"><PolyData><Piece NumberOfPoints="1000000">
<Points><DataArray type="Float32" NumberOfComponents="3" format="binary">{}{}</DataArray></Points>
</Piece></PolyData></VTKFile>"#,
        b64(&header),
        b64(&[0x78, 0x9c, 0, 0, 0, 0, 0, 0, 0, 0])
    );
    assert_eq!(
        error(bomb.as_bytes()),
        "p.vtp line 2: DataArray 'Points': 10 compressed bytes cannot inflate to the 12000000 bytes the point \
             count needs (deflate expands at most 1032:1)"
    );
}

#[test]
fn binary_uncompressed_big_endian_one_or_two_runs() {
    let points: Vec<u8> = [1.0f32, 2.0, 3.0].iter().flat_map(|v| v.to_be_bytes()).collect();
    let mut one_run = 12u32.to_be_bytes().to_vec();
    one_run.extend(&points);
    let two_runs = format!("{}{}", b64(&12u32.to_be_bytes()), b64(&points));
    for encoded in [b64(&one_run), two_runs] {
        let text = format!(
            r#"<VTKFile type="PolyData" byte_order="BigEndian"><PolyData><Piece NumberOfPoints="1"><Points>
<DataArray type="Float32" NumberOfComponents="3" format="binary">{encoded}</DataArray></Points></Piece></PolyData></VTKFile>"#
        );
        assert_eq!(parse_bytes(text.as_bytes()).unwrap().positions, vec![[1.0, 2.0, 3.0]]);
    }
}

/// An appended raw file: two pieces, Int16 values and Float32 points.
fn appended_raw(value_name_second: &str) -> Vec<u8> {
    let mut data = Vec::new();
    let mut offsets = Vec::new();
    let arrays: [Vec<u8>; 4] = [
        le_bytes(&[0.0f32, 0.0, 0.0, 1.0, 1.0, 1.0], f32::to_le_bytes),
        le_bytes(&[-5i16, 6], i16::to_le_bytes),
        le_bytes(&[2.0f32, 2.0, 2.0], f32::to_le_bytes),
        le_bytes(&[7i16], i16::to_le_bytes),
    ];
    for a in &arrays {
        offsets.push(data.len());
        data.extend((a.len() as u32).to_le_bytes());
        data.extend(a);
    }
    let mut f = format!(
            r#"<?xml version="1.0"?>
<VTKFile type="PolyData" version="0.1" byte_order="LittleEndian">
<PolyData>
<Piece NumberOfPoints="2"><PointData><DataArray type="Int16" Name="T" format="appended" offset="{}"/></PointData>
<Points><DataArray type="Float32" NumberOfComponents="3" format="appended" offset="{}"/></Points></Piece>
<Piece NumberOfPoints="1"><PointData><DataArray type="Int16" Name="{value_name_second}" format="appended" offset="{}"/></PointData>
<Points><DataArray type="Float32" NumberOfComponents="3" format="appended" offset="{}"/></Points></Piece>
</PolyData>
<AppendedData encoding="raw">
_"#,
            offsets[1], offsets[0], offsets[3], offsets[2]
        )
        .into_bytes();
    f.extend(&data);
    f.extend(b"\n</AppendedData>\n</VTKFile>\n");
    f
}

#[test]
fn appended_raw_pieces() {
    let p = parse_bytes(&appended_raw("T")).unwrap();
    assert_eq!(p.positions, vec![[0.0; 3], [1.0; 3], [2.0; 3]]);
    assert_eq!(p.values, vec![-5.0, 6.0, 7.0]);
    assert_eq!(p.value_name, "T");
    assert_eq!(
        error(&appended_raw("U")),
        "p.vtp: piece 2 has no scalar array 'T' that piece 1 has: every piece needs the same arrays"
    );
    let file = appended_raw("T");
    for end in 0..file.len() {
        let _ = parse_bytes(&file[..end]);
    }
}

/// Pieces whose appended arrays all name the same data, which would decode to far more than the file holds.
fn shared_offsets(pieces: usize, points: usize, compressed: bool) -> Vec<u8> {
    let zeros = vec![0u8; points * 12];
    let data = if compressed {
        let block = zlib(&zeros);
        let mut data = le_bytes(&[1u32, zeros.len() as u32, 0, block.len() as u32], u32::to_le_bytes);
        data.extend(block);
        data
    } else {
        let mut data = (zeros.len() as u32).to_le_bytes().to_vec();
        data.extend(&zeros);
        data
    };
    let compressor = if compressed { r#" compressor="vtkZLibDataCompressor""# } else { "" };
    let piece = format!(
        r#"<Piece NumberOfPoints="{points}"><Points>{}</Points></Piece>"#,
        r#"<DataArray type="Float32" NumberOfComponents="3" format="appended" offset="0"/>"#
    );
    let mut f = format!(
        r#"<VTKFile type="PolyData"{compressor}><PolyData>{}</PolyData><AppendedData encoding="raw">_"#,
        piece.repeat(pieces)
    )
    .into_bytes();
    f.extend(data);
    f.extend(b"</AppendedData></VTKFile>");
    f
}

#[test]
fn appended_arrays_sharing_their_data_are_refused() {
    // Sharing within what the file holds is read.
    assert_eq!(parse_bytes(&shared_offsets(2, 1, false)).unwrap().positions, vec![[0.0; 3]; 2]);
    let e = error(&shared_offsets(3, 1000, false));
    assert!(e.contains("DataArray 'Points': with the arrays before it, 24000 bytes of data, more than the"), "{e}");
    assert!(e.ends_with("bytes can hold: arrays cannot share their data"), "{e}");
    // A zlib block of 1.2 MB of zeros, named by 3 pieces: one inflates within 1032:1, two do not.
    let e = error(&shared_offsets(3, 100_000, true));
    assert!(e.contains("with the arrays before it, 2400000 bytes of data"), "{e}");
    assert!(e.ends_with("can inflate to (deflate expands at most 1032:1): arrays cannot share their data"), "{e}");
}

#[test]
fn appended_base64_compressed() {
    let points = le_bytes(&[4.0f32, 5.0, 6.0], f32::to_le_bytes);
    let mass = le_bytes(&[3.0f64], f64::to_le_bytes);
    let first = compressed_inline(&mass, 8);
    let text = format!(
        r#"<VTKFile type="PolyData" header_type="UInt64" compressor="vtkZLibDataCompressor">
<PolyData><Piece NumberOfPoints="1"><PointData><DataArray type="Float64" Name="m" format="appended" offset="0"/></PointData>
<Points><DataArray type="Float32" NumberOfComponents="3" format="appended" offset="{}"/></Points></Piece></PolyData>
<AppendedData encoding="base64">
_{first}{}
</AppendedData></VTKFile>"#,
        first.len(),
        compressed_inline(&points, 12)
    );
    let p = parse_bytes(text.as_bytes()).unwrap();
    assert_eq!(p.positions, vec![[4.0, 5.0, 6.0]]);
    assert_eq!(p.masses, vec![3.0]);
}

/// The layout PySPH's `dump_vtk` (through pyvisfile) writes: an unstructured grid of one vertex cell per particle,
/// every array appended as its own base64 run of a UInt32 byte count and the values.
#[test]
fn unstructured_grid_as_pysph_writes_it() {
    let run = |data: Vec<u8>| b64(&[(data.len() as u32).to_le_bytes().to_vec(), data].concat());
    let arrays = [
        ("Float64", "rho", 1, run(le_bytes(&[1000.5f64, 1001.5], f64::to_le_bytes))),
        ("Float64", "m", 1, run(le_bytes(&[0.064f64, 0.064], f64::to_le_bytes))),
        ("Float64", "h", 1, run(le_bytes(&[0.052f64, 0.052], f64::to_le_bytes))),
        ("Float64", "velocity", 3, run(le_bytes(&[0.0f64, 1.0, 2.0, 3.0, 4.0, 5.0], f64::to_le_bytes))),
        ("Float64", "points", 3, run(le_bytes(&[0.1f64, 0.2, 0.3, 1.1, 1.2, 1.3], f64::to_le_bytes))),
        ("Int64", "connectivity", 1, run(le_bytes(&[0i64, 1], i64::to_le_bytes))),
    ];
    let mut offset = 0;
    let mut elements = Vec::new();
    for (ty, name, components, text) in &arrays {
        elements.push(format!(
                r#"<DataArray type="{ty}" Name="{name}" NumberOfComponents="{components}" format="appended" offset="{offset}"/>"#
            ));
        offset += text.len();
    }
    let appended: String = arrays.iter().map(|a| a.3.as_str()).collect();
    let text = format!(
        r#"<?xml version="1.0"?>
<VTKFile type="UnstructuredGrid" version="0.1" byte_order="LittleEndian">
<UnstructuredGrid>
<Piece NumberOfPoints="2" NumberOfCells="2">
<PointData>
{}
{}
{}
{}
</PointData>
<Points>
{}
</Points>
<Cells>
{}
</Cells>
</Piece>
</UnstructuredGrid>
<AppendedData encoding="base64">
_{appended}
</AppendedData>
</VTKFile>
"#,
        elements[0], elements[1], elements[2], elements[3], elements[4], elements[5]
    );
    let p = parse_dataset(text.as_bytes(), Path::new("p.vtu"), Dataset::UnstructuredGrid).unwrap();
    assert_eq!(p.positions, vec![[0.1, 0.2, 0.3], [1.1, 1.2, 1.3]]);
    assert_eq!(p.smoothing, vec![0.052, 0.052]);
    assert_eq!(p.masses, vec![0.064, 0.064]);
    assert_eq!(p.values, vec![1000.5, 1001.5]);
    assert_eq!(p.value_name, "rho");
    // The type must be what the name says.
    assert_eq!(
        error(text.as_bytes()),
        "p.vtp: unsupported: VTKFile type 'UnstructuredGrid': only PolyData is read from .vtp (name the file .vtu to \
             read it)"
    );
    let polydata = parse_dataset(ASCII.as_bytes(), Path::new("p.vtu"), Dataset::UnstructuredGrid);
    assert_eq!(
        polydata.unwrap_err().to_string(),
        "p.vtu: unsupported: VTKFile type 'PolyData': only UnstructuredGrid is read from .vtu (name the file .vtp to \
             read it)"
    );
}

#[test]
fn errors_name_the_problem() {
    let count = ASCII.replace("NumberOfPoints=\"3\"", "NumberOfPoints=\"4\"");
    assert_eq!(error(count.as_bytes()), "p.vtp line 14: DataArray 'Points': 9 values, the point count needs 12");
    let many = ASCII.replace("1.5 2.5 3.5", "1.5 2.5 3.5 4.5");
    assert_eq!(
        error(many.as_bytes()),
        "p.vtp line 7: DataArray 'density': more than the 3 values the point count needs"
    );
    let word = ASCII.replace("1.5 2.5", "1.5 x");
    assert_eq!(error(word.as_bytes()), "p.vtp line 7: DataArray 'density': 'x' is not a number");
    let two =
        ASCII.replace("NumberOfComponents=\"3\" format=\"ascii\">\n", "NumberOfComponents=\"2\" format=\"ascii\">\n");
    assert_eq!(error(two.as_bytes()), "p.vtp line 14: Points with 2 components (3 expected)");
    let huge = ASCII.replace("NumberOfPoints=\"3\"", "NumberOfPoints=\"18446744073709551615\"");
    assert!(error(huge.as_bytes()).contains("too many"));
    let big = ASCII.replace("NumberOfPoints=\"3\"", "NumberOfPoints=\"1000000000000\"");
    assert!(error(big.as_bytes()).contains("more than 4294967296 bytes in one array"));
    let grid = ASCII.replace("type=\"PolyData\"", "type=\"UnstructuredGrid\"");
    assert!(error(grid.as_bytes()).contains("unsupported: VTKFile type 'UnstructuredGrid'"));
    assert!(error(b"<VTKFile type=\"PolyData\"><PolyData><Piece></Piece></PolyData></VTKFile>")
        .contains("Piece has no NumberOfPoints"));
    assert!(error(b"<VTKFile type=\"PolyData\"><Piece NumberOfPoints=\"1\"></Piece></VTKFile>")
        .contains("piece 1 has 1 points but no Points array"));
    assert!(error(b"<a><b></a>").contains("malformed XML"));
    assert_eq!(error(b"hello"), "p.vtp: not a VTK XML file: no VTKFile element");
    let mut raw = b"<VTKFile type=\"PolyData\"><PolyData><Piece NumberOfPoints=\"1000\"><Points>\
            <DataArray type=\"Float32\" NumberOfComponents=\"3\" format=\"appended\" offset=\"0\"/></Points></Piece>\
            </PolyData><AppendedData encoding=\"raw\">_"
        .to_vec();
    raw.extend(12000u32.to_le_bytes());
    raw.extend(b"\0\0\0\0</AppendedData></VTKFile>");
    assert_eq!(error(&raw), "p.vtp line 1: DataArray 'Points': truncated data: 29 bytes of the 12000 announced");
}
