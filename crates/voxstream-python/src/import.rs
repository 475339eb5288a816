//! `voxstream._native.import_volume`: a volume file (any format `voxstream import` reads) or a 3-D numpy array into
//! a voxstream store, with a progress callback and Ctrl-C.
//!
//! Through the facade ([`voxstream_api::import_input`]), as `voxstream import`. The import runs with the GIL released;
//! the callback (input bytes read, of the total) and Python's signal handlers run between slabs of z slices (the GIL
//! taken for each). Ctrl-C (or an exception in the callback) stops the import at the next slab: the partial store is
//! removed and an existing store at `out` is left as it was.

use std::path::{Path, PathBuf};

use numpy::PyReadonlyArray3;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use voxstream_api::import_input::{open_input, ImportInput, ImportSettings};
use voxstream_api::remote_output::remote_output;
use voxstream_store::formats::sample_type::{SampleConversion, SampleType};
use voxstream_store::formats::WithGeometry;
use voxstream_store::{BrickCodec, DType, ImportReport, Orientation, StoreError, VolumeInfo, VolumeSource};

use crate::errors::{progress_step, to_py_err};

/// Samples of a numpy array, x fastest (the array is indexed `[z, y, x]`).
enum Samples {
    U8(Vec<u8>),
    U16(Vec<u16>),
    I16(Vec<i16>),
    F32(Vec<f32>),
}

/// A numpy array's samples, read a few z slices at a time as the importer asks.
struct ArraySource {
    info: VolumeInfo,
    samples: Samples,
    /// The next z slice to hand out.
    next_slice: usize,
    /// For int8, int32, uint32 and float64 arrays: what converting them to the store's type did (as `voxstream
    /// import` of a `.npy` of them says).
    conversion: Option<SampleConversion>,
}

impl VolumeSource for ArraySource {
    fn info(&self) -> &VolumeInfo {
        &self.info
    }

    fn conversion(&self) -> Option<SampleConversion> {
        self.conversion
    }

    fn read_slices(&mut self, count: usize, out: &mut Vec<f32>) -> Result<(), StoreError> {
        let slice = (self.info.dims[0] * self.info.dims[1]) as usize;
        let from = self.next_slice * slice;
        let to = ((self.next_slice + count) * slice).min(slice * self.info.dims[2] as usize);
        match &self.samples {
            Samples::U8(v) => out.extend(v[from..to].iter().map(|&s| f32::from(s))),
            Samples::U16(v) => out.extend(v[from..to].iter().map(|&s| f32::from(s))),
            Samples::I16(v) => out.extend(v[from..to].iter().map(|&s| f32::from(s))),
            Samples::F32(v) => out.extend_from_slice(&v[from..to]),
        }
        self.next_slice += count;
        Ok(())
    }
}

/// Imports `source` (a file's path: any format `voxstream import` reads, meshes and particles included; or a 3-D
/// numpy array indexed `[z, y, x]` of uint8, uint16, int16 or float32) into the store `out` (a folder, or
/// `s3://BUCKET/NAME.zarr`, `gs://…`, `az://…`: built in a temporary folder, then uploaded); returns what was written.
#[pyfunction]
#[pyo3(signature = (source, out, *, spacing=None, origin=None, brick_size=32, overwrite=false, nan_as=None,
    resolution=None, amplify=None, progress=None, codec="zstd", max_error=None, series=None, orientation=None))]
#[allow(clippy::too_many_arguments)]
pub fn import_volume<'py>(
    py: Python<'py>,
    source: &Bound<'py, PyAny>,
    out: PathBuf,
    spacing: Option<[f64; 3]>,
    origin: Option<[f64; 3]>,
    brick_size: u64,
    overwrite: bool,
    nan_as: Option<f32>,
    resolution: Option<u64>,
    amplify: Option<f64>,
    progress: Option<Py<PyAny>>,
    codec: &str,
    max_error: Option<f64>,
    series: Option<String>,
    orientation: Option<String>,
) -> PyResult<Bound<'py, PyDict>> {
    let codec = BrickCodec::from_choice(codec, max_error).map_err(PyValueError::new_err)?;
    if let Some(s) = spacing.filter(|s| s.iter().any(|v| !(v.is_finite() && *v > 0.0))) {
        return Err(PyValueError::new_err(format!("spacing must be positive, got {s:?}")));
    }
    let parsed_orientation = orientation
        .as_deref()
        .map(Orientation::parse)
        .transpose()
        .map_err(|e| PyValueError::new_err(format!("orientation: {e}")))?;
    let settings = ImportSettings {
        spacing,
        origin,
        orientation,
        nan_as,
        brick_size,
        overwrite,
        resolution,
        amplify,
        codec,
        series,
        ..ImportSettings::default()
    };
    // A remote `out` (s3://, gs://, az://) is checked before the source is read; the store is built in a temporary
    // folder and uploaded.
    let remote = py.detach(|| remote_output(&out, &settings)).map_err(to_py_err)?;
    let input = match array_source(source, spacing, origin)? {
        Some(array) => ImportInput::from_source(
            Box::new(WithGeometry::new(Box::new(array), None, None).with_orientation(parsed_orientation)),
            Path::new("the array"),
        ),
        None => {
            let path: PathBuf = source.extract().map_err(|_| {
                PyValueError::new_err(
                    "source must be a file's path or a 3-D numpy array of uint8, uint16, int16 or float32",
                )
            })?;
            py.detach(|| open_input(&path, &settings)).map_err(to_py_err)?
        }
    };
    let info = input.info.clone();
    let description = input.description.clone();
    let mut raised: Option<PyErr> = None;
    let mut last = 0;
    let report = py.detach(|| {
        let mut step = |done, total| {
            last = done;
            // Between slabs: Python's signal handlers (Ctrl-C) and the callback.
            progress_step(&progress, &mut raised, done, total)
        };
        match &remote {
            None => input.import(&out, &settings, &mut step),
            Some(remote) => remote.import(input, &settings, &mut step, &mut |_, _| {}).map(|(report, _)| report),
        }
    });
    if let Some(error) = raised {
        return Err(error);
    }
    let report = report.map_err(to_py_err)?;
    let total = info.byte_len();
    if let (Some(callback), true) = (&progress, last < total) {
        callback.call1(py, (total, total))?;
    }
    let result = report_dict(py, &out, info.dims, info.dtype, &report)?;
    if let Some(description) = description {
        result.set_item("description", description)?;
    }
    Ok(result)
}

