//! Vehicle detection: one trait, three detectors.
//!
//! - [`MotionDetector`]: weight-free, for fixed cameras (background model + foreground blobs);
//!   the default.
//! - [`FileDetector`]: boxes from any external detector, read from the reference's
//!   `detections.json` or from our simple CSV/JSON ([`crate::detect::file`] documents them).
//! - `OnnxDetector` (cargo feature `onnx`): a learned detector from a user-supplied ONNX file.

pub mod file;
pub mod motion;
#[cfg(feature = "onnx")]
pub mod onnx;
#[cfg(feature = "onnx")]
pub mod yolox;

pub use file::FileDetector;
pub use motion::{MotionConfig, MotionDetector};
#[cfg(feature = "onnx")]
pub use onnx::{OnnxConfig, OnnxDetector, OnnxLayout};
#[cfg(feature = "onnx")]
pub use yolox::{YoloxConfig, YoloxDetector};

use vpcal_geom::BoxPx;

use crate::error::Result;
use crate::source::Frame;

/// One detected vehicle.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Detection {
    /// The box in frame pixels (continuous coordinates: pixel (i, j) covers [i, i+1) × [j, j+1)).
    /// Named `bbox` because `box` is a Rust keyword.
    pub bbox: BoxPx,
    /// Confidence in [0, 1]; its meaning depends on the detector (see each detector's docs).
    pub score: f32,
}

/// Finds vehicles in frames. Detectors may keep state across frames (a background model, the
/// position in a file), so frames must be passed in stream order.
pub trait Detector: Send {
    /// The vehicles in `frame`, in no particular order.
    ///
    /// # Errors
    /// Detector-specific: a frame of the wrong size, a failed model run.
    fn detect(&mut self, frame: &Frame) -> Result<Vec<Detection>>;

    /// The vehicles in each of `frames` (consecutive frames, in stream order), one result per
    /// frame: the same as calling [`Detector::detect`] on each in turn, which is what this
    /// default does. A detector whose work per frame splits into independent runs spreads the
    /// runs of all the frames over the cores.
    fn detect_batch(&mut self, frames: &[Frame]) -> Vec<Result<Vec<Detection>>> {
        frames.iter().map(|f| self.detect(f)).collect()
    }

    /// How many consecutive frames [`Detector::detect_batch`] is best given at a time (1: it
    /// gains nothing from more).
    fn batch_frames(&self) -> usize {
        1
    }

    /// A short name for logs and for the settings recorded with results.
    fn name(&self) -> String;

    /// The frames before this index (source index) only taught the detector (a motion
    /// detector's warm-up builds its background from them) and gave no detections. `None`
    /// when the detector needs no such frames or is still learning.
    fn learned_until(&self) -> Option<u64> {
        None
    }

    /// A detector for a second look at the frames before [`Detector::learned_until`], with
    /// what was learned from them; feed it those frames in stream order. `None` when there is
    /// nothing to look at again.
    fn replay(&self) -> Option<Box<dyn Detector>> {
        None
    }
}

/// Intersection over union of two boxes (0 when either is empty).
pub fn iou(a: &BoxPx, b: &BoxPx) -> f64 {
    let iw = (a.x1.min(b.x1) - a.x0.max(b.x0)).max(0.0);
    let ih = (a.y1.min(b.y1) - a.y0.max(b.y0)).max(0.0);
    let inter = iw * ih;
    let union =
        a.width().max(0.0) * a.height().max(0.0) + b.width().max(0.0) * b.height().max(0.0) - inter;
    if union > 0.0 {
        inter / union
    } else {
        0.0
    }
}

/// Greedy non-maximum suppression: keeps the best-scoring boxes and drops any box whose IoU
/// with an already kept box exceeds `iou_threshold`. The result is sorted by score, best first.
pub fn non_max_suppression(mut dets: Vec<Detection>, iou_threshold: f64) -> Vec<Detection> {
    dets.sort_by(|a, b| b.score.total_cmp(&a.score));
    let mut kept: Vec<Detection> = Vec::with_capacity(dets.len());
    for d in dets {
        if kept.iter().all(|k| iou(&k.bbox, &d.bbox) <= iou_threshold) {
            kept.push(d);
        }
    }
    kept
}

#[cfg(test)]
mod tests {
    use super::*;

    fn det(x0: f64, y0: f64, x1: f64, y1: f64, score: f32) -> Detection {
        Detection {
            bbox: BoxPx::new(x0, y0, x1, y1),
            score,
        }
    }

    #[test]
    fn iou_of_known_boxes() {
        let a = BoxPx::new(0.0, 0.0, 10.0, 10.0);
        assert!((iou(&a, &a) - 1.0).abs() < 1e-12);
        assert!((iou(&a, &BoxPx::new(5.0, 0.0, 15.0, 10.0)) - 50.0 / 150.0).abs() < 1e-12);
        assert_eq!(iou(&a, &BoxPx::new(20.0, 20.0, 30.0, 30.0)), 0.0);
    }

    #[test]
    fn nms_keeps_the_best_of_overlapping_boxes() {
        let kept = non_max_suppression(
            vec![
                det(0.0, 0.0, 10.0, 10.0, 0.5),
                det(1.0, 0.0, 11.0, 10.0, 0.9),
                det(50.0, 50.0, 60.0, 60.0, 0.3),
            ],
            0.5,
        );
        assert_eq!(kept.len(), 2);
        assert_eq!(kept[0].score, 0.9);
        assert_eq!(kept[1].score, 0.3);
    }
}
