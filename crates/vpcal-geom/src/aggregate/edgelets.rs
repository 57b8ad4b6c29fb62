//! The horizon's roll and the focal length from edgelets that point at VP2 (and VP1 from those
//! that point at VP1).
//!
//! Edges running across a vehicle (bumpers, window sills, the roof's front and back edges)
//! are parallel to the road plane and perpendicular to the direction of travel, so their
//! image lines pass through VP2. Each vehicle's edgelets (short edge pieces with a position
//! and a direction, found by `vpcal_video::edgelets`) are gated twice: they must lie within
//! `gate_vp2_deg` of the network's VP2 ray of that vehicle (the network tells which edges are
//! transverse; its direction is biased by a few degrees, so the gate is wide), and not point
//! at VP1 (`exclude_vp1_deg`). With VP1 fixed, the camera is `(f, roll)`: VP2 is the point of
//! the horizon through VP1 at angle `roll` that is orthogonal to VP1 for `f`. The fit
//! minimises a Cauchy loss of the angles between the edgelets and the directions from them to
//! VP2 (a grid, then Nelder-Mead), and a bootstrap over vehicles measures its spread. Every
//! edge is first turned back by the vehicles' systematic turn towards VP1 ([`EDGE_TURN_DEG`]
//! times [`edge_turn_share`], which falls as the edge and the direction to VP1 part), and
//! refits with that turn's uncertainty measure what it moves the roll and f.
//!
//! Why: the bundled network's VP2 rays are right in the mean only on some scenes; its roll is
//! pulled towards 0° (the aggregator's roll prior, and the network's own). On the synthetic
//! suite's straight roads and intersection the edgelets gave the roll to 0.14-0.75° (the
//! network's rays: 0.1-3.2°) and, where VP2 is within 10 image widths, the focal length to
//! 0-11 %. Where VP2 is far (long lenses looking along the road: 20-40 widths) the edgelets
//! are nearly parallel and the focal length is not identified (it came out 25-95 % too long);
//! the bootstrap spread and the VP2 distance decide whether it is used.
//!
//! [`fit_vp1`] does the same for VP1 with the edges *along* the vehicles, for inputs where no
//! vehicle tracks give VP1.

use super::focal::{FocalSource, Likelihood, Measured};
use super::line_angle_diff;
use super::tracks::Tangent;
use crate::point::Point2;
use crate::solve::{half_p16_p84, nelder_mead, par_map, percentile, percentile_sorted, SplitMix};

/// Focal lengths the straight edgelet fit's grid spans, in image widths: 0.25 (a 127° view) to
/// 20 (a 3° view), beyond the physical range of traffic cameras on both sides, so that the
/// data, not the grid, bounds the fit.
pub const STRAIGHT_FOCAL_GRID_WIDTHS: [f64; 2] = [0.25, 20.0];

/// Focal lengths the curved-road fit's grid spans, in image widths: 0.3 (a 118° view) to 10
/// (a 6° view). Narrower than the straight fit's: this grid has a third axis (the horizon's
/// height, 40 cells) and its fit is dropped when it ends at an edge ([`CURVED_ROLL_LIMIT_DEG`]),
/// so the range is the physical one with a margin rather than a search for outliers.
pub const CURVED_FOCAL_GRID_WIDTHS: [f64; 2] = [0.3, 10.0];

/// A curved-road fit whose roll strays further than this from the centre of the grid its
/// search started in is dropped: the grid searches ±[`CURVED_ROLL_GRID_DEG`] around each
/// centre, and a fit that walks past it has found no consistent camera.
pub const CURVED_ROLL_LIMIT_DEG: f64 = 8.0;

/// The curved fit's grid spans the roll this far either side of its centres, in whole degrees
/// ([`curved_grid_rolls`]).
pub const CURVED_ROLL_GRID_DEG: f64 = 6.0;

/// The straight fit's grid spans the roll this far either side of the rays' (in
/// [`STRAIGHT_ROLL_GRID_CELLS`] cells each side). A fit that ends within a cell of its edge
/// has found no roll inside the grid (on garbage boxes the cost can be flat, and the
/// bootstrap's refits then all stay where they start): its roll is not used.
pub const STRAIGHT_ROLL_GRID_DEG: f64 = 10.0;
/// The straight fit's roll cells either side of the rays' roll (0.5° each).
const STRAIGHT_ROLL_GRID_CELLS: i32 = 20;

/// Nelder-Mead budgets: a fit from the grid's best cell, and a bootstrap refit, which starts
/// at the fit and moves little (both converge well within them on the suite's scenes).
const FIT_ITERATIONS: usize = 300;
const REFIT_ITERATIONS: usize = 150;
/// The three-parameter curved fit and the two-parameter VP1 fit take longer to converge.
const CURVED_FIT_ITERATIONS: usize = 400;
const VP1_FIT_ITERATIONS: usize = 400;

/// A short straight piece of an image edge: position (frame pixels), direction of the edge
/// (radians, a line angle: `a` and `a + π` are the same), and gradient strength.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Edgelet {
    pub x: f64,
    pub y: f64,
    pub angle: f64,
    pub strength: f64,
}

impl Edgelet {
    pub fn point(&self) -> Point2 {
        Point2::new(self.x, self.y)
    }
}

/// Settings of the edgelet fit.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EdgeletFitOptions {
    /// An edgelet must be within this angle of its vehicle's VP2 ray, degrees.
    pub gate_vp2_deg: f64,
    /// ... and farther than this from the direction to VP1, degrees.
    pub exclude_vp1_deg: f64,
    /// Scale of the Cauchy loss on the angles, degrees.
    pub scale_deg: f64,
    /// At most this many edgelets per vehicle (the strongest).
    pub max_per_vehicle: usize,
    /// The fit uses at most this many edgelets (evenly spaced vehicles).
    pub max_edgelets: usize,
    /// Fewer vehicles with edgelets than this, or fewer edgelets than `min_edgelets`: no fit.
    pub min_vehicles: usize,
    pub min_edgelets: usize,
    /// Bootstrap resamples (over vehicles).
    pub bootstrap: usize,
    /// The roll is used when its bootstrap standard deviation is below this, degrees.
    pub max_roll_sd_deg: f64,
    /// The focal length is used when half of `ln(p84 / p16)` of its bootstrap is below this
    /// ...
    pub max_focal_log_spread: f64,
    /// ... and VP2 lies within this many image widths of the principal point ...
    pub max_vp2_widths: f64,
    /// ... and a systematic turn of the edges by 1° either way moves it by less than this
    /// (half of the `ln f` difference; [`EdgeletFit::focal_bias_log_spread`]).
    #[serde(default = "default_max_focal_bias_log_spread")]
    pub max_focal_bias_log_spread: f64,
}

