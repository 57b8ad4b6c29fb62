//! Training: Adam with a piecewise-constant learning rate (the paper: 1e-3 for 60 epochs, then
//! 1e-4 for 15), loss summed over the supervised outputs, validation with VP metrics after every
//! epoch, atomic checkpoints and exact resume.
//!
//! # Run folder
//! ```text
//! OUT/train_config.json              the TrainConfig (model config included)
//! OUT/checkpoints/epoch-NNNN/        model.safetensors, optimizer.bpk, state.json, train_config.json
//! OUT/latest.json                    {"epoch": N, "checkpoint": "checkpoints/epoch-NNNN"}
//! OUT/metrics.csv, metrics.jsonl     one row per epoch
//! OUT/curves.png                     loss and VP-error curves
//! ```
//! A checkpoint folder is written under a temporary name and renamed when complete, and
//! `latest.json` is replaced atomically after it, so killing the process at any moment loses at
//! most the epoch in progress. Resuming reloads weights (with their parameter ids), the Adam
//! state and the epoch counter; a [`BatchSource`] that is deterministic per epoch then yields
//! the same batches, so the loss curve continues as if never interrupted.

use std::path::{Path, PathBuf};
use std::time::Instant;

use burn::optim::{AdamConfig, GradientsParams, ModuleOptimizer};
use burn::tensor::{Bytes, Device};
use serde::{Deserialize, Serialize};

use crate::fsutil::write_atomic;
use crate::metrics::{VpErrorAccumulator, VpMetrics};
use crate::network::{images_tensor, to_vec, VpNetwork};
use crate::source::BatchSource;
use crate::store::{weights_to_bytes, WeightsFile};
use crate::NetError;

/// One constant-learning-rate phase.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LrPhase {
    pub epochs: usize,
    pub lr: f64,
}

/// Piecewise-constant learning rate over epochs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LrSchedule {
    pub phases: Vec<LrPhase>,
}

impl LrSchedule {
    /// The paper: 1e-3 for 60 epochs, then 1e-4 for 15.
    pub fn paper() -> Self {
        LrSchedule {
            phases: vec![
                LrPhase {
                    epochs: 60,
                    lr: 1e-3,
                },
                LrPhase {
                    epochs: 15,
                    lr: 1e-4,
                },
            ],
        }
    }

    /// The paper's shape scaled to `epochs` at base rate `lr`: the first 80 % of the epochs
    /// (rounded, at least one) at `lr`, the rest at `lr / 10`. `two_phase(75, 1e-3)` is the
    /// paper's schedule.
    pub fn two_phase(epochs: usize, lr: f64) -> Self {
        let first = ((epochs as f64 * 0.8).round() as usize).clamp(1.min(epochs), epochs);
        let mut phases = vec![LrPhase { epochs: first, lr }];
        if epochs > first {
            phases.push(LrPhase {
                epochs: epochs - first,
                lr: lr / 10.0,
            });
        }
        LrSchedule { phases }
    }

    /// A single rate for all epochs.
    pub fn constant(epochs: usize, lr: f64) -> Self {
        LrSchedule {
            phases: vec![LrPhase { epochs, lr }],
        }
    }

    /// Total number of epochs.
    pub fn total_epochs(&self) -> usize {
        self.phases.iter().map(|p| p.epochs).sum()
    }

    /// Learning rate of epoch `epoch` (0-based); the last phase's rate past the end.
    pub fn lr_at(&self, epoch: usize) -> f64 {
        let mut start = 0;
        for p in &self.phases {
            if epoch < start + p.epochs {
                return p.lr;
            }
            start += p.epochs;
        }
        self.phases.last().map_or(0.0, |p| p.lr)
    }

    fn validate(&self) -> Result<(), NetError> {
        if self.phases.is_empty()
            || self
                .phases
                .iter()
                .any(|p| !(p.lr.is_finite() && p.lr > 0.0))
        {
            return Err(NetError::Config(format!(
                "learning-rate schedule {:?} needs at least one phase with a positive rate",
                self.phases
            )));
        }
        Ok(())
    }
}

/// Adam hyper-parameters (defaults: Keras', as the reference used).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AdamSettings {
    pub beta1: f32,
    pub beta2: f32,
    pub epsilon: f32,
}

impl Default for AdamSettings {
    fn default() -> Self {
        AdamSettings {
            beta1: 0.9,
            beta2: 0.999,
            epsilon: 1e-7,
        }
    }
}

