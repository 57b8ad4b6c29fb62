//! What the trainer needs from a network: the [`VpNetwork`] trait, implemented by the heatmap
//! models ([`StackedHourglass`], [`EncoderNet`]) and the regression baselines
//! ([`Regressor`](crate::regression::Regressor)).

use burn::module::Module;
use burn::tensor::{Device, Tensor, TensorData};
use serde::de::DeserializeOwned;
use serde::Serialize;
use vpcal_data::Batch;
use vpcal_geom::heatmap::{DecodeMode, HeatmapCodec};
use vpcal_geom::Point2;

use crate::config::{Encoder, ModelConfig};
use crate::encoder::{Backbone, EncoderNet};
use crate::metrics::VpErrorAccumulator;
use crate::model::StackedHourglass;
use crate::NetError;

/// A trainable VP network with a serialisable config.
pub trait VpNetwork: Module + Clone + core::fmt::Debug + 'static {
    /// The config saved with every checkpoint.
    type Config: Serialize + DeserializeOwned + Clone + core::fmt::Debug + PartialEq;

    /// Short name of the architecture, stored in checkpoints (`stacked_hourglass`, ...).
    const KIND: &'static str;

    /// Check the config.
    ///
    /// # Errors
    /// [`NetError::Config`] naming the offending field.
    fn validate_config(config: &Self::Config) -> Result<(), NetError>;

    /// How messages name a network of this config: [`VpNetwork::KIND`] unless the kind has
    /// variants a reader would want to tell apart.
    fn describe(_config: &Self::Config) -> String {
        Self::KIND.to_string()
    }

    /// A freshly initialised network.
    fn init(config: &Self::Config, device: &Device) -> Self;

    /// Load the pretrained parts of a freshly initialised network (a new training run from
    /// scratch calls it after [`VpNetwork::init`]; loading a checkpoint does not need it). The
    /// default has none and returns the network unchanged.
    ///
    /// # Errors
    /// [`NetError::Weights`] when the pretrained weights do not fit.
    fn load_pretrained(self, _config: &Self::Config) -> Result<Self, NetError> {
        Ok(self)
    }

    /// Freeze (`true`) or unfreeze a pretrained encoder: frozen, no gradient reaches it and
    /// the optimizer leaves it unchanged. The default (networks without one) accepts `false`
    /// only.
    ///
    /// # Errors
    /// [`NetError::Config`] when asked to freeze a network without a pretrained encoder.
    fn freeze_encoder(self, frozen: bool) -> Result<Self, NetError> {
        if frozen {
            return Err(NetError::Config(format!(
                "a {:?} network has no pretrained encoder to freeze",
                Self::KIND
            )));
        }
        Ok(self)
    }

    /// Input crop side, pixels.
    fn input_size(config: &Self::Config) -> usize;

    /// The codec of the heatmap targets the batches must carry (regression models ignore
    /// targets and ask for a small one).
    fn target_codec(config: &Self::Config) -> HeatmapCodec;

    /// Number of parameters, batch-norm running statistics included.
    fn param_count(&self) -> usize {
        self.num_params()
    }

    /// Check that a batch fits this network (input size, target layout).
    ///
    /// # Errors
    /// [`NetError::Input`] naming the mismatching field with both values.
    fn check_batch(config: &Self::Config, batch: &Batch) -> Result<(), NetError>;

    /// The loss terms of a batch, `[terms]` (their sum is minimised); for the heatmap model one
    /// MSE per stack. `fg_weight` weights each heatmap pixel's squared error by
    /// `1 + fg_weight * target` (0 = the paper's plain MSE); the regression models ignore it.
    ///
    /// # Shapes
    /// - `images`: `[batch, 3, input, input]`
    /// - output: `[terms]`
    fn loss_terms(
        &self,
        config: &Self::Config,
        images: Tensor<4>,
        batch: &Batch,
        fg_weight: f64,
    ) -> Tensor<1>;

    /// Validation on a batch with a validation-mode network (`Module::valid`): returns the
    /// loss terms and adds the VP errors to `acc`.
    ///
    /// # Errors
    /// [`NetError::Tensor`] when an output cannot be read back.
    fn evaluate(
        &self,
        config: &Self::Config,
        images: Tensor<4>,
        batch: &Batch,
        acc: &mut VpErrorAccumulator,
    ) -> Result<Vec<f32>, NetError>;
}

