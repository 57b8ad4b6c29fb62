//! Self-labelled training crops from real footage (`vpcal label`).
//!
//! BoxCars116k, the paper's training set, was labelled automatically: each camera was
//! calibrated (Dubská et al.) and every vehicle seen by it got that camera's VPs. This module
//! does the same with any footage of a straight road:
//!
//! ```text
//! footage -> pipeline + robust aggregation (VP1 from straight tracks, horizon roll and f from
//!   edgelets or the prior) -> gates (refuse what cannot be labelled confidently)
//!   -> tracks of moving vehicles that head for VP1 -> every vehicle box on them gets the
//!   camera's VP1 and VP2 -> crops with a margin, VPs in crop pixels, label weights
//! ```
//!
//! - **Why one VP pair serves every vehicle**: on a straight road every vehicle drives along
//!   it, so its length axis is the road's direction (VP1) and its axle axis the road's
//!   horizontal cross direction (VP2). A vehicle that changes lanes or turns is not: tracks
//!   whose line misses VP1 by more than [`LabelSettings::max_track_angle_deg`] are dropped.
//! - **Gates** (a refusal names the first that failed): the camera calibrates; VP1 comes from
//!   at least [`LabelSettings::min_track_lines`] straight tracks that agree to
//!   [`LabelSettings::max_track_residual_deg`]; the road is not called curved; the horizon's
//!   spread (`confidence.horizon_angle_sd_deg`: the edgelets', or the rays' roll under its
//!   physical prior of 2°, which is always below this gate, so there the labels' weights
//!   carry it) is at most [`LabelSettings::max_horizon_sd_deg`]. The input must be
//!   consecutive frames (a video, or a folder with `--fps`): stills have no tracks.
//! - **Cameras whose vehicles do not share one VP1** (curves, intersections, roads whose
//!   straight tracks agree worse than the gate; refused above only for want of one VP1 shared
//!   by the straight tracks): a moving point of a vehicle draws in the image a curve whose
//!   tangent passes through the VP of its heading, which, as every ground direction's, lies on
//!   the horizon. So a vehicle's own VP1 is its track's tangent at the box ([`local_tangent`],
//!   over a window that travels [`LabelSettings::min_tangent_span_heights`] box heights) met
//!   with the horizon, and its VP2 the point of the horizon orthogonal to it for the camera's
//!   focal length. These need only a confident horizon (the last gate above); their VP1
//!   uncertainty is the tangent's standard error and [`TANGENT_FLOOR_DEG`], measured on the
//!   cameras that pass the straight-road gates, where every moving track's tangent is checked
//!   against the camera's VP1 (`tangent_check_deg` in the report). On those cameras a track
//!   that misses VP1 is not labelled: there it is far more often a tracking error or an
//!   occlusion than a vehicle changing lanes.
//! - **Label quality** ([`label_uncertainty`]): the direction of each label at the box centre
//!   is uncertain by `sd1` for VP1 (the median angle of the straight tracks to VP1: how well
//!   one track's heading is known; VP1's bootstrap spread in pixels is not used, since for a
//!   distant VP1 it lies along the line of sight and hardly turns the direction) and
//!   `sd2` for VP2 (how far the VP2 direction turns across the focal length's 68 % interval,
//!   and the horizon's roll spread). An assumed focal length has a wide interval, so near VP2s
//!   get low weights, far ones (nearly the horizon's direction whatever f) keep theirs. The
//!   loss weight is `1 / (1 + (sd / sd0)²)` with `sd0` = [`LABEL_SD0_DEG`].
//! - **Crops**: the detector's box grown by [`LabelSettings::margin`] on each side (the
//!   training augmentation warps the crop and cuts the box again, so it needs pixels around
//!   it), clamped to the frame, JPEG. The sample's "3D box" is the detector's box as a flat
//!   rectangle (both faces): its hull is the box the network sees at inference.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use serde::Serialize;
use vpcal_geom::aggregate::tracks::{link, Axis, TrackOptions};
use vpcal_geom::camera::{orthogonal_vp_on_line, Calibration};
use vpcal_geom::{BoxPx, Line, Point2};
use vpcal_synth::{RealMeta, SampleMeta, SampleRecord};

use crate::aggregate::Aggregated;
use crate::detector::is_stills;
use crate::pipeline::{calibrate, open_input, run_pipeline, PipelineConfig, VehicleRecord};
use crate::progress::Progress;

/// Label direction uncertainty (degrees) at which a sample's loss weight is one half: about
/// the per-vehicle direction error of the paper's BoxCars-trained networks on good detections
/// (1-2.5°), so a label counts fully only when it is better than what the network can learn.
pub const LABEL_SD0_DEG: f64 = 2.0;

/// The part of a track tangent's direction error that its fit does not show, degrees: the box
/// centre is not one point of the vehicle (it drifts over the body as the view turns, occluders
/// cut the box, the detector's box jitters). Measured with `vpcal label --every 2` on the six
/// corpus cameras that pass the straight-road gates: every moving track's tangent misses the
/// camera's VP1 by a median of 0.74, 0.92, 1.00, 1.24, 1.59 and 3.13° (`tangent_check_deg`;
/// the last a dense telephoto queue), median 1.12°, the median absolute value of a normal
/// error of 1.7°; less the fits' own standard errors (about 0.6°), 1.5°.
pub const TANGENT_FLOOR_DEG: f64 = 1.5;

/// Multiples of [`LabelSettings::tangent_half`] a tangent's window grows through until it
/// travels [`LabelSettings::min_tangent_span_heights`] box heights.
const TANGENT_HALVES: [usize; 5] = [1, 2, 3, 5, 8];

/// `format` of the `config.json` that `vpcal label` writes.
pub const LABEL_FORMAT: &str = "vpcal-real-crops";

