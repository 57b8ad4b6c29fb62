//! From per-vehicle VP pairs to one camera (DESIGN.md §7, paper §6.2).
//!
//! - [`reference`]: the paper's rule (medians of focal lengths, horizon slopes and
//!   intercepts), reproduced exactly, including how the reference code treated NaN and
//!   infinite values.
//! - [`robust`]: VP1 as the robust intersection of the vehicles' VP1 lines, then focal
//!   length, roll and the CNN's ray bias fitted to the vehicles' VP2 rays with weak priors;
//!   duplicate and small boxes down-weighted; bootstrap confidence.

mod bootstrap;
pub mod edgelets;
pub mod focal;
pub mod rays;
pub mod reference;
pub mod robust;
pub mod scene_lines;
pub mod sizes;
pub mod tracks;
pub mod vehicle_vp;
pub mod vehicles;
pub mod verticals;
mod vp1;

use crate::point::{BoxPx, Point2};

/// Wrap an angle difference of two lines (undirected) to (-pi/2, pi/2].
pub fn line_angle_diff(a: f64) -> f64 {
    let pi = std::f64::consts::PI;
    a - pi * (a / pi).round()
}

/// One vehicle's evidence: its VP pair in frame pixels and what we know about its quality.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehicleVps {
    /// VP1 (facing direction), frame pixels; may be non-finite.
    pub vp1: Point2,
    /// VP2 (axle direction), frame pixels; may be non-finite.
    pub vp2: Point2,
    /// Detector score of the vehicle's box.
    pub score: f64,
    /// The vehicle's box, frame pixels, when known.
    pub box_px: Option<BoxPx>,
    /// Frame index, when known.
    pub frame: Option<f64>,
    /// Decoder spread `D^s` of VP1 at the selected scale, when known.
    pub vp1_spread: Option<f64>,
    /// Decoder spread `D^s` of VP2 at the selected scale, when known.
    pub vp2_spread: Option<f64>,
    /// The VPs are not the network's for this box but copied from an earlier box of the
    /// same vehicle (the pipeline sends a few boxes per followed vehicle to the network):
    /// the box counts for the tracks and its edgelets (gated by those VPs), not as rays.
    pub copied: bool,
}

impl VehicleVps {
    /// A pair with only VPs and a score.
    pub fn new(vp1: Point2, vp2: Point2, score: f64) -> VehicleVps {
        VehicleVps {
            vp1,
            vp2,
            score,
            box_px: None,
            frame: None,
            vp1_spread: None,
            vp2_spread: None,
            copied: false,
        }
    }

    /// Whether the VPs are the network's own for this box, finite, above `min_score`: a
    /// ray of the fits.
    pub fn is_ray(&self, min_score: f64) -> bool {
        !self.copied && self.score > min_score && self.vp1.is_finite() && self.vp2.is_finite()
    }
}

/// Why the evidence does not support a calibration.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AggregateError {
    /// Too few usable vehicles, or the estimate is degenerate; the message says which.
    #[error("not enough evidence: {0}")]
    NotEnoughEvidence(String),
}
