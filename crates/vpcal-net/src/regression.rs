//! Direct-regression baselines of the paper's ablation (§5.2, Table 2, models 6-10): a network
//! regresses the two box-frame VPs `(vp1.x, vp1.y, vp2.x, vp2.y)` and is trained with a
//! normalised loss, because plain L1/L2 losses did not converge:
//!
//! ```text
//! nL2(v, v̂) = ||v - v̂||² / ||v̂||²        nL1(v, v̂) = ||v - v̂||₁ / ||v̂||₁
//! ```
//! (`v̂` the truth), averaged over the batch, one term per VP.
//!
//! Backbones:
//! - [`RegressionBackbone::ResNet`]: ResNet-50 (He et al. 2016; bottleneck blocks 3-4-6-3,
//!   torchvision's v1.5 layout with the stride on the 3x3 convolution), global average pooling
//!   and one fully connected layer to 4 outputs. Width and block counts are configurable.
//! - [`RegressionBackbone::HourglassPool`]: the stacked hourglass with 64 output channels,
//!   global average pooling and fully connected layers (64 -> 256 -> 4, ReLU between).

use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::{BatchNorm, BatchNormConfig, Linear, LinearConfig, PaddingConfig2d};
use burn::tensor::activation::relu;
use burn::tensor::module::{adaptive_avg_pool2d, max_pool2d};
use burn::tensor::ops::MaxPoolOptions;
use burn::tensor::{Device, Tensor, TensorData};
use serde::{Deserialize, Serialize};
use vpcal_data::Batch;
use vpcal_geom::Point2;

use crate::config::{ChannelOrder, ModelConfig, Normalisation};
use crate::metrics::VpErrorAccumulator;
use crate::model::StackedHourglass;
use crate::network::{to_vec, VpNetwork};
use crate::NetError;

/// The normalised regression loss.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum NormLoss {
    /// `||v - v̂||₁ / ||v̂||₁`
    L1,
    /// `||v - v̂||² / ||v̂||²`
    L2,
}

/// Which backbone regresses the VPs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum RegressionBackbone {
    /// ResNet with bottleneck blocks; ResNet-50 is `width 64, blocks [3, 4, 6, 3]`.
    ResNet { width: usize, blocks: [usize; 4] },
    /// A stacked hourglass (its `scales` are ignored) with `features` output channels, then
    /// global pooling and `features -> hidden -> 4` fully connected layers.
    HourglassPool {
        hourglass: ModelConfig,
        features: usize,
        hidden: usize,
    },
}

/// Config of a [`Regressor`], saved with its checkpoints.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RegressionConfig {
    /// Side of the square input crop, pixels (paper: 128).
    pub input_size: usize,
    pub backbone: RegressionBackbone,
    pub loss: NormLoss,
    pub channel_order: ChannelOrder,
    pub normalisation: Normalisation,
    /// Batch-norm momentum (burn convention) and epsilon of the ResNet blocks.
    pub bn_momentum: f64,
    pub bn_epsilon: f64,
}

impl RegressionConfig {
    /// ResNet-50 on 128x128 crops with the given loss (paper models 6-9).
    pub fn resnet50(loss: NormLoss) -> Self {
        RegressionConfig {
            input_size: 128,
            backbone: RegressionBackbone::ResNet {
                width: 64,
                blocks: [3, 4, 6, 3],
            },
            loss,
            channel_order: ChannelOrder::Rgb,
            normalisation: Normalisation::Unit,
            bn_momentum: 0.1,
            bn_epsilon: 1e-5,
        }
    }

    /// The paper's stacked hourglass with 64-channel output, global pooling and FC layers
    /// (paper model 10).
    pub fn hourglass_pool(loss: NormLoss) -> Self {
        RegressionConfig {
            input_size: 128,
            backbone: RegressionBackbone::HourglassPool {
                hourglass: ModelConfig::paper(),
                features: 64,
                hidden: 256,
            },
            ..Self::resnet50(loss)
        }
    }

    /// Small versions for tests and smoke runs: `resnet` (width 8, one block per stage) or
    /// `hourglass` (the tiny hourglass), both on 32x32 crops like [`ModelConfig::tiny`].
    pub fn tiny(backbone: &str, loss: NormLoss) -> Result<Self, NetError> {
        let base = RegressionConfig {
            input_size: ModelConfig::tiny().input_size,
            ..Self::resnet50(loss)
        };
        match backbone {
            "resnet" | "resnet50" => Ok(RegressionConfig {
                backbone: RegressionBackbone::ResNet {
                    width: 8,
                    blocks: [1, 1, 1, 1],
                },
                ..base
            }),
            "hourglass" | "hourglass-pool" => Ok(RegressionConfig {
                backbone: RegressionBackbone::HourglassPool {
                    hourglass: ModelConfig::tiny(),
                    features: 16,
                    hidden: 32,
                },
                ..base
            }),
            other => Err(NetError::Config(format!(
                "unknown regression backbone {other:?} (expected \"resnet50\" or \"hourglass-pool\")"
            ))),
        }
    }