/// What is labelled, and how strictly.
#[derive(Debug, Clone, PartialEq)]
pub struct LabelSettings {
    /// Straight tracks needed for VP1.
    pub min_track_lines: usize,
    /// The straight tracks must point at VP1 to this median angle, degrees.
    pub max_track_residual_deg: f64,
    /// Largest spread of the horizon's angle (the calibration's `horizon_angle_sd_deg`),
    /// degrees.
    pub max_horizon_sd_deg: f64,
    /// Boxes a vehicle track needs.
    pub min_track_boxes: usize,
    /// A track whose line misses VP1 by more than this (degrees) is not driving along the road.
    pub max_track_angle_deg: f64,
    /// A track must travel this many times its median box height (parked cars, false boxes).
    pub min_travel_heights: f64,
    /// Smallest box height, pixels (smaller crops carry little).
    pub min_box_height_px: f64,
    /// Boxes within this many pixels of the frame border are cut off: not labelled.
    pub border_px: f64,
    /// At most this many crops per track, evenly spaced along it (neighbouring frames are
    /// nearly the same picture).
    pub max_per_track: usize,
    /// Label the vehicles of cameras without one VP1 shared by straight tracks (curves,
    /// intersections) by their tracks' tangents when the horizon is confident.
    pub tangents: bool,
    /// Boxes on each side of a box that its track's tangent is fitted over, at least (more, up
    /// to 8 times as many, until the window travels `min_tangent_span_heights`).
    pub tangent_half: usize,
    /// Largest standard error of a tangent's direction (degrees) for its box to be labelled.
    pub max_tangent_sd_deg: f64,
    /// A tangent's window must travel this many box heights.
    pub min_tangent_span_heights: f64,
    /// Margin added on each side of the box, in box sizes.
    pub margin: f64,
    /// JPEG quality of the crops.
    pub jpeg_quality: u8,
}

impl Default for LabelSettings {
    fn default() -> LabelSettings {
        LabelSettings {
            min_track_lines: 5,
            max_track_residual_deg: 1.0,
            max_horizon_sd_deg: 2.0,
            min_track_boxes: 5,
            max_track_angle_deg: 2.0,
            min_travel_heights: 1.0,
            min_box_height_px: 24.0,
            border_px: 2.0,
            max_per_track: 12,
            tangents: true,
            tangent_half: 3,
            max_tangent_sd_deg: 1.5,
            min_tangent_span_heights: 2.0,
            margin: 0.2,
            jpeg_quality: 92,
        }
    }
}

/// One camera's labelling: what was obtained, how consistent its labels are, or why it was
/// refused.
#[derive(Debug, Clone, Serialize)]
pub struct CameraReport {
    pub camera: String,
    pub source: String,
    /// Why the footage was not labelled (`None` when it was).
    pub refused: Option<String>,
    pub frames: u64,
    pub boxes: usize,
    /// Tracks of at least `min_track_boxes` boxes, and of those the moving ones that head for
    /// VP1 (the labelled vehicles).
    pub tracks: usize,
    pub vehicles: usize,
    /// Of the labelled vehicles, those labelled by their track's tangent.
    pub tangent_vehicles: usize,
    pub crops: usize,
    /// On a camera that passes the straight-road gates: the median angle between every moving
    /// track's tangent (where one would be labelled) and the line to the camera's VP1, degrees.
    /// On a straight road nearly every vehicle drives along it, so this is the tangent labels'
    /// own error, tracking errors and occlusions included.
    pub tangent_check_deg: Option<f64>,
    /// Why the camera's straight tracks did not take its VPs, when every vehicle was labelled
    /// by its track's tangent instead.
    pub tangents_only: Option<String>,
    /// The camera's own consistency.
    pub track_lines: Option<u64>,
    pub track_residual_deg: Option<f64>,
    pub horizon_sd_deg: Option<f64>,
    pub focal_px: Option<f64>,
    pub focal_source: Option<String>,
    pub focal_interval_px: Option<[f64; 2]>,
    /// Medians over the crops of the label uncertainties and weights.
    pub vp1_sd_deg: Option<f64>,
    pub vp2_sd_deg: Option<f64>,
    pub label_weight: Option<[f64; 2]>,
}

impl CameraReport {
    fn new(camera: &str, source: &Path) -> CameraReport {
        CameraReport {
            camera: camera.to_string(),
            source: source.display().to_string(),
            refused: None,
            frames: 0,
            boxes: 0,
            tracks: 0,
            vehicles: 0,
            tangent_vehicles: 0,
            crops: 0,
            tangent_check_deg: None,
            tangents_only: None,
            track_lines: None,
            track_residual_deg: None,
            horizon_sd_deg: None,
            focal_px: None,
            focal_source: None,
            focal_interval_px: None,
            vp1_sd_deg: None,
            vp2_sd_deg: None,
            label_weight: None,
        }
    }
}

/// The angle between the lines from `at` to `a` and from `at` to `b`, degrees in [0, 90]
/// (a VP is a direction: lines, not rays).
pub fn direction_error_deg(at: Point2, a: Point2, b: Point2) -> f64 {
    let (u, v) = (a - at, b - at);
    let ang = (u.x * v.y - u.y * v.x).atan2(u.dot(v)).abs().to_degrees();
    ang.min(180.0 - ang)
}

/// Loss weight of a label whose direction is uncertain by `sd_deg`: `1 / (1 + (sd / sd0)²)`.
pub fn label_weight(sd_deg: f64, sd0_deg: f64) -> f32 {
    if !sd_deg.is_finite() {
        return 0.0;
    }
    (1.0 / (1.0 + (sd_deg / sd0_deg).powi(2))) as f32
}

