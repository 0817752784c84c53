//! Integration tests of the renderer crate (one binary; modules per area).

mod auto_model;
mod common;
mod camera;
mod gltf;
mod integrator;
mod render;
