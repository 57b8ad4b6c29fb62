//! Plausibility of a calibration run's results: what road traffic and traffic cameras can be.
//!
//! A camera from vanishing points can be wrong in ways its own intervals do not show (a
//! time-lapse read as real time, a few seconds of footage, an assumed focal length far from the
//! true one). Physics and the purpose of the camera bound what is possible; a result outside
//! those bounds is kept, said in a warning with its likely cause and remedy, and lowers the
//! calibration's status ([`Status::Rough`]: atypical; [`Status::Unreliable`]: impossible),
//! instead of being filtered out silently or printed as if it were true.
//!
//! Every check takes the calibration's own uncertainty into account: a speed is impossible
//! only when the lower end of what the calibration allows ([`along_factor`]) is still too
//! fast; a median above what traffic usually drives is atypical (`rough`) either way.
//!
//! The bounds (named constants below) come from physics and from how traffic cameras are
//! mounted, not from one dataset:
//! - speeds: the fastest series cars reach about 300-400 km/h on a test track; in traffic
//!   nobody is measured above ~300 km/h, and the median of a traffic flow stays below the
//!   highest posted limits (130-140 km/h; unrestricted German motorways average 120-140 km/h in
//!   the fast lane), so a clip's median above [`MEDIAN_SPEED_TYPICAL_MAX_KMH`] is atypical and
//!   above [`MEDIAN_SPEED_POSSIBLE_MAX_KMH`] impossible: the frame rate is wrong (time-lapse
//!   footage, an export with a wrong rate) or the scale is.
//! - camera height: roadside poles and gantries 5-15 m, overpasses 5-10 m, buildings up to a
//!   few tens of metres ([`CAMERA_HEIGHT_TYPICAL_M`]); below a person's height or above a tall
//!   mast is impossible for a camera that sees traffic as vehicles
//!   ([`CAMERA_HEIGHT_POSSIBLE_M`]).
//! - tilt: a camera that sees the road's vanishing point looks at most a few degrees above
//!   the horizon; the horizon's own row bounds it from below ([`TILT_POSSIBLE_DEG`]).
//! - VP1: resting on the network's VP1 rays alone while they scatter ([`check_vp1`]).
//! - the horizon: contradicted by the scene's plumb lines beyond a road's cross slope
//!   ([`check_horizon`]).

use vpcal_formats::calib::{CalibrationFile, PlausibilityCheck, Status};

use crate::tracks::VehicleTrack;

/// Above this, no road vehicle in traffic is measured, km/h.
pub const VEHICLE_SPEED_POSSIBLE_MAX_KMH: f64 = 300.0;
/// A clip's median speed above this is atypical of road traffic, km/h.
pub const MEDIAN_SPEED_TYPICAL_MAX_KMH: f64 = 140.0;
/// A clip's median speed above this is impossible for road traffic, km/h.
pub const MEDIAN_SPEED_POSSIBLE_MAX_KMH: f64 = 200.0;
/// Heights of traffic cameras above the road, metres: typical.
pub const CAMERA_HEIGHT_TYPICAL_M: [f64; 2] = [3.0, 50.0];
/// Heights of traffic cameras above the road, metres: possible.
pub const CAMERA_HEIGHT_POSSIBLE_M: [f64; 2] = [1.0, 300.0];
/// Tilt of the optical axis below the road plane, degrees: a camera that sees the road's
/// vanishing point cannot look far above the horizon.
pub const TILT_POSSIBLE_DEG: [f64; 2] = [-10.0, 90.0];
/// Tracks needed for a median speed to be judged.
pub const MIN_TRACKS_FOR_MEDIAN: usize = 3;

/// The check of the camera's height and tilt ([`check_camera`]).
pub const CAMERA_CHECK: &str = "camera";
/// The check of the tracks' speeds ([`check_speeds`]).
pub const SPEEDS_CHECK: &str = "speeds";
/// The check of what VP1 rests on ([`check_vp1`]).
pub const VP1_CHECK: &str = "vp1";
/// The check of the horizon against the scene's vertical lines ([`check_horizon`]).
pub const HORIZON_CHECK: &str = "horizon";

/// A failed check of kind `check`.
fn failed(check: &str, status: Status, warning: String) -> PlausibilityCheck {
    PlausibilityCheck {
        check: check.to_string(),
        status,
        warning,
    }
}

