//! Data sources and the batch type that the network consumes.

use std::sync::Arc;

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
    /// Sources that cannot be used together, or a request outside a source.
    #[error("{0}")]
    Config(String),
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
    /// Loss weight of each heatmap, `[size, channels]`: the sample's label weight for VP1 on
    /// the first half of the channels and for VP2 on the second (1 for exact labels).
    pub weights: Vec<f32>,
}

impl Batch {
    /// Whether some heatmap is weighted below 1 (self-labelled samples in the batch).
    pub fn is_weighted(&self) -> bool {
        self.weights.iter().any(|&w| w != 1.0)
    }
}

/// The per-heatmap weights of one sample: `label_weight[0]` on the VP1 channels (the first
/// half), `label_weight[1]` on the VP2 channels.
pub fn channel_weights(label_weight: [f32; 2], channels: usize) -> impl Iterator<Item = f32> {
    (0..channels).map(move |c| label_weight[usize::from(2 * c >= channels)])
}

/// Several sources of one split read as one: indices run through the first source, then the
/// second, and so on (e.g. synthetic crops and self-labelled real crops in one training run).
/// Vehicle ids are kept as each source gives them.
#[derive(Clone)]
pub struct ConcatSource {
    parts: Vec<Arc<dyn SampleSource>>,
    split: Split,
}

impl ConcatSource {
    /// The concatenation of `parts`, all of which must hold the same split.
    ///
    /// # Errors
    /// [`DataError::Config`] when no part is given or the parts' splits differ.
    pub fn new(parts: Vec<Arc<dyn SampleSource>>) -> Result<ConcatSource, DataError> {
        let Some(first) = parts.first() else {
            return Err(DataError::Config(
                "a concatenation needs at least one source".into(),
            ));
        };
        let split = first.split();
        if let Some(p) = parts.iter().find(|p| p.split() != split) {
            return Err(DataError::Config(format!(
                "cannot concatenate a {:?} source with a {split:?} source",
                p.split()
            )));
        }
        Ok(ConcatSource { parts, split })
    }
}

impl std::fmt::Debug for ConcatSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ConcatSource")
            .field("parts", &self.parts.len())
            .field("len", &self.len())
            .field("split", &self.split)
            .finish()
    }
}

impl SampleSource for ConcatSource {
    fn len(&self) -> usize {
        self.parts.iter().map(|p| p.len()).sum()
    }
    fn split(&self) -> Split {
        self.split
    }
    fn get(&self, index: usize) -> Result<Sample, DataError> {
        let mut i = index;
        for p in &self.parts {
            if i < p.len() {
                return p.get(i);
            }
            i -= p.len();
        }
        Err(DataError::Config(format!(
            "sample {index} out of range ({} samples)",
            self.len()
        )))
    }
}
