//! `voxstream import` of sample types a store does not keep (NumPy `f8`, `i4`, `u4`, `i1`; raw `--dtype`), and of
//! units (NIfTI's `xyzt_units`, `--unit`) through the real binary: the values read back equal the input converted,
//! one note says what was converted, the unit reaches the store's axes and `info`, a bad `--unit` is one line.

mod common;

use std::path::Path;

use common::{scratch, stderr, voxstream};
use voxstream_store::StoreReader;

const DIMS: [u64; 3] = [12, 10, 9];

fn count() -> usize {
    DIMS.iter().product::<u64>() as usize
}

/// A `.npy` of `descr` holding `data` in C order, shape (z, y, x).
fn npy(descr: &str, data: &[u8]) -> Vec<u8> {
    voxstream_store::formats::npy::npy_bytes(descr, [DIMS[2], DIMS[1], DIMS[0]], data)
}

fn level0(store: &Path) -> Vec<f32> {
    StoreReader::open(store).unwrap().read_region(0, [0, 0, 0], DIMS).unwrap()
}

fn import(dir: &Path, args: &[&str]) -> String {
    let output = voxstream(args, dir);
    assert!(output.status.success(), "{args:?}: {}", stderr(&output));
    stderr(&output)
}

#[test]
fn numpy_f8_i4_u4_i1_import_converted_with_a_note() {
    let dir = scratch("converted-imports", "numpy");
    let n = count();
    let f8: Vec<f64> = (0..n).map(|i| i as f64 / 3.0 - 50.0).collect();
    let i4: Vec<i32> = (0..n).map(|i| i as i32 * 40_001 - 20_000_001).collect();
    let u4: Vec<u32> = (0..n).map(|i| i as u32 * 7).collect();
    let i1: Vec<i8> = (0..n).map(|i| (i % 256) as u8 as i8).collect();
    let cases: [(&str, Vec<u8>, Vec<f32>, &str, &str); 4] = [
        (
            "<f8",
            f8.iter().flat_map(|v| v.to_le_bytes()).collect(),
            f8.iter().map(|&v| v as f32).collect(),
            "f32",
            "note: float64 converted to float32: ",
        ),
        (
            "<i4",
            i4.iter().flat_map(|v| v.to_le_bytes()).collect(),
            i4.iter().map(|&v| v as f32).collect(),
            "f32",
            "note: int32 converted to float32: ",
        ),
        (
            "<u4",
            u4.iter().flat_map(|v| v.to_le_bytes()).collect(),
            u4.iter().map(|&v| v as f32).collect(),
            "f32",
            "note: uint32 converted to float32: exact",
        ),
        (
            "|i1",
            i1.iter().map(|&v| v as u8).collect(),
            i1.iter().map(|&v| v as f32).collect(),
            "i16",
            "note: int8 converted to int16",
        ),
    ];
    for (descr, bytes, expected, stored, note) in cases {
        let name = descr.trim_start_matches(['<', '|']);
        std::fs::write(dir.join(format!("{name}.npy")), npy(descr, &bytes)).unwrap();
        let store = format!("{name}.zarr");
        let err = import(&dir, &["import", &format!("{name}.npy"), "--out", &store]);
        assert!(err.contains(note), "{descr}: {err}");
        assert_eq!(err.matches("note:").count(), 1, "{descr}: one note line: {err}");
        assert!(err.contains(&format!("{} {stored})", DIMS[2])), "{descr}: the summary names the stored type: {err}");
        assert!(level0(&dir.join(&store)) == expected, "{descr}: level 0 differs from the input converted");
    }
    // int32 values beyond ±2^24 are rounded, and the note says how many and by how much.
    let err = import(&dir, &["import", "i4.npy", "--out", "again.zarr", "--quiet"]);
    assert!(err.contains("values beyond ±2^24 were rounded to the nearest float32, by at most"), "{err}");
    assert_eq!(err.lines().count(), 1, "--quiet keeps only the note: {err}");
}