/// What the camera's estimate leaves uncertain, for the labels' directions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraUncertainty {
    /// Median angle of the straight tracks to VP1, degrees.
    pub track_residual_deg: f64,
    /// Bootstrap spread of the horizon's angle, degrees.
    pub horizon_sd_deg: f64,
    /// The focal length's 68 % interval, pixels.
    pub focal_interval_px: [f64; 2],
}

/// Direction uncertainties (degrees) of the VP1 and VP2 labels at `at` (a box centre) for the
/// camera's own VPs: VP1's is the tracks' residual, VP2's that of [`vp2_label`].
/// `None` when the camera gives no VP2 for an end of the focal interval.
pub fn label_uncertainty(
    cal: &Calibration,
    at: Point2,
    u: &CameraUncertainty,
) -> Option<(f64, f64)> {
    let (_, sd2) = vp2_label(cal, cal.vp1, at, u)?;
    Some((u.track_residual_deg, sd2))
}

/// The VP2 of a vehicle whose VP1 is `vp1` (on the camera's horizon): the horizon's point
/// orthogonal to it for the camera's focal length, and its direction uncertainty at `at`, from
/// how far that direction turns when the focal length moves to either end of its interval (VP2
/// slides along the horizon) and the horizon's roll spread. `None` when the camera gives no
/// VP2 for the focal length or an end of its interval.
pub fn vp2_label(
    cal: &Calibration,
    vp1: Point2,
    at: Point2,
    u: &CameraUncertainty,
) -> Option<(Point2, f64)> {
    let vp2 = orthogonal_vp_on_line(vp1, cal.horizon, cal.focal_px, cal.pp)?;
    let mut turn: f64 = 0.0;
    for f in u.focal_interval_px {
        let end = orthogonal_vp_on_line(vp1, cal.horizon, f, cal.pp)?;
        turn = turn.max(direction_error_deg(at, vp2, end));
    }
    Some((vp2, (turn.powi(2) + u.horizon_sd_deg.powi(2)).sqrt()))
}

/// A track's direction at one of its boxes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tangent {
    /// The box centre the direction is at.
    pub at: Point2,
    /// Unit direction.
    pub dir: Point2,
    /// Standard error of the direction's angle from the fit's residuals, degrees.
    pub sd_deg: f64,
    /// How far the window's centres spread along it, pixels.
    pub span_px: f64,
}

/// The principal axis of `points` ([`Axis`]): their mean and unit direction; `None` for fewer
/// than 2 points or points that do not spread.
fn principal_axis(points: &[Point2]) -> Option<(Point2, Point2)> {
    let axis = Axis::of(points);
    (points.len() >= 2 && axis.major_rms > 0.0).then_some((axis.mean, axis.dir))
}

/// The tangent of the track through `centres` (in time order) at its `k`-th centre. Over the
/// centres `k - half ..= k + half` (shifted inside the track near its ends), in the frame of
/// their principal axis (`t` along, `e` across), `e = a + b t + c t²` is fitted by least
/// squares (a line for fewer than 5 centres), so that a bend and a window at the track's end
/// still give the direction at the box itself: the slope `b + 2 c t_k`, its angle's standard
/// error from the fit's residual variance and covariance, and the window's span along the axis.
/// `None` for fewer than 3 centres, centres that do not move, or a singular fit.
pub fn local_tangent(centres: &[Point2], k: usize, half: usize) -> Option<Tangent> {
    if k >= centres.len() {
        return None;
    }
    // Near an end the window keeps its length, shifted inside the track.
    let len = (2 * half + 1).min(centres.len());
    let lo = k.saturating_sub(half).min(centres.len() - len);
    let window = &centres[lo..lo + len];
    if window.len() < 3 {
        return None;
    }
    let (mean, dir) = principal_axis(window)?;
    let across = Point2::new(-dir.y, dir.x);
    let te: Vec<(f64, f64)> = window
        .iter()
        .map(|c| ((*c - mean).dot(dir), (*c - mean).dot(across)))
        .collect();
    let (lo_t, hi_t) = te
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &(t, _)| {
            (a.min(t), b.max(t))
        });
    let span = hi_t - lo_t;
    // Powers of t scaled by the span keep the normal equations well conditioned.
    let terms = if window.len() >= 5 { 3 } else { 2 };
    let basis = |t: f64| {
        let u = t / span;
        [1.0, u, u * u]
    };
    let mut ata = [[0.0; 3]; 3];
    let mut atb = [0.0; 3];
    for &(t, e) in &te {
        let x = basis(t);
        for i in 0..terms {
            atb[i] += x[i] * e;
            for j in 0..terms {
                ata[i][j] += x[i] * x[j];
            }
        }
    }
    if terms == 2 {
        // The line's normal equations as the leading block of an invertible 3 x 3.
        ata[2][2] = 1.0;
    }
    let inv = vpcal_geom::rotation::inverse3(&ata)?;
    let scale = ata.iter().flatten().fold(0.0f64, |a, v| a.max(v.abs()));
    if !inv
        .iter()
        .flatten()
        .all(|v| v.is_finite() && v.abs() * scale < 1e12)
    {
        return None;
    }
    let coef: Vec<f64> = (0..terms)
        .map(|i| (0..terms).map(|j| inv[i][j] * atb[j]).sum())
        .collect();
    let residual: f64 = te
        .iter()
        .map(|&(t, e)| {
            let x = basis(t);
            e - (0..terms).map(|i| coef[i] * x[i]).sum::<f64>()
        })
        .map(|r| r * r)
        .sum();
    let dof = window.len() - terms;
    let var = if dof > 0 { residual / dof as f64 } else { 0.0 };
    // de/dt at t_k = (b + 2 c u_k) / span; its gradient in the coefficients.
    let tk = (centres[k] - mean).dot(dir);
    let g = [0.0, 1.0 / span, 2.0 * tk / (span * span)];
    let slope: f64 = (1..terms).map(|i| coef[i] * g[i]).sum();
    let slope_var: f64 = (1..terms)
        .flat_map(|i| (1..terms).map(move |j| (i, j)))
        .map(|(i, j)| g[i] * inv[i][j] * g[j])
        .sum::<f64>()
        * var;
    let d = dir + across * slope;
    let d = d / d.norm();
    let sd = (slope_var.max(0.0).sqrt() / (1.0 + slope * slope))
        .atan()
        .to_degrees();
    Some(Tangent {
        at: centres[k],
        dir: d,
        sd_deg: sd,
        span_px: span,
    })
}

