//! A pretrained encoder for the VP network: the backbone (CSPDarknet) of the YOLOX-nano COCO
//! detector that vpcal ships (`models/yolox_nano_coco`, Apache-2.0; Ge et al., "YOLOX:
//! Exceeding YOLO Series in 2021", arXiv 2107.08430), written out by hand, and [`EncoderNet`],
//! that backbone followed by an FPN-lite decoder and the paper's diamond-space heatmap outputs.
//!
//! ```text
//! backbone (YOLOX-nano, width 0.25, depth 0.33, depthwise; every conv has a bias, BN is folded)
//! image 3xSxS BGR 0-255
//!  -> stem:  Focus (space-to-depth 2x2 -> 12 ch) -> conv3x3 16, SiLU                stride 2
//!  -> dark2: dw(16 -> 32, s2) -> csp(32, n=1)                                        stride 4
//!  -> dark3: dw(32 -> 64, s2) -> csp(64, n=3)                                        stride 8
//!  -> dark4: dw(64 -> 128, s2) -> csp(128, n=3)                                      stride 16
//!  -> dark5: dw(128 -> 256, s2) -> spp(256) -> csp(256, n=1, no shortcut)            stride 32
//! dw(a -> b, s):  dconv = depthwise 3x3 stride s, SiLU; pconv = 1x1 a -> b, SiLU
//! csp(c, n):      y1 = m_n(...m_1(conv1(x))), y2 = conv2(x) (1x1 c -> c/2, SiLU each);
//!                 out = conv3(cat(y1, y2)) (1x1 c -> c, SiLU)
//! m_i(x):         conv2(conv1(x)) (+ x with shortcut); conv1 1x1 SiLU, conv2 = dw(c/2 -> c/2, 1)
//! spp(c):         x = conv1(x) (1x1 c -> c/2); conv2(cat(x, maxpool5(x), maxpool9(x), maxpool13(x)))
//!
//! EncoderNet (ModelConfig::yolox_nano: 128 px crops, 32x32 heatmaps, width W = 64)
//! crop RGB [0,1] -> flip to BGR, x255 -> backbone
//! p = lateral_0(dark5)                                         (1x1 -> W, stride 32)
//! p = upsample2(p) + lateral_i(feature of the next finer stage)  ... down to the heatmap stride
//! head: [conv3x3 W, BN, ReLU] x 2 -> out: conv1x1 -> 2 * scales heatmaps (VP1 at each scale, VP2)
//! ```
//! Weight names mirror the structure and YOLOX's own (`dark3.csp.m.1.conv2.dconv.weight`);
//! inside [`EncoderNet`] they sit under `encoder.`. [`EncoderNet`]'s backbone is a [`Backbone`]:
//! this one, or an ImageNet-pretrained inverted-residual network of [`crate::mobile`] with the
//! same decoder. The pretrained weights are
//! `models/encoders/yolox_nano_backbone.safetensors` (written by
//! `scripts/convert_yolox_backbone.py`, see its NOTICE), embedded in the crate.

use std::path::Path;

use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::{BatchNorm, BatchNormConfig, PaddingConfig2d};
use burn::tensor::activation::{relu, silu};
use burn::tensor::module::{interpolate, max_pool2d};
use burn::tensor::ops::{InterpolateMode, InterpolateOptions, MaxPoolOptions};
use burn::tensor::{Device, Tensor};

use crate::config::{Encoder, ModelConfig};
use crate::mobile::MobileNet;
use crate::model::apply;
use crate::store::WeightsFile;
use crate::NetError;

/// The YOLOX-nano backbone weights (COCO), extracted from the bundled detector.
pub const YOLOX_NANO_BACKBONE: &[u8] = include_bytes!(concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../models/encoders/yolox_nano_backbone.safetensors"
));

/// Label of the embedded weights in error messages.
const YOLOX_NANO_LABEL: &str = "models/encoders/yolox_nano_backbone.safetensors (embedded)";

