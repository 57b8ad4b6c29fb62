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

use super::bootstrap::{bootstrap, Samples};
use super::edgelets::EdgeletFitOptions;
use super::edgelets::{self as edge, BoxEdgelets, CurvedFit, CurvedVehicle, Edgelet};
use super::focal::{
    self, focal_prior_range_widths, physical_focal_prior, FocalPosterior, FocalSource,
};
use super::line_angle_diff;
use super::rays::{fit_camera, rays_focal, RayOptions, RaysFocal, RaysRoll, Vp2Model};
use super::scene_lines::{self, SceneLineOptions, SceneVp1};
use super::sizes;
use super::tracks::{self, CurveTest, RoadTracks, TrackLine, TrackOptions};
use super::vehicles::{prepare, tracked_boxes, vehicle_units, Prepared, Weighting};
use super::verticals::{self, Segment, VerticalOptions};
use super::vp1::{self, homogeneous, Vp1Choice, Vp1Lines};
use super::{AggregateError, VehicleVps};
use crate::camera::Calibration;
use crate::point::{BoxPx, Point2};
use crate::solve::{half_p16_p84, percentile, sd, SplitMix};

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
    /// The physical prior on the horizon's angle: level, with this standard deviation
    /// (degrees), against which the network's rays' own roll is weighed
    /// ([`RaysRoll`](super::rays::RaysRoll)). Measured on real traffic cameras: the 12
    /// BrnoCompSpeed reference cameras of sessions 0-3 (`camera_truth.json`) have an rms
    /// horizon angle of 2.29° (0.62-4.88° in size), the 15 real clips whose horizon the
    /// vehicles' edgelets set (`docs/accuracy.md` §27) 1.58° (up to 4.0°).
    pub roll_prior_sigma_deg: f64,
    /// Standard deviation of the prior on the CNN's VP2 ray bias, degrees.
    pub ray_bias_prior_sigma_deg: f64,
    /// Scale of the Cauchy loss on VP2 ray angles, degrees.
    pub ray_scale_deg: f64,
    /// Inlier threshold (and Cauchy scale) for VP1 lines, degrees.
    pub vp1_threshold_deg: f64,
    /// Strength of the rays' bias prior relative to the data: its term is multiplied by this
    /// fraction of the total vehicle weight.
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
    /// tell; the share and the t-statistic still keep the straight roads straight. Where
    /// at least `min_track_lines` straight tracks meet at no one VP1, this many bent ones
    /// make the road curved whatever their share: the road curves through part of the view
    /// (two of four unseen rendered curves, docs/accuracy.md §32).
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
    /// Measure the focal length from the scene's vertical lines ([`verticals`]) when its line
    /// segments are given ([`Scene::segments`]); `None`: never.
    #[serde(default)]
    pub verticals: Option<VerticalOptions>,
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
            roll_prior_sigma_deg: 2.0,
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
            verticals: Some(VerticalOptions::default()),
        }
    }
}

impl RobustOptions {
    /// How the vehicles are weighed.
    fn weighting(&self) -> Weighting {
        Weighting {
            min_score: self.min_score,
            duplicate_iou: self.duplicate_iou,
            duplicate_keep: self.duplicate_keep,
            min_box_fraction: self.min_box_fraction,
        }
    }

    /// When the tracks say the road curves.
    fn curve_test(&self) -> CurveTest {
        CurveTest {
            bend_t: self.curved_bend_t,
            bend_deg: self.curved_bend_deg,
            share: self.curved_share,
            min_tracks: self.min_curved_tracks,
            max_se_deg: self.curved_max_se_deg,
        }
    }

    /// Which lines VP1 is fitted to.
    fn vp1_choice(&self) -> Vp1Choice {
        Vp1Choice {
            vp1_threshold_deg: self.vp1_threshold_deg,
            min_track_lines: self.min_track_lines,
            track_threshold_deg: self.track_threshold_deg,
            track_above_scatter_deg: self.track_above_scatter_deg,
            track_residual_ratio: self.track_residual_ratio,
        }
    }

