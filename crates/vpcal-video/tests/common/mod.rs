//! Helpers shared by the integration tests of vpcal-video.
#![allow(dead_code)]

use std::path::PathBuf;

/// The real data (`$VPCAL_DATA`, default `../shared/data` beside the checkout), or `None`
/// with a SKIP message when it is absent.
pub fn data_dir() -> Option<PathBuf> {
    let dir = std::env::var_os("VPCAL_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data"))
        });
    if dir.is_dir() {
        Some(dir)
    } else {
        eprintln!("SKIP: no data at {}", dir.display());
        None
    }
}
