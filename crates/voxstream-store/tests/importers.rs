//! Every importer against a synthetic volume written in its format: level 0 of the store must equal the source
//! exactly, geometry must be kept, and bad files must fail with a clear error naming the file.

use std::io::Write;
use std::path::{Path, PathBuf};

use voxstream_store::formats::{open_volume, Endian, RawLayout};
use voxstream_store::{import_volume, DType, ImportOptions, StoreError, StoreReader, VolumeInfo};

const DIMS: [u64; 3] = [37, 29, 23];

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("voxstream-import-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The test volume's value at (i, j, k), representable exactly in every type.
fn value(i: u64, j: u64, k: u64, dtype: DType) -> f32 {
    let v = ((i * 7 + j * 13 + k * 3) % 251) as f32;
    match dtype {
        DType::U8 => v,
        DType::U16 => v * 200.0,
        DType::I16 => v * 100.0 - 12000.0,
        DType::F32 => v * 0.37 - 20.25,
    }
}

fn samples(dtype: DType) -> Vec<f32> {
    let mut out = Vec::new();
    for k in 0..DIMS[2] {
        for j in 0..DIMS[1] {
            for i in 0..DIMS[0] {
                out.push(value(i, j, k, dtype));
            }
        }
    }
    out
}

fn encode(dtype: DType, endian: Endian) -> Vec<u8> {
    let big = endian == Endian::Big;
    samples(dtype)
        .into_iter()
        .flat_map(|v| -> Vec<u8> {
            match dtype {
                DType::U8 => vec![v as u8],
                DType::U16 => {
                    if big {
                        (v as u16).to_be_bytes().to_vec()
                    } else {
                        (v as u16).to_le_bytes().to_vec()
                    }
                }
                DType::I16 => {
                    if big {
                        (v as i16).to_be_bytes().to_vec()
                    } else {
                        (v as i16).to_le_bytes().to_vec()
                    }
                }
                DType::F32 => {
                    if big {
                        v.to_be_bytes().to_vec()
                    } else {
                        v.to_le_bytes().to_vec()
                    }
                }
            }
        })
        .collect()
}

fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut encoder = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    encoder.write_all(bytes).unwrap();
    encoder.finish().unwrap()
}

fn zlib(bytes: &[u8]) -> Vec<u8> {
    let mut encoder = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
    encoder.write_all(bytes).unwrap();
    encoder.finish().unwrap()
}

/// Imports `path` and checks level 0 and the geometry.
fn check_import(path: &Path, raw: Option<&RawLayout>, dtype: DType, spacing: [f64; 3], origin: [f64; 3]) {
    let dir = path.parent().unwrap();
    let store = dir.join(format!("{}.zarr", path.file_name().unwrap().to_string_lossy()));
    let mut source = open_volume(path, raw).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(source.info().dims, DIMS);
    assert_eq!(source.info().dtype, dtype);
    let options = ImportOptions { brick_size: 8, shard_bricks: 2, ..ImportOptions::default() };
    import_volume(source.as_mut(), &store, &options, &mut |_, _| {})
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let reader = StoreReader::open(&store).unwrap();
    assert_eq!(reader.info().dtype, dtype, "{}", path.display());
    for a in 0..3 {
        assert!(
            (reader.info().spacing[a] - spacing[a]).abs() < 1e-6,
            "{}: spacing {:?}",
            path.display(),
            reader.info().spacing
        );
        assert!(
            (reader.info().origin[a] - origin[a]).abs() < 1e-6,
            "{}: origin {:?}",
            path.display(),
            reader.info().origin
        );
    }
    let level0 = reader.read_region(0, [0, 0, 0], DIMS).unwrap();
    assert!(level0 == samples(dtype), "{}: level 0 differs from the source", path.display());
    // The pyramid: 37 → 19 → 10 → 5 samples; the last level fits one brick of 8.
    assert_eq!(reader.layout().levels(), 4);
    // Level 1 averages 2×2×2 blocks.
    let coarse = reader.read_region(1, [0, 0, 0], [1, 1, 1]).unwrap()[0];
    let mut mean = 0.0;
    for (i, j, k) in [(0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0), (0, 0, 1), (1, 0, 1), (0, 1, 1), (1, 1, 1)] {
        mean += value(i, j, k, dtype) as f64 / 8.0;
    }
    let tolerance = if dtype == DType::F32 { 1e-3 } else { 0.5 };
    assert!((coarse as f64 - mean).abs() <= tolerance, "{}: level 1 {coarse} vs mean {mean}", path.display());
}

fn nrrd_header(dtype: &str, encoding: &str, data_file: Option<&str>) -> String {
    let mut h = format!(
        "NRRD0004\n# test\ntype: {dtype}\ndimension: 3\nspace: left-posterior-superior\nsizes: {} {} {}\n\
         space directions: (0.5,0,0) (0,0.75,0) (0,0,2)\nendian: little\nencoding: {encoding}\n\
         space origin: (-1,2.5,3)\n",
        DIMS[0], DIMS[1], DIMS[2]
    );
    if let Some(file) = data_file {
        h.push_str(&format!("data file: {file}\n"));
    }
    h.push('\n');
    h
}