    /// The horizon model's settings.
    fn ray_options(&self) -> RayOptions {
        RayOptions {
            focal_prior_ratio: self.focal_prior_ratio,
            roll_prior_sigma_deg: self.roll_prior_sigma_deg,
            ray_bias_prior_sigma_deg: self.ray_bias_prior_sigma_deg,
            ray_scale_deg: self.ray_scale_deg,
            prior_weight: self.prior_weight,
            consistency_log_ratio: self.consistency_log_ratio,
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
    /// The straight edgelet fit's own roll, degrees, whether or not it was used.
    #[serde(default)]
    pub edgelet_roll_deg: Option<f64>,
    /// The edgelet fit's focal length (px) and the bootstrap spread of its roll (degrees),
    /// whether or not they were used.
    pub edgelet_focal_px: Option<f64>,
    pub edgelet_roll_sd_deg: Option<f64>,
    /// How far the uncertainty of the edges' systematic turn towards VP1
    /// (`edge::EDGE_TURN_SD_DEG`) moves the edgelet fit's roll, degrees; the roll's spread
    /// downstream is this and the bootstrap's in quadrature.
    pub edgelet_roll_turn_sd_deg: Option<f64>,
    /// How far VP1's spread across the horizon moves the straight edgelet fit's roll,
    /// degrees (`edgelets::roll_vp1_sd_deg`), where that fit set the roll.
    pub edgelet_roll_vp1_sd_deg: Option<f64>,
    /// Where the untrusted rays placed the horizon: their own roll (degrees, before the
    /// physical prior on it pulled it towards level) and its standard deviation
    /// ([`RaysRoll`](super::rays::RaysRoll)); the roll is `roll_deg` unless the edgelets or
    /// the curved-road fit set it.
    #[serde(default)]
    pub rays_roll_own_deg: Option<f64>,
    #[serde(default)]
    pub rays_roll_sd_deg: Option<f64>,
    /// The part of `rays_roll_sd_deg` from the own roll's spread over the bootstrap's
    /// resamples (half their 16th-84th percentile range, degrees): VP1 placed loosely turns
    /// the rays' horizon with it.
    #[serde(default)]
    pub rays_roll_sampling_sd_deg: Option<f64>,
    /// Half of `ln(p84 / p16)` of the edgelet fit's bootstrap focal lengths, and the distance
    /// of its VP2 from the principal point in image widths (the focal length's two gates).
    pub edgelet_focal_log_spread: Option<f64>,
    pub edgelet_vp2_widths: Option<f64>,
    /// How far a systematic turn of the edges by 1° moves the edgelet fit's `ln f` (its third
    /// gate; `edge::EdgeletFit::focal_bias_log_spread`).
    pub edgelet_focal_bias_log_spread: Option<f64>,
    /// How the vehicles' box sizes grow with their distance below the estimated horizon (the
    /// power of a log-log fit; 1 when they agree, see `super::sizes`); `None` with too few
    /// boxes.
    pub size_slope: Option<f64>,
    /// Where the VP2 rays were not trusted: the focal length they alone give (pixels), the
    /// weighted median angle of the rays around it (degrees), the systematic error assumed
    /// for their VP2 ([`RAY_SYSTEMATIC_PER_SCATTER`](super::rays::RAY_SYSTEMATIC_PER_SCATTER) times that, degrees), and the 16th,
    /// 50th and 84th percentiles of the focal length under the physical prior and that
    /// evidence alone ([`rays_focal_posterior`](super::rays::rays_focal_posterior)).
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
    /// The scene's vertical lines ([`verticals`]): the segments that could be verticals and
    /// those that point at the fit's VP3 (0 without segments), the focal length they give
    /// (pixels; `None` where not identified), and whether they carried it in its posterior.
    #[serde(default)]
    pub vertical_candidates: usize,
    #[serde(default)]
    pub vertical_supporting: usize,
    #[serde(default)]
    pub verticals_focal_px: Option<f64>,
    #[serde(default)]
    pub focal_from_verticals: bool,
    /// The scene's vertical lines' own roll, degrees, with no prior from the road (gravity's
    /// horizon), where they identify it, and its spread over their resamples
    /// (`verticals::VerticalsFit::own_roll`).
    pub verticals_roll_deg: Option<f64>,
    pub verticals_roll_sd_deg: Option<f64>,
    /// How far `verticals_roll_deg` lies from the road horizon's roll, in standard deviations
    /// (`verticals::VerticalsFit::against_horizon`).
    pub verticals_roll_z: Option<f64>,
    /// Where that exceeds `verticals::HORIZON_CONFLICT_Z`: the difference, degrees (no focal
    /// cue is then used, each resting on that horizon: f is the prior's; and the horizon's
    /// spread takes the difference).
    pub horizon_conflict_deg: Option<f64>,
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
    /// Spread of VP1's position over the resamples, pixels: half the 16th-84th percentile
    /// range of x and of y, RMS over the two (a few resamples whose VP1 runs off to infinity
    /// do not decide it). Each resample redoes the moves that placed VP1 (the edgelets along
    /// the vehicles it drew, the scene's lines).
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

/// An edgelet VP2 farther than this many image widths from the principal point says the
/// edges across the vehicles are parallel in the image (f > 100 widths is a 0.6° view: no
/// traffic camera): the view looks almost straight down, or VP1 and VP2 cannot both be
/// placed, and the focal length is not observable.
pub const PARALLEL_EDGES_VP2_WIDTHS: f64 = 100.0;

/// A curved road's track tangents span this many boxes before and after each box.
const CURVE_TANGENT_HALF: usize = 4;

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
    /// Its edgelets: the lines along the road move VP1 ([`scene_lines`]).
    pub edgelets: &'a [Edgelet],
    /// Its straight line segments: the vertical ones measure the focal length
    /// ([`verticals`]).
    pub segments: &'a [Segment],
}

/// [`aggregate_with_edgelets`], with what the scene's background shows ([`Scene`]): with
/// `opts.scene_lines` set and a straight road, VP1 moves to where the scene's lines along the
/// road meet ([`scene_lines`]) while the vehicles' VP1 evidence agrees
/// (`opts.scene_max_extra_deg`); with `opts.verticals` set, its vertical lines measure the
/// focal length ([`verticals`]).
///
/// The stages, each a function below with what it found as its result: the vehicles
/// (`usable_vehicles`), VP1 (`place_vp1`), the horizon's roll (`place_horizon`), the focal
/// posterior (`fuse_focal`) and the camera they make (`make_camera`).
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

/// VP1 and what placed it (`super::vp1`, then the moves of [`move_vp1`]), with the network's
/// VP2 rays fitted around it (`super::rays`).
struct PlacedVp1<'a> {
    located: vp1::Located,
    /// The rays' horizon model, around VP1 where the moves left it.
    model: Vp2Model<'a>,
    /// The rays' fit: `(ln f, roll, bias)`, and whether they were trusted.
    x: [f64; 3],
    rays_trusted: bool,
    /// Untrusted, the rays' own roll (degrees) and its model, weighed against the physical
    /// prior on the horizon's angle.
    rays_roll: Option<(f64, RaysRoll)>,
    moved: MovedVp1,
    /// The edgelet and scene-line settings where there is something for them to fit.
    edge_opts: Option<&'a EdgeletFitOptions>,
    scene_opts: Option<&'a SceneLineOptions>,
}

/// VP1 where the tracks' or the network's VP1 lines meet (`super::vp1`), the network's VP2
/// rays around it (trusted, they fit f, the roll and VP1 with it; else the roll and their bias
/// are fitted with f held at the prior's middle), then moved by the edges along the vehicles
/// and the scene's lines along the road ([`move_vp1`]).
fn place_vp1<'a>(
    input: &Input<'a>,
    full: &Prepared,
    prep: &'a Prepared,
    road: &mut RoadTracks,
    boxes: &[BoxEdgelets],
    rng: &mut SplitMix,
) -> Result<PlacedVp1<'a>, AggregateError> {
    let (pp, opts, width) = (input.pp, input.opts, input.width());
    let choice = opts.vp1_choice();
    let located = vp1::locate(full, prep, road, pp, width, &choice, rng).map_err(not_enough)?;
    // Straight tracks that do not meet at one VP1, while at least `min_curved_tracks` bend
    // alike: the road curves through part of the view, and the share test had counted the
    // straight stretch's tracks against it.
    if located.tracks_disagree && road.curved_tracks >= opts.min_curved_tracks.max(1) {
        road.road_curved = true;
    }
    let model = Vp2Model {
        vp1: located.vp1,
        pp,
        prep,
        opts: opts.ray_options(),
        f0: opts.focal_prior_ratio * width,
        fixed_bias: None,
        fixed_ln_f: None,
    };
    let lines = &located.lines;
    let fit = fit_camera(&model, lines, &lines.weight, &prep.weight, None);
    let scene = input.scene.edgelets;
    let edge_opts = opts.edgelets.as_ref().filter(|_| !boxes.is_empty());
    let scene_opts = opts
        .scene_lines
        .as_ref()
        .filter(|_| !road.road_curved && !scene.is_empty());
    let moved = move_vp1(fit.vp1, lines, boxes, edge_opts, scene, scene_opts, opts);
    Ok(PlacedVp1 {
        model: Vp2Model {
            vp1: moved.vp1,
            ..model
        },
        x: fit.x,
        rays_trusted: fit.trusted,
        rays_roll: fit.own_roll.map(|(own, rr)| (own.to_degrees(), rr)),
        moved,
        edge_opts,
        scene_opts,
        located,
    })
}

