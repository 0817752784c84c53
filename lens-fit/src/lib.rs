//! lens-fit: fits a Petzval lens — its prescription parameters, or a correction of its LRTF
//! table — to photographs of point light sources, so renders match real footage.
//!
//! Data flows one way: capture manifest ([`Manifest`]) → captures → forward model (exact
//! trace through [`petzval_optics::Lens`]) → fit → lens file. The crate depends on
//! `petzval-optics` only: it knows no scene, camera or renderer.
//!
//! Stages: [`manifest`] (parse, validate) → [`captures`] (load, mask) → [`forward`] (exact
//! trace of a fixed pupil pattern onto the sensor) → [`fit`] (the residuals) → [`solve`]
//! (NLopt CRS2, BOBYQA, Levenberg–Marquardt, uncertainties) → [`staged`] (which stages)
//! → [`report`] (lens file, fit.json,
//! images).
//! [`correction`] is the LRTF correction mode: a smooth, rotationally symmetric correction of
//! the outgoing rays, fitted like any parameter and baked into a corrected table.

// `!(x > 0.0)` is our NaN-rejecting validation: unlike `x <= 0.0` it is also true for NaN, which
// is exactly what every such check wants (a NaN setting or sample must be refused).
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod captures;
pub mod correction;
mod error;
pub mod fit;
pub mod forward;
pub mod manifest;
pub mod params;
pub mod report;
pub mod solve;
pub mod staged;
pub mod synth;

pub use error::{Error, Result};
pub use manifest::{Capture, FreeParam, Manifest, SensorSpec};
pub use params::{CameraParams, Model, Param};
