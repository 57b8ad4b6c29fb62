//! What a calibration run writes: the calibration file, the BrnoCompSpeed system file, the
//! per-vehicle records, the vehicle tracks; and the checks that let a run fail before it starts, not after.

use std::path::Path;

use anyhow::{bail, Context, Result};
use serde_json::{json, Map, Value};
use vpcal_formats::bcs::{write_system, SystemCalibration, SystemCar, SystemFile};
use vpcal_formats::calib::{CalibrationFile, Dropped, InputSummary};
use vpcal_formats::reference::{infer_image_size, write_scene_edgelets, write_vpout, VpOutItem};
use vpcal_geom::aggregate::edgelets::Edgelet;
use vpcal_geom::aggregate::VehicleVps;
use vpcal_geom::camera::Calibration;
use vpcal_video::{SourceKind, Start};

use crate::aggregate::{aggregate, check_focal_settings, edgelets_of, Aggregated, Method};
use crate::pipeline::{PipelineConfig, PipelineOutput, PrincipalPoint};
use crate::road::{scale_from_points, KnownDistance};
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
        "edgelets": c.edgelets,
        "replay": c.replay,
        "bootstrap": c.bootstrap,
        "pp": c.pp.to_json(),
        "focal": c.focal_px,
        "focal_range": c.focal_range_px,
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
    file
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
    file
}