#[test]
fn raw_dtype_f64_with_a_unit_and_info_shows_it() {
    let dir = scratch("converted-imports", "raw");
    let values: Vec<f64> = (0..count()).map(|i| (i as f64).sqrt()).collect();
    std::fs::write(dir.join("v.raw"), values.iter().flat_map(|v| v.to_be_bytes()).collect::<Vec<u8>>()).unwrap();
    let dims = format!("{},{},{}", DIMS[0], DIMS[1], DIMS[2]);
    let err = import(
        &dir,
        &[
            "import",
            "v.raw",
            "--out",
            "v.zarr",
            "--dims",
            &dims,
            "--dtype",
            "f64",
            "--endian",
            "big",
            "--unit",
            "µm",
            "--spacing",
            "0.5,0.5,2",
        ],
    );
    assert!(err.contains("note: float64 converted to float32"), "{err}");
    let expected: Vec<f32> = values.iter().map(|&v| v as f32).collect();
    assert!(level0(&dir.join("v.zarr")) == expected);

    let zarr: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("v.zarr/zarr.json")).unwrap()).unwrap();
    let axes = zarr["attributes"]["ome"]["multiscales"][0]["axes"].as_array().unwrap().clone();
    assert!(axes.iter().all(|a| a["unit"] == "micrometer"), "{axes:?}");

    let info = voxstream(&["info", "v.zarr"], &dir);
    let text = String::from_utf8_lossy(&info.stdout);
    assert!(text.contains("spacing      0.5 0.5 2 micrometer"), "{text}");
    let json = voxstream(&["info", "v.zarr", "--json"], &dir);
    let json: serde_json::Value = serde_json::from_slice(&json.stdout).unwrap();
    assert_eq!(json["unit"], "micrometer");
}

#[test]
fn nifti_millimetres_reach_the_store_and_info() {
    let dir = scratch("converted-imports", "nifti");
    let mut h = common::nifti_u8_header(DIMS.map(|d| d as usize), [1.0, 0.9, 0.9, 1.2], 2 | 8); // millimetres, seconds
    h.extend((0..count()).map(|i| (i % 200) as u8));
    std::fs::write(dir.join("t1.nii"), h).unwrap();
    let err = import(&dir, &["import", "t1.nii", "--out", "t1.zarr"]);
    assert!(!err.contains("note:"), "uint8 is stored as it is: {err}");
    let info = voxstream(&["info", "t1.zarr"], &dir);
    let text = String::from_utf8_lossy(&info.stdout);
    assert!(text.lines().any(|l| l.starts_with("spacing") && l.ends_with(" millimeter")), "{text}");
    // --unit replaces the file's.
    import(&dir, &["import", "t1.nii", "--out", "t1m.zarr", "--unit", "meter"]);
    let json = voxstream(&["info", "t1m.zarr", "--json"], &dir);
    assert_eq!(serde_json::from_slice::<serde_json::Value>(&json.stdout).unwrap()["unit"], "meter");
}

#[test]
fn a_unit_that_ome_zarr_does_not_know_is_refused_in_one_line() {
    let dir = scratch("converted-imports", "bad-unit");
    std::fs::write(dir.join("v.npy"), npy("|u1", &vec![1u8; count()])).unwrap();
    let output = voxstream(&["import", "v.npy", "--out", "v.zarr", "--unit", "furlong"], &dir);
    let err = stderr(&output);
    assert_eq!(output.status.code(), Some(1), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.contains("--unit: 'furlong' is not an OME-Zarr space unit") && err.contains("millimeter"), "{err}");
    assert!(!dir.join("v.zarr").exists());
    // An old store without a unit reads as before: info prints the spacing alone.
    import(&dir, &["import", "v.npy", "--out", "plain.zarr"]);
    let info = voxstream(&["info", "plain.zarr"], &dir);
    assert!(String::from_utf8_lossy(&info.stdout).contains("spacing      1 1 1\n"));
    // An unknown --dtype names the types that import.
    let output = voxstream(&["import", "v.npy", "--out", "x.zarr", "--dims", "1,1,1", "--dtype", "i64"], &dir);
    let err = stderr(&output);
    assert!(err.contains("unknown --dtype 'i64'") && err.contains("f64 (converted)"), "{err}");
}
