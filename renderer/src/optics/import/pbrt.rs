//! pbrt `.dat` lens files (stub, being written).
use crate::error::{Error, Result};
use crate::optics::prescription::{Prescription, SourceMap};

/// Imports a pbrt lens table.
pub fn import_pbrt(_text: &str, file: &str, _name: &str) -> Result<(Prescription, SourceMap)> {
    Err(Error::lens_file(file, 0, "file", "pbrt import not yet implemented"))
}