#[test]
fn nrrd_raw_gzip_and_detached() {
    let dir = scratch("nrrd");
    let spacing = [0.5, 0.75, 2.0];
    let origin = [-1.0, 2.5, 3.0];
    let mut attached = nrrd_header("short", "raw", None).into_bytes();
    attached.extend(encode(DType::I16, Endian::Little));
    std::fs::write(dir.join("a.nrrd"), attached).unwrap();
    check_import(&dir.join("a.nrrd"), None, DType::I16, spacing, origin);

    let mut compressed = nrrd_header("float", "gzip", None).into_bytes();
    compressed.extend(gzip(&encode(DType::F32, Endian::Little)));
    std::fs::write(dir.join("b.nrrd"), compressed).unwrap();
    check_import(&dir.join("b.nrrd"), None, DType::F32, spacing, origin);

    std::fs::write(dir.join("c.nhdr"), nrrd_header("ushort", "raw", Some("c.raw"))).unwrap();
    std::fs::write(dir.join("c.raw"), encode(DType::U16, Endian::Little)).unwrap();
    check_import(&dir.join("c.nhdr"), None, DType::U16, spacing, origin);
}

fn nifti(dtype: DType, code: i16, bitpix: i16) -> Vec<u8> {
    let mut h = vec![0u8; 352];
    h[0..4].copy_from_slice(&348i32.to_le_bytes());
    let dims = [3i16, DIMS[0] as i16, DIMS[1] as i16, DIMS[2] as i16, 1, 1, 1, 1];
    for (n, d) in dims.iter().enumerate() {
        h[40 + 2 * n..42 + 2 * n].copy_from_slice(&d.to_le_bytes());
    }
    h[70..72].copy_from_slice(&code.to_le_bytes());
    h[72..74].copy_from_slice(&bitpix.to_le_bytes());
    for (n, p) in [1.0f32, 1.5, 0.8, 2.0].iter().enumerate() {
        h[76 + 4 * n..80 + 4 * n].copy_from_slice(&p.to_le_bytes());
    }
    h[108..112].copy_from_slice(&352f32.to_le_bytes());
    h[252..254].copy_from_slice(&1i16.to_le_bytes());
    for (n, o) in [-90.0f32, -126.0, -72.0].iter().enumerate() {
        h[268 + 4 * n..272 + 4 * n].copy_from_slice(&o.to_le_bytes());
    }
    h[344..348].copy_from_slice(b"n+1\0");
    h.extend(encode(dtype, Endian::Little));
    h
}

#[test]
fn nifti_plain_and_gzip() {
    let dir = scratch("nifti");
    let spacing = [1.5, 0.800000011920929, 2.0];
    let origin = [-90.0, -126.0, -72.0];
    std::fs::write(dir.join("a.nii"), nifti(DType::U8, 2, 8)).unwrap();
    check_import(&dir.join("a.nii"), None, DType::U8, spacing, origin);
    std::fs::write(dir.join("b.nii.gz"), gzip(&nifti(DType::U16, 512, 16))).unwrap();
    check_import(&dir.join("b.nii.gz"), None, DType::U16, spacing, origin);
}

#[test]
fn metaimage_local_compressed_and_detached() {
    let dir = scratch("mha");
    let header =
        |element: &str, compressed: bool, file: &str| {
            format!(
            "ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\nCompressedData = {}\n\
             Offset = 1 2 3\nElementSpacing = 0.25 0.5 4\nDimSize = {} {} {}\nElementType = {element}\n\
             ElementDataFile = {file}\n",
            if compressed { "True" } else { "False" },
            DIMS[0], DIMS[1], DIMS[2]
        )
        };
    let spacing = [0.25, 0.5, 4.0];
    let origin = [1.0, 2.0, 3.0];
    let mut local = header("MET_SHORT", false, "LOCAL").into_bytes();
    local.extend(encode(DType::I16, Endian::Little));
    std::fs::write(dir.join("a.mha"), local).unwrap();
    check_import(&dir.join("a.mha"), None, DType::I16, spacing, origin);

    let mut compressed = header("MET_FLOAT", true, "LOCAL").into_bytes();
    compressed.extend(zlib(&encode(DType::F32, Endian::Little)));
    std::fs::write(dir.join("b.mha"), compressed).unwrap();
    check_import(&dir.join("b.mha"), None, DType::F32, spacing, origin);

    std::fs::write(dir.join("c.mhd"), header("MET_UCHAR", false, "c.raw")).unwrap();
    std::fs::write(dir.join("c.raw"), encode(DType::U8, Endian::Little)).unwrap();
    check_import(&dir.join("c.mhd"), None, DType::U8, spacing, origin);
}

