//! vpcal's calibration file (`calib.json`): one typed, versioned document that every command
//! writes and reads (`calibrate`, `aggregate`, `demo`, `scale`, `measure`).
//!
//! Field by field reference: `docs/calibration-file.md`. The document is strict JSON: a
//! non-finite number (a vanishing point at infinity) is written as `null`. Readers accept
//! every version in [`SUPPORTED_VERSIONS`]; writers write [`FORMAT`].

use std::path::Path;

use serde::{Deserialize, Serialize};
use vpcal_geom::camera::Calibration;
use vpcal_geom::rotation::{rotation_vector, Mat3};
use vpcal_geom::Point2;

use crate::error::FormatError;
use crate::fs::write_atomic;

/// The format tag vpcal writes.
pub const FORMAT: &str = "vpcal-calibration/3";
/// The versions of the format readers accept (1 lacks the OpenCV block and the camera height;
/// 2 has no `rough`/`unreliable` status and keeps the bootstrap's focal percentiles in
/// `confidence`).
pub const SUPPORTED_VERSIONS: [u32; 3] = [1, 2, 3];

/// The start of the warning an automatic metric scale carries (dropped once a known distance
/// gives the scale).
pub const AUTOMATIC_SCALE_WARNING: &str = "the metric scale is automatic:";
/// What separates the aggregation's summary from the scale's part of it.
pub const SCALE_SUMMARY_SEPARATOR: &str = "; scale ";
/// What separates the aggregation's summary from a focal length refitted to known lengths
/// (`vpcal scale`); the scale's part follows it.
pub const FOCAL_SUMMARY_SEPARATOR: &str = "; focal length from ";
/// The starts of the warnings about the aggregation's focal length, which a focal length
/// measured from known lengths replaces: an assumed one, one outside the given range, the
/// curved-road fit against the straight one.
pub const FOCAL_WARNINGS: [&str; 3] = [
    "the focal length is assumed, not measured",
    "the measured focal length (",
    "the curved-road fit gives a focal length",
];

/// Whether the run produced a camera, and whether it passed the plausibility checks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Status {
    /// The camera fields are present and every plausibility check passed.
    Calibrated,
    /// The camera fields are present, but a result lies outside what is typical of traffic
    /// cameras and traffic (the tracks' speeds, the camera's height): `warnings` says which;
    /// measurements may be off by more than the intervals say.
    Rough,
    /// The camera fields are present, but a result is impossible for a traffic camera or for
    /// road traffic, or rests on evidence too weak to carry it (`warnings` says which): do not
    /// measure with it.
    Unreliable,
    /// The footage did not support a calibration; `reason` says why.
    NotEnoughEvidence,
}

impl Status {
    /// The name in calibration files.
    pub fn name(self) -> &'static str {
        match self {
            Status::Calibrated => "calibrated",
            Status::Rough => "rough",
            Status::Unreliable => "unreliable",
            Status::NotEnoughEvidence => "not_enough_evidence",
        }
    }

    /// Whether the file has a camera.
    pub fn has_camera(self) -> bool {
        self != Status::NotEnoughEvidence
    }

    /// The lower of two statuses (a camera's status after another check).
    pub fn worst(self, other: Status) -> Status {
        let rank = |s: Status| match s {
            Status::Calibrated => 0,
            Status::Rough => 1,
            Status::Unreliable => 2,
            Status::NotEnoughEvidence => 3,
        };
        if rank(other) > rank(self) {
            other
        } else {
            self
        }
    }
}

/// A plausibility check that failed (`vpcal::plausible`): which check, the status it lowers
/// the calibration to, and the warning it added.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlausibilityCheck {
    /// `camera` (height, tilt) or `speeds` (the tracks' speeds).
    pub check: String,
    pub status: Status,
    pub warning: String,
}

/// Boxes the per-frame filter dropped, by reason.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default)]
pub struct Dropped {
    pub low_score: u64,
    pub r#static: u64,
    pub over_limit: u64,
    pub outside_frame: u64,
    pub seen_before: u64,
}

/// What was read: the footage (or a file of per-vehicle records) and what came of it.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct InputSummary {
    /// The input path as given.
    pub path: String,
    /// `video`, `image_folder`, `image` or `vehicle_records` (a VPout file).
    pub kind: Option<String>,
    pub width: u32,
    pub height: u32,
    /// Frames per second (videos, and image folders given `--fps`).
    pub fps: Option<f64>,
    pub codec: Option<String>,
    pub frames_processed: u64,
    pub frames_replayed: u64,
    pub detections: u64,
    pub dropped: Dropped,
    /// Vehicle boxes that reached the network (for a VPout file: its records).
    pub vehicle_boxes: u64,
    /// Boxes of vehicles followed from frame to frame that the network did not see again
    /// (they count for the tracks; `calibrate --crops all` sends every box).
    pub followed_boxes: u64,
    pub seconds: f64,
}

