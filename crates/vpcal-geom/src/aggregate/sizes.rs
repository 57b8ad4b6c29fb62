//! Do the vehicles' sizes agree with the horizon?
//!
//! On a road plane, the image size of an object standing at foot point `p` is proportional to
//! 1/depth, and 1/depth is proportional to the distance of `p` from the horizon line (both
//! vanish at the horizon). So a vehicle's box grows linearly with how far below the horizon it
//! stands: `ln size` against `ln distance` has slope 1 when the horizon is right (a little
//! more in practice, as far vehicles are seen more from the front and detectors clip them).
//! When the estimated horizon is wrong the slope says so: a camera looking straight down
//! sees every vehicle at about the same size, so an estimated horizon inside or near the frame
//! gives a slope near 0.
//!
//! Measured with the reference detector's boxes (`detections.json`, score ≥ 0.5) against the
//! reference cameras of the 12 real BrnoCompSpeed dev videos (`camera_truth.json`): slopes
//! 1.16-1.90, median 1.41 (`scripts/size_slope.py`). [`MIN_SIZE_SLOPE`] sits well below.

use crate::point::{BoxPx, Line, Point2};
use crate::solve::{median, SplitMix};

/// A calibration whose horizon gives a slope below this contradicts the vehicles' sizes.
pub const MIN_SIZE_SLOPE: f64 = 0.5;
/// Fewer usable boxes than this: no check.
pub const MIN_SIZE_BOXES: usize = 30;
/// Boxes within this many pixels of the frame's border are clipped: not used.
pub const BORDER_PX: f64 = 10.0;
/// Random pairs of boxes for the Theil-Sen slope (all pairs would be quadratic).
const SLOPE_PAIRS: usize = 4000;
/// Pairs whose log distances differ by less than this carry no slope.
const MIN_LOG_GAP: f64 = 0.05;

/// The slope of `ln size` against `ln distance below the horizon`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SizeSlope {
    /// Theil-Sen slope (1 when sizes scale as the horizon predicts).
    pub slope: f64,
    /// Boxes used.
    pub boxes: usize,
    /// How far apart the boxes stand: the 10th-90th percentile range of `ln distance`.
    pub log_distance_range: f64,
}

/// The size slope of `boxes` (frame pixels; size `sqrt(width·height)`, foot point the bottom
/// centre; each with its weight in `weights`: repeated boxes of a static false detection
/// must not outvote the traffic) against `horizon`, in a `width` × `height` frame. Boxes near the border, or on or
/// above the horizon, are left out. `None` with fewer than [`MIN_SIZE_BOXES`] usable boxes or
/// a degenerate horizon.
pub fn size_slope(
    boxes: &[BoxPx],
    weights: &[f64],
    horizon: Line,
    width: f64,
    height: f64,
) -> Option<SizeSlope> {
    let line = horizon.normalized()?;
    let inside = |b: &&BoxPx| b.clear_of_edges(width, height, BORDER_PX);
    let raw: Vec<(f64, f64, f64)> = boxes
        .iter()
        .zip(weights)
        .filter(|(b, w)| inside(b) && **w > 0.0)
        .filter_map(|(b, &w)| {
            let foot = Point2::new(0.5 * (b.x0 + b.x1), b.y1);
            let d = line.signed_distance(foot)?;
            let s = (b.width() * b.height()).sqrt();
            (d.is_finite() && s > 0.0).then_some((d, s, w))
        })
        .collect();
    // Below the horizon is the side most vehicles stand on.
    let side = if median(&raw.iter().map(|r| r.0).collect::<Vec<_>>())? < 0.0 {
        -1.0
    } else {
        1.0
    };
    let pts: Vec<(f64, f64)> = raw
        .iter()
        .filter(|(d, _, _)| side * d > 0.0)
        .map(|&(d, s, _)| ((side * d).ln(), s.ln()))
        .collect();
    if pts.len() < MIN_SIZE_BOXES {
        return None;
    }
    // Pairs drawn with probability proportional to the boxes' weights.
    let mut cumulative = Vec::with_capacity(pts.len());
    let mut total = 0.0;
    for (d, _, w) in &raw {
        if side * d > 0.0 {
            total += w;
            cumulative.push(total);
        }
    }
    let mut rng = SplitMix(0x5153_5a45);
    let mut draw = || {
        let u = rng.next_f64() * total;
        pts[cumulative.partition_point(|&c| c <= u).min(pts.len() - 1)]
    };
    let slopes: Vec<f64> = (0..SLOPE_PAIRS)
        .filter_map(|_| {
            let a = draw();
            let b = draw();
            let dx = a.0 - b.0;
            (dx.abs() > MIN_LOG_GAP).then(|| (a.1 - b.1) / dx)
        })
        .collect();
    let mut logs: Vec<f64> = pts.iter().map(|p| p.0).collect();
    logs.sort_by(f64::total_cmp);
    Some(SizeSlope {
        slope: median(&slopes)?,
        boxes: pts.len(),
        log_distance_range: crate::solve::percentile_sorted(&logs, 90.0)
            - crate::solve::percentile_sorted(&logs, 10.0),
    })
}

