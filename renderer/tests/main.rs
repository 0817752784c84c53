//! Integration tests of the renderer crate (one binary; modules per area).

mod aperture;
mod auto_model;
mod common;
mod camera;
mod gltf;
mod import;
mod lrtf;
mod lrtf_cases;
mod integrator;
mod optics;
mod render;
