//! BrnoCompSpeed files: ground truth (`gt_data.pkl`, or its JSON twin `gt_data.json`) and
//! calibration results (`system_<name>.json`).
//!
//! Layout: `dataset/sessionN_{left,center,right}/gt_data.pkl` and
//! `results/sessionN_{left,center,right}/system_<name>.json` with
//! `{"camera_calibration": {"vp1", "vp2", "pp", "scale"}, "cars": [{"id", "frames", "posX", "posY"}]}`.
//!
//! `gt_data.json` holds the same keys as the pickle (numpy arrays as lists, sets as lists);
//! vpcal's synthetic scenes write it, since they have no reason to write pickles.

use crate::error::FormatError;
use crate::fs::{read_json, write_json};
use crate::json::{AccessError, Json};
use std::path::{Path, PathBuf};
use vpcal_geom::metrics::RoadMeasurement;
use vpcal_geom::Point2;

/// One ground-truth distance between two road points.
#[derive(Debug, Clone, PartialEq)]
pub struct DistanceMeasurement {
    pub p1: Point2,
    pub p2: Point2,
    pub distance_m: f64,
    /// Whether the measured segment runs along the traffic direction (towards VP1).
    pub to_vp1: bool,
}

/// A ground-truth vehicle pass (for speed evaluation).
#[derive(Debug, Clone, PartialEq)]
pub struct GtCar {
    pub car_id: i64,
    pub speed_kmh: f64,
    pub valid: bool,
    pub lane_index: Vec<i64>,
    /// `(measurementLineId, videoTime in seconds)`.
    pub intersections: Vec<(i64, f64)>,
}

/// The content of `gt_data.pkl` that vpcal uses.
#[derive(Debug, Clone, PartialEq)]
pub struct GtData {
    pub fps: f64,
    pub distance_measurements: Vec<DistanceMeasurement>,
    /// Homogeneous lines `[a, b, c]`.
    pub measurement_lines: Vec<[f64; 3]>,
    /// Homogeneous lines `[a, b, c]`.
    pub lane_div_lines: Vec<[f64; 3]>,
    pub invalid_lanes: Vec<i64>,
    pub cars: Vec<GtCar>,
}

impl GtData {
    /// The distance measurements as geometry-crate measurements.
    pub fn road_measurements(&self) -> Vec<RoadMeasurement> {
        self.distance_measurements
            .iter()
            .map(|d| RoadMeasurement {
                p1: d.p1,
                p2: d.p2,
                distance_m: d.distance_m,
            })
            .collect()
    }

    /// Parse from the generic value (a parsed `gt_data.json`, or a pickle converted to JSON).
    ///
    /// # Errors
    /// [`AccessError`] naming the field.
    pub fn from_json(v: &Json) -> Result<GtData, AccessError> {
        let homogeneous = |j: &Json, at: &str| -> Result<Point2, AccessError> {
            let xs = j.as_f64_vec(at)?;
            match xs.as_slice() {
                [x, y] => Ok(Point2::new(*x, *y)),
                [x, y, w] if *w != 0.0 => Ok(Point2::new(x / w, y / w)),
                _ => Err(AccessError {
                    path: at.into(),
                    expected: "a point [x, y] or [x, y, w] with w != 0".into(),
                    found: j.kind(),
                }),
            }
        };
        let mut distance_measurements = Vec::new();
        let dm = v.field("", "distanceMeasurement")?;
        for (i, m) in dm.as_array("distanceMeasurement")?.iter().enumerate() {
            let at = format!("distanceMeasurement[{i}]");
            distance_measurements.push(DistanceMeasurement {
                p1: homogeneous(m.field(&at, "p1")?, &format!("{at}.p1"))?,
                p2: homogeneous(m.field(&at, "p2")?, &format!("{at}.p2"))?,
                distance_m: m
                    .field(&at, "distance")?
                    .as_f64(&format!("{at}.distance"))?,
                to_vp1: match m.get("toVP1") {
                    Some(b) => b.as_bool(&format!("{at}.toVP1"))?,
                    None => false,
                },
            });
        }
        let lines = |key: &str| -> Result<Vec<[f64; 3]>, AccessError> {
            match v.get(key) {
                None | Some(Json::Null) => Ok(vec![]),
                Some(l) => l
                    .as_array(key)?
                    .iter()
                    .enumerate()
                    .map(|(i, x)| x.as_f64_array::<3>(&format!("{key}[{i}]")))
                    .collect(),
            }
        };
        let ints = |j: &Json, at: &str| -> Result<Vec<i64>, AccessError> {
            Ok(j.as_f64_vec(at)?.into_iter().map(|x| x as i64).collect())
        };
        let mut cars = Vec::new();
        if let Some(list) = v.get("cars") {
            for (i, c) in list.as_array("cars")?.iter().enumerate() {
                let at = format!("cars[{i}]");
                let mut intersections = Vec::new();
                if let Some(xs) = c.get("intersections") {
                    for (k, x) in xs
                        .as_array(&format!("{at}.intersections"))?
                        .iter()
                        .enumerate()
                    {
                        let at = format!("{at}.intersections[{k}]");
                        intersections.push((
                            x.field(&at, "measurementLineId")?
                                .as_f64(&format!("{at}.measurementLineId"))?
                                as i64,
                            x.field(&at, "videoTime")?
                                .as_f64(&format!("{at}.videoTime"))?,
                        ));
                    }
                }
                cars.push(GtCar {
                    car_id: c.field(&at, "carId")?.as_f64(&format!("{at}.carId"))? as i64,
                    speed_kmh: c.field(&at, "speed")?.as_f64(&format!("{at}.speed"))?,
                    valid: c.field(&at, "valid")?.as_bool(&format!("{at}.valid"))?,
                    lane_index: match c.get("laneIndex") {
                        Some(l) => ints(l, &format!("{at}.laneIndex"))?,
                        None => vec![],
                    },
                    intersections,
                });
            }
        }
        Ok(GtData {
            fps: v.field("", "fps")?.as_f64("fps")?,
            distance_measurements,
            measurement_lines: lines("measurementLines")?,
            lane_div_lines: lines("laneDivLines")?,
            invalid_lanes: match v.get("invalidLanes") {
                Some(l) => ints(l, "invalidLanes")?,
                None => vec![],
            },
            cars,
        })
    }

