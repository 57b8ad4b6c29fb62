//! The overlay picture of a calibration: horizon, a road-plane grid aligned with the traffic
//! direction, and the VP directions the network gave for a sample of vehicles.
//!
//! Colours: horizon yellow, road grid cyan, boxes white, directions towards VP1 red and
//! towards VP2 green (the same colours as the synthetic ground-truth pictures), and the paths
//! of the straight vehicle tracks (the aggregator's VP1 evidence when the network's rays
//! scatter) orange.

use image::{Rgb, RgbImage};
use vpcal_geom::aggregate::tracks::TrackLine;
use vpcal_geom::camera::Calibration;
use vpcal_geom::Point2;
use vpcal_video::draw::{draw_line, draw_ring};

use crate::pipeline::VehicleRecord;

const YELLOW: Rgb<u8> = Rgb([255, 220, 0]);
const CYAN: Rgb<u8> = Rgb([0, 220, 255]);
const RED: Rgb<u8> = Rgb([255, 40, 40]);
const GREEN: Rgb<u8> = Rgb([40, 230, 40]);
const WHITE: Rgb<u8> = Rgb([255, 255, 255]);
const ORANGE: Rgb<u8> = Rgb([255, 140, 0]);

/// How many vehicles get their boxes and VP directions drawn.
const SAMPLE_VEHICLES: usize = 16;

fn line_width(img: &RgbImage) -> f64 {
    (f64::from(img.width().max(img.height())) / 640.0).clamp(1.0, 4.0)
}

/// Up to `n` records spread evenly over the run, with finite VPs.
fn sample(records: &[VehicleRecord], n: usize) -> Vec<&VehicleRecord> {
    let ok: Vec<&VehicleRecord> = records
        .iter()
        .filter(|r| r.vp1.is_finite() && r.vp2.is_finite())
        .collect();
    if ok.len() <= n {
        return ok;
    }
    (0..n).map(|i| ok[i * ok.len() / n]).collect()
}

/// A point `len` pixels from `from` towards `to`.
fn towards(from: Point2, to: Point2, len: f64) -> [f64; 2] {
    let d = Point2 {
        x: to.x - from.x,
        y: to.y - from.y,
    };
    let n = d.norm();
    if n < 1e-9 {
        return [from.x, from.y];
    }
    let l = len.min(n);
    [from.x + d.x / n * l, from.y + d.y / n * l]
}

fn draw_vehicles(img: &mut RgbImage, records: &[VehicleRecord]) {
    let w = line_width(img);
    for r in sample(records, SAMPLE_VEHICLES) {
        let b = &r.crop_box;
        let corners = [[b.x0, b.y0], [b.x1, b.y0], [b.x1, b.y1], [b.x0, b.y1]];
        for k in 0..4 {
            draw_line(img, corners[k], corners[(k + 1) % 4], WHITE, w * 0.75);
        }
        let c = b.center();
        let len = 1.5 * b.width().max(b.height());
        draw_line(img, [c.x, c.y], towards(c, r.vp1, len), RED, w);
        draw_line(img, [c.x, c.y], towards(c, r.vp2, len), GREEN, w);
    }
}

/// Boxes and per-vehicle VP directions only (for runs without a calibration).
pub fn draw_records_only(picture: &RgbImage, records: &[VehicleRecord]) -> RgbImage {
    let mut img = picture.clone();
    draw_vehicles(&mut img, records);
    img
}

/// Percentile (0..1) of values; `None` when there are none.
fn percentile(v: &[f64], q: f64) -> Option<f64> {
    Some(vpcal_geom::solve::percentile(v.to_vec(), q * 100.0)).filter(|p| p.is_finite())
}

