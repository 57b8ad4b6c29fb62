//! Inference: load trained weights and predict the VPs of vehicle crops, batched.
//!
//! ```no_run
//! # fn main() -> Result<(), vpcal_net::NetError> {
//! let device = vpcal_net::device::select("cpu")?;
//! let net = vpcal_net::VpNet::load(std::path::Path::new("runs/tiny"), &device)?;
//! let crop = image::RgbImage::new(90, 60);
//! let preds = net.predict(&[crop])?;
//! println!("VP1 in the box frame: {:?}", preds[0].vp.vp1);
//! # Ok(()) }
//! ```

use std::path::Path;

use burn::module::Module;
use burn::tensor::{Device, Tensor, TensorData};
use image::imageops::FilterType;
use image::RgbImage;
use vpcal_geom::heatmap::{DecodeMode, HeatmapCodec, VpPrediction};

use crate::config::{Encoder, ModelConfig};
use crate::encoder::EncoderNet;
use crate::model::StackedHourglass;
use crate::network::{to_vec, VpNetwork};
use crate::store::WeightsFile;
use crate::train::{checkpoint_weights, resolve_checkpoint};
use crate::NetError;

/// A crop's decoded VPs together with the heatmaps they came from.
#[derive(Debug, Clone)]
pub struct CropPrediction {
    /// VPs in the crop's box frame, the selected scales and the spreads `D^s`.
    pub vp: VpPrediction,
    /// The last stack's heatmaps, `[channels][R][R]` row-major.
    pub heatmaps: Vec<f32>,
}

/// The heatmap networks [`VpNet`] can run, chosen by the checkpoint's config.
#[derive(Debug, Clone)]
pub enum VpModel {
    /// The stacked hourglass ([`Encoder::Hourglass`]).
    Hourglass(Box<StackedHourglass>),
    /// The pretrained-encoder network ([`Encoder::YoloxNano`] and the other pretrained
    /// encoders).
    Encoder(Box<EncoderNet>),
}

impl From<StackedHourglass> for VpModel {
    fn from(m: StackedHourglass) -> Self {
        VpModel::Hourglass(Box::new(m))
    }
}

impl From<EncoderNet> for VpModel {
    fn from(m: EncoderNet) -> Self {
        VpModel::Encoder(Box::new(m))
    }
}

impl VpModel {
    /// The stacked hourglass, if it is one.
    pub fn as_hourglass(&self) -> Option<&StackedHourglass> {
        match self {
            VpModel::Hourglass(m) => Some(m),
            VpModel::Encoder(_) => None,
        }
    }

    /// The pretrained-encoder network, if it is one.
    pub fn as_encoder(&self) -> Option<&EncoderNet> {
        match self {
            VpModel::Encoder(m) => Some(m),
            VpModel::Hourglass(_) => None,
        }
    }

    /// The architecture name stored in checkpoints ([`VpNetwork::KIND`]).
    pub fn kind(&self) -> &'static str {
        match self {
            VpModel::Hourglass(_) => StackedHourglass::KIND,
            VpModel::Encoder(_) => EncoderNet::KIND,
        }
    }

    /// Number of parameters (batch-norm running statistics included).
    pub fn num_params(&self) -> usize {
        match self {
            VpModel::Hourglass(m) => m.num_params(),
            VpModel::Encoder(m) => m.num_params(),
        }
    }

    /// The final heatmaps, `[batch, outputs, heatmap, heatmap]`, of RGB `[0, 1]` input
    /// `[batch, 3, input, input]`.
    pub fn forward_last(&self, images: Tensor<4>) -> Tensor<4> {
        match self {
            VpModel::Hourglass(m) => m.forward_last(images),
            VpModel::Encoder(m) => m.forward_last(images),
        }
    }

    /// In validation mode on `device`.
    fn valid_on(self, device: &Device) -> Self {
        match self {
            VpModel::Hourglass(m) => VpModel::from(m.valid().to_device(device)),
            VpModel::Encoder(m) => VpModel::from(m.valid().to_device(device)),
        }
    }
}

/// A trained heatmap network ready for inference.
#[derive(Debug)]
pub struct VpNet {
    model: VpModel,
    config: ModelConfig,
    codec: HeatmapCodec,
    device: Device,
    mode: DecodeMode,
    batch_size: usize,
    flip_average: bool,
}