fn inr(kind: &str, bits: u32, cpu: &str, endian: Endian, dtype: DType) -> Vec<u8> {
    let mut header = format!(
        "#INRIMAGE-4#{{\nXDIM={}\nYDIM={}\nZDIM={}\nVDIM=1\nTYPE={kind}\nPIXSIZE={bits} bits\nCPU={cpu}\nVX=0.5\nVY=0.5\nVZ=1.25\n",
        DIMS[0], DIMS[1], DIMS[2]
    );
    while header.len() < 252 {
        header.push('\n');
    }
    header.push_str("##}\n");
    let mut bytes = header.into_bytes();
    bytes.extend(encode(dtype, endian));
    bytes
}

#[test]
fn inr_plain_and_gzip() {
    let dir = scratch("inr");
    std::fs::write(dir.join("a.inr"), inr("unsigned fixed", 8, "decm", Endian::Little, DType::U8)).unwrap();
    check_import(&dir.join("a.inr"), None, DType::U8, [0.5, 0.5, 1.25], [0.0; 3]);
    std::fs::write(dir.join("b.inr.gz"), gzip(&inr("float", 32, "sun", Endian::Big, DType::F32))).unwrap();
    check_import(&dir.join("b.inr.gz"), None, DType::F32, [0.5, 0.5, 1.25], [0.0; 3]);
}

#[test]
fn npy_and_raw() {
    let dir = scratch("npy");
    let npy = voxstream_store::formats::npy::npy_bytes(
        "<i2",
        [DIMS[2], DIMS[1], DIMS[0]],
        &encode(DType::I16, Endian::Little),
    );
    std::fs::write(dir.join("a.npy"), npy).unwrap();
    check_import(&dir.join("a.npy"), None, DType::I16, [1.0; 3], [0.0; 3]);

    let mut raw = vec![7u8; 62];
    raw.extend(encode(DType::U16, Endian::Big));
    std::fs::write(dir.join("b.den"), raw).unwrap();
    let layout = RawLayout {
        info: VolumeInfo {
            dims: DIMS,
            dtype: DType::U16,
            spacing: [2.0, 2.0, 3.0],
            origin: [5.0, 0.0, -5.0],
            unit: None,
            orientation: None,
        },
        file_type: None,
        endian: Endian::Big,
        header_bytes: 62,
    };
    check_import(&dir.join("b.den"), Some(&layout), DType::U16, [2.0, 2.0, 3.0], [5.0, 0.0, -5.0]);
}

fn import_error(path: &Path, raw: Option<&RawLayout>) -> StoreError {
    let store = path.with_extension("zarr");
    let result = open_volume(path, raw)
        .and_then(|mut source| import_volume(source.as_mut(), &store, &ImportOptions::default(), &mut |_, _| {}));
    let error = result.expect_err("bad input was accepted");
    assert!(!store.exists(), "a failed import left a store");
    assert!(!voxstream_store::import::partial_path(&store).exists(), "a failed import left a partial store");
    error
}

#[test]
fn bad_files_fail_naming_the_file_and_the_problem() {
    let dir = scratch("bad");
    // Truncated NRRD (raw and gzip), NIfTI and npy.
    let mut short = nrrd_header("short", "raw", None).into_bytes();
    short.extend(&encode(DType::I16, Endian::Little)[..1000]);
    std::fs::write(dir.join("short.nrrd"), short).unwrap();
    let e = import_error(&dir.join("short.nrrd"), None).to_string();
    assert!(e.contains("short.nrrd") && e.contains("truncated"), "{e}");

    let mut short_gz = nrrd_header("short", "gzip", None).into_bytes();
    short_gz.extend(gzip(&encode(DType::I16, Endian::Little)[..5000]));
    std::fs::write(dir.join("shortgz.nrrd"), short_gz).unwrap();
    let e = import_error(&dir.join("shortgz.nrrd"), None).to_string();
    assert!(e.contains("shortgz.nrrd") && e.contains("truncated"), "{e}");

    let nii = nifti(DType::U8, 2, 8);
    std::fs::write(dir.join("short.nii"), &nii[..nii.len() - 10]).unwrap();
    let e = import_error(&dir.join("short.nii"), None).to_string();
    assert!(e.contains("short.nii") && e.contains("truncated"), "{e}");

    // Header and size disagree: a raw file larger than its layout.
    std::fs::write(dir.join("big.raw"), vec![0u8; 100_000]).unwrap();
    let layout = RawLayout {
        info: VolumeInfo {
            dims: DIMS,
            dtype: DType::U8,
            spacing: [1.0; 3],
            origin: [0.0; 3],
            unit: None,
            orientation: None,
        },
        file_type: None,
        endian: Endian::Little,
        header_bytes: 0,
    };
    let e = import_error(&dir.join("big.raw"), Some(&layout)).to_string();
    assert!(e.contains("big.raw") && e.contains("--dims"), "{e}");

    // Unsupported type, wrong magic, nonsense dimensions.
    let mut long = nrrd_header("int64", "raw", None).into_bytes();
    long.extend(vec![0u8; 8]);
    std::fs::write(dir.join("long.nrrd"), long).unwrap();
    let e = import_error(&dir.join("long.nrrd"), None).to_string();
    assert!(e.contains("unsupported") && e.contains("int64"), "{e}");
    std::fs::write(dir.join("fake.nii"), vec![1u8; 400]).unwrap();
    assert!(import_error(&dir.join("fake.nii"), None).to_string().contains("not a NIfTI-1 file"));
    let zero = "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 0 4 4\nencoding: raw\n\n";
    std::fs::write(dir.join("zero.nrrd"), zero).unwrap();
    assert!(import_error(&dir.join("zero.nrrd"), None).to_string().contains("positive"));
    std::fs::write(dir.join("garbage.vdb"), b"not a vdb at all").unwrap();
    let e = import_error(&dir.join("garbage.vdb"), None).to_string();
    assert!(e.contains("garbage.vdb") && e.contains("VDB"), "{e}");
    std::fs::write(dir.join("what.xyz"), b"hello").unwrap();
    assert!(import_error(&dir.join("what.xyz"), None).to_string().contains("unknown format"));
}

