//! Throughput measurement of the network (for `vpcal bench-net`; never used by tests).
//!
//! Forward: the validation-mode model on random crops, timed until the heatmaps are read back.
//! Train step: forward with autodiff, MSE on all stacks, backward and an Adam step.
//! Each is run `warmup` times untimed, then `runs` times; the median time is reported.

use std::time::Instant;

use burn::module::Module;
use burn::optim::{AdamConfig, GradientsParams};
use burn::tensor::{Device, Distribution, Tensor};
use serde::Serialize;

use crate::config::{Encoder, ModelConfig};
use crate::encoder::EncoderNet;
use crate::metrics::median;
use crate::model::StackedHourglass;
use crate::network::to_vec;
use crate::NetError;

/// What to measure.
#[derive(Debug, Clone)]
pub struct BenchOptions {
    pub forward_batch: usize,
    pub train_batch: usize,
    pub warmup: usize,
    pub runs: usize,
}

impl Default for BenchOptions {
    fn default() -> Self {
        BenchOptions {
            forward_batch: 10,
            train_batch: 8,
            warmup: 1,
            runs: 3,
        }
    }
}

/// Measured times (seconds, median over runs) and throughputs.
#[derive(Debug, Clone, Serialize)]
pub struct BenchResult {
    pub params: usize,
    pub forward_batch: usize,
    pub forward_s: f64,
    pub forward_crops_per_s: f64,
    pub train_batch: usize,
    pub train_step_s: f64,
    pub train_crops_per_s: f64,
    pub forward_runs_s: Vec<f64>,
    pub train_runs_s: Vec<f64>,
}

fn time<F: FnMut() -> Result<(), NetError>>(
    warmup: usize,
    runs: usize,
    mut f: F,
) -> Result<Vec<f64>, NetError> {
    for _ in 0..warmup {
        f()?;
    }
    let mut out = Vec::with_capacity(runs);
    for _ in 0..runs.max(1) {
        let t = Instant::now();
        f()?;
        out.push(t.elapsed().as_secs_f64());
    }
    Ok(out)
}

/// The heatmap networks' forward pass, for timing either.
trait Heatmaps: Module + Clone + 'static {
    fn heatmaps(&self, images: Tensor<4>) -> Vec<Tensor<4>>;
}

impl Heatmaps for StackedHourglass {
    fn heatmaps(&self, images: Tensor<4>) -> Vec<Tensor<4>> {
        self.forward(images)
    }
}

impl Heatmaps for EncoderNet {
    fn heatmaps(&self, images: Tensor<4>) -> Vec<Tensor<4>> {
        self.forward(images)
    }
}

/// Benchmark `config` on `device` (a plain, non-autodiff device): the stacked hourglass, or
/// the pretrained-encoder network for the other encoders (randomly initialised here; the
/// time does not depend on the weights).
///
/// # Errors
/// [`NetError::Config`] for an invalid config; [`NetError::Tensor`] when outputs cannot be read.
pub fn run(
    config: &ModelConfig,
    device: &Device,
    opts: &BenchOptions,
) -> Result<BenchResult, NetError> {
    config.validate()?;
    device.seed(0);
    match config.encoder {
        Encoder::Hourglass => {
            run_model(StackedHourglass::new(config, device), config, device, opts)
        }
        Encoder::YoloxNano | Encoder::MobilenetV2 | Encoder::EfficientnetLite0 => {
            run_model(EncoderNet::new(config, device), config, device, opts)
        }
    }
}

fn run_model<M: Heatmaps>(
    model: M,
    config: &ModelConfig,
    device: &Device,
    opts: &BenchOptions,
) -> Result<BenchResult, NetError> {
    let s = config.input_size;
    let r = config.heatmap_size;
    let params = model.num_params();

    let eval = model.valid();
    let x = Tensor::<4>::random([opts.forward_batch, 3, s, s], Distribution::Default, device);
    let forward_runs = time(opts.warmup, opts.runs, || {
        let outs = eval.heatmaps(x.clone());
        match outs.into_iter().last() {
            Some(out) => to_vec(out).map(|_| ()),
            None => Err(NetError::Config("model has no output".into())),
        }
    })?;

    let ad = device.clone().autodiff();
    let mut train_model = model.to_device(&ad).train();
    let mut optim = AdamConfig::new().init();
    let xb = Tensor::<4>::random([opts.train_batch, 3, s, s], Distribution::Default, &ad);
    let yb = Tensor::<4>::random(
        [opts.train_batch, config.outputs(), r, r],
        Distribution::Default,
        &ad,
    );
    let train_runs = time(opts.warmup, opts.runs, || {
        let outs = train_model.heatmaps(xb.clone());
        let mut loss: Option<Tensor<1>> = None;
        for o in outs {
            let l = (o - yb.clone()).square().mean();
            loss = Some(match loss {
                Some(acc) => acc + l,
                None => l,
            });
        }
        let Some(loss) = loss else {
            return Err(NetError::Config("model has no stacks".into()));
        };
        let grads = loss.backward();
        let grads = GradientsParams::from_grads(grads, &train_model);
        train_model = optim.step(1e-3, train_model.clone(), grads);
        // Read one parameter-dependent value back so that the step has really run.
        to_vec(loss).map(|_| ())
    })?;
    let fwd = median(&forward_runs).unwrap_or(f64::NAN);
    let trn = median(&train_runs).unwrap_or(f64::NAN);
    Ok(BenchResult {
        params,
        forward_batch: opts.forward_batch,
        forward_s: fwd,
        forward_crops_per_s: opts.forward_batch as f64 / fwd,
        train_batch: opts.train_batch,
        train_step_s: trn,
        train_crops_per_s: opts.train_batch as f64 / trn,
        forward_runs_s: forward_runs,
        train_runs_s: train_runs,
    })
}
