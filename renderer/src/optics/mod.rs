//! Lens optics: glass, prescriptions and importers, surfaces, exact tracing, apertures,
//! paraxial analysis, exit-pupil bounds and the embedded lens library.

pub mod aperture;
pub mod glass;
pub mod import;
pub mod info;
pub mod lens;
pub mod library;
pub mod paraxial;
pub mod prescription;
pub mod pupil;
pub mod surface;
pub mod draw;
pub mod lrtf;
pub mod lrtf_scene;
