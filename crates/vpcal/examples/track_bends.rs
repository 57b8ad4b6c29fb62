//! The vehicle tracks of a vehicles file and how each bends (the road-shape evidence).
//!
//! `cargo run --release -p vpcal --example track_bends -- VEHICLES.json [WIDTHxHEIGHT]` prints
//! (with `TRACK_POINTS=1` also each box's centre, width and height) one line per
//! track of at least the tracker's minimum length: boxes, travel, mean centre, direction, RMS
//! off its line, and the bend (t-statistic, degrees, standard error) the curved-road test reads.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use vpcal_formats::reference::read_vpout;
use vpcal_geom::aggregate::robust::RobustOptions;
use vpcal_geom::aggregate::tracks::{self, TrackOptions};
use vpcal_geom::BoxPx;

fn main() {
    let path = std::env::args()
        .nth(1)
        .expect("usage: track_bends VEHICLES.json");
    let items = read_vpout(std::path::Path::new(&path)).expect("read vehicles");
    let opts = RobustOptions::default();
    let boxes: Vec<(f64, BoxPx)> = items
        .iter()
        .map(|i| i.to_vehicle())
        .filter(|v| v.score > opts.min_score)
        .filter_map(|v| Some((v.frame?, v.box_px.filter(BoxPx::is_valid)?)))
        .collect();
    let frame = std::env::args().nth(2).map(|s| {
        let (w, h) = s.split_once('x').expect("WIDTHxHEIGHT");
        [w.parse().expect("width"), h.parse().expect("height")]
    });
    let t = opts.tracks.clone().unwrap_or_default();
    let any = TrackOptions {
        max_rms_fraction: f64::INFINITY,
        frame,
        ..t.clone()
    };
    println!("boxes\ttravel\tx\ty\tdir_deg\trms\tstraight\tbend_t\tbend_deg\tbend_se");
    for l in tracks::link(&boxes, &t) {
        if let Some(f) = tracks::fit_line(&boxes, &l, &any) {
            println!(
                "{}\t{:.0}\t{:.0}\t{:.0}\t{:.1}\t{:.2}\t{}\t{:.1}\t{:.2}\t{:.2}",
                f.boxes,
                f.travel,
                f.point.x,
                f.point.y,
                f.dir.y.atan2(f.dir.x).to_degrees(),
                f.rms,
                f.is_straight(&t),
                f.bend_t,
                f.bend_deg,
                f.bend_se_deg
            );
            if std::env::var_os("TRACK_POINTS").is_some() {
                let pts: Vec<String> = l
                    .iter()
                    .map(|&i| {
                        let b = boxes[i].1;
                        let c = b.center();
                        format!("{:.1},{:.1},{:.1},{:.1}", c.x, c.y, b.width(), b.height())
                    })
                    .collect();
                println!("#\t{}", pts.join(" "));
            }
        }
    }
}
