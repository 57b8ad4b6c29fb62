//! The vehicle-shape evidence for the focal length on BrnoCompSpeed's real views, where the
//! focal length is known: each dev video's reference camera (`camera_truth.json`) keeps its
//! VP1 and horizon while the focal length moves over 0.5-2x its own, and the reference
//! detector's boxes (`detections.json`, score >= 0.5, off the border) are fitted with the
//! typical car, as a cuboid and as body and cabin (`vehicle_scale::PASSENGER_CAR_CABIN`).
//! Prints, per view and model, the focal length (over the reference) at which the boxes'
//! median misfit is least, and how much the misfit rises at half and twice that focal length
//! (a flat curve identifies nothing).
//!
//! `VPCAL_DATA=../shared/data cargo run --release --example shape_focal_bcs [MAX_BOXES]`
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::PathBuf;

use vpcal_formats::reference::read_detections;
use vpcal_geom::camera::{orthogonal_vp_on_line, Calibration};
use vpcal_geom::vehicle_scale::{fit_vehicle, Cabin, PASSENGER_CAR, PASSENGER_CAR_CABIN};
use vpcal_geom::{BoxPx, Point2};

/// Focal lengths over the reference's, log-spaced.
fn ratios() -> Vec<f64> {
    (0..=24).map(|k| 0.5 * 4f64.powf(k as f64 / 24.0)).collect()
}

fn median_misfit(cal: &Calibration, boxes: &[BoxPx], cabin: Cabin) -> f64 {
    let rms: Vec<f64> = vpcal_geom::solve::par_map(boxes, |b| {
        fit_vehicle(cal, *b, 0.0, PASSENGER_CAR, cabin).map(|fit| fit.rms)
    })
    .into_iter()
    .flatten()
    .collect();
    vpcal_geom::solve::median(&rms).unwrap_or(f64::NAN)
}

fn main() {
    let data = PathBuf::from(std::env::var("VPCAL_DATA").unwrap_or("../shared/data".into()));
    let max: usize = std::env::args().nth(1).map_or(300, |s| s.parse().unwrap());
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(data.join("bcs/camera_truth.json")).unwrap())
            .unwrap();
    let p = |v: &serde_json::Value| Point2::new(v[0].as_f64().unwrap(), v[1].as_f64().unwrap());
    println!("video\tboxes\tmodel\tbest f/truth\tmisfit there\tat half / twice, over it");
    for (video, c) in truth["cameras"].as_object().unwrap() {
        let cal = Calibration::from_vps(p(&c["vp1"]), p(&c["vp2"]), p(&c["pp"])).unwrap();
        let dir = data.join("bcs/dataset").join(video);
        let all: Vec<BoxPx> = read_detections(&dir.join("detections.json"))
            .unwrap()
            .iter()
            .flat_map(|f| f.boxes_px(0.5, 1920, 1080).collect::<Vec<_>>())
            .filter(|b| b.is_valid() && b.clear_of_edges(1920.0, 1080.0, 2.0))
            .collect();
        let step = all.len().div_ceil(max).max(1);
        let boxes: Vec<BoxPx> = all.into_iter().step_by(step).collect();
        for (name, cabin) in [("cuboid", Cabin::NONE), ("car", PASSENGER_CAR_CABIN)] {
            let curve: Vec<(f64, f64)> = ratios()
                .into_iter()
                .filter_map(|r| {
                    let f = cal.focal_px * r;
                    let vp2 = orthogonal_vp_on_line(cal.vp1, cal.horizon, f, cal.pp)?;
                    let c = Calibration::from_vps(cal.vp1, vp2, cal.pp).ok()?;
                    Some((r, median_misfit(&c, &boxes, cabin)))
                })
                .collect();
            let Some(&(best, m)) = curve.iter().min_by(|a, b| a.1.total_cmp(&b.1)) else {
                continue;
            };
            let at = |r: f64| {
                curve
                    .iter()
                    .min_by(|a, b| {
                        (a.0.ln() - r.ln())
                            .abs()
                            .total_cmp(&(b.0.ln() - r.ln()).abs())
                    })
                    .map_or(f64::NAN, |x| x.1 / m)
            };
            println!(
                "{video}\t{}\t{name}\t{best:.2}\t{m:.4}\t{:.2} / {:.2}",
                boxes.len(),
                at(best / 2.0),
                at(best * 2.0)
            );
        }
    }
}
