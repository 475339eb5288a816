//! Replays every input a fuzz target once failed on (`tests/fuzz_regressions/TARGET/NAME`) through the same code path
//! as that target (see `fuzz/fuzz_targets/`): each must now end in an answer (usually an error), without a panic, an
//! abort or a hang.

use std::path::{Path, PathBuf};

use voxstream_geometry::formats::{parse_geometry, RawGeometry, GEOMETRY_FILE_ENDINGS};
use voxstream_geometry::{ParticleSet, TriangleMesh};
use voxstream_store::formats::{open_volume, Endian, RawLayout};
use voxstream_store::{import_volume, DType, ImportOptions, VolumeInfo};

/// The `store_shards` target's driver, the very file the fuzz crate builds.
#[path = "../../../fuzz/src/shard_input.rs"]
mod shard_input;

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("voxstream-fuzz-regressions-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// As `fuzz/src/lib.rs`: the bytes as a file with `extension`, imported into a scratch store.
fn import_bytes(dir: &Path, extension: &str, data: &[u8], raw: Option<&RawLayout>) {
    let input = dir.join(format!("input.{extension}"));
    std::fs::write(&input, data).unwrap();
    let store = dir.join("store.zarr");
    if let Ok(mut source) = open_volume(&input, raw) {
        let options = ImportOptions { brick_size: 8, overwrite: true, ..ImportOptions::default() };
        let _ = import_volume(source.as_mut(), &store, &options, &mut |_, _| {});
    }
    let _ = std::fs::remove_dir_all(&store);
}

fn replay(dir: &Path, target: &str, data: &[u8]) {
    let selected = |a: &str, b: &str| match data.split_first() {
        Some((&selector, file)) => import_bytes(dir, if selector % 2 == 0 { a } else { b }, file, None),
        None => {}
    };
    let text = std::str::from_utf8(data).ok();
    match target {
        "import_nrrd" => import_bytes(dir, "nrrd", data, None),
        "import_metaimage" => import_bytes(dir, "mha", data, None),
        "import_vti" => import_bytes(dir, "vti", data, None),
        "import_tiff" => import_bytes(dir, "tif", data, None),
        "import_dicom" => import_bytes(dir, "dcm", data, None),
        "import_nifti" => selected("nii", "nii.gz"),
        "import_inr" => selected("inr", "inr.gz"),
        "import_npy" => selected("npy", "npz"),
        "import_raw" if data.len() >= 8 => {
            let dim = |i: usize| u16::from_le_bytes([data[i], data[i + 1]]) as u64;
            let dtype = [DType::U8, DType::U16, DType::I16, DType::F32][(data[6] % 4) as usize];
            let layout = RawLayout {
                info: VolumeInfo {
                    dims: [dim(0), dim(2), dim(4)],
                    dtype,
                    spacing: [1.0; 3],
                    origin: [0.0; 3],
                    unit: None,
                    orientation: None,
                },
                file_type: None,
                endian: if data[6] & 4 == 0 { Endian::Little } else { Endian::Big },
                header_bytes: data[7] as u64,
            };
            import_bytes(dir, "raw", &data[8..], Some(&layout));
        }
        "import_raw" => {}
        "vdb_converter_header" => {
            if let Some(text) = text {
                let _ = voxstream_store::formats::vdb::parse_converter_header(Path::new("fuzz.vdb"), text);
            }
        }
        "store_metadata" => {
            let store = dir.join("metadata.zarr");
            std::fs::create_dir_all(&store).unwrap();
            std::fs::write(store.join("zarr.json"), data).unwrap();
            let _ = voxstream_store::StoreReader::open(&store);
        }
        "store_shards" => assert!(shard_input::read_shard_input(dir, data), "the template store could not be made"),
        "foreign_metadata" => {
            // As `voxstream_fuzz::foreign_files`: a selector byte (bit 0: Zarr v2), then the group's document and
            // two datasets', separated by NUL bytes.
            let store = dir.join("foreign.zarr");
            let _ = std::fs::remove_dir_all(&store);
            let Some((&selector, rest)) = data.split_first() else { return };
            let is_v2 = selector & 1 == 1;
            let mut documents = rest.splitn(3, |&b| b == 0);
            let group = documents.next().unwrap_or_default();
            std::fs::create_dir_all(&store).unwrap();
            if is_v2 {
                std::fs::write(store.join(".zgroup"), br#"{"zarr_format": 2}"#).unwrap();
                std::fs::write(store.join(".zattrs"), group).unwrap();
            } else {
                std::fs::write(store.join("zarr.json"), group).unwrap();
            }
            for (index, document) in documents.enumerate() {
                std::fs::create_dir_all(store.join(index.to_string())).unwrap();
                let name = if is_v2 { ".zarray" } else { "zarr.json" };
                std::fs::write(store.join(format!("{index}/{name}")), document).unwrap();
            }
            if let Ok(reader) = voxstream_store::StoreReader::open(&store) {
                for level in 0..reader.layout().levels() {
                    let _ = reader.stored_chunks(level);
                }
            }
        }
        "transfer_function" => {
            if let Some(Ok(tf)) = text.map(voxstream_render::transfer_function::TransferFunction::from_json) {
                for value in [-1.0, 0.0, 0.5, 1.0, 1e9, f64::NAN] {
                    let _ = tf.evaluate(value);
                }
                let _ = voxstream_render::transfer_function::TransferLut::new(&tf, 0.0, 1.0, 1.0).lookup(0.5);
            }
        }
        "geometry_files" => {
            if let Some((&selector, file)) = data.split_first() {
                let ending = GEOMETRY_FILE_ENDINGS[selector as usize % GEOMETRY_FILE_ENDINGS.len()];
                match parse_geometry(file, ending, Path::new(&format!("fuzz{ending}"))) {
                    Ok(RawGeometry::Mesh(raw)) => {
                        let _ = TriangleMesh::new(raw).map(|mesh| mesh.bounds());
                    }
                    Ok(RawGeometry::Particles(raw)) => {
                        let _ = ParticleSet::new(raw).map(|particles| particles.bounds());
                    }
                    Err(_) => {}
                }
            }
        }
        "camera_path" => {
            if let Some(text) = text {
                let _ = voxstream::camera_path::parse_camera_path(text);
            }
        }
        other => panic!("tests/fuzz_regressions/{other}: no such fuzz target"),
    }
}

#[test]
fn every_input_a_fuzzer_failed_on_now_gets_an_answer() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fuzz_regressions");
    let mut replayed = 0;
    let mut targets: Vec<PathBuf> = std::fs::read_dir(&root).unwrap().flatten().map(|e| e.path()).collect();
    targets.sort();
    for target in targets.iter().filter(|p| p.is_dir()) {
        let name = target.file_name().unwrap().to_string_lossy().into_owned();
        let dir = scratch(&name);
        let mut inputs: Vec<PathBuf> = std::fs::read_dir(target).unwrap().flatten().map(|e| e.path()).collect();
        inputs.sort();
        for input in inputs {
            replay(&dir, &name, &std::fs::read(&input).unwrap());
            replayed += 1;
        }
    }
    assert!(replayed > 0, "no regression inputs found under {}", root.display());
}