#[test]
fn existing_store_is_kept_unless_overwritten_and_interrupted_imports_never_open() {
    let dir = scratch("overwrite");
    let mut bytes = nrrd_header("uchar", "raw", None).into_bytes();
    bytes.extend(encode(DType::U8, Endian::Little));
    std::fs::write(dir.join("v.nrrd"), bytes).unwrap();
    let store = dir.join("v.zarr");
    let run = |overwrite: bool| {
        let mut source = open_volume(&dir.join("v.nrrd"), None).unwrap();
        let options = ImportOptions { overwrite, ..ImportOptions::default() };
        import_volume(source.as_mut(), &store, &options, &mut |_, _| {})
    };
    run(false).unwrap();
    let e = run(false).unwrap_err().to_string();
    assert!(e.contains("already exists"), "{e}");
    assert!(StoreReader::open(&store).is_ok(), "the existing store survives a refused import");
    run(true).unwrap();
    // An interrupted import leaves only STORE.partial: the store does not open, and a new import restarts cleanly.
    let other = dir.join("w.zarr");
    std::fs::create_dir_all(voxstream_store::import::partial_path(&other)).unwrap();
    let e = StoreReader::open(&other).err().unwrap().to_string();
    assert!(e.contains("interrupted"), "{e}");
    let mut source = open_volume(&dir.join("v.nrrd"), None).unwrap();
    import_volume(source.as_mut(), &other, &ImportOptions::default(), &mut |_, _| {}).unwrap();
    assert!(StoreReader::open(&other).is_ok());
}

#[test]
fn one_import_per_store_the_second_refuses_touching_nothing() {
    use voxstream_store::import::{aside_path, partial_path};
    let dir = scratch("lock");
    let mut bytes = nrrd_header("uchar", "raw", None).into_bytes();
    bytes.extend(encode(DType::U8, Endian::Little));
    std::fs::write(dir.join("a.nrrd"), bytes).unwrap();
    let mut bytes = nrrd_header("ushort", "raw", None).into_bytes();
    bytes.extend(encode(DType::U16, Endian::Little));
    std::fs::write(dir.join("b.nrrd"), bytes).unwrap();
    let store = dir.join("v.zarr");
    let options = |overwrite: bool| ImportOptions { brick_size: 8, overwrite, ..ImportOptions::default() };
    let import = |input: &str, overwrite: bool, progress: &mut dyn FnMut(u64, u64)| {
        let mut source = open_volume(&dir.join(input), None).unwrap();
        import_volume(source.as_mut(), &store, &options(overwrite), progress)
    };
    // A good store, then a leftover aside folder beside it, as a kill after the swap leaves.
    import("a.nrrd", false, &mut |_, _| {}).unwrap();
    let leftover = aside_path(&store, 4_000_000_000);
    std::fs::create_dir_all(leftover.join("0")).unwrap();
    for overwrite in [false, true] {
        // While `b` is being imported with --overwrite, a second import of the same store (with or without
        // --overwrite) is refused and neither deletes the first one's partial store nor touches the store.
        let mut refusals = Vec::new();
        let mut during = |_: u64, _: u64| {
            assert!(!leftover.exists(), "the leftover aside folder survived into the import");
            let error = import("a.nrrd", overwrite, &mut |_, _| panic!("the second import wrote")).unwrap_err();
            assert!(partial_path(&store).is_dir(), "the refused import deleted the running one's partial store");
            assert_eq!(StoreReader::open(&store).unwrap().info().dtype, DType::U8, "the store changed mid-import");
            refusals.push(error);
        };
        import("b.nrrd", true, &mut during).unwrap();
        assert!(!refusals.is_empty());
        for error in &refusals {
            assert!(matches!(error, StoreError::Busy { pid: Some(pid), .. } if *pid == std::process::id()), "{error}");
            let text = error.to_string();
            assert!(text.starts_with(&format!("another import is writing {}", store.display())), "{text}");
        }
        // The winner's store is in place, whole; nothing is left beside it.
        let reader = StoreReader::open(&store).unwrap();
        assert_eq!(reader.info().dtype, DType::U16);
        assert!(reader.read_region(0, [0, 0, 0], DIMS).unwrap() == samples(DType::U16));
        let beside: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with("v.zarr."))
            .collect();
        assert!(beside.is_empty(), "{beside:?}");
        import("a.nrrd", true, &mut |_, _| {}).unwrap();
        std::fs::create_dir_all(leftover.join("0")).unwrap();
    }
    // With the store missing, an aside folder is its only whole copy: kept while the new store is written.
    std::fs::remove_dir_all(&store).unwrap();
    let mut seen = false;
    import("b.nrrd", false, &mut |_, _| seen |= leftover.is_dir()).unwrap();
    assert!(seen, "the only copy of the store was deleted before the new one was in place");
}

