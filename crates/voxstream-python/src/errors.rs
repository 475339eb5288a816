//! voxstream's errors as Python exceptions, carrying the CLI's one-line messages
//! ([`voxstream_api::error_message::user_message`]): a missing file is `FileNotFoundError`, other I/O `OSError`, a
//! render that could not read some bricks `RuntimeError`, everything else (bad arguments, bad data) `ValueError`.

use pyo3::exceptions::{PyFileNotFoundError, PyOSError, PyRuntimeError, PyValueError};
use pyo3::PyErr;
use voxstream_api::error_message::user_message;

/// The Python exception for `error`.
pub fn to_py_err(error: anyhow::Error) -> PyErr {
    let message = user_message(&error);
    let io = error.chain().find_map(|cause| cause.downcast_ref::<std::io::Error>());
    match io {
        Some(io) if io.kind() == std::io::ErrorKind::NotFound => PyFileNotFoundError::new_err(message),
        Some(_) => PyOSError::new_err(message),
        None if message.contains("does not exist") || message.contains("not found") => {
            PyFileNotFoundError::new_err(message)
        }
        None => PyValueError::new_err(message),
    }
}

/// A render that finished but could not read every brick (the CLI's exit 3).
pub fn incomplete(failed: usize, first: &str) -> PyErr {
    PyRuntimeError::new_err(format!(
        "{failed} bricks could not be read ({first}); coarser data stood in: the image is incomplete"
    ))
}