/// Everything that defines a training run; saved as `train_config.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainConfig<C> {
    /// Architecture name ([`VpNetwork::KIND`]).
    pub kind: String,
    /// The model config.
    pub model: C,
    /// Crops per training step (paper: 32).
    pub batch_size: usize,
    /// Learning rate per epoch.
    pub schedule: LrSchedule,
    /// Seed of the model initialisation (the data source has its own).
    pub seed: u64,
    pub adam: AdamSettings,
    /// Stop each epoch after this many batches (quick runs); `None` = the whole source.
    pub max_train_batches: Option<usize>,
    /// Validate on at most this many batches; `None` = all.
    pub max_val_batches: Option<usize>,
    /// Description of the data source (informational); the current one when a resumed run
    /// switched sources (see `data_history`).
    pub data: String,
    /// The sources of a run that changed its data on resume, oldest first; empty for a run
    /// trained on one source throughout.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub data_history: Vec<DataSegment>,
    /// How many epoch checkpoints to keep (the latest ones); at least 1.
    pub keep_checkpoints: usize,
    /// Heatmap loss: weight of a pixel's squared error is `1 + fg_weight * target` (0, the
    /// default, is the paper's plain MSE). Validation loss is always the plain MSE.
    #[serde(default)]
    pub fg_weight: f64,
    /// Keep a pretrained encoder fixed ([`VpNetwork::freeze_encoder`]): the first phase of
    /// fine-tuning a pretrained-encoder network, training only its decoder. Absent (false) in
    /// older runs.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub freeze_encoder: bool,
}

impl<C> TrainConfig<C> {
    /// A config with the paper's schedule, batch 32, seed 0.
    pub fn new<N: VpNetwork<Config = C>>(model: C) -> Self {
        TrainConfig {
            kind: N::KIND.to_string(),
            model,
            batch_size: 32,
            schedule: LrSchedule::paper(),
            seed: 0,
            adam: AdamSettings::default(),
            max_train_batches: None,
            max_val_batches: None,
            data: String::new(),
            data_history: Vec::new(),
            keep_checkpoints: 2,
            fg_weight: 0.0,
            freeze_encoder: false,
        }
    }
}

/// One stretch of a run trained on one data source.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DataSegment {
    /// First epoch (1-based) trained on `data`.
    pub first_epoch: usize,
    /// Description of the source, as in [`TrainConfig::data`].
    pub data: String,
}

pub use crate::report::EpochRecord;

/// The trainer's resumable state, saved in every checkpoint as `state.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct TrainState {
    pub epochs_done: usize,
    pub steps: u64,
    pub history: Vec<EpochRecord>,
}

#[derive(Debug, Serialize, Deserialize)]
struct Latest {
    epoch: usize,
    checkpoint: String,
}

const LATEST: &str = "latest.json";
const WEIGHTS: &str = "model.safetensors";
const OPTIMIZER: &str = "optimizer.bpk";
const STATE: &str = "state.json";
const TRAIN_CONFIG: &str = "train_config.json";

/// Trains a [`VpNetwork`] into a run folder.
pub struct Trainer<N: VpNetwork> {
    config: TrainConfig<N::Config>,
    out: PathBuf,
    device: Device,
    model: N,
    optim: ModuleOptimizer,
    state: TrainState,
    progress: bool,
}

impl<N: VpNetwork> std::fmt::Debug for Trainer<N> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Trainer")
            .field("out", &self.out)
            .field("config", &self.config)
            .field("state", &self.state)
            .finish_non_exhaustive()
    }
}

fn adam(settings: &AdamSettings) -> ModuleOptimizer {
    AdamConfig::new()
        .with_beta_1(settings.beta1)
        .with_beta_2(settings.beta2)
        .with_epsilon(settings.epsilon)
        .init()
}

fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T, NetError> {
    let text = std::fs::read_to_string(path).map_err(|e| NetError::io(path, e))?;
    serde_json::from_str(&text).map_err(|e| NetError::Checkpoint {
        path: path.to_path_buf(),
        message: format!("malformed JSON: {e}"),
    })
}

fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<(), NetError> {
    let text = serde_json::to_string_pretty(value)?;
    write_atomic(path, text.as_bytes())
}

