//! Importers from other lens formats into our [`Prescription`]: pbrt `.dat`, Zemax `.zmx` and
//! the lentil JSON database. Each returns the prescription and a [`SourceMap`] whose lines point
//! into the original file, so validation errors name the right line.

use super::lens::Lens;
use super::prescription::{self, Prescription, SourceMap};
use crate::error::{Error, Result};
use std::path::Path;

mod lentil;
mod pbrt;
mod zemax;

pub use lentil::import_lentil;
pub use pbrt::{import_pbrt, import_pbrt_axpos};
pub use zemax::import_zemax;

/// Reads a lens file of any supported format, chosen by extension: `.toml` (ours), `.dat`
/// (pbrt), `.zmx` (Zemax, ASCII or UTF-16). A lentil database entry is `FILE.json#ID`.
pub fn load_lens_file(path: &Path) -> Result<Lens> {
    let (p, map) = read_prescription(path)?;
    Lens::new(p, &map, path.parent())
}

/// Reads a lens file of any supported format into a prescription (see [`load_lens_file`]).
pub fn read_prescription(path: &Path) -> Result<(Prescription, SourceMap)> {
    let s = path.to_string_lossy();
    if let Some((file, id)) = s.rsplit_once('#') {
        if file.ends_with(".json") {
            let text = std::fs::read_to_string(file).map_err(|e| Error::io(file, e))?;
            return import_lentil(&text, file, id);
        }
    }
    let file = path.display().to_string();
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    match ext.as_str() {
        "toml" => {
            let text = String::from_utf8(bytes).map_err(|_| Error::lens_file(&file, 0, "file", "not UTF-8 text"))?;
            prescription::parse_toml(&text, &file)
        }
        "dat" => {
            let text = String::from_utf8_lossy(&bytes).into_owned();
            let name = path.file_stem().and_then(|s| s.to_str()).unwrap_or("lens").to_string();
            import_pbrt(&text, &file, &name)
        }
        "zmx" => import_zemax(&bytes, &file),
        _ => Err(Error::lens_file(
            &file,
            0,
            "file",
            "unknown lens format: expected .toml, .dat (pbrt), .zmx (Zemax) or FILE.json#ID (lentil)",
        )),
    }
}
