//! A vehicle's length, width and height from the detector boxes of its track.
//!
//! A detector box is axis-aligned: its four sides are four numbers, and a cuboid standing on
//! the road, heading along it, has five (its centre on the road, length, width, height). One
//! box cannot give all five; the boxes of one track can (the view turns as the vehicle
//! drives), but on most roads the turn is small and length, width and height trade against
//! each other along a shallow valley. So the width carries a prior: [`ASSUMED_WIDTH_M`], with
//! a spread of [`WIDTH_LOG_SD`] (passenger cars are 1.7-1.9 m wide without mirrors, vans
//! about 2.0 m, trucks and buses 2.5 m, the EU's legal maximum), weighed as one more box side
//! of the typical detector error [`BOX_SIDE_SD`]; length and height carry wide priors
//! ([`LENGTH_LOG_SD`], [`HEIGHT_LOG_SD`]) that matter only where the boxes do not fit a
//! cuboid. For candidate dimensions every box gets the
//! cuboid centre whose image fits it best; the dimensions with the least total misfit plus
//! prior win. On exact boxes of a car the fit returns its dimensions; a 12 × 2.5 × 3.6 m
//! truck comes out about 13 × 2.4 × 3.4 m (the prior pulls its width in, the length makes up
//! for it).
//!
//! Units: plane units of the calibration throughout; the caller multiplies by the metric
//! scale (metres per unit).

use crate::camera::Calibration;
use crate::point::BoxPx;
use crate::solve::nelder_mead;
use crate::vehicle_scale::{box_misfit, cuboid_box_in, PASSENGER_CAR};

/// The width prior's centre, metres (module docs).
pub const ASSUMED_WIDTH_M: f64 = 1.8;

/// Spread of vehicle widths around [`ASSUMED_WIDTH_M`], in `ln`.
pub const WIDTH_LOG_SD: f64 = 0.15;

/// Spreads of vehicle lengths and heights around the typical car's ([`PASSENGER_CAR`]), in
/// `ln`: wide (a 16 m truck is 1.7 of them from a car, a 4 m tall one 2.5), they only keep a
/// fit that the boxes do not pin down (boxes of a shape no cuboid has) at sizes vehicles
/// have.
pub const LENGTH_LOG_SD: f64 = 0.75;
pub const HEIGHT_LOG_SD: f64 = 0.4;

/// Typical error of a detector box's side, fraction of its diagonal.
pub const BOX_SIDE_SD: f64 = 0.01;

/// Boxes of a track used for its fit, spread evenly over the track (the fit costs a
/// centre search per box and candidate).
pub const MAX_BOXES: usize = 8;

/// A vehicle's fitted dimensions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehicleDims {
    /// Length, width and height, plane units.
    pub length: f64,
    pub width: f64,
    pub height: f64,
    /// Median road-frame y of the fitted cuboids' centres, plane units: where across the
    /// road the vehicle's centre line runs (the box's bottom centre is off it in oblique
    /// views).
    pub lateral: f64,
    /// RMS misfit of the box sides, fraction of the box diagonal.
    pub rms: f64,
    /// Boxes fitted.
    pub boxes: usize,
    /// RMS change of the box sides (fraction of the diagonal) when the length changes by a
    /// quarter either way, the other dimensions held and the centres refitted: how well the
    /// boxes see the length.
    pub length_sensitivity: f64,
}

/// The best cuboid centre for `bbox` with dimensions `dims` (plane units), with its squared
/// misfit ([`box_misfit`]) as the value.
fn fit_centre(
    cal: &Calibration,
    frame: &crate::camera::RoadFrame,
    bbox: &BoxPx,
    heading: f64,
    dims: [f64; 3],
    start: [f64; 2],
) -> crate::solve::Minimum {
    let misfit =
        |p: &[f64]| box_misfit(bbox, cuboid_box_in(cal, frame, [p[0], p[1]], heading, dims));
    let step = [0.5 * dims[0], 0.5 * dims[1]];
    nelder_mead(misfit, &start, &step, 200)
}

/// The dimensions of the vehicle whose track has the boxes `boxes` (module docs), with the
/// width prior centred on `width` (plane units: [`ASSUMED_WIDTH_M`] over the scale) and
/// heading `heading` (radians from the road frame's x axis); `None` without a box whose
/// bottom sees the road.
pub fn fit_dims(
    cal: &Calibration,
    boxes: &[BoxPx],
    width: f64,
    heading: f64,
) -> Option<VehicleDims> {
    if !(width > 0.0 && width.is_finite()) {
        return None;
    }
    let n = boxes.len();
    let picked: Vec<BoxPx> = if n <= MAX_BOXES {
        boxes.to_vec()
    } else {
        (0..MAX_BOXES)
            .map(|k| boxes[k * (n - 1) / (MAX_BOXES - 1)])
            .collect()
    };
    // Each box's search starts at the road point under its bottom centre.
    let starts: Vec<(BoxPx, [f64; 2])> = picked
        .iter()
        .filter(|b| b.is_valid())
        .filter_map(|b| {
            cal.road_point(crate::point::Point2::new(0.5 * (b.x0 + b.x1), b.y1))
                .map(|q| (*b, q))
        })
        .collect();
    if starts.is_empty() {
        return None;
    }
    let frame = cal.road_frame();
    let unit = width / PASSENGER_CAR[1];
    let start = [
        (PASSENGER_CAR[0] * unit).ln(),
        (PASSENGER_CAR[2] * unit).ln(),
        width.ln(),
    ];
    let spread = [LENGTH_LOG_SD, HEIGHT_LOG_SD, WIDTH_LOG_SD];
    // The boxes' total squared misfit for dimensions `dims`, each box's centre refitted.
    let fitted = |dims: [f64; 3]| -> f64 {
        starts
            .iter()
            .map(|(b, q)| fit_centre(cal, &frame, b, heading, dims, *q).value)
            .sum::<f64>()
    };
    let total = |p: &[f64]| -> f64 {
        let prior: f64 = (0..3)
            .map(|k| ((p[k] - start[k]) / spread[k]).powi(2))
            .sum();
        fitted([p[0].exp(), p[2].exp(), p[1].exp()]) + 4.0 * BOX_SIDE_SD * BOX_SIDE_SD * prior
    };
    let m = nelder_mead(total, &start, &[0.4, 0.3, 0.1], 300);
    let best = [m.x[0].exp(), m.x[2].exp(), m.x[1].exp()];
    let lateral: Vec<f64> = starts
        .iter()
        .map(|(b, q)| fit_centre(cal, &frame, b, heading, best, *q).x[1])
        .collect();
    // How far the boxes move when the length changes by a quarter (centres refitted): RMS
    // per box side, fraction of the diagonal. Below the boxes' own error the length is not
    // seen (a vehicle seen end-on from low down).
    let base = fitted(best);
    let moved = [1.25, 0.8]
        .map(|k| fitted([best[0] * k, best[1], best[2]]) - base)
        .into_iter()
        .fold(f64::INFINITY, f64::min);
    let length_sensitivity = (moved.max(0.0) / (4.0 * starts.len() as f64)).sqrt();
    let dims = VehicleDims {
        length_sensitivity,
        length: best[0],
        width: best[1],
        height: best[2],
        lateral: crate::solve::median(&lateral).unwrap_or(f64::NAN),
        rms: (m.value / (4.0 * starts.len() as f64)).sqrt(),
        boxes: starts.len(),
    };
    (dims.length.is_finite() && dims.width.is_finite() && dims.height.is_finite()).then_some(dims)
}
