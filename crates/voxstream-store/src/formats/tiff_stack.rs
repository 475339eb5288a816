//! TIFF stacks: one multi-page file (a page per z slice) or a folder of single-page slices (sorted by name).
//! Greyscale 8/16-bit unsigned, 16-bit signed and 32-bit float pages; all pages the same size and type. TIFF carries
//! no reliable z spacing: spacing 1 and origin 0 unless `--spacing`/`--origin` are given.

use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

use tiff::decoder::{Decoder, DecodingResult};
use tiff::ColorType;

use crate::error::StoreError;
use crate::volume::{DType, VolumeInfo, VolumeSource};

/// A TIFF stack read one page per z slice.
pub struct TiffStack {
    info: VolumeInfo,
    /// Files to read, in order; a multi-page file appears once.
    files: Vec<PathBuf>,
    /// Current multi-page decoder and the file it reads.
    decoder: Option<(usize, Decoder<BufReader<File>>)>,
    next_file: usize,
    pages_read: u64,
}

fn tiff_error(path: &Path, error: tiff::TiffError) -> StoreError {
    StoreError::format(path, format!("unreadable TIFF: {error}"))
}

fn dtype_of(path: &Path, color: ColorType, sample_format_float: bool, signed: bool) -> Result<DType, StoreError> {
    match (color, sample_format_float, signed) {
        (ColorType::Gray(8), false, false) => Ok(DType::U8),
        (ColorType::Gray(16), false, false) => Ok(DType::U16),
        (ColorType::Gray(16), false, true) => Ok(DType::I16),
        (ColorType::Gray(32), true, _) => Ok(DType::F32),
        (other, _, _) => Err(StoreError::Unsupported {
            path: path.into(),
            message: format!("TIFF pages of type {other:?} (greyscale u8, u16, i16 or f32 only)"),
        }),
    }
}

/// The most a decoded TIFF page may hold: a 32768² f32 slice.
pub const MAX_TIFF_PAGE_BYTES: u64 = 4 << 30;

/// The most a TIFF page may expand over its file's size (LZW, the most expansive of the codecs read, reaches ~2730:1).
pub const MAX_TIFF_EXPANSION: u64 = 4096;

/// The most bytes a page of `path` may decode to.
fn page_limit(path: &Path) -> Result<u64, StoreError> {
    let file_len = std::fs::metadata(path).map_err(|e| StoreError::io(path, e))?.len();
    Ok(file_len.saturating_mul(MAX_TIFF_EXPANSION).min(MAX_TIFF_PAGE_BYTES))
}

/// A decoder whose buffers are bounded by the file: a page may decode to at most [`MAX_TIFF_EXPANSION`] times the
/// file's size and [`MAX_TIFF_PAGE_BYTES`], so a header cannot make it allocate for data that is not there.
fn open_decoder(path: &Path) -> Result<Decoder<BufReader<File>>, StoreError> {
    let file = File::open(path).map_err(|e| StoreError::io(path, e))?;
    let page_bytes = page_limit(path)?;
    let mut limits = tiff::decoder::Limits::default();
    limits.decoding_buffer_size = usize::try_from(page_bytes).unwrap_or(usize::MAX);
    limits.intermediate_buffer_size = limits.decoding_buffer_size;
    Decoder::new(BufReader::new(file)).map_err(|e| tiff_error(path, e)).map(|d| d.with_limits(limits))
}

/// Page width, height and sample type of the decoder's current page.
fn page_format(path: &Path, decoder: &mut Decoder<BufReader<File>>) -> Result<(u32, u32, DType), StoreError> {
    let (width, height) = decoder.dimensions().map_err(|e| tiff_error(path, e))?;
    let color = decoder.colortype().map_err(|e| tiff_error(path, e))?;
    let format =
        decoder.find_tag_unsigned::<u16>(tiff::tags::Tag::SampleFormat).map_err(|e| tiff_error(path, e))?.unwrap_or(1);
    Ok((width, height, dtype_of(path, color, format == 3, format == 2)?))
}

