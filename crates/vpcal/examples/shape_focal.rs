//! How well the boxes of the vehicles fit typical-car cuboids for candidate focal lengths,
//! with VP1 and the horizon of a calibration held: the "vehicle shape" evidence for f.
//!
//! `cargo run --release --example shape_focal -- CALIB.json DETECTIONS.csv [MAX_BOXES]`
//! prints, per focal length (0.5-8x the calibration's), the median cuboid misfit of the
//! boxes (fraction of the box diagonal) and the share that fits within the automatic
//! scale's limit.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use vpcal_formats::calib::CalibrationFile;
use vpcal_geom::camera::{orthogonal_vp_on_line, Calibration};
use vpcal_geom::vehicle_scale::{fit_cuboid, MAX_FIT_RMS, PASSENGER_CAR};
use vpcal_geom::BoxPx;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let file = CalibrationFile::read(std::path::Path::new(&args[1])).unwrap();
    let cal = file.camera().unwrap();
    let [w, h] = file.image_size.map(f64::from);
    let text = std::fs::read_to_string(&args[2]).unwrap();
    let mut boxes: Vec<BoxPx> = text
        .lines()
        .skip(1)
        .filter_map(|l| {
            let v: Vec<f64> = l.split(',').filter_map(|x| x.trim().parse().ok()).collect();
            (v.len() >= 5).then(|| BoxPx {
                x0: v[1],
                y0: v[2],
                x1: v[3],
                y1: v[4],
            })
        })
        .filter(|b| b.is_valid() && b.x0 > 2.0 && b.y0 > 2.0 && b.x1 < w - 2.0 && b.y1 < h - 2.0)
        .collect();
    let max: usize = args.get(3).map_or(400, |s| s.parse().unwrap());
    let step = boxes.len().div_ceil(max).max(1);
    boxes = boxes.into_iter().step_by(step).collect();
    println!(
        "f_px\tratio\tmedian_rms\tshare_fit\t(boxes {})",
        boxes.len()
    );
    for k in 0..=16 {
        let ratio = 0.5 * 16f64.powf(k as f64 / 16.0);
        let f = cal.focal_px * ratio;
        let Some(vp2) = orthogonal_vp_on_line(cal.vp1, cal.horizon, f, cal.pp) else {
            continue;
        };
        let Ok(c) = Calibration::from_vps(cal.vp1, vp2, cal.pp) else {
            continue;
        };
        let mut rms: Vec<f64> = boxes
            .iter()
            .filter_map(|b| fit_cuboid(&c, *b, 0.0, PASSENGER_CAR).map(|fit| fit.rms))
            .collect();
        rms.sort_by(f64::total_cmp);
        let share = rms.iter().filter(|r| **r <= MAX_FIT_RMS).count() as f64 / rms.len() as f64;
        println!(
            "{f:.0}\t{ratio:.2}\t{:.4}\t{share:.2}",
            rms.get(rms.len() / 2).copied().unwrap_or(f64::NAN)
        );
    }
}