    /// Check the sizes.
    ///
    /// # Errors
    /// [`NetError::Config`] naming the offending field.
    pub fn validate(&self) -> Result<(), NetError> {
        match &self.backbone {
            RegressionBackbone::ResNet { width, blocks } => {
                if *width == 0 || blocks.contains(&0) {
                    return Err(NetError::Config(format!(
                        "ResNet width {width} and blocks {blocks:?} must be positive"
                    )));
                }
                if self.input_size < 32 {
                    return Err(NetError::Config(format!(
                        "input_size {} is below the ResNet's total stride 32",
                        self.input_size
                    )));
                }
            }
            RegressionBackbone::HourglassPool {
                hourglass,
                features,
                hidden,
            } => {
                hourglass.validate()?;
                if hourglass.input_size != self.input_size {
                    return Err(NetError::Config(format!(
                        "hourglass input_size {} differs from input_size {}",
                        hourglass.input_size, self.input_size
                    )));
                }
                if *features == 0 || *hidden == 0 {
                    return Err(NetError::Config(format!(
                        "features {features} and hidden {hidden} must be positive"
                    )));
                }
            }
        }
        Ok(())
    }
}

fn bn(c: usize, config: &RegressionConfig, device: &Device) -> BatchNorm {
    BatchNormConfig::new(c)
        .with_momentum(config.bn_momentum)
        .with_epsilon(config.bn_epsilon)
        .init(device)
}

fn conv(cin: usize, cout: usize, k: usize, stride: usize, device: &Device) -> Conv2d {
    let p = k / 2;
    Conv2dConfig::new([cin, cout], [k, k])
        .with_stride([stride, stride])
        .with_padding(PaddingConfig2d::Explicit(p, p, p, p))
        .with_bias(false)
        .init(device)
}

/// ResNet bottleneck block: 1x1, 3x3 (stride), 1x1 x4, each with BN; ReLU after the first two
/// and after the residual sum.
#[derive(Module, Debug)]
pub struct Bottleneck {
    conv1: Conv2d,
    bn1: BatchNorm,
    conv2: Conv2d,
    bn2: BatchNorm,
    conv3: Conv2d,
    bn3: BatchNorm,
    down: Option<Conv2d>,
    down_bn: Option<BatchNorm>,
}

impl Bottleneck {
    fn new(
        cin: usize,
        width: usize,
        stride: usize,
        config: &RegressionConfig,
        device: &Device,
    ) -> Self {
        let cout = 4 * width;
        let project = stride != 1 || cin != cout;
        Bottleneck {
            conv1: conv(cin, width, 1, 1, device),
            bn1: bn(width, config, device),
            conv2: conv(width, width, 3, stride, device),
            bn2: bn(width, config, device),
            conv3: conv(width, cout, 1, 1, device),
            bn3: bn(cout, config, device),
            down: project.then(|| conv(cin, cout, 1, stride, device)),
            down_bn: project.then(|| bn(cout, config, device)),
        }
    }

    /// # Shapes
    /// - `x`: `[b, cin, h, w]`; output `[b, 4 width, h / stride, w / stride]`
    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let skip = match (&self.down, &self.down_bn) {
            (Some(c), Some(b)) => b.forward(c.forward(x.clone())),
            _ => x.clone(),
        };
        let y = relu(self.bn1.forward(self.conv1.forward(x)));
        let y = relu(self.bn2.forward(self.conv2.forward(y)));
        let y = self.bn3.forward(self.conv3.forward(y));
        relu(y + skip)
    }
}

/// ResNet feature extractor: stem (7x7/2 conv, BN, ReLU, 3x3/2 max-pool) and four stages.
#[derive(Module, Debug)]
pub struct ResNet {
    stem: Conv2d,
    stem_bn: BatchNorm,
    stages: Vec<Vec<Bottleneck>>,
}

impl ResNet {
    fn new(width: usize, blocks: [usize; 4], config: &RegressionConfig, device: &Device) -> Self {
        let mut cin = width;
        let mut stages = Vec::new();
        for (i, &n) in blocks.iter().enumerate() {
            let w = width << i;
            let mut stage = Vec::new();
            for j in 0..n {
                let stride = if i > 0 && j == 0 { 2 } else { 1 };
                stage.push(Bottleneck::new(cin, w, stride, config, device));
                cin = 4 * w;
            }
            stages.push(stage);
        }
        ResNet {
            stem: conv(3, width, 7, 2, device),
            stem_bn: bn(width, config, device),
            stages,
        }
    }