/// [`calibration_file`] with the metric scale of `known` (`calibrate --scale-points`) when
/// given, else the automatic scale from the vehicles' sizes ([`crate::autoscale`]) when
/// enough vehicles fit a car-shaped box; returns the file and the scale.
///
/// # Errors
/// Pixels of `known` that do not fix a scale (above the horizon, coinciding).
pub fn calibrated_run_file(
    out: &PipelineOutput,
    config: &PipelineConfig,
    cal: &Calibration,
    agg: &Aggregated,
    known: Option<KnownDistance>,
) -> Result<(CalibrationFile, Option<f64>)> {
    let mut file = calibration_file(out, config, cal, agg);
    let Some(k) = known else {
        let Some(auto) = crate::autoscale::vehicle_scale(out, cal, 0) else {
            return Ok((file, None));
        };
        file.set_vehicle_scale(auto.m_per_unit, auto.interval)
            .map_err(anyhow::Error::msg)?;
        file.summary = Some(format!(
            "{}; scale {}",
            file.summary.as_deref().unwrap_or_default(),
            crate::autoscale::summary_line(&auto, cal.plane_distance())
        ));
        let sensitivity = agg
            .focal_interval_px
            .and_then(|iv| crate::autoscale::focal_sensitivity(out, cal, &auto, iv));
        file.scale_focal_sensitivity = sensitivity;
        let focal_part = sensitivity.map_or(String::new(), |s| {
            format!(
                "; and as good as the focal length: over its 68% interval ({:.0}-{:.0} px) \
                 distances along the road (and speeds) change by x{:.2}-x{:.2}, across it by \
                 x{:.2}-x{:.2}",
                s.focal_px[0],
                s.focal_px[1],
                s.along[0].min(s.along[1]),
                s.along[0].max(s.along[1]),
                s.across[0].min(s.across[1]),
                s.across[0].max(s.across[1])
            )
        });
        file.warnings.push(format!(
            "the metric scale is automatic: the vehicles' sizes read as typical {} x {} x {} m \
             cars (68% {:.4}-{:.4} m per unit, about ±{:.0} %){focal_part}; give a known road \
             distance (--scale-points/--scale-distance or `vpcal scale`) for measurements",
            vpcal_geom::vehicle_scale::PASSENGER_CAR[0],
            vpcal_geom::vehicle_scale::PASSENGER_CAR[1],
            vpcal_geom::vehicle_scale::PASSENGER_CAR[2],
            auto.interval[0],
            auto.interval[1],
            50.0 * (auto.interval[1] / auto.interval[0] - 1.0)
        ));
        return Ok((file, Some(auto.m_per_unit)));
    };
    let (scale, reference) = scale_from_points(cal, k.p1, k.p2, k.distance_m, "--scale-points")?;
    file.set_scale(scale, Some(reference))
        .map_err(anyhow::Error::msg)?;
    Ok((file, Some(scale)))
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
/// errors) and the scene's edgelets (`scene`, from `calibrate --scene-edgelets`; may be empty)
/// into a calibration file, as `vpcal aggregate` does.
///
/// # Errors
/// A frame size that neither the settings nor the records' boxes give. Too little evidence
/// is not an error here: the file then says why (`result` holds the reason).
pub fn aggregate_records(
    items: &[VpOutItem],
    scene: &[Edgelet],
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
        scene,
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
        Ok((cal, agg)) => aggregated_file(input, cal, agg),
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
    min_points: usize,
) -> Result<usize> {
    let mut system = bcs_system(cal, scale);
    system.cars = bcs_cars(tracks, min_points);
    let n = system.cars.len();
    write_system(path, &system)?;
    Ok(n)
}

/// The BrnoCompSpeed `cars` of `tracks`: those with at least `min_points` (and at least one)
/// unclipped points ([`write_bcs_system_with_tracks`]), and, where a track has a speed, whose
/// speed is known to [`crate::tracks::BCS_MAX_SPEED_REL_UNCERTAINTY`] of itself.
pub fn bcs_cars(tracks: &[VehicleTrack], min_points: usize) -> Vec<SystemCar> {
    tracks
        .iter()
        .filter(|t| {
            t.speed.is_none_or(|s| {
                s.uncertainty_kmh <= crate::tracks::BCS_MAX_SPEED_REL_UNCERTAINTY * s.kmh.abs()
            })
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
        "note": header.note,
        "tracks": list,
    })
}

/// The tracks as CSV: one row per track point, the track's speed columns repeated on each.
pub fn tracks_csv(tracks: &[VehicleTrack]) -> String {
    let opt = |v: Option<f64>| {
        v.filter(|x| x.is_finite())
            .map_or(String::new(), |x| format!("{x}"))
    };
    let mut s = String::from(
        "id,frame,time_s,x_px,y_px,clipped,road_x_m,road_y_m,speed_kmh,speed_uncertainty_kmh,\
         speed_fit_kmh,lateral_m,lane,direction\n",
    );
    for t in tracks {
        for p in &t.points {
            s.push_str(&format!(
                "{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
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
                opt(t.speed.map(|v| v.fit_kmh)),
                opt(t.lateral_m),
                t.lane.map_or(String::new(), |l| l.to_string()),
                direction(t).unwrap_or(""),
            ));
        }
    }
    s
}

/// The tracks of a run, and why they have no speeds when they have none.
pub fn run_tracks(
    out: &PipelineOutput,
    road: Option<(&Calibration, f64)>,
    calibrated: bool,
) -> (Vec<VehicleTrack>, TracksHeader) {
    let settings = TrackSettings::default();
    let mut header = TracksHeader {
        input: out.info.path.display().to_string(),
        fps: out.info.fps.filter(|f| f.is_finite() && *f > 0.0),
        size: (out.info.width, out.info.height),
        scale_m_per_unit: road.map(|r| r.1),
        window_points: settings.window_points,
        note: None,
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

/// The one-line summary of the tracks.
pub fn tracks_line(tracks: &[VehicleTrack], header: &TracksHeader) -> String {
    let (n, with_speed, median) = summary(tracks);
    let mut line = format!("tracks: {n}, {with_speed} with a speed");
    if let Some(m) = median {
        line.push_str(&format!(", median speed {m:.1} km/h"));
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
        line.push_str(&format!(
            ", {lanes} lanes, {towards} towards VP1 and {from} from it"
        ));
    }
    if let Some(note) = &header.note {
        line.push_str(&format!(" ({note})"));
    }
    line
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
        tracks_csv(tracks).into_bytes()
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

/// Write the scene's edgelets of a run (what `--scene-edgelets` writes).
///
/// # Errors
/// The file cannot be written.
pub fn write_scene(path: &Path, out: &PipelineOutput) -> Result<()> {
    write_scene_edgelets(path, &out.scene_edgelets)?;
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
    use vpcal_geom::{BoxPx, Point2};

    /// A track of `n` points of which the first `clipped` touch the border.
    fn track(id: u64, n: u64, clipped: u64) -> VehicleTrack {
        VehicleTrack {
            id,
            points: (0..n)
                .map(|f| TrackPoint {
                    frame: f,
                    time_s: f as f64 / 25.0,
                    image: Point2::new(10.0 + f as f64, 50.0),
                    box_px: BoxPx::new(0.0, 0.0, 1.0, 1.0),
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

    #[test]
    fn bcs_cars_are_the_tracks_with_a_speed_window_of_unclipped_points() {
        let tracks = [
            track(1, 9, 0),
            track(2, 10, 0),
            track(3, 14, 5),
            track(4, 15, 5),
        ];
        let cars = bcs_cars(&tracks, 10);
        let ids: Vec<i64> = cars.iter().map(|c| c.id).collect();
        assert_eq!(ids, vec![2, 4]);
        // Only the unclipped points are the car's.
        assert_eq!(cars[1].frames.first(), Some(&5.0));
        assert_eq!(cars[1].pos_x.len(), 10);
        // A limit of 0 still leaves out a track with no unclipped point.
        assert_eq!(bcs_cars(&[track(5, 3, 3)], 0).len(), 0);
        // A speed known to 10 % of itself is written, one known to 12 % is not.
        let with_speed = |id, uncertainty_kmh| VehicleTrack {
            speed: Some(crate::tracks::SpeedEstimate {
                kmh: 100.0,
                uncertainty_kmh,
                fit_kmh: 100.0,
                windows: 5,
            }),
            ..track(id, 20, 0)
        };
        let cars = bcs_cars(&[with_speed(6, 10.0), with_speed(7, 12.0)], 10);
        let ids: Vec<i64> = cars.iter().map(|c| c.id).collect();
        assert_eq!(ids, vec![6]);
    }
}
