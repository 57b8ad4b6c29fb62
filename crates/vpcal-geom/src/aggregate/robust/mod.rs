//! Robust aggregation: per-vehicle VP pairs to one camera using the geometry of the problem
//! rather than coordinate medians. This module is the fusion core: it runs the evidence
//! sources, each in its own module with its own settings, and combines what they say.
//!
//! # Why not medians
//! Each vehicle's VP1 defines a *line*: from the vehicle through VP1. The direction of that
//! line is what a CNN predicts well; the distance along it is not. For VP2 it is worse: on real
//! BrnoCompSpeed footage the public DeepVPCalib-style CNNs place VP2 10-100x too close to the
//! vehicle (so per-pair focal lengths are biased low by a factor 2-4), while the *direction*
//! towards VP2 is right to a few degrees, with a per-video bias of 1-10°. The reference rule
//! (medians of per-pair focal lengths and horizon slopes) inherits both problems.
//!
//! # The estimator, source by source
//! 1. **The vehicles** ([`super::vehicles`]): pairs with a detector score above `min_score`,
//!    finite VPs and a box; repeated boxes at one place (IoU > `duplicate_iou`) share a
//!    weight of `duplicate_keep`; small boxes (below `min_box_fraction` of the image height)
//!    are down-weighted quadratically; each box belongs to a physical vehicle, the
//!    bootstraps' unit.
//! 2. **The tracks** ([`super::tracks`]): boxes of successive frames linked into tracks; the
//!    straight ones are VP1 lines, and tracks that bend alike say the road curves.
//! 3. **VP1** (`vp1`): the robust intersection of VP1 lines on the sphere of homogeneous
//!    points. The network's per-vehicle VP1 rays (weighted by `1 / (D^s_vp1 + 0.05)` where
//!    the decoder spread is known), or the straight tracks' lines when at least
//!    `min_track_lines` agree and the network's rays scatter by more than
//!    `track_above_scatter_deg` around their own VP1 (or the tracks by less than
//!    `track_residual_ratio` times that). Box-centre tracks point at VP1 to ~0.1° on the
//!    synthetic suite, where the bundled network's rays are off by 3-12° with a bias; on
//!    BrnoCompSpeed the two better public CNNs' rays scatter by 1.2-2.9° and the tracks of the
//!    sparse detections (every 10th frame) by 0.25-0.93°, and the rays are mostly kept: there
//!    the tracks were 0.6-5° off the published DubskaCalib VP1.
//! 4. **The network's VP2 rays** ([`super::rays`]): the horizon model (`f`, the roll `θ`
//!    through VP1, a constant ray bias `δ` under a weak Gaussian prior), with `f` held
//!    at `focal_prior_ratio` x image width unless a source measures it. (Fitting `f` too
//!    under a prior on `ln f` let the biased rays pull it: with the physical prior's spread of
//!    0.59 the pooled ratio error on BrnoCompSpeed 0-3 rose from 9.5 / 12.2 / 8.8 % to 10.9 /
//!    17.4 / 11.0 % and the synthetic demo's focal length fell 29 % below the truth.) Where
//!    the VP2 *points* imply the focal length the rays alone give (within
//!    `consistency_log_ratio`) the rays are trusted and fit VP1, `f` and `θ` jointly; else
//!    their likelihood of `f` is a cue (the systematic error of their VP2 taken as
//!    [`RAY_SYSTEMATIC_PER_SCATTER`](super::rays::RAY_SYSTEMATIC_PER_SCATTER) times their
//!    scatter), and their own roll, free in the fit, is weighed against the physical prior
//!    on the horizon's angle (`roll_prior_sigma_deg` around level) by its measured error
//!    ([`RaysRoll`](super::rays::RaysRoll): twice their scatter).
//! 5. **The edgelets** ([`super::edgelets`]): without tracks, VP1 is re-fitted to the edges
//!    along the vehicles; the edges across them fit (f, roll) with VP1 fixed, the roll
//!    replacing the rays' where its bootstrap spread is small and its fit inside the grid
//!    ([`STRAIGHT_ROLL_GRID_DEG`](super::edgelets::STRAIGHT_ROLL_GRID_DEG)), and the focal
//!    length a cue where it is identified (its gates: `max_vp2_widths`, its spread, its
//!    turn). On a curved road the curved-road fit takes each car's VP1 from its track's
//!    tangent.
//! 6. **The scene's lines** ([`super::scene_lines`]): on a straight road, VP1 moves to where
//!    the background's lines along the road meet while the vehicles' VP1 lines still agree
//!    (`scene_max_extra_deg`).
//! 7. **The scene's vertical lines** ([`super::verticals`]): where the background's line
//!    segments are given, VP3 (where poles and posts meet) with VP1 and the horizon measures
//!    `f` without VP2.
//! 8. **The focal posterior** ([`super::focal`]): the prior (uniform in `ln f` over 15-90°
//!    views, soft edges, or the user's range) times the cues whose model holds: on a straight
//!    road the edgelets, the trusted rays' fit or the untrusted rays' likelihood; on a curved
//!    road the curved-road fit only; none of these where the edges across the vehicles are
//!    parallel in the image ([`PARALLEL_EDGES_VP2_WIDTHS`]); the verticals wherever the
//!    horizon is placed (not on a curved road without the curved-road fit). `f` is the posterior's median where the
//!    cues carry at least the prior's information, else the prior's middle; the roll and ray
//!    bias are refitted with `f` held where no edgelets set the roll.
//! 9. **Confidence** (`bootstrap`): Poisson(1) counts per vehicle refit VP1 and (f, θ, δ);
//!    the 16th-84th percentiles of `f` (or those of the edgelet fit that carried it) and the
//!    spread of the horizon angle are reported.
//! 10. **The horizon against the vehicles** ([`super::sizes`]): more than `max_above_horizon`
//!     of the vehicle weight above the horizon, or box sizes that do not grow away from it
//!     (near-top-down views, where the VPs are near infinity and the focal length cannot be
//!     observed), is not enough evidence.
//!
//! Each stage writes its own fields of [`Evidence`]. On the 12 BrnoCompSpeed training videos
//! this is measured against the reference rule by `vpcal eval vpout` (ARCHITECTURE.md has the
//! table).

