//! The network's size and input conventions, saved with every checkpoint.
//!
//! A [`ModelConfig`] builds a [`StackedHourglass`](crate::StackedHourglass) and travels with its
//! weights (safetensors metadata and `config.json`), so a checkpoint always says how its input
//! must be prepared (size, channel order, normalisation) and how its heatmaps are decoded
//! (resolution, scales).

use serde::{Deserialize, Serialize};

use crate::mobile::MobileFamily;
use crate::NetError;

/// Order of the colour channels the network was trained on.
///
/// Crops enter the crate as RGB; the model swaps them to BGR itself when its config says so
/// (the reference Keras models were trained on OpenCV's BGR images).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ChannelOrder {
    Rgb,
    Bgr,
}

/// How 8-bit pixel values become network input values.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum Normalisation {
    /// `value / 255` (the paper and the reference code).
    Unit,
    /// `(value / 255 - mean[c]) / std[c]` per channel, in the model's channel order.
    MeanStd { mean: [f32; 3], std: [f32; 3] },
}

/// The feature extractor in front of the heatmap outputs.
///
/// Checkpoints written before this field existed lack it and load as [`Encoder::Hourglass`];
/// hourglass configs are still written without it, so their JSON is unchanged.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Encoder {
    /// The paper's stacked hourglass ([`StackedHourglass`](crate::StackedHourglass)), trained
    /// from scratch.
    #[default]
    Hourglass,
    /// The backbone of the COCO-pretrained YOLOX-nano detector with an FPN-lite decoder
    /// ([`EncoderNet`](crate::encoder::EncoderNet)).
    YoloxNano,
    /// ImageNet-pretrained MobileNetV2 1.0 with the same decoder
    /// ([`MobileNet`](crate::mobile::MobileNet)).
    MobilenetV2,
    /// ImageNet-pretrained EfficientNet-Lite0 with the same decoder
    /// ([`MobileNet`](crate::mobile::MobileNet)).
    EfficientnetLite0,
}

impl Encoder {
    /// Whether this is the default, [`Encoder::Hourglass`] (serde's `skip_serializing_if`).
    pub fn is_hourglass(&self) -> bool {
        *self == Encoder::Hourglass
    }

    /// The inverted-residual network of [`Encoder::MobilenetV2`] and
    /// [`Encoder::EfficientnetLite0`].
    pub fn mobile_family(self) -> Option<MobileFamily> {
        match self {
            Encoder::MobilenetV2 => Some(MobileFamily::MobilenetV2),
            Encoder::EfficientnetLite0 => Some(MobileFamily::EfficientnetLite0),
            Encoder::Hourglass | Encoder::YoloxNano => None,
        }
    }

    /// Name in configs and presets (`yolox_nano`, `mobilenet_v2`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Encoder::Hourglass => "hourglass",
            Encoder::YoloxNano => "yolox_nano",
            Encoder::MobilenetV2 => "mobilenet_v2",
            Encoder::EfficientnetLite0 => "efficientnet_lite0",
        }
    }
}

/// Size, layout and input conventions of the VP network: the stacked hourglass of DESIGN.md §5
/// or, with [`Encoder::YoloxNano`], the pretrained-encoder network
/// ([`EncoderNet`](crate::encoder::EncoderNet)), which uses `input_size`, `heatmap_size`,
/// `channels` (decoder width), `scales` and the batch-norm settings, and requires `stacks` 1,
/// RGB order and unit normalisation (the encoder converts to the detector's BGR 0-255 itself).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelConfig {
    /// The feature extractor (absent in older checkpoints: the hourglass).
    #[serde(default, skip_serializing_if = "Encoder::is_hourglass")]
    pub encoder: Encoder,
    /// Side of the square input crop, pixels (paper: 128).
    pub input_size: usize,
    /// Side of the square output heatmaps, pixels (paper: 64). `input_size / heatmap_size`
    /// must be a power of two; the front module max-pools that many times.
    pub heatmap_size: usize,
    /// Number of hourglass stacks, each supervised (paper: 2).
    pub stacks: usize,
    /// Channels of the front 7x7 convolution (paper: 64).
    pub front_channels: usize,
    /// Channels inside the hourglasses (paper: 256). Must be even.
    pub channels: usize,
    /// Resolution levels of each hourglass (paper: 4, i.e. 64 -> 32 -> 16 -> 8).
    pub depth: usize,
    /// Diamond-space scales of the heatmaps, one channel per scale and VP
    /// (paper: 0.03, 0.1, 0.3, 1.0). Output channels: VP1 at each scale, then VP2.
    pub scales: Vec<f64>,
    /// Channel order of the input the model was trained on.
    pub channel_order: ChannelOrder,
    /// Input normalisation.
    pub normalisation: Normalisation,
    /// Batch-norm momentum in burn's convention (weight of the new batch statistic; Keras'
    /// 0.99 is 0.01 here).
    pub bn_momentum: f64,
    /// Batch-norm epsilon.
    pub bn_epsilon: f64,
}