#[test]
fn vti_appended_raw_inline_compressed_and_ascii() {
    let dir = scratch("vti");
    let extent = format!("2 {} 0 {} 1 {}", 2 + DIMS[0] - 1, DIMS[1] - 1, DIMS[2]);
    // Appended raw, UInt64 header, no compression, Int16.
    let data = encode(DType::I16, Endian::Little);
    let mut file = format!(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"ImageData\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">\n\
         <ImageData WholeExtent=\"{extent}\" Origin=\"10 20 30\" Spacing=\"0.5 0.25 2\">\n<Piece Extent=\"{extent}\">\n\
         <PointData Scalars=\"s\"><DataArray type=\"Int16\" Name=\"s\" format=\"appended\" offset=\"0\"/></PointData>\n\
         </Piece></ImageData>\n<AppendedData encoding=\"raw\">\n_"
    )
    .into_bytes();
    file.extend((data.len() as u64).to_le_bytes());
    file.extend(&data);
    file.extend(b"\n</AppendedData>\n</VTKFile>\n");
    std::fs::write(dir.join("a.vti"), file).unwrap();
    // Origin shifts by the extent's start: 10 + 0.5·2, 20, 30 + 2·1.
    check_import(&dir.join("a.vti"), None, DType::I16, [0.5, 0.25, 2.0], [11.0, 20.0, 32.0]);

    // Inline base64, zlib in two blocks, UInt32 headers, Float32.
    let data = encode(DType::F32, Endian::Little);
    let block = 40_000usize;
    let chunks: Vec<&[u8]> = data.chunks(block).collect();
    let compressed: Vec<Vec<u8>> = chunks.iter().map(|c| zlib(c)).collect();
    let mut header = Vec::new();
    for v in [chunks.len(), block, chunks.last().unwrap().len()] {
        header.extend((v as u32).to_le_bytes());
    }
    for c in &compressed {
        header.extend((c.len() as u32).to_le_bytes());
    }
    use base64::Engine;
    let b64 = base64::engine::general_purpose::STANDARD;
    let payload = format!("{}{}", b64.encode(&header), b64.encode(compressed.concat()));
    let file = format!(
        "<VTKFile type=\"ImageData\" version=\"0.1\" byte_order=\"LittleEndian\" header_type=\"UInt32\" compressor=\"vtkZLibDataCompressor\">\n\
         <ImageData WholeExtent=\"0 {} 0 {} 0 {}\" Origin=\"0 0 0\" Spacing=\"1 1 1\"><Piece>\n\
         <PointData><DataArray type=\"Float32\" Name=\"f\" format=\"binary\">\n{payload}\n</DataArray></PointData>\n\
         </Piece></ImageData></VTKFile>\n",
        DIMS[0] - 1, DIMS[1] - 1, DIMS[2] - 1
    );
    std::fs::write(dir.join("b.vti"), file).unwrap();
    check_import(&dir.join("b.vti"), None, DType::F32, [1.0; 3], [0.0; 3]);

    // ASCII UInt8.
    let text: Vec<String> = samples(DType::U8).iter().map(|v| (*v as u8).to_string()).collect();
    let file = format!(
        "<VTKFile type=\"ImageData\" byte_order=\"LittleEndian\"><ImageData WholeExtent=\"0 {} 0 {} 0 {}\" Spacing=\"1 1 1\">\n\
         <Piece><PointData><DataArray type=\"UInt8\" format=\"ascii\">{}</DataArray></PointData></Piece></ImageData></VTKFile>",
        DIMS[0] - 1, DIMS[1] - 1, DIMS[2] - 1, text.join(" ")
    );
    std::fs::write(dir.join("c.vti"), file).unwrap();
    check_import(&dir.join("c.vti"), None, DType::U8, [1.0; 3], [0.0; 3]);

    // Truncated compressed data is an error naming the file.
    let cut = std::fs::read_to_string(dir.join("b.vti")).unwrap().replace(&payload, &payload[..payload.len() / 2]);
    std::fs::write(dir.join("cut.vti"), cut).unwrap();
    let e = import_error(&dir.join("cut.vti"), None).to_string();
    assert!(e.contains("cut.vti"), "{e}");
}

