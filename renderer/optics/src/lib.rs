//! Petzval's lens optics: glass, prescriptions and importers, surfaces, exact sequential
//! tracing (f64), apertures, paraxial analysis, exit-pupil bounds, the embedded lens library and
//! lens ray transfer function (LRTF) tables. It knows no scene: the renderer and lens-fit build on
//! it, never the other way round.
//!
//! Data flows one way: lens file → [`Prescription`] → [`Lens`] → (traced rays, [`lrtf`] tables).

// `!(x > 0.0)` is our NaN-rejecting validation: unlike `x <= 0.0` it is also true for NaN, which
// is exactly what every such check wants (a NaN setting or sample must be refused).
#![allow(clippy::neg_cmp_op_on_partial_ord)]

mod error;
mod io;

pub mod aperture;
pub mod draw;
pub mod glass;
pub mod import;
pub mod info;
pub mod lens;
pub mod library;
pub mod lrtf;
pub mod lrtf_scene;
pub mod paraxial;
pub mod prescription;
pub mod pupil;
pub mod surface;

pub use aperture::{Aperture, ApertureMask, ApertureShape, PreparedAperture};
pub use error::{Error, Result};
pub use glass::Material;
pub use import::{load_lens_file, read_prescription};
pub use io::{read_input_file, write_atomic, MAX_LENS_FILE_BYTES};
pub use lens::{Absorbed, Lens, LensSurface, Ray, StopMode, TraceDirection, Traced};
pub use library::{library_lens, load_lens, LIBRARY};
pub use paraxial::ParaxialData;
pub use prescription::Prescription;
