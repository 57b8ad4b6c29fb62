//! Small file helpers: atomic writes.

use std::path::Path;

use crate::NetError;

/// Write `bytes` to `path` atomically ([`vpcal_formats::fs::replace_bytes`]).
///
/// # Errors
/// [`NetError::Io`] naming the file.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), NetError> {
    vpcal_formats::fs::replace_bytes(path, bytes).map_err(|e| NetError::io(path, e))
}