impl<N: VpNetwork> Trainer<N> {
    /// A new run in `out` with a freshly initialised model (seeded by `config.seed`), its
    /// pretrained parts loaded ([`VpNetwork::load_pretrained`]).
    ///
    /// # Errors
    /// [`NetError::Config`] for an invalid config; [`NetError::Checkpoint`] when `out` already
    /// holds a run (resume it or choose another folder); [`NetError::Io`].
    pub fn new(
        config: TrainConfig<N::Config>,
        out: &Path,
        device: &Device,
    ) -> Result<Self, NetError> {
        N::validate_config(&config.model)?;
        let device = device.clone().autodiff();
        device.seed(config.seed);
        let model = N::init(&config.model, &device).load_pretrained(&config.model)?;
        Self::with_model(config, out, &device, model)
    }

    /// A new run in `out` whose model starts from the weights in `weights` (fine-tuning a
    /// trained model, e.g. the bundled one, on new data). `config.model` must be the file's own
    /// model config ([`WeightsFile::config`]).
    ///
    /// # Errors
    /// As [`Trainer::new`], and [`NetError::Weights`] when the file's tensors or config do not
    /// match `config.model`.
    pub fn from_weights(
        config: TrainConfig<N::Config>,
        out: &Path,
        device: &Device,
        weights: &WeightsFile,
    ) -> Result<Self, NetError> {
        N::validate_config(&config.model)?;
        if let Some(stored) = weights.config::<N::Config>()? {
            if stored != config.model {
                return Err(NetError::Weights {
                    path: weights.path().to_path_buf(),
                    message: format!(
                        "the file's model config {stored:?} differs from the run's {:?}",
                        config.model
                    ),
                });
            }
        }
        // Loaded on the plain device: tensors made there become leaves (trainable) when
        // `with_model` moves the model to the autodiff device.
        device.seed(config.seed);
        let model = weights.load_into(N::init(&config.model, device))?;
        Self::with_model(config, out, device, model)
    }

    /// A new run in `out` starting from the given model (e.g. for fine-tuning, or to start
    /// two runs from identical weights).
    ///
    /// # Errors
    /// As [`Trainer::new`].
    pub fn with_model(
        config: TrainConfig<N::Config>,
        out: &Path,
        device: &Device,
        model: N,
    ) -> Result<Self, NetError> {
        N::validate_config(&config.model)?;
        config.schedule.validate()?;
        if config.batch_size == 0 {
            return Err(NetError::Config("batch size must be at least 1".into()));
        }
        if out.join(LATEST).exists() {
            return Err(NetError::Checkpoint {
                path: out.to_path_buf(),
                message: "already holds a training run (use --resume, or another --out)".into(),
            });
        }
        std::fs::create_dir_all(out.join("checkpoints"))
            .map_err(|e| NetError::io(&out.join("checkpoints"), e))?;
        let device = device.clone().autodiff();
        let model = model
            .to_device(&device)
            .train()
            .freeze_encoder(config.freeze_encoder)?;
        write_json(&out.join(TRAIN_CONFIG), &config)?;
        Ok(Trainer {
            optim: adam(&config.adam),
            config,
            out: out.to_path_buf(),
            device,
            model,
            state: TrainState::default(),
            progress: true,
        })
    }

    /// Continue the run in `out` from its latest checkpoint.
    ///
    /// # Errors
    /// [`NetError::Checkpoint`] when `out` holds no checkpoint or the checkpoint is
    /// inconsistent (kind, config, weights), naming the file; [`NetError::Io`].
    pub fn resume(out: &Path, device: &Device) -> Result<Self, NetError> {
        let latest_path = out.join(LATEST);
        if !latest_path.exists() {
            return Err(NetError::Checkpoint {
                path: out.to_path_buf(),
                message: format!("no {LATEST}: nothing to resume (no epoch finished yet?)"),
            });
        }
        let latest: Latest = read_json(&latest_path)?;
        let dir = out.join(&latest.checkpoint);
        let config: TrainConfig<N::Config> = read_json(&dir.join(TRAIN_CONFIG))?;
        if config.kind != N::KIND {
            return Err(NetError::Checkpoint {
                path: dir.join(TRAIN_CONFIG),
                message: format!("run trains a {:?}, not a {:?}", config.kind, N::KIND),
            });
        }
        N::validate_config(&config.model)?;
        let state: TrainState = read_json(&dir.join(STATE))?;
        if state.epochs_done != latest.epoch {
            return Err(NetError::Checkpoint {
                path: dir.join(STATE),
                message: format!(
                    "state says {} epochs done, {LATEST} says {}",
                    state.epochs_done, latest.epoch
                ),
            });
        }
        let device = device.clone().autodiff();
        let weights = WeightsFile::read(&dir.join(WEIGHTS))?;
        if let Some(saved) = weights.config::<N::Config>()? {
            if saved != config.model {
                return Err(NetError::Checkpoint {
                    path: dir.join(WEIGHTS),
                    message: "model config in the weights differs from train_config.json".into(),
                });
            }
        }
        let model = weights
            .load_into(N::init(&config.model, &device))?
            .train()
            .freeze_encoder(config.freeze_encoder)?;
        let opt_path = dir.join(OPTIMIZER);
        let opt_bytes = std::fs::read(&opt_path).map_err(|e| NetError::io(&opt_path, e))?;
        let optim = adam(&config.adam)
            .from_bytes(Bytes::from_bytes_vec(opt_bytes))
            .map_err(|e| NetError::Checkpoint {
                path: opt_path.clone(),
                message: format!("optimizer state unreadable: {e}"),
            })?;
        Ok(Trainer {
            config,
            out: out.to_path_buf(),
            device,
            model,
            optim,
            state,
            progress: true,
        })
    }

