//! VP1 from the lines of one picture of a scene, from a start point: what the calibration does
//! with the median of a video's frames (`vpcal_geom::aggregate::scene_lines`), on a picture.
//!
//! `cargo run --release --example scene_vp1 -- IMAGE X,Y [MASK]` prints one JSON object:
//! `{"vp1": [x, y] or null, "edgelets": N used, "scene_edgelets": N found}`. MASK (optional):
//! a picture of the same size whose black pixels are left out (BrnoCompSpeed's
//! `video_mask.png`). `scripts/bcs_scene_vp1.py` runs it on the BrnoCompSpeed views.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use vpcal_geom::aggregate::scene_lines::{refine_vp1, SceneLineOptions};
use vpcal_geom::Point2;
use vpcal_video::background::{keep_inside, scene_edgelet_options, scene_edgelets};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    assert!(args.len() >= 3, "usage: scene_vp1 IMAGE X,Y [MASK]");
    let image = image::open(&args[1]).expect("reading IMAGE").to_luma8();
    let xy: Vec<f64> = args[2]
        .split(',')
        .map(|v| v.parse().expect("X,Y"))
        .collect();
    let start = Point2::new(xy[0], xy[1]);
    let mut edgelets = scene_edgelets(&image, &scene_edgelet_options());
    if let Some(mask) = args.get(3) {
        let mask = image::open(mask).expect("reading MASK").to_luma8();
        assert_eq!(mask.dimensions(), image.dimensions(), "MASK size");
        keep_inside(&mut edgelets, &mask);
    }
    let fit = refine_vp1(start, &edgelets, &SceneLineOptions::default());
    println!(
        "{}",
        serde_json::json!({
            "vp1": fit.map(|f| [f.vp1.x, f.vp1.y]),
            "edgelets": fit.map_or(0, |f| f.edgelets),
            "scene_edgelets": edgelets.len(),
        })
    );
}