    /// The ground truth as JSON (the layout of `gt_data.json`).
    pub fn to_json(&self) -> Json {
        let point = |p: Point2| Json::from(&[p.x, p.y, 1.0][..]);
        let obj = |m: Vec<(&str, Json)>| {
            Json::Object(m.into_iter().map(|(k, v)| (k.to_string(), v)).collect())
        };
        let ints = |v: &[i64]| Json::Array(v.iter().map(|x| Json::Number(*x as f64)).collect());
        let lines = |v: &[[f64; 3]]| Json::Array(v.iter().map(|l| Json::from(&l[..])).collect());
        obj(vec![
            ("fps", self.fps.into()),
            (
                "distanceMeasurement",
                Json::Array(
                    self.distance_measurements
                        .iter()
                        .map(|d| {
                            obj(vec![
                                ("p1", point(d.p1)),
                                ("p2", point(d.p2)),
                                ("distance", d.distance_m.into()),
                                ("toVP1", Json::Bool(d.to_vp1)),
                            ])
                        })
                        .collect(),
                ),
            ),
            ("measurementLines", lines(&self.measurement_lines)),
            ("laneDivLines", lines(&self.lane_div_lines)),
            ("invalidLanes", ints(&self.invalid_lanes)),
            (
                "cars",
                Json::Array(
                    self.cars
                        .iter()
                        .map(|c| {
                            obj(vec![
                                ("carId", Json::Number(c.car_id as f64)),
                                ("speed", c.speed_kmh.into()),
                                ("valid", Json::Bool(c.valid)),
                                ("laneIndex", ints(&c.lane_index)),
                                (
                                    "intersections",
                                    Json::Array(
                                        c.intersections
                                            .iter()
                                            .map(|(id, t)| {
                                                obj(vec![
                                                    ("measurementLineId", Json::Number(*id as f64)),
                                                    ("videoTime", (*t).into()),
                                                ])
                                            })
                                            .collect(),
                                    ),
                                ),
                            ])
                        })
                        .collect(),
                ),
            ),
        ])
    }
}

/// Read the ground truth of one BCS video directory: `gt_data.pkl` when present, else
/// `gt_data.json`.
///
/// # Errors
/// [`FormatError`] naming the file (and the field) when neither exists or parsing fails.
pub fn read_gt(video_dir: &Path) -> Result<GtData, FormatError> {
    let pkl = video_dir.join("gt_data.pkl");
    if pkl.is_file() {
        let value = crate::pickle::from_path(&pkl, &crate::pickle::LoadOptions::default())
            .map_err(|e| FormatError::Invalid {
                path: pkl.clone(),
                message: e.to_string(),
            })?;
        let json =
            crate::pickle_json::to_json(&value).map_err(|m| FormatError::invalid(&pkl, m))?;
        return GtData::from_json(&json).map_err(|e| FormatError::field(&pkl, e));
    }
    let js = video_dir.join("gt_data.json");
    if js.is_file() {
        let doc = read_json(&js)?;
        return GtData::from_json(&doc).map_err(|e| FormatError::field(&js, e));
    }
    Err(FormatError::invalid(
        video_dir,
        "no gt_data.pkl or gt_data.json in this directory",
    ))
}

/// Write `gt_data.json` atomically.
///
/// # Errors
/// [`FormatError::Io`] naming the file.
pub fn write_gt_json(path: &Path, gt: &GtData) -> Result<(), FormatError> {
    write_json(path, &gt.to_json())
}

/// The camera of a BCS system file.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SystemCalibration {
    pub vp1: Point2,
    pub vp2: Point2,
    pub pp: Point2,
    /// Metres per road-plane unit of the BCS back-projection.
    pub scale: f64,
}

/// A tracked vehicle of a BCS system file (positions in frame pixels).
#[derive(Debug, Clone, PartialEq)]
pub struct SystemCar {
    pub id: i64,
    pub frames: Vec<f64>,
    pub pos_x: Vec<f64>,
    pub pos_y: Vec<f64>,
}

