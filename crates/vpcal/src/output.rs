//! What a calibration run writes: the calibration file, the BrnoCompSpeed system file, the
//! per-vehicle records, the vehicle tracks; and the checks that let a run fail before it starts, not after.

use std::path::Path;

use anyhow::{bail, Context, Result};
use serde_json::{json, Map, Value};
use vpcal_formats::bcs::{write_system, SystemCalibration, SystemCar, SystemFile};
use vpcal_formats::calib::{CalibrationFile, Dropped, InputSummary};
use vpcal_formats::reference::{
    infer_image_size, write_scene_edgelets, write_vpout, SceneRecord, VpOutItem,
};
use vpcal_geom::aggregate::VehicleVps;
use vpcal_geom::camera::Calibration;
use vpcal_video::{SourceKind, Start};

use crate::aggregate::{aggregate, check_focal_settings, edgelets_of, Aggregated, Method, Scene};
use crate::pipeline::{PipelineConfig, PipelineOutput, PrincipalPoint};
use crate::road::{KnownDistance, RoadCamera, RoadMeasure, ScaleInput};
use crate::tracks::{build_tracks, summary, TrackSettings, VehicleTrack};

/// How calibration files name a kind of input.
pub fn kind_name(kind: SourceKind) -> &'static str {
    match kind {
        SourceKind::Video => "video",
        SourceKind::ImageFolder => "image_folder",
        SourceKind::SingleImage => "image",
    }
}

/// The input part of a calibration file.
pub fn input_summary(out: &PipelineOutput) -> InputSummary {
    let s = &out.stats;
    InputSummary {
        path: out.info.path.display().to_string(),
        kind: Some(kind_name(out.info.kind).to_string()),
        width: out.info.width,
        height: out.info.height,
        fps: out.info.fps,
        codec: out.info.codec.clone(),
        frames_processed: s.frames,
        frames_replayed: s.replayed_frames,
        detections: s.detections,
        dropped: Dropped {
            low_score: s.dropped_low_score,
            r#static: s.dropped_static,
            over_limit: s.dropped_over_limit,
            outside_frame: s.dropped_outside,
            seen_before: s.dropped_seen,
        },
        vehicle_boxes: s.crops,
        followed_boxes: s.crops_skipped,
        seconds: s.seconds,
    }
}

/// The settings of a pipeline run, by flag name.
pub fn settings(out: &PipelineOutput, c: &PipelineConfig) -> Map<String, Value> {
    let v = json!({
        "model": out.model,
        "device": c.device,
        "detector": out.detector,
        "every": c.frames.every,
        "fps": c.frames.image_fps,
        "max_frames": c.frames.max_frames,
        "start": match c.frames.start {
            Start::Beginning => Value::Null,
            Start::Frame(n) => json!(n),
            Start::Seconds(t) => json!(format!("{t}s")),
        },
        "min_score": c.min_score,
        "drop_static": !c.keep_static,
        "max_per_frame": c.max_per_frame,
        "method": c.method.name(),
        "flip_average": c.flip_average,
        "min_crop_px": c.min_crop_px,
        "edgelets": c.edgelets,
        "replay": c.replay,
        "bootstrap": c.bootstrap,
        "pp": c.pp.to_json(),
        "focal": c.focal_px,
        "focal_range": c.focal_range_px,
        "max_records": c.max_records,
        "markings": c.markings.map(|m| [m.period_m, m.lane_width_m]),
    });
    match v {
        Value::Object(m) => m,
        _ => Map::new(),
    }
}

/// The calibration file of camera `cal` aggregated as `agg` from a pipeline run.
pub fn calibration_file(
    out: &PipelineOutput,
    config: &PipelineConfig,
    cal: &Calibration,
    agg: &Aggregated,
) -> CalibrationFile {
    let mut file = aggregated_file(input_summary(out), cal, agg);
    file.settings = settings(out, config);
    keep_input_warnings(&mut file, out);
    file
}

/// The run's warnings about its input (a truncated or damaged file: which frames were used)
/// go into the file first, so that the file says what it was made from.
fn keep_input_warnings(file: &mut CalibrationFile, out: &PipelineOutput) {
    let mut warnings = out.warnings.clone();
    warnings.extend(
        std::mem::take(&mut file.warnings)
            .into_iter()
            .filter(|w| !out.warnings.contains(w)),
    );
    file.warnings = warnings;
}

/// The calibration file of camera `cal` aggregated as `agg` from what `input` describes
/// (footage, or a file of per-vehicle records): the camera, the aggregation's evidence,
/// confidence and summary, the focal length's source and interval, and the warnings.
pub fn aggregated_file(
    input: InputSummary,
    cal: &Calibration,
    agg: &Aggregated,
) -> CalibrationFile {
    let mut file = CalibrationFile::calibrated(input, cal);
    file.evidence = Some(agg.evidence.clone());
    file.confidence = agg.confidence.clone();
    file.summary = Some(agg.summary.clone());
    file.focal_source = Some(agg.focal_source.name().to_string());
    file.focal_interval_px = agg.focal_interval_px;
    file.warnings = agg.warnings();
    file.replace_checks(
        crate::plausible::VP1_CHECK,
        crate::plausible::check_vp1(agg),
    );
    file.replace_checks(
        crate::plausible::HORIZON_CHECK,
        crate::plausible::check_horizon(agg),
    );
    file
}

