//! Robust aggregation: per-vehicle VP pairs to one camera using the geometry of the problem
//! rather than coordinate medians.
//!
//! # Why not medians
//! Each vehicle's VP1 defines a *line*: from the vehicle through VP1. The direction of that
//! line is what a CNN predicts well; the distance along it is not. For VP2 it is worse: on real
//! BrnoCompSpeed footage the public DeepVPCalib-style CNNs place VP2 10-100x too close to the
//! vehicle (so per-pair focal lengths are biased low by a factor 2-4), while the *direction*
//! towards VP2 is right to a few degrees, with a per-video bias of 1-10°. The reference rule
//! (medians of per-pair focal lengths and horizon slopes) inherits both problems.
//!
//! # The estimator
//! 1. **Evidence weights.** Pairs with a detector score above `min_score` and finite VPs.
//!    Boxes that stay at the same place over neighbouring frames (static objects, parked
//!    vehicles: IoU > `duplicate_iou`) share, per place, a total weight of `duplicate_keep`;
//!    small boxes (below `min_box_fraction` of the image height) are down-weighted
//!    quadratically, since their VP directions are unreliable.
//! 2. **VP1**: the robust intersection of the lines from each box centre towards its VP1:
//!    RANSAC over pairs of lines (MSAC score on the angle between a line and the direction
//!    to the candidate), then Cauchy-weighted least squares on the angles. The candidate lives
//!    on the sphere of homogeneous points, so a far VP1 is no special case. Lines are weighted
//!    by `1 / (D^s_vp1 + 0.05)` when the decoder spread is known.
//!    **Tracks** ([`super::tracks`]): when boxes of successive frames link into at least
//!    `min_track_lines` straight tracks that agree on a VP1, and the network's rays scatter
//!    around their own VP1 by more than `track_above_scatter_deg` (median) or the track lines
//!    around theirs by less than `track_residual_ratio` times that, VP1 is fitted the same way
//!    to the tracks' lines instead. Box-centre tracks point at VP1 to ~0.1° on the synthetic
//!    suite, where the bundled network's rays are off by 3-12° with a bias; on BrnoCompSpeed
//!    the two better public CNNs' rays scatter by 1.2-2.9° and the tracks of the sparse
//!    detections (every 10th frame) by 0.25-0.93°, and the rays are mostly kept: there the
//!    tracks were 0.6-5° off the published DubskaCalib VP1.
//! 3. **Horizon and focal length.** The camera is parametrised by the focal length `f`, the
//!    horizon's roll `θ` through VP1, and a constant angular bias `δ` of the CNN's VP2 rays;
//!    VP2 is the point of the horizon orthogonal to VP1 for `f` (so every candidate is a valid
//!    camera). The cost is a robust loss of the angles between each vehicle's VP2 ray and the
//!    direction to VP2 (rotated by `δ`), plus weak Gaussian priors on `θ` and `δ`; `f` is held
//!    at `focal_prior_ratio` x image width (assumed) unless step 4 or 5 measures it. A coarse
//!    grid is refined by Nelder-Mead. (Fitting `f` too under a prior on `ln f`, as before,
//!    let the biased rays pull it: with the physical prior's spread of 0.59 the pooled ratio
//!    error on BrnoCompSpeed 0-3 rose from 9.5 / 12.2 / 8.8 % to 10.9 / 17.4 / 11.0 % and the
//!    synthetic demo's focal length fell 29 % below the truth.)
//! 4. **Trusting the data.** When the VP2 *points* imply the same focal length as the rays
//!    alone (within `consistency_log_ratio`), the network has no distance bias and the rays
//!    are trusted: `f` is fitted, the roll prior is dropped, `δ` is fixed at 0 and VP1, `f` and `θ` are refined
//!    jointly. The loss is then Geman-McClure (bounded: true outliers add a constant);
//!    in the biased regime it is Cauchy (its unbounded tail lets systematically deviating
//!    rays still pull, which measured better on the real CNN outputs: 8.8 / 22 / 9.1 % vs
//!    9.3 / 21 / 9.0 % pooled for the three public CNNs).
//!    **Untrusted rays** ([`rays_focal_likelihood`]): otherwise the rays alone still place
//!    VP2 on a horizon, off by an angle taken as [`RAY_SYSTEMATIC_PER_SCATTER`] times their
//!    scatter: a likelihood of `f`, one cue of the focal posterior (step 6).
//! 5. **Edgelets** ([`aggregate_with_edgelets`], [`super::edgelets`]): without tracks, VP1
//!    is re-fitted to the edges along the vehicles (they point at VP1). With the edges across
//!    the vehicles that point at VP2, (f, roll) is fitted again with VP1 fixed; the roll
//!    replaces the one above when its bootstrap spread is small, and the focal length is a
//!    cue where it is identified (VP2 within `max_vp2_widths` image widths, small spread, a
//!    systematic turn of the edges moving it little: beyond these the fit fails in ways its
//!    bootstrap does not show, e.g. pixel staircases on nearly horizontal edges).
//! 6. **The focal posterior** ([`super::focal`]): the prior (uniform in `ln f` over 15-90°
//!    views, soft edges) times the cues that apply: on a straight road the edgelets, the
//!    trusted rays' fit or the untrusted rays' likelihood; on a curved road the curved-road
//!    fit only (each car has its own VP2 there). `f` is the posterior's median where the cues
//!    carry at least the prior's information, else the prior's middle; the roll and ray bias
//!    are refitted with `f` held where no edgelets set the roll.
//! 7. **Confidence**: a bootstrap over vehicles (re-weighting with Poisson(1) counts) re-fits
//!    VP1 and (f, θ, δ); the 16th-84th percentiles of `f` and the spread of the horizon angle
//!    are reported, with the focal length the data alone prefers (no focal prior).
//! 8. **Vehicles stand below the horizon.** An estimate whose horizon has more than
//!    `max_above_horizon` (half) of the vehicle weight's box centres above it is impossible,
//!    and is reported as not enough evidence instead of returned. On the synthetic suite the
//!    outright failures had 98-100 % above (one had 11 %), every other result none
//!    (`scripts/horizon_vs_boxes.py`); a tighter 10 % also refused a real residential-street
//!    clip with a plausible horizon (motion boxes of distant cars and foliage near it).
//!
//! 9. **Vehicles grow away from the horizon** ([`super::sizes`]): an estimate whose horizon
//!    the boxes' sizes contradict (they do not grow with the distance below it) is reported
//!    as not enough evidence: near-top-down views, where the VPs are near infinity and the
//!    focal length cannot be observed, end here.
//!
//! On the 12 BrnoCompSpeed training videos this is measured against the reference rule by
//! `vpcal eval vpout` (ARCHITECTURE.md has the table).

use super::edgelets::{self as edge, BoxEdgelets, CurvedVehicle, Edgelet, EdgeletFitOptions};
use super::focal::{self, FocalPosterior, FocalSource, Likelihood};
use super::line_angle_diff;
use super::scene_lines::{self, SceneLineOptions};
use super::tracks::{self, TrackLine, TrackOptions};
use super::{AggregateError, VehicleVps};
use crate::camera::Calibration;
use crate::point::{BoxPx, Line, Point2};
use crate::solve::{nelder_mead, percentile, sd, SplitMix};

/// Horizontal fields of view of traffic cameras, degrees: from a telephoto view far along a
/// motorway (15°) to a wide-angle view of a junction (90°). The focal-length prior comes from
/// this range, not from any dataset's cameras.
pub const TRAFFIC_FOV_DEG: [f64; 2] = [15.0, 90.0];

/// The focal length of a horizontal field of view, in image widths: `0.5 / tan(fov / 2)`.
pub fn focal_widths(fov_deg: f64) -> f64 {
    0.5 / (fov_deg.to_radians() / 2.0).tan()
}

/// The focal-length prior as `(median, sd of ln f)` in image widths: a focal length uniform
/// in `ln f` over [`TRAFFIC_FOV_DEG`] has its median at the geometric mean of the range's
/// ends (1.38 widths, a 40° view) and a standard deviation of `ln(range) / sqrt(12)` (0.59).
pub fn physical_focal_prior() -> (f64, f64) {
    let (long, wide) = (
        focal_widths(TRAFFIC_FOV_DEG[0]),
        focal_widths(TRAFFIC_FOV_DEG[1]),
    );
    ((long * wide).sqrt(), (long / wide).ln() / 12f64.sqrt())
}

/// The focal-length prior's range in image widths, `[short, long]`: `range`, or the focal
/// lengths of [`TRAFFIC_FOV_DEG`] (0.5-3.8 widths).
pub fn focal_prior_range_widths(range: Option<[f64; 2]>) -> [f64; 2] {
    range.unwrap_or([
        focal_widths(TRAFFIC_FOV_DEG[1]),
        focal_widths(TRAFFIC_FOV_DEG[0]),
    ])
}

