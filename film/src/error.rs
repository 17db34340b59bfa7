//! The error type of frame files. Its variants print exactly as the renderer's variants of the
//! same names, which they convert into, so a message reads the same whichever crate reports it.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file could not be read or written.
    #[error("{file}: {source}")]
    Io {
        file: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A file could not be decoded or encoded.
    #[error("{file}: {message}")]
    Image { file: PathBuf, message: String },
    /// A request that makes no sense regardless of files (e.g. merging frames of two sizes).
    #[error("{0}")]
    Invalid(String),
}

pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    pub fn io(file: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io { file: file.into(), source }
    }
    pub fn image(file: impl Into<PathBuf>, message: impl ToString) -> Self {
        Error::Image { file: file.into(), message: message.to_string() }
    }
}
