//! Data sources and the batch type that the network consumes.

use crate::{Sample, Split};

/// Error from a data source: names the file and the sample when it knows them.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    /// A file could not be read or parsed.
    #[error("{path}: {message}")]
    File {
        path: std::path::PathBuf,
        message: String,
    },
    /// One sample is unusable (e.g. a corrupt JPEG); sources may skip it with a warning.
    #[error("{path}: sample {sample}: {message}")]
    Sample {
        path: std::path::PathBuf,
        sample: String,
        message: String,
    },
}

/// A random-access collection of training samples of one split.
///
/// Implementations decode lazily (`get` does the I/O) so that memory stays bounded.
pub trait SampleSource: Send + Sync {
    /// Number of samples in this source.
    fn len(&self) -> usize;
    /// True when the source holds no sample.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// The split these samples belong to.
    fn split(&self) -> Split;
    /// Load sample `index` (`index < len()`).
    ///
    /// # Errors
    /// [`DataError::Sample`] when this one sample is unusable, [`DataError::File`] when the
    /// source itself is broken.
    fn get(&self, index: usize) -> Result<Sample, DataError>;
}

/// A batch ready for the network: augmented crops, heatmap targets and the true VPs.
///
/// # Shapes
/// - `images`: `[size, 3, input_size, input_size]` (NCHW, row-major), values in `[0, 1]`,
///   channel order RGB.
/// - `targets`: `[size, channels, heatmap_res, heatmap_res]`, from
///   `vpcal_geom::heatmap::HeatmapCodec::render_targets` (VP1 scales, then VP2 scales).
#[derive(Debug, Clone)]
pub struct Batch {
    pub size: usize,
    pub input_size: usize,
    pub images: Vec<f32>,
    pub channels: usize,
    pub heatmap_res: usize,
    pub targets: Vec<f32>,
    /// True VP1 of each crop in the box frame of the final (augmented) crop.
    pub vp1_box: Vec<[f64; 2]>,
    /// True VP2 of each crop in the box frame of the final (augmented) crop.
    pub vp2_box: Vec<[f64; 2]>,
    pub ids: Vec<crate::SampleId>,
}