/// Settings of the robust aggregation; `Default` is what vpcal uses.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RobustOptions {
    /// Pairs need a detector score strictly above this.
    pub min_score: f64,
    /// Image width and height in pixels; default: twice the principal point.
    pub image_size: Option<[f64; 2]>,
    /// The focal length assumed when no evidence fixes it, as a multiple of the image width
    /// (default: the median of [`physical_focal_prior`]).
    pub focal_prior_ratio: f64,
    /// The focal lengths the camera can have, in image widths (e.g. a zoom lens's range
    /// from its data sheet), replacing [`TRAFFIC_FOV_DEG`] as the prior's range (uniform in
    /// `ln f`); `focal_prior_ratio` should then be its geometric middle.
    #[serde(default)]
    pub focal_range_widths: Option<[f64; 2]>,
    /// Standard deviation of the roll prior, degrees.
    pub roll_prior_sigma_deg: f64,
    /// Standard deviation of the prior on the CNN's VP2 ray bias, degrees.
    pub ray_bias_prior_sigma_deg: f64,
    /// Scale of the Cauchy loss on VP2 ray angles, degrees.
    pub ray_scale_deg: f64,
    /// Inlier threshold (and Cauchy scale) for VP1 lines, degrees.
    pub vp1_threshold_deg: f64,
    /// Strength of the priors relative to the data: each prior term is multiplied by this
    /// fraction of the total vehicle weight (for rays that scatter like `ray_noise_reference_deg`
    /// around the fitted model; see there).
    pub prior_weight: f64,
    /// The VP2 points agree with the VP2 rays when their focal lengths differ by less than
    /// this in `|ln(f_points / f_rays)|`; the focal prior is then dropped.
    pub consistency_log_ratio: f64,
    /// Boxes overlapping with IoU above this are the same object seen again.
    pub duplicate_iou: f64,
    /// Total weight of a group of repeated boxes.
    pub duplicate_keep: f64,
    /// Boxes whose geometric-mean half size is below this fraction of the image height get
    /// weight `(size / threshold)²`.
    pub min_box_fraction: f64,
    /// Bootstrap resamples for the confidence (0 to skip).
    pub bootstrap: usize,
    /// Seed of RANSAC and the bootstrap (results are deterministic for a seed).
    pub seed: u64,
    /// Fewer effective vehicles than this is "not enough evidence".
    pub min_effective_vehicles: f64,
    /// Fit on at most this many vehicles: larger inputs are thinned to an evenly spaced
    /// subsample (in input order, weights rescaled to the full total) for the fits, while the
    /// evidence counts use every vehicle. Thousands of vehicles already pin the estimate far
    /// below the networks' systematic errors; this bounds the time (100 000 pairs well under
    /// a second).
    pub max_fit_vehicles: usize,
    /// Largest share of the vehicle weight whose box centres may lie above the estimated
    /// horizon; more is "not enough evidence" (vehicles stand on the road, below it).
    pub max_above_horizon: f64,
    /// Link the boxes of successive frames into tracks and fit VP1 to the tracks' lines
    /// instead of the network's VP1 rays when at least `min_track_lines` tracks qualify
    /// (`None`: always the network's rays).
    pub tracks: Option<TrackOptions>,
    /// Fewest qualifying tracks for VP1 to come from the tracks.
    pub min_track_lines: usize,
    /// Inlier threshold (and Cauchy scale) for track lines, degrees.
    pub track_threshold_deg: f64,
    /// The tracks replace the network's VP1 rays only when those scatter around their own
    /// VP1 by more than this (weighted median angle, degrees): well-trained networks on real
    /// footage (BrnoCompSpeed) scatter less and their VP1 beats box-centre tracks there.
    pub track_above_scatter_deg: f64,
    /// ... or when the track lines' median angle around their own VP1 is below this fraction
    /// of the network rays' (`evidence.track_residual_deg` vs `vp1_ray_scatter_deg`).
    pub track_residual_ratio: f64,
    /// The road is taken as curved, and the track lines are not used for VP1, when at least
    /// `curved_share` of the qualifying tracks bend the same way, significantly (t-statistic
    /// above `curved_bend_t`, [`TrackLine::bend_t`]) and by more than `curved_bend_deg`
    /// ([`TrackLine::bend_deg`]): on a curve every car has its own heading, so lines fitted to
    /// whole tracks miss VP1 and the horizon (`evidence.curved_tracks`). A track's bend is read
    /// from its boxes that the picture's edge does not cut and that are at least a third of its
    /// tallest box (`vehicle_scale::BORDER_PX`, `tracks::BEND_MIN_HEIGHT_SHARE`): cut boxes and
    /// far, tiny ones move their centres sideways on straight roads too. Exact boxes of cars
    /// on a straight road bend a little too (a box's centre is not a fixed point of the car),
    /// significantly but by less than a degree or two on the synthetic suite.
    pub curved_bend_t: f64,
    pub curved_bend_deg: f64,
    pub curved_share: f64,
    /// ... and at least this many tracks bend so (one or two bent tracks on a short clip are
    /// no curve: a wide-angle camera's box centres bend by a few degrees on straight roads).
    /// The share counts only tracks that can tell: whose turn has a standard error below
    /// `curved_max_se_deg` ([`TrackLine::bend_se_deg`]). The motion detector's boxes jitter:
    /// its long tracks on the suite's curves have standard errors of 1.2-1.7°, where exact
    /// boxes have 0.1-0.6°, so 2° (with 3 tracks) lets 6-s clips of two of the three curves
    /// tell; the share and the t-statistic still keep the straight roads straight.
    pub min_curved_tracks: usize,
    pub curved_max_se_deg: f64,
    /// Fit the horizon's roll (and, where VP2 is near enough, the focal length) to edgelets
    /// inside the vehicle boxes when they are given ([`aggregate_with_edgelets`]); `None`:
    /// never.
    pub edgelets: Option<EdgeletFitOptions>,
    /// Move VP1 to where the scene's lines along the road meet ([`scene_lines`]) when the
    /// scene's edgelets are given ([`aggregate_with_scene`]) and the road is straight; `None`:
    /// never.
    #[serde(default)]
    pub scene_lines: Option<SceneLineOptions>,
    /// ... and only while the VP1 evidence of the vehicles still agrees: the median angle of
    /// their lines (tracks, or the network's rays) at the moved VP1 at most this much above
    /// the one at their own VP1, degrees. The box centres of real vehicles' tracks miss the
    /// true VP1 by a few degrees the same way (BrnoCompSpeed sessions 0-3, deep_vp's
    /// detections: their median angle at the reference VP1 is 0.0-2.1° above the one at their
    /// own VP1, `scripts/bcs_scene_vp1.py`); a fit that ended on the lines of another
    /// direction raised it by 8.4°.
    #[serde(default = "default_scene_max_extra_deg")]
    pub scene_max_extra_deg: f64,
}

fn default_scene_max_extra_deg() -> f64 {
    2.5
}

impl Default for RobustOptions {
    fn default() -> Self {
        let (focal_prior_ratio, _) = physical_focal_prior();
        RobustOptions {
            min_score: 0.1,
            image_size: None,
            focal_prior_ratio,
            focal_range_widths: None,
            roll_prior_sigma_deg: 1.0,
            ray_bias_prior_sigma_deg: 2.0,
            ray_scale_deg: 1.0,
            vp1_threshold_deg: 2.0,
            prior_weight: 0.3,
            consistency_log_ratio: 0.15,
            duplicate_iou: 0.7,
            duplicate_keep: 3.0,
            min_box_fraction: 0.023,
            bootstrap: 30,
            seed: 0,
            min_effective_vehicles: 10.0,
            max_fit_vehicles: 2000,
            max_above_horizon: 0.5,
            tracks: Some(TrackOptions::default()),
            min_track_lines: 5,
            track_threshold_deg: 1.0,
            track_above_scatter_deg: 3.0,
            track_residual_ratio: 0.15,
            curved_bend_t: 4.0,
            curved_bend_deg: 3.0,
            curved_share: 0.6,
            min_curved_tracks: 3,
            curved_max_se_deg: 2.0,
            edgelets: Some(EdgeletFitOptions::default()),
            scene_lines: Some(SceneLineOptions::default()),
            scene_max_extra_deg: default_scene_max_extra_deg(),
        }
    }
}

/// How much evidence the estimate used.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Evidence {
    /// Pairs given.
    pub pairs_in: usize,
    /// Pairs above the score threshold with finite VPs and a box.
    pub pairs_used: usize,
    /// Sum of the vehicle weights (after duplicate and size down-weighting).
    pub effective_vehicles: f64,
    /// Boxes found repeated at the same place (down-weighted).
    pub repeated_boxes: usize,
    /// VP1 lines within the threshold angle of the estimate.
    pub vp1_inliers: usize,
    /// VP2 rays within three loss scales of the fitted model.
    pub vp2_inliers: usize,
    /// Whether the VP2 points agreed with the VP2 rays, so that the data were trusted over
    /// the priors (false for CNNs that place VP2 far too close).
    pub rays_trusted: bool,
    /// Tracks whose box centres gave a straight line.
    pub track_lines: usize,
    /// Whether VP1 was fitted to the track lines (else to the network's VP1 rays).
    pub vp1_from_tracks: bool,
    /// Weighted median angle between the network's VP1 rays and the VP1 they alone give,
    /// degrees (`None` when they give none).
    pub vp1_ray_scatter_deg: Option<f64>,
    /// Median angle between the track lines and the VP1 they alone give, degrees (`None`
    /// without enough agreeing tracks).
    pub track_residual_deg: Option<f64>,
    /// Track lines that bend significantly the same way (the larger of the two sides), and
    /// whether they made the road count as curved, so that VP1 did not come from the tracks.
    pub curved_tracks: usize,
    pub road_curved: bool,
    /// Whether the horizon and focal length came from the curved-road fit
    /// ([`edge::fit_curved`]: each car's own VP1 from its track's tangent), and on how many
    /// vehicles.
    pub curved_fit: bool,
    pub curved_vehicles: usize,
    /// Whether the curved-road fit carried the focal length in its posterior
    /// (`super::focal`); without it the fit gave the horizon only.
    #[serde(default)]
    pub curved_focal: bool,
    /// Edgelets (and vehicles with edgelets) the edgelet fit used; 0 without one.
    pub edgelets: usize,
    pub edgelet_vehicles: usize,
    /// Whether VP1 came from the edgelets along the vehicles (only without tracks), and how
    /// many edgelets that fit used.
    pub vp1_from_edgelets: bool,
    pub vp1_edgelets: usize,
    /// Whether VP1 was then moved to where the scene's lines along the road meet
    /// ([`scene_lines`]), on how many edgelets, and by how far (pixels).
    pub vp1_from_scene_lines: bool,
    pub vp1_scene_edgelets: usize,
    pub vp1_scene_shift_px: Option<f64>,
    /// How much the scene lines' VP1 raised the median angle of the vehicles' VP1 lines
    /// (degrees), whether or not it was used (`None`: no scene fit).
    pub vp1_scene_extra_deg: Option<f64>,
    /// Whether the horizon's roll came from the edgelets, and whether the straight edgelet
    /// fit carried the focal length in its posterior.
    pub roll_from_edgelets: bool,
    pub focal_from_edgelets: bool,
    /// The edgelet fit's focal length (px) and the bootstrap spread of its roll (degrees),
    /// whether or not they were used.
    pub edgelet_focal_px: Option<f64>,
    pub edgelet_roll_sd_deg: Option<f64>,
    /// Half of `ln(p84 / p16)` of the edgelet fit's bootstrap focal lengths, and the distance
    /// of its VP2 from the principal point in image widths (the focal length's two gates).
    pub edgelet_focal_log_spread: Option<f64>,
    pub edgelet_vp2_widths: Option<f64>,
    /// How far a systematic turn of the edges by `edge::EDGE_BIAS_DEG` moves the edgelet
    /// fit's focal length (half the `ln f` difference; its third gate).
    pub edgelet_focal_bias_log_spread: Option<f64>,
    /// How the vehicles' box sizes grow with their distance below the estimated horizon (the
    /// power of a log-log fit; 1 when they agree, see `super::sizes`); `None` with too few
    /// boxes.
    pub size_slope: Option<f64>,
    /// Where the VP2 rays were not trusted: the focal length they alone give (pixels), the
    /// weighted median angle of the rays around it (degrees), the systematic error assumed
    /// for their VP2 ([`RAY_SYSTEMATIC_PER_SCATTER`] times that, degrees), and the 16th,
    /// 50th and 84th percentiles of the focal length under the physical prior and that
    /// evidence alone ([`rays_focal_posterior`]).
    #[serde(default)]
    pub rays_focal_px: Option<f64>,
    #[serde(default)]
    pub rays_scatter_deg: Option<f64>,
    #[serde(default)]
    pub rays_vp2_sd_deg: Option<f64>,
    #[serde(default)]
    pub rays_posterior_px: Option<[f64; 3]>,
    /// Whether the rays carried the focal length in its posterior (`super::focal`).
    #[serde(default)]
    pub focal_from_rays: bool,
}

