//! Training data for vpcal: the shared [`Sample`] type, data sources (BoxCars116k, synthetic
//! crops), the paper's augmentation, heatmap targets and a streaming batch pipeline.

mod sample;
mod source;

pub use sample::{Sample, SampleId, Split};
pub use source::{Batch, DataError, SampleSource};
