//! Petzval core library: lens optics (prescriptions, exact tracing, paraxial analysis, apertures),
//! cameras and sensors. Data flows one way: lens file → [`Lens`] → [`Camera`].

mod error;
pub mod film;
pub mod integrator;
pub mod render;
pub mod sampler;
pub mod scene;
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
    BuiltCamera, Camera, CameraRay, CameraSpec, FocusPlane, LensModel, LrtfCamera, ModelChoice, PinholeCamera,
    RealisticCamera, Sensor, ShotContext, ThickLensCamera, ThinLensCamera,
};
pub use integrator::{PathSample, PathTracer, RenderScene, SurfaceHit};