fn default_max_focal_bias_log_spread() -> f64 {
    MAX_FOCAL_BIAS_LOG_SPREAD
}

/// The systematic turn of the edges across vehicles towards the vehicle's length (the
/// direction to VP1), degrees, where the two directions meet at a small angle: the edge
/// filter's integration window (`sigma_t` 3 px) reaches from an edge across the vehicle into
/// the edges along it near the corners where they meet, and mixes their orientations into
/// one; the closer the two directions, the farther from the corner they stay within the
/// window and still pass the coherence gate. Below the horizon and between the two VPs,
/// "towards VP1" is the same way round for every vehicle, so the turn moves VP2 across the
/// horizon (the roll) more than along it (the focal length). The fit turns every edge back
/// by this much times [`edge_turn_share`] of the angle between the edge and the direction to
/// VP1 at its place.
///
/// Measured per box (`scripts/edge_turn.py`, true boxes: each box's robust fit of its
/// edgelets' turn towards VP1, binned by that angle), over the six synthetic speed scenes
/// (6,209 boxes) and the synthetic suite rendered at `--supersample 3` (synth01, 03, 04, 10,
/// 14): at 15-30° the median turns are +0.44 to +0.64° (speed scenes, in 5° bins; per scene
/// +0.22 to +1.20°) and +0.52 to +0.69° (synth04), at 30-40° +0.22 and 0.00°, at 40-60°
/// +0.14, +0.12, +0.18, -0.08 and -0.05°, above 60° +0.02 to +0.06°. Divided by the share,
/// the median is about 0.7°. synth03's boxes at 15-25° do not turn (-0.04°), which the uncertainty covers. KITTI's labels are
/// not exact enough to measure it: its clean vehicles' per-box turns spread over -5 to +6°.
pub const EDGE_TURN_DEG: f64 = 0.7;

/// The share of [`EDGE_TURN_DEG`] by which an edge meeting the direction to VP1 at `alpha`
/// radians turns: `cos⁴ alpha`, 1 where the two directions coincide, 0.73 at 22.5°, 0.17 at
/// 50° and below 0.01 beyond 75° (the measured turns of [`EDGE_TURN_DEG`]'s doc fall that
/// way; the exact law of the window's mixing depends on the vehicles' shapes).
pub fn edge_turn_share(alpha: f64) -> f64 {
    alpha.cos().powi(4)
}

/// The systematic turn (radians) of an edge whose angle to the direction to VP1 at its place
/// is `alpha` (signed: positive where turning the edge counter-clockwise turns it towards that
/// direction): [`EDGE_TURN_DEG`] times its [`edge_turn_share`], towards VP1. An edge is
/// turned back by subtracting it.
pub fn edge_turn(alpha: f64) -> f64 {
    EDGE_TURN_DEG.to_radians() * edge_turn_share(alpha.abs()) * alpha.signum()
}

/// The uncertainty of the edges' turn, degrees: what it moves the roll (measured by refits
/// with every edge turned back by a degree less and more than [`EDGE_TURN_DEG`] times its
/// share) is the roll's systematic spread. It covers most per-scene turns of
/// [`EDGE_TURN_DEG`]'s doc against the model: -0.2 to +0.2° at 40° and more, -0.3 to +0.1°
/// at 15-30° (synth03's -0.5° at 1 of it), not highway_s2's +0.7° there. The focal length's
/// gate (`max_focal_bias_log_spread`) is on a uniform turn of a degree.
pub const EDGE_TURN_SD_DEG: f64 = 0.5;

impl Default for EdgeletFitOptions {
    fn default() -> Self {
        EdgeletFitOptions {
            gate_vp2_deg: 12.0,
            exclude_vp1_deg: 4.0,
            scale_deg: 1.0,
            max_per_vehicle: 48,
            max_edgelets: 20_000,
            min_vehicles: 20,
            min_edgelets: 300,
            bootstrap: 20,
            max_roll_sd_deg: 0.5,
            max_focal_log_spread: 0.05,
            max_vp2_widths: 20.0,
            max_focal_bias_log_spread: MAX_FOCAL_BIAS_LOG_SPREAD,
        }
    }
}

/// The edgelets of one vehicle within `gate_deg` of the line from `centre` towards `vp2`
/// (none when `vp2` is not finite), strongest first, at most `max`.
pub fn near_ray(
    centre: Point2,
    vp2: Point2,
    edgelets: &[Edgelet],
    gate_deg: f64,
    max: usize,
) -> Vec<Edgelet> {
    if !vp2.is_finite() || vp2 == centre {
        return Vec::new();
    }
    let a2 = (vp2.y - centre.y).atan2(vp2.x - centre.x);
    let gate = gate_deg.to_radians();
    let mut kept: Vec<Edgelet> = edgelets
        .iter()
        .filter(|e| line_angle_diff(e.angle - a2).abs() < gate)
        .copied()
        .collect();
    kept.sort_by(|a, b| b.strength.total_cmp(&a.strength));
    kept.truncate(max);
    kept
}

/// The edgelets worth keeping for one vehicle: up to `max` within `gate_deg` of its VP2 ray
/// (for the roll and focal length) and up to `max` more within `gate_deg` of its VP1 ray (for
/// VP1 when no tracks give it).
pub fn near_rays(
    centre: Point2,
    vp1: Point2,
    vp2: Point2,
    edgelets: &[Edgelet],
    gate_deg: f64,
    max: usize,
) -> Vec<Edgelet> {
    let mut kept = near_ray(centre, vp2, edgelets, gate_deg, max);
    let rest: Vec<Edgelet> = edgelets
        .iter()
        .filter(|e| !kept.contains(e))
        .copied()
        .collect();
    kept.extend(near_ray(centre, vp1, &rest, gate_deg, max));
    kept
}