impl PlacedVp1<'_> {
    fn record(&self, road: &RoadTracks, e: &mut Evidence) {
        e.track_lines = road.straight.len();
        e.curved_tracks = road.curved_tracks;
        e.road_curved = road.road_curved;
        e.vp1_inliers = self.located.inliers;
        e.vp1_from_tracks = self.located.lines.from_tracks;
        e.vp1_ray_scatter_deg = self.located.network_scatter;
        e.track_residual_deg = self.located.track_residual;
        e.rays_trusted = self.rays_trusted;
        e.rays_roll_own_deg = self.rays_roll.map(|(own, _)| own);
        self.moved.record(e);
    }
}

/// The horizon through VP1: its roll and what set it ([`RollFrom`]), with the bootstrap's
/// resamples.
struct Horizon<'a> {
    /// The rays' model around the final VP1 (the curved-road fit's on a curved road).
    model: Vp2Model<'a>,
    /// `(ln f, roll, bias)`, the roll from [`RollFrom`].
    x: [f64; 3],
    /// The straight edgelet fit, and whether it says the edges across the vehicles are
    /// parallel in the image ([`PARALLEL_EDGES_VP2_WIDTHS`]).
    edge_fit: Option<edge::EdgeletFit>,
    edges_parallel: bool,
    /// That fit where its roll is usable, its spread with VP1's.
    usable: Option<edge::EdgeletFit>,
    curved: Option<CurvedFit>,
    samples: Option<Samples>,
    roll_from: RollFrom,
    /// The untrusted rays' roll model with its sampling spread (`rays_roll_sampling_sd_deg`).
    rays_roll: Option<RaysRoll>,
    rays_roll_sampling_sd_deg: Option<f64>,
    edgelet_roll_vp1_sd_deg: Option<f64>,
}

