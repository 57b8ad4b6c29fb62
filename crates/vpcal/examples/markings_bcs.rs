//! The road markings of BrnoCompSpeed's views against their reference cameras: which lane
//! lines and dashes `vpcal::markings` finds in each `screen.png` (inside `video_mask.png`)
//! with the reference VP1, the dash period over the lane width they measure on the reference
//! camera (a ratio, so no scale is needed), and the focal length a marking standard gives with
//! the reference VP1 and horizon held.
//!
//! `VPCAL_DATA=../shared/data cargo run --release --example markings_bcs -- [PERIOD,LANE]`
//! (default 9,3.5: the Czech 3 + 6 m dashed line; lanes 3.5 m). `VERBOSE=1` lists each line's
//! bars and dashes on stderr; `BARS_DIR=DIR` writes each view's bars as `DIR/VIDEO.csv` (line
//! index, dashed, ends) to draw them; `RADIUS=R` sets the top-hat's half window at 1080p.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::PathBuf;

use vpcal::markings::{lane_lines, standard_lengths, summary, MarkingStandard};
use vpcal::road_focal::{fit_focal_from_lengths, CameraSpread, LengthFocalFit};
use vpcal_geom::camera::Calibration;
use vpcal_geom::Point2;
use vpcal_video::markings::{bright_bars, BarOptions};

fn main() {
    let data = PathBuf::from(std::env::var("VPCAL_DATA").unwrap_or("../shared/data".into()));
    let std: MarkingStandard = std::env::args()
        .nth(1)
        .unwrap_or("9,3.5".into())
        .parse()
        .unwrap();
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(data.join("bcs/camera_truth.json")).unwrap())
            .unwrap();
    let p = |v: &serde_json::Value| Point2::new(v[0].as_f64().unwrap(), v[1].as_f64().unwrap());
    println!("video\tlines\tdashed\tlanes\tperiod/lane\tf_true\tf_markings\t68%\terr%");
    let mut errors = Vec::new();
    let cameras = truth["cameras"].as_object().unwrap();
    for (video, c) in cameras {
        let cal = Calibration::from_vps(p(&c["vp1"]), p(&c["vp2"]), p(&c["pp"])).unwrap();
        let dir = data.join("bcs/dataset").join(video);
        let grey = image::open(dir.join("screen.png")).unwrap().to_luma8();
        let mask = image::open(dir.join("video_mask.png"))
            .ok()
            .map(|m| m.to_luma8());
        let options = BarOptions {
            radius_1080p: std::env::var("RADIUS").map_or(7, |r| r.parse().unwrap()),
            ..BarOptions::default()
        };
        let bars = bright_bars(&grey, mask.as_ref(), &options);
        let lines = lane_lines(&bars, cal.vp1);
        if let Ok(dir) = std::env::var("BARS_DIR") {
            let mut csv = String::from("line,dashed,x0,y0,x1,y1\n");
            for b in &bars {
                let line = lines.iter().position(|l| l.bars.contains(b));
                let dashed = line.is_some_and(|i| lines[i].dashes.is_some());
                csv.push_str(&format!(
                    "{},{},{:.1},{:.1},{:.1},{:.1}\n",
                    line.map_or(-1, |i| i as i64),
                    u8::from(dashed),
                    b.ends[0].x,
                    b.ends[0].y,
                    b.ends[1].x,
                    b.ends[1].y
                ));
            }
            std::fs::write(format!("{dir}/{video}.csv"), csv).unwrap();
        }
        if std::env::var("VERBOSE").is_ok() {
            eprintln!("{video}: {} bars", bars.len());
            for l in &lines {
                eprintln!(
                    "  angle {:7.2} bars {:3} near_t {:6.0} lengths {:?} dashes {:?}",
                    l.direction.y.atan2(l.direction.x).to_degrees(),
                    l.bars.len(),
                    l.near_t,
                    l.bars.iter().map(|b| b.length.round()).collect::<Vec<_>>(),
                    l.dashes.as_ref().map(|d| {
                        let (n, f) = (d.centres_u[0], d.centres_u[d.centres_u.len() - 1]);
                        let a = cal.road_point(l.pixel_at(cal.vp1, n));
                        let b = cal.road_point(l.pixel_at(cal.vp1, f));
                        let units = a
                            .zip(b)
                            .map(|(a, b)| (a[0] - b[0]).hypot(a[1] - b[1]) / d.span_periods());
                        (
                            d.centres_u.len(),
                            d.span_periods(),
                            d.cv,
                            d.duty,
                            units,
                            cal.road_point(l.pixel_at(cal.vp1, 1.0 / l.near_t)),
                        )
                    })
                );
            }
        }
        let s = summary(&lines, &cal, None);
        let ratio = s["dash_period"].as_f64().unwrap_or(f64::NAN)
            / s["lane_width"].as_f64().unwrap_or(f64::NAN);
        let width = f64::from(grey.width());
        let inputs = standard_lengths(&lines, &cal, &std);
        let fit = fit_focal_from_lengths(&cal, &inputs, CameraSpread::floored(None, width), width);
        let (f, iv) = match &fit {
            LengthFocalFit::Measured(m) => (m.focal_px, m.interval_px),
            LengthFocalFit::NotIdentified(_) | LengthFocalFit::Inconsistent(_) => {
                (f64::NAN, [f64::NAN; 2])
            }
        };
        if std::env::var("VERBOSE").is_ok() {
            // Each length's residual on the fitted camera (the reference one where none fits).
            let on = match &fit {
                LengthFocalFit::Measured(m) => m.camera.clone(),
                LengthFocalFit::NotIdentified(_) | LengthFocalFit::Inconsistent(_) => cal.clone(),
            };
            if let Ok(s) = vpcal::road::fit_scale(&on, &inputs, |i| format!("#{i}")) {
                for (m, r) in inputs.iter().zip(&s.residuals_pct) {
                    eprintln!(
                        "  {:?} {:.1} m px {:.0},{:.0}-{:.0},{:.0} residual {r:+.1} %",
                        m.kind,
                        m.known.distance_m,
                        m.known.p1.x,
                        m.known.p1.y,
                        m.known.p2.x,
                        m.known.p2.y
                    );
                }
            }
        }
        let err = 100.0 * (f / cal.focal_px - 1.0);
        if err.is_finite() {
            errors.push(err);
        }
        println!(
            "{video}\t{}\t{}\t{}\t{ratio:.2}\t{:.0}\t{f:.0}\t{:.0}-{:.0}\t{err:+.1}",
            s["lines"], s["dashed_lines"], s["lanes"], cal.focal_px, iv[0], iv[1]
        );
    }
    errors.sort_by(|a, b| a.abs().total_cmp(&b.abs()));
    println!(
        "measured on {} of {}; median |error| {:.1} %; standard {} m period, {} m lanes (ratio {:.2})",
        errors.len(),
        cameras.len(),
        errors.get(errors.len() / 2).map_or(f64::NAN, |e| e.abs()),
        std.period_m,
        std.lane_width_m,
        std.period_m / std.lane_width_m
    );
}
