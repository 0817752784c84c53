//! Importers from other lens formats into our [`Prescription`]: pbrt `.dat`, Zemax `.zmx` and
//! the lentil JSON database. Each returns the prescription and a [`SourceMap`] whose lines point
//! into the original file, so validation errors name the right line.

use super::lens::Lens;
use super::prescription::{self, Prescription, SourceMap};
use crate::error::{Error, Result};
use crate::io::{read_input_file, MAX_LENS_FILE_BYTES};
use std::path::Path;

mod lentil;
mod pbrt;
mod zemax;

pub use lentil::import_lentil;
pub use pbrt::{import_pbrt, import_pbrt_axpos};
pub use zemax::import_zemax;

/// Decodes the bytes of a text lens file, whatever wrote it: UTF-16 LE/BE (with a byte-order mark
/// or by its zero-byte pattern) or UTF-8 with or without a BOM (lossy, so Latin-1 bytes become
/// U+FFFD rather than an error; TOML's own parser then names the line).
pub(crate) fn decode_text(bytes: &[u8]) -> String {
    let utf16 = |b: &[u8], le: bool| -> String {
        let units =
            b.chunks_exact(2)
                .map(|c| if le { u16::from_le_bytes([c[0], c[1]]) } else { u16::from_be_bytes([c[0], c[1]]) });
        char::decode_utf16(units).map(|r| r.unwrap_or(char::REPLACEMENT_CHARACTER)).collect()
    };
    match bytes {
        [0xFF, 0xFE, rest @ ..] => utf16(rest, true),
        [0xFE, 0xFF, rest @ ..] => utf16(rest, false),
        [0xEF, 0xBB, 0xBF, rest @ ..] => String::from_utf8_lossy(rest).into_owned(),
        [a, 0, ..] if *a != 0 => utf16(bytes, true),
        [0, b, ..] if *b != 0 => utf16(bytes, false),
        _ => String::from_utf8_lossy(bytes).into_owned(),
    }
}

/// Reads a lens file of any supported format, chosen by extension: `.toml` (ours), `.dat`
/// (pbrt), `.zmx` (Zemax); each as UTF-8 (with or without a BOM) or UTF-16. A lentil database
/// entry is `FILE.json#ID`.
pub fn load_lens_file(path: &Path) -> Result<Lens> {
    let (p, map) = read_prescription(path)?;
    Lens::new(p, &map, path.parent())
}

/// Reads a lens file of any supported format into a prescription (see [`load_lens_file`]).
/// Only regular files of at most [`MAX_LENS_FILE_BYTES`] are read.
pub fn read_prescription(path: &Path) -> Result<(Prescription, SourceMap)> {
    let read = |p: &Path| read_input_file(p, MAX_LENS_FILE_BYTES, "lens file");
    let s = path.to_string_lossy();
    if let Some((file, id)) = s.rsplit_once('#') {
        if file.ends_with(".json") {
            return read_prescription_bytes(&read(Path::new(file))?, LensFormat::Lentil { id }, file);
        }
    }
    let file = path.display().to_string();
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    let format = match ext.as_str() {
        "toml" => LensFormat::Toml,
        "dat" => LensFormat::Pbrt { name: path.file_stem().and_then(|s| s.to_str()).unwrap_or("lens") },
        "zmx" => LensFormat::Zemax,
        _ => {
            return Err(Error::lens_file(
                &file,
                0,
                "file",
                "unknown lens format: expected .toml, .dat (pbrt), .zmx (Zemax) or FILE.json#ID (lentil)",
            ))
        }
    };
    read_prescription_bytes(&read(path)?, format, &file)
}

/// The format of a lens file's bytes (chosen by extension in [`read_prescription`]).
#[derive(Debug, Clone, Copy)]
pub enum LensFormat<'a> {
    /// Our TOML.
    Toml,
    /// A pbrt `.dat` table; `name` becomes the lens's name (pbrt files have none).
    Pbrt {
        /// The lens's name (the file's stem).
        name: &'a str,
    },
    /// A Zemax `.zmx` file.
    Zemax,
    /// Entry `id` of a lentil JSON database.
    Lentil {
        /// The entry's key, e.g. `"0001"`.
        id: &'a str,
    },
}

/// A lens file's bytes (UTF-8 with or without a BOM, or UTF-16) into a prescription; `file`
/// names it in errors.
pub fn read_prescription_bytes(bytes: &[u8], format: LensFormat, file: &str) -> Result<(Prescription, SourceMap)> {
    match format {
        LensFormat::Toml => prescription::parse_toml(&decode_text(bytes), file),
        LensFormat::Pbrt { name } => import_pbrt(&decode_text(bytes), file, name),
        LensFormat::Zemax => import_zemax(bytes, file),
        LensFormat::Lentil { id } => import_lentil(&decode_text(bytes), file, id),
    }
}