/// A BCS `system_<name>.json`.
#[derive(Debug, Clone, PartialEq)]
pub struct SystemFile {
    pub calibration: SystemCalibration,
    pub cars: Vec<SystemCar>,
}

impl SystemFile {
    /// A system file with a calibration and no cars.
    pub fn new(calibration: SystemCalibration) -> SystemFile {
        SystemFile {
            calibration,
            cars: vec![],
        }
    }

    /// Parse from JSON.
    ///
    /// # Errors
    /// [`AccessError`] naming the field.
    pub fn from_json(v: &Json) -> Result<SystemFile, AccessError> {
        let c = v.field("", "camera_calibration")?;
        let at = "camera_calibration";
        let calibration = SystemCalibration {
            vp1: c.field(at, "vp1")?.as_point("camera_calibration.vp1")?,
            vp2: c.field(at, "vp2")?.as_point("camera_calibration.vp2")?,
            pp: c.field(at, "pp")?.as_point("camera_calibration.pp")?,
            scale: match c.get("scale") {
                Some(s) => s.as_f64("camera_calibration.scale")?,
                None => 1.0,
            },
        };
        let mut cars = Vec::new();
        if let Some(list) = v.get("cars") {
            for (i, car) in list.as_array("cars")?.iter().enumerate() {
                let at = format!("cars[{i}]");
                cars.push(SystemCar {
                    id: car.field(&at, "id")?.as_f64(&format!("{at}.id"))? as i64,
                    frames: car
                        .field(&at, "frames")?
                        .as_f64_vec(&format!("{at}.frames"))?,
                    pos_x: car.field(&at, "posX")?.as_f64_vec(&format!("{at}.posX"))?,
                    pos_y: car.field(&at, "posY")?.as_f64_vec(&format!("{at}.posY"))?,
                });
            }
        }
        Ok(SystemFile { calibration, cars })
    }

    /// The file as JSON, keys in the order the reference wrote them.
    pub fn to_json(&self) -> Json {
        let c = &self.calibration;
        let cars = self
            .cars
            .iter()
            .map(|car| {
                Json::Object(vec![
                    ("frames".into(), Json::from(&car.frames[..])),
                    ("id".into(), Json::Number(car.id as f64)),
                    ("posX".into(), Json::from(&car.pos_x[..])),
                    ("posY".into(), Json::from(&car.pos_y[..])),
                ])
            })
            .collect();
        Json::Object(vec![
            ("cars".into(), Json::Array(cars)),
            (
                "camera_calibration".into(),
                Json::Object(vec![
                    ("pp".into(), c.pp.into()),
                    ("scale".into(), c.scale.into()),
                    ("vp1".into(), c.vp1.into()),
                    ("vp2".into(), c.vp2.into()),
                ]),
            ),
        ])
    }
}

/// Read a BCS system file.
///
/// # Errors
/// [`FormatError`] naming the file and field.
pub fn read_system(path: &Path) -> Result<SystemFile, FormatError> {
    let doc = read_json(path)?;
    SystemFile::from_json(&doc).map_err(|e| FormatError::field(path, e))
}

/// Write a BCS system file atomically.
///
/// # Errors
/// [`FormatError::Io`] naming the file.
pub fn write_system(path: &Path, system: &SystemFile) -> Result<(), FormatError> {
    write_json(path, &system.to_json())
}

/// The sessions of each official split (the paper reports split C).
pub fn split_sessions(split: char) -> Option<&'static [u32]> {
    match split.to_ascii_uppercase() {
        'A' => Some(&[1, 2, 3, 4, 5, 6]),
        'B' => Some(&[3, 4, 5, 6]),
        'C' => Some(&[4, 5, 6]),
        _ => None,
    }
}

/// A video directory name `session<N>_<view>` split into `(N, view)`.
pub fn parse_video_name(name: &str) -> Option<(u32, &str)> {
    let rest = name.strip_prefix("session")?;
    let (n, view) = rest.split_once('_')?;
    Some((n.parse().ok()?, view))
}

/// The video directories under a BCS `dataset` directory, sorted by session then view
/// (`center`, `left`, `right`, as the official evaluation lists them); any other directory
/// holding a `gt_data.pkl`/`gt_data.json` (e.g. a synthetic scene) is included after them by
/// name.
///
/// # Errors
/// [`FormatError::Io`] when the directory cannot be listed.
pub fn list_videos(dataset: &Path) -> Result<Vec<(String, PathBuf)>, FormatError> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dataset).map_err(|e| FormatError::io(dataset, e))? {
        let entry = entry.map_err(|e| FormatError::io(dataset, e))?;
        let path = entry.path();
        if path.join("gt_data.pkl").is_file() || path.join("gt_data.json").is_file() {
            out.push((entry.file_name().to_string_lossy().into_owned(), path));
        }
    }
    out.sort_by(|a, b| {
        let key = |n: &str| {
            parse_video_name(n).map_or((u32::MAX, n.to_string()), |(s, v)| (s, v.to_string()))
        };
        key(&a.0).cmp(&key(&b.0))
    });
    Ok(out)
}