impl VpNet {
    /// Wrap a model ([`StackedHourglass`] or [`EncoderNet`]; moved to `device` and put in
    /// validation mode).
    pub fn new(model: impl Into<VpModel>, config: ModelConfig, device: &Device) -> VpNet {
        let device = device.clone().without_autodiff();
        let model = model.into().valid_on(&device);
        VpNet {
            codec: config.codec(),
            model,
            config,
            device,
            mode: DecodeMode::Centre,
            batch_size: 32,
            flip_average: false,
        }
    }

    /// Load weights from a `.safetensors` file, a checkpoint folder or a training run folder
    /// (its latest checkpoint); the model config comes from the weights' metadata.
    ///
    /// # Errors
    /// [`NetError::Weights`] / [`NetError::Checkpoint`] naming the file when it holds no
    /// config, another architecture, or tensors that do not fit the config.
    pub fn load(path: &Path, device: &Device) -> Result<VpNet, NetError> {
        Self::from_weights(&WeightsFile::read(&weights_path(path)?)?, device)
    }

    /// Load weights held in memory (e.g. a model embedded in the binary); `label` names them
    /// in errors. The model config comes from the weights' metadata.
    ///
    /// # Errors
    /// As [`VpNet::load`].
    pub fn from_bytes(bytes: &[u8], label: &Path, device: &Device) -> Result<VpNet, NetError> {
        Self::from_weights(&WeightsFile::parse(bytes, label)?, device)
    }

    fn from_weights(file: &WeightsFile, device: &Device) -> Result<VpNet, NetError> {
        let config = file
            .config::<ModelConfig>()?
            .ok_or_else(|| NetError::Weights {
                path: file.path().to_path_buf(),
                message: "no vpcal model config in the metadata: use VpNet::load_with_config"
                    .into(),
            })?;
        Self::from_file(file, config, device)
    }

    /// Load weights into a model built from `config`, refusing a file whose stored config
    /// differs (listing the differing fields) or whose tensors do not fit.
    ///
    /// # Errors
    /// As [`VpNet::load`], plus [`NetError::Weights`] for a config mismatch.
    pub fn load_with_config(
        path: &Path,
        config: ModelConfig,
        device: &Device,
    ) -> Result<VpNet, NetError> {
        let file = WeightsFile::read(&weights_path(path)?)?;
        if let Some(saved) = file.config::<ModelConfig>()? {
            let diff = config.differences(&saved);
            if !diff.is_empty() {
                return Err(NetError::Weights {
                    path: file.path().to_path_buf(),
                    message: format!(
                        "model config differs (expected vs file): {}",
                        diff.join("; ")
                    ),
                });
            }
        }
        Self::from_file(&file, config, device)
    }

    fn from_file(
        file: &WeightsFile,
        config: ModelConfig,
        device: &Device,
    ) -> Result<VpNet, NetError> {
        let expected = match config.encoder {
            Encoder::Hourglass => StackedHourglass::KIND,
            Encoder::YoloxNano | Encoder::MobilenetV2 | Encoder::EfficientnetLite0 => {
                EncoderNet::KIND
            }
        };
        if let Some(kind) = &file.kind {
            if kind != expected {
                return Err(NetError::Weights {
                    path: file.path().to_path_buf(),
                    message: format!("weights of a {kind:?} network, not a {expected:?}"),
                });
            }
        }
        config.validate().map_err(|e| NetError::Weights {
            path: file.path().to_path_buf(),
            message: e.to_string(),
        })?;
        let device = device.clone().without_autodiff();
        let model = match config.encoder {
            Encoder::Hourglass => {
                VpModel::from(file.load_into(StackedHourglass::new(&config, &device))?)
            }
            Encoder::YoloxNano | Encoder::MobilenetV2 | Encoder::EfficientnetLite0 => {
                VpModel::from(file.load_into(EncoderNet::new(&config, &device))?)
            }
        };
        Ok(Self::new(model, config, &device))
    }

    /// Use another decoding mode for the spreads (default [`DecodeMode::Centre`]).
    pub fn with_decode_mode(mut self, mode: DecodeMode) -> Self {
        self.mode = mode;
        self
    }

    /// Largest number of crops run through the network at once (default 32).
    pub fn with_batch_size(mut self, batch_size: usize) -> Self {
        self.batch_size = batch_size.max(1);
        self
    }

    /// Also run every crop mirrored left-right and average its heatmaps, mirrored back, with
    /// the crop's own (test-time augmentation; twice the network work). Mirroring a crop maps
    /// a box-frame VP `(x, y)` to `(-x, y)`, which in the rotated diamond swaps the two
    /// heatmap axes, so the mirrored crop's heatmaps are transposed back exactly. A network's
    /// error that is not mirror-symmetric (a rotation of every VP ray the same way) cancels.
    pub fn with_flip_average(mut self, on: bool) -> Self {
        self.flip_average = on;
        self
    }