/// A `k x k` convolution with bias, stride `stride`, `groups` groups and padding `k / 2`.
fn conv(
    cin: usize,
    cout: usize,
    k: usize,
    stride: usize,
    groups: usize,
    device: &Device,
) -> Conv2d {
    let p = k / 2;
    Conv2dConfig::new([cin, cout], [k, k])
        .with_stride([stride, stride])
        .with_groups(groups)
        .with_padding(PaddingConfig2d::Explicit(p, p, p, p))
        .init(device)
}

/// Max-pooling of `k x k` (odd) with stride 1 and padding `k / 2` (size-preserving).
fn pool_same(x: Tensor<4>, k: usize) -> Tensor<4> {
    max_pool2d(
        x,
        MaxPoolOptions::new([k, k])
            .with_stride([1, 1])
            .with_padding([k / 2, k / 2]),
    )
}

/// Nearest-neighbour upsampling by 2.
fn upsample2(x: Tensor<4>) -> Tensor<4> {
    let [_, _, h, w] = x.dims();
    interpolate(
        x,
        InterpolateOptions::new(InterpolateMode::Nearest).with_output_size([2 * h, 2 * w]),
    )
}

/// Depthwise-separable convolution: depthwise 3x3 (stride `s`) + SiLU, pointwise 1x1 + SiLU.
#[derive(Module, Debug)]
pub struct DwConv {
    dconv: Conv2d,
    pconv: Conv2d,
}

impl DwConv {
    fn new(cin: usize, cout: usize, stride: usize, device: &Device) -> Self {
        DwConv {
            dconv: conv(cin, cin, 3, stride, cin, device),
            pconv: conv(cin, cout, 1, 1, 1, device),
        }
    }

    /// `[b, cin, h, w]` -> `[b, cout, h / s, w / s]`
    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let x = silu(apply(&self.dconv, x)); // [b, cin, h/s, w/s]
        silu(apply(&self.pconv, x)) // [b, cout, h/s, w/s]
    }
}

/// CSP bottleneck: 1x1 conv, depthwise-separable 3x3, optional identity shortcut.
#[derive(Module, Debug)]
pub struct Bottleneck {
    conv1: Conv2d,
    conv2: DwConv,
    shortcut: bool,
}

impl Bottleneck {
    /// `[b, c, h, w]` -> `[b, c, h, w]`
    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let y = self.conv2.forward(silu(apply(&self.conv1, x.clone())));
        if self.shortcut {
            y + x
        } else {
            y
        }
    }
}

/// Cross-stage-partial block of `n` bottlenecks (see the module docs).
#[derive(Module, Debug)]
pub struct Csp {
    conv1: Conv2d,
    conv2: Conv2d,
    conv3: Conv2d,
    m: Vec<Bottleneck>,
}

impl Csp {
    fn new(c: usize, n: usize, shortcut: bool, device: &Device) -> Self {
        let h = c / 2;
        Csp {
            conv1: conv(c, h, 1, 1, 1, device),
            conv2: conv(c, h, 1, 1, 1, device),
            conv3: conv(c, c, 1, 1, 1, device),
            m: (0..n)
                .map(|_| Bottleneck {
                    conv1: conv(h, h, 1, 1, 1, device),
                    conv2: DwConv::new(h, h, 1, device),
                    shortcut,
                })
                .collect(),
        }
    }

    /// `[b, c, h, w]` -> `[b, c, h, w]`
    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let mut y1 = silu(apply(&self.conv1, x.clone())); // [b, c/2, h, w]
        for block in &self.m {
            y1 = block.forward(y1);
        }
        let y2 = silu(apply(&self.conv2, x)); // [b, c/2, h, w]
        silu(apply(&self.conv3, Tensor::cat(vec![y1, y2], 1))) // [b, c, h, w]
    }
}

/// Spatial pyramid pooling (5, 9, 13) of dark5.
#[derive(Module, Debug)]
pub struct Spp {
    conv1: Conv2d,
    conv2: Conv2d,
}

impl Spp {
    /// `[b, c, h, w]` -> `[b, c, h, w]`
    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let x = silu(apply(&self.conv1, x)); // [b, c/2, h, w]
        let pooled = vec![
            x.clone(),
            pool_same(x.clone(), 5),
            pool_same(x.clone(), 9),
            pool_same(x, 13),
        ];
        silu(apply(&self.conv2, Tensor::cat(pooled, 1))) // [b, c, h, w]
    }
}

