//! The VP network: the bundled model, or weights the user gives.

use std::path::Path;

use anyhow::{Context, Result};
use vpcal_net::VpNet;

/// The model shipped with vpcal (see `models/default/MODEL.md`), embedded in the binary.
pub const BUNDLED_MODEL: &[u8] = include_bytes!(concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../models/default/model.safetensors"
));

/// How settings files name the bundled model.
pub const BUNDLED_MODEL_NAME: &str = "bundled:models/default";

/// Load the network at `model` (weights, a checkpoint or a `vpcal train` run folder), or the
/// bundled one, on `device` (`cpu`, or `wgpu` in builds with that feature). Returns the
/// network and how settings files name it.
///
/// # Errors
/// An unknown device, unreadable or incompatible weights.
pub fn load_model(model: Option<&Path>, device: &str) -> Result<(VpNet, String)> {
    let device = vpcal_net::device::select(device)?;
    match model {
        Some(path) => {
            let net = VpNet::load(path, &device)
                .with_context(|| format!("loading the VP network from {}", path.display()))?;
            Ok((net, path.display().to_string()))
        }
        None => {
            let label = Path::new("<bundled models/default/model.safetensors>");
            let net = VpNet::from_bytes(BUNDLED_MODEL, label, &device)
                .context("loading the bundled VP network")?;
            Ok((net, BUNDLED_MODEL_NAME.to_string()))
        }
    }
}