/// The horizon: a homogeneous line `a x + b y + c = 0` with `a² + b² = 1`, and its angle.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Horizon {
    pub line: [f64; 3],
    pub angle_deg: f64,
}

/// How road distances measured with an automatic scale move with the focal length: a
/// distance along the road (what speeds are made of) and one across it (a lane width), with
/// the camera at each end of the focal length's interval (the same VP1, horizon and principal
/// point) scaled by its own vehicles, as ratios to their values with the file's camera.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FocalSensitivity {
    /// The focal lengths compared, pixels: the interval's ends.
    pub focal_px: [f64; 2],
    /// Along-road distance ratio at each end.
    pub along: [f64; 2],
    /// Across-road distance ratio at each end.
    pub across: [f64; 2],
    /// Camera height ratio at each end (`[1, 1]` in files written before it was recorded).
    #[serde(default = "unit_ratios")]
    pub height: [f64; 2],
}

fn unit_ratios() -> [f64; 2] {
    [1.0; 2]
}

impl FocalSensitivity {
    /// In words: `over its 68% interval (A-B px) distances along the road (and speeds) change
    /// by xL-xH, across it by xL-xH`.
    pub fn describe(&self) -> String {
        let (a, b) = (self.along, self.across);
        format!(
            "over its 68% interval ({:.0}-{:.0} px) distances along the road (and speeds) \
             change by x{:.2}-x{:.2}, across it by x{:.2}-x{:.2}",
            self.focal_px[0],
            self.focal_px[1],
            a[0].min(a[1]),
            a[0].max(a[1]),
            b[0].min(b[1]),
            b[0].max(b[1])
        )
    }
}

/// The known distance a metric scale came from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScaleReference {
    /// The two road pixels `[[x1, y1], [x2, y2]]`.
    pub points: [[f64; 2]; 2],
    pub distance_m: f64,
}

/// Bootstrap spread of the robust aggregation's horizon and VP1. (The focal length's one
/// interval is `focal_interval_px`; the bootstrap's own focal percentiles, which version 2
/// kept here, are diagnostics under `evidence`.)
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Confidence {
    pub horizon_angle_sd_deg: f64,
    pub vp1_sd_px: f64,
    pub resamples: usize,
}

/// The camera as OpenCV takes it: `cv2.projectPoints(road_points, rvec, tvec, camera_matrix,
/// dist_coeffs)` maps road-frame points (z = 0 on the road) to pixels.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OpenCvCamera {
    pub camera_matrix: Mat3,
    /// `k1, k2, p1, p2, k3`: all zero, the method assumes no lens distortion.
    pub dist_coeffs: [f64; 5],
    /// Road frame to camera rotation (Rodrigues vector, radians).
    pub rvec: [f64; 3],
    /// The road origin in camera coordinates, in `units`.
    pub tvec: [f64; 3],
    /// `m` once the calibration has a metric scale, else `road_units` (the BCS plane units).
    pub units: String,
    /// `[width, height]`.
    pub image_size: [u32; 2],
}

impl OpenCvCamera {
    /// The camera as an OpenCV FileStorage YAML document (`cv2.FileStorage(path,
    /// cv2.FILE_STORAGE_READ)`): `image_width`, `image_height`, `camera_matrix`,
    /// `distortion_coefficients`, `rvec`, `tvec` (matrices of doubles), `units`, and
    /// `camera_height_m` when known.
    pub fn to_filestorage_yaml(&self, camera_height_m: Option<f64>) -> String {
        fn matrix(name: &str, rows: usize, cols: usize, data: &[f64]) -> String {
            let values: Vec<String> = data.iter().map(|v| format!("{v:?}")).collect();
            format!(
                "{name}: !!opencv-matrix\n   rows: {rows}\n   cols: {cols}\n   dt: d\n   data: [ {} ]\n",
                values.join(", ")
            )
        }
        let k: Vec<f64> = self.camera_matrix.iter().flatten().copied().collect();
        let mut out = String::from("%YAML:1.0\n---\n");
        out.push_str(&format!(
            "image_width: {}\nimage_height: {}\n",
            self.image_size[0], self.image_size[1]
        ));
        out.push_str(&matrix("camera_matrix", 3, 3, &k));
        out.push_str(&matrix("distortion_coefficients", 1, 5, &self.dist_coeffs));
        out.push_str(&matrix("rvec", 3, 1, &self.rvec));
        out.push_str(&matrix("tvec", 3, 1, &self.tvec));
        out.push_str(&format!("units: \"{}\"\n", self.units));
        if let Some(h) = camera_height_m.filter(|h| h.is_finite()) {
            out.push_str(&format!("camera_height_m: {h:?}\n"));
        }
        out
    }
}

