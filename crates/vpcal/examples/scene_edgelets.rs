//! The edgelets of one picture of a scene, as the calibration finds them in the median of a
//! video's frames (`vpcal_video::background`): `cargo run --release --example scene_edgelets
//! -- IMAGE [MASK]` prints a JSON array of `[x, y, angle, strength]` (pixels, radians of the
//! edge's direction). MASK (optional): a picture of the same size whose black pixels are left
//! out. `scripts/scene_verticals_focal.py` reads it on the BrnoCompSpeed views.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use vpcal_video::background::{keep_inside, scene_edgelet_options, scene_edgelets};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    assert!(args.len() >= 2, "usage: scene_edgelets IMAGE [MASK]");
    let image = image::open(&args[1]).expect("reading IMAGE").to_luma8();
    let mut edgelets = scene_edgelets(&image, &scene_edgelet_options());
    if let Some(mask) = args.get(2) {
        let mask = image::open(mask).expect("reading MASK").to_luma8();
        assert_eq!(mask.dimensions(), image.dimensions(), "MASK size");
        keep_inside(&mut edgelets, &mask);
    }
    let rows: Vec<[f64; 4]> = edgelets
        .iter()
        .map(|e| [e.x, e.y, e.angle, e.strength])
        .collect();
    println!("{}", serde_json::to_string(&rows).expect("JSON"));
}
