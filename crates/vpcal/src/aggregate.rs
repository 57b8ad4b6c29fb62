//! Per-vehicle VP pairs to one camera: the aggregation methods, and what they report (a
//! summary line, counts as JSON, the bootstrap's confidence).

use vpcal_formats::calib::Confidence;
use vpcal_formats::reference::VpOutItem;
use vpcal_geom::aggregate::edgelets::Edgelet;
use vpcal_geom::aggregate::reference::{self, ReferenceOptions};
pub use vpcal_geom::aggregate::robust::Scene;
use vpcal_geom::aggregate::robust::{self, RobustOptions};
use vpcal_geom::aggregate::tracks::TrackLine;
use vpcal_geom::aggregate::{AggregateError, VehicleVps};
use vpcal_geom::Point2;

/// Aggregation method.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// Robust line intersection and focal fit (the paper's aggregation, made robust; the default). VP1 comes
    /// from the vehicles' tracks when enough boxes of successive frames link into straight
    /// tracks, else from the network's per-vehicle VP1 rays.
    Robust,
    /// The robust method with VP1 always from the network's per-vehicle VP1 rays.
    RobustNetwork,
    /// The paper's medians, exactly as the reference code computed them.
    Reference,
}

impl Method {
    /// Every method, by name (for flag parsers and help).
    pub const NAMES: [&'static str; 3] = ["robust", "robust-network", "reference"];

    pub fn name(self) -> &'static str {
        match self {
            Method::Robust => "robust",
            Method::RobustNetwork => "robust-network",
            Method::Reference => "reference",
        }
    }
}

impl std::str::FromStr for Method {
    type Err = String;

    fn from_str(s: &str) -> Result<Method, String> {
        match s {
            "robust" => Ok(Method::Robust),
            "robust-network" => Ok(Method::RobustNetwork),
            "reference" => Ok(Method::Reference),
            _ => Err(format!(
                "unknown aggregation method `{s}`: expected {}",
                Method::NAMES.join(", ")
            )),
        }
    }
}

/// Where a calibration's focal length came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FocalSource {
    /// The edgelets across the vehicles placed VP2 (the robust method).
    Edgelets,
    /// The network's VP2 rays and points agreed (the robust method trusted them).
    Network,
    /// The network's VP2 rays, which their points contradict, narrowed the physical prior
    /// to less than half its width (the robust method's `rays_focal_posterior`).
    NetworkRays,
    /// The scene's vertical lines placed VP3 (the robust method's `verticals`).
    Verticals,
    /// No evidence fixed it: the robust method's focal prior decided.
    Prior,
    /// The median of the per-vehicle focal lengths (the reference method).
    PerVehicle,
    /// Given by the user (`--focal`).
    Given,
}

impl FocalSource {
    pub fn name(self) -> &'static str {
        match self {
            FocalSource::Edgelets => "edgelets",
            FocalSource::Network => "network",
            FocalSource::NetworkRays => "network_rays",
            FocalSource::Verticals => "verticals",
            FocalSource::Prior => "prior",
            FocalSource::PerVehicle => "per_vehicle_median",
            FocalSource::Given => "given",
        }
    }

    /// Whether the focal length was assumed rather than measured.
    pub fn is_assumed(self) -> bool {
        self == FocalSource::Prior
    }
}

pub use vpcal_geom::aggregate::focal::TRAFFIC_FOV_DEG;

/// Model error of a measured focal length in `ln f` (the robust method's
/// `focal::MODEL_LOG_SD`, part of every geometric cue's likelihood).
pub use vpcal_geom::aggregate::focal::MODEL_LOG_SD as MEASURED_FOCAL_MODEL_LOG_SD;

/// The 68 % interval of a focal length nobody measured, for frames `width` pixels wide: the
/// central 68 % (16th to 84th percentile) of a distribution uniform in `ln f` over the focal
/// lengths of [`TRAFFIC_FOV_DEG`] (`f = (W / 2) / tan(fov / 2)`).
pub fn assumed_focal_interval(width: u32) -> [f64; 2] {
    let [short, long] =
        vpcal_geom::aggregate::focal::focal_prior_range_widths(None).map(|r| r * f64::from(width));
    range_focal_interval([short, long])
}

/// The central 68 % of a distribution uniform in `ln f` over `[short, long]` pixels
/// (`vpcal_geom::aggregate::focal::prior_percentiles`).
pub fn range_focal_interval(range_px: [f64; 2]) -> [f64; 2] {
    match vpcal_geom::aggregate::focal::prior_percentiles(range_px) {
        Some([lo, _, hi]) => [lo, hi],
        None => [f64::NAN, f64::NAN],
    }
}

