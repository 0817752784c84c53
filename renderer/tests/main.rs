//! Integration tests of the renderer crate.