/// One backbone stage: stride-2 depthwise-separable conv, (SPP on dark5), CSP block.
#[derive(Module, Debug)]
pub struct Stage {
    down: DwConv,
    spp: Option<Spp>,
    csp: Csp,
}

impl Stage {
    fn new(cin: usize, cout: usize, n: usize, last: bool, device: &Device) -> Self {
        Stage {
            down: DwConv::new(cin, cout, 2, device),
            spp: last.then(|| Spp {
                conv1: conv(cout, cout / 2, 1, 1, 1, device),
                conv2: conv(2 * cout, cout, 1, 1, 1, device),
            }),
            csp: Csp::new(cout, n, !last, device),
        }
    }

    /// `[b, cin, h, w]` -> `[b, cout, h / 2, w / 2]`
    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let mut x = self.down.forward(x);
        if let Some(spp) = &self.spp {
            x = spp.forward(x);
        }
        self.csp.forward(x)
    }
}

/// The Focus stem: space-to-depth 2x2, then a dense 3x3 conv + SiLU.
#[derive(Module, Debug)]
pub struct Focus {
    conv: Conv2d,
}

impl Focus {
    /// `[b, 3, h, w]` (h, w even) -> `[b, 16, h / 2, w / 2]`
    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let [b, c, h, w] = x.dims();
        // x[b, c, 2i + dy, 2j + dx] -> channel (2 dx + dy) c + c: YOLOX's order top-left,
        // bottom-left, top-right, bottom-right.
        let x = x
            .reshape([b, c, h / 2, 2, w / 2, 2]) // [b, c, i, dy, j, dx]
            .permute([0, 5, 3, 1, 2, 4]) // [b, dx, dy, c, i, j]
            .reshape([b, 4 * c, h / 2, w / 2]);
        silu(apply(&self.conv, x))
    }
}

/// The backbone's feature maps.
#[derive(Debug, Clone)]
pub struct Features {
    /// Stem output, stride 2: `[b, 16, S/2, S/2]`.
    pub stem: Tensor<4>,
    /// dark2, stride 4: `[b, 32, S/4, S/4]`.
    pub dark2: Tensor<4>,
    /// dark3, stride 8: `[b, 64, S/8, S/8]`.
    pub dark3: Tensor<4>,
    /// dark4, stride 16: `[b, 128, S/16, S/16]`.
    pub dark4: Tensor<4>,
    /// dark5, stride 32: `[b, 256, S/32, S/32]`.
    pub dark5: Tensor<4>,
}

impl Features {
    /// The maps from coarse (stride 32) to fine (stride 2).
    pub fn coarse_to_fine(self) -> [Tensor<4>; 5] {
        [self.dark5, self.dark4, self.dark3, self.dark2, self.stem]
    }

    /// Each map with its gradient cut off.
    pub fn detach(self) -> Self {
        Features {
            stem: self.stem.detach(),
            dark2: self.dark2.detach(),
            dark3: self.dark3.detach(),
            dark4: self.dark4.detach(),
            dark5: self.dark5.detach(),
        }
    }
}

/// The YOLOX-nano backbone (see the module docs).
#[derive(Module, Debug)]
pub struct YoloxNano {
    stem: Focus,
    dark2: Stage,
    dark3: Stage,
    dark4: Stage,
    dark5: Stage,
}

impl YoloxNano {
    /// Channels of the stem and dark2..dark5 outputs.
    pub const CHANNELS: [usize; 5] = [16, 32, 64, 128, 256];

    /// A randomly initialised backbone (burn's default initialisers).
    pub fn new(device: &Device) -> Self {
        let [c1, c2, c3, c4, c5] = Self::CHANNELS;
        YoloxNano {
            stem: Focus {
                conv: conv(12, c1, 3, 1, 1, device),
            },
            dark2: Stage::new(c1, c2, 1, false, device),
            dark3: Stage::new(c2, c3, 3, false, device),
            dark4: Stage::new(c3, c4, 3, false, device),
            dark5: Stage::new(c4, c5, 1, true, device),
        }
    }

