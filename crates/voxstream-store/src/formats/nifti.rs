//! NIfTI-1 (`.nii`, `.nii.gz`): the 348-byte header, then samples at `vox_offset`.
//!
//! Spacing comes from `pixdim[1..3]`, in the unit `xyzt_units` names (meter, millimeter or micrometer; none when it
//! says "unknown"), the origin from the qform offsets (or the sform translation), the anatomical orientation from the
//! qform's rotation (or the sform's columns; [`crate::Orientation`]). Rotations in the qform/sform are not applied:
//! the volume is axis-aligned in voxstream's world, as in VTK's image data. Values
//! are kept as stored, unless the header sets a `scl_slope`/`scl_inter` scaling other than the identity: then the
//! scaled values are imported, as f32. int8, int32, uint32 and float64 data are converted ([`super::sample_type`]).
//! `datatype` and `bitpix` must agree: a header where they do not is refused, never read by either one.

use std::io::Read;
use std::path::Path;

use super::sample_stream::{Compression, Endian, SampleStream};
use super::sample_type::SampleType;
use crate::error::StoreError;
use crate::orientation::Orientation;
use crate::space_unit::SpaceUnit;
use crate::volume::VolumeInfo;

/// Opens a NIfTI-1 volume.
pub fn open(path: &Path, is_gzip: bool) -> Result<SampleStream, StoreError> {
    let file = std::fs::File::open(path).map_err(|e| StoreError::io(path, e))?;
    let mut reader: Box<dyn Read> =
        if is_gzip { Box::new(flate2::read::MultiGzDecoder::new(file)) } else { Box::new(file) };
    let mut h = [0u8; 348];
    reader.read_exact(&mut h).map_err(|_| StoreError::format(path, "shorter than a NIfTI-1 header (348 bytes)"))?;
    let endian = if i32::from_le_bytes([h[0], h[1], h[2], h[3]]) == 348 {
        Endian::Little
    } else if i32::from_be_bytes([h[0], h[1], h[2], h[3]]) == 348 {
        Endian::Big
    } else {
        return Err(StoreError::format(path, "not a NIfTI-1 file (sizeof_hdr is not 348)"));
    };
    if &h[344..347] != b"n+1" {
        return Err(StoreError::Unsupported {
            path: path.into(),
            message: "only single-file NIfTI-1 (magic n+1) is read; convert .hdr/.img pairs".into(),
        });
    }
    let i16_at = |o: usize| match endian {
        Endian::Little => i16::from_le_bytes([h[o], h[o + 1]]),
        Endian::Big => i16::from_be_bytes([h[o], h[o + 1]]),
    };
    let f32_at = |o: usize| {
        let b = [h[o], h[o + 1], h[o + 2], h[o + 3]];
        match endian {
            Endian::Little => f32::from_le_bytes(b),
            Endian::Big => f32::from_be_bytes(b),
        }
    };
    let ndims = i16_at(40);
    let dim = [i16_at(42), i16_at(44), i16_at(46)];
    if !(3..=4).contains(&ndims) || (ndims == 4 && i16_at(48) > 1) {
        return Err(StoreError::Unsupported { path: path.into(), message: format!("{ndims}-D image (only 3-D)") });
    }
    if dim.iter().any(|&d| d <= 0) {
        return Err(StoreError::format(path, format!("dimensions must be positive, got {dim:?}")));
    }
    let file_type = match i16_at(70) {
        2 => SampleType::U8,
        4 => SampleType::I16,
        8 => SampleType::I32,
        16 => SampleType::F32,
        64 => SampleType::F64,
        256 => SampleType::I8,
        512 => SampleType::U16,
        768 => SampleType::U32,
        code => {
            return Err(StoreError::Unsupported {
                path: path.into(),
                message: format!(
                    "datatype code {code} (supported: 2 uint8, 4 int16, 16 float32, 512 uint16; converted: 8 int32, \
                     64 float64, 256 int8, 768 uint32)"
                ),
            })
        }
    };
    let name = file_type.name();
    // The samples' size is said twice; when the two disagree, either reading reads the wrong bytes.
    let bitpix = i16_at(72);
    let bits = 8 * file_type.size() as i16;
    if bitpix != bits {
        return Err(StoreError::format(
            path,
            format!(
                "datatype {} ({name}, {bits} bits) and bitpix {bitpix} disagree: the header is inconsistent; fix \
                 whichever of the two is wrong (e.g. with nibabel) and import again",
                i16_at(70)
            ),
        ));
    }
    let spacing = [f32_at(80), f32_at(84), f32_at(88)].map(|v| if v > 0.0 { v.abs() as f64 } else { 1.0 });
    let origin = if i16_at(252) > 0 {
        [f32_at(268), f32_at(272), f32_at(276)].map(|v| v as f64)
    } else if i16_at(254) > 0 {
        [f32_at(292), f32_at(308), f32_at(324)].map(|v| v as f64)
    } else {
        [0.0; 3]
    };
    let vox_offset = f32_at(108);
    if !(vox_offset >= 348.0) {
        return Err(StoreError::format(path, format!("vox_offset {vox_offset} is before the end of the header")));
    }
    let (slope, intercept) = (f32_at(112), f32_at(116));
    let unit = SpaceUnit::from_nifti(h[123]);
    // The axes' directions in RAS: the qform's rotation (with its qfac flip of k), else the sform's columns.
    let orientation = if i16_at(252) > 0 {
        let [b, c, d] = [f32_at(256), f32_at(260), f32_at(264)].map(|v| v as f64);
        let a = (1.0 - (b * b + c * c + d * d)).max(0.0).sqrt();
        let qfac = if f32_at(76) < 0.0 { -1.0 } else { 1.0 };
        Orientation::nearest_ras([
            [a * a + b * b - c * c - d * d, 2.0 * (b * c + a * d), 2.0 * (b * d - a * c)],
            [2.0 * (b * c - a * d), a * a + c * c - b * b - d * d, 2.0 * (c * d + a * b)],
            [2.0 * (b * d + a * c) * qfac, 2.0 * (c * d - a * b) * qfac, (a * a + d * d - b * b - c * c) * qfac],
        ])
    } else if i16_at(254) > 0 {
        let row = |o: usize| [f32_at(o), f32_at(o + 4), f32_at(o + 8)].map(|v| v as f64);
        let [x, y, z] = [row(280), row(296), row(312)];
        Orientation::nearest_ras([[x[0], y[0], z[0]], [x[1], y[1], z[1]], [x[2], y[2], z[2]]])
    } else {
        None
    };
    let info =
        VolumeInfo { dims: dim.map(|d| d as u64), dtype: file_type.stored(), spacing, origin, unit, orientation };
    let stream = if is_gzip {
        SampleStream::open(path, 0, Compression::Gzip, vox_offset as u64, info, file_type, endian)?
    } else {
        SampleStream::open(path, vox_offset as u64, Compression::None, 0, info, file_type, endian)?
    };
    // As nibabel: a zero or non-finite slope means "not scaled".
    let is_identity = slope == 0.0 || !slope.is_finite() || (slope == 1.0 && intercept == 0.0);
    if !is_identity && !intercept.is_finite() {
        return Err(StoreError::format(path, format!("scl_inter is {intercept} with scl_slope {slope}")));
    }
    Ok(if is_identity { stream } else { stream.with_scaling(slope, intercept) })
}
