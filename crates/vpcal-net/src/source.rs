//! Where the trainer gets its batches: the [`BatchSource`] trait, and [`ToySource`], a
//! self-contained synthetic task for tests, demos and smoke runs.
//!
//! Any data pipeline plugs in by implementing [`BatchSource`] over `vpcal_data::Batch`es. For
//! `--resume` to continue exactly, a source must produce the same batches for the same epoch
//! every time (derive shuffling and augmentation from a seed and the epoch index).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use vpcal_data::{Batch, DataError, SampleId};
use vpcal_geom::heatmap::HeatmapCodec;
use vpcal_geom::Point2;

/// An iterator of batches that may fail one batch at a time.
pub type BatchIter<'a> = Box<dyn Iterator<Item = Result<Batch, DataError>> + 'a>;

/// A provider of training and validation batches.
pub trait BatchSource {
    /// A one-line description for logs (e.g. `toy:64 seed 1`).
    fn describe(&self) -> String;
    /// Number of training batches one epoch yields at `batch_size` (for the progress bar).
    fn train_batches(&self, batch_size: usize) -> usize;
    /// The training batches of epoch `epoch` (0-based): a deterministic function of the
    /// source's own seed and `epoch`.
    fn train_epoch(&self, epoch: usize, batch_size: usize) -> BatchIter<'_>;
    /// Number of validation batches at `batch_size` (0 when there is no validation split).
    fn validation_batches(&self, batch_size: usize) -> usize;
    /// The validation batches (no augmentation; the same every epoch).
    fn validation(&self, batch_size: usize) -> BatchIter<'_>;
}

/// A synthetic VP task needing no dataset: each crop shows short line segments that point to
/// its two VPs (VP1 segments red, VP2 segments green, on grey), with heatmap targets rendered
/// by the codec. The network must read the segment directions, as on real vehicles, so it
/// learns something real; it is small and fast enough for CPU tests.
///
/// VPs are drawn in the box frame with a log-uniform distance in `[0.5, 100]` box half-sizes
/// and a uniform direction, so every scale of the paper's codec is exercised.
#[derive(Debug, Clone)]
pub struct ToySource {
    /// Number of training samples.
    pub train_len: usize,
    /// Number of validation samples.
    pub val_len: usize,
    /// Seed of everything: samples, order.
    pub seed: u64,
    /// Crop side, pixels.
    pub input_size: usize,
    /// Codec of the targets.
    pub codec: HeatmapCodec,
    /// Shuffle the training samples every epoch.
    pub shuffle: bool,
}

/// One toy sample: the crop (RGB `[0, 1]`, CHW) and its VPs in the box frame.
#[derive(Debug, Clone)]
pub struct ToySample {
    pub image: Vec<f32>,
    pub vp1: Point2,
    pub vp2: Point2,
}

impl ToySource {
    /// A toy source matching a model config's input size and codec.
    pub fn new(
        train_len: usize,
        val_len: usize,
        seed: u64,
        input_size: usize,
        codec: HeatmapCodec,
    ) -> ToySource {
        ToySource {
            train_len,
            val_len,
            seed,
            input_size,
            codec,
            shuffle: true,
        }
    }

    /// Sample `index` of the training (`validation == false`) or validation split.
    pub fn sample(&self, index: usize, validation: bool) -> ToySample {
        let stream = if validation { 1u64 << 40 } else { 0 };
        let mut rng = ChaCha8Rng::seed_from_u64(
            self.seed
                .wrapping_mul(0x9E37_79B9_7F4A_7C15)
                .wrapping_add(stream + index as u64),
        );
        let draw_vp = |rng: &mut ChaCha8Rng| {
            let r = 10f64.powf(rng.random_range(-0.3..2.0));
            let a = rng.random_range(0.0..std::f64::consts::TAU);
            Point2::new(r * a.cos(), r * a.sin())
        };
        let vp1 = draw_vp(&mut rng);
        let vp2 = draw_vp(&mut rng);
        let s = self.input_size;
        let mut image = vec![0.5f32; 3 * s * s];
        let half = s as f64 / 2.0;
        let segments = 6;
        for (channel, vp) in [(0usize, vp1), (1usize, vp2)] {
            // The VP in crop pixels (x right, y down): centre + vp * half size.
            let vp_px = Point2::new(half + vp.x * half, half + vp.y * half);
            for _ in 0..segments {
                let q = Point2::new(
                    rng.random_range(0.15..0.85) * s as f64,
                    rng.random_range(0.15..0.85) * s as f64,
                );
                let d = vp_px - q;
                let n = d.norm();
                if n < 1e-9 {
                    continue;
                }
                let dir = d / n;
                let len = rng.random_range(0.15..0.3) * s as f64;
                draw_segment(
                    &mut image,
                    s,
                    channel,
                    q - dir * (len / 2.0),
                    q + dir * (len / 2.0),
                );
            }
        }
        ToySample { image, vp1, vp2 }
    }