/// The demo's comparison with the synthetic scene's true camera.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DemoComparison {
    pub scene: String,
    pub true_focal_px: f64,
    pub focal_error_pct: f64,
    pub true_vp1: [f64; 2],
    pub true_vp2: [f64; 2],
    pub horizon_angle_error_deg: f64,
    pub horizon_y_at_centre: Option<f64>,
    pub true_horizon_y_at_centre: Option<f64>,
    pub bcs_ratio_error_pct: RatioErrors,
    /// The automatic scale (from the vehicles' sizes) against the best scale for the
    /// estimated camera (the one that fits the scene's true road distances), percent; `None`
    /// without an automatic scale.
    #[serde(default)]
    pub scale_error_pct: Option<f64>,
    /// Median error of the scene's true road distances measured with the estimated camera
    /// and its automatic scale, percent.
    #[serde(default)]
    pub distance_error_pct: Option<f64>,
}

/// BrnoCompSpeed ratio errors of road distances, percent.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RatioErrors {
    pub mean: f64,
    pub median: f64,
    pub p95: f64,
    pub max: f64,
    pub pairs: usize,
}

/// A calibration file. With `status: calibrated` the camera fields (`pp` to `roll_deg`) are
/// all present; otherwise they are absent and `reason` says why.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CalibrationFile {
    /// `vpcal-calibration/<version>`.
    pub format: String,
    pub status: Status,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// The vpcal that wrote the file.
    #[serde(default)]
    pub vpcal_version: String,
    #[serde(default)]
    pub input: InputSummary,
    /// `[width, height]` in pixels.
    pub image_size: [u32; 2],
    /// Principal point, pixels (the image centre `(W/2, H/2)` unless given).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pp: Option<[f64; 2]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub focal_px: Option<f64>,
    /// Where the focal length came from: `edgelets`, `network` (the VP2 rays, trusted),
    /// `network_rays` (the VP2 rays within the physical prior), `prior` (assumed: no evidence
    /// fixed it), `per_vehicle_median` (the reference method) or `given` (`--focal`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub focal_source: Option<String>,
    /// 68 % interval of the focal length, pixels: the bootstrap's spread and the model error
    /// (`vpcal::aggregate::MEASURED_FOCAL_MODEL_LOG_SD`) for measured focal lengths,
    /// the plausible range of traffic cameras (15-90° views) for assumed ones.
    #[serde(default)]
    pub focal_interval_px: Option<[f64; 2]>,
    /// Intrinsic matrix `[[f, 0, px], [0, f, py], [0, 0, 1]]`.
    #[serde(rename = "K", default, skip_serializing_if = "Option::is_none")]
    pub k: Option<Mat3>,
    /// Road to camera rotation of the BCS convention: columns are vp1's direction, vp2's
    /// (signed for a right-handed frame) and the road normal towards vp3 (into the road for a
    /// camera above it). For a z-up road frame see `opencv`.
    #[serde(rename = "R", default, skip_serializing_if = "Option::is_none")]
    pub r: Option<Mat3>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vp1: Option<[f64; 2]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vp2: Option<[f64; 2]>,
    /// The vertical vanishing point; `null` when it is at infinity.
    #[serde(default)]
    pub vp3: Option<[f64; 2]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub horizon: Option<Horizon>,
    /// Unit road normal in camera coordinates (x right, y down, z forward), towards vp3.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub road_normal: Option<[f64; 3]>,
    /// Angle of the optical axis below the road plane, degrees.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tilt_deg: Option<f64>,
    /// Angle of the horizon against the image x axis, degrees.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub roll_deg: Option<f64>,
    /// Metres per BCS road-plane unit; `null` until a scale is known.
    #[serde(default)]
    pub scale_m_per_unit: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale_reference: Option<ScaleReference>,
    /// Where the scale came from: `distance` (a known road distance, `scale_reference`) or
    /// `vehicles` (the sizes of the vehicles seen, as typical cars); `null` without a scale
    /// or when a file does not say.
    #[serde(default)]
    pub scale_source: Option<String>,
    /// 68 % interval of `scale_m_per_unit` (for an automatic scale: the sampling spread and
    /// the spread of typical car sizes between fleets).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale_interval_m_per_unit: Option<[f64; 2]>,
    /// With an automatic scale: how the distances it gives move when the focal length moves
    /// over `focal_interval_px` (each end's camera scaled by its own vehicles).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale_focal_sensitivity: Option<FocalSensitivity>,
    /// Height of the camera above the road, metres (with a scale).
    #[serde(default)]
    pub camera_height_m: Option<f64>,
    /// 68 % interval of `camera_height_m` with an automatic scale: the scale's own interval
    /// and the height's change over the focal length's interval (`scale_focal_sensitivity`)
    /// together ([`height_interval`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera_height_interval_m: Option<[f64; 2]>,
    /// Pixels to road points in metres, `[x, y, 1] ~ H [u, v, 1]` (with a scale): the road
    /// frame of `opencv` (origin under the camera, x along the road towards vp1, y across,
    /// z up), scaled so that `w = 1` at the principal point.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub road_homography: Option<Mat3>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub opencv: Option<OpenCvCamera>,
    /// What the aggregation used (counts and flags of the method; diagnostic, its members
    /// depend on the method).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub evidence: Option<serde_json::Value>,
    #[serde(default)]
    pub confidence: Option<Confidence>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub summary: Option<String>,
    /// What a user should know about this calibration (an assumed focal length, ...).
    #[serde(default)]
    pub warnings: Vec<String>,
    /// The plausibility checks that failed, each also in `warnings`; `status` is the lowest of
    /// theirs (`calibrated` when none failed).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub failed_checks: Vec<PlausibilityCheck>,
    /// The settings of the run, by flag name.
    #[serde(default)]
    pub settings: serde_json::Map<String, serde_json::Value>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub demo: Option<DemoComparison>,
}