/// The spread of the estimate under resampling of the vehicles.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Confidence {
    /// 16th percentile of the bootstrap focal lengths, pixels.
    pub focal_px_p16: f64,
    /// 84th percentile of the bootstrap focal lengths, pixels.
    pub focal_px_p84: f64,
    /// Standard deviation of the horizon angle, degrees.
    pub horizon_angle_sd_deg: f64,
    /// Standard deviation of VP1's position, pixels (RMS over x and y).
    pub vp1_sd_px: f64,
    /// The focal length the VP2 rays alone prefer (no priors, no ray bias), pixels.
    pub focal_px_data_only: f64,
    /// Bootstrap resamples used.
    pub resamples: usize,
}

/// The robust estimate and the evidence behind it.
#[derive(Debug, Clone, PartialEq)]
pub struct RobustResult {
    pub calibration: Calibration,
    /// Roll of the horizon, radians.
    pub roll: f64,
    /// Fitted angular bias of the VP2 rays, radians.
    pub ray_bias: f64,
    pub evidence: Evidence,
    /// `None` when `bootstrap` is 0.
    pub confidence: Option<Confidence>,
    /// The focal length's posterior (its median is `calibration.focal_px`).
    pub focal: FocalPosterior,
    /// The straight vehicle tracks found (whether or not VP1 came from them).
    pub track_lines: Vec<TrackLine>,
}

/// The Geman-McClure loss `r² / (1 + r²)`: quadratic near zero, bounded by 1, so that
/// outliers (wrong rays far from the model) add a constant rather than pulling the fit. Used
/// when the rays are trusted (module docs, step 4); the biased regime uses Cauchy.
fn geman_mcclure(r: f64) -> f64 {
    let r2 = r * r;
    r2 / (1.0 + r2)
}

/// Per-vehicle data prepared for fitting (frame pixels).
#[derive(Debug, Clone)]
struct Prepared {
    centre: Vec<Point2>,
    /// Unit direction from the centre towards VP1.
    dir1: Vec<Point2>,
    /// Angle of the ray from the centre towards VP2, radians.
    angle2: Vec<f64>,
    /// VP1 points, frame pixels.
    vp1: Vec<Point2>,
    /// VP2 points, frame pixels.
    vp2: Vec<Point2>,
    /// Base weight (duplicates, size).
    weight: Vec<f64>,
    /// VP1-line weight factor from the decoder spread.
    spread1: Vec<f64>,
    /// The boxes.
    boxes: Vec<BoxPx>,
    /// The physical vehicle of each box ([`vehicle_units`]): the bootstrap's unit.
    unit: Vec<usize>,
    /// How many vehicles `unit` numbers.
    units: usize,
    repeated: usize,
}

impl Prepared {
    /// At most `max` vehicles, evenly spaced in input order, with weights rescaled so that
    /// their total equals the full total.
    fn thinned(&self, max: usize) -> Prepared {
        let n = self.centre.len();
        if max == 0 || n <= max {
            return self.clone();
        }
        let idx: Vec<usize> = (0..max).map(|k| k * n / max).collect();
        let pick = |v: &Vec<Point2>| idx.iter().map(|&i| v[i]).collect::<Vec<_>>();
        let pickf = |v: &Vec<f64>| idx.iter().map(|&i| v[i]).collect::<Vec<_>>();
        let total: f64 = self.weight.iter().sum();
        let mut weight = pickf(&self.weight);
        let sub: f64 = weight.iter().sum();
        if sub > 0.0 {
            weight.iter_mut().for_each(|w| *w *= total / sub);
        }
        Prepared {
            centre: pick(&self.centre),
            dir1: pick(&self.dir1),
            angle2: pickf(&self.angle2),
            vp1: pick(&self.vp1),
            vp2: pick(&self.vp2),
            weight,
            spread1: pickf(&self.spread1),
            boxes: idx.iter().map(|&i| self.boxes[i]).collect(),
            unit: idx.iter().map(|&i| self.unit[i]).collect(),
            units: self.units,
            repeated: self.repeated,
        }
    }
}

fn unit(v: Point2) -> Option<Point2> {
    let n = v.norm();
    (n > 0.0 && n.is_finite()).then(|| v / n)
}

/// Buckets of box indices by the grid cell of their centre, for fast overlap queries.
struct BoxGrid<'a> {
    boxes: &'a [BoxPx],
    cells: std::collections::HashMap<(i64, i64), Vec<usize>>,
}

impl<'a> BoxGrid<'a> {
    const CELL: f64 = 32.0;

    fn key(p: Point2) -> (i64, i64) {
        (
            (p.x / Self::CELL).floor() as i64,
            (p.y / Self::CELL).floor() as i64,
        )
    }

    fn new(boxes: &'a [BoxPx], keep: impl Fn(usize) -> bool) -> BoxGrid<'a> {
        let mut cells: std::collections::HashMap<(i64, i64), Vec<usize>> =
            std::collections::HashMap::new();
        for (i, b) in boxes.iter().enumerate().filter(|(i, _)| keep(*i)) {
            cells.entry(Self::key(b.center())).or_default().push(i);
        }
        BoxGrid { boxes, cells }
    }

    /// Indices of the boxes of the grid overlapping box `i` with IoU above `iou` (boxes with
    /// IoU > 0.5 have centres within half the box size of each other).
    fn overlapping(&self, i: usize, iou: f64) -> impl Iterator<Item = usize> + '_ {
        let b = self.boxes[i];
        let (kx, ky) = Self::key(b.center());
        let rx = (b.width() / 2.0 / Self::CELL).ceil() as i64 + 1;
        let ry = (b.height() / 2.0 / Self::CELL).ceil() as i64 + 1;
        (kx - rx..=kx + rx)
            .flat_map(move |gx| (ky - ry..=ky + ry).map(move |gy| (gx, gy)))
            .filter_map(|k| self.cells.get(&k))
            .flatten()
            .copied()
            .filter(move |&j| b.iou(&self.boxes[j]) > iou)
    }
}

/// How far (in median frame steps) the stationary-box count looks back and ahead.
const REPEAT_WINDOW_STEPS: f64 = 100.0;

/// For each box, how many boxes share its place: the number of *stationary* boxes overlapping
/// it with IoU above `iou` (itself included) within [`REPEAT_WINDOW_STEPS`] frame steps, or 1
/// for a moving box.
///
/// A box is stationary when a box of a neighbouring frame (at most 1.5 median frame steps
/// away) overlaps it with IoU above `iou`: a parked vehicle or a static false detection. Cars
/// that pass the same spot at different times are not. Without frame numbers every box
/// counts as stationary (the conservative choice) and is compared with every other box
/// without a frame number.
///
/// Boxes are bucketed by (frame, grid cell), so the work grows with the boxes per frame and
/// the window, not with the square of the number of boxes.
fn repeat_counts(boxes: &[BoxPx], frames: &[Option<f64>], iou: f64) -> Vec<usize> {
    let n = boxes.len();
    let mut distinct: Vec<f64> = frames.iter().flatten().copied().collect();
    distinct.sort_by(f64::total_cmp);
    distinct.dedup();
    let steps: Vec<f64> = distinct.windows(2).map(|w| w[1] - w[0]).collect();
    let median_step = if steps.is_empty() {
        0.0
    } else {
        let mut s = steps.clone();
        s.sort_by(f64::total_cmp);
        s[s.len() / 2]
    };
    let max_gap = 1.5 * median_step;
    let window = REPEAT_WINDOW_STEPS * median_step;
    let key = |b: &BoxPx| BoxGrid::key(b.center());
    // Per grid cell, the (frame, box) entries sorted by frame.
    let mut cells: std::collections::HashMap<(i64, i64), Vec<(f64, usize)>> =
        std::collections::HashMap::new();
    for (i, b) in boxes.iter().enumerate() {
        if let Some(f) = frames[i] {
            cells.entry(key(b)).or_default().push((f, i));
        }
    }
    for v in cells.values_mut() {
        v.sort_by(|a, b| a.0.total_cmp(&b.0));
    }
    // Boxes with a frame in [lo, hi] overlapping box `i` above `iou`, among those `keep`
    // accepts.
    let overlapping_in = |i: usize, lo: f64, hi: f64, keep: &dyn Fn(usize) -> bool| -> usize {
        let b = boxes[i];
        let (kx, ky) = key(&b);
        let rx = (b.width() / 2.0 / BoxGrid::CELL).ceil() as i64 + 1;
        let ry = (b.height() / 2.0 / BoxGrid::CELL).ceil() as i64 + 1;
        let mut count = 0;
        for gx in kx - rx..=kx + rx {
            for gy in ky - ry..=ky + ry {
                if let Some(v) = cells.get(&(gx, gy)) {
                    let start = v.partition_point(|e| e.0 < lo);
                    count += v[start..]
                        .iter()
                        .take_while(|e| e.0 <= hi)
                        .filter(|e| keep(e.1) && b.iou(&boxes[e.1]) > iou)
                        .count();
                }
            }
        }
        count
    };
    let frameless_set: Vec<bool> = frames.iter().map(Option::is_none).collect();
    let still_frameless = BoxGrid::new(boxes, |i| frameless_set[i]);
    let stationary: Vec<bool> = (0..n)
        .map(|i| match frames[i] {
            None => true,
            Some(f) => overlapping_in(i, f - max_gap, f + max_gap, &|j| frames[j] != Some(f)) > 0,
        })
        .collect();
    (0..n)
        .map(|i| {
            if !stationary[i] {
                return 1;
            }
            match frames[i] {
                None => still_frameless.overlapping(i, iou).count().max(1),
                Some(f) => overlapping_in(i, f - window, f + window, &|j| stationary[j]).max(1),
            }
        })
        .collect()
}

/// The physical vehicle each pair belongs to, numbered `0..n` (returned with `n`): the boxes
/// of one vehicle seen in consecutive frames (a track of the box tracker, [`tracks::link`])
/// share a number; a box without a frame or a valid box is a vehicle of its own.
///
/// The boxes of one vehicle are not independent evidence: the network and the edges see the
/// same car, the same way, frame after frame. Bootstraps resample vehicles, not boxes:
/// resampling the 20 boxes of each of three cars as 60 independent samples gave intervals
/// that left out the estimate of longer footage of the same camera (20 frames of a real
/// highway clip, issue 41).
pub fn vehicle_units(pairs: &[VehicleVps]) -> (Vec<usize>, usize) {
    let linked: Vec<(f64, BoxPx)> = pairs
        .iter()
        .map(|p| match (p.frame, p.box_px) {
            (Some(f), Some(b)) if f.is_finite() && b.is_valid() => (f, b),
            // Not linked by the tracker (it skips non-finite frames).
            _ => (f64::NAN, BoxPx::new(0.0, 0.0, 0.0, 0.0)),
        })
        .collect();
    let mut unit = vec![usize::MAX; pairs.len()];
    let mut n = 0;
    for track in tracks::link(&linked, &TrackOptions::default()) {
        for i in track {
            unit[i] = n;
        }
        n += 1;
    }
    for u in &mut unit {
        if *u == usize::MAX {
            *u = n;
            n += 1;
        }
    }
    (unit, n)
}

