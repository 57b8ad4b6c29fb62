//! The automatic scale (vehicle sizes) on BrnoCompSpeed's real views against the scale their
//! taped distances give: each video's reference camera (`camera_truth.json`), the reference
//! detector's boxes sampled over the video (`detections.json`, score >= 0.5), the typical car
//! of `vpcal_geom::vehicle_scale`; the scale those taped distances fit on that camera
//! (`metrics::optimal_scale`) is the truth. Prints the automatic scale's metres per unit over
//! the truth, and its 68 % interval's.
//!
//! `VPCAL_DATA=../shared/data cargo run --release --example scale_bcs`
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::PathBuf;

use vpcal_formats::reference::read_detections;
use vpcal_geom::camera::Calibration;
use vpcal_geom::metrics::optimal_scale;
use vpcal_geom::vehicle_scale::{
    scale_from_vehicles, SizedBox, PASSENGER_CAR, PASSENGER_CAR_CABIN,
};
use vpcal_geom::Point2;

fn main() {
    let data = PathBuf::from(std::env::var("VPCAL_DATA").unwrap_or("../shared/data".into()));
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(data.join("bcs/camera_truth.json")).unwrap())
            .unwrap();
    let p = |v: &serde_json::Value| Point2::new(v[0].as_f64().unwrap(), v[1].as_f64().unwrap());
    println!("video\tboxes\tvehicles_used\tscale/truth\t68%/truth");
    let mut ratios = Vec::new();
    for (video, c) in truth["cameras"].as_object().unwrap() {
        let cal = Calibration::from_vps(p(&c["vp1"]), p(&c["vp2"]), p(&c["pp"])).unwrap();
        let dir = data.join("bcs/dataset").join(video);
        let gt = vpcal_formats::bcs::read_gt(&dir).unwrap();
        let Some(reference) = optimal_scale(&cal, &gt.road_measurements()) else {
            continue;
        };
        let boxes: Vec<SizedBox> = read_detections(&dir.join("detections.json"))
            .unwrap()
            .iter()
            .flat_map(|f| f.boxes_px(0.5, 1920, 1080).collect::<Vec<_>>())
            .map(|bbox| SizedBox {
                bbox,
                heading: None,
                group: None,
            })
            .collect();
        let Some(s) = scale_from_vehicles(
            &cal,
            &boxes,
            1920.0,
            1080.0,
            PASSENGER_CAR,
            PASSENGER_CAR_CABIN,
            0,
        ) else {
            println!("{video}\t{}\t-", boxes.len());
            continue;
        };
        let ratio = s.m_per_unit / reference;
        ratios.push(ratio);
        println!(
            "{video}\t{}\t{}\t{ratio:.3}\t{:.3}-{:.3}",
            boxes.len(),
            s.vehicles,
            s.interval[0] / reference,
            s.interval[1] / reference
        );
    }
    let inside = ratios.iter().filter(|r| (**r - 1.0).abs() < 0.1).count();
    println!(
        "median ratio {:.3} over {} views; within 10 % on {inside}",
        vpcal_geom::solve::median(&ratios).unwrap_or(f64::NAN),
        ratios.len()
    );
}
