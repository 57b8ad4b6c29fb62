//! Errors of the file readers and writers: each names the file, then what is wrong in it.

use std::path::{Path, PathBuf};

/// An error reading or writing a file.
#[derive(Debug, thiserror::Error)]
pub enum FormatError {
    /// The file could not be read or written.
    #[error("{}: {cause}", path.display())]
    Io {
        path: PathBuf,
        /// Printed in the message, not chained (a chain would print it twice).
        cause: std::io::Error,
    },
    /// The file is not valid JSON.
    #[error("{}: invalid JSON at {cause}", path.display())]
    Json {
        path: PathBuf,
        cause: crate::json::ParseError,
    },
    /// A value in the file has the wrong shape.
    #[error("{}: {cause}", path.display())]
    Field {
        path: PathBuf,
        cause: crate::json::AccessError,
    },
    /// The file is readable but its content is not what the format requires.
    #[error("{}: {message}", path.display())]
    Invalid { path: PathBuf, message: String },
}

impl FormatError {
    pub(crate) fn io(path: &Path, source: std::io::Error) -> FormatError {
        FormatError::Io {
            path: path.to_path_buf(),
            cause: source,
        }
    }

    pub(crate) fn field(path: &Path, source: crate::json::AccessError) -> FormatError {
        FormatError::Field {
            path: path.to_path_buf(),
            cause: source,
        }
    }

    pub(crate) fn invalid(path: &Path, message: impl Into<String>) -> FormatError {
        FormatError::Invalid {
            path: path.to_path_buf(),
            message: message.into(),
        }
    }
}
