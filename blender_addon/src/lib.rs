//! `petzval._native`: Petzval's Python module (pyo3) — lenses, scenes built from numpy buffers,
//! and rendering with a progress callback. The only crate that depends on pyo3 and the only
//! place where the renderer's errors become Python exceptions. No Rust panic crosses into
//! Python: every entry point runs under [`guard`], which turns a panic into `PetzvalError`.
//!
//! The API, its conventions (glTF axes, top-row-first images, glTF UVs) and the meaning of
//! every argument are documented in `python/petzval/_native.pyi`.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `render(scene, camera, width, height)` | a `Scene`, a `Camera` (see `camera.rs`), pixels | px | — |
//! | `render(..., crop)` | optional (x0, y0, x1, y1), row 0 at the top | px | None |
//! | `render(..., spp, seed, max_depth)` | u32 | — | 64, 0, 8 |
//! | `render(..., filter_width_px)` | f32, Cycles' filter_width | px | 1.5 |
//! | `render(..., spectral)` | bool | — | false |
//! | `render(..., threads)` | 0 = every core | — | 0 |
//! | `render(..., progress_interval_s)` | f64 | s | 0.1 |

// `!(x > 0.0)` is our NaN-rejecting validation: unlike `x <= 0.0` it is also true for NaN, which
// is exactly what every such check wants (a NaN setting or sample must be refused).
#![allow(clippy::neg_cmp_op_on_partial_ord)]

mod camera;
mod errors;
mod lens;
mod render;
mod scene;

use errors::*;
use lens::{library_lenses, PyLens};

use pyo3::prelude::*;
use scene::PyScene;

/// The module.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("PetzvalError", py.get_type::<PetzvalError>())?;
    m.add("InvalidLensError", py.get_type::<InvalidLensError>())?;
    m.add("InvalidSceneError", py.get_type::<InvalidSceneError>())?;
    m.add("InvalidSettingsError", py.get_type::<InvalidSettingsError>())?;
    m.add("CancelledError", py.get_type::<CancelledError>())?;
    m.add_class::<PyLens>()?;
    m.add_class::<camera::PyCamera>()?;
    m.add_class::<PyScene>()?;
    m.add_function(wrap_pyfunction!(library_lenses, m)?)?;
    m.add_function(wrap_pyfunction!(render::render, m)?)?;
    Ok(())
}