/// [`calibration_file`] with the metric scale of `known` (`calibrate --scale-points`) when
/// given, else the automatic scale from the vehicles' sizes ([`crate::autoscale`]) when
/// enough vehicles fit a car-shaped box; returns the file, the scale and the camera. Known
/// lengths in two directions also measure the focal length ([`RoadCamera::refit_focal`]):
/// the camera returned is then the refitted one.
///
/// # Errors
/// Pixels of `known` that do not fix a scale (above the horizon, coinciding).
pub fn calibrated_run_file(
    out: &PipelineOutput,
    config: &PipelineConfig,
    cal: &Calibration,
    agg: &Aggregated,
    known: &[KnownDistance],
) -> Result<(CalibrationFile, Option<f64>, Calibration)> {
    let mut file = calibration_file(out, config, cal, agg);
    let lines = out
        .background
        .as_ref()
        .map(|bg| crate::markings::lines_in(bg, cal.vp1))
        .unwrap_or_default();
    let mut inputs: Vec<ScaleInput> = known
        .iter()
        .map(|k| ScaleInput {
            kind: RoadMeasure::Distance,
            known: *k,
        })
        .collect();
    let given = inputs.len();
    if let Some(standard) = &config.markings {
        let marked = crate::markings::standard_lengths(&lines, cal, standard);
        if marked.is_empty() {
            file.warnings.push(format!(
                "--markings: no dashed lane line of the standard was found in the scene's \
                 background ({} lines along the road, {} dashed), so the markings gave no \
                 lengths",
                lines.len(),
                lines.iter().filter(|l| l.dashes.is_some()).count()
            ));
        }
        let width = f64::from(out.info.width);
        match crate::road_focal::disagreement(cal, &marked, width) {
            Some(why) => file.warnings.push(format!(
                "--markings: the {} lengths the lane lines make disagree with each other on \
                 this camera ({why}), so they were not used",
                marked.len()
            )),
            None => inputs.extend(marked),
        }
    }
    let (mut file, scale, camera) = if inputs.is_empty() {
        let boxes = crate::tracks::record_boxes(&out.records);
        let size = (out.info.width, out.info.height);
        let scale = set_vehicle_scale(&mut file, &boxes, size, cal, agg)?;
        (file, scale, cal.clone())
    } else {
        let flag = |i: usize| {
            if i < given {
                format!("--scale-points #{}", i + 1)
            } else {
                format!("--markings (length {})", i - given + 1)
            }
        };
        let mut road = RoadCamera::new(file, "the calibration")?;
        if given == 0 {
            road.lengths_source = "markings";
        }
        let (_, fit) = road.apply_lengths(&inputs, flag, "the calibration", false)?;
        (road.file, Some(fit.scale), road.cal)
    };
    if !lines.is_empty() {
        let mut summary = crate::markings::summary(&lines, &camera, scale);
        // What the lines would imply under each common standard, on the footage's own
        // camera (VP1 and horizon), whatever carried the focal length.
        let width = f64::from(out.info.width);
        let by_standard = crate::markings::focal_by_standard(
            &lines,
            cal,
            crate::road_focal::CameraSpread::of_file(&file, width),
            width,
        );
        if let Value::Object(m) = &mut summary {
            m.insert("focal_by_standard".to_string(), Value::Array(by_standard));
        }
        let evidence = file
            .evidence
            .get_or_insert_with(|| Value::Object(Map::new()));
        if let Value::Object(e) = evidence {
            e.insert("markings".to_string(), summary);
        }
    }
    Ok((file, scale, camera))
}

/// Everything a calibrated run writes: the calibration file (its status after the
/// plausibility checks), the metric scale, and the tracks with their speeds.
#[derive(Debug)]
pub struct CalibratedRun {
    pub file: CalibrationFile,
    /// The camera of `file`: the aggregation's, or with the focal length known lengths
    /// measured.
    pub camera: Calibration,
    pub scale: Option<f64>,
    pub tracks: Vec<VehicleTrack>,
    pub header: TracksHeader,
}

/// [`calibrated_run_file`], then the run's tracks (speeds with its scale), and the
/// plausibility of the camera and the speeds ([`crate::plausible`]) in the file's status
/// and warnings.
///
/// # Errors
/// As [`calibrated_run_file`].
pub fn calibrated_run(
    out: &PipelineOutput,
    config: &PipelineConfig,
    cal: &Calibration,
    agg: &Aggregated,
    known: &[KnownDistance],
) -> Result<CalibratedRun> {
    let (mut file, scale, camera) = calibrated_run_file(out, config, cal, agg, known)?;
    let curved = agg.robust_evidence.as_ref().is_some_and(|e| e.road_curved);
    let (tracks, mut header) = run_tracks(out, scale.map(|s| (&camera, s)), true, curved);
    if curved && scale.is_some() {
        header.note = Some("the road curves: tracks without lanes".to_string());
    }
    header.speed_factor = Some(crate::plausible::along_factor(&file));
    let camera_checks = crate::plausible::check_camera(&file);
    file.replace_checks(crate::plausible::CAMERA_CHECK, camera_checks);
    let speeds = crate::plausible::check_speeds(&tracks, &file, config.frames.image_fps.is_some());
    file.replace_checks(crate::plausible::SPEEDS_CHECK, speeds);
    Ok(CalibratedRun {
        file,
        camera,
        scale,
        tracks,
        header,
    })
}

