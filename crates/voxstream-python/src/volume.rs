//! `voxstream._native.Volume`: one source, opened through the facade, rendered into numpy arrays.
//!
//! A render runs on a thread of its own while the calling thread waits with the GIL released, waking every 50 ms to
//! let Python run its signal handlers: Ctrl-C raises `KeyboardInterrupt` at once and stops the frame after its
//! current pass (the session stays usable). The pixels are moved into the array (`PyArray::from_vec`), not copied.

use std::ops::ControlFlow;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, RecvTimeoutError};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use numpy::{PyArray1, PyArrayMethods};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use voxstream_api::camera_presets::{CameraTurn, ViewDirection};
use voxstream_api::scenes::SCENE_NAMES;
use voxstream_api::{
    Backend, Camera, CameraOptions, IsoOptions, Mode, SessionOptions, Shading, SourceMeta, SourceOptions,
    TransferFunction, TransferFunctionChoice, ViewOptions, Volume,
};
use voxstream_render::{ClipPlane, Projection};
use voxstream_store::remote_access::RemoteAccess;
use voxstream_store::DType;

use crate::errors::{incomplete, to_py_err};

/// The most bytes `read_region` hands over at once.
const MAX_REGION_BYTES: u64 = 4 << 30;

/// How often a waiting render lets Python handle signals (Ctrl-C).
const SIGNAL_POLL: Duration = Duration::from_millis(50);

/// A camera as Python passes it: eye, target, up, vertical field of view in degrees.
type CameraTuple = ([f64; 3], [f64; 3], [f64; 3], f64);

/// A source opened for rendering.
#[pyclass(name = "Volume", module = "voxstream._native")]
pub struct PyVolume {
    volume: Arc<Mutex<Volume>>,
    meta: SourceMeta,
}

/// What the render thread hands back.
struct Rendered {
    width: u32,
    height: u32,
    rgba8: Option<Vec<u8>>,
    rgba32: Option<Vec<f32>>,
    stats: Vec<(&'static str, f64)>,
    converged: bool,
    interrupted: bool,
    failures: Vec<String>,
    /// The renderer that drew it (`cpu…`, `gpu: adapter, filtering`).
    renderer: String,
}

#[pymethods]
impl PyVolume {
    /// Opens `source`: a built-in scene, a mesh or particle file, or a store's folder or URL; `channel` and `time`
    /// choose the volume of a 4-D or 5-D OME-Zarr image (the first of each by default; `info["leading_axes"]`).
    #[new]
    #[pyo3(signature = (source, *, width=512, height=512, budget_mb=256, value_range=None, in_memory=false,
        cache_dir=None, cache_mb=None, request_timeout=None, retries=None, concurrent_requests=None, channel=None,
        time=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        source: PathBuf,
        width: u32,
        height: u32,
        budget_mb: u64,
        value_range: Option<[f64; 2]>,
        in_memory: bool,
        cache_dir: Option<PathBuf>,
        cache_mb: Option<u64>,
        request_timeout: Option<f64>,
        retries: Option<usize>,
        concurrent_requests: Option<usize>,
        channel: Option<u64>,
        time: Option<u64>,
    ) -> PyResult<Self> {
        let name = source.to_str().ok_or_else(|| PyValueError::new_err("the source's name is not valid UTF-8"))?;
        let mut remote = RemoteAccess { cache_dir, ..RemoteAccess::default() };
        if let Some(mb) = cache_mb {
            remote.cache_limit_bytes = mb.saturating_mul(1 << 20);
        }
        if let Some(seconds) = request_timeout {
            if !(seconds.is_finite() && seconds > 0.0 && seconds < 1e6) {
                return Err(PyValueError::new_err(format!(
                    "request_timeout {seconds} is not a positive number of seconds"
                )));
            }
            remote.options.request_timeout = Duration::from_secs_f64(seconds);
        }
        if let Some(retries) = retries {
            remote.options.retries = retries;
        }
        if let Some(concurrency) = concurrent_requests {
            if concurrency == 0 {
                return Err(PyValueError::new_err("concurrent_requests must be at least 1"));
            }
            remote.options.concurrency = concurrency;
        }
        let planes = voxstream_store::image_planes::PlaneChoice { channel, time };
        let options =
            SourceOptions { value_range, in_memory, remote, width, height, planes, ..SourceOptions::default() };
        let name = name.to_string();
        let volume = py.detach(|| Volume::open(&name, &options, budget_mb)).map_err(to_py_err)?;
        let meta = volume.meta().clone();
        Ok(PyVolume { volume: Arc::new(Mutex::new(volume)), meta })
    }