/// One vehicle's evidence for the edgelet fits: its box centre, where the network's VP1 and
/// VP2 rays from the centre point, and the edgelets found in its box.
#[derive(Debug, Clone, Copy)]
pub struct BoxEdgelets<'a> {
    pub centre: Point2,
    pub vp1: Point2,
    pub vp2: Point2,
    pub edgelets: &'a [Edgelet],
    /// The physical vehicle the box shows (boxes of one vehicle share it; see
    /// `vehicles::vehicle_units`): the bootstrap resamples vehicles, not boxes.
    pub vehicle: usize,
}

/// What the edgelets say.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgeletFit {
    pub focal_px: f64,
    /// Horizon roll, radians (the angle of the horizon's direction from VP1 towards VP2).
    pub roll: f64,
    pub vp2: Point2,
    /// Edgelets and vehicles the fit used.
    pub edgelets: usize,
    pub vehicles: usize,
    /// Bootstrap spread of the roll, degrees (`bootstrap_spread`).
    pub roll_sd_deg: f64,
    /// How far the uncertainty of the edges' systematic turn ([`EDGE_TURN_SD_DEG`]) moves
    /// the roll, degrees: half the roll difference between the fits with the edges turned
    /// back by [`EDGE_TURN_DEG`] (times each edge's [`edge_turn_share`]) ∓ 1°, per degree,
    /// times that uncertainty.
    pub roll_turn_sd_deg: f64,
    /// How far VP1's spread across the horizon moves the roll, degrees
    /// ([`roll_vp1_sd_deg`]); 0 until measured ([`EdgeletFit::with_vp1_spread`]).
    pub roll_vp1_sd_deg: f64,
    pub focal_px_p16: f64,
    pub focal_px_p84: f64,
    /// Whether the roll and the focal length pass the identifiability gates (the roll: its
    /// spread, and a fit inside [`STRAIGHT_ROLL_GRID_DEG`]).
    pub roll_usable: bool,
    pub focal_usable: bool,
    /// How far a systematic turn of every edge by 1° moves `ln f`: half of the `ln f`
    /// difference between the same two fits as `roll_turn_sd_deg`'s (large when VP2 is far,
    /// where the edges are nearly parallel).
    pub focal_bias_log_spread: f64,
}

impl EdgeletFit {
    /// Half of `ln(p84 / p16)` of the bootstrap focal lengths (about the standard deviation
    /// of `ln f`).
    pub fn focal_log_spread(&self) -> f64 {
        0.5 * (self.focal_px_p84 / self.focal_px_p16).ln()
    }

    /// The roll's spread, degrees: its bootstrap's, the edges' turn's and VP1's together.
    pub fn roll_total_sd_deg(&self) -> f64 {
        self.roll_sd_deg
            .hypot(self.roll_turn_sd_deg)
            .hypot(self.roll_vp1_sd_deg)
    }

    /// The fit with VP1's share of the roll's spread (degrees; a non-finite one leaves it).
    pub fn with_vp1_spread(self, roll_vp1_sd_deg: f64) -> EdgeletFit {
        EdgeletFit {
            roll_vp1_sd_deg: if roll_vp1_sd_deg.is_finite() {
                roll_vp1_sd_deg
            } else {
                self.roll_vp1_sd_deg
            },
            ..self
        }
    }

    fn measured(&self) -> Measured {
        Measured {
            name: "edgelets",
            focal_px: self.focal_px,
            bootstrap_px: [self.focal_px_p16, self.focal_px_p84],
            turn: self.focal_bias_log_spread * EDGE_TURN_SD_DEG,
        }
    }
}

/// The straight-road fit's focal length, where it passes its identifiability gates
/// ([`EdgeletFit::focal_usable`]: beyond them it fails in ways its bootstrap and the edges'
/// turn do not show; docs/accuracy.md §19).
impl FocalSource for EdgeletFit {
    fn name(&self) -> &'static str {
        "edgelets"
    }

    fn likelihood(&self) -> Option<Likelihood> {
        self.focal_usable
            .then(|| self.measured().likelihood())
            .flatten()
    }
}

/// The curved-road fit's focal length, from its bootstrap and the edges' turn.
impl FocalSource for CurvedFit {
    fn name(&self) -> &'static str {
        "curved_edgelets"
    }

    fn likelihood(&self) -> Option<Likelihood> {
        Measured {
            name: self.name(),
            focal_px: self.focal_px,
            bootstrap_px: [self.focal_px_p16, self.focal_px_p84],
            turn: self.focal_bias_log_spread * EDGE_TURN_SD_DEG,
        }
        .likelihood()
    }
}

/// VP2 for (ln f, roll) with VP1 and pp fixed, as `VP2 = VP1 + h / u`.
pub(super) fn vp2_direction(vp1: Point2, pp: Point2, ln_f: f64, roll: f64) -> (Point2, f64) {
    let h = Point2::new(roll.cos(), roll.sin());
    let v = vp1 - pp;
    let f = ln_f.exp();
    (h, -v.dot(h) / (f * f + v.dot(v)))
}

/// The straight fit's first Nelder-Mead step in `[ln f, roll]`: 5 % in f, 0.2° in roll.
fn straight_step() -> [f64; 2] {
    [0.05, 0.2f64.to_radians()]
}

/// Edgelets of the vehicles that the fit uses, flattened, with each one's box index
/// (`group`), and each box's physical vehicle (`vehicle_of_group`, numbered `0..vehicles`).
struct Flat {
    point: Vec<Point2>,
    /// Each edgelet's angle, turned back by the edges' systematic turn towards VP1
    /// ([`EDGE_TURN_DEG`] times its [`edge_turn_share`]).
    angle: Vec<f64>,
    /// +1 where turning the edgelet counter-clockwise (a positive angle) turns it towards
    /// the direction to VP1 at its place, else -1.
    towards_vp1: Vec<f64>,
    group: Vec<usize>,
    groups: usize,
    vehicle_of_group: Vec<usize>,
    vehicles: usize,
}

