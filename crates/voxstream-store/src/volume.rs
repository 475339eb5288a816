//! What an imported volume is: dimensions, sample type, spacing and origin (VTK/ITK convention: sample `(i, j, k)`
//! lies at `origin + spacing·(i, j, k)`) and their unit, and a source that yields it slab by slab.

use crate::error::StoreError;
use crate::formats::SampleConversion;
use crate::orientation::Orientation;
use crate::space_unit::SpaceUnit;

/// Sample types kept from the input.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DType {
    /// Unsigned 8-bit.
    U8,
    /// Unsigned 16-bit.
    U16,
    /// Signed 16-bit.
    I16,
    /// 32-bit float.
    F32,
}

impl DType {
    /// Bytes per sample.
    pub fn size(self) -> usize {
        match self {
            DType::U8 => 1,
            DType::U16 | DType::I16 => 2,
            DType::F32 => 4,
        }
    }

    /// Name used on the command line and in metadata (`u8`, `u16`, `i16`, `f32`).
    pub fn name(self) -> &'static str {
        match self {
            DType::U8 => "u8",
            DType::U16 => "u16",
            DType::I16 => "i16",
            DType::F32 => "f32",
        }
    }

    /// Parses a command-line name.
    pub fn from_name(name: &str) -> Option<DType> {
        match name {
            "u8" | "uint8" => Some(DType::U8),
            "u16" | "uint16" => Some(DType::U16),
            "i16" | "int16" => Some(DType::I16),
            "f32" | "float32" => Some(DType::F32),
            _ => None,
        }
    }

    /// The Zarr data type of these samples.
    pub fn zarr_data_type(self) -> zarrs::array::DataType {
        match self {
            DType::U8 => zarrs::array::data_type::uint8(),
            DType::U16 => zarrs::array::data_type::uint16(),
            DType::I16 => zarrs::array::data_type::int16(),
            DType::F32 => zarrs::array::data_type::float32(),
        }
    }

    /// The sample type of a Zarr data type, where it is one of these four.
    pub fn from_zarr_data_type(data_type: &zarrs::array::DataType) -> Option<DType> {
        [DType::U8, DType::U16, DType::I16, DType::F32].into_iter().find(|d| d.zarr_data_type() == *data_type)
    }
}

/// Geometry and type of a volume.
#[derive(Clone, Debug, PartialEq)]
pub struct VolumeInfo {
    /// Samples along x, y, z (x fastest in memory).
    pub dims: [u64; 3],
    /// Sample type.
    pub dtype: DType,
    /// World distance between samples along x, y, z.
    pub spacing: [f64; 3],
    /// World position of sample (0, 0, 0).
    pub origin: [f64; 3],
    /// Unit of `spacing` and `origin`, when the file (or the user) says it.
    pub unit: Option<SpaceUnit>,
    /// The anatomical direction each axis points to, when the file (or the user) says it ([`Orientation`]).
    pub orientation: Option<Orientation>,
}

impl VolumeInfo {
    /// Checks dimensions, spacing and origin (the box they make: [`crate::world_extent`]).
    pub fn validate(&self, path: &std::path::Path) -> Result<(), StoreError> {
        if self.dims.iter().any(|&d| d == 0) {
            return Err(StoreError::format(path, format!("dimensions must be positive, got {:?}", self.dims)));
        }
        if self.dims.iter().any(|&d| d > 1 << 20) {
            return Err(StoreError::format(path, format!("dimensions {:?} exceed 2^20 per axis", self.dims)));
        }
        if self.spacing.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
            return Err(StoreError::format(path, format!("spacing must be positive, got {:?}", self.spacing)));
        }
        if self.origin.iter().any(|o| !o.is_finite()) {
            return Err(StoreError::format(path, "origin must be finite"));
        }
        if let Err((field, problem)) = crate::world_extent::check_world_extent(self.dims, self.spacing, self.origin) {
            return Err(StoreError::format(path, format!("{field} {problem}")));
        }
        Ok(())
    }

    /// Samples in one z slice.
    pub fn slice_len(&self) -> usize {
        (self.dims[0] * self.dims[1]) as usize
    }

    /// Bytes of all samples.
    pub fn byte_len(&self) -> u64 {
        self.dims.iter().product::<u64>() * self.dtype.size() as u64
    }
}

/// A volume read front to back, a few z slices at a time, so imports run in bounded memory.
pub trait VolumeSource: Send {
    /// Geometry and type.
    fn info(&self) -> &VolumeInfo;

    /// Appends the next `count` z slices to `out` (x fastest, then y, then z), as `f32` (exact for every supported
    /// type).
    fn read_slices(&mut self, count: usize, out: &mut Vec<f32>) -> Result<(), StoreError>;

    /// For a file whose sample type the store does not keep: what converting its samples did so far (complete once
    /// every slice is read). `None` when the samples are stored as they are.
    fn conversion(&self) -> Option<SampleConversion> {
        None
    }

    /// One line on what was found in the input, for sources whose reading involved choices the user should see
    /// (a DICOM series: its modality, description, slice count, spacing and rescale). `None` for plain files.
    fn description(&self) -> Option<String> {
        None
    }
}

/// A volume whose samples are already in memory (f32, x fastest), handed out slice by slice: for callers whose
/// volume is an array, and for tests.
pub struct SamplesInMemory {
    info: VolumeInfo,
    values: Vec<f32>,
    next: usize,
}

impl SamplesInMemory {
    /// `values` holds `info.dims` samples, x fastest; `None` when the count differs.
    pub fn new(info: VolumeInfo, values: Vec<f32>) -> Option<SamplesInMemory> {
        let count = info.dims.iter().try_fold(1u64, |n, &d| n.checked_mul(d))?;
        (count == values.len() as u64).then_some(SamplesInMemory { info, values, next: 0 })
    }
}

impl VolumeSource for SamplesInMemory {
    fn info(&self) -> &VolumeInfo {
        &self.info
    }

    fn read_slices(&mut self, count: usize, out: &mut Vec<f32>) -> Result<(), StoreError> {
        let slice = (self.info.dims[0] * self.info.dims[1]) as usize;
        let end = (self.next + count).min(self.info.dims[2] as usize);
        out.extend_from_slice(&self.values[self.next * slice..end * slice]);
        self.next = end;
        Ok(())
    }
}