/// The 68 % interval of `file`'s camera height where its scale is automatic: on each side,
/// the scale interval's log distance from the scale and the height's log change over the
/// focal length's interval towards that side (`scale_focal_sensitivity.height`), in
/// quadrature (the two are independent: the cars' sizes and the lens). `None` without an
/// automatic scale's interval (a known distance, or no scale).
pub fn height_interval(file: &CalibrationFile) -> Option<[f64; 2]> {
    let h = file.camera_height_m.filter(|h| h.is_finite() && *h > 0.0)?;
    let s = file.scale_m_per_unit.filter(|s| *s > 0.0)?;
    let [lo, hi] = file
        .scale_interval_m_per_unit
        .filter(|[lo, hi]| *lo > 0.0 && hi.is_finite())?;
    let (scale_down, scale_up) = ((s / lo).ln().max(0.0), (hi / s).ln().max(0.0));
    let [a, b] = file.scale_focal_sensitivity.map_or([1.0; 2], |f| f.height);
    let (focal_down, focal_up) = if a > 0.0 && b > 0.0 && a.is_finite() && b.is_finite() {
        ((-a.min(b).ln()).max(0.0), a.max(b).ln().max(0.0))
    } else {
        (0.0, 0.0)
    };
    Some([
        h * (-scale_down.hypot(focal_down)).exp(),
        h * scale_up.hypot(focal_up).exp(),
    ])
}

fn point(p: Point2) -> Option<[f64; 2]> {
    p.is_finite().then_some([p.x, p.y])
}

impl CalibrationFile {
    /// A file without a camera: the run could not support one, for `reason`.
    pub fn not_calibrated(input: InputSummary, reason: String) -> CalibrationFile {
        CalibrationFile {
            format: FORMAT.to_string(),
            status: Status::NotEnoughEvidence,
            reason: Some(reason),
            vpcal_version: env!("CARGO_PKG_VERSION").to_string(),
            image_size: [input.width, input.height],
            input,
            pp: None,
            focal_px: None,
            focal_source: None,
            focal_interval_px: None,
            k: None,
            r: None,
            vp1: None,
            vp2: None,
            vp3: None,
            horizon: None,
            road_normal: None,
            tilt_deg: None,
            roll_deg: None,
            scale_m_per_unit: None,
            scale_reference: None,
            camera_height_m: None,
            camera_height_interval_m: None,
            road_homography: None,
            scale_source: None,
            scale_interval_m_per_unit: None,
            scale_focal_sensitivity: None,
            opencv: None,
            evidence: None,
            confidence: None,
            summary: None,
            warnings: Vec::new(),
            failed_checks: Vec::new(),
            settings: serde_json::Map::new(),
            demo: None,
        }
    }

    /// A file of camera `cal` (no metric scale yet).
    pub fn calibrated(input: InputSummary, cal: &Calibration) -> CalibrationFile {
        let mut file = CalibrationFile::not_calibrated(input, String::new());
        file.status = Status::Calibrated;
        file.reason = None;
        file.set_camera(cal);
        file
    }

    fn set_camera(&mut self, cal: &Calibration) {
        self.pp = point(cal.pp);
        self.focal_px = Some(cal.focal_px);
        self.k = Some(cal.k());
        self.r = Some(cal.rotation);
        self.vp1 = point(cal.vp1);
        self.vp2 = point(cal.vp2);
        self.vp3 = point(cal.vp3);
        self.horizon = Some(Horizon {
            line: cal.horizon.0,
            angle_deg: cal.horizon.angle().to_degrees(),
        });
        self.road_normal = Some(cal.road_normal);
        self.tilt_deg = Some(cal.tilt().to_degrees());
        self.roll_deg = Some(cal.roll().to_degrees());
        self.update_export(cal);
    }