    /// Show (default) or hide the progress bar.
    pub fn with_progress(mut self, progress: bool) -> Self {
        self.progress = progress;
        self
    }

    /// Replace the learning-rate schedule (e.g. to train a resumed run for more epochs).
    ///
    /// # Errors
    /// [`NetError::Config`] when the schedule is empty or ends before the epochs already done.
    pub fn set_schedule(&mut self, schedule: LrSchedule) -> Result<(), NetError> {
        schedule.validate()?;
        if schedule.total_epochs() < self.state.epochs_done {
            return Err(NetError::Config(format!(
                "schedule of {} epochs ends before the {} epochs already trained",
                schedule.total_epochs(),
                self.state.epochs_done
            )));
        }
        self.config.schedule = schedule;
        write_json(&self.out.join(TRAIN_CONFIG), &self.config)
    }

    /// Record that the epochs from the next one on train on `data` (a resumed run given another
    /// source). The run's `train_config.json` keeps every source with its first epoch.
    pub fn set_data(&mut self, data: &str) -> Result<(), NetError> {
        if data == self.config.data {
            return Ok(());
        }
        let first_epoch = self.state.epochs_done + 1;
        let history = &mut self.config.data_history;
        if history.is_empty() {
            history.push(DataSegment {
                first_epoch: 1,
                data: self.config.data.clone(),
            });
        }
        // A source that never trained an epoch is replaced, not kept.
        if history.last().is_some_and(|s| s.first_epoch == first_epoch) {
            history.pop();
        }
        if history.last().is_none_or(|s| s.data != data) {
            history.push(DataSegment {
                first_epoch,
                data: data.to_string(),
            });
        }
        if history.len() == 1 {
            history.clear();
        }
        self.config.data = data.to_string();
        write_json(&self.out.join(TRAIN_CONFIG), &self.config)
    }

    /// The run's config.
    pub fn config(&self) -> &TrainConfig<N::Config> {
        &self.config
    }

    /// Progress so far.
    pub fn state(&self) -> &TrainState {
        &self.state
    }

    /// The model being trained (on the autodiff device).
    pub fn model(&self) -> &N {
        &self.model
    }

    /// The run folder.
    pub fn out_dir(&self) -> &Path {
        &self.out
    }

    /// One optimizer step on `batch` at learning rate `lr`; returns the loss terms before the
    /// step.
    ///
    /// # Errors
    /// [`NetError::Input`] for a batch that does not fit the model; [`NetError::Tensor`] when
    /// the loss is not finite (the step is then not applied).
    pub fn step(&mut self, batch: &vpcal_data::Batch, lr: f64) -> Result<Vec<f32>, NetError> {
        N::check_batch(&self.config.model, batch)?;
        let images = images_tensor(batch, &self.device)?; // [b, 3, s, s]
        let terms = self
            .model
            .loss_terms(&self.config.model, images, batch, self.config.fg_weight); // [terms]
        let total = terms.clone().sum(); // [1]
        let grads = total.backward();
        let values = to_vec(terms)?;
        if values.iter().any(|v| !v.is_finite()) {
            return Err(NetError::Tensor(format!(
                "loss is not finite ({values:?}) at epoch {} step {}",
                self.state.epochs_done + 1,
                self.state.steps + 1
            )));
        }
        let grads = GradientsParams::from_grads(grads, &self.model);
        self.model = self.optim.step(lr, self.model.clone(), grads);
        self.state.steps += 1;
        Ok(values)
    }

