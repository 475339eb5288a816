//! DICOM series written here with dicom-rs's writer, slice by slice, as a scanner would: the importer must order the
//! slices by position whatever the files' names, measure the spacing, keep CT's rescale, and refuse every stack that
//! is not one evenly spaced pile of parallel slices. (Real files from pydicom's test set, decoded by pydicom, are
//! `crates/voxstream/tests/dicom_import.rs`.)

use std::path::{Path, PathBuf};

use dicom_core::value::{PrimitiveValue, C};
use dicom_core::{DataElement, VR};
use dicom_dictionary_std::{tags, uids};
use dicom_object::{FileMetaTableBuilder, InMemDicomObject};
use voxstream_store::formats::dicom::DicomSeries;
use voxstream_store::formats::open_volume;
use voxstream_store::{DType, StoreError, VolumeSource};

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("voxstream-dicom-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// One slice as a scanner writes it.
#[derive(Clone)]
struct Slice {
    series: &'static str,
    position: [f64; 3],
    orientation: [f64; 6],
    size: [u16; 2],
    bits_stored: u16,
    signed: bool,
    intercept: f64,
    /// Stored values, row by row.
    values: Vec<u16>,
}

fn decimal(values: &[f64]) -> PrimitiveValue {
    PrimitiveValue::Strs(values.iter().map(|v| format!("{v}")).collect::<C<String>>())
}

fn write_slice(path: &Path, slice: &Slice, instance: usize) {
    let [columns, rows] = slice.size;
    let element = |tag, vr, value: PrimitiveValue| DataElement::new(tag, vr, value);
    let uid = format!("2.25.{}{instance}", 1000 + instance);
    let object = InMemDicomObject::from_element_iter([
        element(tags::SOP_CLASS_UID, VR::UI, PrimitiveValue::from(uids::CT_IMAGE_STORAGE)),
        element(tags::SOP_INSTANCE_UID, VR::UI, PrimitiveValue::from(uid.as_str())),
        element(tags::MODALITY, VR::CS, PrimitiveValue::from("CT")),
        element(tags::SERIES_INSTANCE_UID, VR::UI, PrimitiveValue::from(slice.series)),
        element(tags::INSTANCE_NUMBER, VR::IS, PrimitiveValue::from(format!("{instance}").as_str())),
        element(tags::IMAGE_POSITION_PATIENT, VR::DS, decimal(&slice.position)),
        element(tags::IMAGE_ORIENTATION_PATIENT, VR::DS, decimal(&slice.orientation)),
        element(tags::SAMPLES_PER_PIXEL, VR::US, PrimitiveValue::from(1u16)),
        element(tags::PHOTOMETRIC_INTERPRETATION, VR::CS, PrimitiveValue::from("MONOCHROME2")),
        element(tags::ROWS, VR::US, PrimitiveValue::from(rows)),
        element(tags::COLUMNS, VR::US, PrimitiveValue::from(columns)),
        element(tags::PIXEL_SPACING, VR::DS, decimal(&[0.5, 0.75])),
        element(tags::BITS_ALLOCATED, VR::US, PrimitiveValue::from(16u16)),
        element(tags::BITS_STORED, VR::US, PrimitiveValue::from(slice.bits_stored)),
        element(tags::HIGH_BIT, VR::US, PrimitiveValue::from(slice.bits_stored - 1)),
        element(tags::PIXEL_REPRESENTATION, VR::US, PrimitiveValue::from(slice.signed as u16)),
        element(tags::RESCALE_INTERCEPT, VR::DS, decimal(&[slice.intercept])),
        element(tags::RESCALE_SLOPE, VR::DS, decimal(&[1.0])),
        element(tags::PIXEL_DATA, VR::OW, PrimitiveValue::U16(slice.values.iter().copied().collect())),
    ]);
    let file = object.with_meta(FileMetaTableBuilder::new().transfer_syntax(uids::EXPLICIT_VR_LITTLE_ENDIAN)).unwrap();
    file.write_to_file(path).unwrap();
}

const AXIAL: [f64; 6] = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0];

/// An oblique orientation: rows and columns turned 30° about the patient's z and 20° about x.
fn oblique() -> ([f64; 6], [f64; 3]) {
    let (a, b) = (30f64.to_radians(), 20f64.to_radians());
    let row = [a.cos(), a.sin(), 0.0];
    let column = [-a.sin() * b.cos(), a.cos() * b.cos(), b.sin()];
    let normal = [
        row[1] * column[2] - row[2] * column[1],
        row[2] * column[0] - row[0] * column[2],
        row[0] * column[1] - row[1] * column[0],
    ];
    ([row[0], row[1], row[2], column[0], column[1], column[2]], normal)
}

/// Slice `k` of a 5×4 test series: stored value 1000 + 100·k + 10·y + x.
fn slice(k: usize, position: [f64; 3], orientation: [f64; 6]) -> Slice {
    Slice {
        series: "2.25.77",
        position,
        orientation,
        size: [5, 4],
        bits_stored: 12,
        signed: false,
        intercept: -1024.0,
        values: (0..20).map(|i| (1000 + 100 * k + 10 * (i / 5) + i % 5) as u16).collect(),
    }
}