    /// The OpenCV block and the camera height, for the current scale.
    fn update_export(&mut self, cal: &Calibration) {
        let frame = cal.road_frame();
        let s = self.scale_m_per_unit.unwrap_or(1.0);
        let t = frame.translation;
        self.opencv = Some(OpenCvCamera {
            camera_matrix: cal.k(),
            dist_coeffs: [0.0; 5],
            rvec: rotation_vector(&frame.rotation),
            tvec: [t[0] * s, t[1] * s, t[2] * s],
            units: if self.scale_m_per_unit.is_some() {
                "m"
            } else {
                "road_units"
            }
            .to_string(),
            image_size: self.image_size,
        });
        self.camera_height_m = self.scale_m_per_unit.map(|s| s * cal.plane_distance());
        self.camera_height_interval_m = height_interval(self);
        self.road_homography = self.scale_m_per_unit.and_then(|s| cal.road_homography(s));
    }

    /// Give the calibration a metric scale (metres per road unit) and the distance it came
    /// from; the OpenCV block and the camera height follow.
    ///
    /// # Errors
    /// When the file has no camera.
    pub fn set_scale(
        &mut self,
        scale_m_per_unit: f64,
        reference: Option<ScaleReference>,
    ) -> Result<(), String> {
        let cal = self.camera()?;
        // An earlier scale's warning and summary no longer describe the file.
        self.warnings
            .retain(|w| !w.starts_with(AUTOMATIC_SCALE_WARNING));
        if let Some(summary) = &mut self.summary {
            if let Some(at) = summary.find(SCALE_SUMMARY_SEPARATOR) {
                summary.truncate(at);
            }
        }
        self.scale_m_per_unit = Some(scale_m_per_unit);
        self.scale_source = reference.as_ref().map(|_| "distance".to_string());
        self.scale_reference = reference;
        self.scale_interval_m_per_unit = None;
        self.scale_focal_sensitivity = None;
        self.update_export(&cal);
        Ok(())
    }

    /// Replace the camera by `cal`, whose focal length `source` measured (`distances`: known
    /// road lengths in two directions) with 68 % interval `interval_px`; `clause` describes
    /// it in the summary. The warnings about the old focal length go, and so does the metric
    /// scale: the road unit changed with the camera, so a new scale must follow
    /// ([`CalibrationFile::set_scale`]).
    ///
    /// # Errors
    /// When the file has no camera.
    pub fn set_measured_camera(
        &mut self,
        cal: &Calibration,
        source: &str,
        interval_px: [f64; 2],
        clause: &str,
    ) -> Result<(), String> {
        self.camera()?;
        self.scale_m_per_unit = None;
        self.scale_reference = None;
        self.scale_source = None;
        self.scale_interval_m_per_unit = None;
        self.scale_focal_sensitivity = None;
        self.warnings.retain(|w| {
            !w.starts_with(AUTOMATIC_SCALE_WARNING)
                && !FOCAL_WARNINGS.iter().any(|p| w.starts_with(p))
        });
        if let Some(summary) = &mut self.summary {
            for sep in [FOCAL_SUMMARY_SEPARATOR, SCALE_SUMMARY_SEPARATOR] {
                if let Some(at) = summary.find(sep) {
                    summary.truncate(at);
                }
            }
            summary.push_str(FOCAL_SUMMARY_SEPARATOR);
            summary.push_str(clause);
        }
        self.set_camera(cal);
        self.focal_source = Some(source.to_string());
        self.focal_interval_px = Some(interval_px);
        Ok(())
    }

    /// Give the calibration an automatic metric scale (metres per road unit) from the sizes
    /// of the vehicles seen, with its 68 % interval.
    ///
    /// # Errors
    /// When the file has no camera.
    pub fn set_vehicle_scale(
        &mut self,
        scale_m_per_unit: f64,
        interval: [f64; 2],
    ) -> Result<(), String> {
        self.set_scale(scale_m_per_unit, None)?;
        self.scale_source = Some("vehicles".to_string());
        self.scale_interval_m_per_unit = Some(interval);
        self.camera_height_interval_m = height_interval(self);
        Ok(())
    }

    /// The camera height in words, `8.3 m`, with its interval where known:
    /// `8.3 m (68% 7.7-9.1 m)`; `None` without a (finite) height.
    pub fn height_text(&self) -> Option<String> {
        let h = self.camera_height_m.filter(|h| h.is_finite())?;
        Some(match self.camera_height_interval_m {
            Some([lo, hi]) => format!("{h:.1} m (68% {lo:.1}-{hi:.1} m)"),
            None => format!("{h:.1} m"),
        })
    }