/// How much distances along the road (and so speeds) can be off because of the calibration:
/// the factor range `[lo, hi]` (68 %) that combines, in log space, the automatic scale's
/// interval and the change of along-road distances over the focal length's interval
/// (`scale_focal_sensitivity`). `[1, 1]` when neither is known (a known distance along the
/// road fixes the scale; a measured or given focal length).
pub fn along_factor(file: &CalibrationFile) -> [f64; 2] {
    let scale_sd = file
        .scale_interval_m_per_unit
        .zip(file.scale_m_per_unit)
        .map_or(0.0, |([lo, hi], _)| 0.5 * (hi / lo).ln().abs());
    let focal_sd = file
        .scale_focal_sensitivity
        .map_or(0.0, |s| 0.5 * (s.along[1] / s.along[0]).ln().abs());
    let sd = scale_sd.hypot(focal_sd);
    if sd.is_finite() {
        [(-sd).exp(), sd.exp()]
    } else {
        [1.0, 1.0]
    }
}

/// Whether a track's speed is impossible for a road vehicle even at the low end of what the
/// calibration allows (`factor`, [`along_factor`]) and two standard errors below it.
pub fn impossible_speed(track: &VehicleTrack, factor: [f64; 2]) -> bool {
    track.speed.is_some_and(|s| {
        (s.kmh - 2.0 * s.uncertainty_kmh) * factor[0] > VEHICLE_SPEED_POSSIBLE_MAX_KMH
    })
}

/// The speed findings of `tracks` measured with `file`'s calibration; `fps_given` says
/// whether the user gave the frame rate (`--fps`), which the remedy then doubts less.
pub fn check_speeds(
    tracks: &[VehicleTrack],
    file: &CalibrationFile,
    fps_given: bool,
) -> Vec<PlausibilityCheck> {
    let factor = along_factor(file);
    let speeds: Vec<f64> = tracks
        .iter()
        .filter_map(|t| t.speed.map(|s| s.kmh))
        .filter(|v| v.is_finite())
        .collect();
    let mut out = Vec::new();
    let impossible = tracks
        .iter()
        .filter(|t| impossible_speed(t, factor))
        .count();
    let fps = file
        .input
        .fps
        .map_or("its stated".to_string(), |f| format!("{f:.3} frames/s"));
    // An assumed focal length stretches distances along the road (on a telephoto view by
    // more than its interval says): the remedy names it too.
    let focal = if file.focal_source.as_deref() == Some("prior") {
        ", and the focal length, which is assumed (give --focal PX or --focal-range SHORT,LONG)"
    } else {
        ""
    };
    let rate_remedy = if fps_given {
        format!(
            "check the frame rate given with --fps and the metric scale (give a known distance \
             with `vpcal scale`){focal}"
        )
    } else {
        format!(
            "the clip looks like a time-lapse or its frame rate ({fps}) is wrong: give the true \
             rate with --fps; or check the metric scale (give a known distance with `vpcal \
             scale`){focal}"
        )
    };
    if speeds.len() >= MIN_TRACKS_FOR_MEDIAN {
        let median = vpcal_geom::solve::median(&speeds).unwrap_or(f64::NAN);
        let low = median * factor[0];
        if low > MEDIAN_SPEED_POSSIBLE_MAX_KMH {
            out.push(failed(
                SPEEDS_CHECK,
                Status::Unreliable,
                format!(
                    "the median speed of {} tracks is {median:.0} km/h (at least {low:.0} km/h \
                     within the calibration's uncertainty), more than road traffic drives \
                     ({MEDIAN_SPEED_POSSIBLE_MAX_KMH:.0} km/h): {rate_remedy}",
                    speeds.len()
                ),
            ));
        } else if median > MEDIAN_SPEED_TYPICAL_MAX_KMH {
            out.push(failed(
                SPEEDS_CHECK,
                Status::Rough,
                format!(
                    "the median speed of {} tracks is {median:.0} km/h ({low:.0} km/h at the \
                     low end of the calibration's uncertainty), faster than traffic usually \
                     flows (up to {MEDIAN_SPEED_TYPICAL_MAX_KMH:.0} km/h): {rate_remedy}",
                    speeds.len()
                ),
            ));
        }
    }
    if impossible > 0 {
        out.push(failed(
            SPEEDS_CHECK,
            Status::Rough,
            format!(
                "{impossible} of {} tracks with a speed are faster than any road vehicle in \
                 traffic ({VEHICLE_SPEED_POSSIBLE_MAX_KMH:.0} km/h) even at the low end of the \
                 calibration's uncertainty: they are left out of the BrnoCompSpeed cars \
                 (boxes that jumped between vehicles, or a wrong frame rate or scale)",
                speeds.len()
            ),
        ));
    }
    out
}

