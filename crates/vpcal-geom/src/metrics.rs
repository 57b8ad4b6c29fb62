//! Calibration metrics (DESIGN.md §8): the pure-calibration ratio error of BrnoCompSpeed, the
//! scaled distance error, the optimal-scale error of BrnoCarPark, and summary statistics.

use crate::camera::Calibration;
use crate::point::Point2;

/// A measured distance between two road points seen at pixels `p1`, `p2`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RoadMeasurement {
    pub p1: Point2,
    pub p2: Point2,
    pub distance_m: f64,
}

/// Mean, median, 95th percentile and maximum of a set of errors.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Summary {
    /// Number of values.
    pub n: usize,
    pub mean: f64,
    pub median: f64,
    /// 95th percentile, linear interpolation between order statistics (numpy's default).
    pub p95: f64,
    pub max: f64,
}

/// Summary statistics of `values`; `None` when empty or when any value is not finite.
pub fn summarize(values: &[f64]) -> Option<Summary> {
    if values.is_empty() || values.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let n = sorted.len();
    Some(Summary {
        n,
        mean: sorted.iter().sum::<f64>() / n as f64,
        median: percentile_sorted(&sorted, 50.0),
        p95: percentile_sorted(&sorted, 95.0),
        max: sorted[n - 1],
    })
}

pub use crate::solve::{median, percentile_sorted, weighted_median};

/// Road distances (plane units) of the measurements under `calib`; `None` when any pixel
/// cannot be projected.
pub fn projected_distances(calib: &Calibration, m: &[RoadMeasurement]) -> Option<Vec<f64>> {
    m.iter().map(|m| calib.road_distance(m.p1, m.p2)).collect()
}

/// Pure-calibration ratio errors, percent, for every unordered pair `(i, j)`, `i < j`, in
/// lexicographic order: `|d̂_i/d̂_j - d_i/d_j| / (d_i/d_j) · 100`, with `d̂` the projected and
/// `d` the true distances. `None` when a pixel cannot be projected or a ratio is not finite.
pub fn ratio_errors(calib: &Calibration, m: &[RoadMeasurement]) -> Option<Vec<f64>> {
    let projected = projected_distances(calib, m)?;
    let mut out = Vec::with_capacity(m.len() * m.len().saturating_sub(1) / 2);
    for i in 0..m.len() {
        for j in i + 1..m.len() {
            let est = projected[i] / projected[j];
            let truth = m[i].distance_m / m[j].distance_m;
            let e = (est - truth).abs() / truth * 100.0;
            if !e.is_finite() {
                return None;
            }
            out.push(e);
        }
    }
    Some(out)
}

/// Scaled distance errors, percent: `|scale·d̂ - d| / d · 100` per measurement.
pub fn scaled_distance_errors(
    calib: &Calibration,
    scale: f64,
    m: &[RoadMeasurement],
) -> Option<Vec<f64>> {
    let projected = projected_distances(calib, m)?;
    let out: Vec<f64> = projected
        .iter()
        .zip(m)
        .map(|(d_hat, m)| (scale * d_hat - m.distance_m).abs() / m.distance_m * 100.0)
        .collect();
    out.iter().all(|e| e.is_finite()).then_some(out)
}

/// The scale minimising the mean relative distance error `Σ |s·d̂_i - d_i| / d_i`: the
/// weighted median of `d_i / d̂_i` with weights `d̂_i / d_i`.
pub fn optimal_scale(calib: &Calibration, m: &[RoadMeasurement]) -> Option<f64> {
    let projected = projected_distances(calib, m)?;
    let ratios: Vec<f64> = projected
        .iter()
        .zip(m)
        .map(|(p, m)| m.distance_m / p)
        .collect();
    let weights: Vec<f64> = projected
        .iter()
        .zip(m)
        .map(|(p, m)| p / m.distance_m)
        .collect();
    weighted_median(&ratios, &weights)
}

/// The line angle (radians, in `(-π/2, π/2]`) of the direction from `at` towards the point
/// `h`, given in homogeneous coordinates `[x, y, w]` (a point at infinity, `w = 0`, is a
/// direction); `None` when `h` is `at` itself or not finite.
pub fn direction_towards(at: Point2, h: [f64; 3]) -> Option<f64> {
    let (dx, dy) = (h[0] - h[2] * at.x, h[1] - h[2] * at.y);
    if !(dx.is_finite() && dy.is_finite()) || dx == 0.0 && dy == 0.0 {
        return None;
    }
    Some(crate::aggregate::line_angle_diff(dy.atan2(dx)))
}

/// The direction error of a vanishing point seen from `at` (a vehicle's box centre): the
/// angle between the lines from `at` towards `predicted` and towards `truth` (homogeneous,
/// see [`direction_towards`]), modulo 180°, in degrees `[0, 90]`. `None` when either
/// direction is undefined.
pub fn direction_error_deg(at: Point2, predicted: [f64; 3], truth: [f64; 3]) -> Option<f64> {
    signed_direction_error_deg(at, predicted, truth).map(f64::abs)
}

/// [`direction_error_deg`] with its sign: the line angle from the direction towards `truth`
/// to the direction towards `predicted`, degrees in `(-90, 90]` (positive: turned from the
/// image's x axis towards its y axis). A median over many vehicles measures a systematic
/// turn of the evidence rather than its scatter.
pub fn signed_direction_error_deg(at: Point2, predicted: [f64; 3], truth: [f64; 3]) -> Option<f64> {
    let a = direction_towards(at, predicted)?;
    let b = direction_towards(at, truth)?;
    Some(crate::aggregate::line_angle_diff(a - b).to_degrees())
}