impl Flat {
    /// The edgelets of `vehicles` the fit uses with VP1 at `vp1` (near each vehicle's VP2 ray,
    /// not pointing at VP1, turned back by the edges' systematic turn); `None` with too few.
    fn of(vp1: Point2, vehicles: &[BoxEdgelets], opts: &EdgeletFitOptions) -> Option<Flat> {
        let ex1 = opts.exclude_vp1_deg.to_radians();
        let kept: Vec<(usize, Vec<(Point2, f64)>)> = vehicles
            .iter()
            .map(|v| {
                let near = near_ray(
                    v.centre,
                    v.vp2,
                    v.edgelets,
                    opts.gate_vp2_deg,
                    opts.max_per_vehicle,
                )
                .into_iter()
                .filter(|e| {
                    let d = vp1 - e.point();
                    line_angle_diff(e.angle - d.y.atan2(d.x)).abs() > ex1
                })
                .map(|e| (e.point(), e.angle))
                .collect::<Vec<_>>();
                (v.vehicle, near)
            })
            .filter(|(_, v)| !v.is_empty())
            .collect();
        let total: usize = kept.iter().map(|(_, v)| v.len()).sum();
        if kept.len() < opts.min_vehicles || total < opts.min_edgelets || !vp1.is_finite() {
            return None;
        }
        // Evenly spaced vehicles, so that the fit's cost stays bounded.
        let step = (total as f64 / opts.max_edgelets as f64).max(1.0);
        let mut flat = Flat {
            point: vec![],
            angle: vec![],
            towards_vp1: vec![],
            group: vec![],
            groups: 0,
            vehicle_of_group: vec![],
            vehicles: 0,
        };
        let mut next = 0.0;
        let mut renumber = std::collections::HashMap::new();
        for (i, (vehicle, v)) in kept.iter().enumerate() {
            if (i as f64) < next {
                continue;
            }
            next += step;
            for (p, a) in v {
                let to_vp1 = vp1 - *p;
                let alpha = line_angle_diff(to_vp1.y.atan2(to_vp1.x) - a);
                flat.point.push(*p);
                flat.angle.push(a - edge_turn(alpha));
                flat.towards_vp1.push(alpha.signum());
                flat.group.push(flat.groups);
            }
            flat.groups += 1;
            let n = renumber.len();
            flat.vehicle_of_group
                .push(*renumber.entry(*vehicle).or_insert(n));
        }
        flat.vehicles = renumber.len();
        Some(flat)
    }
}

/// The fit's cost of `x = [ln f, roll]`: a Cauchy loss (scale `s`, radians) of the angles
/// between the (turned back) edgelets, each turned by `turn` radians more towards the
/// direction to VP1 at its place (away from it when `turn` is negative), and the directions
/// from them to VP2.
fn cost(flat: &Flat, gw: &[f64], vp1: Point2, pp: Point2, x: &[f64], s: f64, turn: f64) -> f64 {
    let (h, u) = vp2_direction(vp1, pp, x[0], x[1]);
    let mut c = 0.0;
    let edgelets = flat.point.iter().zip(&flat.angle).zip(&flat.towards_vp1);
    for (((p, a), t), g) in edgelets.zip(&flat.group) {
        let w = gw[*g];
        if w == 0.0 {
            continue;
        }
        let d = (vp1 - *p) * u + h;
        let r = line_angle_diff(a + turn * t - d.y.atan2(d.x)) / s;
        c += w * (1.0 + r * r).ln();
    }
    c
}

/// Largest [`EdgeletFit::focal_bias_log_spread`] for a usable focal length: 0.35 in `ln f`,
/// half of the physical prior's 68 % half-width (0.69, `assumed_focal_interval`): evidence
/// that a one-degree turn of the edges moves further is no better than the prior.
pub const MAX_FOCAL_BIAS_LOG_SPREAD: f64 = 0.35;

/// The 16th and 84th percentiles of a bootstrap's focal lengths and the spread of its rolls
/// (degrees): half the distance between their 16th and 84th percentiles, a normal's standard
/// deviation, measured as the focal length's is. NaN where there were no resamples. (A standard
/// deviation would let the few resamples whose refit settles in another valley, such as the
/// edges of a crossing road's traffic, decide alone whether the roll is usable.)
fn bootstrap_spread(mut fs: Vec<f64>, rolls: &[f64]) -> (f64, f64, f64) {
    if fs.is_empty() || rolls.is_empty() {
        return (f64::NAN, f64::NAN, f64::NAN);
    }
    fs.sort_by(f64::total_cmp);
    (
        percentile_sorted(&fs, 16.0),
        percentile_sorted(&fs, 84.0),
        half_p16_p84(rolls),
    )
}

