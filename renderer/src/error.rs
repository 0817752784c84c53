//! The renderer crate's one error type.

use std::path::PathBuf;

/// Every error the renderer crate reports. Messages name the file, line and field where the
/// input came from, so a user can fix the input without reading code.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// An error of the lens optics (a lens file, glass, aperture image, focusing request).
    #[error(transparent)]
    Optics(petzval_optics::Error),
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// An invalid camera or sensor setting (focal length, tilt, sensor size, focus...).
    #[error("camera: {field}: {message}")]
    Camera {
        /// The setting, e.g. `tilt_x_deg`.
        field: String,
        /// What is wrong.
        message: String,
    },
    /// An invalid render setting (resolution, samples, threads, tolerance, output options...).
    #[error("{field}: {message}")]
    Settings {
        /// The setting as the user names it, e.g. `--spp` or `resolution`.
        field: String,
        /// What is wrong.
        message: String,
    },
    /// A scene file (glTF, environment EXR) that cannot be loaded.
    #[error("{file}: {}{message}", location_prefix(.location))]
    Scene {
        /// The file.
        file: String,
        /// Where in the file, e.g. `mesh 2 'Cube', primitive 0` (empty for the whole file).
        location: String,
        /// What is wrong.
        message: String,
    },
    /// Images that cannot be compared (different sizes, a black or non-finite reference).
    #[error("image comparison: {0}")]
    Metrics(String),
    /// A fault inside the renderer (a poisoned lock after a panicked worker); not the input's fault.
    #[error("internal error: {0}")]
    Internal(String),
}

fn location_prefix(location: &str) -> String {
    if location.is_empty() {
        String::new()
    } else {
        format!("{location}: ")
    }
}

/// Optics errors convert as they are, except file-system errors, which stay [`Error::Io`] so
/// every front end sees one kind for "file not found" whichever crate read the file.
impl From<petzval_optics::Error> for Error {
    fn from(e: petzval_optics::Error) -> Self {
        match e {
            petzval_optics::Error::Io { path, source } => Error::Io { path, source },
            other => Error::Optics(other),
        }
    }
}

/// Shorthand result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// Builds an [`Error::Scene`].
    pub fn scene(file: impl Into<String>, location: impl Into<String>, message: impl Into<String>) -> Self {
        Error::Scene { file: file.into(), location: location.into(), message: message.into() }
    }

    /// Builds an [`Error::Io`].
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io { path: path.into(), source }
    }

    /// Builds an [`Error::Settings`].
    pub fn settings(field: impl Into<String>, message: impl Into<String>) -> Self {
        Error::Settings { field: field.into(), message: message.into() }
    }

    /// Builds an [`Error::Camera`].
    pub fn camera(field: impl Into<String>, message: impl Into<String>) -> Self {
        Error::Camera { field: field.into(), message: message.into() }
    }
}