/// The rows of the usable `pairs`, each with its vehicle (`units`: [`vehicle_units`] of
/// `pairs`).
fn prepare(
    pairs: &[VehicleVps],
    units: &(Vec<usize>, usize),
    opts: &RobustOptions,
    image_h: f64,
) -> Prepared {
    let (pair_unit, units) = (&units.0, units.1);
    let mut boxes = Vec::new();
    let mut frames = Vec::new();
    let mut rows = Vec::new();
    let mut row_unit = Vec::new();
    for (p, u) in pairs.iter().zip(pair_unit) {
        if !p.is_ray(opts.min_score) {
            continue;
        }
        let Some(b) = p.box_px.filter(BoxPx::is_valid) else {
            continue;
        };
        let c = b.center();
        let (Some(d1), Some(d2)) = (unit(p.vp1 - c), unit(p.vp2 - c)) else {
            continue;
        };
        let s1 = p.vp1_spread.filter(|s| s.is_finite()).unwrap_or(10.0);
        boxes.push(b);
        frames.push(p.frame);
        row_unit.push(*u);
        rows.push((c, d1, d2.y.atan2(d2.x), s1, p.vp1, p.vp2));
    }
    let counts = repeat_counts(&boxes, &frames, opts.duplicate_iou);
    let threshold = (opts.min_box_fraction * image_h).max(1e-9);
    let mut out = Prepared {
        centre: Vec::with_capacity(rows.len()),
        dir1: Vec::with_capacity(rows.len()),
        angle2: Vec::with_capacity(rows.len()),
        vp1: Vec::with_capacity(rows.len()),
        vp2: Vec::with_capacity(rows.len()),
        weight: Vec::with_capacity(rows.len()),
        spread1: Vec::with_capacity(rows.len()),
        boxes: boxes.clone(),
        unit: row_unit,
        units,
        repeated: counts
            .iter()
            .filter(|c| **c as f64 > opts.duplicate_keep)
            .count(),
    };
    for ((c, d1, a2, s1, v1, v2), (b, count)) in rows.into_iter().zip(boxes.iter().zip(&counts)) {
        let size = (b.width() * b.height()).sqrt() / 2.0;
        let w_size = (size / threshold).min(1.0).powi(2);
        let w_dup = (opts.duplicate_keep / *count as f64).min(1.0);
        out.centre.push(c);
        out.dir1.push(d1);
        out.angle2.push(a2);
        out.vp1.push(v1);
        out.vp2.push(v2);
        out.weight.push(w_size * w_dup);
        out.spread1.push(1.0 / (s1 + 0.05));
    }
    out
}

/// Sine of the angle between line `i` (through `c` with direction `d`) and the direction from
/// `c` to the homogeneous point `p` (unit vector; `p[2] >= 0`; coordinates in units of
/// `SCALE` pixels).
const SCALE: f64 = 1000.0;

fn sin_angle(p: [f64; 3], c: Point2, d: Point2) -> f64 {
    let vx = p[0] - p[2] * c.x / SCALE;
    let vy = p[1] - p[2] * c.y / SCALE;
    let n = vx.hypot(vy);
    if n < 1e-15 {
        return 1.0;
    }
    (vx * d.y - vy * d.x) / n
}

fn sphere(q: [f64; 2]) -> [f64; 3] {
    let (st, ct) = q[0].sin_cos();
    let (sp, cp) = q[1].sin_cos();
    [cp * ct, cp * st, sp]
}

fn from_sphere(p: [f64; 3]) -> [f64; 2] {
    let n = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
    let (mut x, mut y, mut w) = (p[0] / n, p[1] / n, p[2] / n);
    if w < 0.0 {
        x = -x;
        y = -y;
        w = -w;
    }
    [y.atan2(x), w.clamp(-1.0, 1.0).asin()]
}

/// Lines that should meet at VP1: through `centre[i]` with unit direction `dir[i]` (the
/// network's per-vehicle VP1 rays, or the vehicles' tracks).
#[derive(Debug, Clone, Copy)]
struct LineSet<'a> {
    centre: &'a [Point2],
    dir: &'a [Point2],
}

/// Robust cost of VP1 candidate `q` (sphere parameters).
fn vp1_cost(q: [f64; 2], lines: LineSet, w: &[f64], s: f64) -> f64 {
    let p = sphere(q);
    lines
        .centre
        .iter()
        .zip(lines.dir)
        .zip(w)
        .map(|((c, d), w)| {
            let r = sin_angle(p, *c, *d) / s;
            w * (1.0 + r * r).ln()
        })
        .sum()
}

/// RANSAC over pairs of VP1 lines, then Nelder-Mead on the robust angular cost.
fn fit_vp1(
    lines_in: LineSet,
    w: &[f64],
    threshold_deg: f64,
    rng: &mut SplitMix,
    start: Option<[f64; 2]>,
) -> Option<[f64; 3]> {
    let n = lines_in.centre.len();
    if n < 2 {
        return None;
    }
    let s = threshold_deg.to_radians().sin();
    let q0 = match start {
        Some(q) => q,
        None => {
            // Lines in homogeneous form (scaled): l = (nx, ny, -n.c / SCALE).
            let lines: Vec<[f64; 3]> = lines_in
                .centre
                .iter()
                .zip(lines_in.dir)
                .map(|(c, d)| {
                    let (nx, ny) = (-d.y, d.x);
                    [nx, ny, -(nx * c.x + ny * c.y) / SCALE]
                })
                .collect();
            let total: f64 = w.iter().sum();
            if total <= 0.0 {
                return None;
            }
            let mut cum = Vec::with_capacity(n);
            let mut acc = 0.0;
            for x in w {
                acc += x;
                cum.push(acc);
            }
            let pick = |rng: &mut SplitMix| {
                let t = rng.next_f64() * total;
                cum.partition_point(|c| *c <= t).min(n - 1)
            };
            let mut best = (f64::NEG_INFINITY, None);
            for _ in 0..2000 {
                let (i, j) = (pick(rng), pick(rng));
                if i == j {
                    continue;
                }
                let p = crate::point::cross(lines[i], lines[j]);
                let norm = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
                if norm.is_nan() || norm <= 1e-12 {
                    continue;
                }
                let mut p = [p[0] / norm, p[1] / norm, p[2] / norm];
                if p[2] < 0.0 {
                    p = [-p[0], -p[1], -p[2]];
                }
                let score: f64 = lines_in
                    .centre
                    .iter()
                    .zip(lines_in.dir)
                    .zip(w)
                    .map(|((c, d), w)| {
                        let r = sin_angle(p, *c, *d) / s;
                        w * (1.0 - r * r).max(0.0)
                    })
                    .sum();
                if score > best.0 {
                    best = (score, Some(p));
                }
            }
            from_sphere(best.1?)
        }
    };
    let q = nelder_mead(
        |q| vp1_cost([q[0], q[1]], lines_in, w, s),
        &[q0[0], q0[1]],
        &[0.02, 0.02],
        VP1_ITERATIONS,
    )
    .x;
    Some(sphere([q[0], q[1]]))
}

/// The horizon model: VP1 (finite), pp, and the parameters (ln f, roll, bias).
#[derive(Clone, Copy)]
struct Vp2Model<'a> {
    vp1: Point2,
    pp: Point2,
    prep: &'a Prepared,
    opts: &'a RobustOptions,
    f0: f64,
    /// When set, the ray bias is this value rather than a parameter.
    fixed_bias: Option<f64>,
    /// When set, `ln f` is this value rather than a parameter (an assumed focal length).
    fixed_ln_f: Option<f64>,
    /// Whether the roll prior applies.
    roll_prior: bool,
}

impl Vp2Model<'_> {
    /// VP2 as a direction from VP1: `VP2 = VP1 + h / u`, returning `(h, u)`.
    fn vp2(&self, ln_f: f64, roll: f64) -> (Point2, f64) {
        edge::vp2_direction(self.vp1, self.pp, ln_f, roll)
    }

    fn cost(&self, x: &[f64], w: &[f64]) -> f64 {
        let (h, u) = self.vp2(self.fixed_ln_f.unwrap_or(x[0]), x[1]);
        let predicted: Vec<f64> = self
            .prep
            .centre
            .iter()
            .map(|c| {
                let d = (self.vp1 - *c) * u + h;
                d.y.atan2(d.x)
            })
            .collect();
        self.cost_with(x, w, &predicted)
    }

    /// The cost with the predicted ray angles (from the centres towards VP2) given.
    fn cost_with(&self, x: &[f64], w: &[f64], predicted: &[f64]) -> f64 {
        let roll = x[1];
        let bias = self.fixed_bias.unwrap_or(x[2]);
        let s = self.opts.ray_scale_deg.to_radians();
        let mut c = 0.0;
        let mut total = 0.0;
        for ((a, p), w) in self.prep.angle2.iter().zip(predicted).zip(w) {
            total += w;
            if *w == 0.0 {
                continue;
            }
            let r = line_angle_diff(a - p - bias) / s;
            c += w * if self.fixed_bias.is_some() {
                geman_mcclure(r)
            } else {
                (1.0 + r * r).ln()
            };
        }
        let k = total * self.opts.prior_weight;
        let sq = |v: f64, sd: f64| 0.5 * (v / sd) * (v / sd);
        if self.roll_prior {
            c += k * sq(roll.to_degrees(), self.opts.roll_prior_sigma_deg);
        }
        c += k * sq(bias.to_degrees(), self.opts.ray_bias_prior_sigma_deg);
        c
    }

    /// Coarse grid over (ln f, roll, bias) then Nelder-Mead.
    fn fit(&self, w: &[f64], start: Option<[f64; 3]>) -> [f64; 3] {
        let x0 = match start {
            Some(s) => s,
            None => {
                let [lo_w, hi_w] = HORIZON_FOCAL_GRID_WIDTHS;
                let lo = (lo_w * self.f0 / self.opts.focal_prior_ratio).max(1.0).ln();
                let hi = (hi_w * self.f0 / self.opts.focal_prior_ratio).ln();
                let roll_max = if self.roll_prior {
                    (3.0 * self.opts.roll_prior_sigma_deg).min(10.0)
                } else {
                    10.0
                }
                .to_radians();
                let bias_max = (3.0 * self.opts.ray_bias_prior_sigma_deg)
                    .min(15.0)
                    .to_radians();
                let (n_roll, n_bias) = if self.fixed_bias.is_some() {
                    (21, 1)
                } else {
                    (9, 13)
                };
                let mut best = (f64::INFINITY, [self.f0.ln(), 0.0, 0.0]);
                let mut predicted = vec![0.0; self.prep.centre.len()];
                let n_f = if self.fixed_ln_f.is_some() { 1 } else { 48 };
                for i in 0..n_f {
                    let ln_f = self.fixed_ln_f.unwrap_or(lo + (hi - lo) * i as f64 / 47.0);
                    for j in 0..n_roll {
                        let roll = -roll_max + 2.0 * roll_max * j as f64 / (n_roll - 1) as f64;
                        // The ray directions depend on (f, roll) only; the bias loop reuses them.
                        let (h, u) = self.vp2(ln_f, roll);
                        for (p, c) in predicted.iter_mut().zip(&self.prep.centre) {
                            let d = (self.vp1 - *c) * u + h;
                            *p = d.y.atan2(d.x);
                        }
                        for k in 0..n_bias {
                            let bias = match self.fixed_bias {
                                Some(b) => b,
                                None => -bias_max + 2.0 * bias_max * k as f64 / (n_bias - 1) as f64,
                            };
                            let x = [ln_f, roll, bias];
                            let c = self.cost_with(&x, w, &predicted);
                            if c < best.0 {
                                best = (c, x);
                            }
                        }
                    }
                }
                best.1
            }
        };
        let x = nelder_mead(
            |x| self.cost(x, w),
            &x0,
            &[0.05, 0.2f64.to_radians(), 0.3f64.to_radians()],
            HORIZON_ITERATIONS,
        )
        .x;
        [self.fixed_ln_f.unwrap_or(x[0]), x[1], x[2]]
    }
}

