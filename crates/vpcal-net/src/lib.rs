//! vpcal-net: the vanishing-point network of vpcal (DeepVPCalib, Kocur & Ftáčnik, ICANN 2021):
//! a stacked hourglass in [burn] that maps a vehicle crop to diamond-space heatmaps of its two
//! vanishing points. This is the only vpcal crate that names the ML framework.
//!
//! Entry points:
//! - [`ModelConfig`] (presets [`ModelConfig::paper`], [`ModelConfig::small`],
//!   [`ModelConfig::tiny`]) and [`StackedHourglass`], the network of DESIGN.md §5;
//!   [`EncoderNet`] ([`ModelConfig::yolox_nano`], [`ModelConfig::pretrained`]) puts a
//!   pretrained backbone in front of the same heatmap outputs: YOLOX-nano's (COCO,
//!   [`encoder`]), MobileNetV2's or EfficientNet-Lite0's (ImageNet, [`mobile`]);
//!   [`regression`] holds the paper's regression baselines (ResNet-50, hourglass + pooling,
//!   normalised L1/L2 losses).
//! - [`Trainer`] with [`TrainConfig`] and [`LrSchedule`]: Adam, the paper's two-phase schedule,
//!   loss over all stacks, per-epoch validation ([`metrics`]), atomic checkpoints, exact
//!   resume, metrics files and curves ([`report`]).
//! - [`BatchSource`]: where batches come from — [`PipelineSource`] wraps `vpcal_data`'s
//!   augmentation pipeline over any `SampleSource`; [`ToySource`] is a synthetic task for
//!   tests and smoke runs.
//! - [`VpNet`]: inference — load weights (refusing mismatches), predict VPs of crops, batched.
//! - [`store`]: safetensors weights with the config in the metadata; [`device`]: `cpu` or
//!   `wgpu`; [`bench`]: throughput measurement.
//!
//! # Conventions
//! - Images enter as RGB `[0, 1]` NCHW f32 (what `vpcal_data::Batch` holds); the model applies
//!   its own channel order and normalisation from its config.
//! - Heatmaps are `[batch, 2 * scales, R, R]`, VP1 at each scale then VP2, encoded and decoded
//!   by `vpcal_geom::heatmap::HeatmapCodec` (the project's only diamond-space code); VPs are in
//!   the *box frame* of the crop (the crop spans `[-1, 1]²`).
//! - Parameter counts include batch-norm running statistics, as Keras (the reference) counts.
//! - The CPU backend is burn's `flex` (pure Rust, rayon threads); the `wgpu` cargo feature adds
//!   a GPU backend (Vulkan/Metal/DX12 at run time) that builds on machines without a GPU.

pub mod bench;
pub mod config;
pub mod device;
pub mod encoder;
mod fsutil;
pub mod infer;
pub mod metrics;
pub mod mobile;
pub mod model;
pub mod network;
pub mod pipeline_source;
pub mod regression;
pub mod report;
pub mod source;
pub mod store;
pub mod train;

pub use config::{ChannelOrder, Encoder, ModelConfig, Normalisation};
pub use encoder::EncoderNet;
pub use fsutil::write_atomic;
pub use infer::{CropPrediction, VpModel, VpNet};
pub use model::StackedHourglass;
pub use network::VpNetwork;
pub use pipeline_source::PipelineSource;
pub use source::{BatchSource, ToySource};
pub use train::{DataSegment, LrSchedule, TrainConfig, Trainer};

use std::path::{Path, PathBuf};

/// Errors of the network crate; file errors name the file.
#[derive(Debug, thiserror::Error)]
pub enum NetError {
    /// An inconsistent model or training configuration.
    #[error("invalid configuration: {0}")]
    Config(String),
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A weights file that cannot be used with this model.
    #[error("{path}: {message}")]
    Weights { path: PathBuf, message: String },
    /// A checkpoint folder that is incomplete or inconsistent.
    #[error("{path}: {message}")]
    Checkpoint { path: PathBuf, message: String },
    /// Input data with the wrong shape or values.
    #[error("bad input: {0}")]
    Input(String),
    /// A tensor could not be converted.
    #[error("tensor conversion failed: {0}")]
    Tensor(String),
    /// Encoding or decoding a file format failed.
    #[error("format error: {0}")]
    Format(String),
    /// JSON (de)serialisation failed.
    #[error("json: {0}")]
    Json(#[from] serde_json::Error),
    /// A data source failed.
    #[error(transparent)]
    Data(#[from] vpcal_data::DataError),
}

impl NetError {
    pub(crate) fn io(path: &Path, source: std::io::Error) -> NetError {
        NetError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}