fn read_all(source: &mut dyn VolumeSource) -> Vec<f32> {
    let mut values = Vec::new();
    source.read_slices(source.info().dims[2] as usize, &mut values).unwrap();
    values
}

fn error_of(folder: &Path) -> String {
    match open_volume(folder, None) {
        Ok(_) => panic!("{} opened", folder.display()),
        Err(e) => e.to_string(),
    }
}

#[test]
fn slices_are_stacked_by_position_whatever_their_names() {
    let dir = scratch("order");
    let (orientation, n) = oblique();
    let origin = [-20.0, 31.5, 7.25];
    // Written under names in no order the positions have, one in a subfolder, beside a file that is not DICOM.
    let names = ["IM9", "IM2", "a/IM5", "IM0", "zz", "IM1", "b7"];
    std::fs::create_dir_all(dir.join("a")).unwrap();
    for (k, name) in names.iter().enumerate() {
        let p = [0, 1, 2].map(|a| origin[a] + 1.25 * k as f64 * n[a]);
        write_slice(&dir.join(name), &slice(k, p, orientation), 7 - k);
    }
    std::fs::write(dir.join("README.txt"), "exported by a PACS").unwrap();
    // One slice a link to a file elsewhere (a series assembled from an archive's files).
    let elsewhere = dir.with_extension("IM1");
    std::fs::rename(dir.join("IM1"), &elsewhere).unwrap();
    std::os::unix::fs::symlink(&elsewhere, dir.join("IM1")).unwrap();
    let mut source = open_volume(&dir, None).unwrap();
    assert!(source.description().unwrap().contains("CT series: 7 slices of 5x4, 1.2500 mm apart"));
    let info = source.info().clone();
    assert_eq!(info.dims, [5, 4, 7]);
    assert_eq!(info.dtype, DType::I16, "12-bit CT with intercept -1024 fits int16");
    assert!(
        (info.spacing[2] - 1.25).abs() < 1e-6 && info.spacing[0] == 0.75 && info.spacing[1] == 0.5,
        "{:?}",
        info.spacing
    );
    for a in 0..3 {
        assert!((info.origin[a] - origin[a]).abs() < 1e-6, "{:?}", info.origin);
    }
    assert_eq!(info.unit.map(|u| u.name()), Some("millimeter"));
    let values = read_all(source.as_mut());
    for k in 0..7 {
        for i in 0..20 {
            let expected = (1000 + 100 * k + 10 * (i / 5) + i % 5) as f32 - 1024.0;
            assert_eq!(values[k * 20 + i], expected, "slice {k} sample {i}");
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
    std::fs::remove_file(&elsewhere).unwrap();
}

#[test]
fn unsigned_16_bit_ct_is_kept_as_int16_when_its_values_fit() {
    // Stored as unsigned 16 bits, the bits could hold 65535 - 1024: beyond int16, so the values are looked at.
    for (largest, expected) in [(33_791u16, DType::I16), (33_792, DType::F32)] {
        let dir = scratch(&format!("u16-{largest}"));
        for k in 0..3 {
            let mut s = slice(k, [0.0, 0.0, 2.0 * k as f64], AXIAL);
            s.bits_stored = 16;
            if k == 1 {
                s.values[3] = largest;
            }
            write_slice(&dir.join(format!("s{k}")), &s, k);
        }
        let mut source = open_volume(&dir, None).unwrap();
        assert_eq!(source.info().dtype, expected, "largest stored value {largest}");
        let values = read_all(source.as_mut());
        assert_eq!(values[20 + 3], largest as f32 - 1024.0);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

#[test]
fn stacks_that_are_not_one_even_pile_are_refused_with_what_was_found() {
    let (oblique, n) = oblique();
    let cases: Vec<(&str, Vec<Slice>, &str)> = vec![
        (
            "gap",
            [0.0, 1.0, 2.0, 4.0].iter().enumerate().map(|(k, z)| slice(k, [0.0, 0.0, *z], AXIAL)).collect(),
            "unevenly spaced",
        ),
        (
            "twice",
            [0.0, 1.0, 1.0, 2.0].iter().enumerate().map(|(k, z)| slice(k, [0.0, 0.0, *z], AXIAL)).collect(),
            "same position",
        ),
        ("tilt", (0..4).map(|k| slice(k, [0.0, 0.3 * k as f64, k as f64], AXIAL)).collect(), "gantry tilt of 16.7°"),
        (
            "localizer",
            (0..3).map(|k| slice(k, [0.0, 0.0, k as f64], if k == 1 { oblique } else { AXIAL })).collect(),
            "different orientations",
        ),
        (
            "two-series",
            (0..4)
                .map(|k| Slice {
                    series: if k < 2 { "2.25.1" } else { "2.25.2" },
                    ..slice(k, [0.0, 0.0, k as f64], AXIAL)
                })
                .collect(),
            "2 series found",
        ),
        (
            "sizes",
            (0..3)
                .map(|k| Slice {
                    size: [5 - (k == 2) as u16, 4],
                    values: vec![0; 20 - 4 * (k == 2) as usize],
                    ..slice(k, [0.0, 0.0, k as f64], AXIAL)
                })
                .collect(),
            "must have one size",
        ),
        (
            "oblique-gap",
            [0.0, 1.0, 3.0].iter().enumerate().map(|(k, d)| slice(k, n.map(|c| c * d), oblique)).collect(),
            "unevenly spaced",
        ),
    ];
    for (name, slices, expected) in cases {
        let dir = scratch(name);
        for (k, s) in slices.iter().enumerate() {
            write_slice(&dir.join(format!("{k}.dcm")), s, k);
        }
        let message = error_of(&dir);
        assert!(message.contains(expected), "{name}: {message}");
        assert!(!message.contains('\n'), "{name}: one line: {message}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

#[test]
fn a_slice_whose_pixel_data_is_short_is_refused_naming_it() {
    let dir = scratch("short");
    for k in 0..3 {
        let mut s = slice(k, [0.0, 0.0, k as f64], AXIAL);
        if k == 2 {
            s.values.truncate(12);
        }
        write_slice(&dir.join(format!("{k}.dcm")), &s, k);
    }
    // Found when the slice is read (an import stops there and leaves no store: `import_volume`'s contract).
    let mut source = open_volume(&dir, None).unwrap();
    let mut values = Vec::new();
    match source.read_slices(3, &mut values) {
        Err(StoreError::Truncated { path, expected: 40, found: 24 }) => {
            assert!(path.ends_with("2.dcm"), "{}", path.display())
        }
        Err(other) => panic!("expected a truncation naming 2.dcm, got {other}"),
        Ok(()) => panic!("a short slice was read"),
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_folder_without_dicom_or_tiff_files_says_so() {
    let dir = scratch("empty");
    std::fs::write(dir.join("notes.txt"), "nothing here").unwrap();
    let message = error_of(&dir);
    assert!(message.contains("neither .tif/.tiff slices nor DICOM files"), "{message}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn series_chooses_one_of_a_folders_series_by_number_or_uid() {
    let dir = scratch("choose");
    for k in 0..5 {
        let series = if k < 2 { "2.25.1" } else { "2.25.2" };
        write_slice(&dir.join(format!("{k}.dcm")), &Slice { series, ..slice(k, [0.0, 0.0, k as f64], AXIAL) }, k);
    }
    let depth = |choice: &str| DicomSeries::open_series(&dir, Some(choice)).map(|s| s.info().dims[2]);
    assert_eq!(depth("1").unwrap(), 2);
    assert_eq!(depth("2").unwrap(), 3);
    assert_eq!(depth("2.25.2").unwrap(), 3);
    let message = depth("3").unwrap_err().to_string();
    assert!(message.contains("--series 3 is neither a number from 1 to 2 nor the UID"), "{message}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The process's peak resident memory (`VmHWM`), in KiB.
fn peak_rss_kib() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap();
    let line = status.lines().find(|l| l.starts_with("VmHWM:")).unwrap();
    line.split_whitespace().nth(1).unwrap().parse().unwrap()
}

#[test]
fn a_length_beyond_the_file_is_refused_before_anything_is_allocated_for_it() {
    // dicom-rs allocates and zeroes a value by its declared length: the import_dicom fuzz target's 479-byte file
    // declaring 3.7 GB took 3.6 GB. The element lengths are checked against the file first.
    let dir = scratch("forged");
    let path = dir.join("slice.dcm");
    write_slice(&path, &slice(0, [0.0; 3], AXIAL), 1);
    let mut bytes = std::fs::read(&path).unwrap();
    // The Modality element (0008,0060) CS "CT": its 2-byte length becomes an OB's 4-byte 0xDDDDDDDD.
    let at = bytes.windows(6).position(|w| w == [0x08, 0x00, 0x60, 0x00, b'C', b'S']).unwrap();
    bytes.splice(at + 4..at + 8, [b'O', b'B', 0, 0, 0xDD, 0xDD, 0xDD, 0xDD]);
    std::fs::write(&path, &bytes).unwrap();
    let before = peak_rss_kib();
    let message = error_of(&path);
    assert!(message.contains("element (0008,0060) declares 3722304989 bytes, more than the"), "{message}");
    // A VR dicom-rs does not know is read as UN, with a 4-byte length: here "CT" and the next tag's first bytes.
    let mut bytes = std::fs::read(&path).unwrap();
    bytes.splice(at + 4..at + 12, [b'K', b'S', 2, 0, b'C', b'T', 0xF0, 0x7F]);
    std::fs::write(&path, &bytes).unwrap();
    let message = error_of(&path);
    assert!(message.contains("element (0008,0060) declares 2146456643 bytes"), "{message}");
    let grown = peak_rss_kib().saturating_sub(before);
    assert!(grown < 512 * 1024, "peak memory grew by {grown} KiB");
    std::fs::remove_dir_all(&dir).unwrap();
}
