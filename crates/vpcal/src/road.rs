//! Metric measurements on the road plane of a calibration: the scale from one known
//! distance, image points to road points in metres and back, distances between pixels.
//!
//! Used by `vpcal scale`, `vpcal measure`, `calibrate --scale-points` and the Python package;
//! known lengths in two directions also measure the focal length ([`crate::road_focal`]).

use std::path::Path;

use anyhow::{bail, Result};
use vpcal_formats::calib::{CalibrationFile, ScaleReference};
use vpcal_geom::camera::Calibration;
use vpcal_geom::Point2;

use crate::road_focal::LengthFocalFit;

/// A calibration file, the camera it describes and its metric scale (metres per road unit).
#[derive(Debug, Clone)]
pub struct RoadCamera {
    pub file: CalibrationFile,
    pub cal: Calibration,
    pub scale: Option<f64>,
    /// What the known lengths are called where they carry the focal length or the scale
    /// (`focal_source`, `scale_source`): `distances` (the user's), or `markings` (a marking
    /// standard's, [`crate::markings`]).
    pub lengths_source: &'static str,
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
        file.check_consistency()
            .map_err(|e| anyhow::anyhow!("{origin}: {e}"))?;
        Ok(RoadCamera {
            file,
            cal,
            scale,
            lengths_source: "distances",
        })
    }

    /// Read the calibration file at `path`.
    ///
    /// # Errors
    /// An unreadable or malformed file (the message names the field), or one without a camera.
    pub fn read(path: &Path) -> Result<RoadCamera> {
        let file = CalibrationFile::read(path)?;
        RoadCamera::new(file, &path.display().to_string())
    }

    /// The focal lengths the file's run assumed possible, pixels: its `--focal-range`
    /// (`settings.focal_range`), else the 15-90° band of frames `width` pixels wide.
    pub fn focal_range_px(&self, width: f64) -> [f64; 2] {
        crate::report::setting_pair(&self.file, "focal_range").unwrap_or_else(|| {
            vpcal_geom::aggregate::focal::focal_prior_range_widths(None).map(|r| r * width)
        })
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

    /// Whether pixel `p` can be measured: inside the frame (`image_size`) and below the
    /// horizon. `Ok` holds how many pixels below the horizon it is; `what` names it in the
    /// error.
    ///
    /// # Errors
    /// A pixel outside the frame, on or above the horizon.
    pub fn check_measurable(&self, p: Point2, what: &str) -> Result<f64> {
        let [w, h] = self.file.image_size;
        let (w, h) = (f64::from(w), f64::from(h));
        if w > 0.0 && h > 0.0 && !(p.x >= 0.0 && p.x <= w && p.y >= 0.0 && p.y <= h) {
            bail!(
                "{what} ({:.1}, {:.1}) is outside the {w:.0}x{h:.0} frame the calibration was made \
                 for: give pixels of that frame",
                p.x,
                p.y
            );
        }
        // On the road's side of the horizon (`sees_road`), its distance from the horizon.
        let below = self
            .cal
            .horizon
            .signed_distance(p)
            .map_or(f64::NAN, f64::abs);
        if !self.cal.sees_road(p) || below.is_nan() || below <= 0.0 {
            bail!(
                "{what} ({:.1}, {:.1}) is on or above the horizon: it does not see the road, so \
                 it has no place on it (give pixels on the road surface)",
                p.x,
                p.y
            );
        }
        Ok(below)
    }

    /// Known lengths `inputs` into the file, as `vpcal scale` does: each checked on the
    /// file's camera before anything changes, then (unless `keep_focal`) the focal length
    /// they measure ([`RoadCamera::refit_focal`]), then the scale on the resulting camera
    /// ([`RoadCamera::fit_and_set_scale`]). Returns what became of the focal length (`None`
    /// with `keep_focal`) and the scale's fit.
    ///
    /// # Errors
    /// As [`fit_scale`]; a scale the file refuses.
    pub fn apply_lengths(
        &mut self,
        inputs: &[ScaleInput],
        flag_of: impl Fn(usize) -> String,
        origin: &str,
        keep_focal: bool,
    ) -> Result<(Option<FocalRefit>, ScaleFit)> {
        fit_scale(&self.cal, inputs, &flag_of)?;
        let focal = (!keep_focal).then(|| self.refit_focal(inputs));
        let fit = self.fit_and_set_scale(inputs, &flag_of, origin)?;
        Ok((focal, fit))
    }

    /// Fit the metric scale of `inputs` (as `vpcal scale`: [`fit_scale`]) and put it into the
    /// file: the scale, the first known distance as its reference, and its source. `flag_of`
    /// names measurement `i` in errors; `origin` the file.
    ///
    /// # Errors
    /// As [`fit_scale`]; a scale the file refuses.
    pub fn fit_and_set_scale(
        &mut self,
        inputs: &[ScaleInput],
        flag_of: impl Fn(usize) -> String,
        origin: &str,
    ) -> Result<ScaleFit> {
        let fit = fit_scale(&self.cal, inputs, flag_of)?;
        let reference = inputs
            .iter()
            .find(|m| m.kind == RoadMeasure::Distance)
            .map(|m| ScaleReference {
                points: [[m.known.p1.x, m.known.p1.y], [m.known.p2.x, m.known.p2.y]],
                distance_m: m.known.distance_m,
            });
        self.file
            .set_scale(fit.scale, reference)
            .map_err(|e| anyhow::anyhow!("{origin}: {e}"))?;
        let source = if self.lengths_source == "distances" {
            fit.source.to_string()
        } else {
            self.lengths_source.to_string()
        };
        self.file.scale_source = Some(source.clone());
        if let Some(summary) = &mut self.file.summary {
            summary.push_str(&format!(
                "{}{:.4} m per unit from {} known {} ({})",
                vpcal_formats::calib::SCALE_SUMMARY_SEPARATOR,
                fit.scale,
                inputs.len(),
                if inputs.len() == 1 {
                    "length"
                } else {
                    "lengths"
                },
                source
            ));
        }
        self.scale = Some(fit.scale);
        // The camera's height follows the scale: check it again. (A failed check of the
        // speeds `calibrate` measured with the old scale stays: `vpcal speeds` measures the
        // tracks again with the new one and says whether they pass.)
        let camera = crate::plausible::check_camera(&self.file);
        self.file
            .replace_checks(crate::plausible::CAMERA_CHECK, camera);
        Ok(fit)
    }

    /// Measure the focal length from known lengths `inputs` in two directions
    /// ([`crate::road_focal`]), combine it with the file's own ([`crate::road_focal::combine`])
    /// and make the result the file's camera (`focal_source: distances`, or
    /// `distances+<source>` where both carried it), with `evidence.distances_focal`. A given
    /// focal length (`--focal`) stays, and so does an assumed one the lengths cannot narrow.
    /// Call [`RoadCamera::fit_and_set_scale`] next: the scale is gone with the old camera.
    pub fn refit_focal(&mut self, inputs: &[ScaleInput]) -> FocalRefit {
        use crate::road_focal::{combine, fit_focal_from_lengths, CameraSpread, PriorFocal};
        let width = f64::from(self.file.image_size[0]);
        let width = if width > 0.0 {
            width
        } else {
            2.0 * self.cal.pp.x
        };
        let fit = fit_focal_from_lengths(
            &self.cal,
            inputs,
            CameraSpread::of_file(&self.file, width),
            width,
        );
        let prior = PriorFocal {
            focal_px: self.cal.focal_px,
            interval_px: self.file.focal_interval_px,
            source: self
                .file
                .focal_source
                .clone()
                .unwrap_or_else(|| "unknown".to_string()),
        };
        let m = match fit {
            LengthFocalFit::NotIdentified(why) | LengthFocalFit::Inconsistent(why) => {
                return FocalRefit::Kept(why)
            }
            LengthFocalFit::Measured(m) => m,
        };
        let c = match combine(&m, &prior, self.lengths_source, self.focal_range_px(width)) {
            Ok(c) => c,
            Err(why) => return FocalRefit::Kept(why),
        };
        let Some(camera) = crate::road_focal::camera_with_focal(&self.cal, c.focal_px) else {
            return FocalRefit::Kept("the combined focal length gives no camera".to_string());
        };
        let clause = format!(
            "{} known lengths: {:.0} px (68% {:.0}-{:.0} px), with the footage's {:.0} px \
             ({}): {:.0} px ({}, 68% {:.0}-{:.0} px)",
            inputs.len(),
            m.focal_px,
            m.interval_px[0],
            m.interval_px[1],
            prior.focal_px,
            prior.source,
            c.focal_px,
            c.source,
            c.interval_px[0],
            c.interval_px[1]
        );
        if self
            .file
            .set_measured_camera(&camera, &c.source, c.interval_px, &clause)
            .is_err()
        {
            return FocalRefit::Kept("the file has no camera".to_string());
        }
        let evidence = self
            .file
            .evidence
            .get_or_insert_with(|| serde_json::Value::Object(serde_json::Map::new()));
        if let serde_json::Value::Object(e) = evidence {
            e.insert(
                "distances_focal".to_string(),
                serde_json::json!({
                    "focal_px": m.focal_px,
                    "interval_px": m.interval_px,
                    "lengths": inputs.len(),
                    "chi2": m.chi2,
                    "dof": m.dof,
                    "lengths_share": c.lengths_share,
                    "previous_focal_px": prior.focal_px,
                    "previous_focal_interval_px": prior.interval_px,
                    "previous_focal_source": prior.source,
                }),
            );
        }
        if let Some(w) = &c.disagreement {
            self.file.warnings.push(w.clone());
        }
        self.cal = camera;
        self.scale = None;
        FocalRefit::Measured {
            lengths: m,
            combined: c,
        }
    }

    /// The pixel that sees road-frame point `q` (the inverse of [`RoadCamera::road_point`]);
    /// `None` behind the camera.
    pub fn pixel(&self, q: [f64; 2]) -> Option<Point2> {
        let s = self.scale_or_one();
        self.cal.pixel_of_road_point([q[0] / s, q[1] / s])
    }
}

