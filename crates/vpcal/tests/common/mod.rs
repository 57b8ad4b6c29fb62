//! Helpers shared by the `vpcal` binary's integration tests.
#![allow(dead_code, clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Run the `vpcal` binary built for these tests.
pub fn vpcal(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_vpcal"))
        .args(args)
        .output()
        .expect("run vpcal")
}

/// stdout then stderr of a run, for assertion messages.
pub fn text(o: &Output) -> String {
    format!("{}{}", stdout(o), stderr(o))
}

pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// `sub` inside the real data (`VPCAL_DATA`, default `../shared/data` beside the repository),
/// or `None` with a "skipping" message when it is absent.
pub fn real_data(sub: &str) -> Option<PathBuf> {
    let root = std::env::var_os("VPCAL_DATA").map_or_else(
        || Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data"),
        PathBuf::from,
    );
    let dir = root.join(sub);
    if dir.is_dir() {
        Some(dir)
    } else {
        eprintln!("skipping: {} not found (set VPCAL_DATA)", dir.display());
        None
    }
}

/// The last line of a command's standard output, parsed as JSON (`--json` prints one object
/// after any progress lines).
pub fn last_stdout_json(o: &Output) -> serde_json::Value {
    let out = String::from_utf8_lossy(&o.stdout);
    let line = out.lines().last().unwrap_or_default();
    serde_json::from_str(line).unwrap_or_else(|e| panic!("not JSON ({e}): {line}"))
}

pub fn read_json(p: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

/// A calibration file, read with the library's reader (which checks its format).
pub fn read_calibration(p: &Path) -> vpcal_formats::calib::CalibrationFile {
    vpcal_formats::calib::CalibrationFile::read(p).unwrap()
}

/// The VPout file of `video` in the data's `bcs/vp_outputs` whose name contains `part`.
pub fn vpout_file(data: &Path, video: &str, part: &str) -> PathBuf {
    std::fs::read_dir(data.join("bcs/vp_outputs").join(video))
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "json") && p.to_string_lossy().contains(part))
        .unwrap()
}