/// The focal length the VP2 *points* imply with VP1 fixed: the weighted median of
/// `-(vp1 - pp)·(vp2_i - pp)` (negative values included, so imaginary pairs do not bias it),
/// square-rooted; `None` when that median is not positive.
fn points_focal(prep: &Prepared, w: &[f64], vp1: Point2, pp: Point2) -> Option<f64> {
    let mut v: Vec<(f64, f64)> = prep
        .vp2
        .iter()
        .zip(w)
        .map(|(p, w)| (-(vp1 - pp).dot(*p - pp), *w))
        .filter(|(x, w)| x.is_finite() && *w > 0.0)
        .collect();
    let values: Vec<f64> = v.iter().map(|x| x.0).collect();
    let weights: Vec<f64> = v.drain(..).map(|x| x.1).collect();
    let m = crate::metrics::weighted_median(&values, &weights)?;
    (m > 0.0).then(|| m.sqrt())
}

/// The systematic error of the VP2 that a network's rays give, as a multiple of the rays'
/// scatter around it (their weighted median angle, at least [`RAY_MIN_SCATTER_DEG`]): a
/// network's VP2 error is mostly common to the view, so the rays' agreement is no measure of
/// it, but networks whose rays scatter more also err more. Measured on two sources, the
/// rays' likelihood taken into the focal posterior (`super::focal`):
/// - BrnoCompSpeed sessions 0-3, the three public CNNs' VPout files against
///   `camera_truth.json` (`scripts/focal_coverage.py`; these CNNs put VP2 too near): with 5
///   the rays measured f on 21 of 35 videos, their intervals holding the reference for 57 %
///   (median focal error 20.7 %); with 8 on 12, holding it for 83 % (9.0 %).
/// - The synthetic suite with the bundled network (true boxes, 100 frames; this network puts
///   VP2 too far): at 5 the truth lay 0.6-1.8 standard errors from the rays' posterior,
///   always on the near side; at 8 within about one, and the rays no longer pulled the
///   edgelets' focal length off the truth (synth02 +15 % with 5, +7 % with 8).
pub const RAY_SYSTEMATIC_PER_SCATTER: f64 = 8.0;

/// The scatter below which the rays' systematic error is not taken to shrink, degrees: rays
/// that agree more closely than this still share a common error of about
/// [`RAY_SYSTEMATIC_PER_SCATTER`] times it. Measured with 1° and with 2°:
/// - BrnoCompSpeed sessions 0-3, the public CNNs' VPout (`scripts/focal_coverage.py`): with 1°
///   the rays measured f on 12 of 35 videos and their intervals held the reference on 10;
///   with 2° on 5, holding it on all 5, and the median focal error of all 35 fell from 13.7 %
///   to 11.5 % (pooled ratio error 12.38 / 10.22 / 9.81 % to 11.00 / 10.22 / 8.71 %).
/// - The six synthetic speed scenes (docs/accuracy.md §8; true boxes and the motion
///   detector, the bundled network): its rays scatter 0.5-1.1° and place f 0.99-2.83 times
///   the truth (median 1.6); with 1° they pulled the edgelets' focal length (0.94-1.00 of the
///   truth) to 1.07-1.14 on 7 of 12 calibrations, and 4 of the rays' own intervals held the
///   truth; with 2° the fused focal error's median fell from 10 % to 2.5 %.
/// - The bundled network's per-vehicle VP2 turns towards VP1 on KITTI's real cars (median
///   +1.7° clean, +2.5° others: `vpcal eval kitti --all`), which would make f short, while on
///   the renders its rays make f long: its common error changes sign with the domain, so it
///   is widened, not corrected.
pub const RAY_MIN_SCATTER_DEG: f64 = 2.0;

/// An edgelet VP2 farther than this many image widths from the principal point says the
/// edges across the vehicles are parallel in the image (f > 100 widths is a 0.6° view: no
/// traffic camera): the view looks almost straight down, or VP1 and VP2 cannot both be
/// placed, and the focal length is not observable.
pub const PARALLEL_EDGES_VP2_WIDTHS: f64 = 100.0;

/// The focal length's distribution given the network's VP2 rays and the physical prior:
/// [`rays_focal_likelihood`] within the prior uniform in `ln f` over `range_px`. Returns the
/// 16th, 50th and 84th percentiles, pixels; `None` when the rays' fit is not finite.
pub fn rays_focal_posterior(
    vp1: Point2,
    pp: Point2,
    range_px: [f64; 2],
    rays: [f64; 2],
    sd_deg: f64,
) -> Option<[f64; 3]> {
    let l = rays_focal_likelihood(vp1, pp, focal::support(range_px), rays, sd_deg)?;
    focal::alone(range_px, &l)
}

/// What the network's VP2 rays say about the focal length: `(ln f, roll)` is what the rays
/// alone fit (with VP1 at `vp1`), `sd_deg` the systematic error of the VP2 they place. For a
/// candidate `f`, the VP2 orthogonal to VP1 on the rays' horizon is compared with the rays'
/// VP2 as directions seen through a lens of that focal length; the likelihood is Gaussian in
/// that angle, tabulated over `range_px` (`[short, long]` focal lengths, pixels). `None` when
/// the rays' fit is not finite.
///
/// The angle, not `ln f`, carries the error because a network errs by angles: a VP2 far
/// along the horizon moves a long way for a small angle, so the same rays say little about f
/// there (a telephoto view) and much where VP2 is near (a wide view).
pub fn rays_focal_likelihood(
    vp1: Point2,
    pp: Point2,
    range_px: [f64; 2],
    rays: [f64; 2],
    sd_deg: f64,
) -> Option<Likelihood> {
    let [ln_fr, roll] = rays;
    let [short, long] = range_px;
    if !(ln_fr.is_finite() && roll.is_finite() && sd_deg > 0.0 && 0.0 < short && short < long) {
        return None;
    }
    let v = vp1 - pp;
    // VP2 = VP1 + h / u, seen as a direction through a lens of focal length f.
    let direction = |(h, u): (Point2, f64), f: f64| {
        let p = v * u + h;
        [p.x, p.y, u * f]
    };
    let angle = |a: [f64; 3], b: [f64; 3]| {
        let dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let na = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
        let nb = (b[0] * b[0] + b[1] * b[1] + b[2] * b[2]).sqrt();
        (dot.abs() / (na * nb)).min(1.0).acos()
    };
    let rays_vp2 = edge::vp2_direction(vp1, pp, ln_fr, roll);
    let (lo, hi) = (short.ln(), long.ln());
    let s = sd_deg.to_radians();
    let ln_f: Vec<f64> = (0..=focal::GRID)
        .map(|i| lo + (hi - lo) * i as f64 / focal::GRID as f64)
        .collect();
    let log_lik: Vec<f64> = ln_f
        .iter()
        .map(|&ln_f| {
            let f = ln_f.exp();
            let here = edge::vp2_direction(vp1, pp, ln_f, roll);
            let d = angle(direction(rays_vp2, f), direction(here, f)) / s;
            -0.5 * d * d
        })
        .collect();
    log_lik
        .iter()
        .all(|l| l.is_finite())
        .then(|| Likelihood::Table {
            ln_f,
            log_lik,
            own_px: ln_fr.exp(),
        })
}

/// What the VP2 rays alone say about the focal length.
#[derive(Debug, Clone)]
struct RaysFocal {
    /// Their own fit, `(ln f, roll)`.
    fit: [f64; 2],
    /// The weighted median angle of the rays around that fit, and the systematic error
    /// taken for their VP2 from it, degrees.
    scatter_deg: f64,
    sd_deg: f64,
    /// Their likelihood of `ln f` ([`rays_focal_likelihood`], tabulated over all of the
    /// focal posterior's grid, past the band's soft edges), and its percentiles with the
    /// prior alone ([`rays_focal_posterior`]).
    likelihood: Option<Likelihood>,
    posterior: Option<[f64; 3]>,
}

/// The untrusted rays' likelihood ([`rays_focal_likelihood`]).
impl FocalSource for RaysFocal {
    fn name(&self) -> &'static str {
        "network_rays"
    }

    fn likelihood(&self) -> Option<Likelihood> {
        self.likelihood.clone()
    }
}

/// What the VP2 rays alone say about the focal length under `model` (its VP1, no priors, no
/// ray bias).
fn rays_focal(model: &Vp2Model, w: &[f64], range_px: [f64; 2]) -> RaysFocal {
    let free = Vp2Model {
        fixed_bias: Some(0.0),
        fixed_ln_f: None,
        roll_prior: false,
        ..*model
    };
    let x = free.fit(w, None);
    let (h, u) = free.vp2(x[0], x[1]);
    let (angles, weights): (Vec<f64>, Vec<f64>) = model
        .prep
        .centre
        .iter()
        .zip(&model.prep.angle2)
        .zip(w)
        .filter(|(_, w)| **w > 0.0)
        .map(|((c, a), w)| {
            let d = (model.vp1 - *c) * u + h;
            (line_angle_diff(a - d.y.atan2(d.x)).abs().to_degrees(), *w)
        })
        .unzip();
    let scatter = crate::metrics::weighted_median(&angles, &weights).unwrap_or(f64::NAN);
    let sd = RAY_SYSTEMATIC_PER_SCATTER * scatter.max(RAY_MIN_SCATTER_DEG);
    let support = focal::support(range_px);
    let likelihood = scatter
        .is_finite()
        .then(|| rays_focal_likelihood(model.vp1, model.pp, support, [x[0], x[1]], sd))
        .flatten();
    let posterior = likelihood.as_ref().and_then(|l| focal::alone(range_px, l));
    RaysFocal {
        fit: [x[0], x[1]],
        scatter_deg: scatter,
        sd_deg: sd,
        likelihood,
        posterior,
    }
}