    /// The backbone with the detector's COCO weights (embedded in the crate).
    ///
    /// # Errors
    /// [`NetError::Weights`] when the embedded file does not match the module (a build with a
    /// stale weights file).
    pub fn pretrained(device: &Device) -> Result<Self, NetError> {
        WeightsFile::parse(YOLOX_NANO_BACKBONE, Path::new(YOLOX_NANO_LABEL))?
            .load_into(Self::new(device))
    }

    /// Features of images in the detector's own convention.
    ///
    /// # Shapes
    /// - `images`: `[batch, 3, S, S]`, BGR, 0-255, S a multiple of 32
    /// - output: see [`Features`]
    pub fn forward_bgr255(&self, images: Tensor<4>) -> Features {
        let stem = self.stem.forward(images); // [b, 16, S/2, S/2]
        let dark2 = self.dark2.forward(stem.clone()); // [b, 32, S/4, S/4]
        let dark3 = self.dark3.forward(dark2.clone()); // [b, 64, S/8, S/8]
        let dark4 = self.dark4.forward(dark3.clone()); // [b, 128, S/16, S/16]
        let dark5 = self.dark5.forward(dark4.clone()); // [b, 256, S/32, S/32]
        Features {
            stem,
            dark2,
            dark3,
            dark4,
            dark5,
        }
    }

    /// Features of crops in the VP network's convention, converted to the detector's (the
    /// channels reversed to BGR, scaled to 0-255) so that its pretrained statistics hold.
    ///
    /// # Shapes
    /// - `images`: `[batch, 3, S, S]`, RGB in `[0, 1]`
    /// - output: see [`Features`]
    pub fn forward(&self, images: Tensor<4>) -> Features {
        self.forward_bgr255(images.flip([1]).mul_scalar(255.0))
    }
}

/// A 3x3 conv, batch norm and ReLU of the decoder head.
#[derive(Module, Debug)]
pub struct ConvBn {
    conv: Conv2d,
    bn: BatchNorm,
}

impl ConvBn {
    fn new(c: usize, config: &ModelConfig, device: &Device) -> Self {
        ConvBn {
            conv: conv(c, c, 3, 1, 1, device),
            bn: BatchNormConfig::new(c)
                .with_momentum(config.bn_momentum)
                .with_epsilon(config.bn_epsilon)
                .init(device),
        }
    }

    /// `[b, c, h, w]` -> `[b, c, h, w]`
    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        relu(self.bn.forward(apply(&self.conv, x)))
    }
}

/// The pretrained backbone in front of the decoder. Its weights are named as the backbone's own
/// (the variant adds no name: `encoder.dark3.csp.conv1.weight`, `encoder.blocks.3.project.bias`).
// One per network, so the variants' sizes do not matter (burn's derive does not take a Box).
#[allow(clippy::large_enum_variant)]
#[derive(Module, Debug)]
pub enum Backbone {
    /// [`YoloxNano`] (COCO).
    YoloxNano(YoloxNano),
    /// MobileNetV2 or EfficientNet-Lite0 (ImageNet).
    Mobile(MobileNet),
}

impl Backbone {
    /// A randomly initialised backbone of a pretrained-encoder config's kind.
    pub fn new(encoder: Encoder, device: &Device) -> Self {
        match encoder.mobile_family() {
            Some(family) => Backbone::Mobile(MobileNet::new(family, device)),
            None => Backbone::YoloxNano(YoloxNano::new(device)),
        }
    }

    /// The backbone with its pretrained weights.
    ///
    /// # Errors
    /// As [`YoloxNano::pretrained`] and [`MobileNet::pretrained`].
    pub fn pretrained(encoder: Encoder, device: &Device) -> Result<Self, NetError> {
        Ok(match encoder.mobile_family() {
            Some(family) => Backbone::Mobile(MobileNet::pretrained(family, device)?),
            None => Backbone::YoloxNano(YoloxNano::pretrained(device)?),
        })
    }