/// Check a focal-length range `[short, long]` (pixels) given by the user.
///
/// # Errors
/// A message naming `--focal-range` and what was expected.
pub fn check_focal_range(range_px: [f64; 2]) -> Result<(), String> {
    let [short, long] = range_px;
    if short.is_finite() && long.is_finite() && 0.0 < short && short < long {
        Ok(())
    } else {
        Err(format!(
            "--focal-range {short},{long}: expected two positive numbers of pixels, the \
             shorter first (SHORT,LONG)"
        ))
    }
}

/// Check the user's focal-length settings: a valid `--focal-range`, and not both it and
/// `--focal`.
///
/// # Errors
/// A message naming the flags and what was expected.
pub fn check_focal_settings(
    focal_px: Option<f64>,
    range_px: Option<[f64; 2]>,
) -> Result<(), String> {
    let Some(range) = range_px else {
        return Ok(());
    };
    check_focal_range(range)?;
    if focal_px.is_some() {
        return Err(
            "--focal and --focal-range: give one (a known focal length, or the range it lies in)"
                .to_string(),
        );
    }
    Ok(())
}

/// The outcome of one aggregation: the two VPs and what to tell the user.
#[derive(Debug, Clone)]
pub struct Aggregated {
    pub vp1: Point2,
    pub vp2: Point2,
    pub focal_px: f64,
    pub summary: String,
    /// What the method used (counts), as JSON for calibration files.
    pub evidence: serde_json::Value,
    /// Bootstrap spread of the robust method (none without bootstrap or for `reference`).
    pub confidence: Option<Confidence>,
    /// The straight vehicle tracks the robust method found (empty for the other methods).
    pub track_lines: Vec<TrackLine>,
    /// Where the focal length came from.
    pub focal_source: FocalSource,
    /// The 68 % interval of the focal length, pixels: the bootstrap's when evidence gave it,
    /// [`assumed_focal_interval`] when it was assumed; `None` without either.
    pub focal_interval_px: Option<[f64; 2]>,
    /// The robust method's evidence (`None` for `reference`), for the warnings.
    pub robust_evidence: Option<robust::Evidence>,
    /// The camera's focal-length range the user gave (`--focal-range`), pixels.
    pub focal_range_px: Option<[f64; 2]>,
}

/// Above this median scatter of the network's VP1 rays around the VP1 they give (degrees),
/// a VP1 that rests on those rays alone (no tracks, no edgelets) is flagged: BoxCars-trained
/// CNNs scatter 1.2-2.9° on BrnoCompSpeed, and 5° is where the real-data network issue puts a
/// network that sees real vehicles; the bundled network scatters 8-21° on real clips.
pub const WEAK_VP1_RAY_SCATTER_DEG: f64 = 5.0;

/// The straight edgelet fit's focal length when the focal length came from the curved-road
/// fit and the two differ by more than two model errors ([`MEASURED_FOCAL_MODEL_LOG_SD`]):
/// the tracks that made the road count as curved may bend for another reason (box centres
/// drifting on the approaching vehicles, a slight bend far away), and nothing says which fit
/// is right. Only where the curved fit's focal length was used (`curved_focal`): where it
/// gave the horizon only, the focal length is another source's (or assumed).
fn straight_fit_disagreeing(e: &robust::Evidence, focal_px: f64) -> Option<f64> {
    let fs = e.edgelet_focal_px.filter(|f| f.is_finite() && *f > 0.0)?;
    (e.curved_fit
        && e.curved_focal
        && (focal_px / fs).ln().abs() > 2.0 * MEASURED_FOCAL_MODEL_LOG_SD)
        .then_some(fs)
}

use vpcal_formats::calib::FOCAL_WARNINGS;
pub use vpcal_geom::aggregate::robust::PARALLEL_EDGES_VP2_WIDTHS;

