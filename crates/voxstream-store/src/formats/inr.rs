//! INRIMAGE-4 (`.inr`, `.inr.gz`), as written by CGAL: a text header padded to a multiple of 256 bytes. 8-bit signed,
//! 32-bit integer and 64-bit float samples are converted ([`super::sample_type`]).

use std::io::Read;
use std::path::Path;

use super::header_text::numbers;
use super::sample_stream::{Compression, Endian, SampleStream};
use super::sample_type::SampleType;
use crate::error::StoreError;
use crate::volume::VolumeInfo;

/// Opens an INR volume.
pub fn open(path: &Path, is_gzip: bool) -> Result<SampleStream, StoreError> {
    let file = std::fs::File::open(path).map_err(|e| StoreError::io(path, e))?;
    let mut reader: Box<dyn Read> =
        if is_gzip { Box::new(flate2::read::MultiGzDecoder::new(file)) } else { Box::new(file) };
    let mut header = Vec::new();
    let mut block = [0u8; 256];
    loop {
        reader.read_exact(&mut block).map_err(|_| StoreError::format(path, "header shorter than 256 bytes"))?;
        header.extend_from_slice(&block);
        if header.windows(3).any(|w| w == b"##}") || header.len() > 1 << 16 {
            break;
        }
    }
    let text = String::from_utf8_lossy(&header);
    if !text.starts_with("#INRIMAGE-4#{") {
        return Err(StoreError::format(path, "not an INRIMAGE-4 file"));
    }
    let mut dims = [0u64; 3];
    let (mut kind, mut bits, mut vdim) = (String::new(), 0u32, 1u64);
    let (mut spacing, mut origin, mut endian) = ([1.0; 3], [0.0; 3], Endian::Little);
    for line in text.lines() {
        let Some((key, value)) = line.split_once('=') else { continue };
        let value = value.trim();
        let number = |k: &str| numbers::<f64>(path, k, value, 1).map(|v| v[0]);
        match key.trim() {
            "XDIM" => dims[0] = number("XDIM")? as u64,
            "YDIM" => dims[1] = number("YDIM")? as u64,
            "ZDIM" => dims[2] = number("ZDIM")? as u64,
            "VDIM" => vdim = number("VDIM")? as u64,
            "TYPE" => kind = value.to_string(),
            "PIXSIZE" => bits = numbers::<u32>(path, "PIXSIZE", value.trim_end_matches("bits"), 1)?[0],
            "VX" => spacing[0] = number("VX")?,
            "VY" => spacing[1] = number("VY")?,
            "VZ" => spacing[2] = number("VZ")?,
            "TX" => origin[0] = number("TX")?,
            "TY" => origin[1] = number("TY")?,
            "TZ" => origin[2] = number("TZ")?,
            "CPU" => endian = if matches!(value, "sun" | "sgi") { Endian::Big } else { Endian::Little },
            _ => {}
        }
    }
    if vdim != 1 {
        return Err(StoreError::Unsupported { path: path.into(), message: format!("VDIM={vdim} (vector images)") });
    }
    let dtype = match (kind.as_str(), bits) {
        ("unsigned fixed", 8) => SampleType::U8,
        ("unsigned fixed", 16) => SampleType::U16,
        ("signed fixed", 16) => SampleType::I16,
        ("float", 32) => SampleType::F32,
        ("signed fixed", 8) => SampleType::I8,
        ("signed fixed", 32) => SampleType::I32,
        ("unsigned fixed", 32) => SampleType::U32,
        ("float", 64) => SampleType::F64,
        (k, b) => {
            return Err(StoreError::Unsupported { path: path.into(), message: format!("TYPE={k} PIXSIZE={b} bits") })
        }
    };
    let info = VolumeInfo { dims, dtype: dtype.stored(), spacing, origin, unit: None, orientation: None };
    let header_len = header.len() as u64;
    if is_gzip {
        SampleStream::open(path, 0, Compression::Gzip, header_len, info, dtype, endian)
    } else {
        SampleStream::open(path, header_len, Compression::None, 0, info, dtype, endian)
    }
}