/// Fit (ln f, roll, bias) for `model` with vehicle weights `w` (`w1` for the VP1 lines);
/// returns VP1 (refined when the rays are trusted), the parameters, and whether the rays were
/// trusted.
///
/// When the VP2 *points* agree with what the VP2 rays alone say (a network without the
/// distance bias of the public CNNs), the data are trusted: the focal and roll priors are
/// dropped, the ray bias is fixed at zero, and VP1, f and the roll are refined jointly on the
/// VP1 lines and VP2 rays. Real CNNs that put VP2 far too close fail this check; then the
/// focal length is held at `model.f0` (the prior's median, or the rays' posterior median
/// once [`rays_focal`] measured it; not fitted here: with a free ray bias the rays' pull on
/// `f` made it worse both on the public CNNs' BrnoCompSpeed outputs and on the synthetic
/// demo) and the roll and ray bias are fitted under their priors.
fn fit_camera(
    model: &Vp2Model,
    vp1_lines: &Vp1Lines,
    w1: &[f64],
    w: &[f64],
    start: Option<[f64; 3]>,
) -> (Point2, [f64; 3], bool) {
    let unbiased = Vp2Model {
        fixed_bias: Some(0.0),
        roll_prior: false,
        ..*model
    };
    let x_rays = unbiased.fit(w, start.map(|s| [s[0], s[1], 0.0]));
    let f_points = points_focal(model.prep, w, model.vp1, model.pp);
    let trusted =
        f_points.is_some_and(|fp| (fp.ln() - x_rays[0]).abs() < model.opts.consistency_log_ratio);
    let assumed = Vp2Model {
        fixed_ln_f: Some(model.f0.ln()),
        ..*model
    };
    if !trusted {
        return (model.vp1, assumed.fit(w, start), false);
    }
    let s1 = vp1_lines.threshold_deg.to_radians().sin();
    let q1 = from_sphere([model.vp1.x / SCALE, model.vp1.y / SCALE, 1.0]);
    let joint = |p: &[f64]| {
        let sp = sphere([p[0], p[1]]);
        if sp[2] <= 1e-9 {
            return f64::INFINITY;
        }
        let vp1 = Point2::new(sp[0] / sp[2] * SCALE, sp[1] / sp[2] * SCALE);
        let m = Vp2Model { vp1, ..unbiased };
        vp1_cost([p[0], p[1]], vp1_lines.lines(), w1, s1) + m.cost(&[p[2], p[3], 0.0], w)
    };
    let p = nelder_mead(
        joint,
        &[q1[0], q1[1], x_rays[0], x_rays[1]],
        &[0.002, 0.002, 0.02, 0.1f64.to_radians()],
        JOINT_ITERATIONS,
    )
    .x;
    let sp = sphere([p[0], p[1]]);
    let vp1 = Point2::new(sp[0] / sp[2] * SCALE, sp[1] / sp[2] * SCALE);
    if !(sp[2] > 1e-9 && vp1.is_finite()) {
        return (model.vp1, assumed.fit(w, start), false);
    }
    (vp1, [p[2], p[3], 0.0], true)
}

/// Total weight of the points on the other side of `horizon` than the image's bottom, seen
/// from the principal point's column.
fn weight_above_horizon(centres: &[Point2], weights: &[f64], horizon: Line, pp: Point2) -> f64 {
    let side = |p: Point2| horizon.signed_distance(p).map(f64::signum);
    let below = side(Point2::new(pp.x, pp.y + 1e7));
    centres
        .iter()
        .zip(weights)
        .filter(|(c, _)| side(**c) != below)
        .map(|(_, w)| w)
        .sum()
}

/// Nelder-Mead budgets of the fits, by their number of parameters: VP1 on the sphere (2),
/// the horizon model (ln f, roll, ray bias: 3), and VP1 with the horizon jointly (4).
const VP1_ITERATIONS: usize = 300;
const HORIZON_ITERATIONS: usize = 400;
const JOINT_ITERATIONS: usize = 600;

/// Focal lengths the horizon model's grid spans, in image widths: 0.15 (a 147° view) to 15 (a
/// 4° view), beyond the physical range of traffic cameras so that the VP2 evidence (or the
/// prior), not the grid, bounds the fit.
const HORIZON_FOCAL_GRID_WIDTHS: [f64; 2] = [0.15, 15.0];

/// Fewer VP1 lines than this within the threshold of VP1 is "not enough evidence".
const MIN_VP1_INLIERS: usize = 5;

/// A curved road's track tangents span this many boxes before and after each box.
const CURVE_TANGENT_HALF: usize = 4;

/// The lines VP1 is fitted to, with their weights and the Cauchy scale of their angles.
#[derive(Debug, Clone)]
struct Vp1Lines {
    centre: Vec<Point2>,
    dir: Vec<Point2>,
    weight: Vec<f64>,
    threshold_deg: f64,
    /// Tracks (true) or the network's per-vehicle rays (false).
    from_tracks: bool,
}

impl Vp1Lines {
    fn lines(&self) -> LineSet<'_> {
        LineSet {
            centre: &self.centre,
            dir: &self.dir,
        }
    }

    /// Weighted median of the angles between the lines and the directions to `p`, degrees.
    fn median_residual_deg(&self, p: [f64; 3]) -> Option<f64> {
        let angles: Vec<f64> = self
            .centre
            .iter()
            .zip(&self.dir)
            .map(|(c, d)| sin_angle(p, *c, *d).abs().min(1.0).asin().to_degrees())
            .collect();
        crate::metrics::weighted_median(&angles, &self.weight)
    }

    /// Lines within the threshold angle of the homogeneous point `p` (sphere form).
    fn inliers(&self, p: [f64; 3]) -> usize {
        let s = self.threshold_deg.to_radians().sin();
        self.centre
            .iter()
            .zip(&self.dir)
            .filter(|(c, d)| sin_angle(p, **c, **d).abs() < s)
            .count()
    }
}

impl Prepared {
    /// The network's VP1 rays, weighted by the vehicle weight and the decoder spread.
    fn network_vp1_lines(&self, threshold_deg: f64) -> Vp1Lines {
        Vp1Lines {
            centre: self.centre.clone(),
            dir: self.dir1.clone(),
            weight: self
                .weight
                .iter()
                .zip(&self.spread1)
                .map(|(a, b)| a * b)
                .collect(),
            threshold_deg,
            from_tracks: false,
        }
    }
}

/// VP1 as a homogeneous point `[x, y, w]` (units of `SCALE` pixels) in frame pixels, when
/// finite.
fn vp1_of(p: [f64; 3]) -> Option<Point2> {
    let v = Point2::new(p[0] / p[2] * SCALE, p[1] / p[2] * SCALE);
    (p[2] > 1e-9 && v.is_finite()).then_some(v)
}

/// VP1 from the network's per-vehicle lines: RANSAC, and a second start from the weighted
/// median of the VP1 points; the better finite solution wins (RANSAC alone can settle in a
/// poor basin when the lines are nearly parallel).
fn locate_vp1_from_network(
    lines: &Vp1Lines,
    prep: &Prepared,
    pp: Point2,
    width: f64,
    rng: &mut SplitMix,
) -> Option<[f64; 3]> {
    let (w, t) = (&lines.weight, lines.threshold_deg);
    let mut p1 = fit_vp1(lines.lines(), w, t, rng, None)?;
    let xs: Vec<f64> = prep.vp1.iter().map(|v| v.x).collect();
    let ys: Vec<f64> = prep.vp1.iter().map(|v| v.y).collect();
    if let (Some(mx), Some(my)) = (
        crate::metrics::weighted_median(&xs, w),
        crate::metrics::weighted_median(&ys, w),
    ) {
        let start = from_sphere([mx / SCALE, my / SCALE, 1.0]);
        let s = t.to_radians().sin();
        if let Some(alt) = fit_vp1(lines.lines(), w, t, rng, Some(start)) {
            let cost = |p: [f64; 3]| vp1_cost(from_sphere(p), lines.lines(), w, s);
            let finite = |p: [f64; 3]| vp1_of(p).is_some_and(|v| (v - pp).norm() < 20.0 * width);
            if finite(alt) && (!finite(p1) || cost(alt) < cost(p1)) {
                p1 = alt;
            }
        }
    }
    Some(p1)
}

/// How many of the track lines bend with `|bend_t| > min_t` and `|bend_deg| > min_deg`
/// towards the same side (the larger count of the two sides), the lines' directions first
/// oriented alike (doubled-angle mean).
fn bending_the_same_way(lines: &[TrackLine], min_t: f64, min_deg: f64) -> usize {
    let (c, s) = lines.iter().fold((0.0, 0.0), |(c, s), t| {
        let a = 2.0 * t.dir.y.atan2(t.dir.x);
        (c + a.cos(), s + a.sin())
    });
    let mean = 0.5 * f64::atan2(s, c);
    let reference = Point2::new(mean.cos(), mean.sin());
    let (mut left, mut right) = (0, 0);
    for t in lines {
        let sign = if t.dir.dot(reference) >= 0.0 {
            1.0
        } else {
            -1.0
        };
        let (bt, bd) = (sign * t.bend_t, sign * t.bend_deg);
        if bt > min_t && bd > min_deg {
            left += 1;
        } else if bt < -min_t && bd < -min_deg {
            right += 1;
        }
    }
    left.max(right)
}

/// The (frame, box) of every pair the tracker may use: a box, a frame and a score above the
/// threshold (its VPs do not matter).
fn tracked_boxes(pairs: &[VehicleVps], opts: &RobustOptions) -> (Vec<(f64, BoxPx)>, Vec<usize>) {
    pairs
        .iter()
        .enumerate()
        .filter(|(_, p)| p.score > opts.min_score)
        .filter_map(|(i, p)| Some(((p.frame?, p.box_px.filter(BoxPx::is_valid)?), i)))
        .unzip()
}

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
    aggregate_with_scene(pairs, edgelets, &[], pp, opts)
}