/// Give `file` (camera `cal`, aggregated as `agg`) the automatic metric scale from the sizes
/// of the vehicles `boxes` (frames of `size` pixels), with its summary, its sensitivity to
/// the focal length and its warning; returns the scale, `None` (the file unchanged) when too
/// few vehicles fit a car-shaped box.
///
/// # Errors
/// When the file has no camera.
pub fn set_vehicle_scale(
    file: &mut CalibrationFile,
    boxes: &[crate::pipeline::TrackBox],
    size: (u32, u32),
    cal: &Calibration,
    agg: &Aggregated,
) -> Result<Option<f64>> {
    let Some(auto) = crate::autoscale::vehicle_scale_of(boxes, size, cal, 0) else {
        return Ok(None);
    };
    file.set_vehicle_scale(auto.m_per_unit, auto.interval)
        .map_err(anyhow::Error::msg)?;
    file.summary = Some(format!(
        "{}{}{}",
        file.summary.as_deref().unwrap_or_default(),
        vpcal_formats::calib::SCALE_SUMMARY_SEPARATOR,
        crate::autoscale::summary_line(&auto, cal.plane_distance())
    ));
    // A focal length without an interval (given) moves nothing.
    let sensitivity = agg
        .focal_interval_px
        .filter(|[lo, hi]| hi > lo)
        .and_then(|iv| crate::autoscale::focal_sensitivity(boxes, size, cal, &auto, iv));
    file.set_focal_sensitivity(sensitivity);
    let focal_part = sensitivity.map_or(String::new(), |s| {
        format!("; and as good as the focal length: {}", s.describe())
    });
    file.warnings.push(format!(
        "{} the vehicles' sizes read as typical {} x {} x {} m \
         cars (68% {:.4}-{:.4} m per unit, about ±{:.0} %){focal_part}; give a known road \
         distance (--scale-points/--scale-distance or `vpcal scale`) for measurements",
        vpcal_formats::calib::AUTOMATIC_SCALE_WARNING,
        vpcal_geom::vehicle_scale::PASSENGER_CAR[0],
        vpcal_geom::vehicle_scale::PASSENGER_CAR[1],
        vpcal_geom::vehicle_scale::PASSENGER_CAR[2],
        auto.interval[0],
        auto.interval[1],
        50.0 * (auto.interval[1] / auto.interval[0] - 1.0)
    ));
    Ok(Some(auto.m_per_unit))
}

/// How per-vehicle records are aggregated (`vpcal aggregate`'s flags).
#[derive(Debug, Clone)]
pub struct RecordSettings {
    pub method: Method,
    pub pp: PrincipalPoint,
    /// The frames' size; `None`: inferred from the records' boxes.
    pub image_size: Option<(u32, u32)>,
    pub min_score: f64,
    pub bootstrap: usize,
    pub focal_px: Option<f64>,
    /// The focal lengths the camera can have, `[short, long]` pixels (`--focal-range`).
    pub focal_range_px: Option<[f64; 2]>,
}

impl Default for RecordSettings {
    fn default() -> RecordSettings {
        RecordSettings {
            method: Method::Robust,
            pp: PrincipalPoint::Centre,
            image_size: None,
            min_score: 0.1,
            bootstrap: 30,
            focal_px: None,
            focal_range_px: None,
        }
    }
}

/// What aggregating per-vehicle records gave: the calibration file (with the camera, or
/// `not_calibrated` and the reason), and the camera when there is one.
#[derive(Debug)]
pub struct RecordsCalibration {
    pub file: CalibrationFile,
    pub result: Result<(Calibration, Aggregated)>,
    pub image_size: (u32, u32),
}

/// Aggregate per-vehicle records `items` (a VPout file's, named `origin` in the file and in
/// errors) and what the scene's background shows (`scene`, from `calibrate
/// --scene-edgelets`; may be empty) into a calibration file, as `vpcal aggregate` does.
///
/// # Errors
/// A frame size that neither the settings nor the records' boxes give. Too little evidence
/// is not an error here: the file then says why (`result` holds the reason).
pub fn aggregate_records(
    items: &[VpOutItem],
    scene: &SceneRecord,
    origin: &str,
    s: &RecordSettings,
) -> Result<RecordsCalibration> {
    let (width, height) = match s.image_size {
        Some(size) => size,
        None => infer_image_size(items).map_err(|e| {
            anyhow::anyhow!(
                "{origin}: the frame size is not known: {e}; give it with --image-size WxH"
            )
        })?,
    };
    let pp = s.pp.resolve(width, height);
    let vehicles: Vec<VehicleVps> = items.iter().map(VpOutItem::to_vehicle).collect();
    let input = InputSummary {
        path: origin.to_string(),
        kind: Some("vehicle_records".to_string()),
        width,
        height,
        vehicle_boxes: items.len() as u64,
        ..InputSummary::default()
    };
    let settings = json!({
        "method": s.method.name(),
        "min_score": s.min_score,
        "bootstrap": s.bootstrap,
        "pp": s.pp.to_json(),
        "image_size": [width, height],
        "focal": s.focal_px,
        "focal_range": s.focal_range_px,
    });
    check_focal_settings(s.focal_px, s.focal_range_px).map_err(anyhow::Error::msg)?;
    let result = aggregate(
        &vehicles,
        &edgelets_of(items),
        Scene {
            edgelets: &scene.edgelets,
            segments: &scene.segments,
        },
        pp,
        (width, height),
        s.method,
        s.min_score,
        s.bootstrap,
        s.focal_range_px,
    )
    .with_context(|| format!("aggregating {origin}"))
    .and_then(|agg| agg.into_camera(pp, s.focal_px).map_err(anyhow::Error::msg));
    let mut file = match &result {
        Ok((cal, agg)) => {
            let mut file = aggregated_file(input, cal, agg);
            // The automatic scale `calibrate` gives, from the records' boxes (a file written
            // by `calibrate --vehicles` holds every box the network saw, as its integer crop
            // box: the scale can differ from calibrate's by the rounding).
            let boxes: Vec<crate::pipeline::TrackBox> = items
                .iter()
                .filter_map(|it| {
                    let frame = it.frame_cnt;
                    (frame.is_finite() && frame >= 0.0).then_some(())?;
                    Some(crate::pipeline::TrackBox {
                        // Why: a non-negative whole frame counter.
                        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                        frame: frame.round() as u64,
                        bbox: it.box_px()?,
                        score: it.score as f32,
                    })
                })
                .collect();
            set_vehicle_scale(&mut file, &boxes, (width, height), cal, agg)?;
            // The camera's height and tilt, as `calibrate` checks them (no tracks here, so
            // no speeds).
            let camera_checks = crate::plausible::check_camera(&file);
            file.replace_checks(crate::plausible::CAMERA_CHECK, camera_checks);
            file
        }
        Err(e) => CalibrationFile::not_calibrated(input, format!("{e:#}")),
    };
    if let Value::Object(m) = settings {
        file.settings = m;
    }
    Ok(RecordsCalibration {
        file,
        result,
        image_size: (width, height),
    })
}

