//! The native half of a distributed import (`voxstream._distributed`, issue 50): [`ShardImport`], held by the
//! client from the first task to the last, and [`write_shard`], the work of one task on a worker. The design, and
//! why the result is the single-process store byte for byte, is [`voxstream_store::shard_import`]'s.

use std::path::PathBuf;

use numpy::{IntoPyArray, PyArray1, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use voxstream_store::shard_import::{self, ShardInput, ShardSpec, ShardSummary};
use voxstream_store::value_histogram::HistogramParts;
use voxstream_store::{BrickCodec, DType, ImportOptions, VolumeInfo};

use crate::errors::to_py_err;
use crate::import::report_dict;

/// A distributed import in progress: the store's import lock and `STORE.partial`. `finish` puts the store in
/// place; `abort` (or the object's end) removes the partial store and leaves an existing one as it was.
#[pyclass(name = "ShardImport", module = "voxstream._native")]
pub struct ShardImport {
    import: Option<shard_import::ShardImport>,
}

impl ShardImport {
    fn import(&self) -> PyResult<&shard_import::ShardImport> {
        self.import.as_ref().ok_or_else(|| PyValueError::new_err("this import has already finished or been aborted"))
    }
}

#[pymethods]
impl ShardImport {
    /// Begins an import of a volume of `dims` (x, y, z) samples of `dtype` into `out`.
    #[new]
    #[pyo3(signature = (out, dims, dtype, *, spacing=None, origin=None, brick_size=32, overwrite=false, nan_as=None,
        codec="zstd", max_error=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        out: PathBuf,
        dims: [u64; 3],
        dtype: &str,
        spacing: Option<[f64; 3]>,
        origin: Option<[f64; 3]>,
        brick_size: u64,
        overwrite: bool,
        nan_as: Option<f32>,
        codec: &str,
        max_error: Option<f64>,
    ) -> PyResult<ShardImport> {
        let dtype = sample_type(dtype)?;
        let codec = BrickCodec::from_choice(codec, max_error).map_err(PyValueError::new_err)?;
        if let Some(s) = spacing.filter(|s| s.iter().any(|v| !(v.is_finite() && *v > 0.0))) {
            return Err(PyValueError::new_err(format!("spacing must be positive, got {s:?}")));
        }
        if dims.contains(&0) {
            return Err(PyValueError::new_err(format!("the volume has shape {dims:?}: a volume needs samples")));
        }
        let info = VolumeInfo {
            dims,
            dtype,
            spacing: spacing.unwrap_or([1.0; 3]),
            origin: origin.unwrap_or([0.0; 3]),
            unit: None,
            orientation: None,
        };
        let options = ImportOptions { brick_size, overwrite, nan_as, codec, ..ImportOptions::default() };
        let import =
            py.detach(|| shard_import::ShardImport::begin(info, &out, &options)).map_err(|e| to_py_err(e.into()))?;
        Ok(ShardImport { import: Some(import) })
    }

    /// What every task needs, as JSON.
    fn spec(&self) -> PyResult<String> {
        Ok(self.import()?.spec().to_json())
    }

    /// Levels of the pyramid.
    fn levels(&self) -> PyResult<usize> {
        Ok(self.import()?.layout().levels())
    }

    /// Shards per axis (x, y, z) at `level`.
    fn shards(&self, level: usize) -> PyResult<[u64; 3]> {
        let import = self.import()?;
        if level >= import.layout().levels() {
            return Err(PyValueError::new_err(format!("level {level} does not exist")));
        }
        Ok(import.spec().shards(import.layout(), level))
    }

    /// Origin and extent (x, y, z, in samples of `level`) of a shard.
    fn region(&self, level: usize, shard: [u64; 3]) -> PyResult<([u64; 3], [u64; 3])> {
        let import = self.import()?;
        import.spec().region(import.layout(), level, shard).map_err(|e| to_py_err(e.into()))
    }

    /// The shards of `level − 1` whose halves make up `shard`.
    fn children(&self, level: usize, shard: [u64; 3]) -> PyResult<Vec<[u64; 3]>> {
        let import = self.import()?;
        import.spec().region(import.layout(), level, shard).map_err(|e| to_py_err(e.into()))?;
        Ok(import.spec().children(import.layout(), level, shard))
    }

    /// Merges the tasks' summaries and puts the store in place; returns what `import_volume` returns.
    fn finish<'py>(&mut self, py: Python<'py>, summaries: &Bound<'py, PyList>) -> PyResult<Bound<'py, PyDict>> {
        let parsed = summaries.iter().map(|s| summary_from_py(&s)).collect::<PyResult<Vec<_>>>()?;
        let import = self.import.take().ok_or_else(|| PyValueError::new_err("this import has already finished"))?;
        let (dims, out) = (import.spec().dims, import.out().to_path_buf());
        let dtype = sample_type(&import.spec().dtype)?;
        let report = py.detach(|| import.finish(parsed)).map_err(|e| to_py_err(e.into()))?;
        report_dict(py, &out, dims, dtype, &report)
    }

    /// Removes the partial store and releases the lock (an existing store at `out` is left as it was).
    fn abort(&mut self) {
        self.import = None;
    }
}

