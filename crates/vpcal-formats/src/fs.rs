//! File helpers: atomic writes and JSON reading with the file named in errors.

use crate::error::FormatError;
use crate::json::{self, Json};
use std::io::Write;
use std::path::{Path, PathBuf};

/// The hidden temporary sibling of `path` that the atomic writers fill (same folder, so the
/// final rename is atomic): `dir/.name.tmp-PID`.
fn temp_sibling(path: &Path) -> std::io::Result<PathBuf> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let name = path
        .file_name()
        .ok_or_else(|| std::io::Error::new(std::io::ErrorKind::InvalidInput, "not a file path"))?;
    Ok(dir.join(format!(
        ".{}.tmp-{}",
        name.to_string_lossy(),
        std::process::id()
    )))
}

/// Create or replace `path` atomically: `write` fills a temporary file next to it, which is
/// renamed over `path` only when `write` succeeds; otherwise it is removed, so a failure leaves
/// neither a partial file nor a stale temporary behind. The one atomic writer of the project;
/// the other crates wrap it with their error types.
///
/// # Errors
/// The error of `write` or of the rename (the caller names `path`).
pub fn replace_with(
    path: &Path,
    write: impl FnOnce(&Path) -> std::io::Result<()>,
) -> std::io::Result<()> {
    let tmp = temp_sibling(path)?;
    let result = write(&tmp).and_then(|()| std::fs::rename(&tmp, path));
    if result.is_err() {
        // Why ignored: the temporary may not exist; the original error is what matters.
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// [`replace_with`] for a byte buffer, flushed to disk before the rename.
///
/// # Errors
/// I/O errors of the write or the rename.
pub fn replace_bytes(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    replace_with(path, |tmp| {
        let mut f = std::fs::File::create(tmp)?;
        f.write_all(bytes)?;
        f.sync_all()
    })
}

/// Write `bytes` to `path` atomically ([`replace_bytes`]). A failure leaves no partial file
/// behind.
///
/// # Errors
/// [`FormatError::Io`] naming `path`.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), FormatError> {
    replace_bytes(path, bytes).map_err(|e| FormatError::io(path, e))
}

/// Read and parse a JSON file (Python's `Infinity`/`NaN` accepted).
///
/// # Errors
/// [`FormatError::Io`] or [`FormatError::Json`] naming `path`.
pub fn read_json(path: &Path) -> Result<Json, FormatError> {
    let text = std::fs::read_to_string(path).map_err(|e| FormatError::io(path, e))?;
    json::parse(&text).map_err(|cause| FormatError::Json {
        path: path.to_path_buf(),
        cause,
    })
}

/// Serialise `value` as strict JSON (non-finite numbers as `null`) and write it atomically.
///
/// # Errors
/// [`FormatError::Io`] naming `path`.
pub fn write_json(path: &Path, value: &Json) -> Result<(), FormatError> {
    let mut text = value.to_strict_string();
    text.push('\n');
    write_atomic(path, text.as_bytes())
}

/// Encode an RGB image as PNG bytes (the one PNG encoder of the workspace).
///
/// # Errors
/// The encoder's error, as a message.
pub fn encode_png(image: &image::RgbImage) -> Result<Vec<u8>, String> {
    let mut bytes = Vec::new();
    image
        .write_to(
            &mut std::io::Cursor::new(&mut bytes),
            image::ImageFormat::Png,
        )
        .map_err(|e| format!("cannot encode PNG ({e})"))?;
    Ok(bytes)
}

/// Write `image` as a PNG file atomically.
///
/// # Errors
/// [`FormatError`] naming the file.
pub fn write_png(path: &Path, image: &image::RgbImage) -> Result<(), FormatError> {
    let bytes = encode_png(image).map_err(|m| FormatError::invalid(path, m))?;
    write_atomic(path, &bytes)
}
