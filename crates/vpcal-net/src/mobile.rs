//! ImageNet-pretrained inverted-residual encoders for the VP network: MobileNetV2 1.0 (Sandler
//! et al., "MobileNetV2: Inverted Residuals and Linear Bottlenecks", CVPR 2018) and
//! EfficientNet-Lite0 (the edge variant of Tan & Le, "EfficientNet", ICML 2019: no
//! squeeze-excitation, ReLU6, fixed stem and head), written out by hand in burn.
//!
//! ```text
//! stem:  conv3x3 s2 3 -> 32, ReLU6                                                  stride 2
//! block(k, t, c, s): [expand 1x1 -> t*cin, ReLU6] (absent when t = 1)
//!                    depthwise kxk stride s, ReLU6
//!                    project 1x1 -> c (linear), + input when s = 1 and cin = c
//! stages (k, t, c, n, s), the first block of each with stride s, the rest stride 1:
//!   MobileNetV2        (3,1,16,1,1) (3,6,24,2,2) (3,6,32,3,2) (3,6,64,4,2) (3,6,96,3,1)
//!                      (3,6,160,3,2) (3,6,320,1,1)
//!   EfficientNet-Lite0 (3,1,16,1,1) (3,6,24,2,2) (5,6,40,2,2) (3,6,80,3,2) (5,6,112,3,1)
//!                      (5,6,192,4,2) (3,6,320,1,1)
//! taps (the last block at each stride):  stride 2, 4, 8, 16, 32
//!   MobileNetV2        16, 24, 32, 96, 320 channels
//!   EfficientNet-Lite0 16, 24, 40, 112, 320 channels
//! ```
//! Both end at their last 320-channel block: the 1x1 head to 1280 channels and the classifier
//! are for ImageNet's classes and are not used. Batch norm is folded into every convolution
//! (each has a bias), as in the YOLOX encoder.
//!
//! Conventions kept from training: MobileNetV2 (PyTorch) pads each convolution by `k / 2` and
//! takes ImageNet mean/std-normalised RGB; EfficientNet-Lite0 (TensorFlow) pads "SAME", which on
//! the stride-2 convolutions of even-sized maps puts the extra row and column at the bottom and
//! right, and takes `(x - 127) / 128` of 0-255 RGB. The VP network's crops are RGB in `[0, 1]`
//! and [`MobileNet::forward`] converts them.
//!
//! The weights (`models/encoders/{mobilenet_v2,efficientnet_lite0}_backbone.safetensors`,
//! written by `scripts/convert_mobile_encoders.py`, see models/encoders/NOTICE) are read from
//! the repository when a training run starts from them, not embedded: a trained network's own
//! file holds its encoder.

use std::path::{Path, PathBuf};

use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::PaddingConfig2d;
use burn::tensor::{Device, Tensor};

use crate::config::{ChannelOrder, Normalisation};
use crate::encoder::Features;
use crate::model::{apply, InputSpec};
use crate::store::WeightsFile;
use crate::NetError;

/// Which inverted-residual network.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MobileFamily {
    /// MobileNetV2 1.0 (ImageNet top-1 71.8 %).
    MobilenetV2,
    /// EfficientNet-Lite0 (ImageNet top-1 75.1 %).
    EfficientnetLite0,
}

/// One stage: kernel, expansion, output channels, blocks, stride of its first block.
#[derive(Debug, Clone, Copy)]
struct StageSpec {
    kernel: usize,
    expand: usize,
    channels: usize,
    repeats: usize,
    stride: usize,
}

const fn stage(
    kernel: usize,
    expand: usize,
    channels: usize,
    repeats: usize,
    stride: usize,
) -> StageSpec {
    StageSpec {
        kernel,
        expand,
        channels,
        repeats,
        stride,
    }
}

const MOBILENET_V2: [StageSpec; 7] = [
    stage(3, 1, 16, 1, 1),
    stage(3, 6, 24, 2, 2),
    stage(3, 6, 32, 3, 2),
    stage(3, 6, 64, 4, 2),
    stage(3, 6, 96, 3, 1),
    stage(3, 6, 160, 3, 2),
    stage(3, 6, 320, 1, 1),
];