/// Fit `(f, roll)` to the vehicles' edgelets near their VP2 rays with VP1 fixed; `roll0`
/// (radians) centres the roll grid and `width` scales the focal grid. `None` when there are
/// too few vehicles or edgelets after removing those that point at VP1.
pub fn fit(
    vp1: Point2,
    pp: Point2,
    width: f64,
    vehicles: &[BoxEdgelets],
    roll0: f64,
    opts: &EdgeletFitOptions,
    seed: u64,
) -> Option<EdgeletFit> {
    let flat = Flat::of(vp1, vehicles, opts)?;
    let s = opts.scale_deg.to_radians();
    let ones = vec![1.0; flat.groups];
    let [lo_w, hi_w] = STRAIGHT_FOCAL_GRID_WIDTHS;
    let (lo, hi) = ((lo_w * width).ln(), (hi_w * width).ln());
    // The grid's and the bootstrap's fits are independent: they run spread over the cores,
    // each the same as one after another.
    let roll_cell = (STRAIGHT_ROLL_GRID_DEG / f64::from(STRAIGHT_ROLL_GRID_CELLS)).to_radians();
    let grid: Vec<[f64; 2]> = (0..32)
        .flat_map(|i| {
            let ln_f = lo + (hi - lo) * f64::from(i) / 31.0;
            (-STRAIGHT_ROLL_GRID_CELLS..=STRAIGHT_ROLL_GRID_CELLS)
                .map(move |j| [ln_f, roll0 + f64::from(j) * roll_cell])
        })
        .collect();
    let costs = par_map(&grid, |x| cost(&flat, &ones, vp1, pp, x, s, 0.0));
    let mut best = (f64::INFINITY, [0.0, 0.0]);
    for (x, c) in grid.into_iter().zip(costs) {
        if c < best.0 {
            best = (c, x);
        }
    }
    let step0 = straight_step();
    let x = nelder_mead(
        |x| cost(&flat, &ones, vp1, pp, x, s, 0.0),
        &best.1,
        &step0,
        FIT_ITERATIONS,
    )
    .x;
    let mut rng = SplitMix(seed ^ 0xED6E_1E75);
    let weights: Vec<Vec<f64>> = (0..opts.bootstrap)
        .map(|_| {
            // One count per vehicle, shared by its boxes.
            let draws: Vec<f64> = (0..flat.vehicles).map(|_| rng.poisson1()).collect();
            flat.vehicle_of_group.iter().map(|&v| draws[v]).collect()
        })
        .collect();
    let refits = par_map(&weights, |w| {
        nelder_mead(
            |x| cost(&flat, w, vp1, pp, x, s, 0.0),
            &x,
            &step0,
            REFIT_ITERATIONS,
        )
        .x
    });
    let fs: Vec<f64> = refits.iter().map(|xb| xb[0].exp()).collect();
    let rolls: Vec<f64> = refits
        .iter()
        .map(|xb| line_angle_diff(xb[1] - x[1]).to_degrees())
        .collect();
    // What a systematic turn moves: refits with every edge turned a degree more and less
    // (the focal length's gate is on this degree; the roll's spread scales it to the turn's
    // uncertainty).
    let probe = 1f64.to_radians();
    let turned: Vec<[f64; 2]> = par_map(&[-probe, probe], |&turn| {
        let xt = nelder_mead(
            |x| cost(&flat, &ones, vp1, pp, x, s, turn),
            &x,
            &step0,
            REFIT_ITERATIONS,
        )
        .x;
        [xt[0], xt[1]]
    });
    let focal_bias_log_spread = 0.5 * (turned[0][0] - turned[1][0]).abs();
    let roll_per_deg = 0.5
        * line_angle_diff(turned[0][1] - turned[1][1])
            .abs()
            .to_degrees();
    let roll_turn_sd_deg = roll_per_deg * EDGE_TURN_SD_DEG;
    let (h, u) = vp2_direction(vp1, pp, x[0], x[1]);
    let vp2 = vp1 + h / u;
    let focal_px = x[0].exp();
    let (p16, p84, roll_sd_deg) = bootstrap_spread(fs, &rolls);
    let inside =
        line_angle_diff(x[1] - roll0).abs() < STRAIGHT_ROLL_GRID_DEG.to_radians() - roll_cell;
    let roll_usable = roll_sd_deg <= opts.max_roll_sd_deg && inside;
    let focal_usable = roll_usable
        && 0.5 * (p84 / p16).ln() <= opts.max_focal_log_spread
        && focal_bias_log_spread <= opts.max_focal_bias_log_spread
        && vp2.is_finite()
        && (vp2 - pp).norm() <= opts.max_vp2_widths * width;
    Some(EdgeletFit {
        focal_px,
        roll: x[1],
        vp2,
        edgelets: flat.point.len(),
        vehicles: flat.groups,
        roll_sd_deg,
        roll_turn_sd_deg,
        roll_vp1_sd_deg: 0.0,
        focal_px_p16: p16,
        focal_px_p84: p84,
        roll_usable,
        focal_usable,
        focal_bias_log_spread,
    })
}

/// How far VP1's spread across the horizon turns `fit`'s roll, degrees: half the roll
/// difference between two refits (from `fit`'s focal length and roll, no grid, no
/// bootstrap) with VP1 moved `shift_px` either way along the horizon's normal, each with
/// the edgelets it selects there. The bootstrap holds VP1 where it was placed, so its
/// spread does not see this; the horizon runs through VP1, and how far it turns depends on
/// how well the edges place VP2's distance, which the refits let them decide (far and
/// unplaced, VP2 slides and the roll stays). NaN where a refit has too few edgelets.
pub fn roll_vp1_sd_deg(
    fit: &EdgeletFit,
    vp1: Point2,
    pp: Point2,
    vehicles: &[BoxEdgelets],
    opts: &EdgeletFitOptions,
    shift_px: f64,
) -> f64 {
    if shift_px == 0.0 {
        return 0.0;
    }
    let normal = Point2::new(-fit.roll.sin(), fit.roll.cos());
    let s = opts.scale_deg.to_radians();
    let start = [fit.focal_px.ln(), fit.roll];
    let step0 = straight_step();
    let rolls = par_map(&[-shift_px, shift_px], |&d| {
        let moved = vp1 + normal * d;
        let flat = Flat::of(moved, vehicles, opts)?;
        let ones = vec![1.0; flat.groups];
        let x = nelder_mead(
            |x| cost(&flat, &ones, moved, pp, x, s, 0.0),
            &start,
            &step0,
            FIT_ITERATIONS,
        )
        .x;
        Some(x[1])
    });
    match rolls[..] {
        [Some(a), Some(b)] => 0.5 * line_angle_diff(a - b).abs().to_degrees(),
        _ => f64::NAN,
    }
}