    /// The model config.
    pub fn config(&self) -> &ModelConfig {
        &self.config
    }

    /// The heatmap codec.
    pub fn codec(&self) -> &HeatmapCodec {
        &self.codec
    }

    /// The model.
    pub fn model(&self) -> &VpModel {
        &self.model
    }

    /// Resize crops of any size to the network input (bicubic) as RGB `[0, 1]` NCHW values.
    pub fn prepare(&self, crops: &[RgbImage]) -> Vec<f32> {
        let s = self.config.input_size as u32;
        let plane = (s * s) as usize;
        let mut out = vec![0.0f32; crops.len() * 3 * plane];
        for (k, crop) in crops.iter().enumerate() {
            let resized;
            let img = if crop.dimensions() == (s, s) {
                crop
            } else {
                resized = image::imageops::resize(crop, s, s, FilterType::CatmullRom);
                &resized
            };
            let base = k * 3 * plane;
            for (i, p) in img.pixels().enumerate() {
                for c in 0..3 {
                    out[base + c * plane + i] = f32::from(p.0[c]) / 255.0;
                }
            }
        }
        out
    }

    /// Heatmaps of prepared input (`[n, 3, S, S]`, RGB `[0, 1]`), `[n, channels, R, R]`.
    ///
    /// # Errors
    /// [`NetError::Input`] when `images.len()` is not a multiple of `3 * S * S`.
    pub fn heatmaps(&self, images: &[f32]) -> Result<Vec<f32>, NetError> {
        let s = self.config.input_size;
        let per = 3 * s * s;
        if !images.len().is_multiple_of(per) {
            return Err(NetError::Input(format!(
                "{} input values are not a whole number of 3 x {s} x {s} crops",
                images.len()
            )));
        }
        let n = images.len() / per;
        let mut out = Vec::with_capacity(n * self.codec.len());
        for chunk in images.chunks(self.batch_size * per) {
            let b = chunk.len() / per;
            let x =
                Tensor::<4>::from_data(TensorData::new(chunk.to_vec(), [b, 3, s, s]), &self.device);
            out.extend(to_vec(self.model.forward_last(x))?);
        }
        Ok(out)
    }

    /// Predict the VPs of prepared input (see [`VpNet::heatmaps`]).
    ///
    /// # Errors
    /// As [`VpNet::heatmaps`].
    pub fn predict_prepared(&self, images: &[f32]) -> Result<Vec<CropPrediction>, NetError> {
        let mut heat = self.heatmaps(images)?;
        if self.flip_average {
            let s = self.config.input_size;
            let mirrored = self.heatmaps(&mirror_rows(images, s))?;
            let r = self.codec.resolution;
            for (h, m) in heat
                .chunks_exact_mut(r * r)
                .zip(mirrored.chunks_exact(r * r))
            {
                for i in 0..r {
                    for j in 0..r {
                        h[i * r + j] = 0.5 * (h[i * r + j] + m[j * r + i]);
                    }
                }
            }
        }
        let per = self.codec.len();
        Ok(heat
            .chunks_exact(per)
            .map(|h| CropPrediction {
                vp: self.codec.decode(h, self.mode),
                heatmaps: h.to_vec(),
            })
            .collect())
    }

    /// Predict the VPs of vehicle crops (any size; each is resized to the network input).
    /// VPs are in each crop's box frame: map them to frame pixels with
    /// `BoxPx::frame_from_box` of the box the crop was cut from.
    ///
    /// # Errors
    /// [`NetError::Tensor`] when the output cannot be read back.
    pub fn predict(&self, crops: &[RgbImage]) -> Result<Vec<CropPrediction>, NetError> {
        self.predict_prepared(&self.prepare(crops))
    }
}

/// Mirror every row of planes of `size x size` values left-right.
fn mirror_rows(images: &[f32], size: usize) -> Vec<f32> {
    let mut out = images.to_vec();
    for row in out.chunks_exact_mut(size) {
        row.reverse();
    }
    out
}

/// The weights file behind a path: the file itself, a checkpoint folder, or a run folder.
fn weights_path(path: &Path) -> Result<std::path::PathBuf, NetError> {
    if path.is_file() {
        return Ok(path.to_path_buf());
    }
    Ok(checkpoint_weights(&resolve_checkpoint(path)?))
}
