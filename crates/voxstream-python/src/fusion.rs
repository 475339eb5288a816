//! `voxstream._native.fuse` and `synthesize_rgbd`: depth-camera fusion (Reichl ch. 8) from Python, through the
//! facade ([`voxstream_api::depth_fusion`]) as `voxstream fuse` and `voxstream synth-rgbd`. Both run with the GIL
//! released; `fuse`'s callback (frames done, of the total) and Python's signal handlers run after every frame, and
//! Ctrl-C or an exception in the callback stops the fusion with nothing saved.

use std::path::PathBuf;

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use voxstream_api::depth_fusion::{fuse_dataset, FuseOptions, PoseSource};
use voxstream_fusion::rgbd::{write_sequence, NoiseModel, SyntheticSequence, SyntheticSettings};
use voxstream_fusion::FusionSettings;

use crate::errors::{progress_step, to_py_err};

/// Fuses the TUM RGB-D folder `dataset` into the store `out` (and/or surface `points`, a PLY); returns what was done.
#[pyfunction]
#[pyo3(signature = (dataset, out=None, *, points=None, trajectory=None, poses="ground-truth", voxel=0.01, window=16,
    sub_cache=2, confidence=3.0, frames=None, memory_mb=1024, overwrite=false, sign_only=false, progress=None))]
#[allow(clippy::too_many_arguments)]
pub fn fuse<'py>(
    py: Python<'py>,
    dataset: PathBuf,
    out: Option<PathBuf>,
    points: Option<PathBuf>,
    trajectory: Option<PathBuf>,
    poses: &str,
    voxel: f64,
    window: usize,
    sub_cache: usize,
    confidence: f32,
    frames: Option<usize>,
    memory_mb: u64,
    overwrite: bool,
    sign_only: bool,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let poses = match poses {
        "ground-truth" => PoseSource::GroundTruth,
        "track" => PoseSource::Track,
        other => return Err(PyValueError::new_err(format!("poses={other:?}: give \"ground-truth\" or \"track\""))),
    };
    if out.is_none() && points.is_none() && trajectory.is_none() {
        return Err(PyValueError::new_err("give out (a store), points or trajectory: nothing would be saved"));
    }
    if memory_mb < 16 {
        return Err(PyValueError::new_err(format!("memory_mb={memory_mb}: give at least 16")));
    }
    let mut settings = FusionSettings::default();
    settings.integration.voxel = voxel;
    settings.integration.confidence_weight = confidence;
    settings.integration.surface_offsets = !sign_only;
    settings.window = window;
    settings.sub_cache = sub_cache;
    settings.memory_budget = usize::try_from(memory_mb.saturating_mul(1 << 20)).unwrap_or(usize::MAX);
    settings.validate().map_err(|e| PyValueError::new_err(e.to_string()))?;
    let options = FuseOptions {
        settings,
        poses,
        frames,
        intrinsics: None,
        out: out.clone(),
        overwrite,
        points,
        raw_points: false,
        trajectory,
        image: false,
    };
    let mut raised: Option<PyErr> = None;
    let report = py.detach(|| {
        fuse_dataset(&dataset, &options, &mut |done, total| progress_step(&progress, &mut raised, done, total))
    });
    if let Some(error) = raised {
        return Err(error);
    }
    let report = report.map_err(to_py_err)?;
    let s = &report.stats;
    let result = PyDict::new(py);
    result.set_item("frames", s.frames)?;
    result.set_item("frames_lost", report.frames_lost)?;
    result.set_item("windows", s.windows)?;
    result.set_item("bricks", report.bricks)?;
    result.set_item("peak_brick_bytes", s.peak_brick_bytes)?;
    result.set_item("ring_bytes", s.ring_bytes)?;
    result.set_item("fuse_seconds", report.fuse_seconds)?;
    result.set_item("surface_points", report.surface_points)?;
    result.set_item("ate_rmse", report.ate_rmse)?;
    result.set_item("out", out)?;
    result.set_item("levels", report.store.as_ref().map(|r| r.levels))?;
    Ok(result)
}

/// Renders a synthetic RGB-D sequence of the mesh file `mesh` into the TUM RGB-D folder `out`.
#[pyfunction]
#[pyo3(signature = (mesh, out, *, frames=300, noise=true, object_size=0.5, radius=1.2, height=0.5, sweep=360.0,
    up="y", seed=0x5EED, level=false, overwrite=false))]
#[allow(clippy::too_many_arguments)]
pub fn synthesize_rgbd(
    py: Python<'_>,
    mesh: PathBuf,
    out: PathBuf,
    frames: usize,
    noise: bool,
    object_size: f64,
    radius: f64,
    height: f64,
    sweep: f64,
    up: &str,
    seed: u64,
    level: bool,
    overwrite: bool,
) -> PyResult<usize> {
    let up_axis = match up {
        "x" => 0,
        "y" => 1,
        "z" => 2,
        other => return Err(PyValueError::new_err(format!("up={other:?}: give \"x\", \"y\" or \"z\""))),
    };
    let settings = SyntheticSettings {
        frames,
        object_size,
        radius,
        height,
        sweep_degrees: sweep,
        up_axis,
        seed,
        noise: if noise { NoiseModel::KINECT_V1 } else { NoiseModel::NONE },
        world: if level { voxstream_fusion::Pose::IDENTITY } else { SyntheticSettings::tilted_world() },
        ..SyntheticSettings::default()
    };
    py.detach(|| {
        let sequence = SyntheticSequence::from_mesh_file(&mesh, settings)?;
        write_sequence(&sequence, &out, overwrite, &mut |_, _| {})?;
        Ok::<usize, voxstream_fusion::FusionError>(sequence.len())
    })
    .map_err(|e| to_py_err(e.into()))
}