/// [`aggregate_with_edgelets`], with the edgelets of the scene's background (`scene`, frame
/// pixels; empty: none): with `opts.scene_lines` set and a straight road, VP1 moves to where
/// the scene's lines along the road meet ([`scene_lines`]) while the vehicles' VP1 evidence
/// agrees (`opts.scene_max_extra_deg`).
///
/// # Errors
/// As [`aggregate`].
///
/// # Panics
/// As [`aggregate_with_edgelets`].
pub fn aggregate_with_scene(
    pairs: &[VehicleVps],
    edgelets: &[Vec<Edgelet>],
    scene: &[Edgelet],
    pp: Point2,
    opts: &RobustOptions,
) -> Result<RobustResult, AggregateError> {
    assert!(
        edgelets.is_empty() || edgelets.len() == pairs.len(),
        "{} edgelet lists for {} pairs",
        edgelets.len(),
        pairs.len()
    );
    let [width, height] = opts.image_size.unwrap_or([2.0 * pp.x, 2.0 * pp.y]);
    let not_enough = |m: String| AggregateError::NotEnoughEvidence(m);
    if !(width > 0.0 && height > 0.0 && pp.is_finite()) {
        return Err(not_enough(format!(
            "invalid image size {width}x{height} or principal point {pp}"
        )));
    }
    // Each pair's physical vehicle, for the bootstraps of the fits and of the edgelets.
    let vehicles = vehicle_units(pairs);
    let full = prepare(pairs, &vehicles, opts, height);
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
    let prep = full.thinned(opts.max_fit_vehicles);
    let mut rng = SplitMix(opts.seed ^ 0x5EED_CA1B);
    let (tracked_boxes, tracked_pairs) = tracked_boxes(pairs, opts);
    let links = opts
        .tracks
        .as_ref()
        .map_or_else(Vec::new, |t| tracks::link(&tracked_boxes, t));
    // Every track long enough, straight or not (a curve's tracks are the evidence that the
    // road curves), and the straight ones, which are VP1 evidence.
    let (moving, track_lines): (Vec<TrackLine>, Vec<TrackLine>) = match &opts.tracks {
        Some(t) => {
            let any_shape = TrackOptions {
                max_rms_fraction: f64::INFINITY,
                frame: Some([width, height]),
                ..t.clone()
            };
            let moving: Vec<TrackLine> = links
                .iter()
                .filter_map(|l| tracks::fit_line(&tracked_boxes, l, &any_shape))
                .collect();
            let straight = moving
                .iter()
                .filter(|l| l.is_straight(t))
                .copied()
                .collect();
            (moving, straight)
        }
        None => (Vec::new(), Vec::new()),
    };
    let network_lines = prep.network_vp1_lines(opts.vp1_threshold_deg);
    let network = locate_vp1_from_network(&network_lines, &prep, pp, width, &mut rng);
    // Residuals and inliers are counted on every vehicle, not only the thinned ones the fit
    // used.
    let all_network = full.network_vp1_lines(opts.vp1_threshold_deg);
    let network_scatter = network.and_then(|p| all_network.median_residual_deg(p));
    // VP1 from the tracks alone, when there are enough of them and they agree.
    let tracked = (track_lines.len() >= opts.min_track_lines)
        .then(|| {
            let lines = Vp1Lines {
                centre: track_lines.iter().map(|t| t.point).collect(),
                dir: track_lines.iter().map(|t| t.dir).collect(),
                weight: vec![1.0; track_lines.len()],
                threshold_deg: opts.track_threshold_deg,
                from_tracks: true,
            };
            let t = lines.threshold_deg;
            let p1 = fit_vp1(lines.lines(), &lines.weight, t, &mut rng, None)?;
            let inliers = lines.inliers(p1);
            let residual = lines.median_residual_deg(p1)?;
            (vp1_of(p1).is_some() && inliers >= MIN_VP1_INLIERS)
                .then_some((lines, p1, inliers, residual))
        })
        .flatten();
    let track_residual = tracked.as_ref().map(|t| t.3);
    let telling: Vec<TrackLine> = moving
        .iter()
        .filter(|l| l.bend_se_deg < opts.curved_max_se_deg)
        .copied()
        .collect();
    let curved_tracks = bending_the_same_way(&telling, opts.curved_bend_t, opts.curved_bend_deg);
    let road_curved = curved_tracks >= opts.min_curved_tracks.max(1)
        && curved_tracks as f64 >= opts.curved_share * telling.len() as f64;
    let use_tracks = match (&tracked, network_scatter) {
        _ if road_curved => false,
        (None, _) => false,
        (Some(_), None) => true,
        (Some(t), Some(scatter)) => {
            scatter > opts.track_above_scatter_deg || t.3 < opts.track_residual_ratio * scatter
        }
    };
    let from_tracks = tracked
        .filter(|_| use_tracks)
        .map(|(lines, p1, inliers, _)| (lines, p1, inliers));
    let (vp1_lines, p1, vp1_inliers) = match from_tracks {
        Some(found) => found,
        None => {
            let p1 = network.ok_or_else(|| not_enough("the VP1 lines do not intersect".into()))?;
            let inliers = all_network.inliers(p1);
            (network_lines, p1, inliers)
        }
    };
    let vp1 = vp1_of(p1).ok_or_else(|| {
        not_enough(
            "VP1 lies at infinity (the road runs parallel to the image plane); \
             a finite VP1 is needed for a BrnoCompSpeed-style calibration"
                .into(),
        )
    })?;
    if vp1_inliers < MIN_VP1_INLIERS {
        return Err(not_enough(format!(
            "only {vp1_inliers} vehicles agree on a VP1 (within {}°)",
            opts.vp1_threshold_deg
        )));
    }
    let f0 = opts.focal_prior_ratio * width;
    let model = Vp2Model {
        vp1,
        pp,
        prep: &prep,
        opts,
        f0,
        fixed_bias: None,
        fixed_ln_f: None,
        roll_prior: true,
    };
    let (vp1, x, rays_trusted) =
        fit_camera(&model, &vp1_lines, &vp1_lines.weight, &prep.weight, None);
    // The vehicles with edgelets, for both edgelet fits.
    let pair_unit = &vehicles.0;
    let boxes: Vec<BoxEdgelets> = pairs
        .iter()
        .zip(edgelets)
        .zip(pair_unit)
        .filter(|((p, e), _)| p.score > opts.min_score && !e.is_empty())
        .filter_map(|((p, e), u)| {
            Some(BoxEdgelets {
                centre: p.box_px.filter(BoxPx::is_valid)?.center(),
                vp1: p.vp1,
                vp2: p.vp2,
                edgelets: e,
                vehicle: *u,
            })
        })
        .collect();
    let edge_opts = opts.edgelets.as_ref().filter(|_| !boxes.is_empty());
    // Without tracks, the edgelets along the vehicles place VP1 better than the network's
    // VP1 rays (module docs of `edgelets`).
    let edge_vp1 = edge_opts
        .filter(|_| !vp1_lines.from_tracks)
        .and_then(|eo| edge::fit_vp1(vp1, &boxes, eo));
    let vp1 = edge_vp1.map_or(vp1, |e| e.0);
    // The scene's lines along the road place VP1 better than the vehicles (module docs of
    // `scene_lines`), where the vehicles still agree with the point they give.
    let scene_opts = opts
        .scene_lines
        .as_ref()
        .filter(|_| !road_curved && !scene.is_empty());
    let scene_fit = scene_opts.and_then(|so| scene_lines::refine_vp1(vp1, scene, so));
    let residual_at = |v: Point2| vp1_lines.median_residual_deg([v.x / SCALE, v.y / SCALE, 1.0]);
    let scene_extra = scene_fit.and_then(|f| Some(residual_at(f.vp1)? - residual_at(vp1)?));
    let scene_vp1 =
        scene_fit.filter(|_| scene_extra.is_some_and(|x| x <= opts.scene_max_extra_deg));
    let scene_shift = scene_vp1.map(|f| (f.vp1 - vp1).norm());
    let vp1 = scene_vp1.map_or(vp1, |f| f.vp1);
    let model = Vp2Model { vp1, ..model };
    // Rays the VP2 points contradict still say something about f where VP2 is near: their
    // likelihood over ln f (`rays_focal_likelihood`) is one cue of the focal posterior.
    let range_px = focal_prior_range_widths(opts.focal_range_widths).map(|r| r * width);
    let rays = (!rays_trusted).then(|| rays_focal(&model, &prep.weight, range_px));
    let posterior = rays.as_ref().and_then(|r| r.posterior);
    // The edges across the vehicles, where they say those edges are parallel in the image
    // (a view looking almost straight down), contradict rays that place VP2 near.
    let edge_fit = edge_opts.and_then(|eo| edge::fit(vp1, pp, width, &boxes, x[1], eo, opts.seed));
    let edges_parallel = edge_fit.is_some_and(|e| {
        let w = (e.vp2 - pp).norm() / width;
        w.is_nan() || w > PARALLEL_EDGES_VP2_WIDTHS
    });
    let usable = edge_fit.filter(|e| e.roll_usable);
    let mut x = x;
    if let Some(e) = usable {
        x[1] = e.roll;
    }
    // On a curved road every car has its own VP1 on the horizon: fit the horizon and the
    // focal length to the cars' track tangents and edgelets together.
    let curved_fit = edge_opts.filter(|_| road_curved).and_then(|eo| {
        let tangents = tracks::tangents(&tracked_boxes, &links, CURVE_TANGENT_HALF, 3.0);
        let vehicles: Vec<CurvedVehicle> = tangents
            .iter()
            .zip(&tracked_pairs)
            .filter_map(|(t, &i)| {
                let e = edgelets.get(i)?;
                (!e.is_empty()).then_some(CurvedVehicle {
                    tangent: (*t)?,
                    edgelets: e,
                    vehicle: pair_unit[i],
                })
            })
            .collect();
        edge::fit_curved(pp, width, height, &vehicles, x[1], eo, opts.seed)
    });
    let (model, vp1) = match curved_fit {
        Some(c) => {
            x[1] = c.roll;
            (
                Vp2Model {
                    vp1: c.vp1,
                    ..model
                },
                c.vp1,
            )
        }
        None => (model, vp1),
    };
    // The bootstrap's resamples: the focal lengths of trusted rays, the horizon and VP1.
    let samples = (opts.bootstrap > 0).then(|| {
        bootstrap(
            &model,
            &prep,
            &vp1_lines,
            p1,
            x,
            scene_vp1.and(scene_opts).map(|so| (scene, so)),
            opts.bootstrap,
            &mut rng,
        )
    });
    // The focal length's cues (`super::focal`), each where its model holds: on a curved road
    // only the curved fit (every car has its own VP2, so neither the rays nor the straight
    // edgelet fit apply); the rays and the edges across the vehicles not where those edges
    // are parallel in the image (a view straight down, where f cannot be observed).
    let trusted = rays_trusted.then(|| {
        let fs = samples.as_ref().map_or(&[][..], |s| &s.focal_px[..]);
        let bootstrap_px = if fs.len() >= 2 {
            [percentile(fs.to_vec(), 16.0), percentile(fs.to_vec(), 84.0)]
        } else {
            [1.0, 1.0]
        };
        focal::Measured {
            name: "network",
            focal_px: x[0].exp(),
            bootstrap_px,
            turn: 0.0,
        }
    });
    let sources: Vec<&dyn FocalSource> = match &curved_fit {
        Some(c) => vec![c],
        None if !road_curved && !edges_parallel => {
            let edges = usable.as_ref().map(|e| e as &dyn FocalSource);
            let trusted = trusted.as_ref().map(|t| t as &dyn FocalSource);
            let rays = rays.as_ref().map(|r| r as &dyn FocalSource);
            [edges, trusted, rays].into_iter().flatten().collect()
        }
        None => Vec::new(),
    };
    let cues = focal::cues_of(&sources);
    let focal = focal::fuse(range_px, &cues)
        .ok_or_else(|| not_enough(format!("invalid focal range {range_px:?} px")))?;
    let carried = |s: &str| focal.carried_by.contains(&s);
    let curved_focal = carried("curved_edgelets");
    let focal_from_rays = carried("network_rays");
    // Where f moved off the value the VP2 model held, the roll and the rays' bias are
    // refitted with f held there (unless the edgelets set the roll).
    let model = Vp2Model {
        f0: focal.focal_px,
        ..model
    };
    if focal.measured && !rays_trusted && usable.is_none() && curved_fit.is_none() {
        x = Vp2Model {
            fixed_ln_f: Some(focal.focal_px.ln()),
            ..model
        }
        .fit(&prep.weight, Some([focal.focal_px.ln(), x[1], x[2]]));
    }
    x[0] = focal.focal_px.ln();
    let (h, u) = model.vp2(x[0], x[1]);
    let vp2 = vp1 + h / u;
    let calibration = Calibration::from_vps(vp1, vp2, pp)
        .map_err(|e| not_enough(format!("the estimate is not a valid camera: {e}")))?;
    let above =
        weight_above_horizon(&full.centre, &full.weight, calibration.horizon, pp) / effective;
    if above > opts.max_above_horizon {
        return Err(not_enough(format!(
            "the estimated horizon runs through the traffic: {:.0} % of the vehicle weight lies \
             above it (at most {:.0} % allowed); the per-vehicle VPs do not agree on a camera",
            100.0 * above,
            100.0 * opts.max_above_horizon
        )));
    }
    // The vehicles' sizes must grow away from the horizon (`super::sizes`): a camera looking
    // almost straight down sees them all alike, whatever horizon the VPs gave.
    let sizes = super::sizes::size_slope(
        &full.boxes,
        &full.weight,
        calibration.horizon,
        width,
        height,
    );
    if let Some(s) = sizes.filter(|s| s.slope < super::sizes::MIN_SIZE_SLOPE) {
        return Err(not_enough(format!(
            "the vehicles' sizes contradict the estimated horizon: they grow with the distance \
             below it as its power {:.2} (about 1 expected, at least {:.1} allowed; {} boxes); \
             a camera looking almost straight down, whose focal length and horizon cannot be \
             observed, or per-vehicle VPs that do not agree on a camera",
            s.slope,
            super::sizes::MIN_SIZE_SLOPE,
            s.boxes
        )));
    }
    let s2 = opts.ray_scale_deg.to_radians();
    let vp2_inliers = full
        .centre
        .iter()
        .zip(&full.angle2)
        .filter(|(c, a)| {
            let d = (vp1 - **c) * u + h;
            line_angle_diff(**a - d.y.atan2(d.x) - x[2]).abs() < 3.0 * s2
        })
        .count();
    let evidence = Evidence {
        pairs_in: pairs.len(),
        pairs_used: full.centre.len(),
        effective_vehicles: effective,
        repeated_boxes: prep.repeated,
        vp1_inliers,
        vp2_inliers,
        rays_trusted,
        track_lines: track_lines.len(),
        vp1_from_tracks: vp1_lines.from_tracks,
        vp1_ray_scatter_deg: network_scatter,
        track_residual_deg: track_residual,
        curved_tracks,
        road_curved,
        curved_fit: curved_fit.is_some(),
        curved_focal,
        curved_vehicles: curved_fit.map_or(0, |c| c.vehicles),
        vp1_from_edgelets: edge_vp1.is_some(),
        vp1_edgelets: edge_vp1.map_or(0, |e| e.1),
        vp1_from_scene_lines: scene_vp1.is_some(),
        vp1_scene_edgelets: scene_vp1.map_or(0, |f| f.edgelets),
        vp1_scene_shift_px: scene_shift,
        vp1_scene_extra_deg: scene_extra,
        edgelets: edge_fit.map_or(0, |e| e.edgelets),
        edgelet_vehicles: edge_fit.map_or(0, |e| e.vehicles),
        roll_from_edgelets: usable.is_some(),
        focal_from_edgelets: carried("edgelets"),
        edgelet_focal_px: edge_fit.map(|e| e.focal_px),
        edgelet_roll_sd_deg: edge_fit.map(|e| e.roll_sd_deg),
        edgelet_focal_log_spread: edge_fit.map(|e| e.focal_log_spread()),
        edgelet_vp2_widths: edge_fit.map(|e| (e.vp2 - pp).norm() / width),
        edgelet_focal_bias_log_spread: edge_fit.map(|e| e.focal_bias_log_spread),
        size_slope: sizes.map(|s| s.slope),
        rays_focal_px: rays.as_ref().map(|r| r.fit[0].exp()),
        rays_scatter_deg: rays.as_ref().map(|r| r.scatter_deg),
        rays_vp2_sd_deg: rays.as_ref().map(|r| r.sd_deg).filter(|s| s.is_finite()),
        rays_posterior_px: posterior,
        focal_from_rays,
    };
    let confidence = samples.and_then(|b| {
        let data_only = Vp2Model {
            fixed_bias: Some(0.0),
            roll_prior: false,
            ..model
        }
        .fit(&prep.weight, None)[0]
            .exp();
        if b.focal_px.is_empty() {
            return None;
        }
        // Horizon angles near +-180 wrap: measure them as line angles around the estimate.
        let a0 = calibration.horizon.angle().to_degrees();
        let angles: Vec<f64> = b
            .horizon_deg
            .iter()
            .map(|a| line_angle_diff((a - a0).to_radians()).to_degrees())
            .collect();
        // Where the edgelets set the roll, their own bootstrap is its spread (the curved-road
        // fit's, or the straight fit's with VP1 fixed).
        let horizon_sd = match (curved_fit, usable) {
            (Some(c), _) => c.roll_sd_deg,
            (None, Some(e)) => e.roll_sd_deg,
            (None, None) => sd(&angles),
        };
        // The focal lengths' own bootstrap: that of the edgelet fit that carried f, else
        // this one's (where f is held, as for untrusted rays, all its resamples agree).
        let (p16, p84) = match (curved_fit.filter(|_| curved_focal), usable) {
            (Some(c), _) => (c.focal_px_p16, c.focal_px_p84),
            (None, Some(e)) if carried("edgelets") => (e.focal_px_p16, e.focal_px_p84),
            _ => (
                percentile(b.focal_px.clone(), 16.0),
                percentile(b.focal_px.clone(), 84.0),
            ),
        };
        Some(Confidence {
            focal_px_p16: p16,
            focal_px_p84: p84,
            horizon_angle_sd_deg: horizon_sd,
            vp1_sd_px: ((sd(&b.vp1_x).powi(2) + sd(&b.vp1_y).powi(2)) / 2.0).sqrt(),
            focal_px_data_only: data_only,
            resamples: b.focal_px.len(),
        })
    });
    Ok(RobustResult {
        calibration,
        roll: x[1],
        ray_bias: x[2],
        evidence,
        confidence,
        focal,
        track_lines,
    })
}

