//! The robust aggregation's settings ([`RobustOptions`]): one field per decision of the fusion
//! core, and the settings of each evidence source it runs.

use crate::aggregate::edgelets::EdgeletFitOptions;
use crate::aggregate::focal::physical_focal_prior;
use crate::aggregate::rays::RayOptions;
use crate::aggregate::scene_lines::SceneLineOptions;
use crate::aggregate::tracks::{CurveTest, TrackOptions};
use crate::aggregate::vehicles::Weighting;
use crate::aggregate::verticals::VerticalOptions;
use crate::aggregate::vp1::Vp1Choice;

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
    /// from its data sheet), replacing [`TRAFFIC_FOV_DEG`](crate::aggregate::focal::TRAFFIC_FOV_DEG) as the prior's range (uniform in
    /// `ln f`); `focal_prior_ratio` should then be its geometric middle.
    #[serde(default)]
    pub focal_range_widths: Option<[f64; 2]>,
    /// The physical prior on the horizon's angle: level, with this standard deviation
    /// (degrees), against which the network's rays' own roll is weighed
    /// ([`RaysRoll`](crate::aggregate::rays::RaysRoll)). Measured on real traffic cameras: the 12
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
    /// above `curved_bend_t`, [`TrackLine::bend_t`](crate::aggregate::tracks::TrackLine::bend_t)) and by more than `curved_bend_deg`
    /// ([`TrackLine::bend_deg`](crate::aggregate::tracks::TrackLine::bend_deg)): on a curve every car has its own heading, so lines fitted to
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
    /// `curved_max_se_deg` ([`TrackLine::bend_se_deg`](crate::aggregate::tracks::TrackLine::bend_se_deg)). The motion detector's boxes jitter:
    /// its long tracks on the suite's curves have standard errors of 1.2-1.7°, where exact
    /// boxes have 0.1-0.6°, so 2° (with 3 tracks) lets 6-s clips of two of the three curves
    /// tell; the share and the t-statistic still keep the straight roads straight. Where
    /// at least `min_track_lines` straight tracks meet at no one VP1, this many bent ones
    /// make the road curved whatever their share: the road curves through part of the view
    /// (two of four unseen rendered curves, docs/accuracy.md §32).
    pub min_curved_tracks: usize,
    pub curved_max_se_deg: f64,
    /// Fit the horizon's roll (and, where VP2 is near enough, the focal length) to edgelets
    /// inside the vehicle boxes when they are given ([`aggregate_with_edgelets`](super::aggregate_with_edgelets)); `None`:
    /// never.
    pub edgelets: Option<EdgeletFitOptions>,
    /// Move VP1 to where the scene's lines along the road meet ([`scene_lines`](crate::aggregate::scene_lines)) when the
    /// scene's edgelets are given ([`aggregate_with_scene`](super::aggregate_with_scene)) and the road is straight; `None`:
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
    /// Measure the focal length from the scene's vertical lines ([`verticals`](crate::aggregate::verticals)) when its line
    /// segments are given ([`Scene::segments`](super::Scene::segments)); `None`: never.
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
    pub(super) fn weighting(&self) -> Weighting {
        Weighting {
            min_score: self.min_score,
            duplicate_iou: self.duplicate_iou,
            duplicate_keep: self.duplicate_keep,
            min_box_fraction: self.min_box_fraction,
        }
    }

    /// When the tracks say the road curves.
    pub(super) fn curve_test(&self) -> CurveTest {
        CurveTest {
            bend_t: self.curved_bend_t,
            bend_deg: self.curved_bend_deg,
            share: self.curved_share,
            min_tracks: self.min_curved_tracks,
            max_se_deg: self.curved_max_se_deg,
        }
    }

    /// Which lines VP1 is fitted to.
    pub(super) fn vp1_choice(&self) -> Vp1Choice {
        Vp1Choice {
            vp1_threshold_deg: self.vp1_threshold_deg,
            min_track_lines: self.min_track_lines,
            track_threshold_deg: self.track_threshold_deg,
            track_above_scatter_deg: self.track_above_scatter_deg,
            track_residual_ratio: self.track_residual_ratio,
        }
    }

    /// The horizon model's settings.
    pub(super) fn ray_options(&self) -> RayOptions {
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
