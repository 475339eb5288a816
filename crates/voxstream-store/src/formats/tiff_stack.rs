//! TIFF stacks: one multi-page file (a page per z slice) or a folder of slice files (sorted by name), each of one
//! or more pages: every page of every file is a slice, in order.
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
    /// Files to read, in order, with their page counts (checked on open).
    members: Vec<(PathBuf, u64)>,
    /// The member being read, its decoder, and the pages of it read so far.
    decoder: Option<(usize, Decoder<BufReader<File>>, u64)>,
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

fn is_tiff(path: &Path) -> bool {
    path.extension().is_some_and(|e| e.eq_ignore_ascii_case("tif") || e.eq_ignore_ascii_case("tiff"))
}

/// `true` when `folder` holds `.tif`/`.tiff` files (a folder without them may be a DICOM series).
pub fn folder_has_slices(folder: &Path) -> bool {
    std::fs::read_dir(folder).is_ok_and(|entries| entries.flatten().any(|e| is_tiff(&e.path())))
}

impl TiffStack {
    /// A multi-page file, or a folder of `.tif`/`.tiff` slices.
    pub fn open(path: &Path) -> Result<TiffStack, StoreError> {
        let files: Vec<PathBuf> = if path.is_dir() {
            let mut files: Vec<PathBuf> = std::fs::read_dir(path)
                .map_err(|e| StoreError::io(path, e))?
                .flatten()
                .map(|e| e.path())
                .filter(|p| is_tiff(p))
                .collect();
            files.sort();
            if files.is_empty() {
                return Err(StoreError::format(path, "folder holds no .tif or .tiff slices"));
            }
            files
        } else {
            vec![path.to_path_buf()]
        };
        // Every page of every member is a slice, in order: a folder may hold multi-page files (acquisition software
        // splits long stacks into files of a few GB). Each page is checked now, so a page of another size or type is
        // refused before anything is written, naming its file and page.
        let mut decoder = open_decoder(&files[0])?;
        let (width, height, dtype) = page_format(&files[0], &mut decoder)?;
        let mut members = Vec::with_capacity(files.len());
        for (index, file) in files.iter().enumerate() {
            if index > 0 {
                decoder = open_decoder(file)?;
            }
            let mut pages = 0u64;
            loop {
                let (w, h, t) = page_format(file, &mut decoder)?;
                if (w, h, t) != (width, height, dtype) {
                    return Err(StoreError::format(
                        file,
                        format!(
                            "page {pages} is {w}x{h} {t:?}, but {} page 0 is {width}x{height} {dtype:?}: every page \
                             of every slice file must have one size and sample type",
                            files[0].display()
                        ),
                    ));
                }
                pages += 1;
                if !decoder.more_images() {
                    break;
                }
                decoder.next_image().map_err(|e| tiff_error(file, e))?;
            }
            members.push((file.clone(), pages));
        }
        let depth = members.iter().map(|(_, pages)| pages).sum::<u64>();
        let info = VolumeInfo {
            dims: [width as u64, height as u64, depth],
            dtype,
            spacing: [1.0; 3],
            origin: [0.0; 3],
            unit: None,
            orientation: None,
        };
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
        Ok(TiffStack { info, members, decoder: None, pages_read: 0 })
    }

    fn read_page(&mut self, out: &mut Vec<f32>) -> Result<(), StoreError> {
        // The next page of the member being read, or the first page of the next member.
        match self.decoder.as_mut() {
            Some((index, decoder, pages)) if *pages < self.members[*index].1 => {
                decoder.next_image().map_err(|e| tiff_error(&self.members[*index].0, e))?;
                *pages += 1;
            }
            current => {
                let index = current.map_or(0, |(index, _, _)| *index + 1);
                let (path, _) = self
                    .members
                    .get(index)
                    .ok_or_else(|| StoreError::format(&self.members[0].0, "fewer slices than expected"))?;
                self.decoder = Some((index, open_decoder(path)?, 1));
            }
        }
        let Some((index, decoder, _)) = self.decoder.as_mut() else { unreachable!("decoder opened above") };
        let path = self.members[*index].0.clone();
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
