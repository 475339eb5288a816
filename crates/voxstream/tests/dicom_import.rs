//! DICOM as scanners and other tools write it (issue 42 item 6): pydicom's own test files (fetched from PyPI by
//! `scripts/fetch-real-data.sh`, decoded by pydicom into references by `scripts/make_references.py`), and the MNI
//! template written by pydicom as a CT series of 189 files (`scripts/nifti_to_dicom.py`), imported with
//! `voxstream import` and compared with the NIfTI's own import.

use std::path::Path;

mod common;

use common::{data_folder, real_data_dir, reference, scratch, stderr, voxstream};
use voxstream_store::{DType, StoreReader};

fn import(input: &Path, store: &Path, work: &Path) -> StoreReader {
    import_saying(input, store, work).0
}

/// The store, and what the import printed.
fn import_saying(input: &Path, store: &Path, work: &Path) -> (StoreReader, String) {
    let output = voxstream(&["import", input.to_str().unwrap(), "--out", store.to_str().unwrap()], work);
    assert!(output.status.success(), "import {}: {}", input.display(), stderr(&output));
    (StoreReader::open(store).unwrap(), stderr(&output))
}

fn level_zero(reader: &StoreReader) -> Vec<f32> {
    reader.read_region(0, [0, 0, 0], reader.info().dims).unwrap()
}

#[test]
fn pydicoms_test_files_import_as_pydicom_decodes_them() {
    let Some(real) = real_data_dir() else { return };
    let dicom = real.join("dicom");
    let work = scratch("dicom_import", "pydicom");
    let cases = [
        ("CT5N", "dicom_ct5n", DType::I16),
        ("CT_small.dcm", "dicom_ct_small", DType::I16),
        ("MR_small.dcm", "dicom_mr_small", DType::I16),
        ("MR_small_bigendian.dcm", "dicom_mr_small", DType::I16),
        ("MR_small_implicit.dcm", "dicom_mr_small", DType::I16),
        ("MR_small_RLE.dcm", "dicom_mr_small", DType::I16),
        ("MR_small_jp2klossless.dcm", "dicom_mr_small", DType::I16),
        ("rtdose.dcm", "dicom_rtdose", DType::F32),
    ];
    for (input, name, dtype) in cases {
        let reader = import(&dicom.join(input), &work.join(format!("{input}.zarr")), &work);
        let (expected, meta) = reference(&real, name);
        let info = reader.info();
        let dims: Vec<u64> = meta["dims"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap()).collect();
        assert_eq!(info.dims.to_vec(), dims, "{input}");
        assert_eq!(info.dtype, dtype, "{input}");
        for a in 0..3 {
            let (spacing, origin) = (meta["spacing"][a].as_f64().unwrap(), meta["origin"][a].as_f64().unwrap());
            assert!((info.spacing[a] - spacing).abs() < 1e-6, "{input}: spacing {:?}, pydicom {spacing}", info.spacing);
            assert!((info.origin[a] - origin).abs() < 1e-4, "{input}: origin {:?}, pydicom {origin}", info.origin);
        }
        assert_eq!(info.unit.map(|u| u.name()), Some("millimeter"), "{input}");
        let values = level_zero(&reader);
        assert_eq!(values.len(), expected.len(), "{input}");
        let differing = values.iter().zip(&expected).filter(|(a, b)| a.to_bits() != b.to_bits()).count();
        assert_eq!(differing, 0, "{input}: {differing} samples differ from pydicom's");
    }
    std::fs::remove_dir_all(&work).unwrap();
}

#[test]
fn the_mni_template_as_a_scanner_series_imports_as_its_nifti() {
    let Some(real) = real_data_dir() else { return };
    let work = scratch("dicom_import", "mni");
    let series = work.join("series");
    let python = data_folder().join("venv/bin/python");
    let script = common::repository_root().join("scripts/nifti_to_dicom.py");
    let written = std::process::Command::new(&python)
        .args([script.as_os_str(), real.join("mni152_t1.nii.gz").as_os_str(), series.as_os_str()])
        .output()
        .unwrap();
    assert!(written.status.success(), "nifti_to_dicom.py: {}", stderr(&written));
    let files = ["a", "b"].iter().map(|f| std::fs::read_dir(series.join(f)).unwrap().count()).sum::<usize>();
    assert_eq!(files, 189, "one file per slice");

    let (from_dicom, said) = import_saying(&series, &work.join("dicom.zarr"), &work);
    assert!(
        said.contains(
            "DICOM CT series \"MNI152 as CT\": 189 slices of 197x233, 1.0000 mm apart, ordered by position; stored \
             values - 1024 (the modality's rescale)"
        ),
        "{said}"
    );
    let from_nifti = import(&real.join("mni152_t1.nii.gz"), &work.join("nifti.zarr"), &work);
    let (d, n) = (from_dicom.info(), from_nifti.info());
    assert_eq!((d.dims, d.spacing), (n.dims, n.spacing));
    // Written by a scanner's rules (rows towards the patient's right, in LPS): the same RAS axes as the NIfTI's
    // qform, the origin in DICOM's patient frame (x and y negated).
    assert_eq!(n.orientation.map(|o| o.code()).as_deref(), Some("RAS"));
    assert_eq!(d.orientation, n.orientation);
    assert_eq!(d.origin, [-n.origin[0], -n.origin[1], n.origin[2]]);
    assert_eq!(d.dtype, DType::I16, "12-bit CT with intercept -1024 fits int16");
    let (a, b) = (level_zero(&from_dicom), level_zero(&from_nifti));
    let differing = a.iter().zip(&b).filter(|(x, y)| x != y).count();
    assert_eq!(differing, 0, "{differing} of {} samples differ from the NIfTI's", a.len());
    // The whole pyramid, not only level 0: the levels are built from the same samples.
    for level in 1..from_nifti.layout().levels() {
        let dims = from_nifti.layout().level_dims[level];
        assert_eq!(
            from_dicom.read_region(level, [0; 3], dims).unwrap(),
            from_nifti.read_region(level, [0; 3], dims).unwrap(),
            "level {level}"
        );
    }
    std::fs::remove_dir_all(&work).unwrap();
}