/// The crop around `b`: grown by `margin` box sizes on each side, integer pixels, clamped to
/// a `width` x `height` frame. `(x0, y0, x1, y1)` with `x1 > x0`, `y1 > y0` for a box inside.
pub fn crop_rect(b: &BoxPx, margin: f64, width: u32, height: u32) -> (u32, u32, u32, u32) {
    let (mx, my) = (margin * b.width(), margin * b.height());
    let clamp = |v: f64, hi: u32| v.clamp(0.0, f64::from(hi)) as u32;
    (
        clamp((b.x0 - mx).floor(), width),
        clamp((b.y0 - my).floor(), height),
        clamp((b.x1 + mx).ceil(), width),
        clamp((b.y1 + my).ceil(), height),
    )
}

/// The angle (degrees) between the principal axis of `centres` and the line from their mean
/// to `vp1`; `None` for fewer than 2 distinct points.
pub fn track_angle_to_vp_deg(centres: &[Point2], vp1: Point2) -> Option<f64> {
    let (mean, dir) = principal_axis(centres)?;
    Some(direction_error_deg(mean, mean + dir, vp1))
}

/// `k` indices evenly spread over `0..n` (all of them when `n <= k`).
pub fn spread_evenly(n: usize, k: usize) -> Vec<usize> {
    if n <= k {
        return (0..n).collect();
    }
    if k == 0 {
        return Vec::new();
    }
    if k == 1 {
        return vec![n / 2];
    }
    (0..k).map(|i| i * (n - 1) / (k - 1)).collect()
}

/// A stable id base for a camera's vehicles (FNV-1a of its name), so that crops of several
/// cameras written into one folder, or folders joined for training, keep distinct vehicles.
pub fn vehicle_base(camera: &str) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in camera.bytes() {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    (h % 1_000_000_000) * 1_000_000
}

/// A crop still to be cut: which record, which track, which instance.
#[derive(Debug)]
struct Wanted {
    record: usize,
    track: usize,
    instance: u32,
    /// The labels, frame pixels, and their direction uncertainties (degrees).
    vp1: Point2,
    vp2: Point2,
    sd: (f64, f64),
    /// VP1 is the track's tangent met with the horizon, not the camera's.
    tangent: bool,
}

fn evidence_f64(agg: &Aggregated, key: &str) -> Option<f64> {
    agg.evidence.get(key).and_then(serde_json::Value::as_f64)
}

fn evidence_bool(agg: &Aggregated, key: &str) -> bool {
    agg.evidence
        .get(key)
        .and_then(serde_json::Value::as_bool)
        .unwrap_or(false)
}

/// The first gate of a road whose straight tracks share the camera's VP1 that the camera
/// fails, as a sentence; `None` when its straight tracks may take the camera's VPs.
fn straight_road_refusal(agg: &Aggregated, settings: &LabelSettings) -> Option<String> {
    if evidence_bool(agg, "road_curved") {
        return Some("the road curves: vehicles do not share one VP1".into());
    }
    if !evidence_bool(agg, "vp1_from_tracks") {
        return Some(
            "VP1 does not come from straight vehicle tracks (too few tracks, or they disagree)"
                .into(),
        );
    }
    let lines = agg
        .evidence
        .get("track_lines")
        .and_then(serde_json::Value::as_u64)
        .unwrap_or(0);
    if (lines as usize) < settings.min_track_lines {
        return Some(format!(
            "{lines} straight tracks, {} needed",
            settings.min_track_lines
        ));
    }
    match evidence_f64(agg, "track_residual_deg") {
        Some(r) if r <= settings.max_track_residual_deg => {}
        Some(r) => {
            return Some(format!(
                "the straight tracks point at VP1 to {r:.2}° (median), more than {:.2}°",
                settings.max_track_residual_deg
            ))
        }
        None => return Some("no track residual".into()),
    }
    None
}

/// Why the camera's horizon is not confident enough for any label; `None` when it is.
fn horizon_refusal(agg: &Aggregated, settings: &LabelSettings) -> Option<String> {
    match agg.confidence.as_ref().map(|c| c.horizon_angle_sd_deg) {
        Some(sd) if sd.is_finite() && sd <= settings.max_horizon_sd_deg => None,
        Some(sd) => Some(format!(
            "the horizon's angle spreads by {sd:.2}°, more than {:.2}°",
            settings.max_horizon_sd_deg
        )),
        None => Some("no bootstrap spread of the horizon (run with --bootstrap > 0)".into()),
    }
}