/// The per-vehicle records of a run in deep_vp's `VPout` layout (what `--vehicles` writes).
pub fn vehicle_items(out: &PipelineOutput) -> Vec<VpOutItem> {
    let (w, h) = (out.info.width, out.info.height);
    out.records.iter().map(|r| r.to_vpout(w, h)).collect()
}

/// The calibration file of a run that found no camera, for `reason`.
pub fn failure_file(
    out: &PipelineOutput,
    config: &PipelineConfig,
    reason: String,
) -> CalibrationFile {
    let mut file = CalibrationFile::not_calibrated(input_summary(out), reason);
    file.settings = settings(out, config);
    keep_input_warnings(&mut file, out);
    file
}

/// Write `cal` as a BrnoCompSpeed system file (scale 1 without a metric scale).
///
/// # Errors
/// The file cannot be written.
pub fn write_bcs_system(path: &Path, cal: &Calibration, scale: Option<f64>) -> Result<()> {
    write_system(path, &bcs_system(cal, scale))?;
    Ok(())
}

/// The BrnoCompSpeed system file of `cal` (scale 1 without a metric scale), without cars.
fn bcs_system(cal: &Calibration, scale: Option<f64>) -> SystemFile {
    SystemFile::new(SystemCalibration {
        vp1: cal.vp1,
        vp2: cal.vp2,
        pp: cal.pp,
        scale: scale.unwrap_or(1.0),
    })
}

/// Write `cal` as a BrnoCompSpeed system file with `tracks` as its `cars` (the unclipped
/// contact points, image pixels; scale 1 without a metric scale). Only tracks of at least
/// `min_points` unclipped points are cars: `min_points` is a speed window
/// ([`TrackSettings::window_points`](crate::tracks::TrackSettings)), so a piece too short for
/// a speed of ours is not handed to the evaluation as a measured vehicle either (on the six
/// synthetic speed scenes of the README they were 8 of the motion detector's 41 false
/// positives and none of its 67 matches; 6 of YOLOX's 37 and 1 of its 58 matches), nor is
/// a track whose speed is too uncertain ([`bcs_cars`]). Returns the number of cars written.
///
/// # Errors
/// The file cannot be written.
pub fn write_bcs_system_with_tracks(
    path: &Path,
    cal: &Calibration,
    scale: Option<f64>,
    tracks: &[VehicleTrack],
    header: &TracksHeader,
) -> Result<usize> {
    let mut system = bcs_system(cal, scale);
    system.cars = bcs_cars(tracks, header);
    let n = system.cars.len();
    write_system(path, &system)?;
    Ok(n)
}

/// The BrnoCompSpeed `cars` of `tracks`: those with at least a speed window
/// (`header.window_points`, and at least one) of unclipped points
/// ([`write_bcs_system_with_tracks`]), and, where a track has a speed, whose speed is known
/// to [`crate::tracks::BCS_MAX_SPEED_REL_UNCERTAINTY`] of itself and is possible for a road
/// vehicle ([`crate::plausible::impossible_speed`] with `header.speed_factor`).
pub fn bcs_cars(tracks: &[VehicleTrack], header: &TracksHeader) -> Vec<SystemCar> {
    let min_points = header.window_points;
    let factor = header.speed_factor.unwrap_or([1.0, 1.0]);
    tracks
        .iter()
        .filter(|t| {
            t.speed.is_none_or(|s| {
                s.uncertainty_kmh <= crate::tracks::BCS_MAX_SPEED_REL_UNCERTAINTY * s.kmh.abs()
            }) && !crate::plausible::impossible_speed(t, factor)
        })
        .map(VehicleTrack::to_system_car)
        .filter(|c| !c.frames.is_empty() && c.frames.len() >= min_points)
        .collect()
}

/// What a tracks file says besides the tracks.
#[derive(Debug, Clone)]
pub struct TracksHeader {
    pub input: String,
    pub fps: Option<f64>,
    pub size: (u32, u32),
    /// Metres per road unit of the calibration the road points use.
    pub scale_m_per_unit: Option<f64>,
    pub window_points: usize,
    /// Why speeds are missing, when they are.
    pub note: Option<String>,
    /// How far the calibration can put distances along the road, and so speeds, off: the
    /// factor range `[lo, hi]` (68 %, [`crate::plausible::along_factor`]); `None` when not
    /// known.
    pub speed_factor: Option<[f64; 2]>,
}

/// A finite number, or JSON null.
fn num(v: f64) -> Value {
    if v.is_finite() {
        json!(v)
    } else {
        Value::Null
    }
}

/// `towards_vp1`, `from_vp1`, or none (no scale or a standing track).
fn direction(t: &VehicleTrack) -> Option<&'static str> {
    t.towards_vp1
        .map(|v| if v { "towards_vp1" } else { "from_vp1" })
}