    /// Record how the automatic scale's distances and camera height move over the focal
    /// length's interval (`None`: a focal length without one); the height's interval follows.
    pub fn set_focal_sensitivity(&mut self, sensitivity: Option<FocalSensitivity>) {
        self.scale_focal_sensitivity = sensitivity;
        self.camera_height_interval_m = height_interval(self);
    }

    /// Replace the failed plausibility checks named `check` by `failed` (their warnings too),
    /// and set the status of a file with a camera to the lowest of the failed checks'.
    pub fn replace_checks(&mut self, check: &str, failed: Vec<PlausibilityCheck>) {
        let (gone, kept): (Vec<PlausibilityCheck>, Vec<PlausibilityCheck>) =
            self.failed_checks.drain(..).partition(|c| c.check == check);
        self.warnings
            .retain(|w| !gone.iter().any(|c| &c.warning == w));
        self.failed_checks = kept;
        for c in failed {
            if !self.warnings.contains(&c.warning) {
                self.warnings.push(c.warning.clone());
            }
            self.failed_checks.push(c);
        }
        if self.status.has_camera() {
            self.status = self
                .failed_checks
                .iter()
                .fold(Status::Calibrated, |s, c| s.worst(c.status));
        }
    }

    /// Recompute the OpenCV block and the camera height from the camera and the scale (for
    /// version 1 files, which have neither).
    ///
    /// # Errors
    /// When the file has no camera.
    pub fn refresh_export(&mut self) -> Result<(), String> {
        let cal = self.camera()?;
        self.update_export(&cal);
        Ok(())
    }

    /// The format version, if the tag is `vpcal-calibration/<N>`.
    pub fn version(&self) -> Option<u32> {
        self.format
            .strip_prefix("vpcal-calibration/")
            .and_then(|v| v.parse().ok())
    }

    /// The camera of a calibrated file, from its vp1, vp2 and pp.
    ///
    /// # Errors
    /// A message naming the field when the file has no camera or a field is missing.
    pub fn camera(&self) -> Result<Calibration, String> {
        if !self.status.has_camera() {
            return Err(format!(
                "status is \"not_enough_evidence\", not \"calibrated\": this run produced no \
                 camera ({})",
                self.reason.as_deref().unwrap_or("no reason given")
            ));
        }
        let field = |name: &str, v: Option<[f64; 2]>| {
            v.map(Point2::from)
                .filter(|p| p.is_finite())
                .ok_or_else(|| format!("field {name:?} must be [x, y] (finite numbers)"))
        };
        let vp1 = field("vp1", self.vp1)?;
        let vp2 = field("vp2", self.vp2)?;
        let pp = field("pp", self.pp)?;
        Calibration::from_vps(vp1, vp2, pp)
            .map_err(|e| format!("vp1, vp2 and pp give no camera: {e}"))
    }

    /// Check that the fields derived from the camera (`focal_px`, `K`, the OpenCV block's
    /// matrix and units) agree with the camera of `vp1`, `vp2` and `pp`, which every command
    /// measures with: a file edited in one place and not the others is refused rather than
    /// measured with half of its edit.
    ///
    /// # Errors
    /// A message naming the field that disagrees, its value and the camera's.
    pub fn check_consistency(&self) -> Result<(), String> {
        let cal = self.camera()?;
        let f = cal.focal_px;
        let agree = |a: f64, b: f64| (a - b).abs() <= 1e-6 * b.abs().max(1.0);
        let remedy = "edit vp1/vp2 (the camera every command measures with) or calibrate \
                      again, with --focal PX for a known focal length";
        match self.focal_px {
            Some(v) if v.is_finite() && v > 0.0 && agree(v, f) => {}
            Some(v) if v.is_finite() && v > 0.0 => {
                return Err(format!(
                    "field \"focal_px\" is {v}, but vp1, vp2 and pp give {f:.3} px: {remedy}"
                ))
            }
            Some(v) => {
                return Err(format!(
                    "field \"focal_px\" is {v}: expected a positive number of pixels ({f:.3} \
                     from vp1, vp2 and pp)"
                ))
            }
            None if self.version().is_some_and(|v| v >= 2) => {
                return Err(format!(
                    "field \"focal_px\" is missing or null (vp1, vp2 and pp give {f:.3} px)"
                ))
            }
            None => {}
        }
        let k_agrees = |k: &Mat3| {
            agree(k[0][0], f)
                && agree(k[1][1], f)
                && agree(k[0][2], cal.pp.x)
                && agree(k[1][2], cal.pp.y)
        };
        if let Some(k) = &self.k {
            if !k_agrees(k) {
                return Err(format!(
                    "field \"K\" is {k:?}, but vp1, vp2 and pp give f = {f:.3} px at pp \
                     ({:.2}, {:.2}): {remedy}",
                    cal.pp.x, cal.pp.y
                ));
            }
        }
        if let Some(cv) = &self.opencv {
            if !k_agrees(&cv.camera_matrix) {
                return Err(format!(
                    "field \"opencv.camera_matrix\" is {:?}, but vp1, vp2 and pp give f = \
                     {f:.3} px at pp ({:.2}, {:.2}): {remedy}",
                    cv.camera_matrix, cal.pp.x, cal.pp.y
                ));
            }
            let metric = self.scale_m_per_unit.is_some();
            if (cv.units == "m") != metric {
                return Err(format!(
                    "field \"opencv.units\" is {:?} but \"scale_m_per_unit\" is {}: run \
                     `vpcal export` to rewrite the OpenCV block from the file's scale",
                    cv.units,
                    self.scale_m_per_unit
                        .map_or("null".to_string(), |s| s.to_string())
                ));
            }
        }
        Ok(())
    }

