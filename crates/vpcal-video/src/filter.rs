//! Per-frame filtering of detections, as the reference did (DESIGN.md §2, §7).
//!
//! In order, each step switchable:
//! 1. **Score threshold**: keep boxes with `score > min_score` (the reference used 0.1 on
//!    CenterNet scores).
//! 2. Sort by score, best first (a detector's own order is not trusted).
//! 3. **Static-vehicle rule**: `E = Canny(grey, 100, 200)` with OpenCV's grey weights (OpenCV conventions, see
//!    [`crate::edges`]); `D = |E − E_prev|` in 8-bit wrapping arithmetic, as numpy computed it
//!    on `uint8` arrays, so an edge that vanished counts 1 and a new edge 255; on the first frame
//!    `D = E`. A box is kept when the mean of `D` over its integer box
//!    ([`crate::crop::integer_box`]) exceeds 5: parked vehicles have unchanged edges. The
//!    previous edge map is the one of the previous frame *given to the filter*, so the rule
//!    compares frames `every` apart.
//! 4. **Seen before** (off by default; on for folders of stills, where the static rule cannot
//!    work since the pictures are not consecutive frames): a box whose IoU with a box kept in
//!    an earlier frame exceeds `drop_seen_iou` is the same parked vehicle again and counts once.
//! 5. **At most `max_per_frame`** boxes (10), the best-scoring ones that passed.

use image::GrayImage;

use crate::crop::integer_box;
use crate::detect::Detection;
use crate::edges::{canny_opencv, grey_opencv};
use crate::source::Frame;

/// Settings of [`FrameFilter`]; `None`/`false` switches a step off.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FilterConfig {
    /// Keep boxes with a score strictly above this.
    pub min_score: Option<f32>,
    /// Apply the static-vehicle rule.
    pub drop_static: bool,
    /// Mean edge difference a box must exceed to be kept.
    pub static_threshold: f64,
    /// Canny thresholds (low, high).
    pub canny_thresholds: (f32, f32),
    /// Drop a box whose IoU with a box kept in an earlier frame is above this.
    pub drop_seen_iou: Option<f64>,
    /// Keep at most this many boxes per frame.
    pub max_per_frame: Option<usize>,
}

impl Default for FilterConfig {
    fn default() -> Self {
        FilterConfig {
            min_score: Some(0.1),
            drop_static: true,
            static_threshold: 5.0,
            canny_thresholds: (100.0, 200.0),
            drop_seen_iou: None,
            max_per_frame: Some(10),
        }
    }
}

/// Why a detection was dropped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DropReason {
    LowScore,
    Static,
    OverLimit,
    /// The box does not overlap the frame.
    OutsideFrame,
    /// A box kept in an earlier frame is at the same place (see [`FilterConfig::drop_seen_iou`]).
    SeenBefore,
}

/// The outcome for one frame: kept boxes (best first) and dropped ones with the reason.
#[derive(Debug, Clone, Default)]
pub struct Filtered {
    pub kept: Vec<Detection>,
    pub dropped: Vec<(Detection, DropReason)>,
}

/// The stateful per-frame filter (it remembers the previous frame's edges).
#[derive(Debug)]
pub struct FrameFilter {
    config: FilterConfig,
    prev_edges: Option<GrayImage>,
    /// Boxes kept in earlier frames (only with `drop_seen_iou`).
    seen: Vec<vpcal_geom::BoxPx>,
}

impl FrameFilter {
    pub fn new(config: FilterConfig) -> FrameFilter {
        FrameFilter {
            config,
            prev_edges: None,
            seen: Vec::new(),
        }
    }

    pub fn config(&self) -> &FilterConfig {
        &self.config
    }