impl Aggregated {
    /// What the user should know about this calibration: that its focal length is assumed,
    /// when it is.
    pub fn warnings(&self) -> Vec<String> {
        let mut out = Vec::new();
        if let (FocalSource::Prior, Some([lo, hi])) = (self.focal_source, self.focal_interval_px) {
            let prior = match self.focal_range_px {
                Some(_) => "the middle of the given range",
                None => "the prior",
            };
            out.push(format!(
                "{} ({:.0} px from {prior}; plausible {lo:.0}-{hi:.0} px): distances and \
                 speeds carry its error; give the camera's focal length with --focal PX if it \
                 is known, or known lengths along and across the road to `vpcal scale`",
                FOCAL_WARNINGS[0], self.focal_px
            ));
        }
        if let (Some([a, b]), false) = (self.focal_range_px, self.focal_source.is_assumed()) {
            if !(a..=b).contains(&self.focal_px) {
                out.push(format!(
                    "{}{:.0} px, from {}) lies outside the given range {a:.0}-{b:.0} px: \
                     check the range, or the footage's evidence",
                    FOCAL_WARNINGS[1],
                    self.focal_px,
                    self.focal_source.name()
                ));
            }
        }
        let Some(e) = &self.robust_evidence else {
            return out;
        };
        if let Some(w) = self.weak_vp1_warning() {
            out.push(w);
        }
        if let Some(fs) = straight_fit_disagreeing(e, self.focal_px) {
            out.push(format!(
                "{} of {:.0} px, the straight-road fit of the same edges {fs:.0} px: the road \
                 may not be curved (or bends only far away); the focal interval spans both",
                FOCAL_WARNINGS[2], self.focal_px
            ));
        }
        if let Some(widths) = e
            .edgelet_vp2_widths
            .filter(|w| !e.focal_from_edgelets && (w.is_nan() || *w > PARALLEL_EDGES_VP2_WIDTHS))
        {
            out.push(format!(
                "the edges across the vehicles are parallel in the image (their VP2 lies {}): \
                 the camera looks along the road with a long lens, or straight down, and the \
                 focal length cannot be observed from them",
                widths_away(widths)
            ));
        }
        out
    }

    /// The warning of a VP1 that rests on the network's VP1 rays alone (no straight tracks, no
    /// edgelets along the vehicles, no lines of the scene) while they scatter more than
    /// [`WEAK_VP1_RAY_SCATTER_DEG`] around it; `None` otherwise.
    pub fn weak_vp1_warning(&self) -> Option<String> {
        let e = self.robust_evidence.as_ref()?;
        let scatter = e.vp1_ray_scatter_deg.filter(|s| {
            !e.vp1_from_tracks
                && !e.vp1_from_edgelets
                && !e.vp1_from_scene_lines
                && *s > WEAK_VP1_RAY_SCATTER_DEG
        })?;
        Some(format!(
            "VP1 rests on the network's VP1 rays alone ({} vehicles agree, their median angle \
             to it {scatter:.1}°; no straight vehicle tracks, no lines of the road): the road \
             direction, and everything measured from it, is weakly supported; use longer \
             footage of moving traffic",
            e.vp1_inliers
        ))
    }

    /// The warning of a road horizon that the scene's vertical lines contradict
    /// (`evidence.horizon_conflict_deg`); `None` otherwise.
    pub fn horizon_conflict_warning(&self) -> Option<String> {
        let e = self.robust_evidence.as_ref()?;
        let d = e.horizon_conflict_deg?;
        let own = e.verticals_roll_deg?;
        Some(format!(
            "the scene's vertical lines stand {own:+.1}° where the road's horizon is at \
             {:+.1}°: {d:+.1}° apart, more than a road's cross slope and the two measurements' \
             errors allow ({:.1} standard deviations): the road may not be one plane (a road \
             that climbs or falls as it curves) or the vehicles' cues mislead; the horizon's \
             spread takes the difference, and the focal length is assumed, since every cue \
             for it rests on that horizon; check the overlay, and give known distances along \
             and across the road (`vpcal scale`) or --focal for measurements",
            own - d,
            e.verticals_roll_z.unwrap_or(f64::NAN).abs()
        ))
    }

    /// The camera of this aggregation for principal point `pp`, with `focal_px` when the
    /// focal length is known (see [`Aggregated::with_focal`]).
    ///
    /// # Errors
    /// A given focal length that does not fit, or VPs that give no camera.
    pub fn into_camera(
        self,
        pp: Point2,
        focal_px: Option<f64>,
    ) -> Result<(vpcal_geom::camera::Calibration, Aggregated), String> {
        let agg = match focal_px {
            Some(f) => self.with_focal(f, pp)?,
            None => self,
        };
        let cal = vpcal_geom::camera::Calibration::from_vps(agg.vp1, agg.vp2, pp)
            .map_err(|e| format!("the aggregated vanishing points give no camera: {e}"))?;
        Ok((cal, agg))
    }