/// The tracks as JSON (`vpcal-tracks/1`, strict: non-finite numbers are null).
pub fn tracks_json(header: &TracksHeader, tracks: &[VehicleTrack]) -> Value {
    let list: Vec<Value> = tracks
        .iter()
        .map(|t| {
            let road = |k: usize| -> Value {
                if t.points.iter().all(|p| p.road_m.is_none()) {
                    return Value::Null;
                }
                Value::Array(
                    t.points
                        .iter()
                        .map(|p| p.road_m.map_or(Value::Null, |q| num(q[k])))
                        .collect(),
                )
            };
            json!({
                "id": t.id,
                "frames": t.points.iter().map(|p| p.frame).collect::<Vec<_>>(),
                "time_s": t.points.iter().map(|p| num(p.time_s)).collect::<Vec<_>>(),
                "x_px": t.points.iter().map(|p| num(p.image.x)).collect::<Vec<_>>(),
                "y_px": t.points.iter().map(|p| num(p.image.y)).collect::<Vec<_>>(),
                "clipped": t.points.iter().map(|p| p.clipped).collect::<Vec<_>>(),
                "road_x_m": road(0),
                "road_y_m": road(1),
                "speed_kmh": t.speed.map_or(Value::Null, |s| num(s.kmh)),
                "speed_uncertainty_kmh": t.speed.map_or(Value::Null, |s| num(s.uncertainty_kmh)),
                "speed_calibration_uncertainty_kmh": t.speed.map_or(Value::Null, |s| {
                    calibration_uncertainty_kmh(s.kmh, header.speed_factor).map_or(Value::Null, num)
                }),
                "speed_possible": t.speed.map(|_| {
                    !crate::plausible::impossible_speed(t, header.speed_factor.unwrap_or([1.0, 1.0]))
                }),
                "speed_fit_kmh": t.speed.map_or(Value::Null, |s| num(s.fit_kmh)),
                "speed_windows": t.speed.map_or(0, |s| s.windows),
                "lateral_m": t.lateral_m.map_or(Value::Null, num),
                "lane": t.lane,
                "direction": direction(t),
            })
        })
        .collect();
    json!({
        "format": "vpcal-tracks/1",
        "input": header.input,
        "fps": header.fps.map_or(Value::Null, num),
        "width": header.size.0,
        "height": header.size.1,
        "scale_m_per_unit": header.scale_m_per_unit.map_or(Value::Null, num),
        "speed_window_points": header.window_points,
        "speed_calibration_factor": header.speed_factor,
        "note": header.note,
        "tracks": list,
    })
}

/// The part of a speed `kmh` that the calibration leaves open (half the width of its 68 %
/// range from the along-road factor `factor`), km/h; `None` without a factor.
pub fn calibration_uncertainty_kmh(kmh: f64, factor: Option<[f64; 2]>) -> Option<f64> {
    factor.map(|[lo, hi]| 0.5 * kmh.abs() * (hi - lo))
}

/// The tracks as CSV: one row per track point, the track's speed columns repeated on each.
pub fn tracks_csv(header: &TracksHeader, tracks: &[VehicleTrack]) -> String {
    let opt = |v: Option<f64>| {
        v.filter(|x| x.is_finite())
            .map_or(String::new(), |x| format!("{x}"))
    };
    let factor = header.speed_factor.unwrap_or([1.0, 1.0]);
    let mut s = String::from(
        "id,frame,time_s,x_px,y_px,clipped,road_x_m,road_y_m,speed_kmh,speed_uncertainty_kmh,\
         speed_calibration_uncertainty_kmh,speed_possible,speed_fit_kmh,lateral_m,lane,direction\n",
    );
    for t in tracks {
        let possible = t.speed.map_or(String::new(), |_| {
            u8::from(!crate::plausible::impossible_speed(t, factor)).to_string()
        });
        for p in &t.points {
            s.push_str(&format!(
                "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
                t.id,
                p.frame,
                opt(Some(p.time_s)),
                opt(Some(p.image.x)),
                opt(Some(p.image.y)),
                u8::from(p.clipped),
                opt(p.road_m.map(|q| q[0])),
                opt(p.road_m.map(|q| q[1])),
                opt(t.speed.map(|v| v.kmh)),
                opt(t.speed.map(|v| v.uncertainty_kmh)),
                opt(t
                    .speed
                    .and_then(|v| calibration_uncertainty_kmh(v.kmh, header.speed_factor))),
                possible,
                opt(t.speed.map(|v| v.fit_kmh)),
                opt(t.lateral_m),
                t.lane.map_or(String::new(), |l| l.to_string()),
                direction(t).unwrap_or(""),
            ));
        }
    }
    s
}

/// The tracks of a run (no lanes on a curved road), and why they have no speeds when they
/// have none.
pub fn run_tracks(
    out: &PipelineOutput,
    road: Option<(&Calibration, f64)>,
    calibrated: bool,
    curved_road: bool,
) -> (Vec<VehicleTrack>, TracksHeader) {
    let settings = TrackSettings {
        lanes: !curved_road,
        ..TrackSettings::default()
    };
    let mut header = TracksHeader {
        input: out.info.path.display().to_string(),
        fps: out.info.fps.filter(|f| f.is_finite() && *f > 0.0),
        size: (out.info.width, out.info.height),
        scale_m_per_unit: road.map(|r| r.1),
        window_points: settings.window_points,
        note: None,
        speed_factor: None,
    };
    let Some(fps) = header.fps else {
        header.note = Some(
            "no frame rate: tracks need consecutive frames (a video, or an image folder with \
             --fps)"
                .to_string(),
        );
        return (Vec::new(), header);
    };
    if road.is_none() {
        header.note = Some(if calibrated {
            "no metric scale: tracks without road points and speeds (give --scale-points and \
             --scale-distance)"
                .to_string()
        } else {
            "no calibration: tracks without road points and speeds".to_string()
        });
    }
    let tracks = build_tracks(
        &out.boxes,
        fps,
        road,
        (out.info.width, out.info.height),
        &settings,
    );
    (tracks, header)
}

/// What the tracks counted, after their number: `, M with a speed, median speed X km/h, L
/// lanes, T towards VP1 and F from it` (the parts that apply), and the number.
pub fn tracks_counts(tracks: &[VehicleTrack]) -> (usize, String) {
    let (n, with_speed, median) = summary(tracks);
    let mut text = format!(", {with_speed} with a speed");
    if let Some(m) = median {
        text.push_str(&format!(", median speed {m:.1} km/h"));
    }
    let lanes = tracks.iter().filter_map(|t| t.lane).max().unwrap_or(0);
    if lanes > 0 {
        let towards = tracks
            .iter()
            .filter(|t| t.towards_vp1 == Some(true))
            .count();
        let from = tracks
            .iter()
            .filter(|t| t.towards_vp1 == Some(false))
            .count();
        text.push_str(&format!(
            ", {lanes} lanes, {towards} towards VP1 and {from} from it"
        ));
    }
    (n, text)
}