/// The road grid: lines along the traffic direction (VP1) and across it (VP2) over the area
/// where vehicles were seen (5th-95th percentile of their box bottoms on the road plane).
fn draw_grid(img: &mut RgbImage, cal: &Calibration, records: &[VehicleRecord]) {
    let u1 = [cal.rotation[0][0], cal.rotation[1][0], cal.rotation[2][0]];
    let u2 = [cal.rotation[0][1], cal.rotation[1][1], cal.rotation[2][1]];
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let (mut along, mut across) = (Vec::new(), Vec::new());
    let mut origin = None;
    for r in records {
        let b = &r.crop_box;
        let foot = Point2 {
            x: (b.x0 + b.x1) / 2.0,
            y: b.y1,
        };
        if let Some(x) = cal.project_to_road(foot) {
            origin.get_or_insert(x);
            along.push(dot(x, u1));
            across.push(dot(x, u2));
        }
    }
    // Without vehicles on the road: a grid around the road point below the image centre.
    let (a0, a1, b0, b1, base) = match (
        percentile(&along, 0.05),
        percentile(&along, 0.95),
        percentile(&across, 0.05),
        percentile(&across, 0.95),
        origin,
    ) {
        (Some(a0), Some(a1), Some(b0), Some(b1), Some(o)) if a1 > a0 && b1 > b0 => {
            (a0, a1, b0, b1, o)
        }
        _ => {
            let p = Point2 {
                x: f64::from(img.width()) / 2.0,
                y: f64::from(img.height()) * 0.8,
            };
            let Some(o) = cal.project_to_road(p) else {
                return;
            };
            let (a, b) = (dot(o, u1), dot(o, u2));
            let s = (o[0] * o[0] + o[1] * o[1] + o[2] * o[2]).sqrt() * 0.3;
            (a - s, a + s, b - s, b + s, o)
        }
    };
    // A road point from its (along, across) coordinates: base + (a - a_base) u1 + (b - b_base) u2.
    let (ab, bb) = (dot(base, u1), dot(base, u2));
    let road = |a: f64, b: f64| -> [f64; 3] {
        [
            base[0] + (a - ab) * u1[0] + (b - bb) * u2[0],
            base[1] + (a - ab) * u1[1] + (b - bb) * u2[1],
            base[2] + (a - ab) * u1[2] + (b - bb) * u2[2],
        ]
    };
    let w = line_width(img);
    let segment = |img: &mut RgbImage, p: [f64; 3], q: [f64; 3]| {
        // Short pieces, so that a line partly behind the camera is drawn where it is visible.
        let n = 24;
        let mut prev: Option<Point2> = None;
        for k in 0..=n {
            let t = f64::from(k) / f64::from(n);
            let x = [
                p[0] + (q[0] - p[0]) * t,
                p[1] + (q[1] - p[1]) * t,
                p[2] + (q[2] - p[2]) * t,
            ];
            // Road points on the far side of the camera centre (depth of the other sign than
            // the vehicles' road) are not seen.
            let cur = if x[2] * base[2] > 0.0 {
                cal.image_of_road_point(x)
            } else {
                None
            };
            if let (Some(a), Some(b)) = (prev, cur) {
                draw_line(img, [a.x, a.y], [b.x, b.y], CYAN, w);
            }
            prev = cur;
        }
    };
    let lines = 8;
    for i in 0..=lines {
        let t = f64::from(i) / f64::from(lines);
        let b = b0 + (b1 - b0) * t;
        segment(img, road(a0, b), road(a1, b));
        let a = a0 + (a1 - a0) * t;
        segment(img, road(a, b0), road(a, b1));
    }
}

/// The paths of the straight vehicle tracks, each from its first to its last box centre
/// along the fitted line.
fn draw_tracks(img: &mut RgbImage, tracks: &[TrackLine]) {
    let w = line_width(img);
    for t in tracks {
        let (p, d, h) = (t.point, t.dir, t.travel / 2.0);
        draw_line(
            img,
            [p.x - d.x * h, p.y - d.y * h],
            [p.x + d.x * h, p.y + d.y * h],
            ORANGE,
            w,
        );
    }
}

/// The overlay of a calibration on `picture`, with the straight vehicle tracks the
/// aggregation found.
pub fn draw(
    picture: &RgbImage,
    cal: &Calibration,
    records: &[VehicleRecord],
    tracks: &[TrackLine],
) -> RgbImage {
    let mut img = picture.clone();
    draw_grid(&mut img, cal, records);
    draw_tracks(&mut img, tracks);
    draw_vehicles(&mut img, records);
    let w = line_width(&img);
    let [a, b, c] = cal.horizon.0;
    let width = f64::from(img.width());
    if b.abs() > 1e-12 {
        let y = |x: f64| -(a * x + c) / b;
        draw_line(
            &mut img,
            [-width, y(-width)],
            [2.0 * width, y(2.0 * width)],
            YELLOW,
            w * 1.5,
        );
    }
    for (vp, col) in [(cal.vp1, RED), (cal.vp2, GREEN)] {
        draw_ring(&mut img, [vp.x, vp.y], 6.0 * w, col);
    }
    img
}
