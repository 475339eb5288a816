//! A stream of raw samples (any endianness, optionally gzip- or zlib-compressed) after a header: the common tail of
//! every importer.
//!
//! Nothing is allocated from a header's word alone: a plain file must hold every sample the header announces (checked
//! against its length on open); a compressed stream may announce at most [`DEFLATE_MAX_RATIO`] times its compressed
//! length (the most deflate can expand), and is then read in chunks of at most [`READ_CHUNK_BYTES`], so memory grows
//! only with data that actually arrives. A compressed (or otherwise streamed) input is read to its very end once the
//! last sample is in: that is where gzip's CRC32 and ISIZE trailers, zlib's adler32 and a zip entry's CRC are checked,
//! and where data beyond the announced samples (the header's sizes are wrong) or garbage after the stream is refused.
//!
//! Samples of a type a store does not keep (int8, int32, uint32, float64) are converted here, as they stream, to the
//! type [`SampleType::stored`] names; [`SampleStream`] counts what the conversion rounded ([`SampleConversion`]).

use std::fs::File;
use std::io::{BufRead, BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use super::sample_type::{decode, SampleConversion, SampleType};
use crate::error::StoreError;
use crate::volume::{DType, VolumeInfo, VolumeSource};

/// The most a deflate stream (gzip, zlib, zip's deflate) expands: a 258-byte match costs at least 2 bits, 1032:1.
pub const DEFLATE_MAX_RATIO: u64 = 1032;

/// Bytes read from the input at a time: the per-read buffer, whatever the slice size.
pub const READ_CHUNK_BYTES: usize = 1 << 20;

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
    /// A gzip stream (NRRD `gzip`, `.nii.gz`, `.inr.gz`): one or more members, each with its CRC32 and ISIZE.
    Gzip,
    /// A zlib stream (MetaImage `CompressedData = True`), with its adler32.
    Zlib,
}

/// Checks that `compressed_bytes` of deflate data can hold `needed` decompressed bytes (gzip and zlib framing add
/// a few bytes; [`DEFLATE_MAX_RATIO`] is the ceiling), so a header cannot make the importer wait for, or size its
/// buffers by, data that cannot be there.
pub fn check_deflate_capacity(path: &Path, compressed_bytes: u64, needed: u64) -> Result<(), StoreError> {
    let capacity = compressed_bytes.saturating_mul(DEFLATE_MAX_RATIO);
    if needed > capacity {
        return Err(StoreError::format(
            path,
            format!(
                "the header announces {needed} bytes of samples, but {compressed_bytes} compressed bytes can hold at \
                 most {capacity} (deflate expands at most {DEFLATE_MAX_RATIO}:1): the sizes in the header are wrong \
                 or the file is truncated"
            ),
        ));
    }
    Ok(())
}

/// The decompressing reader of a file, kept concrete so that the end of the stream can be checked.
enum Decoded {
    Plain(BufReader<File>),
    Gzip(flate2::bufread::MultiGzDecoder<BufReader<File>>),
    Zlib(flate2::bufread::ZlibDecoder<BufReader<File>>),
    Other(Box<dyn Read + Send>),
}

impl Read for Decoded {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        match self {
            Decoded::Plain(r) => r.read(buf),
            Decoded::Gzip(r) => r.read(buf),
            Decoded::Zlib(r) => r.read(buf),
            Decoded::Other(r) => r.read(buf),
        }
    }
}

/// Samples following a header, read slice by slice.
pub struct SampleStream {
    info: VolumeInfo,
    /// Sample type in the file (the reported type is the one it is stored as, and f32 when a scaling applies).
    file_type: SampleType,
    /// What converting a type the store does not keep has done so far.
    conversion: Option<SampleConversion>,
    /// `value · slope + intercept`, if the header asks for it.
    scaling: Option<(f32, f32)>,
    endian: Endian,
    reader: Decoded,
    path: PathBuf,
    /// Bytes of samples the header announces.
    total: u64,
    /// Bytes of samples read so far.
    consumed: u64,
    /// Read the stream to its end after the last sample (compressed and streamed inputs), verifying checksums.
    verify_end: bool,
    bytes: Vec<u8>,
}