/// Batch images as a tensor on `device`.
///
/// # Errors
/// [`NetError::Input`] when `images.len()` does not match `size * 3 * input * input`.
pub fn images_tensor(batch: &Batch, device: &Device) -> Result<Tensor<4>, NetError> {
    let (n, s) = (batch.size, batch.input_size);
    if batch.images.len() != n * 3 * s * s {
        return Err(NetError::Input(format!(
            "batch images hold {} values, expected size {n} x 3 x {s} x {s} = {}",
            batch.images.len(),
            n * 3 * s * s
        )));
    }
    Ok(Tensor::from_data(
        TensorData::new(batch.images.clone(), [n, 3, s, s]),
        device,
    ))
}

/// Read a float tensor back as f32 values.
///
/// # Errors
/// [`NetError::Tensor`] when the data cannot be converted.
pub fn to_vec<const D: usize>(t: Tensor<D>) -> Result<Vec<f32>, NetError> {
    t.into_data()
        .convert::<f32>()
        .try_to_vec::<f32>()
        .map_err(|e| NetError::Tensor(format!("{e:?}")))
}

/// MSE of every stack's heatmaps against the targets, `[stacks]`; with `fg_weight > 0` each
/// pixel's squared error is weighted by `1 + fg_weight * target`, so the few pixels of the
/// Gaussian peaks are not drowned by the empty background. `labels`, when given, weighs each
/// heatmap by its sample's label weight (`Batch::weights`, shape `[b, k]`).
fn heatmap_losses(
    outs: Vec<Tensor<4>>,
    targets: Tensor<4>,
    fg_weight: f64,
    labels: Option<Tensor<4>>,
) -> Tensor<1> {
    let fg = (fg_weight > 0.0).then(|| targets.clone().mul_scalar(fg_weight).add_scalar(1.0));
    let weights = match (fg, labels) {
        (Some(fg), Some(l)) => Some(fg * l),
        (None, Some(l)) => Some(l),
        (fg, None) => fg,
    };
    let terms: Vec<Tensor<1>> = outs
        .into_iter()
        .map(|o| {
            let sq = (o - targets.clone()).square(); // [b, k, r, r]
            match &weights {
                Some(w) => (sq * w.clone()).mean(),
                None => sq.mean(),
            } // [1]
        })
        .collect();
    Tensor::cat(terms, 0) // [stacks]
}

/// The batch's label weights spread over each heatmap, `[b, k, r, r]`; `None` when every
/// label is exact (the loss is then exactly the unweighted one).
fn label_weights_tensor(batch: &Batch, device: &Device) -> Option<Tensor<4>> {
    if !batch.is_weighted() {
        return None;
    }
    let r = batch.heatmap_res;
    let plane = r * r;
    let mut w = Vec::with_capacity(batch.weights.len() * plane);
    for &v in &batch.weights {
        w.extend(std::iter::repeat_n(v, plane));
    }
    Some(Tensor::from_data(
        TensorData::new(w, [batch.size, batch.channels, r, r]),
        device,
    ))
}

fn targets_tensor(batch: &Batch, device: &Device) -> Tensor<4> {
    let r = batch.heatmap_res;
    Tensor::from_data(
        TensorData::new(batch.targets.clone(), [batch.size, batch.channels, r, r]),
        device,
    )
}

/// `check_batch` of the heatmap networks: input size, heatmap resolution, channels, lengths.
fn check_heatmap_batch(config: &ModelConfig, batch: &Batch) -> Result<(), NetError> {
    let checks = [
        ("input_size", batch.input_size, config.input_size),
        ("heatmap_res", batch.heatmap_res, config.heatmap_size),
        ("channels", batch.channels, config.outputs()),
    ];
    for (name, got, want) in checks {
        if got != want {
            return Err(NetError::Input(format!(
                "batch {name} is {got}, the model expects {want}"
            )));
        }
    }
    let r = config.heatmap_size;
    if batch.targets.len() != batch.size * config.outputs() * r * r
        || batch.vp1_box.len() != batch.size
        || batch.vp2_box.len() != batch.size
    {
        return Err(NetError::Input(format!(
            "batch of {} crops holds {} target values, {} VP1s and {} VP2s (expected {}, {}, {})",
            batch.size,
            batch.targets.len(),
            batch.vp1_box.len(),
            batch.vp2_box.len(),
            batch.size * config.outputs() * r * r,
            batch.size,
            batch.size
        )));
    }
    Ok(())
}

