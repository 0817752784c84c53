//! Integration tests of the optics crate (one binary; modules per area).

mod aperture;
mod import;
mod lens_errors;
mod lrtf;
mod lrtf_cases;
mod optics;