const EFFICIENTNET_LITE0: [StageSpec; 7] = [
    stage(3, 1, 16, 1, 1),
    stage(3, 6, 24, 2, 2),
    stage(5, 6, 40, 2, 2),
    stage(3, 6, 80, 3, 2),
    stage(5, 6, 112, 3, 1),
    stage(5, 6, 192, 4, 2),
    stage(3, 6, 320, 1, 1),
];

/// Channels of the stem's output, the input of the first block.
const STEM_CHANNELS: usize = 32;

/// Environment variable naming the folder of the pretrained encoder files (default: the
/// repository's `models/encoders`, where this crate was built from).
pub const ENCODERS_ENV: &str = "VPCAL_ENCODERS";

impl MobileFamily {
    fn stages(self) -> &'static [StageSpec; 7] {
        match self {
            MobileFamily::MobilenetV2 => &MOBILENET_V2,
            MobileFamily::EfficientnetLite0 => &EFFICIENTNET_LITE0,
        }
    }

    /// Name used in file names and presets.
    pub fn name(self) -> &'static str {
        match self {
            MobileFamily::MobilenetV2 => "mobilenet_v2",
            MobileFamily::EfficientnetLite0 => "efficientnet_lite0",
        }
    }

    /// Channels of the taps at strides 2, 4, 8, 16 and 32.
    pub fn channels(self) -> [usize; 5] {
        let mut out = [0; 5];
        let mut stride = 2;
        for s in self.stages() {
            stride *= s.stride;
            out[stride.trailing_zeros() as usize - 1] = s.channels;
        }
        out
    }

    /// TensorFlow "SAME" padding (EfficientNet-Lite0) rather than `k / 2` on every side.
    fn tf_same(self) -> bool {
        self == MobileFamily::EfficientnetLite0
    }

    /// What turns RGB `[0, 1]` crops into the input the network was trained on: ImageNet's
    /// mean/std, or TF-Lite's `(255 x - 127) / 128` = `(x - 127/255) / (128/255)`.
    fn input(self) -> InputSpec {
        let normalisation = match self {
            MobileFamily::MobilenetV2 => Normalisation::MeanStd {
                mean: [0.485, 0.456, 0.406],
                std: [0.229, 0.224, 0.225],
            },
            MobileFamily::EfficientnetLite0 => Normalisation::MeanStd {
                mean: [127.0 / 255.0; 3],
                std: [128.0 / 255.0; 3],
            },
        };
        InputSpec {
            channel_order: ChannelOrder::Rgb,
            normalisation,
        }
    }

    /// The pretrained weights file: `$VPCAL_ENCODERS/<name>_backbone.safetensors`, or the
    /// repository's `models/encoders`.
    pub fn weights_path(self) -> PathBuf {
        let dir = std::env::var_os(ENCODERS_ENV).map_or_else(
            || Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models/encoders"),
            PathBuf::from,
        );
        dir.join(format!("{}_backbone.safetensors", self.name()))
    }
}

/// A convolution with bias: `k x k`, stride `stride`, `groups` groups; padded by `k / 2`, or
/// TensorFlow-"SAME" for a stride-2 convolution of an even-sized map when `tf_same`.
fn conv(
    cin: usize,
    cout: usize,
    k: usize,
    stride: usize,
    groups: usize,
    tf_same: bool,
    device: &Device,
) -> Conv2d {
    let p = k / 2;
    let padding = if tf_same && stride == 2 {
        // SAME pads k - 2 in all on an even size: floor half before, the rest after.
        let before = (k - 2) / 2;
        let after = k - 2 - before;
        PaddingConfig2d::Explicit(before, before, after, after)
    } else {
        PaddingConfig2d::Explicit(p, p, p, p)
    };
    Conv2dConfig::new([cin, cout], [k, k])
        .with_stride([stride, stride])
        .with_groups(groups)
        .with_padding(padding)
        .init(device)
}

/// One inverted-residual block (see the module docs).
#[derive(Module, Debug)]
pub struct InvertedResidual {
    expand: Option<Conv2d>,
    depthwise: Conv2d,
    project: Conv2d,
    residual: bool,
}