/// `loss_terms` of the heatmap networks, given their outputs.
fn heatmap_loss_terms(outs: Vec<Tensor<4>>, batch: &Batch, fg_weight: f64) -> Tensor<1> {
    let Some(device) = outs.first().map(Tensor::device) else {
        return Tensor::zeros([0], &Device::flex());
    };
    let targets = targets_tensor(batch, &device); // [b, k, r, r]
    let labels = label_weights_tensor(batch, &device);
    heatmap_losses(outs, targets, fg_weight, labels)
}

/// `evaluate` of the heatmap networks, given their outputs (the last one is decoded).
fn heatmap_evaluate(
    config: &ModelConfig,
    outs: Vec<Tensor<4>>,
    batch: &Batch,
    acc: &mut VpErrorAccumulator,
) -> Result<Vec<f32>, NetError> {
    let Some(last) = outs.last().cloned() else {
        return Ok(Vec::new());
    };
    let targets = targets_tensor(batch, &last.device());
    let terms = to_vec(heatmap_losses(outs, targets, 0.0, None))?;
    let heat = to_vec(last)?;
    let codec = config.codec();
    let per = codec.channels() * codec.resolution * codec.resolution;
    for (i, chunk) in heat.chunks_exact(per).enumerate() {
        let pred = codec.decode(chunk, DecodeMode::Centre);
        acc.add(
            &pred,
            Point2::from(batch.vp1_box[i]),
            Point2::from(batch.vp2_box[i]),
        );
    }
    Ok(terms)
}

/// The config's encoder must be the hourglass (`pretrained` false) or a pretrained one (true)
/// for the network `kind`.
fn require_encoder(config: &ModelConfig, pretrained: bool, kind: &str) -> Result<(), NetError> {
    if config.encoder.is_hourglass() == pretrained {
        let want = if pretrained {
            "a pretrained encoder".to_string()
        } else {
            format!("{:?}", Encoder::Hourglass)
        };
        return Err(NetError::Config(format!(
            "encoder {:?} is not built by a {kind:?} network (expected {want})",
            config.encoder
        )));
    }
    Ok(())
}

impl VpNetwork for StackedHourglass {
    type Config = ModelConfig;
    const KIND: &'static str = "stacked_hourglass";

    fn validate_config(config: &ModelConfig) -> Result<(), NetError> {
        require_encoder(config, false, Self::KIND)?;
        config.validate()
    }

    fn init(config: &ModelConfig, device: &Device) -> Self {
        StackedHourglass::new(config, device)
    }

    fn input_size(config: &ModelConfig) -> usize {
        config.input_size
    }

    fn target_codec(config: &ModelConfig) -> HeatmapCodec {
        config.codec()
    }

    fn check_batch(config: &ModelConfig, batch: &Batch) -> Result<(), NetError> {
        check_heatmap_batch(config, batch)
    }

    fn loss_terms(
        &self,
        _config: &ModelConfig,
        images: Tensor<4>,
        batch: &Batch,
        fg_weight: f64,
    ) -> Tensor<1> {
        heatmap_loss_terms(self.forward(images), batch, fg_weight)
    }

    fn evaluate(
        &self,
        config: &ModelConfig,
        images: Tensor<4>,
        batch: &Batch,
        acc: &mut VpErrorAccumulator,
    ) -> Result<Vec<f32>, NetError> {
        heatmap_evaluate(config, self.forward(images), batch, acc)
    }
}

impl VpNetwork for EncoderNet {
    type Config = ModelConfig;
    const KIND: &'static str = "yolox_nano_fpn";

    fn validate_config(config: &ModelConfig) -> Result<(), NetError> {
        require_encoder(config, true, Self::KIND)?;
        config.validate()
    }

    /// The kind with its encoder: checkpoints of every pretrained encoder share the kind.
    fn describe(config: &ModelConfig) -> String {
        format!("{} with the {} encoder", Self::KIND, config.encoder.name())
    }