impl ModelConfig {
    /// The paper's network: 128x128 input, 2 stacks of 4-level hourglasses with 256 channels,
    /// 8 heatmaps of 64x64 (DESIGN.md §5). 6,596,496 parameters counted as Keras counts them
    /// (batch-norm running statistics included; see [`StackedHourglass::new`](crate::StackedHourglass::new)).
    pub fn paper() -> Self {
        ModelConfig {
            encoder: Encoder::Hourglass,
            input_size: 128,
            heatmap_size: 64,
            stacks: 2,
            front_channels: 64,
            channels: 256,
            depth: 4,
            scales: vec![0.03, 0.1, 0.3, 1.0],
            channel_order: ChannelOrder::Rgb,
            normalisation: Normalisation::Unit,
            bn_momentum: 0.1,
            bn_epsilon: 1e-3,
        }
    }

    /// The smallest network of the same architecture, for tests, CI and smoke runs: 32x32
    /// input, 16x16 heatmaps, 2 stacks of 2-level hourglasses with 16 channels, the paper's
    /// scales (20,096 parameters). Too coarse for real calibration.
    pub fn tiny() -> Self {
        ModelConfig {
            input_size: 32,
            heatmap_size: 16,
            stacks: 2,
            front_channels: 8,
            channels: 16,
            depth: 2,
            ..Self::paper()
        }
    }

    /// A CPU-trainable network for experiments: 64x64 input, 32x32 heatmaps, 2 stacks of
    /// 3-level hourglasses with 32 channels, the paper's scales (92,848 parameters).
    pub fn small() -> Self {
        ModelConfig {
            input_size: 64,
            heatmap_size: 32,
            stacks: 2,
            front_channels: 16,
            channels: 32,
            depth: 3,
            ..Self::paper()
        }
    }

    /// The pretrained-encoder network: the YOLOX-nano backbone (COCO weights, 0.46 M
    /// parameters) on 128x128 crops, an FPN-lite decoder of width 64 down to stride 4, 32x32
    /// heatmaps at the paper's scales.
    pub fn yolox_nano() -> Self {
        ModelConfig {
            encoder: Encoder::YoloxNano,
            input_size: 128,
            heatmap_size: 32,
            stacks: 1,
            front_channels: 0,
            channels: 64,
            depth: 0,
            ..Self::paper()
        }
    }

    /// The pretrained-encoder network of [`ModelConfig::yolox_nano`] with another pretrained
    /// backbone (`encoder` must not be [`Encoder::Hourglass`]).
    pub fn pretrained(encoder: Encoder) -> Self {
        ModelConfig {
            encoder,
            ..Self::yolox_nano()
        }
    }

    /// Names accepted by [`ModelConfig::preset`].
    pub const PRESETS: [&'static str; 6] = [
        "paper",
        "small",
        "tiny",
        "yolox_nano",
        "mobilenet_v2",
        "efficientnet_lite0",
    ];

    /// A preset by name: `paper`, `small`, `tiny`, or a pretrained encoder (`yolox_nano`,
    /// `mobilenet_v2`, `efficientnet_lite0`) with the decoder of [`ModelConfig::yolox_nano`].
    ///
    /// # Errors
    /// [`NetError::Config`] for any other name.
    pub fn preset(name: &str) -> Result<Self, NetError> {
        match name {
            "paper" => Ok(Self::paper()),
            "small" => Ok(Self::small()),
            "tiny" => Ok(Self::tiny()),
            "yolox_nano" => Ok(Self::yolox_nano()),
            "mobilenet_v2" => Ok(Self::pretrained(Encoder::MobilenetV2)),
            "efficientnet_lite0" => Ok(Self::pretrained(Encoder::EfficientnetLite0)),
            other => Err(NetError::Config(format!(
                "unknown model preset {other:?} (expected one of {:?})",
                Self::PRESETS
            ))),
        }
    }