/// Label the footage at `input` as camera `camera`: crops go to `out_dir/images/<camera>/`,
/// their records are returned (the caller writes the index, [`vpcal_synth::write_index`]).
/// A camera that cannot be labelled confidently gives a report with `refused` and no records.
///
/// # Errors
/// An unreadable input, a failing detector or network, an unwritable folder.
pub fn label_footage(
    input: &Path,
    camera: &str,
    config: &PipelineConfig,
    settings: &LabelSettings,
    out_dir: &Path,
    progress: &dyn Progress,
) -> Result<(CameraReport, Vec<SampleRecord>)> {
    let mut report = CameraReport::new(camera, input);
    // Training crops want every box the network can see, not a few per vehicle.
    let config = &PipelineConfig {
        crops: crate::pipeline::CropPolicy::All,
        ..config.clone()
    };
    let out = run_pipeline(input, config, progress)?;
    report.frames = out.stats.frames;
    report.boxes = out.records.len();
    if is_stills(&out.info) {
        report.refused =
            Some("stills, not consecutive frames: no tracks (give a folder --fps)".into());
        return Ok((report, Vec::new()));
    }
    let (cal, agg) = match calibrate(&out, config) {
        Ok(c) => c,
        Err(e) => {
            report.refused = Some(format!("{e:#}"));
            return Ok((report, Vec::new()));
        }
    };
    report.track_lines = agg
        .evidence
        .get("track_lines")
        .and_then(serde_json::Value::as_u64);
    report.track_residual_deg = evidence_f64(&agg, "track_residual_deg");
    report.horizon_sd_deg = agg.confidence.as_ref().map(|c| c.horizon_angle_sd_deg);
    report.focal_px = Some(cal.focal_px);
    report.focal_source = Some(agg.focal_source.name().to_string());
    report.focal_interval_px = agg.focal_interval_px;
    if let Some(why) = horizon_refusal(&agg, settings) {
        report.refused = Some(why);
        return Ok((report, Vec::new()));
    }
    let shared_vp1 = match straight_road_refusal(&agg, settings) {
        None => true,
        Some(why) if !settings.tangents => {
            report.refused = Some(why);
            return Ok((report, Vec::new()));
        }
        Some(why) => {
            report.tangents_only = Some(why);
            false
        }
    };
    let uncertainty = CameraUncertainty {
        track_residual_deg: report.track_residual_deg.unwrap_or(0.0),
        horizon_sd_deg: report.horizon_sd_deg.unwrap_or(0.0),
        focal_interval_px: agg
            .focal_interval_px
            .unwrap_or([cal.focal_px, cal.focal_px]),
    };
    let choice = Choice {
        cal: &cal,
        uncertainty: &uncertainty,
        settings,
        shared_vp1,
    };
    let wanted = choose_boxes(&out.records, &choice, &mut report, {
        let (w, h) = (out.info.width, out.info.height);
        move |b: &BoxPx| {
            b.x0 > settings.border_px
                && b.y0 > settings.border_px
                && b.x1 < f64::from(w) - settings.border_px
                && b.y1 < f64::from(h) - settings.border_px
        }
    });
    if wanted.is_empty() {
        report.refused = Some(if shared_vp1 || !settings.tangents {
            "no moving vehicle heads for VP1 on a long enough track".into()
        } else {
            "no moving vehicle's track has a tangent straight enough to label".into()
        });
        return Ok((report, Vec::new()));
    }
    let records = cut_crops(
        input,
        camera,
        config,
        settings,
        out_dir,
        &out.records,
        &cal,
        &agg,
        &wanted,
    )?;
    report.crops = records.len();
    let med = |f: &dyn Fn(&Wanted) -> f64| {
        let v: Vec<f64> = wanted.iter().map(f).collect();
        vpcal_geom::solve::median(&v)
    };
    report.vp1_sd_deg = med(&|w| w.sd.0);
    report.vp2_sd_deg = med(&|w| w.sd.1);
    report.label_weight = match (
        med(&|w| f64::from(label_weight(w.sd.0, LABEL_SD0_DEG))),
        med(&|w| f64::from(label_weight(w.sd.1, LABEL_SD0_DEG))),
    ) {
        (Some(a), Some(b)) => Some([a, b]),
        _ => None,
    };
    Ok((report, records))
}

/// What [`choose_boxes`] labels with.
struct Choice<'a> {
    cal: &'a Calibration,
    uncertainty: &'a CameraUncertainty,
    settings: &'a LabelSettings,
    /// Straight tracks that head for the camera's VP1 take the camera's VPs (the camera passed
    /// the straight-road gates); otherwise every vehicle is labelled by its track's tangent.
    shared_vp1: bool,
}