/// What [`RoadCamera::refit_focal`] did with the focal length.
#[derive(Debug, Clone, PartialEq)]
pub enum FocalRefit {
    /// The lengths measured it (`lengths`), and the file took `combined`.
    Measured {
        lengths: Box<crate::road_focal::LengthFocal>,
        combined: crate::road_focal::CombinedFocal,
    },
    /// The file keeps its focal length, for this reason.
    Kept(String),
}

/// Pixels closer than this below the horizon are measured with a warning: there a pixel's
/// error of 1 px moves its distance from the camera by more than `1 / NEAR_HORIZON_PX`
/// (5 %), since that distance grows as the inverse of the pixel's height below the horizon.
pub const NEAR_HORIZON_PX: f64 = 20.0;

/// Two pixels on the road and the distance between them (a taped distance, lane markings).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KnownDistance {
    pub p1: Point2,
    pub p2: Point2,
    pub distance_m: f64,
}

/// What a known measurement on the road says: the distance between two road points, or the
/// width of a lane (two pixels, one on each of two neighbouring lane lines, anywhere along
/// them: only the part across the road counts).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RoadMeasure {
    Distance,
    LaneWidth,
}

/// One known measurement for the scale.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScaleInput {
    pub kind: RoadMeasure,
    pub known: KnownDistance,
}