    /// Number of output heatmaps: `2 * scales.len()`.
    pub fn outputs(&self) -> usize {
        2 * self.scales.len()
    }

    /// Number of 2x2 max-pools in the front module: `log2(input_size / heatmap_size)`.
    pub fn front_pools(&self) -> usize {
        (self.input_size / self.heatmap_size.max(1)).trailing_zeros() as usize
    }

    /// The heatmap codec matching this network's output.
    pub fn codec(&self) -> vpcal_geom::heatmap::HeatmapCodec {
        vpcal_geom::heatmap::HeatmapCodec {
            resolution: self.heatmap_size,
            scales: self.scales.clone(),
        }
    }

    /// Check that the sizes fit together.
    ///
    /// # Errors
    /// [`NetError::Config`] naming the offending field and value.
    pub fn validate(&self) -> Result<(), NetError> {
        let bad = |msg: String| Err(NetError::Config(msg));
        if self.input_size == 0 || self.heatmap_size == 0 {
            return bad(format!(
                "input_size {} and heatmap_size {} must be positive",
                self.input_size, self.heatmap_size
            ));
        }
        let ratio = self.input_size / self.heatmap_size;
        if !self.input_size.is_multiple_of(self.heatmap_size) || !ratio.is_power_of_two() {
            return bad(format!(
                "input_size {} must be heatmap_size {} times a power of two",
                self.input_size, self.heatmap_size
            ));
        }
        self.validate_common()?;
        if !self.encoder.is_hourglass() {
            return self.validate_pretrained();
        }
        if self.stacks == 0 || self.depth == 0 {
            return bad(format!(
                "stacks {} and depth {} must be at least 1",
                self.stacks, self.depth
            ));
        }
        let levels = 1usize << (self.depth - 1);
        if !self.heatmap_size.is_multiple_of(levels) {
            return bad(format!(
                "heatmap_size {} must be divisible by 2^(depth-1) = {levels} (depth {})",
                self.heatmap_size, self.depth
            ));
        }
        if self.channels < 2 || !self.channels.is_multiple_of(2) || self.front_channels < 2 {
            return bad(format!(
                "channels {} must be even and >= 2, front_channels {} >= 2",
                self.channels, self.front_channels
            ));
        }
        if self.channels < 4 || !(self.channels / 2).is_multiple_of(2) {
            return bad(format!(
                "channels {} must be a multiple of 4 (the front blocks use channels / 2)",
                self.channels
            ));
        }
        Ok(())
    }

