//! The automatic metric scale of a run: the sizes of the vehicles it saw
//! ([`vpcal_geom::vehicle_scale`]), one value per tracked vehicle.

use vpcal_formats::calib::FocalSensitivity;
use vpcal_geom::camera::Calibration;
use vpcal_geom::vehicle_scale::{
    scale_from_vehicles, SizedBox, VehicleScale, PASSENGER_CAR, PASSENGER_CAR_CABIN,
};
use vpcal_geom::Point2;

use crate::pipeline::{PipelineOutput, TrackBox};

/// The scale's source name in calibration files.
pub const SOURCE: &str = "vehicles";

/// The metric scale of `cal` from the detector boxes of `out`, each vehicle (a track of the
/// box tracker) counted once; `None` with too few vehicles whose boxes fit a car-shaped
/// cuboid.
pub fn vehicle_scale(out: &PipelineOutput, cal: &Calibration, seed: u64) -> Option<VehicleScale> {
    let boxes = crate::tracks::record_boxes(&out.records);
    vehicle_scale_of(&boxes, (out.info.width, out.info.height), cal, seed)
}

/// [`vehicle_scale`] of detector boxes `boxes` (with their frames) in frames of `size`
/// pixels: a run's records, or those of a file of per-vehicle records.
pub fn vehicle_scale_of(
    boxes: &[TrackBox],
    size: (u32, u32),
    cal: &Calibration,
    seed: u64,
) -> Option<VehicleScale> {
    scale_of(size, &sized_boxes(boxes), cal, seed)
}

/// The detector boxes, each with its track of the box tracker as its group.
fn sized_boxes(boxes: &[TrackBox]) -> Vec<SizedBox> {
    let link = crate::tracks::TrackSettings::default().link;
    let tracks = crate::tracks::link_boxes(boxes, &link);
    let mut group = vec![0u64; boxes.len()];
    for (t, members) in tracks.iter().enumerate() {
        for &i in members {
            group[i] = t as u64;
        }
    }
    boxes
        .iter()
        .zip(&group)
        .map(|(b, g)| SizedBox {
            bbox: b.bbox,
            heading: None,
            group: Some(*g),
        })
        .collect()
}

/// [`vehicle_scale`] with the boxes already grouped.
fn scale_of(
    size: (u32, u32),
    boxes: &[SizedBox],
    cal: &Calibration,
    seed: u64,
) -> Option<VehicleScale> {
    scale_from_vehicles(
        cal,
        boxes,
        f64::from(size.0),
        f64::from(size.1),
        PASSENGER_CAR,
        PASSENGER_CAR_CABIN,
        seed,
    )
}

/// One line for the run's summary.
pub fn summary_line(s: &VehicleScale, plane_distance: f64) -> String {
    format!(
        "{:.4} m per unit (68% {:.4}-{:.4}; camera {:.1} m above the road) from {} vehicles \
         ({} boxes) as {} x {} x {} m cars; {} boxes did not fit a car, {} cut by the border",
        s.m_per_unit,
        s.interval[0],
        s.interval[1],
        s.m_per_unit * plane_distance,
        s.vehicles,
        s.boxes,
        PASSENGER_CAR[0],
        PASSENGER_CAR[1],
        PASSENGER_CAR[2],
        s.rejected_misfit,
        s.rejected_border
    )
}

/// The camera `cal` would be with focal length `focal_px`: its VP1, horizon and principal
/// point kept, VP2 where the horizon meets VP1's orthogonal locus.
pub fn with_focal(cal: &Calibration, focal_px: f64) -> Option<Calibration> {
    let vp2 = vpcal_geom::camera::orthogonal_vp_on_line(cal.vp1, cal.horizon, focal_px, cal.pp)?;
    Calibration::from_vps(cal.vp1, vp2, cal.pp).ok()
}

/// The [`FocalSensitivity`] of the automatic scale `scale` of `cal` over `interval_px`, measured
/// at the median foot point of the vehicles `track_boxes` (frames of `size` pixels): the along distance to the point a tenth of
/// the frame height towards VP1, the across distance to the point a tenth of the frame width
/// along the horizon's direction. `None` when a camera or scale at an end cannot be had.
pub fn focal_sensitivity(
    track_boxes: &[TrackBox],
    size: (u32, u32),
    cal: &Calibration,
    scale: &VehicleScale,
    interval_px: [f64; 2],
) -> Option<FocalSensitivity> {
    let boxes = sized_boxes(track_boxes);
    let feet: Vec<(f64, f64)> = boxes
        .iter()
        .map(|b| (0.5 * (b.bbox.x0 + b.bbox.x1), b.bbox.y1))
        .collect();
    let median = |v: Vec<f64>| vpcal_geom::solve::median(&v);
    let foot = Point2::new(
        median(feet.iter().map(|f| f.0).collect())?,
        median(feet.iter().map(|f| f.1).collect())?,
    );
    let (w, h) = (f64::from(size.0), f64::from(size.1));
    let towards = (cal.vp1 - foot) / (cal.vp1 - foot).norm();
    let along_px = foot + towards * (0.1 * h);
    let horizon_dir = {
        let [a, b, _] = cal.horizon.0;
        Point2::new(b, -a) / a.hypot(b)
    };
    let across_px = foot + horizon_dir * (0.1 * w);
    // Metres along and across between the foot point and the two others, with camera `c`
    // scaled by `m` metres per unit.
    let metres = |c: &Calibration, m: f64| -> Option<(f64, f64)> {
        let p = c.road_point(foot)?;
        let a = c.road_point(along_px)?;
        let b = c.road_point(across_px)?;
        let along = (a[0] - p[0]).abs() * m;
        let across = (b[1] - p[1]).abs() * m;
        (along > 0.0 && across > 0.0 && along.is_finite() && across.is_finite())
            .then_some((along, across))
    };
    let base = metres(cal, scale.m_per_unit)?;
    let base_height = cal.plane_distance() * scale.m_per_unit;
    let mut along = [1.0; 2];
    let mut across = [1.0; 2];
    let mut height = [1.0; 2];
    for (k, &f) in interval_px.iter().enumerate() {
        let c = with_focal(cal, f)?;
        let s = scale_of(size, &boxes, &c, 0)?;
        let (a, b) = metres(&c, s.m_per_unit)?;
        along[k] = a / base.0;
        across[k] = b / base.1;
        height[k] = c.plane_distance() * s.m_per_unit / base_height;
    }
    Some(FocalSensitivity {
        focal_px: interval_px,
        along,
        across,
        height,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn with_focal_keeps_vp1_and_horizon() {
        let pp = Point2::new(480.0, 270.0);
        let cal = Calibration::from_vps(Point2::new(100.6, 27.3), Point2::new(3306.8, -28.7), pp)
            .unwrap();
        for f in [0.5 * cal.focal_px, cal.focal_px, 2.0 * cal.focal_px] {
            let c = with_focal(&cal, f).unwrap();
            assert!((c.focal_px - f).abs() < 1e-6 * f, "{} vs {f}", c.focal_px);
            assert!((c.vp1 - cal.vp1).norm() < 1e-9);
            assert!((c.roll() - cal.roll()).abs() < 1e-9);
            // VP2 stays on the horizon.
            let d = cal.horizon.signed_distance(c.vp2).unwrap();
            assert!(d.abs() < 1e-6 * c.vp2.norm(), "{d}");
        }
        // A longer focal length puts the road further away: the camera tilts less.
        let long = with_focal(&cal, 2.0 * cal.focal_px).unwrap();
        assert!(long.tilt() < cal.tilt());
    }
}