/// The boxes to label, at most `max_per_track` a track of a moving vehicle, inside the frame
/// and large enough: those of straight tracks that head for VP1 with the camera's VPs, the
/// others (with `tangents`) with the VPs of their track's tangent where it is straight enough.
fn choose_boxes(
    records: &[VehicleRecord],
    choice: &Choice<'_>,
    report: &mut CameraReport,
    inside: impl Fn(&BoxPx) -> bool,
) -> Vec<Wanted> {
    let Choice {
        cal,
        uncertainty,
        settings,
        shared_vp1,
    } = *choice;
    let boxes: Vec<(f64, BoxPx)> = records
        .iter()
        .map(|r| (r.frame as f64, r.det_box))
        .collect();
    let options = TrackOptions {
        max_gap_steps: 8.0,
        ..TrackOptions::default()
    };
    let mut wanted = Vec::new();
    let mut checks = Vec::new();
    for (t, track) in link(&boxes, &options).iter().enumerate() {
        if track.len() < settings.min_track_boxes {
            continue;
        }
        report.tracks += 1;
        let centres: Vec<Point2> = track.iter().map(|&i| records[i].det_box.center()).collect();
        let heights: Vec<f64> = track.iter().map(|&i| records[i].det_box.height()).collect();
        let height = vpcal_geom::solve::median(&heights).unwrap_or(0.0);
        let travel = centres
            .first()
            .zip(centres.last())
            .map_or(0.0, |(a, b)| (*b - *a).norm());
        if travel < settings.min_travel_heights * height {
            continue;
        }
        let straight = shared_vp1
            && track_angle_to_vp_deg(&centres, cal.vp1)
                .is_some_and(|a| a <= settings.max_track_angle_deg);
        // A tangent counts where its window travels `min_tangent_span_heights` box heights and
        // its direction is known: the window grows until it travels that far (slow and far
        // vehicles move little from one frame to the next), and a bend then shows as scatter
        // across it.
        let tangent_at = |p: usize| {
            let min_span = settings.min_tangent_span_heights * heights[p];
            TANGENT_HALVES
                .iter()
                .map(|&k| k * settings.tangent_half)
                .filter_map(|half| local_tangent(&centres, p, half))
                .find(|tg| tg.span_px >= min_span)
                .filter(|tg| tg.sd_deg <= settings.max_tangent_sd_deg)
        };
        let usable: Vec<usize> = (0..track.len())
            .filter(|&p| {
                let b = &records[track[p]].det_box;
                b.height() >= settings.min_box_height_px && inside(b)
            })
            .collect();
        let mut labelled = 0;
        for p in spread_evenly(usable.len(), settings.max_per_track) {
            let pos = usable[p];
            let record = track[pos];
            let at = records[record].det_box.center();
            let label = if shared_vp1 {
                // On a road whose straight tracks share VP1 every track's tangent is checked
                // against it, but only the straight tracks are labelled, with the camera's VPs:
                // there a track that misses VP1 is far more often a tracking error or an
                // occlusion than a vehicle changing lanes.
                if settings.tangents {
                    if let Some(tg) = tangent_at(pos) {
                        checks.push(direction_error_deg(tg.at, tg.at + tg.dir, cal.vp1));
                    }
                }
                straight
                    .then(|| label_uncertainty(cal, at, uncertainty))
                    .flatten()
                    .map(|sd| (cal.vp1, cal.vp2, sd))
            } else {
                tangent_at(pos).and_then(|tg| {
                    let vp1 =
                        Line::through_with_direction(tg.at, tg.dir)?.intersect(cal.horizon)?;
                    let (vp2, sd2) = vp2_label(cal, vp1, at, uncertainty)?;
                    Some((vp1, vp2, (tg.sd_deg.hypot(TANGENT_FLOOR_DEG), sd2)))
                })
            };
            let Some((vp1, vp2, sd)) = label else {
                continue;
            };
            wanted.push(Wanted {
                record,
                track: t,
                instance: labelled,
                vp1,
                vp2,
                sd,
                tangent: !straight,
            });
            labelled += 1;
        }
        if labelled > 0 {
            report.vehicles += 1;
            if !straight {
                report.tangent_vehicles += 1;
            }
        }
    }
    report.tangent_check_deg = vpcal_geom::solve::median(&checks);
    wanted
}

