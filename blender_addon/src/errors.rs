//! Python exceptions and the guard that keeps Rust panics out of Python: the only place where
//! the renderer's errors become Python exceptions.

use petzval_renderer::Error;
use pyo3::exceptions::{PyException, PyFileNotFoundError, PyOSError};
use pyo3::prelude::*;
use std::panic::{catch_unwind, AssertUnwindSafe};

pyo3::create_exception!(_native, PetzvalError, PyException, "Base class of every Petzval error.");
pyo3::create_exception!(_native, InvalidLensError, PetzvalError, "A lens file or lens name is invalid.");
pyo3::create_exception!(_native, InvalidSceneError, PetzvalError, "Scene data is invalid.");
pyo3::create_exception!(_native, InvalidSettingsError, PetzvalError, "Camera or render settings are invalid.");
pyo3::create_exception!(_native, CancelledError, PetzvalError, "The render was cancelled before a pass finished.");

/// Maps the renderer's errors to Python exceptions.
pub(crate) fn py_err(e: impl Into<Error>) -> PyErr {
    use petzval_renderer::optics::Error as OpticsError;
    let e = e.into();
    let msg = e.to_string();
    match e {
        Error::Io { source, .. } if source.kind() == std::io::ErrorKind::NotFound => PyFileNotFoundError::new_err(msg),
        Error::Io { .. } => PyOSError::new_err(msg),
        Error::Optics(OpticsError::UnknownLens(_)) => PyFileNotFoundError::new_err(msg),
        Error::Optics(OpticsError::Io { source, .. }) if source.kind() == std::io::ErrorKind::NotFound => {
            PyFileNotFoundError::new_err(msg)
        }
        Error::Optics(OpticsError::Io { .. }) => PyOSError::new_err(msg),
        Error::Optics(OpticsError::ApertureImage { .. }) => InvalidSettingsError::new_err(msg),
        Error::Optics(_) => InvalidLensError::new_err(msg),
        Error::Camera { .. } | Error::Settings { .. } => InvalidSettingsError::new_err(msg),
        Error::Scene { .. } => InvalidSceneError::new_err(msg),
        Error::Metrics(_) | Error::Internal(_) => PetzvalError::new_err(msg),
    }
}

pub(crate) fn panic_message(p: Box<dyn std::any::Any + Send>) -> String {
    p.downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| p.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "unknown panic".into())
}

/// Runs `f`, turning a Rust panic into `PetzvalError` (no panic crosses into Python).
pub(crate) fn guard<T>(f: impl FnOnce() -> PyResult<T>) -> PyResult<T> {
    catch_unwind(AssertUnwindSafe(f))
        .unwrap_or_else(|p| Err(PetzvalError::new_err(format!("internal error (please report): {}", panic_message(p)))))
}

pub(crate) fn scene_err(name: &str, field: &str, message: String) -> PyErr {
    InvalidSceneError::new_err(format!(
        "{}{field}: {message}",
        if name.is_empty() { String::new() } else { format!("'{name}': ") }
    ))
}

pub(crate) fn settings_err(field: &str, message: String) -> PyErr {
    InvalidSettingsError::new_err(format!("{field}: {message}"))
}
