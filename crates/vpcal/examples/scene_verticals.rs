//! The scene's vertical lines of one picture, given its VP1 and horizon: `cargo run
//! --release --example scene_verticals -- IMAGE VP1X VP1Y ROLL_DEG [SEGMENTS_JSON]` prints a
//! JSON object with the line segments' count and the verticals' fit (`vpcal_geom::aggregate::verticals`),
//! the principal point at the picture's middle and the search over the focal prior's
//! support. `scripts/scene_verticals_focal.py` runs it on the BrnoCompSpeed views and the
//! synthetic suite against their true cameras. SEGMENTS_JSON, if given, receives every line
//! segment's ends `[ax, ay, bx, by]` (to draw them).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use vpcal_geom::aggregate::focal::{focal_prior_range_widths, support};
use vpcal_geom::aggregate::verticals::{fit, VerticalOptions};
use vpcal_geom::Point2;
use vpcal_video::segments::{line_segments, SegmentOptions};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    assert!(
        args.len() == 5 || args.len() == 6,
        "usage: scene_verticals IMAGE VP1X VP1Y ROLL_DEG [SEGMENTS_JSON]"
    );
    let number = |i: usize| args[i].parse::<f64>().expect("a number");
    let image =
        vpcal_video::edges::grey_opencv(&image::open(&args[1]).expect("reading IMAGE").to_rgb8());
    let segments = line_segments(&image, &SegmentOptions::default());
    let (w, h) = (f64::from(image.width()), f64::from(image.height()));
    let pp = Point2::new(w / 2.0, h / 2.0);
    let range = support(focal_prior_range_widths(None).map(|r| r * w));
    let vp1 = Point2::new(number(2), number(3));
    let f = fit(
        &segments,
        vp1,
        pp,
        number(4).to_radians(),
        0.0,
        range,
        &VerticalOptions::default(),
        0,
    );
    let out = serde_json::json!({
        "segments": segments.len(),
        "fit": f.map(|f| serde_json::json!({
            "focal_px": f.focal_px,
            "roll_deg": f.roll.to_degrees(),
            "candidates": f.candidates,
            "supporting": f.supporting,
            "bootstrap_px": f.bootstrap_px,
            "identified": f.identified,
            "own_roll_deg": f.own_roll.map(f64::to_degrees),
            "own_roll_sd_deg": Some(f.own_roll_sd.to_degrees()).filter(|s| s.is_finite()),
        })),
    });
    println!("{out}");
    if let Some(path) = args.get(5) {
        let ends: Vec<[f64; 4]> = segments
            .iter()
            .map(|s| [s.a.x, s.a.y, s.b.x, s.b.y])
            .collect();
        std::fs::write(path, serde_json::to_string(&ends).unwrap()).expect("writing SEGMENTS_JSON");
    }
}