/// The one-line summary of the tracks.
pub fn tracks_line(tracks: &[VehicleTrack], header: &TracksHeader) -> String {
    let (n, counts) = tracks_counts(tracks);
    let mut line = format!("tracks: {n}{counts}");
    if let Some(note) = &header.note {
        line.push_str(&format!(" ({note})"));
    }
    line
}

/// Tracks read back from a tracks file (`calibrate --tracks`): what they were measured on,
/// and each track's points (frames, times, contact points, clipped flags; no road points).
#[derive(Debug, Clone)]
pub struct SavedTracks {
    pub input: Option<String>,
    pub fps: Option<f64>,
    /// `(width, height)` of the frames (JSON files).
    pub size: Option<(u32, u32)>,
    pub tracks: Vec<Vec<crate::tracks::TrackPoint>>,
}

/// Read a tracks file written by `calibrate --tracks`: CSV (by the `.csv` extension) or JSON
/// (`vpcal-tracks/1`).
///
/// # Errors
/// An unreadable file, or one that is not a tracks file (the message names the field, row or
/// column).
pub fn read_tracks(path: &Path) -> Result<SavedTracks> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| anyhow::anyhow!("{}: cannot read: {e}", path.display()))?;
    let csv = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("csv"));
    let parsed = if csv {
        tracks_from_csv(&text)
    } else {
        tracks_from_json(&text)
    };
    parsed.map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
}

fn tracks_from_csv(text: &str) -> Result<SavedTracks, String> {
    let mut lines = text.lines();
    let head: Vec<&str> = lines
        .next()
        .ok_or("empty file: expected the header of a tracks CSV")?
        .split(',')
        .map(str::trim)
        .collect();
    let col = |name: &str| {
        head.iter().position(|h| *h == name).ok_or(format!(
            "no column {name:?}: not a tracks CSV written by `vpcal calibrate --tracks`"
        ))
    };
    let [id, frame, time, x, y, clipped] =
        ["id", "frame", "time_s", "x_px", "y_px", "clipped"].map(col);
    let (id, frame, time, x, y, clipped) = (id?, frame?, time?, x?, y?, clipped?);
    let mut tracks: Vec<(String, Vec<crate::tracks::TrackPoint>)> = Vec::new();
    for (n, line) in lines.enumerate().filter(|(_, l)| !l.trim().is_empty()) {
        let row: Vec<&str> = line.split(',').collect();
        let field = |i: usize, name: &str| -> Result<f64, String> {
            row.get(i)
                .and_then(|v| v.trim().parse::<f64>().ok())
                .filter(|v| v.is_finite())
                .ok_or(format!(
                    "row {}: column {name:?} must be a number, found {:?}",
                    n + 2,
                    row.get(i).copied().unwrap_or("")
                ))
        };
        let key = row.get(id).map_or(String::new(), |v| v.trim().to_string());
        let point = crate::tracks::TrackPoint {
            // Why: frame indices are whole, non-negative numbers in the file.
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            frame: field(frame, "frame")?.max(0.0) as u64,
            time_s: field(time, "time_s")?,
            image: vpcal_geom::Point2::new(field(x, "x_px")?, field(y, "y_px")?),
            clipped: field(clipped, "clipped")? != 0.0,
            road_m: None,
        };
        match tracks.last_mut() {
            Some((k, points)) if *k == key => points.push(point),
            _ => tracks.push((key, vec![point])),
        }
    }
    Ok(SavedTracks {
        input: None,
        fps: None,
        size: None,
        tracks: tracks.into_iter().map(|(_, p)| p).collect(),
    })
}

fn tracks_from_json(text: &str) -> Result<SavedTracks, String> {
    let doc: Value = serde_json::from_str(text).map_err(|e| format!("not a JSON document: {e}"))?;
    let tracks = tracks_from_doc(&doc)?;
    let size = doc
        .get("width")
        .and_then(Value::as_u64)
        .zip(doc.get("height").and_then(Value::as_u64))
        .and_then(|(w, h)| Some((u32::try_from(w).ok()?, u32::try_from(h).ok()?)));
    Ok(SavedTracks {
        input: doc.get("input").and_then(Value::as_str).map(str::to_string),
        fps: doc.get("fps").and_then(Value::as_f64),
        size,
        tracks: tracks.into_iter().map(|t| t.points).collect(),
    })
}

/// The tracks of a `vpcal-tracks/1` document ([`tracks_json`]): points (with their road
/// points where the file has them), speeds, lanes and directions. The file has no boxes and
/// no BrnoCompSpeed paths (`path` stays empty).
///
/// # Errors
/// Another format, or a track whose point lists are missing, not numbers, or not equally
/// long (the message names the field, e.g. `tracks[3].x_px`).
pub fn tracks_from_doc(doc: &Value) -> Result<Vec<VehicleTrack>, String> {
    match doc.get("format").and_then(Value::as_str) {
        Some("vpcal-tracks/1") => {}
        other => {
            return Err(format!(
                "field \"format\" is {other:?}: expected \"vpcal-tracks/1\" (a file written by \
                 `vpcal calibrate --tracks`)"
            ))
        }
    }
    let list = doc
        .get("tracks")
        .and_then(Value::as_array)
        .ok_or("field \"tracks\" must be a list")?;
    list.iter()
        .enumerate()
        .map(|(k, t)| track_from_json(k, t))
        .collect()
}

