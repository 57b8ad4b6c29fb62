//! Pictures of augmented crops for checking the augmentation by eye.
//!
//! Each cell shows one crop (enlarged) with:
//! - the 3D box edges: along the length (towards VP1) red, across (towards VP2) green,
//!   vertical blue;
//! - the tight 2D box (hull of the warped 3D box, before jitter) yellow;
//! - thin lines from every 3D box corner of a VP1 edge towards VP1 (red) and of a VP2 edge
//!   towards VP2 (green), clipped to the cell: when the geometry is right they continue the box
//!   edges and converge; a VP inside the cell is marked with a ring;
//! - arrows from the centre of the 3D box in the directions of VP1 (red) and VP2 (green);
//! - a white triangle in the top-left corner when the crop was mirrored.

use image::{Rgb, RgbImage};
use vpcal_geom::Point2;

use crate::augment::Augmented;
use crate::{BB3D_EDGES_VERTICAL, BB3D_EDGES_VP1, BB3D_EDGES_VP2};

const RED: Rgb<u8> = Rgb([235, 50, 50]);
const GREEN: Rgb<u8> = Rgb([40, 220, 70]);
const BLUE: Rgb<u8> = Rgb([60, 120, 255]);
const YELLOW: Rgb<u8> = Rgb([250, 220, 40]);
const WHITE: Rgb<u8> = Rgb([255, 255, 255]);
const BACKGROUND: Rgb<u8> = Rgb([24, 24, 24]);

/// Blend `color` into pixel (x, y) with opacity `alpha` (ignored outside the image).
fn plot(img: &mut RgbImage, x: i64, y: i64, color: Rgb<u8>, alpha: f32) {
    if x < 0 || y < 0 || x >= i64::from(img.width()) || y >= i64::from(img.height()) {
        return;
    }
    let p = img.get_pixel_mut(x as u32, y as u32);
    for c in 0..3 {
        let v = f32::from(p.0[c]) * (1.0 - alpha) + f32::from(color.0[c]) * alpha;
        p.0[c] = v.round().clamp(0.0, 255.0) as u8;
    }
}

/// Clip segment a-b to the rectangle [x0, x1] x [y0, y1] (Liang-Barsky).
fn clip(a: Point2, b: Point2, x0: f64, y0: f64, x1: f64, y1: f64) -> Option<(Point2, Point2)> {
    let d = b - a;
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [
        (-d.x, a.x - x0),
        (d.x, x1 - a.x),
        (-d.y, a.y - y0),
        (d.y, y1 - a.y),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let t = q / p;
            if p < 0.0 {
                t0 = t0.max(t);
            } else {
                t1 = t1.min(t);
            }
        }
    }
    (t0 <= t1).then(|| (a + d * t0, a + d * t1))
}

/// Draw a line (clipped to the image) with opacity `alpha`, `width` px wide (1 or more).
pub fn draw_line(img: &mut RgbImage, a: Point2, b: Point2, color: Rgb<u8>, alpha: f32) {
    draw_thick_line(img, a, b, color, alpha, 1);
}

/// [`draw_line`] with a width in pixels.
pub fn draw_thick_line(
    img: &mut RgbImage,
    a: Point2,
    b: Point2,
    color: Rgb<u8>,
    alpha: f32,
    width: u32,
) {
    if !(a.is_finite() && b.is_finite()) {
        return;
    }
    let (w, h) = (f64::from(img.width()), f64::from(img.height()));
    let Some((a, b)) = clip(a, b, 0.0, 0.0, w - 1e-9, h - 1e-9) else {
        return;
    };
    let steps = (b - a).x.abs().max((b - a).y.abs()).ceil().max(1.0) as i64;
    let w = i64::from(width.max(1));
    let mut last = (i64::MIN, i64::MIN);
    for i in 0..=steps {
        let p = a + (b - a) * (i as f64 / steps as f64);
        let (x, y) = (
            p.x.floor() as i64 - (w - 1) / 2,
            p.y.floor() as i64 - (w - 1) / 2,
        );
        if (x, y) == last {
            continue;
        }
        last = (x, y);
        for dy in 0..w {
            for dx in 0..w {
                plot(img, x + dx, y + dy, color, alpha);
            }
        }
    }
}

/// An arrow of length `len` (at most the distance) from `from` pointing at `to`.
fn draw_arrow(img: &mut RgbImage, from: Point2, to: Point2, len: f64, color: Rgb<u8>) {
    let d = to - from;
    let n = d.norm();
    if !n.is_finite() || n < 1e-9 {
        return;
    }
    let u = d / n;
    let tip = from + u * len.min(n);
    draw_thick_line(img, from, tip, color, 1.0, 3);
    let side = Point2::new(-u.y, u.x);
    for s in [1.0, -1.0] {
        draw_thick_line(img, tip, tip - u * 9.0 + side * (5.0 * s), color, 1.0, 3);
    }
}

