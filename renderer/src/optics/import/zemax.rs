//! Zemax `.zmx` files (stub, being written).
use crate::error::{Error, Result};
use crate::optics::prescription::{Prescription, SourceMap};

/// Imports a Zemax sequential file.
pub fn import_zemax(_bytes: &[u8], file: &str) -> Result<(Prescription, SourceMap)> {
    Err(Error::lens_file(file, 0, "file", "zemax import not yet implemented"))
}
