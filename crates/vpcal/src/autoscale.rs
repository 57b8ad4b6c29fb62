//! The automatic metric scale of a run: the sizes of the vehicles it saw
//! ([`vpcal_geom::vehicle_scale`]), one value per tracked vehicle.

use vpcal_geom::camera::Calibration;
use vpcal_geom::vehicle_scale::{scale_from_vehicles, SizedBox, VehicleScale, PASSENGER_CAR};

use crate::pipeline::PipelineOutput;

/// The scale's source name in calibration files.
pub const SOURCE: &str = "vehicles";

/// The metric scale of `cal` from the detector boxes of `out`, each vehicle (a track of the
/// box tracker) counted once; `None` with too few vehicles whose boxes fit a car-shaped
/// cuboid.
pub fn vehicle_scale(out: &PipelineOutput, cal: &Calibration, seed: u64) -> Option<VehicleScale> {
    let link = crate::tracks::TrackSettings::default().link;
    let tracks = crate::tracks::link_boxes(&crate::tracks::record_boxes(&out.records), &link);
    let mut group = vec![0u64; out.records.len()];
    for (t, members) in tracks.iter().enumerate() {
        for &i in members {
            group[i] = t as u64;
        }
    }
    let boxes: Vec<SizedBox> = out
        .records
        .iter()
        .zip(&group)
        .map(|(r, g)| SizedBox {
            bbox: r.det_box,
            heading: None,
            group: Some(*g),
        })
        .collect();
    scale_from_vehicles(
        cal,
        &boxes,
        f64::from(out.info.width),
        f64::from(out.info.height),
        PASSENGER_CAR,
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