/// What an import returns to Python: where, dims, sample type, levels, bricks written and empty, value range (for a
/// single-process import and a distributed one alike).
pub fn report_dict<'py>(
    py: Python<'py>,
    out: &Path,
    dims: [u64; 3],
    dtype: DType,
    report: &ImportReport,
) -> PyResult<Bound<'py, PyDict>> {
    let result = PyDict::new(py);
    result.set_item("out", out)?;
    result.set_item("dims", dims)?;
    result.set_item("dtype", dtype.name())?;
    result.set_item("levels", report.levels)?;
    result.set_item("bricks_written", report.bricks_written.iter().sum::<u64>())?;
    result.set_item("bricks_empty", report.bricks_empty.iter().sum::<u64>())?;
    result.set_item("value_range", report.value_range)?;
    if let Some(conversion) = &report.conversion {
        result.set_item("conversion", conversion.to_string())?;
    }
    Ok(result)
}

/// The error for an array of a sample type no store holds (`name` as numpy spells it).
fn unsupported_dtype(name: &str) -> PyErr {
    PyValueError::new_err(format!(
        "arrays of {name} cannot be imported: give uint8, uint16, int16 or float32 (stored as they are), or int8, \
         int32, uint32 or float64 (converted) (e.g. array.astype(numpy.float32))"
    ))
}

/// The array's samples as a source, if `source` is a numpy array (copied once, in x-fastest order).
fn array_source(
    source: &Bound<'_, PyAny>,
    spacing: Option<[f64; 3]>,
    origin: Option<[f64; 3]>,
) -> PyResult<Option<ArraySource>> {
    if !source.hasattr("__array_interface__")? {
        return Ok(None);
    }
    let shape: Vec<usize> = source.getattr("shape")?.extract()?;
    let &[z, y, x] = shape.as_slice() else {
        return Err(PyValueError::new_err(format!(
            "the array has shape {shape:?}: a volume is a 3-D array indexed [z, y, x]"
        )));
    };
    if x == 0 || y == 0 || z == 0 {
        return Err(PyValueError::new_err(format!("the array has shape {shape:?}: a volume needs samples")));
    }
    fn samples<T: numpy::Element + Copy>(source: &Bound<'_, PyAny>) -> Option<Vec<T>> {
        let array: PyReadonlyArray3<T> = source.extract().ok()?;
        let view = array.as_array();
        // `iter` walks the logical order ([z, y, x], x fastest) whatever the strides.
        Some(view.iter().copied().collect())
    }
    // int8, int32, uint32 and float64 are converted as the `.npy` importer converts them (int8 to int16, exactly;
    // the others to float32, the rounding counted and said), a finite float64 beyond float32's range refused.
    let mut conversion = None;
    let mut converted = |ty: SampleType, values: &mut dyn Iterator<Item = f64>| -> PyResult<Vec<f32>> {
        let mut tally = SampleConversion::new(ty);
        let mut out = Vec::new();
        for (i, value) in values.enumerate() {
            let stored = value as f32;
            if value.is_finite() && !stored.is_finite() {
                return Err(PyValueError::new_err(format!(
                    "sample {i} of the float64 array is {value}, beyond float32's range: scale the array first"
                )));
            }
            tally.count(value, stored);
            out.push(stored);
        }
        conversion = Some(tally);
        Ok(out)
    };
    let (dtype, samples) = if let Some(v) = samples::<u8>(source) {
        (DType::U8, Samples::U8(v))
    } else if let Some(v) = samples::<u16>(source) {
        (DType::U16, Samples::U16(v))
    } else if let Some(v) = samples::<i16>(source) {
        (DType::I16, Samples::I16(v))
    } else if let Some(v) = samples::<f32>(source) {
        (DType::F32, Samples::F32(v))
    } else if let Some(v) = samples::<i8>(source) {
        conversion = Some(SampleConversion { samples: v.len() as u64, ..SampleConversion::new(SampleType::I8) });
        (DType::I16, Samples::I16(v.into_iter().map(i16::from).collect()))
    } else if let Some(v) = samples::<i32>(source) {
        (DType::F32, Samples::F32(converted(SampleType::I32, &mut v.into_iter().map(f64::from))?))
    } else if let Some(v) = samples::<u32>(source) {
        (DType::F32, Samples::F32(converted(SampleType::U32, &mut v.into_iter().map(f64::from))?))
    } else if let Some(v) = samples::<f64>(source) {
        (DType::F32, Samples::F32(converted(SampleType::F64, &mut v.into_iter())?))
    } else {
        return Err(unsupported_dtype(&source.getattr("dtype")?.str()?.to_string()));
    };
    let info = VolumeInfo {
        dims: [x as u64, y as u64, z as u64],
        dtype,
        spacing: spacing.unwrap_or([1.0; 3]),
        origin: origin.unwrap_or([0.0; 3]),
        unit: None,
        orientation: None,
    };
    Ok(Some(ArraySource { info, samples, next_slice: 0, conversion }))
}
