//! A multi-threaded batch pipeline: decode → augment → heatmap targets → [`Batch`].
//!
//! # Determinism
//! The sample order of an epoch is a permutation drawn from `(seed, epoch)` and every sample's
//! augmentation from `(seed, epoch, sample index)`, so the batches of an epoch are identical
//! whatever the number of workers or the timing of the threads.
//!
//! # Threads and memory
//! `workers` threads build whole batches (worker `w` builds batches `w`, `w + workers`, ...) and
//! hand them over through one bounded channel each (`prefetch` batches); the consumer takes
//! batch `b` from worker `b % workers`, so batches arrive in order and at most
//! `workers * (prefetch + 1)` batches exist at a time.
//!
//! # Skipped samples
//! A sample whose source reports [`DataError::Sample`] (e.g. a corrupt JPEG) or that cannot be
//! augmented is left out of its batch (which is then smaller) and recorded; the epoch goes on.
//! [`DataError::File`] (the source itself is broken) ends the epoch with that error.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, SyncSender};
use std::sync::Arc;
use std::thread::JoinHandle;

use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use vpcal_geom::heatmap::HeatmapCodec;

use crate::augment::{augment, AugmentConfig, AugmentError, Augmented};
use crate::{Batch, DataError, Sample, SampleSource};

/// Settings of a [`Pipeline`].
#[derive(Debug, Clone)]
pub struct PipelineConfig {
    /// Samples per batch (the last batch of an epoch may be smaller unless `drop_last`).
    pub batch_size: usize,
    /// Worker threads.
    pub workers: usize,
    /// Seed of the order and of every augmentation.
    pub seed: u64,
    /// Shuffle the order every epoch (training); otherwise the source's order.
    pub shuffle: bool,
    /// Leave out a last, incomplete batch.
    pub drop_last: bool,
    /// Finished batches each worker may hold ahead of the consumer.
    pub prefetch: usize,
    /// The augmentation ([`AugmentConfig::evaluation`] for validation and test).
    pub augment: AugmentConfig,
    /// The heatmap codec for the targets.
    pub codec: HeatmapCodec,
    /// Print a warning to stderr for every skipped sample.
    pub warn_on_skip: bool,
}

impl PipelineConfig {
    /// Training settings: shuffled, the paper's augmentation and codec, one worker per core.
    pub fn training(batch_size: usize, seed: u64) -> PipelineConfig {
        PipelineConfig {
            batch_size,
            workers: std::thread::available_parallelism().map_or(1, |n| n.get()),
            seed,
            shuffle: true,
            drop_last: false,
            prefetch: 2,
            augment: AugmentConfig::paper(),
            codec: HeatmapCodec::default(),
            warn_on_skip: true,
        }
    }

    /// Validation/test settings: source order, no augmentation.
    pub fn evaluation(batch_size: usize) -> PipelineConfig {
        PipelineConfig {
            shuffle: false,
            augment: AugmentConfig::evaluation(128),
            ..PipelineConfig::training(batch_size, 0)
        }
    }

    /// Check every value.
    ///
    /// # Errors
    /// A message naming the first bad setting.
    pub fn validate(&self) -> Result<(), String> {
        if self.batch_size == 0 {
            return Err("batch size must be > 0".into());
        }
        if self.workers == 0 {
            return Err("workers must be > 0".into());
        }
        if self.prefetch == 0 {
            return Err("prefetch must be > 0".into());
        }
        self.augment.validate()?;
        self.codec.validate()
    }
}

/// A sample left out of a batch, and why.
#[derive(Debug, Clone, PartialEq)]
pub struct Skipped {
    /// Index of the sample in its source.
    pub index: usize,
    /// The source's or the augmentation's error message (names the file and the sample).
    pub reason: String,
}

/// The random generator of one sample's augmentation.
pub fn sample_rng(seed: u64, epoch: u64, index: usize) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(epoch.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ index as u64);
    rng
}

/// The sample order of an epoch.
pub fn epoch_order(len: usize, seed: u64, epoch: u64, shuffle: bool) -> Vec<usize> {
    let mut order: Vec<usize> = (0..len).collect();
    if shuffle {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed_0000_0000_0000);
        rng.set_stream(epoch);
        order.shuffle(&mut rng);
    }
    order
}

