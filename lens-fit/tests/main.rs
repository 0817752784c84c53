//! Integration tests of lens-fit (one binary; modules per area).

mod manifest;
mod recovery;
mod robustness;
