//! Integration tests of the renderer crate (one binary; modules per area).

mod architecture;
mod auto_model;
mod camera;
mod common;
mod dof;
mod fuzz;
mod gltf;
mod ibrt;
mod instances;
mod integrator;
mod render;