/// What VP1 rests on: the network's VP1 rays alone, scattering more than a network that
/// knows real vehicles does ([`crate::aggregate::WEAK_VP1_RAY_SCATTER_DEG`]), make the road's
/// direction, and every distance measured along it, unreliable. (On 45 frames of a real
/// highway clip such a VP1 put the camera 64 m up, tilted 55° down, where longer footage
/// gives 9 m and 10°.)
pub fn check_vp1(agg: &crate::aggregate::Aggregated) -> Vec<PlausibilityCheck> {
    agg.weak_vp1_warning()
        .map(|w| failed(VP1_CHECK, Status::Unreliable, w))
        .into_iter()
        .collect()
}

/// The road's horizon against the scene's plumb lines: a road's surface leans off gravity's
/// horizon by its cross slope (2-2.5 %, up to 7-8 % on a banked curve: 1-4.6°); a horizon that
/// the vertical lines contradict beyond that and both errors
/// (`vpcal_geom::aggregate::verticals::HORIZON_CONFLICT_Z`) is not the road's, and the camera
/// built on it is not one a road can have.
pub fn check_horizon(agg: &crate::aggregate::Aggregated) -> Vec<PlausibilityCheck> {
    agg.horizon_conflict_warning()
        .map(|w| failed(HORIZON_CHECK, Status::Unreliable, w))
        .into_iter()
        .collect()
}