impl SampleStream {
    /// Samples of `info`'s dimensions and `file_type` in `path` (`info`'s dtype becomes the type they are stored as,
    /// [`SampleType::stored`]). For [`Compression::None`] they start at byte `offset` and the file size is checked
    /// against the header now; compressed data starts at the file's byte `offset` and, once decompressed, skips
    /// `decompressed_offset` bytes; its compressed length is checked against the header with
    /// [`check_deflate_capacity`] now, its checksums and exact length once the last sample is read.
    pub fn open(
        path: &Path,
        offset: u64,
        compression: Compression,
        decompressed_offset: u64,
        mut info: VolumeInfo,
        file_type: SampleType,
        endian: Endian,
    ) -> Result<SampleStream, StoreError> {
        info.validate(path)?;
        info.dtype = file_type.stored();
        let file_bytes = file_bytes(&info, file_type);
        let mut file = File::open(path).map_err(|e| StoreError::io(path, e))?;
        let size = file.metadata().map_err(|e| StoreError::io(path, e))?.len();
        let available = size.checked_sub(offset).ok_or_else(|| {
            StoreError::format(path, format!("the data starts at byte {offset}, past the end of the {size}-byte file"))
        })?;
        file.seek(SeekFrom::Start(offset)).map_err(|e| StoreError::io(path, e))?;
        let buffered = BufReader::with_capacity(READ_CHUNK_BYTES, file);
        let reader = match compression {
            Compression::None => {
                if available < file_bytes {
                    return Err(StoreError::Truncated { path: path.into(), expected: file_bytes, found: available });
                }
                Decoded::Plain(buffered)
            }
            Compression::Gzip | Compression::Zlib => {
                check_deflate_capacity(path, available, decompressed_offset.saturating_add(file_bytes))?;
                let mut decoder = match compression {
                    Compression::Gzip => Decoded::Gzip(flate2::bufread::MultiGzDecoder::new(buffered)),
                    _ => Decoded::Zlib(flate2::bufread::ZlibDecoder::new(buffered)),
                };
                let skipped = std::io::copy(&mut (&mut decoder).take(decompressed_offset), &mut std::io::sink())
                    .map_err(|e| corrupt(path, compression_name(&decoder), e))?;
                if skipped < decompressed_offset {
                    return Err(StoreError::Truncated {
                        path: path.into(),
                        expected: decompressed_offset + file_bytes,
                        found: skipped,
                    });
                }
                decoder
            }
        };
        let mut stream = SampleStream::from_decoded(path, reader, info, file_type, endian)?;
        stream.verify_end = compression != Compression::None;
        Ok(stream)
    }

    /// Applies `value · slope + intercept` to every sample; the volume is then reported (and stored) as f32.
    pub fn with_scaling(mut self, slope: f32, intercept: f32) -> SampleStream {
        self.scaling = Some((slope, intercept));
        self.info.dtype = DType::F32;
        // int8 becomes float32 by the scaling, exactly: no int16 in between to speak of.
        if self.file_type == SampleType::I8 {
            self.conversion = None;
        }
        self
    }

    /// Samples of `info`'s dimensions and `file_type` from any reader (a decoded in-memory buffer, a zip entry, a
    /// converter's output), reported under `path`. The reader must hold exactly the samples: it is read to its end
    /// after the last one, so a checksumming reader gets to check, and anything more is refused.
    pub fn from_reader(
        path: &Path,
        reader: Box<dyn Read + Send>,
        info: VolumeInfo,
        file_type: SampleType,
        endian: Endian,
    ) -> Result<SampleStream, StoreError> {
        let mut stream = SampleStream::from_decoded(path, Decoded::Other(reader), info, file_type, endian)?;
        stream.verify_end = true;
        Ok(stream)
    }

    fn from_decoded(
        path: &Path,
        reader: Decoded,
        mut info: VolumeInfo,
        file_type: SampleType,
        endian: Endian,
    ) -> Result<SampleStream, StoreError> {
        info.validate(path)?;
        info.dtype = file_type.stored();
        Ok(SampleStream {
            total: file_bytes(&info, file_type),
            info,
            file_type,
            conversion: file_type.is_converted().then(|| SampleConversion::new(file_type)),
            scaling: None,
            endian,
            reader,
            path: path.into(),
            consumed: 0,
            verify_end: false,
            bytes: Vec::new(),
        })
    }

