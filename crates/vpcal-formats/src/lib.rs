//! File formats for vpcal. Every reader names the file (and the item and field) in its errors;
//! every writer writes atomically (temporary file, then rename).
//!
//! - [`calib`]: vpcal's calibration file (`calib.json`), typed and versioned.
//! - [`json`]: JSON with Python's `Infinity`/`NaN` tokens (read; vpcal writes strict JSON).
//! - [`pickle`]: a safe Python-pickle reader (no code execution; numpy arrays and scalars): the
//!   values, the stack machine, the node-graph converter, the decoders and the accessors.
//! - [`bcs`]: BrnoCompSpeed ground truth (`gt_data.pkl` / `gt_data.json`) and system files.
//! - [`bcs_speed`]: the official BrnoCompSpeed speed evaluation (eval.py's protocol).
//! - [`bcp`]: BrnoCarPark ground truth (`gt_pairs.json`).
//! - [`reference`]: the reference implementation's `VPout_*.json` and `detections.json`.
//! - [`fs`]: atomic writes and JSON file helpers.

pub mod bcp;
pub mod bcs;
pub mod bcs_speed;
pub mod calib;
mod error;
pub mod fs;
pub mod json;
pub mod pickle;
pub mod pickle_json;
pub mod reference;

pub use error::FormatError;