    /// The metric scale, checked.
    ///
    /// # Errors
    /// When `scale_m_per_unit` is not a positive number.
    pub fn scale(&self) -> Result<Option<f64>, String> {
        match self.scale_m_per_unit {
            None => Ok(None),
            Some(s) if s.is_finite() && s > 0.0 => Ok(Some(s)),
            Some(s) => Err(format!(
                "scale_m_per_unit must be a positive number, found {s}"
            )),
        }
    }

    /// Strict, pretty-printed JSON (with a final newline).
    pub fn to_json_string(&self) -> String {
        // serde_json writes non-finite floats as null: strict JSON.
        let mut text = serde_json::to_string_pretty(self).unwrap_or_default();
        text.push('\n');
        text
    }

    /// Parse a calibration file's text; `path` names it in errors.
    ///
    /// # Errors
    /// [`FormatError`] for invalid JSON, a missing or mistyped field, an unknown format.
    pub fn from_json_str(text: &str, path: &Path) -> Result<CalibrationFile, FormatError> {
        let value: serde_json::Value = serde_json::from_str(text)
            .map_err(|e| FormatError::invalid(path, format!("not a JSON document: {e}")))?;
        let format = value.get("format").and_then(serde_json::Value::as_str);
        match format {
            Some(f) if f.starts_with("vpcal-calibration/") => {}
            Some(f) => {
                return Err(FormatError::invalid(
                    path,
                    format!(
                        "field \"format\" is {f:?}: not a vpcal calibration (expected \
                         \"vpcal-calibration/N\"; a BrnoCompSpeed system file is read by \
                         `vpcal eval`)"
                    ),
                ))
            }
            None => {
                return Err(FormatError::invalid(
                    path,
                    "no \"format\" field: not a vpcal calibration file",
                ))
            }
        }
        let file: CalibrationFile = serde_json::from_value(value)
            .map_err(|e| FormatError::invalid(path, format!("not a valid calibration: {e}")))?;
        match file.version() {
            Some(v) if SUPPORTED_VERSIONS.contains(&v) => Ok(file),
            _ => Err(FormatError::invalid(
                path,
                format!(
                    "format {:?} is not one this vpcal reads (versions {SUPPORTED_VERSIONS:?})",
                    file.format
                ),
            )),
        }
    }

    /// Read a calibration file.
    ///
    /// # Errors
    /// [`FormatError`] naming the file.
    pub fn read(path: &Path) -> Result<CalibrationFile, FormatError> {
        let text = std::fs::read_to_string(path).map_err(|e| FormatError::io(path, e))?;
        CalibrationFile::from_json_str(&text, path)
    }

