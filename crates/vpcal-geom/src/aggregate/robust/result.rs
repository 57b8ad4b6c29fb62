//! What the robust aggregation returns: the camera ([`RobustResult`]), the evidence each
//! stage recorded ([`Evidence`]) and the bootstrap's spread ([`Confidence`]).

use crate::aggregate::focal::FocalPosterior;
use crate::aggregate::tracks::TrackLine;
use crate::camera::Calibration;

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
    /// ([`edge::fit_curved`](crate::aggregate::edgelets::fit_curved): each car's own VP1 from its track's tangent), and on how many
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
    /// ([`scene_lines`](crate::aggregate::scene_lines)), on how many edgelets, and by how far (pixels).
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
    /// ([`RaysRoll`](crate::aggregate::rays::RaysRoll)); the roll is `roll_deg` unless the edgelets or
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
    /// for their VP2 ([`RAY_SYSTEMATIC_PER_SCATTER`](crate::aggregate::rays::RAY_SYSTEMATIC_PER_SCATTER) times that, degrees), and the 16th,
    /// 50th and 84th percentiles of the focal length under the physical prior and that
    /// evidence alone ([`rays_focal_posterior`](crate::aggregate::rays::rays_focal_posterior)).
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
    /// The scene's vertical lines ([`verticals`](crate::aggregate::verticals)): the segments that could be verticals and
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
