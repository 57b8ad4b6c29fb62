//! One vehicle's vanishing point from its own edgelets.
//!
//! The camera-wide edgelet fit ([`super::edgelets::fit`]) pools the edgelets of many vehicles
//! through a camera model. To measure how good the edgelets of a *single* real vehicle are
//! (on images with exact per-vehicle VPs, such as KITTI's), this fits the one point that the
//! vehicle's edgelets converge to, with no camera model.
//!
//! Parametrisation: seen from the box centre `c`, the VP lies in direction `t` at inverse
//! distance `k` (signed: `k < 0` puts it behind), `V = [c·k + u(t), k]` homogeneous with
//! `u(t) = (cos t, sin t)`; `k = 0` is a point at infinity. From an edgelet at `p` the
//! direction to `V` is `u(t) + k (c - p)`, so the loss is smooth in `(t, k)` through infinity.
//! A Cauchy loss of the angles between the edgelets and those directions, a grid over `t`
//! (all of 180°) and `k` (VPs no closer than `reach`), then Nelder-Mead from the best cell.

use super::edgelets::Edgelet;
use super::line_angle_diff;
use crate::point::Point2;
use crate::solve::nelder_mead;

/// Fewer edgelets than this give no fit (two lines always meet; a third is a check).
pub const MIN_VEHICLE_EDGELETS: usize = 3;
/// Grid cells of the direction over 180° (0.5° each) and of the inverse distance.
const DIRECTION_CELLS: usize = 360;
const DISTANCE_CELLS: usize = 21;
const REFINE_ITERATIONS: usize = 200;

/// A vehicle's VP from its edgelets.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehicleVp {
    /// Line angle of the direction from the box centre to the VP, radians in `(-π/2, π/2]`.
    pub direction: f64,
    /// The VP, homogeneous `[x, y, w]` (`w = 0`: at infinity in `direction`).
    pub point: [f64; 3],
    /// Edgelets the fit used.
    pub edgelets: usize,
    /// Mean Cauchy loss per edgelet at the fit (`ln(1 + (d/scale)²)`).
    pub mean_loss: f64,
}

/// The point `edgelets` converge to, seen from `centre`; VPs closer to `centre` than `reach`
/// pixels are not searched (a vehicle's VP lies well outside its box: pass about the box
/// diagonal). `scale_deg` is the Cauchy loss's scale. `None` with fewer than
/// [`MIN_VEHICLE_EDGELETS`] edgelets or a non-positive `reach`.
pub fn vehicle_vp(
    centre: Point2,
    edgelets: &[Edgelet],
    reach: f64,
    scale_deg: f64,
) -> Option<VehicleVp> {
    if edgelets.len() < MIN_VEHICLE_EDGELETS
        || reach.is_nan()
        || reach <= 0.0
        || scale_deg.is_nan()
        || scale_deg <= 0.0
    {
        return None;
    }
    let scale = scale_deg.to_radians();
    // Offsets c - p, and angles, once.
    let pts: Vec<(Point2, f64)> = edgelets
        .iter()
        .map(|e| (centre - e.point(), e.angle))
        .collect();
    // x = [t, k·reach]: both axes of order one for Nelder-Mead; beyond |k·reach| = 1 (closer
    // than `reach`) the loss is that of the boundary, so the search cannot leave the range.
    let loss = |x: &[f64]| -> f64 {
        let (t, k) = (x[0], x[1].clamp(-1.0, 1.0) / reach);
        let u = Point2::new(t.cos(), t.sin());
        pts.iter()
            .map(|&(d, a)| {
                let dir = u + d * k;
                let r = line_angle_diff(a - dir.y.atan2(dir.x)) / scale;
                (r * r).ln_1p()
            })
            .sum()
    };
    let mut best = (f64::INFINITY, [0.0, 0.0]);
    for i in 0..DIRECTION_CELLS {
        let t = std::f64::consts::PI * (i as f64 / DIRECTION_CELLS as f64 - 0.5);
        for j in 0..DISTANCE_CELLS {
            let k = 2.0 * j as f64 / (DISTANCE_CELLS - 1) as f64 - 1.0;
            let v = loss(&[t, k]);
            if v < best.0 {
                best = (v, [t, k]);
            }
        }
    }
    let step_t = std::f64::consts::PI / DIRECTION_CELLS as f64;
    let step_k = 1.0 / (DISTANCE_CELLS - 1) as f64;
    let m = nelder_mead(loss, &best.1, &[step_t, step_k], REFINE_ITERATIONS);
    let (t, k) = if m.value < best.0 {
        (m.x[0], m.x[1].clamp(-1.0, 1.0) / reach)
    } else {
        (best.1[0], best.1[1] / reach)
    };
    let point = [centre.x * k + t.cos(), centre.y * k + t.sin(), k];
    Some(VehicleVp {
        direction: line_angle_diff(t),
        point,
        edgelets: pts.len(),
        mean_loss: loss(&[t, k * reach]) / pts.len() as f64,
    })
}