/// One task: writes shard `shard` (x, y, z) of `level` from `samples` (level 0: the shard's region of the source,
/// indexed `[z, y, x]`) or `pieces` (coarser levels: `(child, halves)` pairs from the child shards' tasks); returns
/// `(halves, summary)`.
#[pyfunction]
#[pyo3(signature = (spec, level, shard, samples=None, pieces=None))]
pub fn write_shard<'py>(
    py: Python<'py>,
    spec: &str,
    level: usize,
    shard: [u64; 3],
    samples: Option<&Bound<'py, PyAny>>,
    pieces: Option<&Bound<'py, PyList>>,
) -> PyResult<(Bound<'py, PyArray1<f32>>, Bound<'py, PyDict>)> {
    let spec = ShardSpec::from_json(spec).map_err(|e| to_py_err(e.into()))?;
    let input = match (samples, pieces) {
        (Some(samples), None) => ShardInput::Samples(region_samples(samples, &spec)?),
        (None, Some(pieces)) => {
            let mut parsed = Vec::with_capacity(pieces.len());
            for piece in pieces.iter() {
                let (child, halves): ([u64; 3], PyReadonlyArray1<f32>) = piece.extract().map_err(|_| {
                    PyValueError::new_err("a piece is a (child shard, float32 array of its halves) pair")
                })?;
                parsed.push((child, halves.as_slice()?.to_vec()));
            }
            ShardInput::Pieces(parsed)
        }
        _ => return Err(PyValueError::new_err("give a shard either its samples (level 0) or its children's pieces")),
    };
    let output = py.detach(|| spec.write_shard(level, shard, input)).map_err(|e| to_py_err(e.into()))?;
    Ok((output.coarse.into_pyarray(py), summary_to_py(py, &output.summary)?))
}

/// A level-0 shard's samples as f32, x fastest, from an array of the import's own sample type.
fn region_samples(samples: &Bound<'_, PyAny>, spec: &ShardSpec) -> PyResult<Vec<f32>> {
    fn values<T: numpy::Element + Copy>(samples: &Bound<'_, PyAny>, cast: fn(T) -> f32) -> Option<Vec<f32>> {
        let array: PyReadonlyArray3<T> = samples.extract().ok()?;
        Some(array.as_array().iter().map(|&v| cast(v)).collect())
    }
    let dtype = sample_type(&spec.dtype)?;
    let parsed = match dtype {
        DType::U8 => values::<u8>(samples, f32::from),
        DType::U16 => values::<u16>(samples, f32::from),
        DType::I16 => values::<i16>(samples, f32::from),
        DType::F32 => values::<f32>(samples, |v| v),
    };
    parsed.ok_or_else(|| {
        let got = samples.getattr("dtype").and_then(|d| d.str().map(|s| s.to_string())).unwrap_or_default();
        PyValueError::new_err(format!("a shard of a {} import was given a 3-D array of {got}", dtype.name()))
    })
}

fn sample_type(name: &str) -> PyResult<DType> {
    let dtype = match name {
        "uint8" => Some(DType::U8),
        "uint16" => Some(DType::U16),
        "int16" => Some(DType::I16),
        "float32" => Some(DType::F32),
        other => DType::from_name(other),
    };
    dtype.ok_or_else(|| {
        PyValueError::new_err(format!(
            "a distributed import of {name} is not possible: its shards hold uint8, uint16, int16 or float32 (convert \
             the array first, e.g. array.astype(numpy.float32))"
        ))
    })
}

fn summary_to_py<'py>(py: Python<'py>, summary: &ShardSummary) -> PyResult<Bound<'py, PyDict>> {
    let dict = PyDict::new(py);
    dict.set_item("level", summary.level)?;
    dict.set_item("shard", summary.shard)?;
    dict.set_item("bricks", summary.bricks.clone().into_pyarray(py))?;
    let ranges: Vec<f32> = summary.ranges.iter().flatten().copied().collect();
    dict.set_item("ranges", ranges.into_pyarray(py).reshape([summary.ranges.len(), 2])?)?;
    dict.set_item("value_range", summary.value_range)?;
    if let Some(parts) = &summary.histogram {
        dict.set_item("histogram_keys", parts.keys.clone().into_pyarray(py))?;
        dict.set_item("histogram_counts", parts.counts.clone().into_pyarray(py))?;
        dict.set_item("histogram_range", (parts.low, parts.high))?;
    }
    Ok(dict)
}

fn summary_from_py(summary: &Bound<'_, PyAny>) -> PyResult<ShardSummary> {
    let bad =
        |what: &str| PyValueError::new_err(format!("not a shard summary ({what}): pass what write_shard returned"));
    let item = |key: &str| summary.get_item(key).map_err(|_| bad(key));
    let ranges: PyReadonlyArray2<f32> = item("ranges")?.extract().map_err(|_| bad("ranges"))?;
    let ranges = ranges.as_array();
    if ranges.ncols() != 2 {
        return Err(bad("ranges"));
    }
    let bricks: PyReadonlyArray1<u64> = item("bricks")?.extract().map_err(|_| bad("bricks"))?;
    let histogram = match summary.get_item("histogram_keys") {
        Ok(keys) => {
            let keys: PyReadonlyArray1<u32> = keys.extract().map_err(|_| bad("histogram_keys"))?;
            let counts: PyReadonlyArray1<u64> = item("histogram_counts")?.extract().map_err(|_| bad("histogram"))?;
            let (low, high): (f32, f32) = item("histogram_range")?.extract().map_err(|_| bad("histogram_range"))?;
            Some(HistogramParts { keys: keys.as_slice()?.to_vec(), counts: counts.as_slice()?.to_vec(), low, high })
        }
        Err(_) => None,
    };
    Ok(ShardSummary {
        level: item("level")?.extract().map_err(|_| bad("level"))?,
        shard: item("shard")?.extract().map_err(|_| bad("shard"))?,
        bricks: bricks.as_slice()?.to_vec(),
        ranges: ranges.rows().into_iter().map(|r| [r[0], r[1]]).collect(),
        value_range: item("value_range")?.extract().map_err(|_| bad("value_range"))?,
        histogram,
    })
}
