//! The paper's aggregation rule, as its public code computed it.
//!
//! 1. Keep pairs with `score > min_score` (0.1).
//! 2. `f_i = sqrt(-(vp1_i - pp)·(vp2_i - pp))`; drop pairs whose `f_i` is NaN (imaginary or
//!    undefined). Infinite `f_i` stay, as they did in the reference.
//! 3. `f = median(f_i)`; horizon slope `m = median((vp1y - vp2y)/(vp1x - vp2x))`; intercept
//!    `k = median` of `vp1y - m_i vp1x` and `vp2y - m_i vp2x` over all pairs (each median
//!    ignores NaN, like numpy's `nanmedian`). Horizon: `y = m x + k`.
//! 4. `vp1` = the component-wise median of the `vp1_i` (a NaN component poisons it, like
//!    numpy's `median`), projected orthogonally onto the horizon.
//! 5. `vp2` = the point of the horizon with `(vp1 - pp)·(vp2 - pp) = -f²`.

use super::{AggregateError, VehicleVps};
use crate::point::Point2;

/// Settings of the reference rule.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ReferenceOptions {
    /// Pairs need a detector score strictly above this.
    pub min_score: f64,
}

impl Default for ReferenceOptions {
    fn default() -> Self {
        ReferenceOptions { min_score: 0.1 }
    }
}

/// The reference rule's output and the evidence it used.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReferenceResult {
    pub vp1: Point2,
    pub vp2: Point2,
    /// The median focal length, pixels.
    pub focal_px: f64,
    /// Horizon slope `m` of `y = m x + k`.
    pub horizon_slope: f64,
    /// Horizon intercept `k` of `y = m x + k`.
    pub horizon_intercept: f64,
    /// Pairs given.
    pub pairs_in: usize,
    /// Pairs above the score threshold.
    pub pairs_scored: usize,
    /// Pairs used (score above threshold and a non-NaN focal length).
    pub pairs_used: usize,
}

/// Median ignoring NaN (numpy `nanmedian`); infinities sort normally. NaN when nothing is left.
fn nan_median(values: impl IntoIterator<Item = f64>) -> f64 {
    let v: Vec<f64> = values.into_iter().collect();
    crate::solve::median(&v).unwrap_or(f64::NAN)
}

/// Median propagating NaN (numpy `median`).
fn plain_median(values: impl IntoIterator<Item = f64>) -> f64 {
    // numpy's median: a NaN anywhere makes the median NaN.
    let v: Vec<f64> = values.into_iter().collect();
    if v.iter().any(|x| x.is_nan()) {
        return f64::NAN;
    }
    crate::solve::median(&v).unwrap_or(f64::NAN)
}

/// Apply the reference rule to `pairs` with principal point `pp`.
///
/// # Errors
/// [`AggregateError::NotEnoughEvidence`] when no pair survives the filters or the medians are
/// not finite.
pub fn aggregate(
    pairs: &[VehicleVps],
    pp: Point2,
    options: &ReferenceOptions,
) -> Result<ReferenceResult, AggregateError> {
    let scored: Vec<&VehicleVps> = pairs
        .iter()
        .filter(|p| p.score > options.min_score && !p.copied)
        .collect();
    let mut used: Vec<(Point2, Point2, f64)> = Vec::with_capacity(scored.len());
    for p in &scored {
        let d = (p.vp1.x - pp.x) * (p.vp2.x - pp.x) + (p.vp1.y - pp.y) * (p.vp2.y - pp.y);
        let f = (-d).sqrt();
        if !f.is_nan() {
            used.push((p.vp1, p.vp2, f));
        }
    }
    if used.is_empty() {
        return Err(AggregateError::NotEnoughEvidence(format!(
            "no vehicle VP pair with score > {} and a real focal length ({} pairs given, {} above the score threshold)",
            options.min_score,
            pairs.len(),
            scored.len()
        )));
    }
    let focal = nan_median(used.iter().map(|u| u.2));
    let slopes: Vec<f64> = used
        .iter()
        .map(|(a, b, _)| (a.y - b.y) / (a.x - b.x))
        .collect();
    let intercepts = used
        .iter()
        .zip(&slopes)
        .map(|((a, _, _), m)| a.y - m * a.x)
        .chain(used.iter().zip(&slopes).map(|((_, b, _), m)| b.y - m * b.x));
    let m = nan_median(slopes.iter().copied());
    let k = nan_median(intercepts);
    let vp1_x = plain_median(used.iter().map(|u| u.0.x));
    let vp1_y = plain_median(used.iter().map(|u| u.0.y));
    if ![focal, m, k, vp1_x, vp1_y].iter().all(|v| v.is_finite()) {
        return Err(AggregateError::NotEnoughEvidence(format!(
            "the medians are not finite (focal {focal}, horizon slope {m}, intercept {k}, vp1 ({vp1_x}, {vp1_y}))"
        )));
    }
    // Horizon a x + b y + c = 0 with (a, b, c) = (m, -1, k); orthogonal projection of the
    // median vp1, written as the reference wrote it.
    let (a, b, c) = (m, -1.0, k);
    let den = a * a + b * b;
    let x1 = (b * (b * vp1_x - a * vp1_y) - a * c) / den;
    let y1 = (a * (-b * vp1_x + a * vp1_y) - b * c) / den;
    // vp2: on the horizon and orthogonal to vp1: solve [[a, b], [aa, bb]] (x, y) = (-c, -cc).
    let aa = -(x1 - pp.x);
    let bb = -(y1 - pp.y);
    let cc = (x1 - pp.x) * pp.x + (y1 - pp.y) * pp.y - focal * focal;
    let vp2 = solve2([[a, b], [aa, bb]], [-c, -cc]).ok_or_else(|| {
        AggregateError::NotEnoughEvidence(
            "vp1 lies where no orthogonal vp2 exists on the horizon".into(),
        )
    })?;
    Ok(ReferenceResult {
        vp1: Point2::new(x1, y1),
        vp2,
        focal_px: focal,
        horizon_slope: m,
        horizon_intercept: k,
        pairs_in: pairs.len(),
        pairs_scored: scored.len(),
        pairs_used: used.len(),
    })
}

/// Solve a 2x2 linear system by Gaussian elimination with partial pivoting (as LAPACK's
/// `gesv` does); `None` when singular.
fn solve2(m: [[f64; 2]; 2], rhs: [f64; 2]) -> Option<Point2> {
    let (mut r0, mut r1, mut b0, mut b1) = (m[0], m[1], rhs[0], rhs[1]);
    if r1[0].abs() > r0[0].abs() {
        std::mem::swap(&mut r0, &mut r1);
        std::mem::swap(&mut b0, &mut b1);
    }
    if r0[0] == 0.0 {
        return None;
    }
    let l = r1[0] / r0[0];
    let u11 = r1[1] - l * r0[1];
    let y1 = b1 - l * b0;
    if u11 == 0.0 {
        return None;
    }
    let x1 = y1 / u11;
    let x0 = (b0 - r0[1] * x1) / r0[0];
    let p = Point2::new(x0, x1);
    p.is_finite().then_some(p)
}