    /// Channels of the maps at strides 2, 4, 8, 16 and 32.
    pub fn channels(&self) -> [usize; 5] {
        match self {
            Backbone::YoloxNano(_) => YoloxNano::CHANNELS,
            Backbone::Mobile(m) => m.family().channels(),
        }
    }

    /// Features of crops, RGB in `[0, 1]`.
    pub fn forward(&self, images: Tensor<4>) -> Features {
        match self {
            Backbone::YoloxNano(b) => b.forward(images),
            Backbone::Mobile(b) => b.forward(images),
        }
    }
}

/// The pretrained-encoder VP network (see the module docs): a pretrained backbone (YOLOX-nano,
/// MobileNetV2 or EfficientNet-Lite0), FPN-lite decoder to the heatmap resolution,
/// `2 * scales` heatmaps. Build it from a valid [`ModelConfig`] whose
/// [`Encoder`](crate::config::Encoder) is a pretrained one.
#[derive(Module, Debug)]
pub struct EncoderNet {
    encoder: Backbone,
    /// 1x1 projections to the decoder width, coarse (dark5) to fine.
    lateral: Vec<Conv2d>,
    head: Vec<ConvBn>,
    out: Conv2d,
    /// Whether gradients stop at the encoder's output (the frozen first training phase).
    frozen: bool,
}

impl EncoderNet {
    /// Number of 3x3 conv + BN + ReLU layers of the head.
    pub const HEAD_LAYERS: usize = 2;

    /// A network with a randomly initialised encoder (load weights into it, or see
    /// [`EncoderNet::pretrained`]). The config must be valid.
    pub fn new(config: &ModelConfig, device: &Device) -> Self {
        let w = config.channels;
        let stride = config.input_size / config.heatmap_size.max(1);
        // Stages used: dark5 (stride 32) down to the one at the heatmap stride.
        let levels = (32 / stride.clamp(2, 32)).trailing_zeros() as usize + 1;
        let encoder = Backbone::new(config.encoder, device);
        let lateral = encoder
            .channels()
            .iter()
            .rev()
            .take(levels)
            .map(|&c| conv(c, w, 1, 1, 1, device))
            .collect();
        EncoderNet {
            encoder,
            lateral,
            head: (0..Self::HEAD_LAYERS)
                .map(|_| ConvBn::new(w, config, device))
                .collect(),
            out: conv(w, config.outputs(), 1, 1, 1, device),
            frozen: false,
        }
    }

    /// A network whose encoder holds its pretrained weights (the decoder is random).
    ///
    /// # Errors
    /// As [`Backbone::pretrained`].
    pub fn pretrained(config: &ModelConfig, device: &Device) -> Result<Self, NetError> {
        Ok(Self::new(config, device).with_encoder(Backbone::pretrained(config.encoder, device)?))
    }

    /// Stop (`true`) or let (`false`) gradients reach the encoder: frozen, its parameters
    /// need no gradient and its features are detached, so an optimizer leaves it unchanged
    /// and backpropagation skips it.
    pub fn with_frozen_encoder(mut self, frozen: bool) -> Self {
        self.encoder = if frozen {
            self.encoder.no_grad()
        } else {
            self.encoder.set_require_grad(true)
        };
        self.frozen = frozen;
        self
    }

    /// The network with another encoder (e.g. [`Backbone::pretrained`]) of the same kind;
    /// keeps the frozen state.
    pub fn with_encoder(mut self, encoder: Backbone) -> Self {
        self.encoder = encoder;
        let frozen = self.frozen;
        self.with_frozen_encoder(frozen)
    }

    /// Whether the encoder is frozen.
    pub fn encoder_frozen(&self) -> bool {
        self.frozen
    }

    /// The backbone.
    pub fn encoder(&self) -> &Backbone {
        &self.encoder
    }

    /// Heatmaps, as a one-element list (the shape contract of
    /// [`StackedHourglass::forward`](crate::StackedHourglass::forward)).
    ///
    /// # Shapes
    /// - `images`: `[batch, 3, input, input]`, RGB in `[0, 1]`
    /// - output: one tensor `[batch, outputs, heatmap, heatmap]`
    pub fn forward(&self, images: Tensor<4>) -> Vec<Tensor<4>> {
        vec![self.forward_last(images)]
    }

