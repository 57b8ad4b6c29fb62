//! The crate's error type.

use std::path::{Path, PathBuf};

/// Errors from rendering and from reading or writing synthetic data sets.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    #[error("cannot access {path}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot read or write the image {path}")]
    Image {
        path: PathBuf,
        #[source]
        source: image::ImageError,
    },
    /// A file exists but its content is not what the format says.
    #[error("{path}: {message}")]
    Format { path: PathBuf, message: String },
    /// Invalid parameters (which one, what was given, what is allowed).
    #[error("invalid configuration: {0}")]
    Config(String),
    /// The `ffmpeg` subprocess failed.
    #[error("ffmpeg writing {path}: {message}")]
    Ffmpeg { path: PathBuf, message: String },
    /// The generator could not place a vehicle after many attempts (should not happen with
    /// sane parameters).
    #[error("could not generate {what} after {attempts} attempts")]
    Exhausted { what: String, attempts: usize },
}

impl SynthError {
    /// The message with its chain of causes, for places that keep only a string.
    pub fn full_message(&self) -> String {
        let mut out = self.to_string();
        let mut cur: Option<&(dyn std::error::Error + 'static)> = std::error::Error::source(self);
        while let Some(e) = cur {
            out.push_str(": ");
            out.push_str(&e.to_string());
            cur = e.source();
        }
        out
    }

    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> SynthError {
        SynthError::Io {
            path: path.into(),
            source,
        }
    }
}

/// Write `bytes` to `path` atomically ([`vpcal_formats::fs::replace_bytes`]), naming `path` on
/// failure.
pub(crate) fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), SynthError> {
    vpcal_formats::fs::replace_bytes(path, bytes).map_err(|e| SynthError::io(path, e))
}