/// The bootstrap's resamples ([`bootstrap`]).
struct Samples {
    /// The focal length, the horizon's angle (degrees) and VP1 of each resample.
    focal_px: Vec<f64>,
    horizon_deg: Vec<f64>,
    vp1_x: Vec<f64>,
    vp1_y: Vec<f64>,
}

/// Refit VP1 and the VP2 model (`x` the start) on `resamples` Poisson resamplings of the
/// physical vehicles (one count per vehicle, shared by its boxes: [`vehicle_units`]; track
/// lines get one count per track). Where the scene's lines placed VP1 (`scene`), each
/// resample's VP1 is moved by them again: they do not change with the vehicles.
#[allow(clippy::too_many_arguments)]
fn bootstrap(
    model: &Vp2Model,
    prep: &Prepared,
    vp1_lines: &Vp1Lines,
    p1: [f64; 3],
    x: [f64; 3],
    scene: Option<(&[Edgelet], &SceneLineOptions)>,
    resamples: usize,
    rng: &mut SplitMix,
) -> Samples {
    let mut out = Samples {
        focal_px: vec![],
        horizon_deg: vec![],
        vp1_x: vec![],
        vp1_y: vec![],
    };
    let q1 = from_sphere(p1);
    let scaled =
        |w: &[f64], c: &[f64]| -> Vec<f64> { w.iter().zip(c).map(|(a, c)| a * c).collect() };
    // The draws in order, then the refits (independent of each other) over the cores: the
    // same resamples as drawing and fitting one after another.
    let weights: Vec<(Vec<f64>, Vec<f64>)> = (0..resamples)
        .map(|_| {
            let draws: Vec<f64> = (0..prep.units).map(|_| rng.poisson1()).collect();
            let counts: Vec<f64> = prep.unit.iter().map(|&u| draws[u]).collect();
            let w = scaled(&prep.weight, &counts);
            let wv1 = if vp1_lines.from_tracks {
                let counts1: Vec<f64> = (0..vp1_lines.weight.len())
                    .map(|_| rng.poisson1())
                    .collect();
                scaled(&vp1_lines.weight, &counts1)
            } else {
                scaled(&vp1_lines.weight, &counts)
            };
            (w, wv1)
        })
        .collect();
    let refits = crate::solve::par_map(&weights, |(w, wv1)| {
        let threshold = vp1_lines.threshold_deg;
        // With a start, the VP1 fit draws no random numbers.
        let mut unused = SplitMix(0);
        let pb = fit_vp1(vp1_lines.lines(), wv1, threshold, &mut unused, Some(q1))?;
        let vb = vp1_of(pb)?;
        let mb = Vp2Model { vp1: vb, ..*model };
        let (vb, xb, _) = fit_camera(&mb, vp1_lines, wv1, w, Some(x));
        let vb = scene
            .and_then(|(edgelets, so)| scene_lines::refine_vp1(vb, edgelets, so))
            .map_or(vb, |f| f.vp1);
        let mb = Vp2Model { vp1: vb, ..*model };
        let (hb, ub) = mb.vp2(xb[0], xb[1]);
        Some((vb, vb + hb / ub, xb[0].exp()))
    });
    for (vb, vp2b, focal) in refits.into_iter().flatten() {
        out.focal_px.push(focal);
        out.horizon_deg
            .push((vp2b.y - vb.y).atan2(vp2b.x - vb.x).to_degrees());
        out.vp1_x.push(vb.x);
        out.vp1_y.push(vb.y);
    }
    out
}