    /// Filters the detections of `frame`. Call it for every processed frame, even one without
    /// detections, so that the static rule compares consecutive processed frames.
    pub fn apply(&mut self, frame: &Frame, detections: Vec<Detection>) -> Filtered {
        let mut out = Filtered::default();
        let mut candidates = Vec::with_capacity(detections.len());
        for d in detections {
            match self.config.min_score {
                Some(t) if d.score <= t => out.dropped.push((d, DropReason::LowScore)),
                _ => candidates.push(d),
            }
        }
        candidates.sort_by(|a, b| b.score.total_cmp(&a.score));
        let diff = if self.config.drop_static {
            let grey = grey_opencv(&frame.image);
            let (lo, hi) = self.config.canny_thresholds;
            let edges = canny_opencv(&grey, lo, hi);
            // The previous edge map's buffer becomes the difference (no copy).
            let diff = match self.prev_edges.take() {
                Some(mut prev) if prev.dimensions() == edges.dimensions() => {
                    for (p, &e) in prev.iter_mut().zip(edges.iter()) {
                        *p = e.wrapping_sub(*p);
                    }
                    prev
                }
                _ => edges.clone(),
            };
            self.prev_edges = Some(edges);
            Some(diff)
        } else {
            None
        };
        let (w, h) = frame.image.dimensions();
        let seen_before = self.seen.len();
        for d in candidates {
            if self
                .config
                .max_per_frame
                .is_some_and(|m| out.kept.len() >= m)
            {
                out.dropped.push((d, DropReason::OverLimit));
                continue;
            }
            let Some(ib) = integer_box(&d.bbox, w, h) else {
                out.dropped.push((d, DropReason::OutsideFrame));
                continue;
            };
            if let Some(diff) = &diff {
                let mut sum = 0u64;
                for y in ib.y0..ib.y1 {
                    for x in ib.x0..ib.x1 {
                        sum += u64::from(diff.get_pixel(x, y)[0]);
                    }
                }
                let mean = sum as f64 / ib.area() as f64;
                if mean <= self.config.static_threshold {
                    out.dropped.push((d, DropReason::Static));
                    continue;
                }
            }
            if let Some(t) = self.config.drop_seen_iou {
                if self.seen[..seen_before]
                    .iter()
                    .any(|b| crate::detect::iou(b, &d.bbox) > t)
                {
                    out.dropped.push((d, DropReason::SeenBefore));
                    continue;
                }
                self.seen.push(d.bbox);
            }
            out.kept.push(d);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use vpcal_geom::BoxPx;

    fn frame_with_square(index: u64, x: u32) -> Frame {
        let mut img = image::RgbImage::from_pixel(80, 40, image::Rgb([30, 30, 30]));
        for yy in 10..30 {
            for xx in x..x + 20 {
                img.put_pixel(xx, yy, image::Rgb([220, 220, 220]));
            }
        }
        Frame {
            index,
            time_s: 0.0,
            image: img,
        }
    }

    fn det(x0: f64, score: f32) -> Detection {
        Detection {
            bbox: BoxPx::new(x0, 8.0, x0 + 24.0, 32.0),
            score,
        }
    }

    #[test]
    fn static_boxes_are_dropped_and_moving_ones_kept() {
        let mut f = FrameFilter::new(FilterConfig::default());
        // First frame: D = E, the square's edges make the mean large.
        let r = f.apply(&frame_with_square(0, 10), vec![det(8.0, 0.9)]);
        assert_eq!(r.kept.len(), 1);
        // Same picture again: no edge changed, the box is static.
        let r = f.apply(&frame_with_square(1, 10), vec![det(8.0, 0.9)]);
        assert_eq!(r.kept.len(), 0);
        assert_eq!(r.dropped[0].1, DropReason::Static);
        // The square moved: edges changed inside its new box.
        let r = f.apply(
            &frame_with_square(2, 40),
            vec![det(38.0, 0.9), det(2.0, 0.05)],
        );
        assert_eq!(r.kept.len(), 1);
        assert_eq!(r.dropped[0].1, DropReason::LowScore);
    }

    #[test]
    fn a_parked_vehicle_in_many_stills_counts_once() {
        let mut f = FrameFilter::new(FilterConfig {
            drop_static: false,
            drop_seen_iou: Some(0.7),
            ..FilterConfig::default()
        });
        let d = |x: f64| Detection {
            bbox: BoxPx::new(x, 10.0, x + 20.0, 30.0),
            score: 0.9,
        };
        let frame = Frame {
            index: 0,
            time_s: 0.0,
            image: image::RgbImage::from_pixel(300, 40, image::Rgb([30, 30, 30])),
        };
        let a = f.apply(&frame, vec![d(10.0), d(50.0)]);
        assert_eq!(a.kept.len(), 2);
        // Same places again (one box moved by a pixel), and a new vehicle.
        let b = f.apply(&frame, vec![d(11.0), d(50.0), d(100.0)]);
        assert_eq!(b.kept.len(), 1);
        assert!((b.kept[0].bbox.x0 - 100.0).abs() < 1e-9);
        assert!(b
            .dropped
            .iter()
            .all(|(_, why)| *why == DropReason::SeenBefore));
        // Two boxes of one frame never suppress each other through this rule.
        let c = f.apply(&frame, vec![d(200.0), d(201.0)]);
        assert_eq!(c.kept.len(), 2);
    }

    #[test]
    fn at_most_max_per_frame_best_first() {
        let mut f = FrameFilter::new(FilterConfig {
            drop_static: false,
            max_per_frame: Some(2),
            ..FilterConfig::default()
        });
        let r = f.apply(
            &frame_with_square(0, 10),
            vec![det(0.0, 0.3), det(10.0, 0.9), det(20.0, 0.5)],
        );
        let scores: Vec<f32> = r.kept.iter().map(|d| d.score).collect();
        assert_eq!(scores, vec![0.9, 0.5]);
        assert_eq!(r.dropped[0].1, DropReason::OverLimit);
    }

    #[test]
    fn vanished_edges_count_one_new_edges_255() {
        // Frame 1 has the square, frame 2 is empty: edges vanished, diff = 1 on them, so the
        // mean inside the box is at most 1 and the box counts as static.
        let mut f = FrameFilter::new(FilterConfig::default());
        f.apply(&frame_with_square(0, 10), vec![]);
        let empty = Frame {
            index: 1,
            time_s: 0.0,
            image: image::RgbImage::from_pixel(80, 40, image::Rgb([30, 30, 30])),
        };
        let r = f.apply(&empty, vec![det(8.0, 0.9)]);
        assert_eq!(r.kept.len(), 0);
    }
}