    /// Checks shared by every encoder: scales, batch norm, normalisation.
    fn validate_common(&self) -> Result<(), NetError> {
        let bad = |msg: String| Err(NetError::Config(msg));
        if self.scales.is_empty() || self.scales.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
            return bad(format!(
                "scales {:?} must be non-empty, finite and positive",
                self.scales
            ));
        }
        if !(self.bn_momentum.is_finite() && (0.0..=1.0).contains(&self.bn_momentum)) {
            return bad(format!(
                "bn_momentum {} must be in [0, 1]",
                self.bn_momentum
            ));
        }
        if !(self.bn_epsilon.is_finite() && self.bn_epsilon > 0.0) {
            return bad(format!("bn_epsilon {} must be positive", self.bn_epsilon));
        }
        if let Normalisation::MeanStd { std, .. } = &self.normalisation {
            if std.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
                return bad(format!("normalisation std {std:?} must be positive"));
            }
        }
        Ok(())
    }

    /// Checks of the pretrained-encoder network (see [`Encoder::YoloxNano`]).
    fn validate_pretrained(&self) -> Result<(), NetError> {
        let bad = |msg: String| Err(NetError::Config(msg));
        let name = self.encoder.name();
        let stride = self.input_size / self.heatmap_size;
        if !(2..=32).contains(&stride) || !self.input_size.is_multiple_of(32) {
            return bad(format!(
                "encoder {name}: input_size {} must be a multiple of 32 and heatmap_size {} \
                 1/2 to 1/32 of it (a backbone stride: 2, 4, 8, 16 or 32)",
                self.input_size, self.heatmap_size
            ));
        }
        if self.stacks != 1 {
            return bad(format!(
                "encoder {name}: stacks {} must be 1 (one heatmap output)",
                self.stacks
            ));
        }
        if self.channels == 0 {
            return bad(format!(
                "encoder {name}: channels (decoder width) must be positive"
            ));
        }
        if self.channel_order != ChannelOrder::Rgb || self.normalisation != Normalisation::Unit {
            return bad(format!(
                "encoder {name}: channel_order {:?} and normalisation {:?} must be rgb and \
                 unit (the encoder converts crops to its own input convention itself)",
                self.channel_order, self.normalisation
            ));
        }
        Ok(())
    }

    /// Fields in which `self` and `other` differ, as `name: self vs other` lines (empty when equal).
    pub fn differences(&self, other: &ModelConfig) -> Vec<String> {
        let mut out = Vec::new();
        macro_rules! cmp {
            ($($f:ident),*) => {$(
                if self.$f != other.$f {
                    out.push(format!("{}: {:?} vs {:?}", stringify!($f), self.$f, other.$f));
                }
            )*};
        }
        cmp!(
            encoder,
            input_size,
            heatmap_size,
            stacks,
            front_channels,
            channels,
            depth,
            scales,
            channel_order,
            normalisation,
            bn_momentum,
            bn_epsilon
        );
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_validate() {
        for name in ModelConfig::PRESETS {
            ModelConfig::preset(name).unwrap().validate().unwrap();
        }
        assert_eq!(ModelConfig::paper().outputs(), 8);
        assert_eq!(ModelConfig::paper().front_pools(), 1);
    }

    #[test]
    fn bad_sizes_are_refused_with_the_field() {
        let mut c = ModelConfig::paper();
        c.heatmap_size = 48;
        let err = c.validate().unwrap_err().to_string();
        assert!(err.contains("input_size 128"), "{err}");
        let mut c = ModelConfig::paper();
        c.depth = 8;
        let err = c.validate().unwrap_err().to_string();
        assert!(err.contains("depth 8"), "{err}");
        assert!(ModelConfig::preset("huge").is_err());
    }

    #[test]
    fn configs_without_an_encoder_are_the_hourglass_and_stay_unchanged() {
        let text = serde_json::to_string(&ModelConfig::small()).unwrap();
        assert!(!text.contains("encoder"), "{text}");
        let back: ModelConfig = serde_json::from_str(&text).unwrap();
        assert_eq!(back.encoder, Encoder::Hourglass);
        let y = ModelConfig::yolox_nano();
        let text = serde_json::to_string(&y).unwrap();
        assert!(text.contains(r#""encoder":"yolox_nano""#), "{text}");
        assert_eq!(serde_json::from_str::<ModelConfig>(&text).unwrap(), y);
        let d = ModelConfig::small().differences(&y);
        assert!(d.iter().any(|l| l.starts_with("encoder: ")), "{d:?}");
        for name in ["mobilenet_v2", "efficientnet_lite0"] {
            let c = ModelConfig::preset(name).unwrap();
            assert_eq!(c.encoder.name(), name);
            let text = serde_json::to_string(&c).unwrap();
            assert!(text.contains(&format!(r#""encoder":"{name}""#)), "{text}");
            assert_eq!(serde_json::from_str::<ModelConfig>(&text).unwrap(), c);
        }
    }

    #[test]
    fn yolox_configs_are_checked() {
        let mut c = ModelConfig::yolox_nano();
        c.heatmap_size = 128;
        let err = c.validate().unwrap_err().to_string();
        assert!(err.contains("heatmap_size 128"), "{err}");
        let mut c = ModelConfig::yolox_nano();
        c.channel_order = ChannelOrder::Bgr;
        let err = c.validate().unwrap_err().to_string();
        assert!(err.contains("rgb and unit"), "{err}");
        let mut c = ModelConfig::yolox_nano();
        c.input_size = 64;
        c.heatmap_size = 2;
        c.validate().unwrap();
    }

    #[test]
    fn config_json_round_trip_and_differences() {
        let c = ModelConfig::tiny();
        let text = serde_json::to_string(&c).unwrap();
        let back: ModelConfig = serde_json::from_str(&text).unwrap();
        assert_eq!(back, c);
        let d = ModelConfig::paper().differences(&c);
        assert!(
            d.iter().any(|l| l.starts_with("channels: 256 vs 16")),
            "{d:?}"
        );
    }
}