    fn batch_of(&self, indices: &[usize], validation: bool) -> Batch {
        let s = self.input_size;
        let channels = self.codec.channels();
        let r = self.codec.resolution;
        let mut images = Vec::with_capacity(indices.len() * 3 * s * s);
        let mut targets = vec![0.0f32; indices.len() * channels * r * r];
        let mut vp1_box = Vec::with_capacity(indices.len());
        let mut vp2_box = Vec::with_capacity(indices.len());
        let mut ids = Vec::with_capacity(indices.len());
        for (k, &i) in indices.iter().enumerate() {
            let sample = self.sample(i, validation);
            images.extend_from_slice(&sample.image);
            let plane = channels * r * r;
            self.codec.render_targets_into(
                sample.vp1,
                sample.vp2,
                &mut targets[k * plane..(k + 1) * plane],
            );
            vp1_box.push(sample.vp1.as_array());
            vp2_box.push(sample.vp2.as_array());
            ids.push(SampleId {
                vehicle: i as u64 * 10 + if validation { 0 } else { 2 },
                instance: 0,
            });
        }
        Batch {
            size: indices.len(),
            input_size: s,
            images,
            channels,
            heatmap_res: r,
            targets,
            vp1_box,
            vp2_box,
            ids,
            weights: vec![1.0; indices.len() * channels],
        }
    }

    fn batches(&self, order: Vec<usize>, batch_size: usize, validation: bool) -> BatchIter<'_> {
        let batch_size = batch_size.max(1);
        let chunks: Vec<Vec<usize>> = order.chunks(batch_size).map(<[usize]>::to_vec).collect();
        Box::new(
            chunks
                .into_iter()
                .map(move |idx| Ok(self.batch_of(&idx, validation))),
        )
    }
}

impl BatchSource for ToySource {
    fn describe(&self) -> String {
        format!(
            "toy: {} train / {} validation crops of {}x{} px, seed {}",
            self.train_len, self.val_len, self.input_size, self.input_size, self.seed
        )
    }

    fn train_batches(&self, batch_size: usize) -> usize {
        self.train_len.div_ceil(batch_size.max(1))
    }

    fn train_epoch(&self, epoch: usize, batch_size: usize) -> BatchIter<'_> {
        let mut order: Vec<usize> = (0..self.train_len).collect();
        if self.shuffle {
            let mut rng = ChaCha8Rng::seed_from_u64(self.seed ^ (0xA5A5_0000 + epoch as u64));
            // Fisher-Yates.
            for i in (1..order.len()).rev() {
                let j = rng.random_range(0..=i);
                order.swap(i, j);
            }
        }
        self.batches(order, batch_size, false)
    }

    fn validation_batches(&self, batch_size: usize) -> usize {
        self.val_len.div_ceil(batch_size.max(1))
    }

    fn validation(&self, batch_size: usize) -> BatchIter<'_> {
        self.batches((0..self.val_len).collect(), batch_size, true)
    }
}

/// Draw a 1.5 px wide segment into one channel of a CHW image (values set to 1, the other
/// channels to 0 under the segment).
fn draw_segment(image: &mut [f32], s: usize, channel: usize, a: Point2, b: Point2) {
    let d = b - a;
    let len = d.norm();
    let steps = (len * 2.0).ceil().max(1.0) as usize;
    let plane = s * s;
    for k in 0..=steps {
        let p = a + d * (k as f64 / steps as f64);
        for (ox, oy) in [(0.0, 0.0), (0.5, 0.0), (0.0, 0.5)] {
            let x = (p.x + ox).floor();
            let y = (p.y + oy).floor();
            if x < 0.0 || y < 0.0 || x >= s as f64 || y >= s as f64 {
                continue;
            }
            let idx = y as usize * s + x as usize;
            for c in 0..3 {
                image[c * plane + idx] = if c == channel { 1.0 } else { 0.0 };
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn toy() -> ToySource {
        ToySource::new(
            10,
            3,
            5,
            32,
            HeatmapCodec::new(16, vec![0.03, 0.1, 0.3, 1.0]),
        )
    }

    #[test]
    fn epochs_are_deterministic_and_shuffled() {
        let t = toy();
        let ids = |epoch| -> Vec<u64> {
            t.train_epoch(epoch, 4)
                .flat_map(|b| b.unwrap().ids.into_iter().map(|i| i.vehicle))
                .collect()
        };
        assert_eq!(ids(0), ids(0));
        assert_ne!(ids(0), ids(1));
        let mut sorted = ids(1);
        sorted.sort_unstable();
        assert_eq!(sorted, (0..10).map(|i| i * 10 + 2).collect::<Vec<_>>());
        assert_eq!(t.train_batches(4), 3);
    }

    #[test]
    fn batches_have_consistent_shapes_and_targets() {
        let t = toy();
        let b = t.validation(2).next().unwrap().unwrap();
        assert_eq!(b.size, 2);
        assert_eq!(b.images.len(), 2 * 3 * 32 * 32);
        assert_eq!(b.targets.len(), 2 * 8 * 16 * 16);
        // Every channel of a finite VP has its peak value 1.
        for c in 0..16 {
            let m = b.targets[c * 256..(c + 1) * 256]
                .iter()
                .fold(0.0f32, |a, &v| a.max(v));
            assert_eq!(m, 1.0, "channel {c}");
        }
        // The image is not blank: segments were drawn in both colours.
        assert!(b.images[..1024].contains(&1.0));
        assert!(b.images[1024..2048].contains(&1.0));
    }
}