/// The scale of several known measurements and how well each agrees with it.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ScaleFit {
    /// Metres per road unit: the geometric mean of the measurements' own scales.
    pub scale: f64,
    /// Per measurement (in the given order): its own scale, and its length with the fitted
    /// scale minus the known one, metres and percent.
    pub own_scales: Vec<f64>,
    pub residuals_m: Vec<f64>,
    pub residuals_pct: Vec<f64>,
    /// `distance`, `lane_width`, or `distance_and_lane_width`.
    pub source: &'static str,
}

/// The length in road units that measurement `m` measures on `cal`.
fn measured_units(cal: &Calibration, m: &ScaleInput, flag: &str) -> Result<f64> {
    let k = m.known;
    if !(k.distance_m.is_finite() && k.distance_m > 0.0) {
        bail!(
            "{flag}: the length {} must be a positive number of metres",
            k.distance_m
        );
    }
    let (Some(a), Some(b)) = (cal.road_point(k.p1), cal.road_point(k.p2)) else {
        bail!(
            "{flag}: pixel ({}, {}) or ({}, {}) is above the horizon of the calibration: it \
             does not see the road",
            k.p1.x,
            k.p1.y,
            k.p2.x,
            k.p2.y
        );
    };
    let units = match m.kind {
        RoadMeasure::Distance => ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt(),
        RoadMeasure::LaneWidth => (a[1] - b[1]).abs(),
    };
    if !(units.is_finite() && units > 0.0) {
        bail!(
            "{flag}: the pixels ({}, {}) and ({}, {}) measure nothing on the road{}",
            k.p1.x,
            k.p1.y,
            k.p2.x,
            k.p2.y,
            if m.kind == RoadMeasure::LaneWidth {
                " across it (both on one lane line?)"
            } else {
                " (they coincide)"
            }
        );
    }
    Ok(units)
}

/// The metric scale from known measurements `inputs` (at least one), with each one's
/// residual; `flag_of` names the option of measurement `i` in errors.
///
/// # Errors
/// No measurement; a length that is not positive; a pixel above the horizon; pixels that
/// measure nothing.
pub fn fit_scale(
    cal: &Calibration,
    inputs: &[ScaleInput],
    flag_of: impl Fn(usize) -> String,
) -> Result<ScaleFit> {
    if inputs.is_empty() {
        bail!("no known distance or lane width to take the scale from");
    }
    let units: Vec<f64> = inputs
        .iter()
        .enumerate()
        .map(|(i, m)| measured_units(cal, m, &flag_of(i)))
        .collect::<Result<_>>()?;
    let own: Vec<f64> = inputs
        .iter()
        .zip(&units)
        .map(|(m, u)| m.known.distance_m / u)
        .collect();
    let scale = (own.iter().map(|s| s.ln()).sum::<f64>() / own.len() as f64).exp();
    let residuals_m: Vec<f64> = inputs
        .iter()
        .zip(&units)
        .map(|(m, u)| scale * u - m.known.distance_m)
        .collect();
    let residuals_pct = residuals_m
        .iter()
        .zip(inputs)
        .map(|(r, m)| 100.0 * r / m.known.distance_m)
        .collect();
    let has = |k: RoadMeasure| inputs.iter().any(|m| m.kind == k);
    let source = match (has(RoadMeasure::Distance), has(RoadMeasure::LaneWidth)) {
        (true, true) => "distance_and_lane_width",
        (false, true) => "lane_width",
        _ => "distance",
    };
    Ok(ScaleFit {
        scale,
        own_scales: own,
        residuals_m,
        residuals_pct,
        source,
    })
}