#[test]
fn tiff_multipage_and_folder_of_slices() {
    use tiff::encoder::{colortype, TiffEncoder};
    let dir = scratch("tiff");
    let values = samples(DType::U16);
    let slice = (DIMS[0] * DIMS[1]) as usize;
    {
        let file = std::fs::File::create(dir.join("stack.tif")).unwrap();
        let mut encoder = TiffEncoder::new(file).unwrap();
        for z in 0..DIMS[2] as usize {
            let page: Vec<u16> = values[z * slice..(z + 1) * slice].iter().map(|&v| v as u16).collect();
            encoder.write_image::<colortype::Gray16>(DIMS[0] as u32, DIMS[1] as u32, &page).unwrap();
        }
    }
    check_import(&dir.join("stack.tif"), None, DType::U16, [1.0; 3], [0.0; 3]);

    let folder = dir.join("slices");
    std::fs::create_dir_all(&folder).unwrap();
    let floats = samples(DType::F32);
    for z in 0..DIMS[2] as usize {
        let file = std::fs::File::create(folder.join(format!("slice_{z:03}.tiff"))).unwrap();
        let mut encoder = TiffEncoder::new(file).unwrap();
        encoder
            .write_image::<colortype::Gray32Float>(DIMS[0] as u32, DIMS[1] as u32, &floats[z * slice..(z + 1) * slice])
            .unwrap();
    }
    check_import(&folder, None, DType::F32, [1.0; 3], [0.0; 3]);

    // A slice of another size is an error naming it.
    let file = std::fs::File::create(folder.join("slice_999.tiff")).unwrap();
    TiffEncoder::new(file).unwrap().write_image::<colortype::Gray32Float>(3, 3, &[0.0; 9]).unwrap();
    std::fs::remove_dir_all(dir.join("slices.zarr")).unwrap();
    let e = import_error(&folder, None).to_string();
    assert!(e.contains("slice_999.tiff"), "{e}");
}

#[test]
fn tiff_folder_members_of_several_pages_give_every_page_in_order() {
    use tiff::encoder::{colortype, TiffEncoder};
    let folder = scratch("tiff-pages").join("slices");
    std::fs::create_dir_all(&folder).unwrap();
    let values = samples(DType::U16);
    let slice = (DIMS[0] * DIMS[1]) as usize;
    let page = |z: usize| -> Vec<u16> { values[z * slice..(z + 1) * slice].iter().map(|&v| v as u16).collect() };
    // Files 0..10 hold one slice each, file 10 holds slices 10, 11 and 12, the rest one each again.
    let mut z = 0;
    for file_index in 0..DIMS[2] as usize - 2 {
        let file = std::fs::File::create(folder.join(format!("slice_{file_index:03}.tif"))).unwrap();
        let mut encoder = TiffEncoder::new(file).unwrap();
        for _ in 0..if file_index == 10 { 3 } else { 1 } {
            encoder.write_image::<colortype::Gray16>(DIMS[0] as u32, DIMS[1] as u32, &page(z)).unwrap();
            z += 1;
        }
    }
    check_import(&folder, None, DType::U16, [1.0; 3], [0.0; 3]);

    // A page of another size in a multi-page member is refused, naming the file and the page.
    let file = std::fs::File::create(folder.join("slice_010.tif")).unwrap();
    let mut encoder = TiffEncoder::new(file).unwrap();
    encoder.write_image::<colortype::Gray16>(DIMS[0] as u32, DIMS[1] as u32, &page(10)).unwrap();
    encoder.write_image::<colortype::Gray16>(3, 3, &[0; 9]).unwrap();
    std::fs::remove_dir_all(folder.with_file_name("slices.zarr")).unwrap();
    let e = import_error(&folder, None).to_string();
    assert!(e.contains("slice_010.tif") && e.contains("page 1 is 3x3"), "{e}");
}

