//! The one error type of the renderer. Every variant a user can trigger names the file it came
//! from and the field, element or line that was wrong, so a message alone is enough to fix it.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A value in a scene (or a file it references) is missing, malformed or out of range.
    #[error("{file}: {field}: {message}")]
    Scene { file: PathBuf, field: String, message: String },
    /// A file could not be read or written.
    #[error("{file}: {source}")]
    Io {
        file: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// An image could not be decoded or encoded.
    #[error("{file}: {message}")]
    Image { file: PathBuf, message: String },
    /// A request that makes no sense regardless of files (e.g. zero samples per pixel).
    #[error("{0}")]
    Invalid(String),
}

pub type Result<T> = std::result::Result<T, Error>;

/// Frame files fail with the variant of the same name, so `?` keeps the message and the kind.
impl From<film::Error> for Error {
    fn from(e: film::Error) -> Self {
        match e {
            film::Error::Io { file, source } => Error::Io { file, source },
            film::Error::Image { file, message } => Error::Image { file, message },
            film::Error::Invalid(m) => Error::Invalid(m),
        }
    }
}

impl Error {
    pub fn scene(file: impl Into<PathBuf>, field: impl Into<String>, message: impl Into<String>) -> Self {
        Error::Scene { file: file.into(), field: field.into(), message: message.into() }
    }
    pub fn io(file: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io { file: file.into(), source }
    }
    pub fn image(file: impl Into<PathBuf>, message: impl ToString) -> Self {
        Error::Image { file: file.into(), message: message.to_string() }
    }
}