fn track_from_json(k: usize, t: &Value) -> Result<VehicleTrack, String> {
    let list = |name: &str| -> Result<&Vec<Value>, String> {
        t.get(name)
            .and_then(Value::as_array)
            .ok_or(format!("tracks[{k}].{name} must be a list"))
    };
    let numbers = |name: &str| -> Result<Vec<f64>, String> {
        list(name)?
            .iter()
            .map(Value::as_f64)
            .collect::<Option<Vec<f64>>>()
            .ok_or(format!("tracks[{k}].{name} must be a list of numbers"))
    };
    // Road points are null where a point has none; the lists may be absent (no camera).
    let optional = |name: &str| -> Result<Vec<Option<f64>>, String> {
        match t.get(name) {
            None | Some(Value::Null) => Ok(Vec::new()),
            Some(v) => v
                .as_array()
                .map(|a| a.iter().map(Value::as_f64).collect())
                .ok_or(format!(
                    "tracks[{k}].{name} must be a list of numbers or nulls"
                )),
        }
    };
    let frames = numbers("frames")?;
    let times = numbers("time_s")?;
    let xs = numbers("x_px")?;
    let ys = numbers("y_px")?;
    let clipped: Vec<bool> = list("clipped")?
        .iter()
        .map(Value::as_bool)
        .collect::<Option<Vec<bool>>>()
        .ok_or(format!("tracks[{k}].clipped must be a list of true/false"))?;
    let (road_x, road_y) = (optional("road_x_m")?, optional("road_y_m")?);
    let n = frames.len();
    if [times.len(), xs.len(), ys.len(), clipped.len()] != [n; 4] {
        return Err(format!(
            "tracks[{k}]: frames, time_s, x_px, y_px and clipped must be equally long"
        ));
    }
    let points = (0..n)
        .map(|i| crate::tracks::TrackPoint {
            // Why: frame indices are whole, non-negative numbers in the file.
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            frame: frames[i].max(0.0) as u64,
            time_s: times[i],
            image: vpcal_geom::Point2::new(xs[i], ys[i]),
            clipped: clipped[i],
            road_m: road_x
                .get(i)
                .copied()
                .flatten()
                .zip(road_y.get(i).copied().flatten())
                .map(|(x, y)| [x, y]),
        })
        .collect();
    let number = |name: &str| t.get(name).and_then(Value::as_f64);
    let speed = number("speed_kmh").map(|kmh| crate::tracks::SpeedEstimate {
        kmh,
        uncertainty_kmh: number("speed_uncertainty_kmh").unwrap_or(f64::NAN),
        fit_kmh: number("speed_fit_kmh").unwrap_or(f64::NAN),
        windows: t
            .get("speed_windows")
            .and_then(Value::as_u64)
            .and_then(|w| usize::try_from(w).ok())
            .unwrap_or(0),
    });
    Ok(VehicleTrack {
        id: t.get("id").and_then(Value::as_u64).unwrap_or(0),
        points,
        speed,
        lateral_m: number("lateral_m"),
        lane: t
            .get("lane")
            .and_then(Value::as_u64)
            .and_then(|l| usize::try_from(l).ok()),
        towards_vp1: match t.get("direction").and_then(Value::as_str) {
            Some("towards_vp1") => Some(true),
            Some("from_vp1") => Some(false),
            _ => None,
        },
        path: Vec::new(),
    })
}

/// Write the tracks to `path`: CSV when it ends in `.csv`, else JSON (atomically).
///
/// # Errors
/// The file cannot be written.
pub fn write_tracks(path: &Path, header: &TracksHeader, tracks: &[VehicleTrack]) -> Result<()> {
    let csv = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("csv"));
    let bytes = if csv {
        tracks_csv(header, tracks).into_bytes()
    } else {
        let mut b = serde_json::to_vec_pretty(&tracks_json(header, tracks))?;
        b.push(b'\n');
        b
    };
    vpcal_formats::fs::write_atomic(path, &bytes)?;
    Ok(())
}

/// Write the OpenCV block of a calibrated `file` as an OpenCV FileStorage YAML file.
///
/// # Errors
/// The file has no camera, or cannot be written.
pub fn write_opencv_yaml(path: &Path, file: &CalibrationFile) -> Result<()> {
    let Some(cv) = &file.opencv else {
        bail!("the calibration has no camera to export");
    };
    let yaml = cv.to_filestorage_yaml(file.camera_height_m);
    vpcal_formats::fs::write_atomic(path, yaml.as_bytes())?;
    Ok(())
}

/// Write the per-vehicle records of a run (deep_vp's `VPout` layout, strict JSON).
///
/// # Errors
/// The file cannot be written.
pub fn write_vehicles(path: &Path, out: &PipelineOutput) -> Result<()> {
    write_vpout(path, &vehicle_items(out))?;
    Ok(())
}

/// Write the scene's edgelets and line segments of a run (what `--scene-edgelets` writes).
///
/// # Errors
/// The file cannot be written.
pub fn write_scene(path: &Path, out: &PipelineOutput) -> Result<()> {
    write_scene_edgelets(
        path,
        &SceneRecord {
            edgelets: out.scene_edgelets.clone(),
            segments: out.scene_segments.clone(),
        },
    )?;
    Ok(())
}

/// `path` made absolute with its folder's symbolic links resolved (the file itself need not
/// exist); `None` when its folder does not exist.
fn resolved(path: &Path) -> Option<std::path::PathBuf> {
    if let Ok(p) = path.canonicalize() {
        return Some(p);
    }
    let name = path.file_name()?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    Some(dir.canonicalize().ok()?.join(name))
}

