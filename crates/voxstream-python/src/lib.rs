//! # voxstream for Python: the native module `voxstream._native`
//!
//! A thin layer over the library facade ([`voxstream_api`]): [`volume::PyVolume`] opens any source the CLI opens
//! and renders it into numpy arrays that own Rust's pixel buffer (no copy), with the GIL released and Ctrl-C
//! honoured; [`import::import_volume`] writes a store from a file or a numpy array; [`fusion::fuse`] fuses an
//! RGB-D sequence into a store; [`shard_tasks`] is the native half of an import spread over a Dask cluster. The Python package (`python/voxstream/`) wraps it with cameras, transfer functions,
//! sessions and Jupyter display.

mod errors;
mod fusion;
mod import;
mod shard_tasks;
mod volume;

use pyo3::prelude::*;

/// The native module.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<volume::PyVolume>()?;
    m.add_function(wrap_pyfunction!(import::import_volume, m)?)?;
    m.add_function(wrap_pyfunction!(volume::scene_names, m)?)?;
    m.add_function(wrap_pyfunction!(fusion::fuse, m)?)?;
    m.add_function(wrap_pyfunction!(fusion::synthesize_rgbd, m)?)?;
    m.add_class::<shard_tasks::ShardImport>()?;
    m.add_function(wrap_pyfunction!(shard_tasks::write_shard, m)?)?;
    Ok(())
}