/// Augment a sample and render its heatmap targets.
///
/// # Errors
/// As [`augment`].
pub fn prepare(
    sample: &Sample,
    augment_cfg: &AugmentConfig,
    codec: &HeatmapCodec,
    rng: &mut ChaCha8Rng,
) -> Result<(Augmented, Vec<f32>), AugmentError> {
    let a = augment(sample, augment_cfg, rng)?;
    let targets = codec.render_targets(a.vp1_box, a.vp2_box);
    Ok((a, targets))
}

/// Batches of one [`SampleSource`], see the module docs.
pub struct Pipeline {
    source: Arc<dyn SampleSource>,
    config: PipelineConfig,
}

impl std::fmt::Debug for Pipeline {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Pipeline")
            .field("samples", &self.source.len())
            .field("split", &self.source.split())
            .field("config", &self.config)
            .finish()
    }
}

impl Pipeline {
    /// A pipeline over `source`.
    ///
    /// # Errors
    /// A message naming the first bad setting.
    pub fn new(source: Arc<dyn SampleSource>, config: PipelineConfig) -> Result<Pipeline, String> {
        config.validate()?;
        Ok(Pipeline { source, config })
    }

    /// The settings.
    pub fn config(&self) -> &PipelineConfig {
        &self.config
    }

    /// Batches per epoch.
    pub fn batches_per_epoch(&self) -> usize {
        let n = self.source.len();
        let bs = self.config.batch_size;
        if self.config.drop_last {
            n / bs
        } else {
            n.div_ceil(bs)
        }
    }

    /// Start the workers for one epoch.
    pub fn epoch(&self, epoch: u64) -> EpochIter {
        let order = Arc::new(epoch_order(
            self.source.len(),
            self.config.seed,
            epoch,
            self.config.shuffle,
        ));
        let n_batches = self.batches_per_epoch();
        let workers = self.config.workers.min(n_batches.max(1));
        let stop = Arc::new(AtomicBool::new(false));
        let mut receivers = Vec::with_capacity(workers);
        let mut handles = Vec::with_capacity(workers);
        for w in 0..workers {
            let (tx, rx) = mpsc::sync_channel(self.config.prefetch);
            receivers.push(rx);
            let job = Worker {
                source: Arc::clone(&self.source),
                config: self.config.clone(),
                order: Arc::clone(&order),
                epoch,
                stop: Arc::clone(&stop),
            };
            handles.push(std::thread::spawn(move || {
                job.run(w, workers, n_batches, tx)
            }));
        }
        EpochIter {
            receivers,
            handles,
            stop,
            next_batch: 0,
            n_batches,
            done: false,
            skipped: Vec::new(),
            warn: self.config.warn_on_skip,
        }
    }
}

type Msg = Result<(Batch, Vec<Skipped>), DataError>;

struct Worker {
    source: Arc<dyn SampleSource>,
    config: PipelineConfig,
    order: Arc<Vec<usize>>,
    epoch: u64,
    stop: Arc<AtomicBool>,
}

impl Worker {
    fn run(self, first: usize, step: usize, n_batches: usize, tx: SyncSender<Msg>) {
        let mut b = first;
        while b < n_batches && !self.stop.load(Ordering::Relaxed) {
            let msg = self.batch(b);
            let failed = msg.is_err();
            if tx.send(msg).is_err() || failed {
                return;
            }
            b += step;
        }
    }

