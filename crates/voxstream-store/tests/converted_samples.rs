//! Sample types a store does not keep (int8, int32, uint32, float64), imported from every format that has them:
//! level 0 of the store must equal the input converted (int8 to int16, the others to float32), the report must say
//! what the conversion did, a float64 beyond float32's range must be refused naming the sample; and the spacing's
//! unit (NIfTI's `xyzt_units`, NRRD's `space units`, a raw layout's) must reach the store's OME-Zarr axes.

use std::path::{Path, PathBuf};

use voxstream_store::formats::{open_volume, Endian, RawLayout, SampleType};
use voxstream_store::{import_volume, DType, ImportOptions, ImportReport, SpaceUnit, StoreReader, VolumeInfo};

const DIMS: [u64; 3] = [19, 13, 11];

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("voxstream-converted-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The test volume in `ty`, as f64 values the type holds exactly (x fastest), spanning most of its range.
fn values(ty: SampleType) -> Vec<f64> {
    let count = DIMS.iter().product::<u64>();
    (0..count)
        .map(|n| {
            let t = ((n * 37) % 251) as f64 / 250.0; // 0 ..= 1
            match ty {
                SampleType::I8 => (t * 255.0).round() - 128.0,
                // Odd offsets: large values that float32 cannot hold exactly.
                SampleType::I32 => {
                    (((t - 0.5) * 4.0e9).round() + (n % 7) as f64).clamp(i32::MIN as f64, i32::MAX as f64)
                }
                SampleType::U32 => (t * 4.29e9).round() + (n % 7) as f64,
                SampleType::F64 => (t - 0.5) * 1.0e6 + 1.0 / 3.0,
                _ => unreachable!("only converted types"),
            }
        })
        .collect()
}

fn encode(ty: SampleType, values: &[f64], big: bool) -> Vec<u8> {
    macro_rules! bytes {
        ($v:expr) => {
            if big {
                $v.to_be_bytes().to_vec()
            } else {
                $v.to_le_bytes().to_vec()
            }
        };
    }
    values
        .iter()
        .flat_map(|&v| match ty {
            SampleType::I8 => bytes!(v as i8),
            SampleType::I32 => bytes!(v as i32),
            SampleType::U32 => bytes!(v as u32),
            SampleType::F64 => bytes!(v),
            _ => unreachable!("only converted types"),
        })
        .collect()
}

/// Imports `path` and checks level 0 against `expected` converted; returns the report and the store.
fn import_and_compare(
    path: &Path,
    raw: Option<&RawLayout>,
    ty: SampleType,
    expected: &[f64],
) -> (ImportReport, PathBuf) {
    let store = path.with_extension("zarr");
    let mut source = open_volume(path, raw).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(source.info().dtype, ty.stored(), "{}", path.display());
    let options = ImportOptions { brick_size: 8, shard_bricks: 2, ..ImportOptions::default() };
    let report = import_volume(source.as_mut(), &store, &options, &mut |_, _| {})
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let reader = StoreReader::open(&store).unwrap();
    assert_eq!(reader.info().dtype, ty.stored());
    let level0 = reader.read_region(0, [0, 0, 0], DIMS).unwrap();
    let converted: Vec<f32> = expected.iter().map(|&v| v as f32).collect();
    assert!(level0 == converted, "{}: level 0 differs from the input converted", path.display());
    let conversion = report.conversion.unwrap_or_else(|| panic!("{}: no conversion reported", path.display()));
    assert_eq!((conversion.from, conversion.samples), (ty, expected.len() as u64), "{}", path.display());
    (report, store)
}

/// The root `zarr.json`'s attributes.
fn attributes(store: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(store.join("zarr.json")).unwrap();
    serde_json::from_str::<serde_json::Value>(&text).unwrap()["attributes"].clone()
}

fn npy(descr: &str, data: &[u8]) -> Vec<u8> {
    voxstream_store::formats::npy::npy_bytes(descr, [DIMS[2], DIMS[1], DIMS[0]], data)
}

#[test]
fn numpy_i1_i4_u4_f8_import_converted() {
    let dir = scratch("npy");
    for (descr, ty) in
        [("|i1", SampleType::I8), ("<i4", SampleType::I32), (">u4", SampleType::U32), ("<f8", SampleType::F64)]
    {
        let values = values(ty);
        let path = dir.join(format!("{}.npy", ty.name()));
        std::fs::write(&path, npy(descr, &encode(ty, &values, descr.starts_with('>')))).unwrap();
        let (report, store) = import_and_compare(&path, None, ty, &values);
        let note = report.conversion.unwrap().to_string();
        assert!(note.starts_with(&format!("{} converted to", ty.name())), "{note}");
        // int32 and uint32 values here reach ±2^31: some are rounded, and the note says so.
        if matches!(ty, SampleType::I32 | SampleType::U32) {
            assert!(note.contains("beyond ±2^24 were rounded"), "{note}");
        }
        assert!(attributes(&store)["voxstream"].get("unit").is_none(), "NumPy has no unit");
    }
}

#[test]
fn integers_within_2_24_are_exact_and_the_note_says_so() {
    let dir = scratch("exact");
    let values: Vec<f64> = (0..DIMS.iter().product::<u64>()).map(|n| n as f64 * 3.0 - 1000.0).collect();
    let path = dir.join("labels.npy");
    std::fs::write(&path, npy("<i4", &encode(SampleType::I32, &values, false))).unwrap();
    let (report, _) = import_and_compare(&path, None, SampleType::I32, &values);
    let note = report.conversion.unwrap().to_string();
    assert!(note.contains("int32 converted to float32: exact"), "{note}");
}

#[test]
fn float64_beyond_float32_is_refused_naming_the_sample() {
    let dir = scratch("f64-range");
    let mut values = values(SampleType::F64);
    let at = (DIMS[0] * DIMS[1] * 2 + DIMS[0] * 3 + 5) as usize;
    values[at] = 1e300;
    let path = dir.join("huge.npy");
    std::fs::write(&path, npy("<f8", &encode(SampleType::F64, &values, false))).unwrap();
    let store = dir.join("huge.zarr");
    let mut source = open_volume(&path, None).unwrap();
    let error = import_volume(source.as_mut(), &store, &ImportOptions::default(), &mut |_, _| {}).unwrap_err();
    let message = error.to_string();
    assert!(message.contains("huge.npy") && message.contains("sample (5, 3, 2) is 1e300"), "{message}");
    assert!(message.contains("beyond float32's range") && !message.contains('\n'), "{message}");
    assert!(!store.exists());
}

#[test]
fn float64_nan_follows_the_nan_as_policy() {
    let dir = scratch("f64-nan");
    let mut values = values(SampleType::F64);
    values[7] = f64::NAN;
    let path = dir.join("nan.npy");
    std::fs::write(&path, npy("<f8", &encode(SampleType::F64, &values, false))).unwrap();
    let mut source = open_volume(&path, None).unwrap();
    let error = import_volume(source.as_mut(), &dir.join("a.zarr"), &ImportOptions::default(), &mut |_, _| {});
    assert!(error.unwrap_err().to_string().contains("--nan-as"));
    let mut source = open_volume(&path, None).unwrap();
    let options = ImportOptions { nan_as: Some(-1.0), ..ImportOptions::default() };
    import_volume(source.as_mut(), &dir.join("b.zarr"), &options, &mut |_, _| {}).unwrap();
    let level0 = StoreReader::open(&dir.join("b.zarr")).unwrap().read_region(0, [0, 0, 0], DIMS).unwrap();
    assert_eq!(level0[7], -1.0);
}

/// A NIfTI-1 file of `ty` (datatype `code`) with spacing 0.5 in the unit `xyzt_units`.
fn nifti(ty: SampleType, code: i16, xyzt_units: u8, data: &[u8]) -> Vec<u8> {
    let mut h = vec![0u8; 352];
    h[0..4].copy_from_slice(&348i32.to_le_bytes());
    let dims = [3i16, DIMS[0] as i16, DIMS[1] as i16, DIMS[2] as i16, 1, 1, 1, 1];
    for (n, d) in dims.iter().enumerate() {
        h[40 + 2 * n..42 + 2 * n].copy_from_slice(&d.to_le_bytes());
    }
    h[70..72].copy_from_slice(&code.to_le_bytes());
    h[72..74].copy_from_slice(&(8 * ty.size() as i16).to_le_bytes());
    for (n, p) in [1.0f32, 0.5, 0.5, 0.5].iter().enumerate() {
        h[76 + 4 * n..80 + 4 * n].copy_from_slice(&p.to_le_bytes());
    }
    h[108..112].copy_from_slice(&352f32.to_le_bytes());
    h[123] = xyzt_units;
    h[344..348].copy_from_slice(b"n+1\0");
    h.extend(data);
    h
}

#[test]
fn nifti_int8_int32_uint32_float64_and_its_units() {
    let dir = scratch("nifti");
    // xyzt_units: 2 mm, 3 micron, 1 meter (with a time unit, seconds = 8, in the high bits).
    for (ty, code, units, unit) in [
        (SampleType::I8, 256, 2 | 8, Some("millimeter")),
        (SampleType::I32, 8, 3, Some("micrometer")),
        (SampleType::U32, 768, 1, Some("meter")),
        (SampleType::F64, 64, 0, None),
    ] {
        let values = values(ty);
        let path = dir.join(format!("{}.nii", ty.name()));
        std::fs::write(&path, nifti(ty, code, units, &encode(ty, &values, false))).unwrap();
        let (_, store) = import_and_compare(&path, None, ty, &values);
        let attributes = attributes(&store);
        assert_eq!(attributes["voxstream"]["unit"].as_str(), unit, "{}", path.display());
        for axis in attributes["ome"]["multiscales"][0]["axes"].as_array().unwrap() {
            assert_eq!(axis["unit"].as_str(), unit, "{}: {axis}", path.display());
        }
        assert_eq!(StoreReader::open(&store).unwrap().info().unit.map(SpaceUnit::name), unit);
    }
}

#[test]
fn nrrd_signed_char_int_uint_double_and_space_units() {
    let dir = scratch("nrrd");
    for (kind, ty) in [
        ("signed char", SampleType::I8),
        ("int", SampleType::I32),
        ("unsigned int", SampleType::U32),
        ("double", SampleType::F64),
    ] {
        let values = values(ty);
        let mut bytes = format!(
            "NRRD0005\ntype: {kind}\ndimension: 3\nspace dimension: 3\nsizes: {} {} {}\nspace directions: (0.2,0,0) \
             (0,0.2,0) (0,0,0.4)\nspace units: \"mm\" \"mm\" \"mm\"\nendian: big\nencoding: raw\n\n",
            DIMS[0], DIMS[1], DIMS[2]
        )
        .into_bytes();
        bytes.extend(encode(ty, &values, true));
        let path = dir.join(format!("{}.nrrd", ty.name()));
        std::fs::write(&path, bytes).unwrap();
        let (_, store) = import_and_compare(&path, None, ty, &values);
        assert_eq!(attributes(&store)["voxstream"]["unit"], "millimeter");
    }
}

#[test]
fn metaimage_and_raw_use_the_same_conversion() {
    let dir = scratch("mha-raw");
    let values = values(SampleType::I32);
    let mut mha = format!(
        "ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\nDimSize = {} {} {}\n\
         ElementType = MET_INT\nElementDataFile = LOCAL\n",
        DIMS[0], DIMS[1], DIMS[2]
    )
    .into_bytes();
    mha.extend(encode(SampleType::I32, &values, false));
    std::fs::write(dir.join("a.mha"), mha).unwrap();
    import_and_compare(&dir.join("a.mha"), None, SampleType::I32, &values);

    let values = values_f64_small();
    std::fs::write(dir.join("b.raw"), encode(SampleType::F64, &values, true)).unwrap();
    let layout = RawLayout {
        info: VolumeInfo {
            dims: DIMS,
            dtype: DType::F32,
            spacing: [1.0; 3],
            origin: [0.0; 3],
            unit: SpaceUnit::from_name("nm"),
            orientation: None,
        },
        file_type: Some(SampleType::F64),
        endian: Endian::Big,
        header_bytes: 0,
    };
    let (_, store) = import_and_compare(&dir.join("b.raw"), Some(&layout), SampleType::F64, &values);
    assert_eq!(attributes(&store)["voxstream"]["unit"], "nanometer");
}

/// float64 values that float32 holds exactly: the note says the conversion was exact.
fn values_f64_small() -> Vec<f64> {
    (0..DIMS.iter().product::<u64>()).map(|n| n as f64 * 0.25).collect()
}