/// VP1 from the edgelets along the vehicles: each vehicle's edgelets within `gate_vp2_deg` of
/// its network VP1 ray and farther than `exclude_vp1_deg` from its VP2 ray (the same two
/// angles as for VP2, with the rays' roles swapped), fitted as the point their lines meet (Cauchy loss on the angles, Nelder-Mead from `start`).
/// Returns VP1 and the edgelets and vehicles used; `None` with too few of them.
///
/// Used when no vehicle tracks give VP1: on the synthetic suite the network's VP1 rays then
/// left VP1 1.5-15° off (angle at the camera) and these edgelets 0.4-3.9° on 6 of 7 inputs
/// (the seventh, a curve, 7° vs 15°).
pub fn fit_vp1(
    start: Point2,
    vehicles: &[BoxEdgelets],
    opts: &EdgeletFitOptions,
) -> Option<(Point2, usize, usize)> {
    let gate = opts.gate_vp2_deg;
    let ex = opts.exclude_vp1_deg.to_radians();
    let mut point = vec![];
    let mut angle = vec![];
    let mut used = 0;
    for &BoxEdgelets {
        centre,
        vp1,
        vp2,
        edgelets,
        ..
    } in vehicles
    {
        if !vp2.is_finite() || vp2 == centre {
            continue;
        }
        let a2 = (vp2.y - centre.y).atan2(vp2.x - centre.x);
        let kept: Vec<Edgelet> = near_ray(centre, vp1, edgelets, gate, opts.max_per_vehicle)
            .into_iter()
            .filter(|e| line_angle_diff(e.angle - a2).abs() > ex)
            .collect();
        if kept.is_empty() {
            continue;
        }
        used += 1;
        for e in kept {
            point.push(e.point());
            angle.push(e.angle);
        }
    }
    if used < opts.min_vehicles || point.len() < opts.min_edgelets || !start.is_finite() {
        return None;
    }
    // Evenly spaced edgelets, at most `max_edgelets`.
    let step = (point.len() as f64 / opts.max_edgelets as f64).max(1.0);
    let picked: Vec<usize> = (0..)
        .map(|k| (k as f64 * step) as usize)
        .take_while(|&i| i < point.len())
        .collect();
    let s = opts.scale_deg.to_radians();
    let cost = |q: &[f64]| -> f64 {
        picked
            .iter()
            .map(|&i| {
                let d = Point2::new(q[0], q[1]) - point[i];
                let r = line_angle_diff(angle[i] - d.y.atan2(d.x)) / s;
                (1.0 + r * r).ln()
            })
            .sum()
    };
    // Steps of 2 % of VP1's distance from the edgelets.
    let n = picked.len() as f64;
    let mean = picked
        .iter()
        .fold(Point2::new(0.0, 0.0), |a, &i| a + point[i] / n);
    let d = 0.02 * (start - mean).norm().max(1.0);
    let q = nelder_mead(cost, &[start.x, start.y], &[d, d], VP1_FIT_ITERATIONS).x;
    let vp1 = Point2::new(q[0], q[1]);
    vp1.is_finite().then_some((vp1, picked.len(), used))
}

/// A vehicle on a curved road: its local direction of travel (from its track) and its
/// edgelets.
#[derive(Debug, Clone, Copy)]
pub struct CurvedVehicle<'a> {
    pub tangent: Tangent,
    pub edgelets: &'a [Edgelet],
    /// The physical vehicle the box shows (as [`BoxEdgelets::vehicle`]).
    pub vehicle: usize,
}

/// The camera [`fit_curved`] found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CurvedFit {
    pub focal_px: f64,
    /// Angle of the horizon's direction, radians (as [`EdgeletFit::roll`]).
    pub roll: f64,
    /// The median of the vehicles' own VP1s along the horizon, and its VP2.
    pub vp1: Point2,
    pub vp2: Point2,
    /// Edgelets and vehicles the fit used.
    pub edgelets: usize,
    pub vehicles: usize,
    /// Bootstrap spread over vehicles.
    pub roll_sd_deg: f64,
    pub focal_px_p16: f64,
    pub focal_px_p84: f64,
    /// What the uncertainty of the edges' systematic turn moves the roll (degrees) and, per
    /// degree of turn, `ln f`: as [`EdgeletFit::roll_turn_sd_deg`] and
    /// [`EdgeletFit::focal_bias_log_spread`].
    pub roll_turn_sd_deg: f64,
    pub focal_bias_log_spread: f64,
}

impl CurvedFit {
    /// The roll's spread, degrees: its bootstrap's and the edges' turn's together.
    pub fn roll_total_sd_deg(&self) -> f64 {
        self.roll_sd_deg.hypot(self.roll_turn_sd_deg)
    }
}

/// Vehicles with their edgelets, flattened: `range[g]` of `point`/`angle` belongs to
/// `tangent[g]`.
struct CurvedFlat {
    point: Vec<Point2>,
    angle: Vec<f64>,
    tangent: Vec<Tangent>,
    range: Vec<std::ops::Range<usize>>,
    /// The physical vehicle of each tangent, numbered `0..vehicles`.
    vehicle: Vec<usize>,
    vehicles: usize,
}

impl CurvedFlat {
    fn new(vehicles: &[CurvedVehicle], max_edgelets: usize) -> CurvedFlat {
        let total: usize = vehicles.iter().map(|v| v.edgelets.len()).sum();
        let step = (total as f64 / max_edgelets as f64).max(1.0);
        let mut flat = CurvedFlat {
            point: vec![],
            angle: vec![],
            tangent: vec![],
            range: vec![],
            vehicle: vec![],
            vehicles: 0,
        };
        let mut renumber = std::collections::HashMap::new();
        let mut next = 0.0;
        for (i, v) in vehicles.iter().enumerate() {
            if (i as f64) < next || v.edgelets.is_empty() {
                continue;
            }
            next += step;
            let start = flat.point.len();
            for e in v.edgelets {
                flat.point.push(e.point());
                flat.angle.push(e.angle);
            }
            flat.tangent.push(v.tangent);
            flat.range.push(start..flat.point.len());
            let n = renumber.len();
            flat.vehicle.push(*renumber.entry(v.vehicle).or_insert(n));
        }
        flat.vehicles = renumber.len();
        flat
    }