    /// The same aggregation with a known focal length: VP1 and the horizon stay, VP2 moves
    /// along the horizon to the point orthogonal to VP1 for `focal_px`.
    ///
    /// # Errors
    /// When `focal_px` is not a positive number or the horizon has no such point.
    pub fn with_focal(mut self, focal_px: f64, pp: Point2) -> Result<Aggregated, String> {
        if !(focal_px.is_finite() && focal_px > 0.0) {
            return Err(format!(
                "--focal {focal_px}: expected a positive number of pixels"
            ));
        }
        let horizon = vpcal_geom::Line::through(self.vp1, self.vp2)
            .ok_or("the aggregated VPs give no horizon")?;
        let vp2 = vpcal_geom::camera::orthogonal_vp_on_line(self.vp1, horizon, focal_px, pp)
            .ok_or("the horizon has no point orthogonal to VP1 for this focal length")?;
        self.summary.push_str(&format!(
            "; focal length given: {focal_px:.0} px (the evidence gave {:.0} px)",
            self.focal_px
        ));
        self.vp2 = vp2;
        self.focal_px = focal_px;
        self.focal_source = FocalSource::Given;
        self.focal_interval_px = Some([focal_px, focal_px]);
        Ok(self)
    }
}

/// The items' edgelets, one list per item; empty when no item has any (files of other tools).
pub fn edgelets_of(items: &[VpOutItem]) -> Vec<Vec<Edgelet>> {
    if items.iter().all(|i| i.edgelets.is_empty()) {
        return Vec::new();
    }
    items.iter().map(VpOutItem::edgelets).collect()
}

/// An optional angle for a summary line.
fn deg(a: Option<f64>) -> String {
    a.map_or("-".to_string(), |a| format!("{a:.2}°"))
}

/// "; the road curves (N tracks bend alike)" when the curved-road test set the tracks aside.
fn curved_note(e: &robust::Evidence) -> String {
    if e.curved_fit {
        format!(
            " (not used for VP1: the road curves, {} tracks bend alike; horizon and focal length \
             from the track tangents and edgelets of {} vehicles)",
            e.curved_tracks, e.curved_vehicles
        )
    } else if e.road_curved {
        format!(
            " (not used for VP1: the road curves, {} tracks bend alike)",
            e.curved_tracks
        )
    } else {
        String::new()
    }
}

/// What the scene's lines along the road did to VP1, for the summary.
fn scene_note(e: &robust::Evidence) -> String {
    match (e.vp1_from_scene_lines, e.vp1_scene_extra_deg) {
        (true, _) => format!(
            "; then moved {:.1} px to where {} edgelets of the scene's lines along the road meet",
            e.vp1_scene_shift_px.unwrap_or(0.0),
            e.vp1_scene_edgelets
        ),
        (false, Some(extra)) => format!(
            "; the scene's lines along the road meet elsewhere (the vehicles' lines {extra:+.1}° \
             there): not used"
        ),
        (false, None) => String::new(),
    }
}

