//! OpenVDB (`.vdb`): fog volumes and level sets, through OpenVDB's own Python binding (Debian `python3-openvdb`).
//!
//! No Rust crate reads VDB files, and the format (a compressed sparse tree of typed leaf buffers) is OpenVDB's own;
//! rather than re-implementing it, voxstream runs `/usr/bin/python3` with `pyopenvdb` as a converter process: it
//! prints the first float grid's active bounding box, voxel size and class as one JSON line, then streams the dense
//! samples of that box z slice by z slice (f32, x fastest) on its standard output, so memory stays bounded. Inactive
//! voxels hold the grid's background (0 for fog volumes, the positive narrow-band width outside a level set).
//! Set `VOXSTREAM_PYTHON` to use another interpreter that has `pyopenvdb`.

use std::io::{BufRead, BufReader, Read};
use std::path::Path;
use std::process::{Command, Stdio};

use super::sample_stream::{Endian, SampleStream};
use crate::error::StoreError;
use crate::volume::{DType, VolumeInfo};

const CONVERTER: &str = r#"
import json, sys
import numpy as np
import pyopenvdb as vdb
path = sys.argv[1]
grids = [g for g in vdb.readAll(path)[0] if isinstance(g, vdb.FloatGrid)]
if not grids:
    sys.exit("no float grid in the file")
grid = grids[0]
lo, hi = grid.evalActiveVoxelBoundingBox()
dims = [hi[a] - lo[a] + 1 for a in range(3)]
if min(dims) <= 0:
    sys.exit("the grid has no active voxels")
voxel = grid.transform.voxelSize()
origin = grid.transform.indexToWorld(lo)
meta = {"name": grid.name, "class": str(grid.gridClass), "dims": dims, "spacing": list(voxel), "origin": list(origin),
        "background": float(grid.background)}
out = sys.stdout.buffer
out.write((json.dumps(meta) + "\n").encode())
plane = np.empty((dims[0], dims[1], 1), dtype=np.float32)
for k in range(dims[2]):
    grid.copyToArray(plane, ijk=(lo[0], lo[1], lo[2] + k))
    out.write(np.ascontiguousarray(plane[:, :, 0].T).astype("<f4").tobytes())
out.flush()
"#;

/// The most samples a `.vdb`'s dense bounding box may hold: the converter streams it without a length known
/// beforehand, so the importer's per-brick tables are bounded by this rather than by a file size (a 4096² × 1024 box).
pub const MAX_VDB_SAMPLES: u64 = 1 << 34;

/// The most samples one z slice of a `.vdb`'s box may hold (16384²).
pub const MAX_VDB_SLICE_SAMPLES: u64 = 1 << 28;

/// Parses the converter's first line: `{"dims": [x, y, z], "spacing": [..], "origin": [..], ...}`, with the box
/// bounded by [`MAX_VDB_SAMPLES`] and [`MAX_VDB_SLICE_SAMPLES`].
pub fn parse_converter_header(path: &Path, line: &str) -> Result<VolumeInfo, StoreError> {
    let meta: serde_json::Value =
        serde_json::from_str(line.trim()).map_err(|e| StoreError::format(path, format!("converter output: {e}")))?;
    let triple = |key: &str| -> Result<[f64; 3], StoreError> {
        let v = meta[key]
            .as_array()
            .filter(|a| a.len() == 3)
            .ok_or_else(|| StoreError::format(path, format!("converter output has no {key}")))?;
        Ok([0, 1, 2].map(|a| v[a].as_f64().unwrap_or(f64::NAN)))
    };
    let dims = triple("dims")?;
    if dims.iter().any(|d| d.fract() != 0.0 || !(1.0..=(1u64 << 20) as f64).contains(d)) {
        return Err(StoreError::format(
            path,
            format!("the grid's active box {dims:?} is not 1 to 2^20 voxels per axis"),
        ));
    }
    let dims = dims.map(|d| d as u64);
    let (slice, volume) = (dims[0] * dims[1], dims[0] * dims[1] * dims[2]);
    if slice > MAX_VDB_SLICE_SAMPLES || volume > MAX_VDB_SAMPLES {
        return Err(StoreError::Unsupported {
            path: path.into(),
            message: format!(
                "the grid's active box {dims:?} is larger than a .vdb import allows ({MAX_VDB_SLICE_SAMPLES} samples \
                 per slice, {MAX_VDB_SAMPLES} in all)"
            ),
        });
    }
    let info = VolumeInfo {
        dims,
        dtype: DType::F32,
        spacing: triple("spacing")?,
        origin: triple("origin")?,
        unit: None,
        orientation: None,
    };
    info.validate(path)?;
    Ok(info)
}

/// Opens a `.vdb` file's first float grid.
pub fn open(path: &Path) -> Result<SampleStream, StoreError> {
    let python = std::env::var("VOXSTREAM_PYTHON").unwrap_or_else(|_| "/usr/bin/python3".into());
    let mut child = Command::new(&python)
        .arg("-c")
        .arg(CONVERTER)
        .arg(path)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| StoreError::Unsupported {
            path: path.into(),
            message: format!("reading .vdb needs {python} with pyopenvdb (Debian python3-openvdb): {e}"),
        })?;
    let stdout = child.stdout.take().ok_or_else(|| StoreError::format(path, "converter has no output"))?;
    let mut reader = BufReader::with_capacity(1 << 20, stdout);
    let mut line = String::new();
    let read = reader.read_line(&mut line).map_err(|e| StoreError::io(path, e))?;
    if read == 0 || !line.starts_with('{') {
        let mut message = String::new();
        if let Some(mut stderr) = child.stderr.take() {
            let _ = stderr.read_to_string(&mut message);
        }
        let _ = child.wait();
        let last = message.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("no output").trim().to_string();
        let hint = if last.contains("No module named") { " (install Debian python3-openvdb)" } else { "" };
        return Err(StoreError::format(path, format!("cannot read the VDB: {last}{hint}")));
    }
    let info = match parse_converter_header(path, &line) {
        Ok(info) => info,
        Err(error) => {
            let _ = child.kill();
            let _ = child.wait();
            return Err(error);
        }
    };
    // The child is reaped when its output ends; a failure mid-stream shows as a truncated volume.
    std::thread::spawn(move || {
        let _ = child.wait();
    });
    SampleStream::from_reader(path, Box::new(reader), info, DType::F32.into(), Endian::Little)
}
