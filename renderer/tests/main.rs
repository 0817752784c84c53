//! Integration tests of the renderer crate (one binary; modules per area).

mod camera;
mod optics;
