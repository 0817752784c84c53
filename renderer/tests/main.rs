//! Integration tests of the renderer crate (one binary; modules per area).

mod aperture;
mod common;
mod camera;
mod gltf;
mod import;
mod lrtf;
mod integrator;
mod optics;
mod render;
