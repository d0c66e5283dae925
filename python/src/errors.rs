//! Errors as Python exceptions: the command line's sentence raised as the matching
//! built-in exception, and panics caught before they can unwind into Python.

use pyo3::exceptions::{PyFileExistsError, PyFileNotFoundError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use verisplat::gpu::GpuError;

/// An error as a Python exception: a missing file is `FileNotFoundError`, an output that
/// exists (without `overwrite`) `FileExistsError`, a device
/// failure `RuntimeError`, anything else (bad input) `ValueError`; the message is the
/// command line's sentence.
pub(crate) fn py_err(e: anyhow::Error) -> PyErr {
    let sentence = verisplat::core::console::error_sentence(&e);
    for cause in e.chain() {
        if let Some(io) = cause.downcast_ref::<std::io::Error>() {
            if io.kind() == std::io::ErrorKind::NotFound {
                return PyFileNotFoundError::new_err(sentence);
            }
        }
        if let Some(verisplat::io::output::OutputError::Exists(_)) = cause.downcast_ref() {
            return PyFileExistsError::new_err(sentence);
        }
        if let Some(verisplat::core::fsutil::WriteError::Exists(_)) = cause.downcast_ref() {
            return PyFileExistsError::new_err(sentence);
        }
        if cause.downcast_ref::<GpuError>().is_some() {
            return PyRuntimeError::new_err(sentence);
        }
    }
    PyValueError::new_err(sentence)
}

pub(crate) fn value_err(message: impl Into<String>) -> PyErr {
    PyValueError::new_err(message.into())
}

/// Runs `f`, turning a panic into `RuntimeError` so none unwinds into Python.
pub(crate) fn guarded<T>(f: impl FnOnce() -> PyResult<T>) -> PyResult<T> {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)) {
        Ok(result) => result,
        Err(payload) => {
            let what = payload
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".into());
            Err(PyRuntimeError::new_err(format!(
                "internal error in verisplat (please report it): {what}"
            )))
        }
    }
}