/// The camera findings of a calibrated `file`: its height (with a metric scale) and tilt.
pub fn check_camera(file: &CalibrationFile) -> Vec<PlausibilityCheck> {
    let mut out = Vec::new();
    let scale_note = match file.scale_source.as_deref() {
        Some("vehicles") => {
            " (with the automatic scale: give a known distance with `vpcal scale`, and check the \
             focal length)"
        }
        _ => " (check the focal length and the known distances)",
    };
    if let (Some(h), Some(h_text)) = (file.camera_height_m, file.height_text()) {
        let [lo, hi] = CAMERA_HEIGHT_POSSIBLE_M;
        let [tlo, thi] = CAMERA_HEIGHT_TYPICAL_M;
        // Impossible when even the end of the height's interval nearest the possible range
        // is outside it (as for speeds: the calibration's own uncertainty first).
        let [near_lo, near_hi] = file.camera_height_interval_m.unwrap_or([h, h]);
        if near_hi < lo || near_lo > hi {
            out.push(failed(
                CAMERA_CHECK,
                Status::Unreliable,
                format!(
                    "the camera comes out {h_text} above the road, which no traffic camera is \
                     ({lo:.0}-{hi:.0} m possible){scale_note}"
                ),
            ));
        } else if h < tlo || h > thi {
            // Atypical, or impossible only at the point and not over its interval.
            out.push(failed(
                CAMERA_CHECK,
                Status::Rough,
                format!(
                    "the camera comes out {h_text} above the road, outside the usual \
                     {tlo:.0}-{thi:.0} m of traffic cameras{scale_note}"
                ),
            ));
        }
    }
    if let Some(t) = file.tilt_deg.filter(|t| t.is_finite()) {
        let [lo, hi] = TILT_POSSIBLE_DEG;
        if t < lo || t > hi {
            out.push(failed(
                CAMERA_CHECK,
                Status::Unreliable,
                format!(
                    "the camera comes out tilted {t:.1}° below the road plane, which a camera \
                     that sees the road's vanishing point cannot be ({lo:.0}° to {hi:.0}°): the \
                     horizon is misplaced; use longer footage of moving traffic"
                ),
            ));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tracks::SpeedEstimate;
    use vpcal_formats::calib::InputSummary;
    use vpcal_geom::camera::Calibration;
    use vpcal_geom::Point2;

    fn file() -> CalibrationFile {
        let cal = Calibration::from_vps(
            Point2::new(700.0, -300.0),
            Point2::new(-20000.0, -250.0),
            Point2::new(640.0, 360.0),
        )
        .unwrap();
        let input = InputSummary {
            width: 1280,
            height: 720,
            fps: Some(25.0),
            ..InputSummary::default()
        };
        CalibrationFile::calibrated(input, &cal)
    }

    fn track(kmh: f64) -> VehicleTrack {
        VehicleTrack {
            id: 1,
            points: Vec::new(),
            speed: Some(SpeedEstimate {
                kmh,
                uncertainty_kmh: 1.0,
                fit_kmh: kmh,
                windows: 3,
            }),
            lateral_m: None,
            lane: None,
            towards_vp1: None,
            path: Vec::new(),
        }
    }

    #[test]
    fn traffic_speeds_pass_and_a_time_lapse_is_called_unreliable() {
        let f = file();
        let normal: Vec<VehicleTrack> = [60.0, 80.0, 95.0, 120.0].map(track).into();
        assert!(check_speeds(&normal, &f, false).is_empty());
        let lapse: Vec<VehicleTrack> = [480.0, 526.0, 700.0, 1418.0].map(track).into();
        let found = check_speeds(&lapse, &f, false);
        assert!(found.iter().any(|x| x.status == Status::Unreliable
            && x.warning.contains("time-lapse")
            && x.warning.contains("--fps")));
        assert!(found.iter().any(|x| x.warning.contains("4 of 4 tracks")));
        let mut g = f.clone();
        g.replace_checks(SPEEDS_CHECK, found);
        assert_eq!(g.status, Status::Unreliable);
        assert!(g.warnings.iter().any(|w| w.contains("time-lapse")));
        // Checked again with speeds that pass, the file is calibrated again.
        g.replace_checks(SPEEDS_CHECK, check_speeds(&normal, &f, false));
        assert_eq!(g.status, Status::Calibrated);
        assert!(g.warnings.is_empty() && g.failed_checks.is_empty());
    }

    #[test]
    fn the_calibrations_uncertainty_decides_between_rough_and_unreliable() {
        let mut f = file();
        let fast: Vec<VehicleTrack> = [150.0, 160.0, 170.0].map(track).into();
        assert_eq!(check_speeds(&fast, &f, false)[0].status, Status::Rough);
        let faster: Vec<VehicleTrack> = [220.0, 230.0, 240.0].map(track).into();
        assert_eq!(
            check_speeds(&faster, &f, false)[0].status,
            Status::Unreliable
        );
        // An automatic scale known to ±25 %: 230 km/h may be 184, atypical but possible.
        f.scale_m_per_unit = Some(0.05);
        f.scale_interval_m_per_unit = Some([0.04, 0.0625]);
        let found = check_speeds(&faster, &f, false);
        assert_eq!(found.len(), 1);
        assert_eq!(found[0].status, Status::Rough);
        assert!(
            found[0].warning.contains("184 km/h"),
            "{}",
            found[0].warning
        );
        let [lo, hi] = along_factor(&f);
        assert!(
            (lo * hi - 1.0).abs() < 1e-12 && lo < 0.81 && lo > 0.79,
            "{lo} {hi}"
        );
    }

    #[test]
    fn camera_heights_and_tilts_outside_traffic_cameras_are_flagged() {
        let mut f = file();
        f.camera_height_m = Some(8.9);
        assert!(check_camera(&f).is_empty());
        f.camera_height_m = Some(64.4);
        assert_eq!(check_camera(&f)[0].status, Status::Rough);
        f.camera_height_m = Some(800.0);
        assert_eq!(check_camera(&f)[0].status, Status::Unreliable);
        f.camera_height_m = Some(0.3);
        assert_eq!(check_camera(&f)[0].status, Status::Unreliable);
        // With an automatic scale's interval: impossible only where the whole interval is.
        f.camera_height_interval_m = Some([0.2, 0.5]);
        assert_eq!(check_camera(&f)[0].status, Status::Unreliable);
        f.camera_height_m = Some(0.8);
        f.camera_height_interval_m = Some([0.55, 1.3]);
        let found = check_camera(&f);
        assert_eq!(found[0].status, Status::Rough);
        assert!(
            found[0].warning.contains("0.8 m (68% 0.6-1.3 m)"),
            "{}",
            found[0].warning
        );
    }
}