use super::edgelets::{BoxEdgelets, Edgelet};
use super::focal::focal_prior_range_widths;
use super::tracks::RoadTracks;
use super::vehicles::{prepare, tracked_boxes, vehicle_units, Prepared};
use super::verticals::Segment;
use super::{AggregateError, VehicleVps};
use crate::point::{BoxPx, Point2};
use crate::solve::SplitMix;

mod camera_stage;
mod focal_stage;
mod horizon_stage;
mod options;
mod result;
mod vp1_stage;
pub use options::RobustOptions;
pub use result::{Confidence, Evidence, RobustResult};

use camera_stage::make_camera;
use focal_stage::fuse_focal;
use horizon_stage::place_horizon;
use vp1_stage::place_vp1;

/// An edgelet VP2 farther than this many image widths from the principal point says the
/// edges across the vehicles are parallel in the image (f > 100 widths is a 0.6° view: no
/// traffic camera): the view looks almost straight down, or VP1 and VP2 cannot both be
/// placed, and the focal length is not observable.
pub const PARALLEL_EDGES_VP2_WIDTHS: f64 = 100.0;

/// Estimate the camera from `pairs` with principal point `pp`.
///
/// # Errors
/// [`AggregateError::NotEnoughEvidence`] when too few usable vehicles remain, VP1 cannot be
/// located (or lies at infinity), or the result is not a valid camera.
pub fn aggregate(
    pairs: &[VehicleVps],
    pp: Point2,
    opts: &RobustOptions,
) -> Result<RobustResult, AggregateError> {
    aggregate_with_edgelets(pairs, &[], pp, opts)
}

/// [`aggregate`], with the edgelets found inside each vehicle's box (`edgelets[i]` belongs
/// to `pairs[i]`; an empty slice means none): with `opts.edgelets` set, they give the
/// horizon's roll, and the focal length where VP2 is near enough to be located
/// ([`super::edgelets`]).
///
/// # Errors
/// As [`aggregate`].
///
/// # Panics
/// When `edgelets` is neither empty nor as long as `pairs`.
pub fn aggregate_with_edgelets(
    pairs: &[VehicleVps],
    edgelets: &[Vec<Edgelet>],
    pp: Point2,
    opts: &RobustOptions,
) -> Result<RobustResult, AggregateError> {
    aggregate_with_scene(pairs, edgelets, Scene::default(), pp, opts)
}

/// What the scene's background picture shows (frame pixels; empty: nothing).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Scene<'a> {
    /// Its edgelets: the lines along the road move VP1 ([`scene_lines`](super::scene_lines)).
    pub edgelets: &'a [Edgelet],
    /// Its straight line segments: the vertical ones measure the focal length
    /// ([`verticals`](super::verticals)).
    pub segments: &'a [Segment],
}

