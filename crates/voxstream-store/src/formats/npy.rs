//! NumPy `.npy` (format versions 1–3) and `.npz` (its first array): a 3-D array of `u1`, `u2`, `i2` or `f4`, or of
//! `i1`, `i4`, `u4` or `f8` (converted: [`super::sample_type`]), C or Fortran order.
//!
//! A C-order array of shape `(Z, Y, X)` (NumPy's usual `volume[z, y, x]`) and a Fortran-order array of shape
//! `(X, Y, Z)` both have x fastest in the file, which is voxstream's order. Spacing 1, origin 0.

use std::io::Read;
use std::path::Path;

use super::sample_stream::{check_deflate_capacity, Compression, Endian, SampleStream};
use super::sample_type::SampleType;
use crate::error::StoreError;
use crate::volume::VolumeInfo;

/// A `.npy` file (format 1.0) of a C-order array of shape `(Z, Y, X)` = `shape_zyx` and type `descr` (`'<u2'`,
/// `'|i1'`, …) holding `data`, the bytes in that type and order: what `numpy.save` writes. For tests and tools that
/// hand voxstream NumPy files (the import reads them back with [`open`]).
pub fn npy_bytes(descr: &str, shape_zyx: [u64; 3], data: &[u8]) -> Vec<u8> {
    let [z, y, x] = shape_zyx;
    let mut header = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': ({z}, {y}, {x}), }}").into_bytes();
    // The magic (6), version (2), header length (2), header and its newline fill a multiple of 64 bytes.
    while !(10 + header.len() + 1).is_multiple_of(64) {
        header.push(b' ');
    }
    header.push(b'\n');
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend((header.len() as u16).to_le_bytes());
    bytes.extend(header);
    bytes.extend(data);
    bytes
}

/// Opens a `.npy` array.
pub fn open(path: &Path) -> Result<SampleStream, StoreError> {
    let mut file = std::fs::File::open(path).map_err(|e| StoreError::io(path, e))?;
    let (info, file_type, endian, header_bytes) = parse_header(&mut file, path)?;
    SampleStream::open(path, header_bytes, Compression::None, 0, info, file_type, endian)
}

/// Opens the first array of a `.npz` archive (stored or deflated), streaming it without extracting.
///
/// The entry's sizes come from the archive's central directory and are checked before anything is read: its
/// compressed bytes must lie inside the file, a stored entry's two sizes must agree, a deflated one cannot expand more
/// than deflate can, and the array header's shape must account for exactly the entry's uncompressed size. While
/// streaming, the entry's CRC32 and length are verified at its end.
pub fn open_npz(path: &Path) -> Result<SampleStream, StoreError> {
    let file = std::fs::File::open(path).map_err(|e| StoreError::io(path, e))?;
    let file_len = file.metadata().map_err(|e| StoreError::io(path, e))?.len();
    let mut archive =
        zip::ZipArchive::new(file).map_err(|e| StoreError::format(path, format!("not a .npz (zip) archive: {e}")))?;
    let entry = {
        let mut found = None;
        for i in 0..archive.len() {
            let entry =
                archive.by_index_raw(i).map_err(|e| StoreError::format(path, format!("corrupt archive: {e}")))?;
            if entry.name().ends_with(".npy") {
                found = Some(NpzEntry {
                    name: entry.name().to_string(),
                    start: entry.data_start(),
                    compressed: entry.compressed_size(),
                    size: entry.size(),
                    crc32: entry.crc32(),
                    method: entry.compression(),
                });
                break;
            }
        }
        found.ok_or_else(|| StoreError::format(path, "archive holds no .npy array"))?
    };
    let name = &entry.name;
    if entry.start.checked_add(entry.compressed).is_none_or(|end| end > file_len) {
        return Err(StoreError::format(
            path,
            format!(
                "{name}: {} compressed bytes at byte {} run past the end of the archive",
                entry.compressed, entry.start
            ),
        ));
    }
    let mut file = std::fs::File::open(path).map_err(|e| StoreError::io(path, e))?;
    std::io::Seek::seek(&mut file, std::io::SeekFrom::Start(entry.start)).map_err(|e| StoreError::io(path, e))?;
    let raw = std::io::BufReader::new(file).take(entry.compressed);
    let decoded: Box<dyn Read + Send> = match entry.method {
        zip::CompressionMethod::Stored if entry.size == entry.compressed => Box::new(raw),
        zip::CompressionMethod::Stored => {
            return Err(StoreError::format(
                path,
                format!("{name} is stored but its sizes differ ({} and {} bytes)", entry.compressed, entry.size),
            ))
        }
        zip::CompressionMethod::Deflated => {
            check_deflate_capacity(path, entry.compressed, entry.size)?;
            Box::new(flate2::bufread::DeflateDecoder::new(raw))
        }
        other => {
            return Err(StoreError::Unsupported {
                path: path.into(),
                message: format!("{name} is compressed with {other:?}"),
            })
        }
    };
    let mut reader = Crc32Checked::new(decoded, entry.crc32, entry.size);
    let (info, file_type, endian, header_bytes) = parse_header(&mut reader, path)?;
    let array_bytes = info.dims.iter().product::<u64>() * file_type.size() as u64;
    if header_bytes.checked_add(array_bytes) != Some(entry.size) {
        return Err(StoreError::format(
            path,
            format!(
                "{name}: the array header's shape {:?} needs {} bytes after its {header_bytes}-byte header, but the \
                 entry holds {} bytes",
                info.dims, array_bytes, entry.size
            ),
        ));
    }
    SampleStream::from_reader(path, Box::new(reader), info, file_type, endian)
}

