//! lentil JSON database entries (stub, being written).
use crate::error::{Error, Result};
use crate::optics::prescription::{Prescription, SourceMap};

/// Imports one entry of the lentil database.
pub fn import_lentil(_text: &str, file: &str, _id: &str) -> Result<(Prescription, SourceMap)> {
    Err(Error::lens_file(file, 0, "file", "lentil import not yet implemented"))
}
