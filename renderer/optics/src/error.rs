//! The optics crate's one error type.

use std::path::PathBuf;

/// Every error the optics crate reports. Messages name the file, line and field where the
/// input came from, so a user can fix the input without reading code.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A lens file (our TOML, pbrt `.dat`, Zemax `.zmx`, lentil JSON) is malformed or invalid.
    #[error("{file}{}: {field}: {message}", line_suffix(*line))]
    LensFile {
        /// File name (or `library:NAME` for embedded lenses).
        file: String,
        /// 1-based line number (0 when the problem is not tied to one line).
        line: usize,
        /// The offending field, e.g. `surface[3].radius_mm`.
        field: String,
        /// What is wrong.
        message: String,
    },
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// A lens name that is neither in the library nor an existing file.
    #[error("unknown lens '{0}': not in the library (see `petzval lens list`) and no such file")]
    UnknownLens(String),
    /// An unknown glass name.
    #[error("unknown glass '{name}'{suggestion}")]
    UnknownGlass {
        /// The name as written.
        name: String,
        /// ", did you mean ...?" or empty.
        suggestion: String,
    },
    /// A request the optics cannot satisfy (focus closer than possible, f-number out of range...).
    #[error("{0}")]
    Optics(String),
    /// An aperture image that cannot be used.
    #[error("aperture image {path}: {message}")]
    ApertureImage {
        /// The image file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

/// Shorthand result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// Builds a [`Error::LensFile`].
    pub fn lens_file(
        file: impl Into<String>,
        line: usize,
        field: impl Into<String>,
        message: impl Into<String>,
    ) -> Self {
        Error::LensFile { file: file.into(), line, field: field.into(), message: message.into() }
    }

    /// Builds an [`Error::Io`].
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io { path: path.into(), source }
    }
}

/// `:N` for a 1-based line number, nothing for 0 (a problem of the whole file).
fn line_suffix(line: usize) -> String {
    if line == 0 {
        String::new()
    } else {
        format!(":{line}")
    }
}
