//! The fitting crate's one error type.

use std::path::PathBuf;

/// Every error lens-fit reports; messages name the file, the capture and the field.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The capture manifest is malformed or contradicts itself.
    #[error("{file}: {field}: {message}")]
    Manifest {
        /// The manifest file.
        file: String,
        /// Where: `capture[3].f_number`, `free[1].param`, `sensor.pixels`…
        field: String,
        /// What is wrong.
        message: String,
    },
    /// A capture image (or its dark frame or mask) that cannot be used.
    #[error("{path}: {message}")]
    Image {
        /// The image file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// An error of the lens optics (the start lens, a parameter the lens cannot take).
    #[error(transparent)]
    Optics(#[from] petzval_optics::Error),
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
}

/// Shorthand result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// Builds an [`Error::Manifest`].
    pub fn manifest(file: impl Into<String>, field: impl Into<String>, message: impl Into<String>) -> Self {
        Error::Manifest { file: file.into(), field: field.into(), message: message.into() }
    }
}
