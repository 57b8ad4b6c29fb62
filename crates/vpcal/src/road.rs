//! Metric measurements on the road plane of a calibration: the scale from one known
//! distance, image points to road points in metres and back, distances between pixels.
//!
//! Used by `vpcal scale`, `vpcal measure`, `calibrate --scale-points` and the Python package.

use std::path::Path;

use anyhow::{bail, Result};
use vpcal_formats::calib::{CalibrationFile, ScaleReference};
use vpcal_geom::camera::Calibration;
use vpcal_geom::Point2;

/// A calibration file, the camera it describes and its metric scale (metres per road unit).
#[derive(Debug, Clone)]
pub struct RoadCamera {
    pub file: CalibrationFile,
    pub cal: Calibration,
    pub scale: Option<f64>,
}

impl RoadCamera {
    /// The camera of `file`; `origin` names the file in errors.
    ///
    /// # Errors
    /// A file without a camera (not calibrated) or with an invalid one or scale.
    pub fn new(file: CalibrationFile, origin: &str) -> Result<RoadCamera> {
        let cal = file
            .camera()
            .map_err(|e| anyhow::anyhow!("{origin}: {e}"))?;
        let scale = file.scale().map_err(|e| anyhow::anyhow!("{origin}: {e}"))?;
        Ok(RoadCamera { file, cal, scale })
    }

    /// Read the calibration file at `path`.
    ///
    /// # Errors
    /// An unreadable or malformed file (the message names the field), or one without a camera.
    pub fn read(path: &Path) -> Result<RoadCamera> {
        let file = CalibrationFile::read(path)?;
        RoadCamera::new(file, &path.display().to_string())
    }

    /// Metres per road unit, or 1 without a scale (distances then in road units).
    pub fn scale_or_one(&self) -> f64 {
        self.scale.unwrap_or(1.0)
    }

    /// The road distance between the road points two pixels see, metres with a scale (road
    /// units without); `None` when either pixel does not see the road (above the horizon).
    pub fn distance(&self, p1: Point2, p2: Point2) -> Option<f64> {
        if !(self.cal.sees_road(p1) && self.cal.sees_road(p2)) {
            return None;
        }
        self.cal
            .road_distance(p1, p2)
            .map(|d| d * self.scale_or_one())
    }

    /// Road-frame point `(x, y)` (x along the traffic towards VP1, y across, origin under the
    /// camera; metres with a scale) that pixel `p` sees; `None` above the horizon.
    pub fn road_point(&self, p: Point2) -> Option<[f64; 2]> {
        let s = self.scale_or_one();
        self.cal.road_point(p).map(|q| [q[0] * s, q[1] * s])
    }

    /// The pixel that sees road-frame point `q` (the inverse of [`RoadCamera::road_point`]);
    /// `None` behind the camera.
    pub fn pixel(&self, q: [f64; 2]) -> Option<Point2> {
        let s = self.scale_or_one();
        self.cal.pixel_of_road_point([q[0] / s, q[1] / s])
    }
}

/// The metric scale that makes the road distance between pixels `p1` and `p2` equal
/// `distance_m`, with its reference for the calibration file. `flag` names the option the
/// pixels came from in errors.
///
/// # Errors
/// A distance that is not a positive number, a pixel above the horizon, coinciding points.
pub fn scale_from_points(
    cal: &Calibration,
    p1: Point2,
    p2: Point2,
    distance_m: f64,
    flag: &str,
) -> Result<(f64, ScaleReference)> {
    if !(distance_m.is_finite() && distance_m > 0.0) {
        bail!("{flag}: the distance {distance_m} must be a positive number of metres");
    }
    for q in [p1, p2] {
        if !cal.sees_road(q) {
            bail!(
                "{flag}: pixel ({}, {}) is above the horizon of the calibration: it does not \
                 see the road",
                q.x,
                q.y
            );
        }
    }
    let scale = cal.scale_from_distance(p1, p2, distance_m).ok_or_else(|| {
        anyhow::anyhow!(
            "{flag}: the two pixels coincide on the road (or a ray misses the road plane)"
        )
    })?;
    Ok((
        scale,
        ScaleReference {
            points: [[p1.x, p1.y], [p2.x, p2.y]],
            distance_m,
        },
    ))
}

/// Two pixels on the road and the distance between them (a taped distance, lane markings).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KnownDistance {
    pub p1: Point2,
    pub p2: Point2,
    pub distance_m: f64,
}