#[test]
fn nifti_datatype_and_bitpix_must_agree() {
    let dir = scratch("nifti-bitpix");
    // uint8 samples announced as 16 bits: reading either way reads the wrong bytes.
    std::fs::write(dir.join("u8-16.nii"), nifti(DType::U8, 2, 16)).unwrap();
    let e = import_error(&dir.join("u8-16.nii"), None).to_string();
    assert!(e.contains("u8-16.nii") && e.contains("datatype 2 (uint8, 8 bits) and bitpix 16 disagree"), "{e}");
    std::fs::write(dir.join("f32-8.nii"), nifti(DType::F32, 16, 8)).unwrap();
    let e = import_error(&dir.join("f32-8.nii"), None).to_string();
    assert!(e.contains("datatype 16 (float32, 32 bits) and bitpix 8 disagree"), "{e}");
    assert_eq!(e.lines().count(), 1, "{e}");
}

#[test]
fn nifti_scaling_is_applied_as_float() {
    let dir = scratch("nifti-scale");
    let mut bytes = nifti(DType::I16, 4, 16);
    bytes[112..116].copy_from_slice(&0.5f32.to_le_bytes());
    bytes[116..120].copy_from_slice(&(-3.0f32).to_le_bytes());
    std::fs::write(dir.join("s.nii"), bytes).unwrap();
    let mut source = open_volume(&dir.join("s.nii"), None).unwrap();
    assert_eq!(source.info().dtype, DType::F32);
    let store = dir.join("s.zarr");
    import_volume(source.as_mut(), &store, &ImportOptions::default(), &mut |_, _| {}).unwrap();
    let level0 = StoreReader::open(&store).unwrap().read_region(0, [0, 0, 0], DIMS).unwrap();
    let expected: Vec<f32> = samples(DType::I16).iter().map(|v| v * 0.5 - 3.0).collect();
    assert!(level0 == expected);
}

#[test]
fn npz_stored_and_deflated() {
    use std::io::Write;
    let dir = scratch("npz");
    let npy = voxstream_store::formats::npy::npy_bytes(
        "<u2",
        [DIMS[2], DIMS[1], DIMS[0]],
        &encode(DType::U16, Endian::Little),
    );
    for (name, method) in
        [("stored.npz", zip::CompressionMethod::Stored), ("deflated.npz", zip::CompressionMethod::Deflated)]
    {
        let file = std::fs::File::create(dir.join(name)).unwrap();
        let mut writer = zip::ZipWriter::new(file);
        let options = zip::write::SimpleFileOptions::default().compression_method(method);
        writer.start_file("volume.npy", options).unwrap();
        writer.write_all(&npy).unwrap();
        writer.finish().unwrap();
        check_import(&dir.join(name), None, DType::U16, [1.0; 3], [0.0; 3]);
    }
}

#[test]
fn multi_member_gzip_imports_and_every_member_is_checked() {
    let dir = scratch("members");
    // Two gzip members (as pigz or bgzip write them) hold one volume.
    let data = encode(DType::U16, Endian::Little);
    let (first, second) = data.split_at(data.len() / 3);
    let mut file = nrrd_header("ushort", "gzip", None).into_bytes();
    file.extend(gzip(first));
    let second_at = file.len();
    file.extend(gzip(second));
    std::fs::write(dir.join("members.nrrd"), &file).unwrap();
    check_import(&dir.join("members.nrrd"), None, DType::U16, [0.5, 0.75, 2.0], [-1.0, 2.5, 3.0]);

    // The first member's CRC is checked too, not only the last one's.
    let mut bad = file.clone();
    bad[second_at - 8] ^= 0x55;
    std::fs::write(dir.join("badfirst.nrrd"), &bad).unwrap();
    let e = import_error(&dir.join("badfirst.nrrd"), None).to_string();
    assert!(e.contains("badfirst.nrrd") && e.contains("checksum"), "{e}");
}

#[test]
fn vti_block_sizes_must_add_up_before_anything_inflates() {
    let dir = scratch("vti-blocks");
    let data = encode(DType::U8, Endian::Little);
    let block = zlib(&data);
    let vti = |blocks: u64, block_size: u64, last: u64| {
        let mut bytes = format!(
            "<?xml version=\"1.0\"?>\n<VTKFile type=\"ImageData\" byte_order=\"LittleEndian\" \
             compressor=\"vtkZLibDataCompressor\">\n<ImageData WholeExtent=\"0 {} 0 {} 0 {}\">\n<Piece>\n<PointData>\n\
             <DataArray type=\"UInt8\" format=\"appended\" offset=\"0\"/>\n</PointData>\n</Piece>\n</ImageData>\n\
             <AppendedData encoding=\"raw\">\n_",
            DIMS[0] - 1,
            DIMS[1] - 1,
            DIMS[2] - 1
        )
        .into_bytes();
        for v in [blocks as u32, block_size as u32, last as u32, block.len() as u32] {
            bytes.extend(v.to_le_bytes());
        }
        bytes.extend(&block);
        bytes.extend(b"\n</AppendedData>\n</VTKFile>\n");
        bytes
    };
    let n = data.len() as u64;
    std::fs::write(dir.join("good.vti"), vti(1, n, n)).unwrap();
    check_import(&dir.join("good.vti"), None, DType::U8, [1.0; 3], [0.0; 3]);
    // The header claims a block smaller than what the extent needs: refused before inflating.
    std::fs::write(dir.join("short.vti"), vti(1, n - 1, n - 1)).unwrap();
    let e = import_error(&dir.join("short.vti"), None).to_string();
    assert!(e.contains("short.vti") && e.contains("does not add up"), "{e}");
}