    /// Cauchy cost of `x = [ln f, roll, y0]`: the horizon runs through `(pp.x, y0)` at angle
    /// `roll`; vehicle `g`'s VP1 is where its tangent meets the horizon, its VP2 the point of
    /// the horizon orthogonal to that VP1 for focal length f, and VP3 the vertical one. An
    /// edgelet within `ex1` of the direction to its VP1 is scored against it, any other
    /// against the nearer of VP2 (turned back by the edges' systematic turn, as in [`fit`],
    /// then `turn` radians towards its VP1: a probe of that turn's uncertainty) and VP3
    /// (vertical edges would otherwise pull the fit).
    fn cost(&self, gw: &[f64], pp: Point2, x: &[f64], s: f64, ex1: f64, turn: f64) -> f64 {
        let h = Point2::new(x[1].cos(), x[1].sin());
        let n = Point2::new(-h.y, h.x);
        let h0 = Point2::new(pp.x, x[2]);
        let f2 = (2.0 * x[0]).exp();
        // VP3 = pp + dv * f^2 / |dv|^2, dv from the horizon's foot point to pp; directions to
        // it are taken as (pp - p) |dv|^2 / f^2 + dv, finite when the horizon passes near pp.
        let foot = h0 + h * (pp - h0).dot(h);
        let dv = pp - foot;
        let k3 = dv.dot(dv) / f2;
        let mut c = 0.0;
        for (g, (t, range)) in self.tangent.iter().zip(&self.range).enumerate() {
            let w = gw[g];
            if w == 0.0 {
                continue;
            }
            let Some(vp1) = meets_horizon(t, h0, n) else {
                continue;
            };
            let a = vp1 - pp;
            let u = -a.dot(h) / (f2 + a.dot(a));
            for i in range.clone() {
                let (p, ang) = (self.point[i], self.angle[i]);
                let d1 = vp1 - p;
                let r1 = line_angle_diff(ang - d1.y.atan2(d1.x));
                let r = if r1.abs() < ex1 {
                    r1
                } else {
                    let d2 = d1 * u + h;
                    let d3 = (pp - p) * k3 + dv;
                    // An edge across the vehicle, turned back by the edges' systematic turn
                    // towards its VP1 (as the straight fit's; `r1` is its angle from that
                    // direction, the opposite sign of `edge_turn`'s).
                    let ang2 = ang - edge_turn(-r1) - turn * r1.signum();
                    let r2 = line_angle_diff(ang2 - d2.y.atan2(d2.x)).abs();
                    let r3 = line_angle_diff(ang - d3.y.atan2(d3.x)).abs();
                    r2.min(r3)
                } / s;
                c += w * (1.0 + r * r).ln();
            }
        }
        c
    }
}

/// The curved fit's grid of rolls (radians), each with the centre it was laid around: whole
/// degrees within [`CURVED_ROLL_GRID_DEG`] of `roll0` (the straight fit's roll) and, where
/// `roll0` is further than [`CURVED_ROLL_GRID_DEG`]` / 2` from level, of level too. On a curve
/// the straight fit's roll can be far off (a rendered U-bend: 10.7°), and a grid around it
/// alone then never reaches the true roll; a level grid alone moved real curved fits into
/// other valleys of their cost. The union keeps both; the lower cost decides.
fn curved_grid_rolls(roll0: f64) -> Vec<(f64, f64)> {
    let half = CURVED_ROLL_GRID_DEG as i32;
    let around = |c: f64| (-half..=half).map(move |j| (c + f64::from(j).to_radians(), c));
    let mut rolls: Vec<(f64, f64)> = around(roll0).collect();
    if line_angle_diff(roll0).abs() > (0.5 * CURVED_ROLL_GRID_DEG).to_radians() {
        let cell = 0.5f64.to_radians();
        let level: Vec<(f64, f64)> = around(0.0)
            .filter(|&(r, _)| {
                rolls
                    .iter()
                    .all(|&(q, _)| line_angle_diff(r - q).abs() > cell)
            })
            .collect();
        rolls.extend(level);
    }
    rolls
}

/// A vehicle's weight in [`fit_curved`]: `1 / (1 + (se / s)^2)` for a tangent whose direction
/// has standard error `se` and an edgelet scale `s` (both radians). Exact boxes give tangents
/// good to a few tenths of a degree (weight near 1); the motion detector's boxes jitter, and a
/// tangent over a short stretch of a slow car can be several degrees off, which moves that
/// car's VP1 along the horizon and pulls the fit with all its edgelets.
fn tangent_weight(t: &Tangent, s: f64) -> f64 {
    let r = t.se_rad / s;
    if r.is_finite() {
        1.0 / (1.0 + r * r)
    } else {
        0.0
    }
}

/// Where the line of tangent `t` meets the horizon through `h0` with unit normal `n` (the
/// vehicle's own VP1); `None` when they are (nearly) parallel.
fn meets_horizon(t: &Tangent, h0: Point2, n: Point2) -> Option<Point2> {
    let tn = t.dir.dot(n);
    (tn.abs() >= 1e-9).then(|| t.point + t.dir * (-(t.point - h0).dot(n) / tn))
}