    /// Number of output features (`32 width`).
    fn features(width: usize) -> usize {
        32 * width
    }

    /// # Shapes
    /// - `x`: `[b, 3, s, s]`; output `[b, 32 width]`
    fn forward(&self, x: Tensor<4>) -> Tensor<2> {
        let x = relu(self.stem_bn.forward(self.stem.forward(x))); // [b, w, s/2, s/2]
        let mut x = max_pool2d(
            x,
            MaxPoolOptions::new([3, 3])
                .with_stride([2, 2])
                .with_padding([1, 1]),
        ); // [b, w, s/4, s/4]
        for stage in &self.stages {
            for block in stage {
                x = block.forward(x);
            }
        } // [b, 32 w, s/32, s/32]
        let [b, c, _, _] = x.dims();
        adaptive_avg_pool2d(x, [1, 1]).reshape([b, c])
    }
}

/// A VP regressor: backbone, pooling, fully connected layers to `(vp1.x, vp1.y, vp2.x, vp2.y)`.
#[derive(Module, Debug)]
pub struct Regressor {
    resnet: Option<ResNet>,
    hourglass: Option<StackedHourglass>,
    fc: Vec<Linear>,
    #[module(skip)]
    input: crate::model::InputSpec,
}

impl Regressor {
    /// A freshly initialised regressor (config must be valid).
    pub fn new(config: &RegressionConfig, device: &Device) -> Self {
        let input = crate::model::InputSpec {
            channel_order: config.channel_order,
            normalisation: config.normalisation.clone(),
        };
        match &config.backbone {
            RegressionBackbone::ResNet { width, blocks } => Regressor {
                resnet: Some(ResNet::new(*width, *blocks, config, device)),
                hourglass: None,
                fc: vec![LinearConfig::new(ResNet::features(*width), 4).init(device)],
                input,
            },
            RegressionBackbone::HourglassPool {
                hourglass,
                features,
                hidden,
            } => Regressor {
                resnet: None,
                hourglass: Some(StackedHourglass::with_outputs(hourglass, *features, device)),
                fc: vec![
                    LinearConfig::new(*features, *hidden).init(device),
                    LinearConfig::new(*hidden, 4).init(device),
                ],
                input,
            },
        }
    }

    /// Box-frame VPs.
    ///
    /// # Shapes
    /// - `images`: `[b, 3, s, s]`, RGB `[0, 1]`
    /// - output: `[b, 4]` = `(vp1.x, vp1.y, vp2.x, vp2.y)`
    pub fn forward(&self, images: Tensor<4>) -> Tensor<2> {
        let mut x = match (&self.resnet, &self.hourglass) {
            (Some(r), _) => r.forward(self.input.apply(images)), // [b, f]
            (None, Some(h)) => {
                // The hourglass applies its own input conventions.
                let out = h.forward_last(images); // [b, f, hm, hm]
                let [b, c, _, _] = out.dims();
                adaptive_avg_pool2d(out, [1, 1]).reshape([b, c]) // [b, f]
            }
            (None, None) => images.flatten(1, 3),
        };
        let n = self.fc.len();
        for (i, fc) in self.fc.iter().enumerate() {
            x = fc.forward(x);
            if i + 1 < n {
                x = relu(x);
            }
        }
        x // [b, 4]
    }
}

/// Normalised loss per VP, `[2]`.
///
/// # Shapes
/// - `pred`, `truth`: `[b, 4]`
pub fn normalised_loss(pred: Tensor<2>, truth: Tensor<2>, loss: NormLoss) -> Tensor<1> {
    let [b, _] = pred.dims();
    let diff = (pred - truth.clone()).reshape([b, 2, 2]); // [b, vp, xy]
    let truth = truth.reshape([b, 2, 2]);
    let (num, den) = match loss {
        NormLoss::L2 => (diff.square().sum_dim(2), truth.square().sum_dim(2)), // [b, 2, 1]
        NormLoss::L1 => (diff.abs().sum_dim(2), truth.abs().sum_dim(2)),
    };
    let ratio = num / den.clamp_min(1e-12); // [b, 2, 1]
    ratio.mean_dim(0).reshape([2]) // [2]
}

fn truth_tensor(batch: &Batch, device: &Device) -> Tensor<2> {
    let mut v = Vec::with_capacity(batch.size * 4);
    for i in 0..batch.size {
        v.extend([
            batch.vp1_box[i][0] as f32,
            batch.vp1_box[i][1] as f32,
            batch.vp2_box[i][0] as f32,
            batch.vp2_box[i][1] as f32,
        ]);
    }
    Tensor::from_data(TensorData::new(v, [batch.size, 4]), device)
}

impl VpNetwork for Regressor {
    type Config = RegressionConfig;
    const KIND: &'static str = "vp_regressor";

    fn validate_config(config: &RegressionConfig) -> Result<(), NetError> {
        config.validate()
    }