/// The horizon's roll (`super::edgelets`, `super::rays`): the straight edgelet fit where its
/// roll is usable, on a curved road the curved-road fit (each car's VP1 from its track's
/// tangent), else the rays' own roll under its prior; then the bootstrap's resamples
/// (`super::bootstrap`), whose VP1 spread widens the edgelets' roll and whose rays' rolls
/// widen the rays'.
fn place_horizon<'a>(
    input: &Input,
    placed: &PlacedVp1<'a>,
    road: &RoadTracks,
    boxes: &[BoxEdgelets],
    unit: &[usize],
    rng: &mut SplitMix,
) -> Horizon<'a> {
    let (pp, opts, width) = (input.pp, input.opts, input.width());
    let (mut x, vp1, edge_opts) = (placed.x, placed.model.vp1, placed.edge_opts);
    let edge_fit = edge_opts.and_then(|eo| edge::fit(vp1, pp, width, boxes, x[1], eo, opts.seed));
    let edges_parallel = edge_fit.is_some_and(|e| {
        let w = (e.vp2 - pp).norm() / width;
        w.is_nan() || w > PARALLEL_EDGES_VP2_WIDTHS
    });
    let usable = edge_fit.filter(|e| e.roll_usable);
    if let Some(e) = usable {
        x[1] = e.roll;
    }
    // On a curved road every car has its own VP1 on the horizon: the horizon and the focal
    // length from the cars' track tangents and edgelets together.
    let curved = edge_opts.filter(|_| road.road_curved).and_then(|eo| {
        curved_road_fit(road, input.edgelets, unit, input.frame, pp, x[1], eo, opts)
    });
    let model = match curved {
        Some(c) => {
            x[1] = c.roll;
            Vp2Model {
                vp1: c.vp1,
                ..placed.model
            }
        }
        None => placed.model,
    };
    // The bootstrap's resamples: the focal lengths of trusted rays, the horizon and VP1.
    let samples = (opts.bootstrap > 0).then(|| {
        let moved = &placed.moved;
        let edges = moved.edges.and(edge_opts).map(|eo| (boxes, eo));
        let scene = moved
            .scene
            .and(placed.scene_opts)
            .map(|so| (input.scene.edgelets, so));
        let (lines, p1, n) = (&placed.located.lines, placed.located.p1, opts.bootstrap);
        bootstrap(&model, model.prep, lines, p1, x, edges, scene, n, rng)
    });
    // The rays' own roll moves with the vehicles drawn and with VP1, through which their
    // horizon runs: its spread over the resamples joins its error model.
    let spread = samples
        .as_ref()
        .filter(|b| b.rays_roll_own_deg.len() > 1)
        .map(|b| half_p16_p84(&b.rays_roll_own_deg));
    let rays_roll = placed
        .rays_roll
        .map(|(_, rr)| spread.map_or(rr, |s| rr.with_sampling(s)));
    // The straight edgelet fit held VP1 where it was placed; VP1's spread across the horizon
    // (its resamples') turns that fit's roll too (`edge::roll_vp1_sd_deg`).
    let mut edgelet_roll_vp1_sd_deg = None;
    let usable = match (usable, edge_opts) {
        (Some(e), Some(eo)) if curved.is_none() => {
            let normal = Point2::new(-e.roll.sin(), e.roll.cos());
            let shift = samples
                .as_ref()
                .map_or(0.0, |b| b.vp1_spread_along(vp1, normal));
            let sd = edge::roll_vp1_sd_deg(&e, vp1, pp, boxes, eo, shift);
            edgelet_roll_vp1_sd_deg = Some(sd).filter(|s| s.is_finite());
            Some(e.with_vp1_spread(sd))
        }
        (u, _) => u,
    };
    let roll_from = RollFrom::of(curved, usable, rays_roll);
    // Where the rays set the roll it is weighed against the prior again.
    if let (RollFrom::Rays(rr), Some((own, _))) = (roll_from, placed.rays_roll) {
        x[1] = rr.roll(own.to_radians());
    }
    Horizon {
        model,
        x,
        edge_fit,
        edges_parallel,
        usable,
        curved,
        samples,
        roll_from,
        rays_roll,
        rays_roll_sampling_sd_deg: spread,
        edgelet_roll_vp1_sd_deg,
    }
}

