//! File helpers: atomic writes and JSON reading with the file named in errors.

use crate::error::FormatError;
use crate::json::{self, Json};
use std::io::Write;
use std::path::Path;

/// Write `bytes` to `path` atomically: into a temporary file in the same directory, flushed,
/// then renamed over `path`. A failure leaves no partial file behind.
///
/// # Errors
/// [`FormatError::Io`] naming `path`.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), FormatError> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let name = path
        .file_name()
        .ok_or_else(|| FormatError::invalid(path, "not a file path"))?;
    let tmp = dir.join(format!(
        ".{}.tmp-{}",
        name.to_string_lossy(),
        std::process::id()
    ));
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(FormatError::io(path, e));
    }
    Ok(())
}

/// Read and parse a JSON file (Python's `Infinity`/`NaN` accepted).
///
/// # Errors
/// [`FormatError::Io`] or [`FormatError::Json`] naming `path`.
pub fn read_json(path: &Path) -> Result<Json, FormatError> {
    let text = std::fs::read_to_string(path).map_err(|e| FormatError::io(path, e))?;
    json::parse(&text).map_err(|source| FormatError::Json {
        path: path.to_path_buf(),
        source,
    })
}

/// Serialise `value` Python-style and write it atomically.
///
/// # Errors
/// [`FormatError::Io`] naming `path`.
pub fn write_json(path: &Path, value: &Json) -> Result<(), FormatError> {
    let mut text = value.to_python_string();
    text.push('\n');
    write_atomic(path, text.as_bytes())
}