    fn init(config: &RegressionConfig, device: &Device) -> Self {
        Regressor::new(config, device)
    }

    fn input_size(config: &RegressionConfig) -> usize {
        config.input_size
    }

    fn target_codec(_config: &RegressionConfig) -> vpcal_geom::heatmap::HeatmapCodec {
        vpcal_geom::heatmap::HeatmapCodec::new(8, vec![1.0])
    }

    fn check_batch(config: &RegressionConfig, batch: &Batch) -> Result<(), NetError> {
        if batch.input_size != config.input_size {
            return Err(NetError::Input(format!(
                "batch input_size is {}, the model expects {}",
                batch.input_size, config.input_size
            )));
        }
        if batch.vp1_box.len() != batch.size || batch.vp2_box.len() != batch.size {
            return Err(NetError::Input(format!(
                "batch of {} crops holds {} VP1s and {} VP2s",
                batch.size,
                batch.vp1_box.len(),
                batch.vp2_box.len()
            )));
        }
        if let Some(bad) = batch
            .vp1_box
            .iter()
            .chain(&batch.vp2_box)
            .find(|v| !(v[0].is_finite() && v[1].is_finite()))
        {
            return Err(NetError::Input(format!(
                "a regression target VP is not finite: {bad:?}"
            )));
        }
        Ok(())
    }

    fn loss_terms(
        &self,
        config: &RegressionConfig,
        images: Tensor<4>,
        batch: &Batch,
        _fg_weight: f64,
    ) -> Tensor<1> {
        let device = images.device();
        let truth = truth_tensor(batch, &device);
        normalised_loss(self.forward(images), truth, config.loss)
    }

    fn evaluate(
        &self,
        config: &RegressionConfig,
        images: Tensor<4>,
        batch: &Batch,
        acc: &mut VpErrorAccumulator,
    ) -> Result<Vec<f32>, NetError> {
        let device = images.device();
        let truth = truth_tensor(batch, &device);
        let pred = self.forward(images);
        let values = to_vec(pred.clone())?;
        let terms = to_vec(normalised_loss(pred, truth, config.loss))?;
        for (i, p) in values.chunks_exact(4).enumerate() {
            acc.add_direct(
                [
                    Point2::new(f64::from(p[0]), f64::from(p[1])),
                    Point2::new(f64::from(p[2]), f64::from(p[3])),
                ],
                [
                    Point2::from(batch.vp1_box[i]),
                    Point2::from(batch.vp2_box[i]),
                ],
            );
        }
        Ok(terms)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalised_losses_match_hand_computation() {
        let device = Device::flex();
        let pred = Tensor::<2>::from_floats([[1.0, 0.0, 0.0, 2.0], [3.0, 4.0, 0.0, 0.0]], &device);
        let truth = Tensor::<2>::from_floats([[2.0, 0.0, 0.0, 4.0], [3.0, 0.0, 1.0, 1.0]], &device);
        // nL2: vp1: (1/4 + 16/9) / 2, vp2: (4/16 + 2/2) / 2
        let l2 = to_vec(normalised_loss(pred.clone(), truth.clone(), NormLoss::L2)).unwrap();
        let want = [(0.25 + 16.0 / 9.0) / 2.0, (0.25 + 1.0) / 2.0];
        for (a, b) in l2.iter().zip(want) {
            assert!((f64::from(*a) - b).abs() < 1e-6, "{l2:?} vs {want:?}");
        }
        // nL1: vp1: (1/2 + 4/3) / 2, vp2: (2/4 + 2/2) / 2
        let l1 = to_vec(normalised_loss(pred, truth, NormLoss::L1)).unwrap();
        let want = [(0.5 + 4.0 / 3.0) / 2.0, (0.5 + 1.0) / 2.0];
        for (a, b) in l1.iter().zip(want) {
            assert!((f64::from(*a) - b).abs() < 1e-6, "{l1:?} vs {want:?}");
        }
    }

    #[test]
    fn resnet50_has_the_standard_size_and_shapes() {
        let device = Device::flex();
        let config = RegressionConfig::resnet50(NormLoss::L1);
        let model = Regressor::new(&config, &device);
        // torchvision's resnet50 without its 1000-way head has 23,508,032 parameters
        // (including BN running statistics as Keras counts them: +53,120).
        assert_eq!(model.num_params(), 23_508_032 + 53_120 + 2048 * 4 + 4);
        for backbone in ["resnet", "hourglass"] {
            let c = RegressionConfig::tiny(backbone, NormLoss::L2).unwrap();
            c.validate().unwrap();
            let m = Regressor::new(&c, &device);
            let out = m.forward(Tensor::zeros([2, 3, 32, 32], &device));
            assert_eq!(out.dims(), [2, 4], "{backbone}");
        }
    }
}