impl Horizon<'_> {
    /// Writes what the horizon's stage found; `width`: of the frames, pixels.
    fn record(&self, width: f64, e: &mut Evidence) {
        e.rays_roll_sampling_sd_deg = self.rays_roll_sampling_sd_deg;
        if let Some(rr) = self.rays_roll {
            e.rays_roll_sd_deg = Some(rr.sd_deg);
        }
        e.edgelet_roll_vp1_sd_deg = self.edgelet_roll_vp1_sd_deg;
        if let Some(f) = self.edge_fit {
            e.edgelets = f.edgelets;
            e.edgelet_vehicles = f.vehicles;
            e.edgelet_focal_px = Some(f.focal_px);
            e.edgelet_roll_sd_deg = Some(f.roll_sd_deg);
            e.edgelet_roll_deg = Some(f.roll.to_degrees());
            e.edgelet_roll_turn_sd_deg = Some(f.roll_turn_sd_deg);
            e.edgelet_focal_log_spread = Some(f.focal_log_spread());
            e.edgelet_vp2_widths = Some((f.vp2 - self.model.pp).norm() / width);
            e.edgelet_focal_bias_log_spread = Some(f.focal_bias_log_spread);
        }
        e.roll_from_edgelets = self.usable.is_some();
        e.curved_fit = self.curved.is_some();
        e.curved_vehicles = self.curved.map_or(0, |c| c.vehicles);
    }

    /// The roll's standard deviation, degrees ([`RollFrom::sd_deg`]).
    fn roll_sd_deg(&self) -> f64 {
        self.roll_from
            .sd_deg(self.samples.as_ref(), self.x[1].to_degrees())
    }
}

/// The focal sources (`super::focal`) and their posterior.
struct FocalCues {
    /// The untrusted rays' likelihood of f.
    rays: Option<RaysFocal>,
    verticals: Option<verticals::VerticalsFit>,
    /// The plumb lines' roll against the horizon's: `(z, difference)`, and the difference
    /// where it is a conflict ([`verticals::HORIZON_CONFLICT_Z`]).
    against: Option<(f64, f64)>,
    conflict: Option<(f64, f64)>,
    posterior: FocalPosterior,
}

/// Each focal cue where its model holds, and their posterior: on a curved road only the
/// curved fit (every car has its own VP2, so neither the rays nor the straight edgelet fit
/// apply); the rays and the edges across the vehicles not where those edges are parallel in
/// the image (a view straight down, where f cannot be observed); the scene's vertical lines
/// wherever the horizon is placed; none where the plumb lines contradict the horizon.
fn fuse_focal(
    input: &Input,
    placed: &PlacedVp1,
    horizon: &Horizon,
    road: &RoadTracks,
) -> Result<FocalCues, AggregateError> {
    let (pp, opts) = (input.pp, input.opts);
    let range_px = input.range_px();
    let weight = &placed.model.prep.weight;
    // Rays the VP2 points contradict still say something about f where VP2 is near: their
    // likelihood over ln f (`rays_focal_likelihood`), around VP1 before a curved-road fit.
    let rays = (!placed.rays_trusted).then(|| rays_focal(&placed.model, weight, range_px));
    let trusted = placed
        .rays_trusted
        .then(|| trusted_rays(horizon.x[0].exp(), horizon.samples.as_ref()));
    // The scene's vertical lines need only the horizon: VP1 on it and its roll, with the
    // roll's spread (the edgelets' where they set it, the rays' posterior's where they did,
    // else the bootstrap's).
    let horizon_placed = horizon.curved.is_some() || !road.road_curved;
    let roll_sd_deg = horizon.roll_sd_deg();
    let (vp1, roll) = (horizon.model.vp1, horizon.x[1]);
    let verticals = opts
        .verticals
        .as_ref()
        .filter(|_| horizon_placed && !input.scene.segments.is_empty())
        .and_then(|vo| {
            let support = focal::support(range_px);
            let roll_sd = roll_sd_deg.to_radians();
            verticals::fit(
                input.scene.segments,
                vp1,
                pp,
                roll,
                roll_sd,
                support,
                vo,
                opts.seed,
            )
        });
    // Plumb lines meet at gravity's VP3: where their own roll contradicts the road horizon's
    // beyond the road's cross slope and both errors, the horizon (or the verticals) is wrong,
    // and no focal cue is used: every one (the verticals under the horizon's roll, the
    // edgelets' and the rays' VP2 on it, the curved fit's one plane) rests on that horizon.
    let against = verticals
        .as_ref()
        .zip(opts.verticals.as_ref())
        .and_then(|(v, vo)| v.against_horizon(roll, roll_sd_deg.to_radians(), vo));
    let conflict = against.filter(|(z, _)| z.abs() > verticals::HORIZON_CONFLICT_Z);
    let vertical = verticals.as_ref().map(|v| v as &dyn FocalSource);
    let sources: Vec<&dyn FocalSource> = match &horizon.curved {
        _ if conflict.is_some() => vec![],
        Some(c) => [Some(c as &dyn FocalSource), vertical]
            .into_iter()
            .flatten()
            .collect(),
        None if !road.road_curved && !horizon.edges_parallel => {
            let edges = horizon.usable.as_ref().map(|e| e as &dyn FocalSource);
            let trusted = trusted.as_ref().map(|t| t as &dyn FocalSource);
            let rays = rays.as_ref().map(|r| r as &dyn FocalSource);
            [edges, trusted, rays, vertical]
                .into_iter()
                .flatten()
                .collect()
        }
        None => vertical.into_iter().collect(),
    };
    let posterior = focal::fuse(range_px, &focal::cues_of(&sources))
        .ok_or_else(|| not_enough(format!("invalid focal range {range_px:?} px")))?;
    Ok(FocalCues {
        rays,
        verticals,
        against,
        conflict,
        posterior,
    })
}

