//! lens-fit: fits a Petzval lens — its prescription parameters, or a correction of its LRTF
//! table — to photographs of point light sources, so renders match real footage.
//!
//! Data flows one way: capture manifest ([`Manifest`]) → captures → forward model (exact
//! trace through [`petzval_optics::Lens`]) → fit → lens file. The crate depends on
//! `petzval-optics` only: it knows no scene, camera or renderer.
//!
//! Status: the manifest, the parameter names and the forward model are here; the optimiser
//! and the report are not yet (`petzval-fit MANIFEST --check` validates a manifest).

// `!(x > 0.0)` is our NaN-rejecting validation: unlike `x <= 0.0` it is also true for NaN, which
// is exactly what every such check wants (a NaN setting or sample must be refused).
#![allow(clippy::neg_cmp_op_on_partial_ord)]

mod error;
pub mod forward;
pub mod manifest;
pub mod params;

pub use error::{Error, Result};
pub use manifest::{Capture, FreeParam, Manifest, SensorSpec};
pub use params::{CameraParams, Model, Param};
