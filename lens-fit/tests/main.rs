//! Integration tests of lens-fit (one binary; modules per area).

mod correction;
mod manifest;
mod recovery;
mod robustness;