/// Where the first array of a `.npz` lies, as the central directory says.
struct NpzEntry {
    name: String,
    start: u64,
    compressed: u64,
    size: u64,
    crc32: u32,
    method: zip::CompressionMethod,
}

/// A reader that checks, at its end, that it delivered exactly `size` bytes whose CRC32 is `crc32` (a zip entry's).
struct Crc32Checked {
    inner: Box<dyn Read + Send>,
    hasher: crc32fast::Hasher,
    crc32: u32,
    size: u64,
    read: u64,
}

impl Crc32Checked {
    fn new(inner: Box<dyn Read + Send>, crc32: u32, size: u64) -> Crc32Checked {
        Crc32Checked { inner, hasher: crc32fast::Hasher::new(), crc32, size, read: 0 }
    }
}

impl Read for Crc32Checked {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.hasher.update(&buf[..n]);
        self.read += n as u64;
        let invalid = |m: String| Err(std::io::Error::new(std::io::ErrorKind::InvalidData, m));
        if self.read > self.size {
            return invalid(format!("the zip entry holds more than its stated {} bytes", self.size));
        }
        if n == 0 && !buf.is_empty() {
            if self.read < self.size {
                return invalid(format!("the zip entry ends after {} of its {} bytes", self.read, self.size));
            }
            let crc = self.hasher.clone().finalize();
            if crc != self.crc32 {
                return invalid(format!("zip CRC32 mismatch (stored {:08x}, data {crc:08x})", self.crc32));
            }
        }
        Ok(n)
    }
}

/// The longest `.npy` header read: NumPy itself refuses headers over 10,000 bytes unless told otherwise.
pub const MAX_NPY_HEADER_BYTES: u64 = 1 << 16;

/// Reads a `.npy` header; returns the geometry (validated), the sample type, the byte order and the header's length
/// in bytes.
fn parse_header(file: &mut dyn Read, path: &Path) -> Result<(VolumeInfo, SampleType, Endian, u64), StoreError> {
    let mut magic = [0u8; 8];
    file.read_exact(&mut magic).map_err(|_| StoreError::format(path, "too short for a .npy file"))?;
    if &magic[..6] != b"\x93NUMPY" {
        return Err(StoreError::format(path, "not a .npy file (bad magic)"));
    }
    let (length_bytes, prefix) = match magic[6] {
        1 => (2usize, 10u64),
        2 | 3 => (4, 12),
        v => return Err(StoreError::Unsupported { path: path.into(), message: format!(".npy format version {v}") }),
    };
    let mut length = [0u8; 4];
    file.read_exact(&mut length[..length_bytes]).map_err(|_| StoreError::format(path, "truncated .npy header"))?;
    let header_len = u32::from_le_bytes(length) as u64;
    if header_len > MAX_NPY_HEADER_BYTES {
        return Err(StoreError::format(
            path,
            format!("the .npy header claims {header_len} bytes (at most {MAX_NPY_HEADER_BYTES} are read)"),
        ));
    }
    let mut header = vec![0u8; header_len as usize];
    file.read_exact(&mut header).map_err(|_| StoreError::format(path, "truncated .npy header"))?;
    let header = String::from_utf8_lossy(&header).into_owned();
    let field = |key: &str| -> Option<String> {
        let start = header.find(&format!("'{key}'"))? + key.len() + 2;
        let rest = header[start..].trim_start().strip_prefix(':')?.trim_start();
        let end = if rest.starts_with('(') { rest.find(')')? + 1 } else { rest.find([',', '}'])? };
        Some(rest[..end].trim().trim_matches('\'').to_string())
    };
    let descr = field("descr").ok_or_else(|| StoreError::format(path, "header has no 'descr'"))?;
    let fortran =
        field("fortran_order").ok_or_else(|| StoreError::format(path, "header has no 'fortran_order'"))? == "True";
    let shape_text = field("shape").ok_or_else(|| StoreError::format(path, "header has no 'shape'"))?;
    let shape: Vec<u64> = shape_text
        .trim_matches(['(', ')'])
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse().map_err(|_| StoreError::format(path, format!("bad shape '{shape_text}'"))))
        .collect::<Result<_, _>>()?;
    if shape.len() != 3 {
        return Err(StoreError::Unsupported {
            path: path.into(),
            message: format!("{}-D array (only 3-D)", shape.len()),
        });
    }
    let endian = if descr.starts_with('>') { Endian::Big } else { Endian::Little };
    let file_type = match descr.trim_start_matches(['<', '>', '|', '=']) {
        "u1" => SampleType::U8,
        "u2" => SampleType::U16,
        "i2" => SampleType::I16,
        "f4" => SampleType::F32,
        "i1" => SampleType::I8,
        "i4" => SampleType::I32,
        "u4" => SampleType::U32,
        "f8" => SampleType::F64,
        other => {
            return Err(StoreError::Unsupported {
                path: path.into(),
                message: format!(
                    "dtype '{other}' (u1, u2, i2, f4 are stored as they are; i1, i4, u4, f8 converted): convert the \
                     array first, e.g. array.astype(numpy.float32)"
                ),
            })
        }
    };
    let dims = if fortran { [shape[0], shape[1], shape[2]] } else { [shape[2], shape[1], shape[0]] };
    let info = VolumeInfo {
        dims,
        dtype: file_type.stored(),
        spacing: [1.0; 3],
        origin: [0.0; 3],
        unit: None,
        orientation: None,
    };
    info.validate(path)?;
    Ok((info, file_type, endian, prefix + header_len))
}
