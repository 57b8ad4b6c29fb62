//! The automatic scale on a rendered scene, split into its two errors: the camera's and the
//! vehicles'. For a scene of `vpcal synth scene` and the per-vehicle records of a run on it
//! (`calibrate --vehicles`), it prints the camera height the vehicles' sizes give on the
//! scene's *true* camera (the vehicles' part: detector boxes and fleet against the typical
//! car) and, with a calibration file of that run, on the run's camera (both parts), each
//! against the true height; then the same true-camera scale with each rendered kind's boxes
//! alone (the records' boxes matched to `vehicles.jsonl` by overlap).
//!
//! `cargo run --release -p vpcal --example scale_synth -- SCENE_DIR RECORDS [CALIB]`
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::collections::BTreeMap;
use std::path::PathBuf;

use vpcal::autoscale::vehicle_scale_of;
use vpcal::pipeline::TrackBox;
use vpcal_formats::calib::CalibrationFile;
use vpcal_formats::reference::read_vpout;
use vpcal_geom::camera::Calibration;
use vpcal_geom::{BoxPx, Point2};

fn height(boxes: &[TrackBox], size: (u32, u32), cal: &Calibration) -> Option<(f64, usize)> {
    let s = vehicle_scale_of(boxes, size, cal, 0)?;
    Some((s.m_per_unit * cal.plane_distance(), s.vehicles))
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    assert!(
        args.len() >= 2,
        "usage: scale_synth SCENE_DIR RECORDS [CALIB]"
    );
    let dir = PathBuf::from(&args[0]);
    let cam: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("camera.json")).unwrap()).unwrap();
    let p = |v: &serde_json::Value| Point2::new(v[0].as_f64().unwrap(), v[1].as_f64().unwrap());
    let truth = Calibration::from_vps(p(&cam["vp1"]), p(&cam["vp2"]), p(&cam["pp"])).unwrap();
    let true_height = cam["height_m"].as_f64().unwrap();
    let size = (
        u32::try_from(cam["width"].as_u64().unwrap()).unwrap(),
        u32::try_from(cam["height"].as_u64().unwrap()).unwrap(),
    );
    let boxes: Vec<TrackBox> = read_vpout(std::path::Path::new(&args[1]))
        .unwrap()
        .iter()
        .filter_map(|it| {
            Some(TrackBox {
                frame: it.frame_cnt.round() as u64,
                bbox: it.box_px()?,
                score: it.score as f32,
            })
        })
        .collect();
    let show = |what: &str, boxes: &[TrackBox], cal: &Calibration| match height(boxes, size, cal) {
        Some((h, n)) => println!(
            "{what:<28} {n:>4} vehicles  camera {h:6.2} m  (true {true_height:.2}: x{:.3})",
            h / true_height
        ),
        None => println!("{what:<28} too few vehicles"),
    };
    show("true camera", &boxes, &truth);
    if let Some(path) = args.get(2) {
        let file = CalibrationFile::read(std::path::Path::new(path)).unwrap();
        show("the run's camera", &boxes, &file.camera().unwrap());
    }
    // Each rendered kind alone: a record's box goes to the unclipped true box it overlaps most
    // (IoU >= 0.5) in its frame.
    let mut frames: BTreeMap<u64, Vec<(String, BoxPx)>> = BTreeMap::new();
    for line in std::fs::read_to_string(dir.join("vehicles.jsonl"))
        .unwrap()
        .lines()
    {
        let v: serde_json::Value = serde_json::from_str(line).unwrap();
        let b = &v["box"];
        let f = |i: usize| b[i].as_f64().unwrap();
        frames
            .entry(v["frame"].as_u64().unwrap())
            .or_default()
            .push((
                v["kind"].as_str().unwrap().to_string(),
                BoxPx::new(f(0), f(1), f(2), f(3)),
            ));
    }
    let mut by_kind: BTreeMap<String, Vec<TrackBox>> = BTreeMap::new();
    for b in &boxes {
        let best = frames.get(&b.frame).and_then(|vs| {
            vs.iter()
                .map(|(k, t)| (k, b.bbox.iou(t)))
                .max_by(|x, y| x.1.total_cmp(&y.1))
        });
        if let Some((k, iou)) = best.filter(|(_, iou)| *iou >= 0.5) {
            let _ = iou;
            by_kind.entry(k.clone()).or_default().push(*b);
        }
    }
    for (kind, kb) in &by_kind {
        show(&format!("true camera, {kind}"), kb, &truth);
    }
}