#[test]
fn series_that_cannot_be_one_volume_are_refused_in_one_line_writing_nothing() {
    let Some(real) = real_data_dir() else { return };
    let dicom = real.join("dicom");
    let work = scratch("dicom_import", "refused");
    let cases = [
        ("CT2", "slices are unevenly spaced: 1.2500 mm apart, but 202.5000 mm"),
        ("mr_study/MR700", "slices in different orientations"),
        ("mr_study", "7 series found: 1. MR \"ANGIO Projected from   C\" (7 slices of 16x16"),
        ("mr_study", "of 16x16, in several orientations: a localizer, not one volume, in "),
        ("mr_study", "choose it with --series N (its number here) or --series UID"),
        ("MR_small_jpeg_ls_lossless.dcm", "JPEG-LS Lossless Image Compression"),
        ("JPEG-lossy.dcm", "SamplePrecision(12)"),
    ];
    for (input, expected) in cases {
        let store = work.join("out.zarr");
        let output =
            voxstream(&["import", dicom.join(input).to_str().unwrap(), "--out", store.to_str().unwrap()], &work);
        let message = stderr(&output);
        assert!(!output.status.success(), "{input} was imported");
        assert!(message.contains(expected), "{input}: {message}");
        assert_eq!(message.trim_end().lines().count(), 1, "{input}: one line: {message}");
        assert!(!message.contains("panicked"), "{input}: {message}");
        assert!(!store.exists() && !work.join("out.zarr.partial").exists(), "{input}: something was written");
    }
    std::fs::remove_dir_all(&work).unwrap();
}

#[test]
fn series_chooses_one_series_of_a_study_folder() {
    let Some(real) = real_data_dir() else { return };
    let study = real.join("dicom/mr_study");
    let work = scratch("dicom_import", "series");
    let import = |series: &str, store: &str| {
        voxstream(&["import", study.to_str().unwrap(), "--series", series, "--out", store], &work)
    };
    // The list the refusal gives numbers the series by UID; number 2 is MR1's first "FAST LOCALIZER", one slice.
    let uid = "1.3.6.1.4.1.5962.1.1.0.0.0.1196533885.18148.0.134";
    for (choice, store) in [("2", "by-number.zarr"), (uid, "by-uid.zarr")] {
        let output = import(choice, store);
        assert!(output.status.success(), "--series {choice}: {}", stderr(&output));
        let reader = StoreReader::open(&work.join(store)).unwrap();
        assert_eq!(reader.info().dims, [16, 16, 1], "--series {choice}");
        assert!(
            stderr(&output).contains("DICOM MR series \"FAST LOCALIZER\": one slice of 16x16; values as stored"),
            "{}",
            stderr(&output)
        );
    }
    let by_number = level_zero(&StoreReader::open(&work.join("by-number.zarr")).unwrap());
    assert_eq!(by_number, level_zero(&StoreReader::open(&work.join("by-uid.zarr")).unwrap()));
    let output = import("9", "none.zarr");
    assert!(!output.status.success());
    assert!(stderr(&output).contains("--series 9 is neither a number from 1 to 7 nor the UID"), "{}", stderr(&output));
    let nifti = real.join("mni152_t1.nii.gz");
    let output = voxstream(&["import", nifti.to_str().unwrap(), "--series", "1", "--out", "n.zarr"], &work);
    assert!(stderr(&output).contains("--series chooses among the series of a DICOM folder"), "{}", stderr(&output));
    assert!(!work.join("none.zarr").exists() && !work.join("n.zarr").exists());
    std::fs::remove_dir_all(&work).unwrap();
}
