//! [`BatchSource`] over `vpcal_data`'s augmentation pipeline: any `SampleSource` (BoxCars116k,
//! synthetic crops) becomes training batches with the paper's augmentation and validation
//! batches without it.

use std::sync::Arc;

use vpcal_data::augment::AugmentConfig;
use vpcal_data::pipeline::{Pipeline, PipelineConfig};
use vpcal_data::{DataError, SampleSource};
use vpcal_geom::heatmap::HeatmapCodec;

use crate::source::{BatchIter, BatchSource};
use crate::NetError;

/// Training and validation samples run through [`Pipeline`]s with the model's input size and
/// codec. Epoch `e` is the pipeline's epoch `e`, deterministic for a seed.
#[derive(Clone)]
pub struct PipelineSource {
    train: Arc<dyn SampleSource>,
    validation: Option<Arc<dyn SampleSource>>,
    train_config: PipelineConfig,
    val_config: PipelineConfig,
    name: String,
}

impl std::fmt::Debug for PipelineSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.describe())
    }
}

impl PipelineSource {
    /// Batches from `train` (augmented with `augment`) and `validation` (tight crops), resized
    /// to `input_size` with targets from `codec`; `seed` drives the order and augmentation.
    ///
    /// # Errors
    /// [`NetError::Config`] for an invalid augmentation or codec.
    pub fn new(
        name: &str,
        train: Arc<dyn SampleSource>,
        validation: Option<Arc<dyn SampleSource>>,
        augment: AugmentConfig,
        input_size: usize,
        codec: HeatmapCodec,
        seed: u64,
    ) -> Result<PipelineSource, NetError> {
        let size = u32::try_from(input_size)
            .map_err(|_| NetError::Config(format!("input size {input_size} is too large")))?;
        let mut train_config = PipelineConfig::training(1, seed);
        train_config.augment = AugmentConfig {
            output_size: size,
            ..augment
        };
        train_config.codec = codec.clone();
        let mut val_config = PipelineConfig::evaluation(1);
        val_config.augment = AugmentConfig::evaluation(size);
        val_config.codec = codec;
        train_config.validate().map_err(NetError::Config)?;
        val_config.validate().map_err(NetError::Config)?;
        Ok(PipelineSource {
            train,
            validation,
            train_config,
            val_config,
            name: name.to_string(),
        })
    }

    /// Use `workers` threads for each pipeline (default: one per core).
    pub fn with_workers(mut self, workers: usize) -> Self {
        self.train_config.workers = workers.max(1);
        self.val_config.workers = workers.max(1);
        self
    }

    fn pipeline(
        &self,
        source: &Arc<dyn SampleSource>,
        config: &PipelineConfig,
        bs: usize,
    ) -> Result<Pipeline, DataError> {
        let mut c = config.clone();
        c.batch_size = bs.max(1);
        Pipeline::new(Arc::clone(source), c).map_err(|message| DataError::File {
            path: self.name.clone().into(),
            message,
        })
    }

    fn iter(
        &self,
        source: &Arc<dyn SampleSource>,
        config: &PipelineConfig,
        bs: usize,
        epoch: u64,
    ) -> BatchIter<'_> {
        match self.pipeline(source, config, bs) {
            Ok(p) => Box::new(p.epoch(epoch)),
            Err(e) => Box::new(std::iter::once(Err(e))),
        }
    }
}

impl BatchSource for PipelineSource {
    fn describe(&self) -> String {
        format!(
            "{}: {} train / {} validation samples, augmentation {:?}, seed {}",
            self.name,
            self.train.len(),
            self.validation.as_ref().map_or(0, |v| v.len()),
            self.train_config.augment,
            self.train_config.seed
        )
    }

    fn train_batches(&self, batch_size: usize) -> usize {
        self.train.len().div_ceil(batch_size.max(1))
    }

    fn train_epoch(&self, epoch: usize, batch_size: usize) -> BatchIter<'_> {
        self.iter(&self.train, &self.train_config, batch_size, epoch as u64)
    }

    fn validation_batches(&self, batch_size: usize) -> usize {
        self.validation
            .as_ref()
            .map_or(0, |v| v.len().div_ceil(batch_size.max(1)))
    }

    fn validation(&self, batch_size: usize) -> BatchIter<'_> {
        match &self.validation {
            Some(v) => self.iter(v, &self.val_config, batch_size, 0),
            None => Box::new(std::iter::empty()),
        }
    }
}