    /// Write the file atomically as strict JSON in the current format.
    ///
    /// # Errors
    /// [`FormatError::Io`] naming the file.
    pub fn write(&self, path: &Path) -> Result<(), FormatError> {
        let mut out = self.clone();
        out.format = FORMAT.to_string();
        write_atomic(path, out.to_json_string().as_bytes())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera() -> Calibration {
        Calibration::from_vps(
            Point2::new(700.0, -300.0),
            Point2::new(-20000.0, -250.0),
            Point2::new(640.0, 360.0),
        )
        .unwrap()
    }

    fn input() -> InputSummary {
        InputSummary {
            path: "clip.mp4".into(),
            kind: Some("video".into()),
            width: 1280,
            height: 720,
            fps: Some(25.0),
            ..InputSummary::default()
        }
    }

    #[test]
    fn a_calibrated_file_round_trips_as_strict_json() {
        let cal = camera();
        let mut file = CalibrationFile::calibrated(input(), &cal);
        file.vp3 = None; // as for a VP at infinity
        let text = file.to_json_string();
        assert!(!text.contains("Infinity") && !text.contains("NaN"));
        let back = CalibrationFile::from_json_str(&text, Path::new("c.json")).unwrap();
        assert_eq!(back, file);
        let again = back.camera().unwrap();
        assert!((again.focal_px - cal.focal_px).abs() < 1e-9);
        assert_eq!(back.opencv.as_ref().unwrap().units, "road_units");
        assert_eq!(back.camera_height_m, None);
    }

    #[test]
    fn a_scale_gives_metres_and_the_height() {
        let cal = camera();
        let mut file = CalibrationFile::calibrated(input(), &cal);
        file.set_scale(0.5, None).unwrap();
        let cv = file.opencv.as_ref().unwrap();
        assert_eq!(cv.units, "m");
        let h = file.camera_height_m.unwrap();
        assert!((h - 0.5 * cal.plane_distance()).abs() < 1e-12);
        let t = cv.tvec;
        assert!(((t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt() - h).abs() < 1e-9);
        let mut nothing = CalibrationFile::not_calibrated(input(), "too few vehicles".into());
        assert!(nothing
            .set_scale(0.5, None)
            .unwrap_err()
            .contains("too few vehicles"));
    }

    #[test]
    fn an_automatic_scale_gives_the_height_an_interval_and_a_known_distance_drops_it() {
        let cal = camera();
        let mut file = CalibrationFile::calibrated(input(), &cal);
        // The cars' sizes alone: the height's interval is the scale's, ends for ends.
        file.set_vehicle_scale(0.5, [0.4, 0.6]).unwrap();
        let h = file.camera_height_m.unwrap();
        let [lo, hi] = file.camera_height_interval_m.unwrap();
        assert!((lo - 0.8 * h).abs() < 1e-9 && (hi - 1.2 * h).abs() < 1e-9);
        // A lens that puts the camera 1.5 times as high at one end of the focal interval and
        // 0.9 times at the other widens each side by its own move, in quadrature.
        file.set_focal_sensitivity(Some(FocalSensitivity {
            focal_px: [500.0, 2000.0],
            along: [1.0; 2],
            across: [1.0; 2],
            height: [1.5, 0.9],
        }));
        let [lo2, hi2] = file.camera_height_interval_m.unwrap();
        assert_eq!(
            file.height_text(),
            Some(format!("{h:.1} m (68% {lo2:.1}-{hi2:.1} m)"))
        );
        let down = 1.25f64.ln().hypot(0.9f64.ln());
        let up = 1.2f64.ln().hypot(1.5f64.ln());
        assert!((lo2 - h * (-down).exp()).abs() < 1e-9, "{lo2}");
        assert!((hi2 - h * up.exp()).abs() < 1e-9, "{hi2}");
        assert!(lo2 < lo && hi2 > hi);
        let text = file.to_json_string();
        let back = CalibrationFile::from_json_str(&text, Path::new("c.json")).unwrap();
        assert_eq!(back.camera_height_interval_m, file.camera_height_interval_m);
        // A taped distance fixes the scale: no automatic interval is left to report.
        file.set_scale(0.5, None).unwrap();
        assert_eq!(file.camera_height_interval_m, None);
        assert!(!file.to_json_string().contains("camera_height_interval_m"));
    }

    #[test]
    fn version_1_files_still_read_and_others_are_refused() {
        let v1 = r#"{"format": "vpcal-calibration/1", "status": "calibrated",
            "vpcal_version": "0.1.0", "image_size": [1280, 720], "pp": [640, 360],
            "focal_px": 1000, "vp1": [700, -300], "vp2": [-20000, -250], "vp3": [1, 2],
            "scale_m_per_unit": null, "confidence": null, "settings": {}}"#;
        let f = CalibrationFile::from_json_str(v1, Path::new("old.json")).unwrap();
        assert_eq!(f.version(), Some(1));
        assert!(f.camera().is_ok());
        let e = CalibrationFile::from_json_str(
            &v1.replace("calibration/1", "calibration/9"),
            Path::new("new.json"),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("new.json") && e.contains("versions [1, 2, 3]"),
            "{e}"
        );
        let e = CalibrationFile::from_json_str(r#"{"vp1": [1, 2]}"#, Path::new("s.json"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("no \"format\" field"), "{e}");
        let e = CalibrationFile::from_json_str(
            &v1.replace("\"vp1\": [700, -300]", "\"vp1\": \"x\""),
            Path::new("bad.json"),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("bad.json") && e.contains("invalid type"), "{e}");
        let missing = CalibrationFile::from_json_str(
            &v1.replace("\"vp1\": [700, -300],", ""),
            Path::new("m.json"),
        )
        .unwrap();
        assert!(missing.camera().unwrap_err().contains("\"vp1\""));
    }
}
