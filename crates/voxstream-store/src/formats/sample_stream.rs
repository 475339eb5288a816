//! A stream of raw samples (any endianness, optionally gzip-compressed) after a header: the common tail of every
//! importer.

use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use crate::error::StoreError;
use crate::volume::{DType, VolumeInfo, VolumeSource};

/// Byte order of the samples in the file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Endian {
    /// Least significant byte first.
    Little,
    /// Most significant byte first.
    Big,
}

/// How the samples are compressed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Compression {
    /// Plain bytes.
    None,
    /// A gzip stream (NRRD `gzip`, `.nii.gz`, `.inr.gz`).
    Gzip,
    /// A zlib stream (MetaImage `CompressedData = True`).
    Zlib,
}

/// Samples following a header, read slice by slice.
pub struct SampleStream {
    info: VolumeInfo,
    /// Sample type in the file (the reported type becomes f32 when a scaling applies).
    file_dtype: DType,
    /// `value · slope + intercept`, if the header asks for it.
    scaling: Option<(f32, f32)>,
    endian: Endian,
    reader: Box<dyn Read + Send>,
    path: PathBuf,
    /// Bytes of samples read so far.
    consumed: u64,
    bytes: Vec<u8>,
}

impl SampleStream {
    /// Samples of `info` in `path`. For [`Compression::None`] they start at byte `offset` and the file size is checked
    /// against the header now; compressed data starts at the file's byte `offset` and, once decompressed, skips
    /// `decompressed_offset` bytes.
    pub fn open(
        path: &Path,
        offset: u64,
        compression: Compression,
        decompressed_offset: u64,
        info: VolumeInfo,
        endian: Endian,
    ) -> Result<SampleStream, StoreError> {
        info.validate(path)?;
        let mut file = File::open(path).map_err(|e| StoreError::io(path, e))?;
        let reader: Box<dyn Read + Send> = if compression != Compression::None {
            file.seek(SeekFrom::Start(offset)).map_err(|e| StoreError::io(path, e))?;
            let buffered = BufReader::with_capacity(1 << 20, file);
            let mut decoder: Box<dyn Read + Send> = match compression {
                Compression::Gzip => Box::new(flate2::read::MultiGzDecoder::new(buffered)),
                _ => Box::new(flate2::read::ZlibDecoder::new(buffered)),
            };
            let offset = decompressed_offset;
            let skipped = std::io::copy(&mut (&mut decoder).take(offset), &mut std::io::sink())
                .map_err(|e| gzip_error(path, e))?;
            if skipped < offset {
                return Err(StoreError::Truncated { path: path.into(), expected: offset, found: skipped });
            }
            decoder
        } else {
            let size = file.metadata().map_err(|e| StoreError::io(path, e))?.len();
            let needed = offset + info.byte_len();
            if size < needed {
                return Err(StoreError::Truncated {
                    path: path.into(),
                    expected: info.byte_len(),
                    found: size.saturating_sub(offset),
                });
            }
            file.seek(SeekFrom::Start(offset)).map_err(|e| StoreError::io(path, e))?;
            Box::new(BufReader::with_capacity(1 << 20, file))
        };
        SampleStream::from_reader(path, reader, info, endian)
    }

    /// Applies `value · slope + intercept` to every sample; the volume is then reported (and stored) as f32.
    pub fn with_scaling(mut self, slope: f32, intercept: f32) -> SampleStream {
        self.scaling = Some((slope, intercept));
        self.info.dtype = DType::F32;
        self
    }
}

impl SampleStream {
    /// Samples of `info` from any reader (a decoded in-memory buffer, say), reported under `path`.
    pub fn from_reader(
        path: &Path,
        reader: Box<dyn Read + Send>,
        info: VolumeInfo,
        endian: Endian,
    ) -> Result<SampleStream, StoreError> {
        info.validate(path)?;
        let file_dtype = info.dtype;
        Ok(SampleStream {
            info,
            file_dtype,
            scaling: None,
            endian,
            reader,
            path: path.into(),
            consumed: 0,
            bytes: Vec::new(),
        })
    }
}

fn gzip_error(path: &Path, error: std::io::Error) -> StoreError {
    StoreError::format(path, format!("corrupt gzip data: {error}"))
}

impl VolumeSource for SampleStream {
    fn info(&self) -> &VolumeInfo {
        &self.info
    }

    fn read_slices(&mut self, count: usize, out: &mut Vec<f32>) -> Result<(), StoreError> {
        let samples = count * self.info.slice_len();
        let size = self.file_dtype.size();
        self.bytes.resize(samples * size, 0);
        let mut filled = 0;
        while filled < self.bytes.len() {
            match self.reader.read(&mut self.bytes[filled..]) {
                Ok(0) => {
                    return Err(StoreError::Truncated {
                        path: self.path.clone(),
                        expected: self.info.slice_len() as u64 * self.info.dims[2] * size as u64,
                        found: self.consumed + filled as u64,
                    })
                }
                Ok(n) => filled += n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e)
                    if e.kind() == std::io::ErrorKind::InvalidInput || e.kind() == std::io::ErrorKind::InvalidData =>
                {
                    return Err(gzip_error(&self.path, e))
                }
                Err(e) => return Err(StoreError::io(&self.path, e)),
            }
        }
        self.consumed += filled as u64;
        out.reserve(samples);
        let start = out.len();
        let big = self.endian == Endian::Big;
        match self.file_dtype {
            DType::U8 => out.extend(self.bytes.iter().map(|&b| b as f32)),
            DType::U16 => out.extend(self.bytes.chunks_exact(2).map(|c| {
                let a = [c[0], c[1]];
                (if big { u16::from_be_bytes(a) } else { u16::from_le_bytes(a) }) as f32
            })),
            DType::I16 => out.extend(self.bytes.chunks_exact(2).map(|c| {
                let a = [c[0], c[1]];
                (if big { i16::from_be_bytes(a) } else { i16::from_le_bytes(a) }) as f32
            })),
            DType::F32 => out.extend(self.bytes.chunks_exact(4).map(|c| {
                let a = [c[0], c[1], c[2], c[3]];
                if big {
                    f32::from_be_bytes(a)
                } else {
                    f32::from_le_bytes(a)
                }
            })),
        }
        if let Some((slope, intercept)) = self.scaling {
            out[start..].iter_mut().for_each(|v| *v = *v * slope + intercept);
        }
        Ok(())
    }
}