/// Outputs that would overwrite an input or each other: each output (flag, path) must differ
/// from every input (flag or role, path) and from every other output, and no picture may be
/// written into an input folder of pictures (it would become a frame of the next run).
///
/// # Errors
/// A message naming both flags and the path.
pub fn check_distinct_paths(
    inputs: &[(&str, &Path)],
    outputs: &[(&str, &Path)],
) -> Result<(), String> {
    let ins: Vec<(&str, &Path, Option<std::path::PathBuf>)> =
        inputs.iter().map(|(f, p)| (*f, *p, resolved(p))).collect();
    let outs: Vec<(&str, &Path, Option<std::path::PathBuf>)> =
        outputs.iter().map(|(f, p)| (*f, *p, resolved(p))).collect();
    for (i, (flag, path, r)) in outs.iter().enumerate() {
        let Some(r) = r else { continue };
        for (what, input, ri) in &ins {
            let Some(ri) = ri else { continue };
            if r == ri {
                return Err(format!(
                    "{flag} {}: is the {what}; it would be overwritten (give another file name)",
                    path.display()
                ));
            }
            if ri.is_dir() && r.starts_with(ri) && vpcal_video::source::is_image_path(r) {
                return Err(format!(
                    "{flag} {}: a picture inside the input folder {}, which would read it as a \
                     frame next time (write it elsewhere)",
                    path.display(),
                    input.display()
                ));
            }
        }
        for (other, other_path, ro) in &outs[..i] {
            if ro.as_ref() == Some(r) {
                return Err(format!(
                    "{flag} {} and {other} {}: the same file; one output would replace the \
                     other (give two file names)",
                    path.display(),
                    other_path.display()
                ));
            }
        }
    }
    Ok(())
}

/// An output file can be created at `path`: its folder exists and is writable, and `path`
/// is not a folder. `flag` names the option in the error.
///
/// # Errors
/// A message naming the flag and the path.
pub fn check_destination(flag: &str, path: &Path) -> Result<()> {
    if path.is_dir() {
        bail!(
            "{flag} {}: is a folder, expected a file name",
            path.display()
        );
    }
    let dir = match path.parent() {
        Some(dir) if !dir.as_os_str().is_empty() => dir,
        _ => Path::new("."),
    };
    if !dir.is_dir() {
        bail!(
            "{flag} {}: the folder {} does not exist",
            path.display(),
            dir.display()
        );
    }
    // Writable: create and remove a probe file next to it.
    let probe = dir.join(format!(".vpcal-write-test-{}", std::process::id()));
    match std::fs::File::create(&probe) {
        Ok(_) => {
            let _ = std::fs::remove_file(&probe);
            Ok(())
        }
        Err(e) => bail!(
            "{flag} {}: cannot write in {}: {e}",
            path.display(),
            dir.display()
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tracks::TrackPoint;
    use vpcal_geom::Point2;

    /// A track of `n` points of which the first `clipped` touch the border.
    fn track(id: u64, n: u64, clipped: u64) -> VehicleTrack {
        VehicleTrack {
            id,
            points: (0..n)
                .map(|f| TrackPoint {
                    frame: f,
                    time_s: f as f64 / 25.0,
                    image: Point2::new(10.0 + f as f64, 50.0),
                    clipped: f < clipped,
                    road_m: None,
                })
                .collect(),
            speed: None,
            lateral_m: None,
            lane: None,
            towards_vp1: None,
            path: vec![],
        }
    }

    fn header(window_points: usize) -> TracksHeader {
        TracksHeader {
            input: "clip.mp4".into(),
            fps: Some(25.0),
            size: (640, 480),
            scale_m_per_unit: Some(0.05),
            window_points,
            note: None,
            speed_factor: Some([0.9, 1.1]),
        }
    }

    #[test]
    fn bcs_cars_are_the_tracks_with_a_speed_window_of_unclipped_points() {
        let tracks = [
            track(1, 9, 0),
            track(2, 10, 0),
            track(3, 14, 5),
            track(4, 15, 5),
        ];
        let cars = bcs_cars(&tracks, &header(10));
        let ids: Vec<i64> = cars.iter().map(|c| c.id).collect();
        assert_eq!(ids, vec![2, 4]);
        // Only the unclipped points are the car's.
        assert_eq!(cars[1].frames.first(), Some(&5.0));
        assert_eq!(cars[1].pos_x.len(), 10);
        // A limit of 0 still leaves out a track with no unclipped point.
        assert_eq!(bcs_cars(&[track(5, 3, 3)], &header(0)).len(), 0);
        // A speed known to 10 % of itself is written, one known to 12 % is not.
        let with_speed = |id, kmh, uncertainty_kmh| VehicleTrack {
            speed: Some(crate::tracks::SpeedEstimate {
                kmh,
                uncertainty_kmh,
                fit_kmh: kmh,
                windows: 5,
            }),
            ..track(id, 20, 0)
        };
        let cars = bcs_cars(
            &[with_speed(6, 100.0, 10.0), with_speed(7, 100.0, 12.0)],
            &header(10),
        );
        let ids: Vec<i64> = cars.iter().map(|c| c.id).collect();
        assert_eq!(ids, vec![6]);
        // A speed no road vehicle drives, even at the low end of the calibration's factor,
        // is not a car; one that the factor can bring down to a possible speed is.
        let cars = bcs_cars(
            &[with_speed(8, 1418.0, 5.0), with_speed(9, 320.0, 5.0)],
            &header(10),
        );
        let ids: Vec<i64> = cars.iter().map(|c| c.id).collect();
        assert_eq!(ids, vec![9]);
        // The CSV says which speeds are possible and the calibration's part of each.
        let csv = tracks_csv(&header(10), &[with_speed(8, 1418.0, 5.0)]);
        let first = csv.lines().nth(1).unwrap();
        let cols: Vec<&str> = first.split(',').collect();
        assert_eq!(cols[9], "5");
        assert!(
            (cols[10].parse::<f64>().unwrap() - 141.8).abs() < 1e-9,
            "{first}"
        );
        assert_eq!(cols[11], "0");
    }
}