    /// Train until the schedule's last epoch, validating and checkpointing after each.
    ///
    /// # Errors
    /// Data-source errors, input mismatches, non-finite losses and checkpoint I/O errors.
    pub fn run(&mut self, source: &dyn BatchSource) -> Result<&[EpochRecord], NetError> {
        while self.state.epochs_done < self.config.schedule.total_epochs() {
            self.run_epoch(source)?;
        }
        Ok(&self.state.history)
    }

    /// Train one epoch, validate, checkpoint and write the metrics files.
    ///
    /// # Errors
    /// As [`Trainer::run`].
    pub fn run_epoch(&mut self, source: &dyn BatchSource) -> Result<EpochRecord, NetError> {
        let epoch = self.state.epochs_done;
        let total_epochs = self.config.schedule.total_epochs();
        let lr = self.config.schedule.lr_at(epoch);
        let bs = self.config.batch_size;
        let mut n_batches = source.train_batches(bs);
        if let Some(m) = self.config.max_train_batches {
            n_batches = n_batches.min(m);
        }
        let bar = self.bar(
            n_batches as u64,
            format!("epoch {}/{}", epoch + 1, total_epochs),
        );
        let start = Instant::now();
        let mut samples = 0usize;
        let mut sum = 0.0f64;
        let mut term_sums: Vec<f64> = Vec::new();
        let (mut first, mut last) = (f64::NAN, f64::NAN);
        for batch in source.train_epoch(epoch, bs).take(n_batches) {
            let batch = batch?;
            let terms = self.step(&batch, lr)?;
            let loss: f64 = terms.iter().map(|&v| f64::from(v)).sum();
            if first.is_nan() {
                first = loss;
            }
            last = loss;
            if term_sums.len() < terms.len() {
                term_sums.resize(terms.len(), 0.0);
            }
            for (s, &t) in term_sums.iter_mut().zip(&terms) {
                *s += f64::from(t) * batch.size as f64;
            }
            sum += loss * batch.size as f64;
            samples += batch.size;
            let rate = samples as f64 / start.elapsed().as_secs_f64().max(1e-9);
            bar.set_message(format!("loss {loss:.3e}, {rate:.1} crops/s"));
            bar.inc(1);
        }
        bar.finish_and_clear();
        if samples == 0 {
            return Err(NetError::Input(format!(
                "the data source yielded no training batch for epoch {}",
                epoch + 1
            )));
        }
        let train_seconds = start.elapsed().as_secs_f64();
        let (val_loss, val) = self.validate(source)?;
        let record = EpochRecord {
            epoch: epoch + 1,
            lr,
            steps: self.state.steps,
            train_samples: samples,
            train_loss: sum / samples as f64,
            train_loss_terms: term_sums.iter().map(|s| s / samples as f64).collect(),
            first_batch_loss: first,
            last_batch_loss: last,
            val_loss,
            val,
            seconds: start.elapsed().as_secs_f64(),
            samples_per_s: samples as f64 / train_seconds.max(1e-9),
        };
        self.state.epochs_done += 1;
        self.state.history.push(record.clone());
        self.save_checkpoint()?;
        crate::report::write_metrics(&self.out, &self.state.history)?;
        Ok(record)
    }

    fn bar(&self, len: u64, prefix: String) -> indicatif::ProgressBar {
        if !self.progress {
            return indicatif::ProgressBar::hidden();
        }
        let bar = indicatif::ProgressBar::new(len);
        if let Ok(style) = indicatif::ProgressStyle::with_template(
            "{prefix} [{bar:30}] {pos}/{len} batches [{elapsed_precise} < {eta_precise}] {msg}",
        ) {
            bar.set_style(style.progress_chars("=> "));
        }
        bar.set_prefix(prefix);
        bar
    }