impl TiffStack {
    /// A multi-page file, or a folder of `.tif`/`.tiff` slices.
    pub fn open(path: &Path) -> Result<TiffStack, StoreError> {
        let files: Vec<PathBuf> = if path.is_dir() {
            let mut files: Vec<PathBuf> = std::fs::read_dir(path)
                .map_err(|e| StoreError::io(path, e))?
                .flatten()
                .map(|e| e.path())
                .filter(|p| {
                    p.extension().is_some_and(|e| e.eq_ignore_ascii_case("tif") || e.eq_ignore_ascii_case("tiff"))
                })
                .collect();
            files.sort();
            if files.is_empty() {
                return Err(StoreError::format(path, "folder holds no .tif or .tiff slices"));
            }
            files
        } else {
            vec![path.to_path_buf()]
        };
        let mut decoder = open_decoder(&files[0])?;
        let (width, height, dtype) = page_format(&files[0], &mut decoder)?;
        let depth = if files.len() == 1 {
            let mut pages = 1u64;
            while decoder.more_images() {
                decoder.next_image().map_err(|e| tiff_error(&files[0], e))?;
                let (w, h, t) = page_format(&files[0], &mut decoder)?;
                if (w, h, t) != (width, height, dtype) {
                    return Err(StoreError::format(
                        &files[0],
                        format!("page {pages} is {w}x{h} {t:?}, page 0 {width}x{height} {dtype:?}"),
                    ));
                }
                pages += 1;
            }
            pages
        } else {
            files.len() as u64
        };
        let info =
            VolumeInfo { dims: [width as u64, height as u64, depth], dtype, spacing: [1.0; 3], origin: [0.0; 3] };
        info.validate(path)?;
        // The page size is checked now, not when the first page is decoded: the importer sizes its slabs by it.
        let page_bytes = width as u64 * height as u64 * dtype.size() as u64;
        let limit = page_limit(&files[0])?;
        if page_bytes > limit {
            return Err(StoreError::format(
                &files[0],
                format!(
                    "pages of {width}x{height} {} samples need {page_bytes} bytes, more than the file can hold ({limit} \
                     bytes: {MAX_TIFF_EXPANSION} times its size, at most {MAX_TIFF_PAGE_BYTES})",
                    dtype.name()
                ),
            ));
        }
        Ok(TiffStack { info, files, decoder: None, next_file: 0, pages_read: 0 })
    }

    fn read_page(&mut self, out: &mut Vec<f32>) -> Result<(), StoreError> {
        let multi_page = self.files.len() == 1;
        if self.decoder.is_none() || !multi_page {
            let index = if multi_page { 0 } else { self.next_file };
            let path = self
                .files
                .get(index)
                .ok_or_else(|| StoreError::format(&self.files[0], "fewer slices than expected"))?;
            self.decoder = Some((index, open_decoder(path)?));
            self.next_file += 1;
        } else if let Some((index, decoder)) = self.decoder.as_mut() {
            decoder.next_image().map_err(|e| tiff_error(&self.files[*index], e))?;
        }
        let Some((index, decoder)) = self.decoder.as_mut() else { unreachable!("decoder opened above") };
        let path = self.files[*index].clone();
        let (w, h, t) = page_format(&path, decoder)?;
        if [w as u64, h as u64] != [self.info.dims[0], self.info.dims[1]] || t != self.info.dtype {
            return Err(StoreError::format(
                &path,
                format!(
                    "slice is {w}x{h} {t:?}, expected {}x{} {:?}",
                    self.info.dims[0], self.info.dims[1], self.info.dtype
                ),
            ));
        }
        let image = decoder.read_image().map_err(|e| tiff_error(&path, e))?;
        let before = out.len();
        match image {
            DecodingResult::U8(v) => out.extend(v.into_iter().map(f32::from)),
            DecodingResult::U16(v) => out.extend(v.into_iter().map(f32::from)),
            DecodingResult::I16(v) => out.extend(v.into_iter().map(f32::from)),
            DecodingResult::F32(v) => out.extend(v),
            _ => return Err(StoreError::Unsupported { path, message: "sample layout".into() }),
        }
        if out.len() - before != self.info.slice_len() {
            return Err(StoreError::format(&path, "page holds the wrong number of samples"));
        }
        self.pages_read += 1;
        Ok(())
    }
}

impl VolumeSource for TiffStack {
    fn info(&self) -> &VolumeInfo {
        &self.info
    }

    fn read_slices(&mut self, count: usize, out: &mut Vec<f32>) -> Result<(), StoreError> {
        for _ in 0..count {
            self.read_page(out)?;
        }
        Ok(())
    }
}