impl FocalCues {
    fn record(&self, e: &mut Evidence) {
        let carried = |s: &str| self.posterior.carried_by.contains(&s);
        if let Some(r) = &self.rays {
            e.rays_focal_px = Some(r.fit[0].exp());
            e.rays_scatter_deg = Some(r.scatter_deg);
            e.rays_vp2_sd_deg = Some(r.sd_deg).filter(|s| s.is_finite());
            e.rays_posterior_px = r.posterior;
        }
        e.focal_from_rays = carried("network_rays");
        if let Some(v) = &self.verticals {
            e.vertical_candidates = v.candidates;
            e.vertical_supporting = v.supporting;
            e.verticals_focal_px = v.identified.then_some(v.focal_px);
            e.verticals_roll_deg = v.own_roll.map(f64::to_degrees);
            e.verticals_roll_sd_deg = v
                .own_roll
                .map(|_| v.own_roll_sd.to_degrees())
                .filter(|s| s.is_finite());
        }
        e.verticals_roll_z = self.against.map(|(z, _)| z);
        e.horizon_conflict_deg = self.conflict.map(|(_, d)| d.to_degrees());
        e.focal_from_verticals = carried("verticals");
        e.focal_from_edgelets = carried("edgelets");
        e.curved_focal = carried("curved_edgelets");
    }
}

/// The camera of VP1, the horizon's roll and the focal posterior's f: where f moved off the
/// value the VP2 model held, the roll and the rays' bias are refitted with f held there
/// (unless another source set the roll), the roll weighed against its prior again; then the
/// horizon against the vehicles (`super::sizes`) and the spread of the estimate.
fn make_camera(
    input: &Input,
    full: &Prepared,
    horizon: Horizon,
    cues: FocalCues,
    mut evidence: Evidence,
    road: RoadTracks,
) -> Result<RobustResult, AggregateError> {
    let (pp, opts) = (input.pp, input.opts);
    let (focal, roll_from, mut x) = (cues.posterior, horizon.roll_from, horizon.x);
    let model = Vp2Model {
        f0: focal.focal_px,
        ..horizon.model
    };
    let (vp1, prep) = (model.vp1, model.prep);
    if let (true, RollFrom::Rays(rr)) = (focal.measured, roll_from) {
        x = Vp2Model {
            fixed_ln_f: Some(focal.focal_px.ln()),
            ..model
        }
        .fit(&prep.weight, Some([focal.focal_px.ln(), x[1], x[2]]));
        evidence.rays_roll_own_deg = Some(x[1].to_degrees());
        x[1] = rr.roll(x[1]);
    }
    x[0] = focal.focal_px.ln();
    let (h, u) = model.vp2(x[0], x[1]);
    let calibration = Calibration::from_vps(vp1, vp1 + h / u, pp)
        .map_err(|e| not_enough(format!("the estimate is not a valid camera: {e}")))?;
    // Vanishing points billions of pixels away (lines parallel in the image: a view straight
    // down) hold the focal length only to rounding: such a camera is not measured.
    if (calibration.focal_px / focal.focal_px - 1.0).abs() > FOCAL_ROUNDING_TOLERANCE {
        return Err(not_enough(format!(
            "the vanishing points lie too far out to place the camera (VP1 {:.3e} px from \
             the principal point, VP2 {:.3e} px: the lines along and across the road are \
             parallel in the image, as in a view straight down)",
            (vp1 - pp).norm(),
            (calibration.vp2 - pp).norm()
        )));
    }
    // The vehicles stand below the horizon and grow away from it (`super::sizes`).
    evidence.size_slope = sizes::check_horizon(
        &full.centre,
        &full.boxes,
        &full.weight,
        calibration.horizon,
        pp,
        input.frame,
        opts.max_above_horizon,
    )
    .map_err(not_enough)?;
    let s2 = opts.ray_scale_deg.to_radians();
    evidence.vp2_inliers = full
        .centre
        .iter()
        .zip(&full.angle2)
        .filter(|(c, a)| {
            let d = (vp1 - **c) * u + h;
            line_angle_diff(**a - d.y.atan2(d.x) - x[2]).abs() < 3.0 * s2
        })
        .count();
    let confidence = horizon.samples.and_then(|b| {
        // Where an edgelet fit carried f, its bootstrap is f's.
        let edge_focal = match roll_from {
            RollFrom::Curved(c) if evidence.curved_focal => Some([c.focal_px_p16, c.focal_px_p84]),
            RollFrom::Edgelets(e) if evidence.focal_from_edgelets => {
                Some([e.focal_px_p16, e.focal_px_p84])
            }
            _ => None,
        };
        let horizon_sd = roll_from.sd_deg(Some(&b), calibration.horizon.angle().to_degrees());
        // Contradicted by the plumb lines, the horizon is known no better than the two differ.
        let horizon_sd = cues
            .conflict
            .map_or(horizon_sd, |(_, d)| horizon_sd.hypot(d.to_degrees()));
        confidence(&b, &model, prep, horizon_sd, edge_focal)
    });
    Ok(RobustResult {
        calibration,
        roll: x[1],
        ray_bias: x[2],
        evidence,
        confidence,
        focal,
        track_lines: road.straight,
    })
}

