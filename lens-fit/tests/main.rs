//! Integration tests of lens-fit (one binary; modules per area).

mod captures;
mod correction;
mod determinism;
mod manifest;
mod recovery;
mod robustness;