fn relu6(x: Tensor<4>) -> Tensor<4> {
    x.clamp(0.0, 6.0)
}

impl InvertedResidual {
    /// `[b, cin, h, w]` -> `[b, cout, h / s, w / s]`
    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let mut y = x.clone();
        if let Some(expand) = &self.expand {
            y = relu6(apply(expand, y)); // [b, t cin, h, w]
        }
        let y = relu6(apply(&self.depthwise, y)); // [b, t cin, h/s, w/s]
        let y = apply(&self.project, y); // [b, cout, h/s, w/s]
        if self.residual {
            y + x
        } else {
            y
        }
    }
}

/// MobileNetV2 or EfficientNet-Lite0 up to its stride-32 320-channel block.
#[derive(Module, Debug)]
pub struct MobileNet {
    stem: Conv2d,
    blocks: Vec<InvertedResidual>,
    #[module(skip)]
    family: MobileFamily,
    /// Index of the last block at strides 2, 4, 8, 16 and 32.
    #[module(skip)]
    taps: [usize; 5],
}

impl MobileNet {
    /// A randomly initialised network (burn's default initialisers).
    pub fn new(family: MobileFamily, device: &Device) -> Self {
        let same = family.tf_same();
        let mut blocks = Vec::new();
        let mut taps = [0; 5];
        let (mut cin, mut stride) = (STEM_CHANNELS, 2usize);
        for s in family.stages() {
            for i in 0..s.repeats {
                let st = if i == 0 { s.stride } else { 1 };
                let hidden = cin * s.expand;
                blocks.push(InvertedResidual {
                    expand: (s.expand != 1).then(|| conv(cin, hidden, 1, 1, 1, same, device)),
                    depthwise: conv(hidden, hidden, s.kernel, st, hidden, same, device),
                    project: conv(hidden, s.channels, 1, 1, 1, same, device),
                    residual: st == 1 && cin == s.channels,
                });
                cin = s.channels;
                stride *= st;
                taps[stride.trailing_zeros() as usize - 1] = blocks.len() - 1;
            }
        }
        MobileNet {
            stem: conv(3, STEM_CHANNELS, 3, 2, 1, same, device),
            blocks,
            family,
            taps,
        }
    }

    /// The network with its ImageNet weights, read from [`MobileFamily::weights_path`].
    ///
    /// # Errors
    /// [`NetError::Weights`] naming the file when it cannot be read (with where to find it) or
    /// does not match the module.
    pub fn pretrained(family: MobileFamily, device: &Device) -> Result<Self, NetError> {
        let path = family.weights_path();
        let file = WeightsFile::read(&path).map_err(|e| match e {
            NetError::Io { source, .. } => NetError::Weights {
                path: path.clone(),
                message: format!(
                    "cannot read the pretrained {} encoder ({source}); it is in a vpcal \
                     checkout's models/encoders, or set ${ENCODERS_ENV} to the folder holding it",
                    family.name()
                ),
            },
            other => other,
        })?;
        file.load_into(Self::new(family, device))
    }

    /// Which network this is.
    pub fn family(&self) -> MobileFamily {
        self.family
    }

    /// Features of crops in the VP network's convention.
    ///
    /// # Shapes
    /// - `images`: `[batch, 3, S, S]`, RGB in `[0, 1]`, S a multiple of 32
    /// - output: [`Features`] with the channels of [`MobileFamily::channels`]
    pub fn forward(&self, images: Tensor<4>) -> Features {
        let x = self.family.input().apply(images);
        let mut x = relu6(apply(&self.stem, x)); // [b, 32, S/2, S/2]
        let mut taps: Vec<Tensor<4>> = Vec::with_capacity(5);
        for (i, block) in self.blocks.iter().enumerate() {
            x = block.forward(x);
            if self.taps.contains(&i) {
                taps.push(x.clone());
            }
        }
        let mut taps = taps.into_iter();
        let mut next = || taps.next().unwrap_or_else(|| x.clone());
        Features {
            stem: next(),
            dark2: next(),
            dark3: next(),
            dark4: next(),
            dark5: next(),
        }
    }
}