/// Read the footage again and cut, encode and write the wanted crops; their records.
#[allow(clippy::too_many_arguments)]
// # Why: the pass needs the run's input, settings and results together; they are not a type
// of their own anywhere else.
fn cut_crops(
    input: &Path,
    camera: &str,
    config: &PipelineConfig,
    settings: &LabelSettings,
    out_dir: &Path,
    records: &[VehicleRecord],
    cal: &Calibration,
    agg: &Aggregated,
    wanted: &[Wanted],
) -> Result<Vec<SampleRecord>> {
    let mut by_frame: BTreeMap<u64, Vec<&Wanted>> = BTreeMap::new();
    for w in wanted {
        by_frame.entry(records[w.record].frame).or_default().push(w);
    }
    let last = by_frame.keys().next_back().copied().unwrap_or(0);
    let rel_dir = PathBuf::from("images").join(camera);
    let dir = out_dir.join(&rel_dir);
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let base = vehicle_base(camera);
    let mut out = Vec::with_capacity(wanted.len());
    let mut source = open_input(input, &config.frames)
        .with_context(|| format!("opening {} again to cut the crops", input.display()))?;
    for frame in source.by_ref() {
        let frame = frame.with_context(|| format!("reading {} again", input.display()))?;
        if frame.index > last {
            break;
        }
        let Some(list) = by_frame.get(&frame.index) else {
            continue;
        };
        let (fw, fh) = frame.image.dimensions();
        for w in list {
            let r = &records[w.record];
            let (x0, y0, x1, y1) = crop_rect(&r.det_box, settings.margin, fw, fh);
            if x1 <= x0 || y1 <= y0 {
                continue;
            }
            let crop = image::imageops::crop_imm(&frame.image, x0, y0, x1 - x0, y1 - y0).to_image();
            let jpeg = vpcal_synth::post::encode_jpeg(&crop, settings.jpeg_quality)
                .with_context(|| format!("encoding a crop of frame {}", frame.index))?;
            let vehicle = base + w.track as u64;
            let name = format!("{vehicle}_{}.jpg", w.instance);
            let path = dir.join(&name);
            vpcal_formats::fs::write_atomic(&path, &jpeg)?;
            let origin = Point2::new(f64::from(x0), f64::from(y0));
            let rel = |p: Point2| (p - origin).as_array();
            let b = &r.det_box;
            let rect = [
                rel(Point2::new(b.x0, b.y1)),
                rel(Point2::new(b.x1, b.y1)),
                rel(Point2::new(b.x1, b.y0)),
                rel(Point2::new(b.x0, b.y0)),
            ];
            let weights = [
                label_weight(w.sd.0, LABEL_SD0_DEG),
                label_weight(w.sd.1, LABEL_SD0_DEG),
            ];
            let box_rel = [rect[0][0], rect[2][1], rect[1][0], rect[0][1]];
            out.push(SampleRecord {
                vehicle,
                instance: w.instance,
                image: rel_dir.join(&name).to_string_lossy().replace('\\', "/"),
                width: x1 - x0,
                height: y1 - y0,
                bb3d: [
                    rect[0], rect[1], rect[2], rect[3], rect[0], rect[1], rect[2], rect[3],
                ],
                vp1: rel(w.vp1),
                vp2: rel(w.vp2),
                box2d: box_rel,
                label_weight: weights,
                meta: SampleMeta::Real(RealMeta {
                    source: input.display().to_string(),
                    camera: camera.to_string(),
                    frame: frame.index,
                    track: w.track as u64,
                    score: r.score,
                    det_box: [b.x0, b.y0, b.x1, b.y1],
                    crop_origin: origin.as_array(),
                    frame_size: [fw, fh],
                    focal_px: cal.focal_px,
                    focal_source: agg.focal_source.name().to_string(),
                    pp: cal.pp.as_array(),
                    vp1_sd_deg: w.sd.0,
                    vp2_sd_deg: w.sd.1,
                    vp1_from_tangent: w.tangent,
                }),
            });
        }
    }
    if out.len() < wanted.len() {
        bail!(
            "{}: the second pass found {} of the {} crops (the footage ended early?)",
            input.display(),
            out.len(),
            wanted.len()
        );
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn direction_error_is_the_angle_between_lines() {
        let at = Point2::new(0.0, 0.0);
        let e = direction_error_deg(at, Point2::new(10.0, 0.0), Point2::new(-10.0, 1e-12));
        assert!(e < 1e-9, "{e}");
        let e = direction_error_deg(at, Point2::new(1.0, 0.0), Point2::new(1.0, 1.0));
        assert!((e - 45.0).abs() < 1e-9, "{e}");
        let e = direction_error_deg(at, Point2::new(1.0, 0.0), Point2::new(0.0, -5.0));
        assert!((e - 90.0).abs() < 1e-9, "{e}");
    }

    #[test]
    fn label_weight_is_half_at_sd0_and_falls() {
        assert!((label_weight(0.0, 2.0) - 1.0).abs() < 1e-6);
        assert!((label_weight(2.0, 2.0) - 0.5).abs() < 1e-6);
        assert!(label_weight(6.0, 2.0) < 0.11);
        assert_eq!(label_weight(f64::NAN, 2.0), 0.0);
    }

    #[test]
    fn crop_rect_grows_and_clamps() {
        let b = BoxPx::new(10.0, 20.0, 30.0, 60.0);
        assert_eq!(crop_rect(&b, 0.25, 100, 100), (5, 10, 35, 70));
        assert_eq!(crop_rect(&b, 1.0, 40, 70), (0, 0, 40, 70));
    }

    #[test]
    fn a_track_tangent_follows_a_curve() {
        // Centres on a circle of radius 200 about (500, 500), 2° apart: the tangent at each,
        // the ends included, is square to the radius there, its window spans ~6 steps, and its
        // error is small.
        let c = Point2::new(500.0, 500.0);
        let pts: Vec<Point2> = (0..20)
            .map(|i| {
                let a = f64::from(i).mul_add(2.0, 10.0).to_radians();
                c + Point2::new(a.cos(), a.sin()) * 200.0
            })
            .collect();
        for k in [0, 7, 19] {
            let tg = local_tangent(&pts, k, 3).unwrap();
            let mid = tg.at - c;
            assert!(mid.dot(tg.dir).abs() / mid.norm() < 0.002, "k {k}: {tg:?}");
            assert_eq!(tg.at, pts[k]);
            assert!(tg.sd_deg < 0.1, "{tg:?}");
        }
        let tg = local_tangent(&pts, 7, 3).unwrap();
        assert!(
            (tg.span_px - 6.0 * 2f64.to_radians() * 200.0).abs() < 1.0,
            "{tg:?}"
        );
        assert!(local_tangent(&pts[..2], 0, 3).is_none());
        assert!(local_tangent(&[Point2::new(1.0, 1.0); 5], 2, 3).is_none());
    }

    #[test]
    fn a_tangent_s_error_grows_with_the_scatter_across_it() {
        // A straight track along x with alternating offsets across it: the direction stays x,
        // the standard error grows with the offsets and falls with the window's length.
        let track = |dy: f64, step: f64| -> Vec<Point2> {
            (0..9)
                .map(|i| Point2::new(f64::from(i) * step, if i % 2 == 0 { dy } else { -dy }))
                .collect()
        };
        let sd = |dy, step, half| local_tangent(&track(dy, step), 4, half).unwrap().sd_deg;
        assert!(sd(0.0, 10.0, 3) < 1e-9);
        assert!(sd(1.0, 10.0, 3) > sd(0.5, 10.0, 3));
        assert!(sd(1.0, 20.0, 3) < sd(1.0, 10.0, 3));
        assert!(sd(1.0, 10.0, 4) < sd(1.0, 10.0, 2));
        let tg = local_tangent(&track(1.0, 10.0), 4, 3).unwrap();
        assert!(tg.dir.y.abs() < 0.05, "{tg:?}");
    }

    /// Boxes of 40 x 30 px centred on `centres`, one per frame from `frame0`.
    fn track_records(frame0: u64, centres: &[Point2]) -> Vec<VehicleRecord> {
        centres
            .iter()
            .zip(frame0..)
            .map(|(c, frame)| {
                let b = BoxPx::new(c.x - 20.0, c.y - 15.0, c.x + 20.0, c.y + 15.0);
                VehicleRecord::of_box(frame, b)
            })
            .collect()
    }

    #[test]
    fn straight_roads_label_straight_tracks_and_other_cameras_label_by_tangents() {
        // A camera with a level horizon at y = 100; a vehicle driving at VP1 and, later, one
        // turning on an arc of the image.
        let pp = Point2::new(640.0, 360.0);
        let vp1 = Point2::new(700.0, 100.0);
        let vp2 =
            orthogonal_vp_on_line(vp1, Line::from_slope_intercept(0.0, 100.0), 900.0, pp).unwrap();
        let cal = Calibration::from_vps(vp1, vp2, pp).unwrap();
        let straight: Vec<Point2> = (0..30)
            .map(|i| vp1 + (Point2::new(-100.0, 560.0) - vp1) * (0.5 + f64::from(i) * 0.015))
            .collect();
        let centre = Point2::new(300.0, 700.0);
        let turning: Vec<Point2> = (0..30)
            .map(|i| {
                let a = f64::from(i).mul_add(1.5, -80.0).to_radians();
                centre + Point2::new(a.cos(), a.sin()) * 300.0
            })
            .collect();
        let mut records = track_records(0, &straight);
        records.extend(track_records(100, &turning));
        let u = CameraUncertainty {
            track_residual_deg: 0.5,
            horizon_sd_deg: 0.5,
            focal_interval_px: [850.0, 950.0],
        };
        let settings = LabelSettings::default();
        let choose = |shared_vp1: bool| {
            let mut report = CameraReport::new("cam", Path::new("cam.mp4"));
            let choice = Choice {
                cal: &cal,
                uncertainty: &u,
                settings: &settings,
                shared_vp1,
            };
            let wanted = choose_boxes(&records, &choice, &mut report, |_| true);
            (wanted, report)
        };
        // A straight road: only the vehicle that heads for VP1, with the camera's VPs; the
        // turning track's tangents are checked against VP1 and miss it by far.
        let (wanted, report) = choose(true);
        assert_eq!((report.vehicles, report.tangent_vehicles), (1, 0));
        assert!(wanted
            .iter()
            .all(|w| w.vp1 == vp1 && w.vp2 == cal.vp2 && !w.tangent));
        assert!(report.tangent_check_deg.is_some(), "{report:?}");
        // No shared VP1: both by their tangents, each VP1 on the horizon and on the line along
        // the track at its box, and VP2 orthogonal to it.
        let (wanted, report) = choose(false);
        assert_eq!((report.vehicles, report.tangent_vehicles), (2, 2));
        for w in &wanted {
            assert!(w.tangent && (w.vp1.y - 100.0).abs() < 1e-6, "{:?}", w.vp1);
            let c = records[w.record].det_box.center();
            let (along, k) = if w.record < 30 {
                (&straight, w.record)
            } else {
                (&turning, w.record - 30)
            };
            let dir = along[(k + 1).min(29)] - along[k.saturating_sub(1)];
            assert!(direction_error_deg(c, c + dir, w.vp1) < 1.0, "{w:?}");
            let again = orthogonal_vp_on_line(w.vp1, cal.horizon, cal.focal_px, pp).unwrap();
            assert!((again - w.vp2).norm() < 1e-6);
            assert!(w.sd.0 >= TANGENT_FLOOR_DEG);
        }
        assert!(wanted
            .iter()
            .any(|w| w.record >= 30 && (w.vp1 - vp1).norm() > 100.0));
    }

    #[test]
    fn spread_evenly_keeps_the_ends() {
        assert_eq!(spread_evenly(3, 5), vec![0, 1, 2]);
        assert_eq!(spread_evenly(10, 3), vec![0, 4, 9]);
        assert_eq!(spread_evenly(10, 1), vec![5]);
        assert!(spread_evenly(10, 0).is_empty());
    }

    #[test]
    fn a_track_towards_vp1_has_a_small_angle() {
        let vp1 = Point2::new(500.0, -1000.0);
        let centres: Vec<Point2> = (0..10)
            .map(|i| {
                let t = f64::from(i) / 10.0;
                Point2::new(100.0, 800.0) * (1.0 - t * 0.3) + vp1 * (t * 0.3)
            })
            .collect();
        let a = track_angle_to_vp_deg(&centres, vp1).unwrap();
        assert!(a < 1e-6, "{a}");
        let sideways: Vec<Point2> = (0..10)
            .map(|i| Point2::new(f64::from(i) * 10.0, 800.0))
            .collect();
        assert!(track_angle_to_vp_deg(&sideways, vp1).unwrap() > 30.0);
        assert!(track_angle_to_vp_deg(&centres[..1], vp1).is_none());
    }

    #[test]
    fn label_uncertainty_of_vp2_grows_with_the_focal_interval_and_is_small_for_far_vp2() {
        // A camera looking down the road: VP1 above and right of the centre, VP2 far left.
        let pp = Point2::new(960.0, 540.0);
        let f = 2000.0;
        let vp1 = Point2::new(960.0 + 200.0, 540.0 - 800.0);
        let horizon = vpcal_geom::Line::from_slope_intercept(0.0, vp1.y);
        let vp2 = orthogonal_vp_on_line(vp1, horizon, f, pp).unwrap();
        let cal = Calibration::from_vps(vp1, vp2, pp).unwrap();
        let at = Point2::new(700.0, 900.0);
        let mut u = CameraUncertainty {
            track_residual_deg: 0.3,
            horizon_sd_deg: 0.0,
            focal_interval_px: [f, f],
        };
        let (sd1, sd2) = label_uncertainty(&cal, at, &u).unwrap();
        assert!((sd1 - 0.3).abs() < 1e-9, "{sd1}");
        assert!(sd2 < 1e-9, "{sd2}");
        u.focal_interval_px = [0.7 * f, 1.4 * f];
        let (_, wide) = label_uncertainty(&cal, at, &u).unwrap();
        u.focal_interval_px = [0.95 * f, 1.05 * f];
        let (_, narrow) = label_uncertainty(&cal, at, &u).unwrap();
        assert!(wide > narrow && narrow > 0.0, "{wide} {narrow}");
        // The roll spread adds in quadrature.
        u.horizon_sd_deg = 1.0;
        let (_, with_roll) = label_uncertainty(&cal, at, &u).unwrap();
        assert!((with_roll - (narrow * narrow + 1.0).sqrt()).abs() < 1e-9);
    }

    #[test]
    fn vehicle_bases_differ_by_camera_and_leave_room_for_tracks() {
        let (a, b) = (vehicle_base("cam_a"), vehicle_base("cam_b"));
        assert_ne!(a, b);
        assert_eq!(a % 1_000_000, 0);
    }
}