    /// Reads the stream to its end: checksums are verified there, and no byte may follow the samples.
    fn verify_end_of_stream(&mut self) -> Result<(), StoreError> {
        let mut probe = [0u8; 4096];
        loop {
            match self.reader.read(&mut probe) {
                Ok(0) => break,
                Ok(_) => {
                    return Err(StoreError::format(
                        &self.path,
                        format!(
                            "more data follows the {} bytes of samples the header announces: the header's sizes or \
                             type are wrong",
                            self.total
                        ),
                    ))
                }
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e)
                    if e.kind() == std::io::ErrorKind::UnexpectedEof
                        || e.kind() == std::io::ErrorKind::InvalidInput =>
                {
                    return Err(StoreError::format(
                        &self.path,
                        format!(
                            "corrupt {} data: {e} (at the end of the stream: a damaged file, or bytes after the stream)",
                            compression_name(&self.reader)
                        ),
                    ))
                }
                Err(e) => return Err(self.read_error(e)),
            }
        }
        // zlib: the stream ends at its adler32; nothing may follow it in the file.
        if let Decoded::Zlib(decoder) = &mut self.reader {
            let rest = decoder.get_mut().fill_buf().map_err(|e| StoreError::io(&self.path, e))?;
            if !rest.is_empty() {
                return Err(StoreError::format(&self.path, "bytes follow the end of the zlib stream"));
            }
        }
        Ok(())
    }

    fn read_error(&self, error: std::io::Error) -> StoreError {
        match error.kind() {
            std::io::ErrorKind::InvalidInput | std::io::ErrorKind::InvalidData | std::io::ErrorKind::UnexpectedEof => {
                corrupt(&self.path, compression_name(&self.reader), error)
            }
            _ => StoreError::io(&self.path, error),
        }
    }

    /// Fills `self.bytes` (already sized) from the reader.
    fn fill(&mut self) -> Result<(), StoreError> {
        let mut filled = 0;
        while filled < self.bytes.len() {
            match self.reader.read(&mut self.bytes[filled..]) {
                Ok(0) => {
                    return Err(StoreError::Truncated {
                        path: self.path.clone(),
                        expected: self.total,
                        found: self.consumed + filled as u64,
                    })
                }
                Ok(n) => filled += n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(self.read_error(e)),
            }
        }
        self.consumed += filled as u64;
        Ok(())
    }
}

/// Bytes of `info`'s samples as `file_type` (validated dimensions: at most 2^60 samples of at most 8 bytes).
fn file_bytes(info: &VolumeInfo, file_type: SampleType) -> u64 {
    info.dims.iter().product::<u64>() * file_type.size() as u64
}

fn compression_name(reader: &Decoded) -> &'static str {
    match reader {
        Decoded::Gzip(_) => "gzip",
        Decoded::Zlib(_) => "zlib",
        Decoded::Plain(_) | Decoded::Other(_) => "compressed",
    }
}

fn corrupt(path: &Path, what: &str, error: std::io::Error) -> StoreError {
    StoreError::format(path, format!("corrupt {what} data: {error}"))
}

impl VolumeSource for SampleStream {
    fn info(&self) -> &VolumeInfo {
        &self.info
    }

    fn conversion(&self) -> Option<SampleConversion> {
        self.conversion
    }

    fn read_slices(&mut self, count: usize, out: &mut Vec<f32>) -> Result<(), StoreError> {
        let size = self.file_type.size();
        let wanted = (count as u64).saturating_mul(self.info.slice_len() as u64).saturating_mul(size as u64);
        if wanted > self.total - self.consumed {
            return Err(StoreError::format(&self.path, "asked for slices past the last one"));
        }
        let start = out.len();
        let big = self.endian == Endian::Big;
        let mut remaining = wanted;
        // Chunks are a multiple of every sample size, so no sample straddles two.
        while remaining > 0 {
            let chunk = remaining.min(READ_CHUNK_BYTES as u64) as usize;
            self.bytes.resize(chunk, 0);
            let first_sample = self.consumed / size as u64;
            self.fill()?;
            remaining -= chunk as u64;
            decode(&self.bytes, self.file_type, big, self.conversion.as_mut(), out).map_err(|(index, value)| {
                let [x, y, _] = self.info.dims;
                let i = first_sample + index as u64;
                StoreError::format(
                    &self.path,
                    format!(
                        "sample ({}, {}, {}) is {value:e}, beyond float32's range (±{:e}): float64 samples are stored \
                         as float32; rescale the data (e.g. to other units) before importing",
                        i % x,
                        i / x % y,
                        i / (x * y),
                        f32::MAX
                    ),
                )
            })?;
        }
        if let Some((slope, intercept)) = self.scaling {
            out[start..].iter_mut().for_each(|v| *v = *v * slope + intercept);
        }
        if self.verify_end && self.consumed == self.total {
            self.verify_end_of_stream()?;
        }
        Ok(())
    }
}