    /// Validation loss and VP metrics with the model in validation mode.
    fn validate(
        &self,
        source: &dyn BatchSource,
    ) -> Result<(Option<f64>, Option<VpMetrics>), NetError> {
        let bs = self.config.batch_size;
        let mut n = source.validation_batches(bs);
        if let Some(m) = self.config.max_val_batches {
            n = n.min(m);
        }
        if n == 0 {
            return Ok((None, None));
        }
        let model = self.model.valid();
        let device = self.device.clone().without_autodiff();
        let bar = self.bar(n as u64, "validation".to_string());
        let mut acc = VpErrorAccumulator::default();
        let (mut sum, mut count) = (0.0f64, 0usize);
        for batch in source.validation(bs).take(n) {
            let batch = batch?;
            N::check_batch(&self.config.model, &batch)?;
            let images = images_tensor(&batch, &device)?;
            let terms = model.evaluate(&self.config.model, images, &batch, &mut acc)?;
            sum += terms.iter().map(|&v| f64::from(v)).sum::<f64>() * batch.size as f64;
            count += batch.size;
            bar.inc(1);
        }
        bar.finish_and_clear();
        if count == 0 {
            return Ok((None, None));
        }
        Ok((Some(sum / count as f64), Some(acc.summary())))
    }

    /// Write the checkpoint of the epochs done so far (see the module docs).
    ///
    /// # Errors
    /// [`NetError::Io`] naming the file.
    pub fn save_checkpoint(&self) -> Result<PathBuf, NetError> {
        let epoch = self.state.epochs_done;
        let ckdir = self.out.join("checkpoints");
        let name = format!("epoch-{epoch:04}");
        let final_dir = ckdir.join(&name);
        let tmp = ckdir.join(format!(".{name}.tmp"));
        if tmp.exists() {
            std::fs::remove_dir_all(&tmp).map_err(|e| NetError::io(&tmp, e))?;
        }
        std::fs::create_dir_all(&tmp).map_err(|e| NetError::io(&tmp, e))?;
        let weights = weights_to_bytes::<N, _>(&self.model, &self.config.model, N::KIND)?;
        write_atomic(&tmp.join(WEIGHTS), &weights)?;
        let opt = self.optim.into_bytes().map_err(|e| NetError::Checkpoint {
            path: tmp.join(OPTIMIZER),
            message: format!("cannot serialise the optimizer state: {e}"),
        })?;
        write_atomic(&tmp.join(OPTIMIZER), &opt)?;
        write_json(&tmp.join(STATE), &self.state)?;
        write_json(&tmp.join(TRAIN_CONFIG), &self.config)?;
        if final_dir.exists() {
            std::fs::remove_dir_all(&final_dir).map_err(|e| NetError::io(&final_dir, e))?;
        }
        std::fs::rename(&tmp, &final_dir).map_err(|e| NetError::io(&final_dir, e))?;
        write_json(
            &self.out.join(LATEST),
            &Latest {
                epoch,
                checkpoint: format!("checkpoints/{name}"),
            },
        )?;
        // Prune old epochs, keeping the newest `keep_checkpoints`.
        let keep = self.config.keep_checkpoints.max(1);
        if epoch > keep {
            for old in 1..=(epoch - keep) {
                let d = ckdir.join(format!("epoch-{old:04}"));
                if d.exists() {
                    std::fs::remove_dir_all(&d).map_err(|e| NetError::io(&d, e))?;
                }
            }
        }
        Ok(final_dir)
    }
}

/// The folder of the latest checkpoint of a run folder, or `path` itself when it is already a
/// checkpoint folder.
///
/// # Errors
/// [`NetError::Checkpoint`] when `path` is neither.
pub fn resolve_checkpoint(path: &Path) -> Result<PathBuf, NetError> {
    if path.join(WEIGHTS).is_file() {
        return Ok(path.to_path_buf());
    }
    let latest = path.join(LATEST);
    if latest.is_file() {
        let l: Latest = read_json(&latest)?;
        return Ok(path.join(l.checkpoint));
    }
    Err(NetError::Checkpoint {
        path: path.to_path_buf(),
        message: format!(
            "neither a checkpoint folder (no {WEIGHTS}) nor a run folder (no {LATEST})"
        ),
    })
}

/// The weights file of a checkpoint folder.
pub fn checkpoint_weights(dir: &Path) -> PathBuf {
    dir.join(WEIGHTS)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn schedules() {
        let p = LrSchedule::paper();
        assert_eq!(p.total_epochs(), 75);
        assert_eq!(p.lr_at(0), 1e-3);
        assert_eq!(p.lr_at(59), 1e-3);
        assert_eq!(p.lr_at(60), 1e-4);
        assert_eq!(p.lr_at(200), 1e-4);
        assert_eq!(LrSchedule::two_phase(75, 1e-3), p);
        let one = LrSchedule::two_phase(1, 1e-3);
        assert_eq!(one.total_epochs(), 1);
        assert_eq!(one.lr_at(0), 1e-3);
        assert!(LrSchedule::constant(3, 0.0).validate().is_err());
    }
}
