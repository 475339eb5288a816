//! NRRD (`.nrrd` with attached data, `.nhdr` with a detached data file), raw and gzip encodings
//! (http://teem.sourceforge.net/nrrd/format.html).

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use super::header_text::{numbers, read_line, three};
use super::sample_stream::{Compression, Endian, SampleStream};
use crate::error::StoreError;
use crate::volume::{DType, VolumeInfo};

/// Opens a NRRD volume.
pub fn open(path: &Path) -> Result<SampleStream, StoreError> {
    let file = File::open(path).map_err(|e| StoreError::io(path, e))?;
    let mut reader = BufReader::new(file);
    let mut line = String::new();
    let mut header_bytes = 0u64;
    let mut first = true;
    let (mut dtype, mut dims, mut encoding, mut endian) = (None, None, None, Endian::Little);
    let (mut spacing, mut origin, mut data_file) = ([1.0; 3], [0.0; 3], None::<String>);
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
                    "uchar" | "unsigned char" | "uint8" | "uint8_t" => DType::U8,
                    "ushort" | "unsigned short" | "unsigned short int" | "uint16" | "uint16_t" => DType::U16,
                    "short" | "short int" | "signed short" | "signed short int" | "int16" | "int16_t" => DType::I16,
                    "float" => DType::F32,
                    other => {
                        return Err(StoreError::Unsupported {
                            path: path.into(),
                            message: format!("sample type '{other}' (supported: uchar, ushort, short, float)"),
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
            }
            "space origin" => origin = three(path, "space origin", value)?,
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
    let info = VolumeInfo { dims, dtype, spacing, origin };
    match data_file {
        Some(name) => {
            let data_path = path.parent().unwrap_or(Path::new(".")).join(name);
            SampleStream::open(&data_path, 0, compression, 0, info, endian)
        }
        None => SampleStream::open(path, header_bytes, compression, 0, info, endian),
    }
}