/// Aggregate with `method`; `image_size` is used by the robust method's priors, `scene` (what
/// the scene's background shows; may be empty) by the robust methods' VP1 and focal length.
///
/// # Errors
/// "Not enough evidence" from the method.
#[allow(clippy::too_many_arguments)]
pub fn aggregate(
    vehicles: &[VehicleVps],
    edgelets: &[Vec<Edgelet>],
    scene: Scene,
    pp: Point2,
    image_size: (u32, u32),
    method: Method,
    min_score: f64,
    bootstrap: usize,
    focal_range_px: Option<[f64; 2]>,
) -> Result<Aggregated, AggregateError> {
    match method {
        Method::Reference => {
            let r = reference::aggregate(vehicles, pp, &ReferenceOptions { min_score })?;
            Ok(Aggregated {
                vp1: r.vp1,
                vp2: r.vp2,
                focal_px: r.focal_px,
                summary: format!(
                    "reference: {} vehicles, {} above score {min_score}, {} with a real focal length",
                    r.pairs_in, r.pairs_scored, r.pairs_used
                ),
                evidence: serde_json::json!({
                    "method": "reference",
                    "pairs_in": r.pairs_in,
                    "pairs_scored": r.pairs_scored,
                    "pairs_used": r.pairs_used,
                }),
                confidence: None,
                track_lines: Vec::new(),
                focal_source: FocalSource::PerVehicle,
                focal_interval_px: None,
                robust_evidence: None,
                focal_range_px,
            })
        }
        Method::Robust | Method::RobustNetwork => {
            let defaults = RobustOptions::default();
            let width = f64::from(image_size.0);
            let options = RobustOptions {
                min_score,
                image_size: Some([width, f64::from(image_size.1)]),
                focal_range_widths: focal_range_px.map(|r| r.map(|f| f / width)),
                focal_prior_ratio: focal_range_px
                    .map_or(defaults.focal_prior_ratio, |[a, b]| (a * b).sqrt() / width),
                bootstrap,
                tracks: defaults.tracks.clone().filter(|_| method == Method::Robust),
                ..defaults
            };
            let r = robust::aggregate_with_scene(vehicles, edgelets, scene, pp, &options)?;
            let e = &r.evidence;
            let mut summary = format!(
                "robust: {} vehicles, {} used (effective weight {:.0}, {} repeated boxes down-weighted), \
                 {} VP1 inliers ({}{}), {} VP2 inliers, roll {:.2}°, {}",
                e.pairs_in,
                e.pairs_used,
                e.effective_vehicles,
                e.repeated_boxes,
                e.vp1_inliers,
                if e.vp1_from_tracks {
                    format!(
                        "VP1 from {} vehicle tracks, median angle {}; the network's rays {}",
                        e.track_lines,
                        deg(e.track_residual_deg),
                        deg(e.vp1_ray_scatter_deg)
                    )
                } else if e.vp1_from_edgelets {
                    format!(
                        "VP1 from {} edgelets along the vehicles; the network's rays {}, {} straight vehicle tracks{}",
                        e.vp1_edgelets,
                        deg(e.vp1_ray_scatter_deg),
                        e.track_lines,
                        curved_note(e)
                    )
                } else {
                    format!(
                        "VP1 from the network's rays, median angle {}; {} straight vehicle tracks, {}{}",
                        deg(e.vp1_ray_scatter_deg),
                        e.track_lines,
                        deg(e.track_residual_deg),
                        curved_note(e)
                    )
                },
                scene_note(e),
                e.vp2_inliers,
                r.roll.to_degrees(),
                {
                    let rays = if e.rays_trusted {
                        "VP2 points agree with the rays (data trusted)"
                    } else {
                        "VP2 points disagree with the rays (points not used)"
                    };
                    let edges = format!("{} edgelets on {} vehicles", e.edgelets, e.edgelet_vehicles);
                    if e.focal_from_edgelets {
                        format!("roll and focal length from {edges}")
                    } else if e.roll_from_edgelets {
                        format!("roll from {edges} (VP2 too far for the focal length); {rays}")
                    } else if e.edgelets > 0 {
                        format!("{rays}; {edges} not used (roll ±{})", deg(e.edgelet_roll_sd_deg))
                    } else {
                        rays.to_string()
                    }
                }
            );
            // The focal length is the posterior of the prior and every cue
            // (`vpcal_geom::aggregate::focal`): measured when the cues carry at least the
            // prior's information, named after the cue that carried most.
            let focal = &r.focal;
            let focal_source = match focal.carried_by.first().copied() {
                Some("edgelets" | "curved_edgelets") => FocalSource::Edgelets,
                Some("network") => FocalSource::Network,
                Some("network_rays") => FocalSource::NetworkRays,
                Some("verticals") => FocalSource::Verticals,
                _ => FocalSource::Prior,
            };
            let prior_name = match focal_range_px {
                Some([a, b]) => format!("the given {a:.0}-{b:.0} px range"),
                None => format!("the {}-{}° prior", TRAFFIC_FOV_DEG[0], TRAFFIC_FOV_DEG[1]),
            };
            let cue_note = |c: &vpcal_geom::aggregate::focal::CueReport| {
                let [lo, hi] = c.interval_px;
                let what = cue_words(c.source);
                if c.used {
                    format!(
                        "{what} {:.0} px (with the prior {lo:.0}-{hi:.0}, {:.0} % of the \
                         evidence)",
                        c.focal_px,
                        100.0 * c.share
                    )
                } else {
                    format!(
                        "{what} {:.0} px (contradicts {}: not used)",
                        c.focal_px,
                        contradicted_words(c.contradicts)
                    )
                }
            };
            let cues: Vec<String> = focal.cues.iter().map(cue_note).collect();
            let cues = if cues.is_empty() {
                "no cue applies".to_string()
            } else {
                cues.join(", ")
            };
            let [lo, hi] = focal.interval_px;
            if focal_source.is_assumed() {
                summary.push_str(&format!(
                    "; focal length ASSUMED ({:.0} px: {prior_name}, the evidence too weak to \
                     measure it: {cues}; 68% interval {lo:.0}-{hi:.0} px)",
                    r.calibration.focal_px
                ));
            } else {
                summary.push_str(&format!(
                    "; focal length {:.0} px from {} within {prior_name} ({cues}; 68% \
                     interval {lo:.0}-{hi:.0} px)",
                    r.calibration.focal_px,
                    focal
                        .carried_by
                        .iter()
                        .map(|s| cue_words(s))
                        .collect::<Vec<_>>()
                        .join(" and ")
                ));
            }
            // A curved-road fit that the straight fit contradicts: either may be right, so the
            // interval spans both.
            let focal_interval_px =
                Some(match straight_fit_disagreeing(e, r.calibration.focal_px) {
                    Some(fs) => [lo.min(fs), hi.max(fs)],
                    None => [lo, hi],
                });
            if let Some(c) = &r.confidence {
                // Rays that put VP2 at infinity give absurd focal lengths: say so instead.
                let alone = c.focal_px_data_only;
                let alone = if alone.is_finite() && alone <= 1000.0 * f64::from(image_size.0) {
                    format!("{alone:.0} px")
                } else {
                    "VP2 at infinity".to_string()
                };
                summary.push_str(&format!(
                    " (VP2 rays alone: {alone}), horizon ±{:.2}°",
                    c.horizon_angle_sd_deg
                ));
            }
            let focal_cues: Vec<serde_json::Value> = r
                .focal
                .cues
                .iter()
                .map(|c| {
                    serde_json::json!({
                        "source": c.source,
                        "focal_px": c.focal_px,
                        "interval_px": c.interval_px,
                        "share": c.share,
                        "used": c.used,
                        "contradicts": c.contradicts,
                    })
                })
                .collect();
            let mut evidence = serde_json::json!({
                "method": method.name(),
                "pairs_in": e.pairs_in,
                "pairs_used": e.pairs_used,
                "effective_vehicles": e.effective_vehicles,
                "repeated_boxes": e.repeated_boxes,
                "vp1_inliers": e.vp1_inliers,
                "vp2_inliers": e.vp2_inliers,
                "rays_trusted": e.rays_trusted,
                "track_lines": e.track_lines,
                "vp1_from_tracks": e.vp1_from_tracks,
                "vp1_ray_scatter_deg": e.vp1_ray_scatter_deg,
                "track_residual_deg": e.track_residual_deg,
                "curved_tracks": e.curved_tracks,
                "road_curved": e.road_curved,
                "curved_fit": e.curved_fit,
                "curved_focal": e.curved_focal,
                "curved_vehicles": e.curved_vehicles,
                "vp1_from_edgelets": e.vp1_from_edgelets,
                "vp1_edgelets": e.vp1_edgelets,
                "vp1_from_scene_lines": e.vp1_from_scene_lines,
                "vp1_scene_edgelets": e.vp1_scene_edgelets,
                "vp1_scene_shift_px": e.vp1_scene_shift_px,
                "vp1_scene_extra_deg": e.vp1_scene_extra_deg,
                "edgelets": e.edgelets,
                "edgelet_vehicles": e.edgelet_vehicles,
                "roll_from_edgelets": e.roll_from_edgelets,
                "focal_from_edgelets": e.focal_from_edgelets,
                "edgelet_focal_px": e.edgelet_focal_px,
                "edgelet_roll_sd_deg": e.edgelet_roll_sd_deg,
                "edgelet_focal_log_spread": e.edgelet_focal_log_spread,
                "edgelet_vp2_widths": e.edgelet_vp2_widths,
                "edgelet_focal_bias_log_spread": e.edgelet_focal_bias_log_spread,
                "roll_deg": r.roll.to_degrees(),
                "ray_bias_deg": r.ray_bias.to_degrees(),
                "rays_focal_px": e.rays_focal_px,
                "rays_scatter_deg": e.rays_scatter_deg,
                "rays_vp2_sd_deg": e.rays_vp2_sd_deg,
                "rays_focal_posterior_p16_p50_p84_px": e.rays_posterior_px,
                "focal_from_rays": e.focal_from_rays,
                "bootstrap_focal_p16_p84_px": r
                    .confidence
                    .as_ref()
                    .map(|c| [c.focal_px_p16, c.focal_px_p84]),
                "vp2_rays_only_focal_px": r.confidence.as_ref().map(|c| c.focal_px_data_only),
            });
            let more = [
                (
                    "edgelet_roll_turn_sd_deg",
                    serde_json::json!(e.edgelet_roll_turn_sd_deg),
                ),
                (
                    "edgelet_roll_vp1_sd_deg",
                    serde_json::json!(e.edgelet_roll_vp1_sd_deg),
                ),
                ("edgelet_roll_deg", serde_json::json!(e.edgelet_roll_deg)),
                ("rays_roll_own_deg", serde_json::json!(e.rays_roll_own_deg)),
                ("rays_roll_sd_deg", serde_json::json!(e.rays_roll_sd_deg)),
                (
                    "rays_roll_sampling_sd_deg",
                    serde_json::json!(e.rays_roll_sampling_sd_deg),
                ),
                // The scene's vertical lines (`vpcal_geom::aggregate::verticals`).
                (
                    "vertical_candidates",
                    serde_json::json!(e.vertical_candidates),
                ),
                (
                    "vertical_supporting",
                    serde_json::json!(e.vertical_supporting),
                ),
                (
                    "verticals_focal_px",
                    serde_json::json!(e.verticals_focal_px),
                ),
                (
                    "focal_from_verticals",
                    serde_json::json!(e.focal_from_verticals),
                ),
                (
                    "verticals_roll_deg",
                    serde_json::json!(e.verticals_roll_deg),
                ),
                (
                    "verticals_roll_sd_deg",
                    serde_json::json!(e.verticals_roll_sd_deg),
                ),
                ("verticals_roll_z", serde_json::json!(e.verticals_roll_z)),
                (
                    "horizon_conflict_deg",
                    serde_json::json!(e.horizon_conflict_deg),
                ),
                ("focal_sources", serde_json::json!(r.focal.carried_by)),
                ("focal_cues", serde_json::Value::Array(focal_cues)),
            ];
            if let Some(o) = evidence.as_object_mut() {
                for (key, value) in more {
                    o.insert(key.into(), value);
                }
            }
            let confidence = r.confidence.as_ref().map(|c| Confidence {
                horizon_angle_sd_deg: c.horizon_angle_sd_deg,
                vp1_sd_px: c.vp1_sd_px,
                resamples: c.resamples,
            });
            Ok(Aggregated {
                vp1: r.calibration.vp1,
                vp2: r.calibration.vp2,
                focal_px: r.calibration.focal_px,
                summary,
                evidence,
                confidence,
                track_lines: r.track_lines,
                focal_source,
                focal_interval_px,
                robust_evidence: Some(r.evidence),
                focal_range_px,
            })
        }
    }
}