/// The horizon and the focal length of a curved road, where every vehicle has its own
/// heading: each vehicle's VP1 lies where its track's tangent meets the horizon, and its
/// edgelets point at that VP1, at the VP2 orthogonal to it, or at VP3. Three parameters
/// (ln f, roll, the horizon's height at `pp.x`), from a grid (around `roll0` and level,
/// `curved_grid_rolls`, on at most 2000 edgelets) refined by Nelder-Mead on up to `max_edgelets`, with a bootstrap over
/// vehicles; each vehicle weighs by how well its tangent is known ([`tangent_weight`]). `None` with fewer than `min_vehicles` vehicles or `min_edgelets` edgelets.
pub fn fit_curved(
    pp: Point2,
    width: f64,
    height: f64,
    vehicles: &[CurvedVehicle],
    roll0: f64,
    opts: &EdgeletFitOptions,
    seed: u64,
) -> Option<CurvedFit> {
    let full = CurvedFlat::new(vehicles, opts.max_edgelets);
    if full.tangent.len() < opts.min_vehicles || full.point.len() < opts.min_edgelets {
        return None;
    }
    let coarse = CurvedFlat::new(vehicles, 2000);
    let s = opts.scale_deg.to_radians();
    let ex1 = opts.exclude_vp1_deg.to_radians();
    let weights = |flat: &CurvedFlat| -> Vec<f64> {
        flat.tangent.iter().map(|t| tangent_weight(t, s)).collect()
    };
    let weight = weights(&full);
    let coarse_weight = weights(&coarse);
    let [lo_w, hi_w] = CURVED_FOCAL_GRID_WIDTHS;
    let (lo, hi) = ((lo_w * width).ln(), (hi_w * width).ln());
    let rolls = curved_grid_rolls(roll0);
    let grid: Vec<([f64; 3], f64)> = (0..16)
        .flat_map(|i| {
            let ln_f = lo + (hi - lo) * f64::from(i) / 15.0;
            rolls.iter().flat_map(move |&(roll, centre)| {
                (0..40).map(move |k| {
                    let y0 = pp.y - 3.0 * height * (1.0 - f64::from(k) / 40.0);
                    ([ln_f, roll, y0], centre)
                })
            })
        })
        .collect();
    let costs = par_map(&grid, |(x, _)| {
        coarse.cost(&coarse_weight, pp, x, s, ex1, 0.0)
    });
    // The best cell, and the centre of the roll grid it belongs to.
    let mut best = (f64::INFINITY, [0.0; 3], roll0);
    for ((x, centre), c) in grid.into_iter().zip(costs) {
        if c < best.0 {
            best = (c, x, centre);
        }
    }
    let centre_roll = best.2;
    let step0 = [0.05, 0.3f64.to_radians(), 0.01 * height];
    let x = nelder_mead(
        |x| full.cost(&weight, pp, x, s, ex1, 0.0),
        &best.1,
        &step0,
        CURVED_FIT_ITERATIONS,
    )
    .x;
    let mut rng = SplitMix(seed ^ 0xC0C0_1E75);
    // The resamples refit the coarse cost (2000 edgelets), whose optimum is not the full
    // fit's: they spread around the coarse fit, and are moved onto the full fit by the ratio
    // of the two (otherwise the interval can miss its own estimate).
    let centre = nelder_mead(
        |x| coarse.cost(&coarse_weight, pp, x, s, ex1, 0.0),
        &x,
        &step0,
        REFIT_ITERATIONS,
    )
    .x;
    let shift = (x[0] - centre[0]).exp();
    let resampled: Vec<Vec<f64>> = (0..opts.bootstrap.min(10))
        .map(|_| {
            // One count per vehicle, shared by its boxes.
            let draws: Vec<f64> = (0..coarse.vehicles).map(|_| rng.poisson1()).collect();
            coarse_weight
                .iter()
                .zip(&coarse.vehicle)
                .map(|(cw, &v)| cw * draws[v])
                .collect()
        })
        .collect();
    let refits = par_map(&resampled, |w| {
        nelder_mead(
            |x| coarse.cost(w, pp, x, s, ex1, 0.0),
            &centre,
            &step0,
            REFIT_ITERATIONS,
        )
        .x
    });
    let fs: Vec<f64> = refits.iter().map(|xb| xb[0].exp() * shift).collect();
    let rolls: Vec<f64> = refits
        .iter()
        .map(|xb| line_angle_diff(xb[1] - centre[1]).to_degrees())
        .collect();
    // VP1: the median of the vehicles' own VP1s along the horizon.
    let h = Point2::new(x[1].cos(), x[1].sin());
    let n = Point2::new(-h.y, h.x);
    let h0 = Point2::new(pp.x, x[2]);
    let along: Vec<f64> = full
        .tangent
        .iter()
        .filter_map(|t| meets_horizon(t, h0, n))
        .map(|vp1| (vp1 - h0).dot(h))
        .filter(|a| a.is_finite())
        .collect();
    if along.is_empty() {
        return None;
    }
    let vp1 = h0 + h * percentile(along, 50.0);
    let (hd, u) = vp2_direction(vp1, pp, x[0], x[1]);
    let vp2 = vp1 + hd / u;
    let (p16, p84, roll_sd_deg) = bootstrap_spread(fs, &rolls);
    // What a systematic turn of the edges across the vehicles moves, as in the straight fit.
    let probe = 1f64.to_radians();
    let turned: Vec<Vec<f64>> = par_map(&[-probe, probe], |&turn| {
        nelder_mead(
            |xt| full.cost(&weight, pp, xt, s, ex1, turn),
            &x,
            &step0,
            REFIT_ITERATIONS,
        )
        .x
    });
    let focal_bias_log_spread = 0.5 * (turned[0][0] - turned[1][0]).abs();
    let roll_per_deg = 0.5
        * line_angle_diff(turned[0][1] - turned[1][1])
            .abs()
            .to_degrees();
    // A fit that left the grid's range of focal lengths or rolls found no curve's camera.
    let inside = (lo..=hi).contains(&x[0])
        && line_angle_diff(x[1] - centre_roll).abs() <= CURVED_ROLL_LIMIT_DEG.to_radians();
    (inside && vp1.is_finite() && vp2.is_finite()).then_some(CurvedFit {
        focal_px: x[0].exp(),
        roll: x[1],
        vp1,
        vp2,
        edgelets: full.point.len(),
        vehicles: full.tangent.len(),
        roll_sd_deg,
        focal_px_p16: p16,
        focal_px_p84: p84,
        roll_turn_sd_deg: roll_per_deg * EDGE_TURN_SD_DEG,
        focal_bias_log_spread,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solve::sd;

    /// Normal deviates (Box-Muller) with standard deviation `s`.
    fn normals(n: usize, s: f64, seed: u64) -> Vec<f64> {
        let mut rng = SplitMix(seed);
        (0..n).map(|_| s * rng.normal()).collect()
    }

    #[test]
    fn the_roll_spread_is_a_normal_s_standard_deviation() {
        let rolls = normals(2000, 0.3, 7);
        let (_, _, spread) = bootstrap_spread(vec![1000.0; 2000], &rolls);
        assert!((spread - 0.3).abs() < 0.03, "{spread}");
    }

    #[test]
    fn a_few_refits_in_another_valley_do_not_decide_the_roll_spread() {
        // 92 of 100 refits agree within 0.1°, 8 settle 6° away (a crossing road's edges):
        // the standard deviation says the roll is unusable (> 0.5°), the spread does not.
        let mut rolls = normals(92, 0.1, 11);
        rolls.extend([6.0; 8]);
        let (_, _, spread) = bootstrap_spread(vec![1000.0; 100], &rolls);
        assert!(sd(&rolls) > 1.0, "{}", sd(&rolls));
        assert!(spread < 0.2, "{spread}");
    }

    #[test]
    fn no_resamples_give_no_spread() {
        let (p16, p84, spread) = bootstrap_spread(Vec::new(), &[]);
        assert!(p16.is_nan() && p84.is_nan() && spread.is_nan());
    }
}