/// The orientation `open_volume` reads from `bytes` written as `name`, as three letters.
fn orientation_of(dir: &Path, name: &str, bytes: &[u8]) -> Option<String> {
    std::fs::write(dir.join(name), bytes).unwrap();
    open_volume(&dir.join(name), None).unwrap().info().orientation.map(|o| o.code())
}

#[test]
fn anatomical_orientations_come_from_each_formats_header() {
    let dir = scratch("orientation");
    let samples = encode(DType::U8, Endian::Little);
    let with = |header: String| [header.into_bytes(), samples.clone()].concat();
    // NRRD: `space directions` in the anatomical `space` (LPS: x and y flipped into RAS); none without a space.
    let nrrd = |space: &str, directions: &str| {
        format!(
            "NRRD0004\ntype: uchar\ndimension: 3\n{space}sizes: {} {} {}\nspace directions: {directions}\n\
             encoding: raw\n\n",
            DIMS[0], DIMS[1], DIMS[2]
        )
    };
    let oblique = "(0,-0.5,0.01) (0,0,0.75) (2,0.1,0)";
    assert_eq!(orientation_of(&dir, "a.nrrd", &with(nrrd("space: LPS\n", oblique))).as_deref(), Some("ASL"));
    assert_eq!(
        orientation_of(&dir, "b.nrrd", &with(nrrd("space: right-anterior-superior\n", oblique))).as_deref(),
        Some("PSR")
    );
    assert_eq!(orientation_of(&dir, "c.nrrd", &with(nrrd("space: 3D-right-handed\n", oblique))), None);
    // NIfTI: the qform's quaternion (90° about z: x to the front, y to the left), its qfac flipping k; the sform's
    // columns when there is no qform; neither: none.
    let mut h = nifti(DType::U8, 2, 8);
    let half = std::f32::consts::FRAC_1_SQRT_2;
    h[264..268].copy_from_slice(&half.to_le_bytes());
    assert_eq!(orientation_of(&dir, "q.nii", &h).as_deref(), Some("ALS"));
    h[76..80].copy_from_slice(&(-1.0f32).to_le_bytes());
    assert_eq!(orientation_of(&dir, "qfac.nii", &h).as_deref(), Some("ALI"));
    let mut s = nifti(DType::U8, 2, 8);
    s[252..254].copy_from_slice(&0i16.to_le_bytes());
    s[254..256].copy_from_slice(&1i16.to_le_bytes());
    // Rows of the affine: x_world = −1.5·j, y_world = −2·k, z_world = −i (a sagittal layout).
    for (row, values) in [(280, [0.0f32, -1.5, 0.0, 0.0]), (296, [0.0, 0.0, -2.0, 0.0]), (312, [-1.0, 0.0, 0.0, 0.0])] {
        for (n, v) in values.iter().enumerate() {
            s[row + 4 * n..row + 4 * n + 4].copy_from_slice(&v.to_le_bytes());
        }
    }
    assert_eq!(orientation_of(&dir, "s.nii", &s).as_deref(), Some("ILP"));
    s[254..256].copy_from_slice(&0i16.to_le_bytes());
    assert_eq!(orientation_of(&dir, "none.nii", &s), None);
    // MetaImage: ITK's direction cosines, one axis after the other, in LPS.
    let mha = |matrix: &str| {
        format!(
            "ObjectType = Image\nNDims = 3\n{matrix}DimSize = {} {} {}\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n",
            DIMS[0], DIMS[1], DIMS[2]
        )
    };
    assert_eq!(
        orientation_of(&dir, "a.mha", &with(mha("TransformMatrix = 0 1 0 -1 0 0 0 0 1\n"))).as_deref(),
        Some("PRS")
    );
    assert_eq!(orientation_of(&dir, "b.mha", &with(mha(""))), None);
    // Through an import into a store and back.
    std::fs::write(dir.join("lps.nrrd"), with(nrrd("space: left-posterior-superior\n", "(1,0,0) (0,1,0) (0,0,1)")))
        .unwrap();
    let mut source = open_volume(&dir.join("lps.nrrd"), None).unwrap();
    import_volume(source.as_mut(), &dir.join("lps.zarr"), &ImportOptions::default(), &mut |_, _| {}).unwrap();
    let reader = StoreReader::open(&dir.join("lps.zarr")).unwrap();
    assert_eq!(reader.info().orientation.map(|o| o.code()).as_deref(), Some("LPS"));
    assert_eq!(reader.attributes().orientation.as_deref(), Some("LPS"));
}