/// How far the focal length of the camera built from VP1 and VP2 may differ from the one
/// fitted, relative: in exact arithmetic they are equal, and they part only where the
/// vanishing points lie so far out that rounding their coordinates swamps the focal length.
const FOCAL_ROUNDING_TOLERANCE: f64 = 1e-6;

/// What set the horizon's roll, in order of precedence: the curved-road fit, the straight
/// edgelet fit where its roll is usable, the untrusted rays' own roll under its physical
/// prior, else the rays' joint fit (trusted) with the bootstrap's spread.
#[derive(Debug, Clone, Copy)]
enum RollFrom {
    Curved(CurvedFit),
    Edgelets(edge::EdgeletFit),
    Rays(RaysRoll),
    Bootstrap,
}

impl RollFrom {
    fn of(
        curved: Option<CurvedFit>,
        edges: Option<edge::EdgeletFit>,
        rays: Option<RaysRoll>,
    ) -> RollFrom {
        match (curved, edges, rays) {
            (Some(c), _, _) => RollFrom::Curved(c),
            (None, Some(e), _) => RollFrom::Edgelets(e),
            (None, None, Some(r)) => RollFrom::Rays(r),
            (None, None, None) => RollFrom::Bootstrap,
        }
    }

    /// The roll's standard deviation, degrees: the fit's own (the edgelets' with their turn,
    /// the rays' posterior), or the spread of the resamples `samples` around `roll_deg` (0
    /// with fewer than two).
    fn sd_deg(&self, samples: Option<&Samples>, roll_deg: f64) -> f64 {
        match self {
            RollFrom::Curved(c) => c.roll_total_sd_deg(),
            RollFrom::Edgelets(e) => e.roll_total_sd_deg(),
            RollFrom::Rays(r) => r.sd_after_deg(),
            RollFrom::Bootstrap => samples
                .filter(|b| b.horizon_deg.len() > 1)
                .map_or(0.0, |b| horizon_sd_deg(b, roll_deg)),
        }
    }
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

/// VP1 after the edges along the vehicles and the scene's lines moved it.
#[derive(Debug, Clone, Copy)]
struct MovedVp1 {
    vp1: Point2,
    /// The edgelets' VP1 and how many edgelets gave it.
    edges: Option<(Point2, usize, usize)>,
    /// The scene lines' VP1 where used, how far it moved VP1 (pixels), and how much it raised
    /// the median angle of the vehicles' VP1 lines, whether used or not (degrees).
    scene: Option<SceneVp1>,
    scene_shift_px: Option<f64>,
    scene_extra_deg: Option<f64>,
}

impl MovedVp1 {
    fn record(&self, e: &mut Evidence) {
        e.vp1_from_edgelets = self.edges.is_some();
        e.vp1_edgelets = self.edges.map_or(0, |e| e.1);
        e.vp1_from_scene_lines = self.scene.is_some();
        e.vp1_scene_edgelets = self.scene.map_or(0, |f| f.edgelets);
        e.vp1_scene_shift_px = self.scene_shift_px;
        e.vp1_scene_extra_deg = self.scene_extra_deg;
    }
}

/// Without tracks, the edgelets along the vehicles place VP1 better than the network's VP1
/// rays (module docs of `edgelets`); the scene's lines along the road place it better than
/// the vehicles (module docs of `scene_lines`) where the vehicles' lines still agree with the
/// point they give (`opts.scene_max_extra_deg`).
fn move_vp1(
    vp1: Point2,
    lines: &Vp1Lines,
    boxes: &[BoxEdgelets],
    edge_opts: Option<&EdgeletFitOptions>,
    scene: &[Edgelet],
    scene_opts: Option<&SceneLineOptions>,
    opts: &RobustOptions,
) -> MovedVp1 {
    let edges = edge_opts
        .filter(|_| !lines.from_tracks)
        .and_then(|eo| edge::fit_vp1(vp1, boxes, eo));
    let vp1 = edges.map_or(vp1, |e| e.0);
    let fit = scene_opts.and_then(|so| scene_lines::refine_vp1(vp1, scene, so));
    let residual_at = |v: Point2| lines.median_residual_deg(homogeneous(v));
    let extra = fit.and_then(|f| Some(residual_at(f.vp1)? - residual_at(vp1)?));
    let used = fit.filter(|_| extra.is_some_and(|x| x <= opts.scene_max_extra_deg));
    MovedVp1 {
        vp1: used.map_or(vp1, |f| f.vp1),
        edges,
        scene: used,
        scene_shift_px: used.map(|f| (f.vp1 - vp1).norm()),
        scene_extra_deg: extra,
    }
}

/// The curved-road fit ([`edge::fit_curved`]) on the tracked vehicles with edgelets, each
/// with its track's tangent.
#[allow(clippy::too_many_arguments)]
fn curved_road_fit(
    road: &RoadTracks,
    edgelets: &[Vec<Edgelet>],
    unit: &[usize],
    [width, height]: [f64; 2],
    pp: Point2,
    roll: f64,
    eo: &EdgeletFitOptions,
    opts: &RobustOptions,
) -> Option<CurvedFit> {
    let tangents = tracks::tangents(&road.boxes, &road.links, CURVE_TANGENT_HALF, 3.0);
    let vehicles: Vec<CurvedVehicle> = tangents
        .iter()
        .zip(&road.pairs)
        .filter_map(|(t, &i)| {
            let e = edgelets.get(i)?;
            (!e.is_empty()).then_some(CurvedVehicle {
                tangent: (*t)?,
                edgelets: e,
                vehicle: unit[i],
            })
        })
        .collect();
    edge::fit_curved(pp, width, height, &vehicles, roll, eo, opts.seed)
}

/// The trusted rays' fit of f as a cue: its bootstrap's 16th-84th percentiles.
fn trusted_rays(focal_px: f64, samples: Option<&Samples>) -> focal::Measured {
    let fs = samples.map_or(&[][..], |s| &s.focal_px[..]);
    let bootstrap_px = if fs.len() >= 2 {
        [percentile(fs.to_vec(), 16.0), percentile(fs.to_vec(), 84.0)]
    } else {
        [1.0, 1.0]
    };
    focal::Measured {
        name: "network",
        focal_px,
        bootstrap_px,
        turn: 0.0,
    }
}

/// The standard deviation of the resamples' horizon angles, degrees, measured as line angles
/// around `a0_deg` (angles near ±180° wrap).
fn horizon_sd_deg(b: &Samples, a0_deg: f64) -> f64 {
    let angles: Vec<f64> = b
        .horizon_deg
        .iter()
        .map(|a| line_angle_diff((a - a0_deg).to_radians()).to_degrees())
        .collect();
    sd(&angles)
}

/// The estimate's spread from the bootstrap's resamples `b`; `horizon_sd`: the roll's
/// ([`RollFrom::sd_deg`]); `edge_focal`: where an edgelet fit carried f, its bootstrap's 16th
/// and 84th percentiles of f.
fn confidence(
    b: &Samples,
    model: &Vp2Model,
    prep: &Prepared,
    horizon_sd: f64,
    edge_focal: Option<[f64; 2]>,
) -> Option<Confidence> {
    if b.focal_px.is_empty() {
        return None;
    }
    let data_only = Vp2Model {
        fixed_bias: Some(0.0),
        ..*model
    }
    .fit(&prep.weight, None)[0]
        .exp();
    // Where f is held (untrusted rays), all of this bootstrap's resamples agree.
    let [p16, p84] = edge_focal.unwrap_or_else(|| {
        [
            percentile(b.focal_px.clone(), 16.0),
            percentile(b.focal_px.clone(), 84.0),
        ]
    });
    Some(Confidence {
        focal_px_p16: p16,
        focal_px_p84: p84,
        horizon_angle_sd_deg: horizon_sd,
        // One VP1 per resample, and there is at least one.
        vp1_sd_px: ((half_p16_p84(&b.vp1_x).powi(2) + half_p16_p84(&b.vp1_y).powi(2)) / 2.0).sqrt(),
        focal_px_data_only: data_only,
        resamples: b.focal_px.len(),
    })
}
