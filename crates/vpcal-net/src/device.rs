//! Choosing where the network runs.
//!
//! - `cpu` (or `flex`): burn's pure-Rust `flex` backend, always available; threads come from
//!   rayon (`RAYON_NUM_THREADS`, default: all cores).
//! - `wgpu` (or `gpu`, `wgpu:N` for the N-th discrete GPU): burn's wgpu backend (Vulkan, Metal
//!   or DX12 at run time), only in builds with the `wgpu` cargo feature.

use burn::tensor::Device;

use crate::NetError;

/// Device names this build accepts, for help texts.
pub fn available() -> &'static [&'static str] {
    if cfg!(feature = "wgpu") {
        &["cpu", "wgpu", "wgpu:N"]
    } else {
        &["cpu"]
    }
}

/// The device named `name` (see the module docs).
///
/// # Errors
/// [`NetError::Config`] for an unknown name, or a GPU name in a build without a GPU backend.
pub fn select(name: &str) -> Result<Device, NetError> {
    let name = name.trim().to_ascii_lowercase();
    match name.as_str() {
        "cpu" | "flex" => Ok(Device::flex()),
        n if n == "gpu" || n == "wgpu" || n.starts_with("wgpu:") => gpu(n),
        other => Err(NetError::Config(format!(
            "unknown device {other:?} (this build knows {:?})",
            available()
        ))),
    }
}

#[cfg(feature = "wgpu")]
fn gpu(name: &str) -> Result<Device, NetError> {
    use burn::tensor::DeviceKind;
    let kind = match name.strip_prefix("wgpu:") {
        Some(i) => DeviceKind::DiscreteGpu(
            i.parse()
                .map_err(|_| NetError::Config(format!("bad GPU index in device {name:?}")))?,
        ),
        None => DeviceKind::DefaultDevice,
    };
    Ok(Device::wgpu(kind))
}

#[cfg(not(feature = "wgpu"))]
fn gpu(name: &str) -> Result<Device, NetError> {
    Err(NetError::Config(format!(
        "device {name:?} needs a GPU backend: rebuild with `--features vpcal-net/wgpu`"
    )))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names() {
        assert!(select("cpu").is_ok());
        assert!(select("FLEX").is_ok());
        let err = select("tpu").unwrap_err().to_string();
        assert!(err.contains("\"tpu\""), "{err}");
        #[cfg(not(feature = "wgpu"))]
        assert!(select("wgpu")
            .unwrap_err()
            .to_string()
            .contains("--features"));
    }
}