    fn batch(&self, b: usize) -> Msg {
        let cfg = &self.config;
        let size = cfg.augment.output_size as usize;
        let plane = size * size;
        let start = b * cfg.batch_size;
        let end = (start + cfg.batch_size).min(self.order.len());
        let indices = self.order.get(start..end).unwrap_or(&[]);
        let mut batch = Batch {
            size: 0,
            input_size: size,
            images: Vec::with_capacity(indices.len() * 3 * plane),
            channels: cfg.codec.channels(),
            heatmap_res: cfg.codec.resolution,
            targets: Vec::with_capacity(indices.len() * cfg.codec.len()),
            vp1_box: Vec::with_capacity(indices.len()),
            vp2_box: Vec::with_capacity(indices.len()),
            ids: Vec::with_capacity(indices.len()),
            weights: Vec::with_capacity(indices.len() * cfg.codec.channels()),
        };
        let mut skipped = Vec::new();
        for &index in indices {
            let sample = match self.source.get(index) {
                Ok(s) => s,
                Err(e @ DataError::Sample { .. }) => {
                    skipped.push(Skipped {
                        index,
                        reason: e.to_string(),
                    });
                    continue;
                }
                Err(e) => return Err(e),
            };
            let mut rng = sample_rng(cfg.seed, self.epoch, index);
            let a = match augment(&sample, &cfg.augment, &mut rng) {
                Ok(a) => a,
                Err(e) => {
                    skipped.push(Skipped {
                        index,
                        reason: format!(
                            "vehicle {} instance {}: {e}",
                            sample.id.vehicle, sample.id.instance
                        ),
                    });
                    continue;
                }
            };
            // HWC u8 → CHW f32 in [0, 1]
            let i0 = batch.images.len();
            batch.images.resize(i0 + 3 * plane, 0.0);
            let (r, rest) = batch.images[i0..].split_at_mut(plane);
            let (g, b) = rest.split_at_mut(plane);
            for (k, px) in a.image.as_raw().chunks_exact(3).enumerate().take(plane) {
                r[k] = f32::from(px[0]) / 255.0;
                g[k] = f32::from(px[1]) / 255.0;
                b[k] = f32::from(px[2]) / 255.0;
            }
            let t0 = batch.targets.len();
            batch.targets.resize(t0 + cfg.codec.len(), 0.0);
            cfg.codec
                .render_targets_into(a.vp1_box, a.vp2_box, &mut batch.targets[t0..]);
            batch.vp1_box.push(a.vp1_box.as_array());
            batch.vp2_box.push(a.vp2_box.as_array());
            batch.ids.push(sample.id);
            batch.weights.extend(crate::source::channel_weights(
                sample.label_weight,
                cfg.codec.channels(),
            ));
            batch.size += 1;
        }
        Ok((batch, skipped))
    }
}

/// The batches of one epoch, in order. Dropping it stops the workers.
pub struct EpochIter {
    receivers: Vec<Receiver<Msg>>,
    handles: Vec<JoinHandle<()>>,
    stop: Arc<AtomicBool>,
    next_batch: usize,
    n_batches: usize,
    done: bool,
    skipped: Vec<Skipped>,
    warn: bool,
}

impl std::fmt::Debug for EpochIter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EpochIter")
            .field("next_batch", &self.next_batch)
            .field("n_batches", &self.n_batches)
            .field("skipped", &self.skipped.len())
            .finish()
    }
}

impl EpochIter {
    /// Samples left out so far, in sample order.
    pub fn skipped(&self) -> &[Skipped] {
        &self.skipped
    }

    /// Batches in this epoch (some may be skipped entirely when all their samples fail).
    pub fn n_batches(&self) -> usize {
        self.n_batches
    }
}

impl Iterator for EpochIter {
    type Item = Result<Batch, DataError>;

    fn next(&mut self) -> Option<Self::Item> {
        while !self.done && self.next_batch < self.n_batches {
            let b = self.next_batch;
            let Some(rx) = self.receivers.get(b % self.receivers.len().max(1)) else {
                self.done = true;
                return None;
            };
            self.next_batch += 1;
            match rx.recv() {
                Ok(Ok((batch, skipped))) => {
                    if self.warn {
                        for s in &skipped {
                            eprintln!("warning: skipping sample {}: {}", s.index, s.reason);
                        }
                    }
                    self.skipped.extend(skipped);
                    if batch.size > 0 {
                        return Some(Ok(batch));
                    }
                }
                Ok(Err(e)) => {
                    self.done = true;
                    return Some(Err(e));
                }
                Err(_) => {
                    self.done = true;
                    return Some(Err(DataError::File {
                        path: std::path::PathBuf::new(),
                        message: format!("batch worker for batch {b} stopped unexpectedly"),
                    }));
                }
            }
        }
        None
    }
}

impl Drop for EpochIter {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        self.receivers.clear(); // blocked senders fail and return
        for h in self.handles.drain(..) {
            let _ = h.join();
        }
    }
}