/// [`aggregate_with_edgelets`], with what the scene's background shows ([`Scene`]): with
/// `opts.scene_lines` set and a straight road, VP1 moves to where the scene's lines along the
/// road meet ([`scene_lines`](super::scene_lines)) while the vehicles' VP1 evidence agrees
/// (`opts.scene_max_extra_deg`); with `opts.verticals` set, its vertical lines measure the
/// focal length ([`verticals`](super::verticals)).
///
/// The stages, each a function with what it found as its result: the vehicles
/// (`usable_vehicles`, below), VP1 (`place_vp1`, `vp1_stage.rs`), the horizon's roll
/// (`place_horizon`, `horizon_stage.rs`), the focal posterior (`fuse_focal`,
/// `focal_stage.rs`) and the camera they make (`make_camera`, `camera_stage.rs`).
///
/// # Errors
/// As [`aggregate`].
///
/// # Panics
/// As [`aggregate_with_edgelets`].
pub fn aggregate_with_scene(
    pairs: &[VehicleVps],
    edgelets: &[Vec<Edgelet>],
    scene: Scene,
    pp: Point2,
    opts: &RobustOptions,
) -> Result<RobustResult, AggregateError> {
    assert!(
        edgelets.is_empty() || edgelets.len() == pairs.len(),
        "{} edgelet lists for {} pairs",
        edgelets.len(),
        pairs.len()
    );
    let frame = opts.image_size.unwrap_or([2.0 * pp.x, 2.0 * pp.y]);
    if !(frame[0] > 0.0 && frame[1] > 0.0 && pp.is_finite()) {
        return Err(not_enough(format!(
            "invalid image size {}x{} or principal point {pp}",
            frame[0], frame[1]
        )));
    }
    let input = Input {
        pairs,
        edgelets,
        scene,
        pp,
        frame,
        opts,
    };
    let (unit, full, effective) = usable_vehicles(&input)?;
    let prep = full.thinned(opts.max_fit_vehicles);
    let mut evidence = Evidence {
        pairs_in: pairs.len(),
        pairs_used: full.centre.len(),
        effective_vehicles: effective,
        repeated_boxes: prep.repeated,
        ..Evidence::default()
    };
    let mut rng = SplitMix(opts.seed ^ 0x5EED_CA1B);
    // The tracks (`super::tracks`): VP1 evidence where straight, the road's shape.
    let (boxes, tracked) = tracked_boxes(pairs, &opts.weighting());
    let curve = opts.curve_test();
    let mut road = RoadTracks::of(boxes, tracked, opts.tracks.as_ref(), frame, &curve);
    let boxes = box_edgelets(pairs, edgelets, &unit, opts.min_score);
    let placed = place_vp1(&input, &full, &prep, &mut road, &boxes, &mut rng)?;
    placed.record(&road, &mut evidence);
    let horizon = place_horizon(&input, &placed, &road, &boxes, &unit, &mut rng);
    horizon.record(input.width(), &mut evidence);
    let focal = fuse_focal(&input, &placed, &horizon, &road)?;
    focal.record(&mut evidence);
    make_camera(&input, &full, horizon, focal, evidence, road)
}

/// What [`aggregate_with_scene`] was given, for its stages.
#[derive(Clone, Copy)]
struct Input<'a> {
    pairs: &'a [VehicleVps],
    edgelets: &'a [Vec<Edgelet>],
    scene: Scene<'a>,
    pp: Point2,
    /// Width and height of the frames, pixels.
    frame: [f64; 2],
    opts: &'a RobustOptions,
}

impl Input<'_> {
    fn width(&self) -> f64 {
        self.frame[0]
    }

    /// The focal posterior's prior range, pixels (the user's or the physical band).
    fn range_px(&self) -> [f64; 2] {
        focal_prior_range_widths(self.opts.focal_range_widths).map(|r| r * self.width())
    }
}

/// The vehicles (`super::vehicles`): each pair's physical vehicle (the bootstraps' unit for
/// the fits and the edgelets), and the usable pairs weighed, with their effective number;
/// `Err` where too few are.
fn usable_vehicles(input: &Input) -> Result<(Vec<usize>, Prepared, f64), AggregateError> {
    let (pairs, opts) = (input.pairs, input.opts);
    let vehicles = vehicle_units(pairs);
    let full = prepare(pairs, &vehicles, &opts.weighting(), input.frame[1]);
    // `+ 0.0` turns an empty sum's -0.0 into 0.0 for the messages.
    let effective: f64 = full.weight.iter().sum::<f64>() + 0.0;
    if full.centre.len() < 2 || effective < opts.min_effective_vehicles {
        return Err(not_enough(format!(
            "{} usable vehicles (effective weight {effective:.1}) of {} pairs; at least {} needed \
             (a pair needs score > {}, finite VPs and a box)",
            full.centre.len(),
            pairs.len(),
            opts.min_effective_vehicles,
            opts.min_score
        )));
    }
    Ok((vehicles.0, full, effective))
}

/// Why the evidence gives no camera.
fn not_enough(message: impl Into<String>) -> AggregateError {
    AggregateError::NotEnoughEvidence(message.into())
}

/// The vehicles with edgelets (`edgelets[i]` those of `pairs[i]`, `unit[i]` its vehicle).
fn box_edgelets<'a>(
    pairs: &[VehicleVps],
    edgelets: &'a [Vec<Edgelet>],
    unit: &[usize],
    min_score: f64,
) -> Vec<BoxEdgelets<'a>> {
    pairs
        .iter()
        .zip(edgelets)
        .zip(unit)
        .filter(|((p, e), _)| p.score > min_score && !e.is_empty())
        .filter_map(|((p, e), u)| {
            Some(BoxEdgelets {
                centre: p.box_px.filter(BoxPx::is_valid)?.center(),
                vp1: p.vp1,
                vp2: p.vp2,
                edgelets: e,
                vehicle: *u,
            })
        })
        .collect()
}