/// Total weight of the points on the other side of `horizon` than the image's bottom, seen
/// from the principal point's column.
pub fn weight_above_horizon(centres: &[Point2], weights: &[f64], horizon: Line, pp: Point2) -> f64 {
    let side = |p: Point2| horizon.signed_distance(p).map(f64::signum);
    let below = side(Point2::new(pp.x, pp.y + 1e7));
    centres
        .iter()
        .zip(weights)
        .filter(|(c, _)| side(**c) != below)
        .map(|(_, w)| w)
        .sum()
}

/// The camera's horizon against the vehicles (`centres`, `boxes` and `weights` of the usable
/// ones, in a `frame` of `[width, height]` pixels): more than `max_above` of their weight above
/// it is impossible (vehicles stand on the road, below the horizon; on the synthetic suite
/// the outright failures had 98-100 % above, every other result none,
/// `scripts/horizon_vs_boxes.py`), and so is a [`size_slope`] below [`MIN_SIZE_SLOPE`] (a
/// camera looking almost straight down sees them all alike, whatever horizon the VPs gave).
/// Returns the size slope where there were enough boxes to measure it.
///
/// # Errors
/// Why the horizon contradicts the vehicles, as a sentence.
pub fn check_horizon(
    centres: &[Point2],
    boxes: &[BoxPx],
    weights: &[f64],
    horizon: Line,
    pp: Point2,
    [width, height]: [f64; 2],
    max_above: f64,
) -> Result<Option<f64>, String> {
    let total: f64 = weights.iter().sum::<f64>() + 0.0;
    let above = weight_above_horizon(centres, weights, horizon, pp) / total;
    if above > max_above {
        return Err(format!(
            "the estimated horizon runs through the traffic: {:.0} % of the vehicle weight lies \
             above it (at most {:.0} % allowed); the per-vehicle VPs do not agree on a camera",
            100.0 * above,
            100.0 * max_above
        ));
    }
    let sizes = size_slope(boxes, weights, horizon, width, height);
    if let Some(s) = sizes.filter(|s| s.slope < MIN_SIZE_SLOPE) {
        return Err(format!(
            "the vehicles' sizes contradict the estimated horizon: they grow with the distance \
             below it as its power {:.2} (about 1 expected, at least {:.1} allowed; {} boxes); \
             a camera looking almost straight down, whose focal length and horizon cannot be \
             observed, or per-vehicle VPs that do not agree on a camera",
            s.slope, MIN_SIZE_SLOPE, s.boxes
        ));
    }
    Ok(sizes.map(|s| s.slope))
}

#[cfg(test)]
mod tests {
    use super::*;

    const FRAME: [f64; 2] = [1280.0, 720.0];
    const PP: Point2 = Point2::new(640.0, 360.0);

    /// 60 vehicles standing between 60 and 560 px below the line y = 100, each box
    /// `size(distance)` pixels wide.
    fn vehicles(size: impl Fn(f64) -> f64) -> (Vec<Point2>, Vec<BoxPx>) {
        (0..60)
            .map(|i| {
                let d = 60.0 + 500.0 * (i as f64 / 59.0);
                let (x, foot, s) = (100.0 + 18.0 * i as f64, 100.0 + d, size(d));
                let b = BoxPx::new(x - s / 2.0, foot - 0.8 * s, x + s / 2.0, foot);
                (b.center(), b)
            })
            .unzip()
    }

    fn check(horizon_y: f64, size: impl Fn(f64) -> f64) -> Result<Option<f64>, String> {
        let (centres, boxes) = vehicles(size);
        let weights = vec![1.0; centres.len()];
        let horizon =
            Line::through(Point2::new(0.0, horizon_y), Point2::new(1280.0, horizon_y)).unwrap();
        check_horizon(&centres, &boxes, &weights, horizon, PP, FRAME, 0.5)
    }

    #[test]
    fn vehicles_that_grow_away_from_the_horizon_agree_with_it() {
        let slope = check(100.0, |d| 0.25 * d).unwrap().unwrap();
        assert!((slope - 1.0).abs() < 0.05, "{slope}");
    }

    #[test]
    fn a_horizon_through_the_traffic_is_refused() {
        let err = check(500.0, |d| 0.25 * d).unwrap_err();
        assert!(err.contains("runs through the traffic"), "{err}");
    }

    #[test]
    fn vehicles_all_alike_contradict_a_horizon() {
        let err = check(100.0, |_| 60.0).unwrap_err();
        assert!(err.contains("sizes contradict"), "{err}");
    }
}
