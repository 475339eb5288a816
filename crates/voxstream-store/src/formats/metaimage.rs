//! MetaImage (`.mha` with local data, `.mhd` with a data file), ITK's text-header format, raw or zlib-compressed.
//! `MET_CHAR`, `MET_INT`, `MET_UINT` and `MET_DOUBLE` samples are converted ([`super::sample_type`]). The direction
//! cosines (`TransformMatrix`, in ITK's LPS) give the axes' anatomical orientation ([`crate::Orientation`]).

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use super::header_text::{numbers, read_line, three};
use super::sample_stream::{Compression, Endian, SampleStream};
use super::sample_type::SampleType;
use crate::error::StoreError;
use crate::orientation::Orientation;
use crate::volume::VolumeInfo;

/// Opens a MetaImage volume.
pub fn open(path: &Path) -> Result<SampleStream, StoreError> {
    let file = File::open(path).map_err(|e| StoreError::io(path, e))?;
    let mut reader = BufReader::new(file);
    let mut line = String::new();
    let mut header_bytes = 0u64;
    let (mut dims, mut dtype, mut data_file) = (None, None, None::<String>);
    let (mut spacing, mut origin, mut endian, mut compression) =
        ([1.0; 3], [0.0; 3], Endian::Little, Compression::None);
    let mut orientation = None;
    loop {
        let read = read_line(path, &mut reader, &mut line, &mut header_bytes)?;
        if read == 0 {
            break;
        }
        let Some((key, value)) = line.split_once('=') else {
            return Err(StoreError::format(path, format!("malformed header line '{}'", line.trim())));
        };
        let value = value.trim();
        match key.trim() {
            "NDims" if value != "3" => {
                return Err(StoreError::Unsupported { path: path.into(), message: format!("NDims = {value} (only 3)") })
            }
            "DimSize" => dims = Some(three::<u64>(path, "DimSize", value)?),
            "ElementSpacing" | "ElementSize" => spacing = three(path, "ElementSpacing", value)?,
            "Offset" | "Position" | "Origin" => origin = three(path, "Offset", value)?,
            // ITK's direction cosines, one axis after the other, in LPS.
            "TransformMatrix" | "Rotation" | "Orientation" => {
                let v = numbers::<f64>(path, "TransformMatrix", value, 9)?;
                orientation = Orientation::nearest_lps([0, 1, 2].map(|a| [v[3 * a], v[3 * a + 1], v[3 * a + 2]]));
            }
            "ElementNumberOfChannels" if value != "1" => {
                return Err(StoreError::Unsupported { path: path.into(), message: "multi-channel images".into() })
            }
            "BinaryDataByteOrderMSB" | "ElementByteOrderMSB" => {
                endian = if value.eq_ignore_ascii_case("true") { Endian::Big } else { Endian::Little }
            }
            "CompressedData" => {
                compression = if value.eq_ignore_ascii_case("true") { Compression::Zlib } else { Compression::None }
            }
            "ElementType" => {
                dtype = Some(match value {
                    "MET_UCHAR" => SampleType::U8,
                    "MET_USHORT" => SampleType::U16,
                    "MET_SHORT" => SampleType::I16,
                    "MET_FLOAT" => SampleType::F32,
                    "MET_CHAR" => SampleType::I8,
                    "MET_INT" => SampleType::I32,
                    "MET_UINT" => SampleType::U32,
                    "MET_DOUBLE" => SampleType::F64,
                    other => {
                        return Err(StoreError::Unsupported {
                            path: path.into(),
                            message: format!(
                                "ElementType {other} (MET_UCHAR, MET_USHORT, MET_SHORT, MET_FLOAT; converted: \
                                 MET_CHAR, MET_INT, MET_UINT, MET_DOUBLE)"
                            ),
                        })
                    }
                })
            }
            "ElementDataFile" => {
                data_file = Some(value.to_string());
                break;
            }
            _ => {}
        }
    }
    let dims = dims.ok_or_else(|| StoreError::format(path, "header has no DimSize"))?;
    let dtype = dtype.ok_or_else(|| StoreError::format(path, "header has no ElementType"))?;
    let data_file = data_file.ok_or_else(|| StoreError::format(path, "header has no ElementDataFile"))?;
    let info = VolumeInfo { dims, dtype: dtype.stored(), spacing, origin, unit: None, orientation };
    if data_file == "LOCAL" {
        SampleStream::open(path, header_bytes, compression, 0, info, dtype, endian)
    } else {
        let data_path = path.parent().unwrap_or(Path::new(".")).join(data_file);
        SampleStream::open(&data_path, 0, compression, 0, info, dtype, endian)
    }
}
