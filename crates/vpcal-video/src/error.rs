//! The error type of this crate.

use std::path::PathBuf;

/// Everything that can go wrong while reading frames, detecting vehicles or cropping them.
///
/// Messages name the offending value first and the file last, so that a one-line report
/// (`error: {err}`) says what was wrong and where.
#[derive(Debug, thiserror::Error)]
pub enum VideoError {
    /// The `ffmpeg` or `ffprobe` executable could not be started.
    #[error(
        "cannot run `{}`: {reason}; vpcal decodes video with FFmpeg: install it \
         (Debian/Ubuntu: `sudo apt-get install ffmpeg`, macOS: `brew install ffmpeg`) \
         or set {env_var} to the program's path",
        program.display()
    )]
    FfmpegMissing {
        program: PathBuf,
        env_var: &'static str,
        reason: String,
    },

    /// A file or folder could not be opened or read.
    #[error("{action}: {cause}: {}", path.display())]
    Io {
        action: &'static str,
        path: PathBuf,
        /// Printed in the message, not chained (a chain would print it twice).
        cause: std::io::Error,
    },

    /// The file is not something FFmpeg can read as video.
    #[error("not a readable video ({message}): {}", path.display())]
    NotVideo { path: PathBuf, message: String },

    /// The input holds no frame at all (0-byte file, zero-length video, empty folder, or a start
    /// position past the end).
    #[error("no frames: {reason}: {}", path.display())]
    Empty { path: PathBuf, reason: String },

    /// FFmpeg failed or reported damaged data while decoding.
    #[error(
        "video decoding failed after {frames_read} frames ({status}): {message}: {}",
        path.display()
    )]
    Decode {
        path: PathBuf,
        frames_read: u64,
        status: String,
        message: String,
    },

    /// An image (frame, mask) could not be decoded or has the wrong size.
    #[error("{message}: {}", path.display())]
    Image { path: PathBuf, message: String },

    /// A detections file is malformed.
    #[error("{location}: {message}: {}", path.display())]
    DetectionFile {
        path: PathBuf,
        /// Where in the file, e.g. `line 12` or `item 3`.
        location: String,
        message: String,
    },

    /// An option has a value outside its domain.
    #[error("invalid {name} {value:?}: expected {expected}")]
    InvalidOption {
        name: &'static str,
        value: String,
        expected: &'static str,
    },

    /// The learned detector's model file is unusable or inference failed.
    #[error("{message}: {}", path.display())]
    Model { path: PathBuf, message: String },
}

impl VideoError {
    pub(crate) fn io(
        action: &'static str,
        path: impl Into<PathBuf>,
        source: std::io::Error,
    ) -> Self {
        VideoError::Io {
            action,
            path: path.into(),
            cause: source,
        }
    }
}

/// Result alias of this crate.
pub type Result<T, E = VideoError> = std::result::Result<T, E>;