    /// The name the source was opened by (a URL without credentials).
    #[getter]
    fn name(&self) -> String {
        self.meta.name.clone()
    }

    /// What the source is: its kind, size, sample type, spacing, levels and values.
    #[getter]
    fn info<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let meta = &self.meta;
        let info = PyDict::new(py);
        info.set_item("name", &meta.name)?;
        info.set_item("value_range", meta.value_range)?;
        info.set_item("typical_range", meta.typical_range)?;
        match &meta.store {
            Some(store) => {
                let attributes = store.attributes();
                let volume = store.info();
                info.set_item("kind", "store")?;
                info.set_item("dims", volume.dims)?;
                info.set_item("dtype", volume.dtype.name())?;
                info.set_item("spacing", volume.spacing)?;
                info.set_item("origin", volume.origin)?;
                // The spacing's unit as OME-Zarr names it ("millimeter", …), or None when the store has none.
                info.set_item("unit", volume.unit.map(|u| u.name()))?;
                // The anatomical direction each axis points to ("RAS", "LPS", …), or None when the store has none.
                info.set_item("orientation", volume.orientation.map(|o| o.code()))?;
                info.set_item("levels", store.layout().levels())?;
                info.set_item("brick_size", store.layout().brick_size)?;
                info.set_item("native", store.is_native())?;
                info.set_item("remote", store.remote().is_some())?;
                // How the bricks are compressed: "zstd" or "wavelet", and the wavelet codec's guaranteed bound.
                let codec = attributes.brick_codec.unwrap_or_default();
                let codec_name = match codec {
                    voxstream_store::BrickCodec::Zstd => "zstd",
                    voxstream_store::BrickCodec::Wavelet { .. } => "wavelet",
                };
                info.set_item("codec", codec_name)?;
                info.set_item("max_error", codec.max_error())?;
                let percentiles: Vec<[f64; 2]> = attributes.value_percentiles.clone().unwrap_or_default();
                info.set_item("percentiles", percentiles)?;
                // A 4-D/5-D image's axes before z, y, x: (name, kind, extent, index read).
                let axes: Vec<(String, &str, u64, u64)> = store
                    .image_planes()
                    .axes
                    .iter()
                    .map(|a| (a.name.clone(), a.kind.name(), a.extent, a.index))
                    .collect();
                info.set_item("leading_axes", axes)?;
            }
            None if meta.description.is_some() => info.set_item("kind", "geometry")?,
            None => info.set_item("kind", "scene")?,
        }
        if let Some(description) = &meta.description {
            info.set_item("description", description)?;
        }
        Ok(info)
    }

    /// The source's default camera for the size it was opened with: (eye, target, up, fov).
    #[getter]
    fn default_camera(&self) -> CameraTuple {
        let c = self.meta.camera;
        (c.eye, c.target, c.up, c.fov)
    }

    /// A store's levels' sizes, finest first, each (x, y, z); empty for scenes and geometry.
    #[getter]
    fn level_dims(&self) -> Vec<[u64; 3]> {
        self.meta.store.as_ref().map(|store| store.layout().level_dims.clone()).unwrap_or_default()
    }

    /// Samples `[lower, lower + size)` (x, y, z) of a store's `level` in data values, as an array of the store's
    /// sample type (uint8, uint16, int16 or float32) indexed [z, y, x] (what napari's multiscale layers read). At
    /// most 4 GiB at once.
    fn read_region<'py>(
        &self,
        py: Python<'py>,
        level: usize,
        lower: [u64; 3],
        size: [u64; 3],
    ) -> PyResult<Bound<'py, PyAny>> {
        let Some(store) = self.meta.store.clone() else {
            return Err(PyValueError::new_err(format!("{} is not a store: it has no samples to read", self.meta.name)));
        };
        let levels = &store.layout().level_dims;
        let Some(dims) = levels.get(level) else {
            return Err(PyValueError::new_err(format!("level {level} does not exist: the store has {}", levels.len())));
        };
        let inside = (0..3).all(|a| size[a] > 0 && lower[a].checked_add(size[a]).is_some_and(|u| u <= dims[a]));
        if !inside {
            return Err(PyValueError::new_err(format!(
                "region {lower:?} + {size:?} is not inside level {level} ({dims:?}, x, y, z)"
            )));
        }
        let dtype = store.info().dtype;
        let bytes = size.iter().try_fold(dtype.size() as u64, |n, s| n.checked_mul(*s));
        if bytes.is_none_or(|b| b > MAX_REGION_BYTES) {
            return Err(PyValueError::new_err(format!(
                "region {size:?} of level {level} is too large to read at once (at most {} GiB): read a coarser \
                 level or a smaller region",
                MAX_REGION_BYTES >> 30
            )));
        }
        let values = py.detach(|| store.read_region(level, lower, size)).map_err(|e| to_py_err(e.into()))?;
        let shape = [size[2] as usize, size[1] as usize, size[0] as usize];
        // The store's values are exact in f32 for every sample type: converted back without loss.
        Ok(match dtype {
            DType::U8 => PyArray1::from_vec(py, values.iter().map(|&v| v as u8).collect()).reshape(shape)?.into_any(),
            DType::U16 => PyArray1::from_vec(py, values.iter().map(|&v| v as u16).collect()).reshape(shape)?.into_any(),
            DType::I16 => PyArray1::from_vec(py, values.iter().map(|&v| v as i16).collect()).reshape(shape)?.into_any(),
            DType::F32 => PyArray1::from_vec(py, values).reshape(shape)?.into_any(),
        })
    }

    /// The samples' type of a store (`u8`, `u16`, `i16`, `f32`), or None.
    #[getter]
    fn dtype(&self) -> Option<&'static str> {
        self.meta.store.as_ref().map(|store| store.info().dtype.name())
    }

    /// Renders one frame; returns (pixels, stats). See the Python wrapper `voxstream.Volume.render`.
    #[pyo3(signature = (*, width=512, height=512, budget_mb=256, backend="cpu", mode="converged", camera=None,
        tf_points=None, tf_file=None, iso=Vec::new(), iso_colors=Vec::new(), iso_opacities=Vec::new(),
        shadows=false, light=None, background=[0.0; 3], step=0.5, lod_bias=0.0, shading=None, blending=true,
        preintegrate=false, adaptive_step=None, faithful=false, float32=false, region=None, projection="composite",
        clip_planes=Vec::new(), view=None, azimuth=None, elevation=None, zoom=None, slice=None, slice_with_volume=false,
        color_bar=false, scale_bar=false))]
    #[allow(clippy::too_many_arguments)]
    fn render<'py>(
        &self,
        py: Python<'py>,
        width: u32,
        height: u32,
        budget_mb: u64,
        backend: &str,
        mode: &str,
        camera: Option<CameraTuple>,
        tf_points: Option<Vec<[f64; 5]>>,
        tf_file: Option<PathBuf>,
        iso: Vec<f64>,
        iso_colors: Vec<[f64; 3]>,
        iso_opacities: Vec<f32>,
        shadows: bool,
        light: Option<[f64; 3]>,
        background: [f64; 3],
        step: f64,
        lod_bias: f64,
        shading: Option<&str>,
        blending: bool,
        preintegrate: bool,
        adaptive_step: Option<f64>,
        faithful: bool,
        float32: bool,
        region: Option<[[u64; 3]; 2]>,
        projection: &str,
        clip_planes: Vec<([f64; 3], [f64; 3])>,
        view: Option<&str>,
        azimuth: Option<f64>,
        elevation: Option<f64>,
        zoom: Option<f64>,
        slice: Option<&str>,
        slice_with_volume: bool,
        color_bar: bool,
        scale_bar: bool,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyDict>)> {
        let annotations = voxstream_api::annotations::Annotations { color_bar, scale_bar };
        let slice = slice.map(voxstream_api::slices::parse_slice).transpose().map_err(PyValueError::new_err)?;
        let mode = match mode {
            "converged" => Mode::Converged,
            "interactive" => Mode::Interactive,
            other => return Err(PyValueError::new_err(format!("mode '{other}' is not one of converged, interactive"))),
        };
        let backend = Backend::from_name(backend).map_err(to_py_err)?;
        let transfer_function = match (tf_points, tf_file) {
            (Some(_), Some(_)) => {
                return Err(PyValueError::new_err("give a transfer function's points or its file, not both"))
            }
            (Some(points), None) => {
                TransferFunctionChoice::Given(TransferFunction::new(points, None).map_err(|e| to_py_err(e.into()))?)
            }
            (None, Some(file)) => TransferFunctionChoice::File(file),
            (None, None) => TransferFunctionChoice::Default,
        };
        let shading = match shading {
            None => None,
            Some("none") => Some(Shading::None),
            Some("phong") => Some(Shading::Phong),
            Some(other) => return Err(PyValueError::new_err(format!("shading '{other}' is not one of none, phong"))),
        };
        let projection = match projection {
            "composite" => Projection::Composite,
            "max" => Projection::Maximum,
            "min" => Projection::Minimum,
            "mean" => Projection::Mean,
            other => {
                return Err(PyValueError::new_err(format!(
                    "projection '{other}' is not one of composite, max, min, mean"
                )))
            }
        };
        let preset = view.map(ViewDirection::parse).transpose().map_err(|e| PyValueError::new_err(e.to_string()))?;
        let clip_planes = clip_planes.into_iter().map(|(point, normal)| ClipPlane { point, normal }).collect();
        let view = ViewOptions {
            width,
            height,
            transfer_function,
            iso: IsoOptions {
                values: iso,
                colors: iso_colors,
                opacities: iso_opacities,
                shadows,
                central_normals: false,
            },
            shading,
            light,
            background,
            step,
            preintegrate,
            adaptive_step,
            faithful,
            lod_bias,
            colour_by_level: false,
            camera: CameraOptions {
                camera: camera.map(|(eye, target, up, fov)| Camera { eye, target, up, fov }),
                preset,
                turn: CameraTurn { azimuth, elevation, zoom },
                ..CameraOptions::default()
            },
            region,
            projection,
            clip_planes,
            slice: slice.map(|slice| voxstream_api::slices::Slice { with_volume: slice_with_volume, ..slice }),
            volume_slice: None,
        };
        let session = SessionOptions { budget_mb, backend, blending, ..SessionOptions::default() };
        let rendered = self.render_on_thread(py, view, session, mode, float32, annotations)?;
        if !rendered.failures.is_empty() && mode == Mode::Converged {
            return Err(incomplete(rendered.failures.len(), &rendered.failures[0]));
        }
        let (h, w) = (rendered.height as usize, rendered.width as usize);
        let pixels = match (rendered.rgba8, rendered.rgba32) {
            (Some(bytes), _) => PyArray1::from_vec(py, bytes).reshape([h, w, 4])?.into_any(),
            (None, Some(floats)) => PyArray1::from_vec(py, floats).reshape([h, w, 4])?.into_any(),
            (None, None) => return Err(PyRuntimeError::new_err("the render thread returned no pixels (a bug)")),
        };
        let stats = PyDict::new(py);
        for (key, value) in rendered.stats {
            stats.set_item(key, value)?;
        }
        stats.set_item("converged", rendered.converged)?;
        stats.set_item("interrupted", rendered.interrupted)?;
        stats.set_item("failures", rendered.failures)?;
        stats.set_item("renderer", rendered.renderer)?;
        Ok((pixels, stats))
    }
}

