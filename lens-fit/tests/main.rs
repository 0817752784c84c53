//! Integration tests of lens-fit (one binary; modules per area).

mod correction;
mod determinism;
mod manifest;
mod recovery;
mod robustness;