fn draw_ring(img: &mut RgbImage, c: Point2, r: f64, color: Rgb<u8>) {
    let n = (r * 8.0).ceil().max(8.0) as usize;
    for i in 0..n {
        let t = i as f64 / n as f64 * std::f64::consts::TAU;
        plot(
            img,
            (c.x + r * t.cos()).floor() as i64,
            (c.y + r * t.sin()).floor() as i64,
            color,
            1.0,
        );
    }
}

/// One augmented crop, enlarged `scale` times, with its geometry drawn.
pub fn draw_augmented(a: &Augmented, scale: u32) -> RgbImage {
    let scale = scale.max(1);
    let s = f64::from(scale);
    let img = image::imageops::resize(
        &a.image,
        a.image.width() * scale,
        a.image.height() * scale,
        image::imageops::FilterType::Nearest,
    );
    let mut img = img;
    let out = |p: [f64; 2]| Point2::new(p[0] * s, p[1] * s);
    let size = f64::from(a.image.width());
    // box frame → output pixels: the crop spans [-1, 1]² ↔ [0, size]²
    let vp_px = |v: Point2| Point2::new((v.x + 1.0) * size / 2.0 * s, (v.y + 1.0) * size / 2.0 * s);
    for (vp, edges, color) in [
        (a.vp1_box, BB3D_EDGES_VP1, RED),
        (a.vp2_box, BB3D_EDGES_VP2, GREEN),
    ] {
        let v = vp_px(vp);
        for (i, j) in edges {
            for k in [i, j] {
                draw_line(&mut img, out(a.bb3d[k]), v, color, 0.35);
            }
        }
        if v.is_finite()
            && v.x >= 0.0
            && v.y >= 0.0
            && v.x < f64::from(img.width())
            && v.y < f64::from(img.height())
        {
            draw_ring(&mut img, v, 5.0, color);
        }
    }
    let h = a.hull;
    let corners = [
        Point2::new(h.x0 * s, h.y0 * s),
        Point2::new(h.x1 * s, h.y0 * s),
        Point2::new(h.x1 * s, h.y1 * s),
        Point2::new(h.x0 * s, h.y1 * s),
    ];
    for k in 0..4 {
        draw_line(&mut img, corners[k], corners[(k + 1) % 4], YELLOW, 1.0);
    }
    for (edges, color) in [
        (BB3D_EDGES_VP1, RED),
        (BB3D_EDGES_VP2, GREEN),
        (BB3D_EDGES_VERTICAL, BLUE),
    ] {
        for (i, j) in edges {
            draw_thick_line(&mut img, out(a.bb3d[i]), out(a.bb3d[j]), color, 1.0, 2);
        }
    }
    let centre = a
        .bb3d
        .iter()
        .fold(Point2::new(0.0, 0.0), |acc, p| acc + out(*p))
        / 8.0;
    let arrow = f64::from(img.width()) * 0.3;
    draw_arrow(&mut img, centre, vp_px(a.vp1_box), arrow, RED);
    draw_arrow(&mut img, centre, vp_px(a.vp2_box), arrow, GREEN);
    if a.flipped {
        for y in 0..8i64 {
            for x in 0..(8 - y) {
                plot(&mut img, x, y, WHITE, 1.0);
            }
        }
    }
    img
}

/// A grid of [`draw_augmented`] cells, `columns` wide (0: about square).
pub fn contact_sheet(items: &[Augmented], columns: usize, scale: u32) -> RgbImage {
    let cells: Vec<RgbImage> = items.iter().map(|a| draw_augmented(a, scale)).collect();
    let columns = if columns == 0 {
        (cells.len() as f64).sqrt().ceil().max(1.0) as usize
    } else {
        columns
    };
    let rows = cells.len().div_ceil(columns).max(1);
    let cw = cells.iter().map(|c| c.width()).max().unwrap_or(1);
    let ch = cells.iter().map(|c| c.height()).max().unwrap_or(1);
    let gap = 4u32;
    let mut sheet = RgbImage::from_pixel(
        columns as u32 * (cw + gap) + gap,
        rows as u32 * (ch + gap) + gap,
        BACKGROUND,
    );
    for (k, cell) in cells.iter().enumerate() {
        let (col, row) = ((k % columns) as u32, (k / columns) as u32);
        image::imageops::replace(
            &mut sheet,
            cell,
            i64::from(gap + col * (cw + gap)),
            i64::from(gap + row * (ch + gap)),
        );
    }
    sheet
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clipping_keeps_the_part_inside() {
        let (a, b) = clip(
            Point2::new(-10.0, 5.0),
            Point2::new(1e9, 5.0),
            0.0,
            0.0,
            100.0,
            100.0,
        )
        .unwrap_or((Point2::new(0.0, 0.0), Point2::new(0.0, 0.0)));
        assert!(
            (a.x - 0.0).abs() < 1e-9 && (b.x - 100.0).abs() < 1e-6,
            "{a:?} {b:?}"
        );
        assert!(clip(
            Point2::new(-10.0, -5.0),
            Point2::new(-1.0, 500.0),
            0.0,
            0.0,
            100.0,
            100.0
        )
        .is_none());
    }
}
