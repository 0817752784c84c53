//! The embedded lens library: our TOML files under `renderer/optics/lenses/`, compiled in, each citing
//! its source.

use super::import::load_lens_file;
use super::lens::Lens;
use crate::error::{Error, Result};
use std::path::Path;

/// One embedded lens file.
#[derive(Debug, Clone, Copy)]
pub struct LibraryEntry {
    /// Library name (the file stem).
    pub name: &'static str,
    /// The TOML text.
    pub toml: &'static str,
}

macro_rules! lenses {
    ($($name:literal),* $(,)?) => {
        &[$(LibraryEntry { name: $name, toml: include_str!(concat!("../lenses/", $name, ".toml")) }),*]
    };
}

/// Every library lens, sorted by name.
pub const LIBRARY: &[LibraryEntry] = lenses![
    "angenieux-double-gauss-100mm",
    "aspheric-fisheye-10mm",
    "biconvex-singlet-50mm",
    "cooke-speed-panchro-25mm",
    "double-gauss-50mm",
    "fisheye-10mm",
    "kodak-petzval-100mm",
    "nikon-normal-52mm",
    "petzval-portrait-100mm",
    "schneider-anamorphic-31mm",
    "telephoto-250mm",
    "wide-22mm",
    "zeiss-biotar-100mm",
];

/// Loads a library lens by name.
pub fn library_lens(name: &str) -> Result<Lens> {
    let e = LIBRARY.iter().find(|e| e.name == name).ok_or_else(|| Error::UnknownLens(name.to_string()))?;
    Lens::from_toml(e.toml, &format!("library:{}", e.name), None)
}

/// Loads a lens by library name, or else as a file path of any supported format.
pub fn load_lens(name_or_path: &str) -> Result<Lens> {
    if LIBRARY.iter().any(|e| e.name == name_or_path) {
        return library_lens(name_or_path);
    }
    let path = Path::new(name_or_path);
    let file_part = name_or_path.rsplit_once('#').map(|(f, _)| f).unwrap_or(name_or_path);
    if Path::new(file_part).exists() {
        return load_lens_file(path);
    }
    Err(Error::UnknownLens(name_or_path.to_string()))
}
