//! Petzval core library: lens optics (prescriptions, exact tracing, paraxial analysis, apertures),
//! cameras and sensors. Data flows one way: lens file → [`Lens`] → [`Camera`]; [`shot`] joins a
//! camera spec with the scene (depth probe, autofocus), above both the camera and the integrator.

// `!(x > 0.0)` is our NaN-rejecting validation: unlike `x <= 0.0` it is also true for NaN, which
// is exactly what every such check wants (a NaN setting or sample must be refused).
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod bokeh;
pub mod dof;
mod error;
pub mod film;
#[doc(hidden)]
pub mod fuzzing;
pub mod integrator;
pub mod limits;
pub mod render;
pub mod sampler;
pub mod scene;
pub mod shot;
pub mod spectral;

pub use error::{Error, Result};
pub use optics::aperture::{Aperture, ApertureMask, ApertureShape};
pub use optics::glass::Material;
pub use optics::import::{load_lens_file, read_prescription};
pub use optics::lens::{Absorbed, Lens, LensSurface, Ray, StopMode, TraceDirection, Traced};
pub use optics::library::{library_lens, load_lens, LIBRARY};
pub use optics::paraxial::ParaxialData;
pub use optics::prescription::Prescription;
/// The lens optics crate, re-exported (`petzval_renderer::optics::…`).
pub use petzval_optics as optics;
pub use petzval_optics::write_atomic;
pub mod camera;
pub use camera::{
    BuiltCamera, Camera, CameraRay, CameraSpec, ExactCamera, FocusPlane, LensModel, LrtfCamera, ModelChoice,
    OrthographicCamera, PinholeCamera, Sensor, ShotContext, ThickCamera, ThinCamera,
};
pub use integrator::{PathSample, PathTracer, RenderScene, SurfaceHit};