    /// A random network; [`VpNetwork::load_pretrained`] loads the encoder's pretrained
    /// weights (COCO or ImageNet).
    fn init(config: &ModelConfig, device: &Device) -> Self {
        EncoderNet::new(config, device)
    }

    fn load_pretrained(self, config: &ModelConfig) -> Result<Self, NetError> {
        let device = self.devices().first().cloned().unwrap_or_else(Device::flex);
        // Loaded on the plain device: moved to an autodiff device, its tensors become leaves.
        let encoder = Backbone::pretrained(config.encoder, &device.clone().without_autodiff())?
            .to_device(&device);
        Ok(self.with_encoder(encoder))
    }

    fn freeze_encoder(self, frozen: bool) -> Result<Self, NetError> {
        Ok(self.with_frozen_encoder(frozen))
    }

    fn input_size(config: &ModelConfig) -> usize {
        config.input_size
    }

    fn target_codec(config: &ModelConfig) -> HeatmapCodec {
        config.codec()
    }

    fn check_batch(config: &ModelConfig, batch: &Batch) -> Result<(), NetError> {
        check_heatmap_batch(config, batch)
    }

    fn loss_terms(
        &self,
        _config: &ModelConfig,
        images: Tensor<4>,
        batch: &Batch,
        fg_weight: f64,
    ) -> Tensor<1> {
        heatmap_loss_terms(self.forward(images), batch, fg_weight)
    }

    fn evaluate(
        &self,
        config: &ModelConfig,
        images: Tensor<4>,
        batch: &Batch,
        acc: &mut VpErrorAccumulator,
    ) -> Result<Vec<f32>, NetError> {
        heatmap_evaluate(config, self.forward(images), batch, acc)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn tensor(values: Vec<f32>, shape: [usize; 4]) -> Tensor<4> {
        Tensor::from_data(TensorData::new(values, shape), &Device::flex())
    }

    fn batch_with(weights: Vec<f32>) -> Batch {
        Batch {
            size: 2,
            input_size: 1,
            images: vec![0.0; 6],
            channels: 2,
            heatmap_res: 2,
            targets: vec![0.0; 16],
            vp1_box: vec![[0.0, 0.0]; 2],
            vp2_box: vec![[0.0, 0.0]; 2],
            ids: Vec::new(),
            weights,
        }
    }

    #[test]
    fn label_weights_scale_each_heatmap_and_exact_labels_change_nothing() {
        // Two samples, two heatmaps (VP1, VP2) of 2x2: errors 1 everywhere in sample 0, 2 in
        // sample 1.
        let out: Vec<f32> = [vec![1.0; 8], vec![2.0; 8]].concat();
        let shape = [2, 2, 2, 2];
        let targets = tensor(vec![0.0; 16], shape);
        let loss = |b: &Batch| {
            let labels = label_weights_tensor(b, &Device::flex());
            let l = heatmap_losses(
                vec![tensor(out.clone(), shape)],
                targets.clone(),
                0.0,
                labels,
            );
            to_vec(l).unwrap()[0]
        };
        let exact = batch_with(vec![1.0; 4]);
        assert!(label_weights_tensor(&exact, &Device::flex()).is_none());
        assert!((loss(&exact) - (8.0 * 1.0 + 8.0 * 4.0) / 16.0).abs() < 1e-6);
        // Sample 1 does not count at all; sample 0's VP2 counts half.
        let weighted = batch_with(vec![1.0, 0.5, 0.0, 0.0]);
        assert!((loss(&weighted) - (4.0 + 4.0 * 0.5) / 16.0).abs() < 1e-6);
        // With the foreground weight too, both multiply.
        let t: Vec<f32> = (0..16)
            .map(|i| if i % 4 == 0 { 1.0 } else { 0.0 })
            .collect();
        let targets = tensor(t.clone(), shape);
        let labels = label_weights_tensor(&weighted, &Device::flex());
        let l = heatmap_losses(vec![tensor(out.clone(), shape)], targets, 9.0, labels);
        let mut expect = 0.0;
        for (i, tv) in t.iter().enumerate() {
            let w = [1.0, 0.5, 0.0, 0.0][i / 4] * (1.0 + 9.0 * tv);
            expect += w * (out[i] - tv).powi(2);
        }
        assert!((to_vec(l).unwrap()[0] - expect / 16.0).abs() < 1e-5);
    }
}
