//! NRRD (`.nrrd` with attached data, `.nhdr` with a detached data file), raw and gzip encodings
//! (http://teem.sourceforge.net/nrrd/format.html).
//!
//! `signed char`, `int`, `unsigned int` and `double` samples are converted ([`super::sample_type`]). `space units`
//! gives the spacing's unit when all three are one OME-Zarr unit (`"mm" "mm" "mm"`); other units are left out. An
//! anatomical `space` (RAS, LAS, LPS) with `space directions` gives the axes' orientation ([`crate::Orientation`]).

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use super::header_text::{numbers, read_line, three};
use super::sample_stream::{Compression, Endian, SampleStream};
use super::sample_type::SampleType;
use crate::error::StoreError;
use crate::orientation::Orientation;
use crate::space_unit::SpaceUnit;
use crate::volume::VolumeInfo;

/// Opens a NRRD volume.
pub fn open(path: &Path) -> Result<SampleStream, StoreError> {
    let file = File::open(path).map_err(|e| StoreError::io(path, e))?;
    let mut reader = BufReader::new(file);
    let mut line = String::new();
    let mut header_bytes = 0u64;
    let mut first = true;
    let (mut dtype, mut dims, mut encoding, mut endian) = (None, None, None, Endian::Little);
    let (mut spacing, mut origin, mut data_file) = ([1.0; 3], [0.0; 3], None::<String>);
    let (mut unit, mut space, mut directions) = (None, None::<String>, None::<[[f64; 3]; 3]>);
    loop {
        let read = read_line(path, &mut reader, &mut line, &mut header_bytes)?;
        if read == 0 {
            if data_file.is_none() {
                return Err(StoreError::format(path, "header ends without a blank line before the data"));
            }
            break;
        }
        let text = line.trim_end_matches(['\n', '\r']);
        if first {
            if !text.starts_with("NRRD000") {
                return Err(StoreError::format(path, "not a NRRD file (no NRRD000x magic)"));
            }
            first = false;
            continue;
        }
        if text.is_empty() {
            break;
        }
        if text.starts_with('#') || text.contains(":=") {
            continue;
        }
        let Some((key, value)) = text.split_once(':') else {
            return Err(StoreError::format(path, format!("malformed header line '{text}'")));
        };
        let value = value.trim();
        match key.trim().to_ascii_lowercase().as_str() {
            "type" => {
                dtype = Some(match value {
                    "uchar" | "unsigned char" | "uint8" | "uint8_t" => SampleType::U8,
                    "ushort" | "unsigned short" | "unsigned short int" | "uint16" | "uint16_t" => SampleType::U16,
                    "short" | "short int" | "signed short" | "signed short int" | "int16" | "int16_t" => {
                        SampleType::I16
                    }
                    "float" => SampleType::F32,
                    "signed char" | "int8" | "int8_t" => SampleType::I8,
                    "int" | "signed int" | "int32" | "int32_t" => SampleType::I32,
                    "uint" | "unsigned int" | "uint32" | "uint32_t" => SampleType::U32,
                    "double" => SampleType::F64,
                    other => {
                        return Err(StoreError::Unsupported {
                            path: path.into(),
                            message: format!(
                                "sample type '{other}' (supported: uchar, ushort, short, float; converted: signed \
                                 char, int, uint, double)"
                            ),
                        })
                    }
                })
            }
            "dimension" => {
                if value != "3" {
                    return Err(StoreError::Unsupported {
                        path: path.into(),
                        message: format!("dimension {value} (only 3)"),
                    });
                }
            }
            "sizes" => dims = Some(three::<u64>(path, "sizes", value)?),
            "encoding" => encoding = Some(value.to_ascii_lowercase()),
            "endian" => endian = if value == "big" { Endian::Big } else { Endian::Little },
            "spacings" => spacing = three(path, "spacings", value)?,
            "space directions" => {
                let v = numbers::<f64>(path, "space directions", value, 9)?;
                spacing = [0, 1, 2].map(|a| (v[3 * a].powi(2) + v[3 * a + 1].powi(2) + v[3 * a + 2].powi(2)).sqrt());
                directions = Some([0, 1, 2].map(|a| [v[3 * a], v[3 * a + 1], v[3 * a + 2]]));
            }
            "space origin" => origin = three(path, "space origin", value)?,
            "space" => space = Some(value.to_ascii_lowercase()),
            "space units" => unit = space_units(value),
            "data file" | "datafile" => data_file = Some(value.to_string()),
            _ => {}
        }
    }
    let dtype = dtype.ok_or_else(|| StoreError::format(path, "header has no 'type'"))?;
    let dims = dims.ok_or_else(|| StoreError::format(path, "header has no 'sizes'"))?;
    let compression = match encoding.as_deref() {
        Some("raw") => Compression::None,
        Some("gzip") | Some("gz") => Compression::Gzip,
        Some(other) => {
            return Err(StoreError::Unsupported {
                path: path.into(),
                message: format!("encoding '{other}' (raw, gzip)"),
            })
        }
        None => return Err(StoreError::format(path, "header has no 'encoding'")),
    };
    // The axes' directions in the anatomical `space` the file names, turned into RAS.
    let flips = match space.as_deref() {
        Some("right-anterior-superior" | "ras") => Some([1.0, 1.0, 1.0]),
        Some("left-anterior-superior" | "las") => Some([-1.0, 1.0, 1.0]),
        Some("left-posterior-superior" | "lps") => Some([-1.0, -1.0, 1.0]),
        _ => None,
    };
    let orientation = match (flips, directions) {
        (Some(f), Some(d)) => Orientation::nearest_ras(d.map(|v| [v[0] * f[0], v[1] * f[1], v[2] * f[2]])),
        _ => None,
    };
    let info = VolumeInfo { dims, dtype: dtype.stored(), spacing, origin, unit, orientation };
    match data_file {
        Some(name) => {
            let data_path = path.parent().unwrap_or(Path::new(".")).join(name);
            SampleStream::open(&data_path, 0, compression, 0, info, dtype, endian)
        }
        None => SampleStream::open(path, header_bytes, compression, 0, info, dtype, endian),
    }
}

/// The unit of a `space units` field (`"mm" "mm" "mm"`): one OME-Zarr unit shared by every axis, else none.
fn space_units(value: &str) -> Option<SpaceUnit> {
    let units: Vec<&str> = value.split('"').skip(1).step_by(2).collect();
    let first = SpaceUnit::from_name(units.first()?)?;
    units.iter().all(|u| SpaceUnit::from_name(u) == Some(first)).then_some(first)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn space_units_must_be_one_known_unit() {
        assert_eq!(space_units(r#""mm" "mm" "mm""#).map(SpaceUnit::name), Some("millimeter"));
        assert_eq!(space_units(r#""microns" "µm" "micrometer""#).map(SpaceUnit::name), Some("micrometer"));
        assert_eq!(space_units(r#""mm" "mm" "cm""#), None);
        assert_eq!(space_units(r#""furlong" "furlong" "furlong""#), None);
        assert_eq!(space_units("mm mm mm"), None);
    }
}