impl PyVolume {
    /// Renders on a thread of its own; the caller waits without the GIL and answers Ctrl-C within [`SIGNAL_POLL`].
    fn render_on_thread(
        &self,
        py: Python<'_>,
        view: ViewOptions,
        session: SessionOptions,
        mode: Mode,
        float32: bool,
        annotations: voxstream_api::annotations::Annotations,
    ) -> PyResult<Rendered> {
        let volume = self.volume.clone();
        let cancel = Arc::new(AtomicBool::new(false));
        let cancelled = cancel.clone();
        let (sender, receiver) = mpsc::channel();
        std::thread::Builder::new()
            .name("voxstream-render".into())
            .spawn(move || {
                // A render interrupted earlier may still hold the volume until its pass ends; a poisoned lock only
                // means such a thread panicked, and the session is rebuilt by the next render's checks.
                let mut volume = volume.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
                let mut observe = |_: &voxstream_api::PassProgress| {
                    if cancelled.load(Ordering::Relaxed) {
                        ControlFlow::Break(())
                    } else {
                        ControlFlow::Continue(())
                    }
                };
                let started = std::time::Instant::now();
                let result = volume
                    .render(&view, &session, mode, &mut observe)
                    .and_then(|(frame, prepared)| {
                        if annotations.color_bar && prepared.drawing_surfaces && !prepared.settings.surfaces_in_volume {
                            anyhow::bail!(
                            "color_bar shows the transfer function, and only isosurfaces are drawn: give tf= to draw \
                             the volume too, or drop color_bar"
                        );
                        }
                        Ok((frame, prepared))
                    })
                    .map(|(frame, prepared)| {
                        let rendered_at = std::time::Instant::now();
                        let remote = volume.meta().remote.as_ref().map(|remote| remote.counts());
                        let mut stats = vec![
                            ("passes", f64::from(frame.passes)),
                            ("elapsed_ms", frame.elapsed_ms),
                            ("render_ms", frame.render_ms),
                            ("rays", frame.rays as f64),
                            ("samples", frame.samples as f64),
                            ("requests", frame.requests as f64),
                            ("bricks_produced", frame.bricks_produced as f64),
                            ("pending", frame.pending as f64),
                        ];
                        if let Some(counts) = remote {
                            stats.push(("remote_requests", counts.requests as f64));
                            stats.push(("remote_bytes", counts.bytes as f64));
                        }
                        let renderer = volume.session().map(|s| s.renderer().describe()).unwrap_or_default();
                        let image = match annotations.any() {
                            true => {
                                let unit = volume.meta().store.as_ref().and_then(|s| s.info().unit.map(|u| u.name()));
                                let context = voxstream_api::annotations::AnnotationContext {
                                    transfer_function: &prepared.transfer_function,
                                    camera: &prepared.camera,
                                    world_per_unit: 1.0,
                                    unit,
                                };
                                voxstream_api::annotations::annotate(&frame.image, annotations, &context)
                            }
                            false => frame.image,
                        };
                        let (width, height) = (image.width, image.height);
                        let rgba8 = (!float32).then(|| image.to_rgba8());
                        let rgba32 = float32.then(|| image.pixels.into_flattened());
                        // Where the time outside the engine's frame went: preparing the view and session, converting.
                        let total_ms = started.elapsed().as_secs_f64() * 1000.0;
                        stats.push(("convert_ms", rendered_at.elapsed().as_secs_f64() * 1000.0));
                        stats.push(("call_ms", total_ms));
                        Rendered {
                            width,
                            height,
                            rgba8,
                            rgba32,
                            stats,
                            converged: frame.pending == 0 && !frame.interrupted,
                            interrupted: frame.interrupted,
                            failures: frame.failures.iter().map(ToString::to_string).collect(),
                            renderer,
                        }
                    });
                let _ = sender.send(result);
            })
            .map_err(|e| PyRuntimeError::new_err(format!("cannot start a render thread: {e}")))?;
        let mut receiver = receiver;
        loop {
            // (The receiver travels into the GIL-free closure and back: it is `Send`, not `Sync`.)
            let (answer, back) = py.detach(move || (receiver.recv_timeout(SIGNAL_POLL), receiver));
            receiver = back;
            match answer {
                Ok(result) => return result.map_err(to_py_err),
                Err(RecvTimeoutError::Timeout) => {
                    if let Err(error) = py.check_signals() {
                        cancel.store(true, Ordering::Relaxed);
                        return Err(error);
                    }
                }
                Err(RecvTimeoutError::Disconnected) => {
                    return Err(PyRuntimeError::new_err("the render thread stopped without an answer (a bug)"))
                }
            }
        }
    }
}

/// The names of the built-in scenes.
#[pyfunction]
pub fn scene_names() -> Vec<&'static str> {
    SCENE_NAMES.to_vec()
}
