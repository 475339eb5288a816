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

/// One step of a long call's progress, on a thread without the GIL: takes it to run Python's signal handlers
/// (Ctrl-C) and `progress(done, total)`, and answers `Break` (keeping the exception in `raised`) when either raised.
pub fn progress_step<T: for<'py> pyo3::IntoPyObject<'py> + Copy>(
    progress: &Option<pyo3::Py<pyo3::PyAny>>,
    raised: &mut Option<PyErr>,
    done: T,
    total: T,
) -> std::ops::ControlFlow<()> {
    let answer = pyo3::Python::attach(|py| -> pyo3::PyResult<()> {
        py.check_signals()?;
        if let Some(callback) = progress {
            callback.call1(py, (done, total))?;
        }
        Ok(())
    });
    match answer {
        Ok(()) => std::ops::ControlFlow::Continue(()),
        Err(error) => {
            *raised = Some(error);
            std::ops::ControlFlow::Break(())
        }
    }
}