    /// Heatmaps.
    ///
    /// # Shapes
    /// - `images`: `[batch, 3, input, input]`, RGB in `[0, 1]`
    /// - output: `[batch, outputs, heatmap, heatmap]`
    pub fn forward_last(&self, images: Tensor<4>) -> Tensor<4> {
        let mut features = self.encoder.forward(images);
        if self.frozen {
            features = features.detach();
        }
        let mut p: Option<Tensor<4>> = None;
        for (lateral, f) in self.lateral.iter().zip(features.coarse_to_fine()) {
            let l = apply(lateral, f); // [b, w, S/s, S/s]
            p = Some(match p {
                Some(p) => upsample2(p) + l,
                None => l,
            });
        }
        // `new` builds at least one lateral conv.
        let Some(mut x) = p else {
            return Tensor::zeros([0, 0, 0, 0], &self.devices()[0]);
        };
        for layer in &self.head {
            x = layer.forward(x); // [b, w, hm, hm]
        }
        apply(&self.out, x) // [b, outputs, hm, hm]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::named_tensors;

    #[test]
    fn tensor_names_and_counts() {
        let device = Device::flex();
        let b = YoloxNano::pretrained(&device).unwrap();
        let names: Vec<String> = named_tensors(&b)
            .unwrap()
            .into_iter()
            .map(|t| t.name)
            .collect();
        assert_eq!(names.len(), 94);
        assert!(
            names.iter().any(|n| n == "dark5.spp.conv1.weight"),
            "{names:?}"
        );
        assert!(names.iter().any(|n| n == "dark3.csp.m.2.conv2.dconv.bias"));
        assert_eq!(b.num_params(), 456_592);
        let net = EncoderNet::new(&ModelConfig::yolox_nano(), &device);
        let x = Tensor::<4>::zeros([2, 3, 128, 128], &device);
        assert_eq!(net.forward_last(x).dims(), [2, 8, 32, 32]);
        let names: Vec<String> = named_tensors(&net)
            .unwrap()
            .into_iter()
            .map(|t| t.name)
            .collect();
        // The backbone enum's variant adds no name: the bundled model's names still load.
        assert!(names
            .iter()
            .any(|n| n == "encoder.dark3.csp.m.2.conv2.dconv.bias"));
    }

    #[test]
    fn mobile_encoder_networks_have_their_taps_and_names() {
        let device = Device::flex();
        for (encoder, backbone_params, expand_convs) in [
            (Encoder::MobilenetV2, 1_795_936, 16),
            (Encoder::EfficientnetLite0, 2_939_120, 15),
        ] {
            let config = ModelConfig::pretrained(encoder);
            config.validate().unwrap();
            let net = EncoderNet::new(&config, &device);
            let Backbone::Mobile(m) = net.encoder() else {
                panic!("{encoder:?} built another backbone");
            };
            assert_eq!(m.num_params(), backbone_params, "{encoder:?}");
            let names: Vec<String> = named_tensors(&net)
                .unwrap()
                .into_iter()
                .map(|t| t.name)
                .collect();
            let expands = names
                .iter()
                .filter(|n| n.starts_with("encoder.blocks.") && n.ends_with(".expand.weight"))
                .count();
            assert_eq!(expands, expand_convs, "{encoder:?}");
            assert!(
                names.iter().any(|n| n == "encoder.stem.weight"),
                "{names:?}"
            );
            let x = Tensor::<4>::zeros([1, 3, 64, 64], &device);
            let f = net.encoder().forward(x);
            let dims: Vec<[usize; 4]> = f.coarse_to_fine().iter().map(|t| t.dims()).collect();
            let c = encoder.mobile_family().unwrap().channels();
            assert_eq!(
                dims,
                vec![
                    [1, c[4], 2, 2],
                    [1, c[3], 4, 4],
                    [1, c[2], 8, 8],
                    [1, c[1], 16, 16],
                    [1, c[0], 32, 32]
                ],
                "{encoder:?}"
            );
        }
    }
}
