//! Pictures to check the ground truth by eye: a contact sheet of crops with their 3D boxes and
//! VP directions, and a frame with the true horizon, VPs and boxes.
//!
//! Colours: VP1 (heading) red, VP2 (sideways) green, vertical edges blue, horizon yellow.

use image::{Rgb, RgbImage};

use crate::camera::Camera;
use crate::truth::VehicleTruth;
pub use vpcal_video::draw::{draw_line, draw_ring};

pub const RED: Rgb<u8> = Rgb([255, 40, 40]);
pub const GREEN: Rgb<u8> = Rgb([40, 230, 60]);
pub const BLUE: Rgb<u8> = Rgb([60, 140, 255]);
pub const YELLOW: Rgb<u8> = Rgb([255, 220, 0]);

/// Box edges along VP1, VP2 and vertical, for the crate's corner order.
pub const EDGES_VP1: [(usize, usize); 4] = [(0, 3), (1, 2), (4, 7), (5, 6)];
pub const EDGES_VP2: [(usize, usize); 4] = [(0, 1), (3, 2), (4, 5), (7, 6)];
pub const EDGES_VERT: [(usize, usize); 4] = [(0, 4), (1, 5), (2, 6), (3, 7)];

/// Draw a 3D box, the rays from its VP1/VP2 edges towards the VPs, and VP markers.
pub fn draw_truth(
    img: &mut RgbImage,
    bb3d: &[[f64; 2]; 8],
    vp1: Option<[f64; 2]>,
    vp2: Option<[f64; 2]>,
    width: f64,
) {
    // Rays from the box's far corners to the VPs: they must run along the box edges.
    for (vp, edges, col) in [(vp1, EDGES_VP1, RED), (vp2, EDGES_VP2, GREEN)] {
        let Some(vp) = vp else { continue };
        let faint = Rgb([col[0] / 2 + 60, col[1] / 2 + 60, col[2] / 2 + 60]);
        for (a, b) in edges {
            // From the corner farther from the VP, through the nearer, to the VP.
            let da = (bb3d[a][0] - vp[0]).hypot(bb3d[a][1] - vp[1]);
            let db = (bb3d[b][0] - vp[0]).hypot(bb3d[b][1] - vp[1]);
            let near = if da < db { bb3d[a] } else { bb3d[b] };
            draw_line(img, near, vp, faint, width * 0.5);
        }
    }
    for (edges, col) in [(EDGES_VP1, RED), (EDGES_VP2, GREEN), (EDGES_VERT, BLUE)] {
        for (a, b) in edges {
            draw_line(img, bb3d[a], bb3d[b], col, width);
        }
    }
    for (vp, col) in [(vp1, RED), (vp2, GREEN)] {
        if let Some(v) = vp {
            draw_ring(img, v, 5.0 * width, col);
        }
    }
}

/// A frame with the true horizon, every vehicle's 3D box and VP rays.
pub fn overlay_frame(frame: &RgbImage, cam: &Camera, vehicles: &[VehicleTruth]) -> RgbImage {
    let mut img = frame.clone();
    let (w, h) = (f64::from(img.width()), f64::from(img.height()));
    let hz = cam.horizon();
    // Horizon: a x + b y + c = 0, drawn across a wide range (it may lie above the image).
    if hz[1].abs() > 1e-9 {
        let y = |x: f64| -(hz[0] * x + hz[2]) / hz[1];
        draw_line(
            &mut img,
            [-10.0 * w, y(-10.0 * w)],
            [11.0 * w, y(11.0 * w)],
            YELLOW,
            3.0,
        );
    } else if hz[0].abs() > 1e-9 {
        let x = -hz[2] / hz[0];
        draw_line(&mut img, [x, -h], [x, 2.0 * h], YELLOW, 3.0);
    }
    let lw = (w / 900.0).max(1.0);
    for v in vehicles.iter().filter(|v| v.visible_fraction > 0.2) {
        draw_truth(&mut img, &v.bb3d, v.vp1, v.vp2, lw);
    }
    img
}

/// A contact sheet: crops (with their truth drawn when `draw`) in a grid of `cell` x `cell` tiles.
pub fn contact_sheet(
    samples: &[vpcal_data::Sample],
    cols: usize,
    cell: u32,
    draw: bool,
) -> RgbImage {
    let cols = cols.max(1);
    let rows = samples.len().div_ceil(cols).max(1);
    let mut sheet = RgbImage::from_pixel(cols as u32 * cell, rows as u32 * cell, Rgb([30, 30, 30]));
    for (k, s) in samples.iter().enumerate() {
        let (cw, ch) = (s.image.width().max(1), s.image.height().max(1));
        let sc = (f64::from(cell - 4) / f64::from(cw)).min(f64::from(cell - 4) / f64::from(ch));
        let (nw, nh) = (
            ((f64::from(cw) * sc).round() as u32).max(1),
            ((f64::from(ch) * sc).round() as u32).max(1),
        );
        let mut tile =
            image::imageops::resize(&s.image, nw, nh, image::imageops::FilterType::Triangle);
        let m = |p: [f64; 2]| [p[0] * sc, p[1] * sc];
        let bb = s.bb3d.map(m);
        // Draw in a padded canvas so VP rays show their direction beyond the crop.
        if draw {
            draw_truth(&mut tile, &bb, Some(m(s.vp1)), Some(m(s.vp2)), 1.2);
        }
        let x = (k % cols) as u32 * cell + (cell - nw) / 2;
        let y = (k / cols) as u32 * cell + (cell - nh) / 2;
        image::imageops::replace(&mut sheet, &tile, i64::from(x), i64::from(y));
    }
    sheet
}