/// What a cue left out of the focal posterior contradicts, in words.
pub fn contradicted_words(against: Option<&str>) -> &str {
    match against {
        None | Some("prior") => "the prior",
        Some(source) => cue_words(source),
    }
}

/// A focal cue's name (`evidence.focal_cues[].source`) in words.
fn cue_words(source: &str) -> &str {
    match source {
        "edgelets" => "the edges across the vehicles",
        "curved_edgelets" => "the curved-road fit",
        "network" => "the network's VP2 points and rays",
        "network_rays" => "the network's VP2 rays",
        "verticals" => "the scene's vertical lines",
        other => other,
    }
}

/// How far a vanishing point lies, in image widths, in words: a number up to a thousand,
/// beyond that "more than a thousand image widths away" (the difference is no longer
/// measurable: the edges are parallel).
pub fn widths_away(widths: f64) -> String {
    if widths.is_finite() && widths <= 1000.0 {
        format!("{widths:.0} image widths away")
    } else {
        "more than a thousand image widths away, at infinity for all purposes".to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with_evidence(focal_source: FocalSource, e: robust::Evidence) -> Aggregated {
        Aggregated {
            vp1: Point2::new(100.0, 50.0),
            vp2: Point2::new(5000.0, 80.0),
            focal_px: 1000.0,
            summary: String::new(),
            evidence: serde_json::Value::Null,
            confidence: None,
            track_lines: Vec::new(),
            focal_source,
            focal_interval_px: Some([900.0, 1100.0]),
            robust_evidence: Some(e),
            focal_range_px: None,
        }
    }

    #[test]
    fn a_measured_focal_length_outside_the_given_range_is_flagged() {
        let outside = |source: FocalSource, range: [f64; 2]| {
            let a = Aggregated {
                focal_range_px: Some(range),
                ..with_evidence(source, robust::Evidence::default())
            };
            a.warnings()
                .iter()
                .any(|w| w.contains("outside the given range"))
        };
        // f is 1000 px.
        assert!(outside(FocalSource::Edgelets, [1500.0, 2500.0]));
        assert!(outside(FocalSource::NetworkRays, [400.0, 900.0]));
        assert!(!outside(FocalSource::Edgelets, [800.0, 1200.0]));
        // An assumed focal length is the range's own middle: nothing to flag.
        assert!(!outside(FocalSource::Prior, [1500.0, 2500.0]));
        assert!(FocalSource::NetworkRays.name() == "network_rays");
        assert!(!FocalSource::NetworkRays.is_assumed());
    }

    #[test]
    fn a_vp1_from_scattered_rays_alone_is_flagged_and_one_from_tracks_is_not() {
        let weak = robust::Evidence {
            vp1_ray_scatter_deg: Some(12.8),
            vp1_inliers: 10,
            ..robust::Evidence::default()
        };
        let w = with_evidence(FocalSource::Edgelets, weak).warnings();
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(w[0].contains("12.8°") && w[0].contains("VP1"), "{w:?}");
        for strong in [
            robust::Evidence {
                vp1_from_tracks: true,
                ..weak
            },
            robust::Evidence {
                vp1_from_edgelets: true,
                ..weak
            },
            robust::Evidence {
                vp1_ray_scatter_deg: Some(WEAK_VP1_RAY_SCATTER_DEG - 0.1),
                ..weak
            },
        ] {
            let w = with_evidence(FocalSource::Edgelets, strong).warnings();
            assert!(w.is_empty(), "{strong:?}: {w:?}");
        }
    }

    #[test]
    fn a_horizon_the_plumb_lines_contradict_fails_the_horizon_check() {
        let e = robust::Evidence {
            verticals_roll_deg: Some(-0.4),
            verticals_roll_z: Some(-5.4),
            horizon_conflict_deg: Some(-8.8),
            ..robust::Evidence::default()
        };
        let a = with_evidence(FocalSource::Edgelets, e);
        let w = a.horizon_conflict_warning().unwrap();
        assert!(
            w.contains("-0.4°") && w.contains("+8.4°") && w.contains("5.4 standard"),
            "{w}"
        );
        let found = crate::plausible::check_horizon(&a);
        assert_eq!(found.len(), 1);
        assert_eq!(found[0].status, vpcal_formats::calib::Status::Unreliable);
        assert_eq!(found[0].check, crate::plausible::HORIZON_CHECK);
        // The plumb lines' own roll identified and agreeing: no finding.
        let agree = with_evidence(
            FocalSource::Edgelets,
            robust::Evidence {
                horizon_conflict_deg: None,
                verticals_roll_z: Some(0.7),
                ..e
            },
        );
        assert!(agree.horizon_conflict_warning().is_none());
        assert!(crate::plausible::check_horizon(&agree).is_empty());
    }

    #[test]
    fn a_curved_fit_that_the_straight_fit_contradicts_is_flagged() {
        let curved = |straight: f64| robust::Evidence {
            curved_fit: true,
            curved_focal: true,
            vp1_from_tracks: true,
            edgelet_focal_px: Some(straight),
            ..robust::Evidence::default()
        };
        // focal_px is 1000 in `with_evidence`.
        let w = with_evidence(FocalSource::Edgelets, curved(300.0)).warnings();
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(w[0].contains("300 px"), "{w:?}");
        assert!(with_evidence(FocalSource::Edgelets, curved(1200.0))
            .warnings()
            .is_empty());
        let straight = robust::Evidence {
            curved_fit: false,
            ..curved(300.0)
        };
        assert!(with_evidence(FocalSource::Edgelets, straight)
            .warnings()
            .is_empty());
        // The curved fit gave the horizon only: the focal length is not its to contradict.
        let horizon_only = robust::Evidence {
            curved_focal: false,
            ..curved(300.0)
        };
        assert!(with_evidence(FocalSource::Prior, horizon_only)
            .warnings()
            .iter()
            .all(|w| !w.contains("curved-road fit")));
    }

    #[test]
    fn parallel_edges_say_the_focal_length_cannot_be_observed() {
        let far = |widths: f64| robust::Evidence {
            edgelet_vp2_widths: Some(widths),
            vp1_from_tracks: true,
            ..robust::Evidence::default()
        };
        let w = with_evidence(FocalSource::Prior, far(5e9)).warnings();
        assert_eq!(w.len(), 2, "{w:?}");
        assert!(
            w[0].contains("assumed") && w[1].contains("parallel"),
            "{w:?}"
        );
        // An absurd distance is not printed as a number.
        assert!(w[1].contains("more than a thousand image widths"), "{w:?}");
        let w = with_evidence(FocalSource::Prior, far(f64::INFINITY)).warnings();
        assert!(w[1].contains("at infinity"), "{w:?}");
        // A VP2 within reach says nothing of the kind.
        let w = with_evidence(FocalSource::Prior, far(12.0)).warnings();
        assert_eq!(w.len(), 1, "{w:?}");
    }

    #[test]
    fn the_assumed_interval_is_the_middle_of_the_traffic_camera_range() {
        // f of a 90° view is W/2, of a 15° view 3.80 W; the middle 68 % in ln f.
        let [lo, hi] = assumed_focal_interval(1000);
        let (f90, f15) = (500.0f64, 500.0 / 7.5f64.to_radians().tan());
        let ln = |f: f64| f.ln();
        assert!((ln(lo) - (ln(f90) + 0.16 * (ln(f15) - ln(f90)))).abs() < 1e-12);
        assert!((ln(hi) - (ln(f90) + 0.84 * (ln(f15) - ln(f90)))).abs() < 1e-12);
        // Python: exp(ln 500 + q ln(3797.88 / 500)) for q = 0.16, 0.84 -> 691.61, 2745.68.
        assert!(
            (lo - 691.61).abs() < 0.01 && (hi - 2745.68).abs() < 0.01,
            "{lo} {hi}"
        );
    }
}
