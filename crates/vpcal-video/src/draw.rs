//! Drawing for debug pictures and overlays: detection boxes, anti-aliased lines, rings; and
//! the PNG writer they are saved with.

use std::path::Path;

use image::{Rgb, RgbImage};
use imageproc::drawing::draw_hollow_rect_mut;
use imageproc::rect::Rect;
use vpcal_geom::BoxPx;

use crate::error::{Result, VideoError};

/// Green, for kept boxes.
pub const KEPT: Rgb<u8> = Rgb([0, 230, 0]);
/// Red, for dropped boxes.
pub const DROPPED: Rgb<u8> = Rgb([240, 30, 30]);

/// Draws the outline of `b` (frame pixels) on `image`, `thickness` pixels wide, inside the box.
pub fn draw_box(image: &mut RgbImage, b: &BoxPx, color: Rgb<u8>, thickness: u32) {
    let (w, h) = image.dimensions();
    for t in 0..thickness {
        let t = f64::from(t);
        // Why: clamped to the image before the casts.
        let x0 = (b.x0 + t).floor().clamp(0.0, f64::from(w)) as i32;
        let y0 = (b.y0 + t).floor().clamp(0.0, f64::from(h)) as i32;
        let x1 = (b.x1 - t).ceil().clamp(0.0, f64::from(w)) as i32;
        let y1 = (b.y1 - t).ceil().clamp(0.0, f64::from(h)) as i32;
        if x1 - x0 < 1 || y1 - y0 < 1 {
            break;
        }
        // Why: both sides are at least 1 (checked above).
        let rect = Rect::at(x0, y0).of_size((x1 - x0) as u32, (y1 - y0) as u32);
        draw_hollow_rect_mut(image, rect, color);
    }
}

/// A copy of `image` with `boxes` drawn, each with its colour.
pub fn draw_boxes(image: &RgbImage, boxes: &[(BoxPx, Rgb<u8>)]) -> RgbImage {
    let mut out = image.clone();
    let thickness = (image.width() / 480).max(1);
    for (b, c) in boxes {
        draw_box(&mut out, b, *c, thickness);
    }
    out
}

/// Saves `image` as PNG atomically (temporary file, then rename).
///
/// # Errors
/// [`VideoError::Io`] / [`VideoError::Image`] naming the file.
pub fn save_png(image: &RgbImage, path: &Path) -> Result<()> {
    let bytes = vpcal_formats::fs::encode_png(image).map_err(|message| VideoError::Image {
        path: path.to_path_buf(),
        message,
    })?;
    crate::detect::file::write_atomic(path, &bytes)
}

/// Clip segment p-q to the rectangle [0, w] x [0, h] (Liang-Barsky).
fn clip(p: [f64; 2], q: [f64; 2], w: f64, h: f64) -> Option<([f64; 2], [f64; 2])> {
    let (dx, dy) = (q[0] - p[0], q[1] - p[1]);
    let mut t0 = 0.0f64;
    let mut t1 = 1.0f64;
    for (pk, qk) in [(-dx, p[0]), (dx, w - p[0]), (-dy, p[1]), (dy, h - p[1])] {
        if pk == 0.0 {
            if qk < 0.0 {
                return None;
            }
        } else {
            let r = qk / pk;
            if pk < 0.0 {
                t0 = t0.max(r);
            } else {
                t1 = t1.min(r);
            }
        }
    }
    if t0 > t1 {
        return None;
    }
    Some((
        [p[0] + t0 * dx, p[1] + t0 * dy],
        [p[0] + t1 * dx, p[1] + t1 * dy],
    ))
}

/// Anti-aliased line of the given width (pixels), clipped to the image.
pub fn draw_line(img: &mut RgbImage, p: [f64; 2], q: [f64; 2], c: Rgb<u8>, width: f64) {
    let (w, h) = (f64::from(img.width()), f64::from(img.height()));
    if !(p.iter().chain(&q).all(|v| v.is_finite())) {
        return;
    }
    let Some((a, b)) = clip(p, q, w, h) else {
        return;
    };
    let len = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
    let steps = (len * 2.0).ceil().max(1.0) as usize;
    let r = width / 2.0;
    let ri = (r + 1.0).ceil() as i64;
    let mut last: Option<(i64, i64)> = None;
    for k in 0..=steps {
        let t = k as f64 / steps as f64;
        let x = a[0] + (b[0] - a[0]) * t;
        let y = a[1] + (b[1] - a[1]) * t;
        let cell = (x.floor() as i64, y.floor() as i64);
        if last == Some(cell) {
            continue;
        }
        last = Some(cell);
        for dy in -ri..=ri {
            for dx in -ri..=ri {
                let px = cell.0 + dx;
                let py = cell.1 + dy;
                if px < 0 || py < 0 || px >= img.width() as i64 || py >= img.height() as i64 {
                    continue;
                }
                // Distance from the pixel centre to the segment.
                let (cx, cy) = (px as f64 + 0.5, py as f64 + 0.5);
                let d = seg_dist([cx, cy], a, b);
                let cov = (r + 0.5 - d).clamp(0.0, 1.0) as f32;
                if cov <= 0.0 {
                    continue;
                }
                let o = img.get_pixel_mut(px as u32, py as u32);
                for ch in 0..3 {
                    let v = f32::from(o[ch]) * (1.0 - cov) + f32::from(c[ch]) * cov;
                    o[ch] = v.round() as u8;
                }
            }
        }
    }
}

fn seg_dist(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (abx, aby) = (b[0] - a[0], b[1] - a[1]);
    let l2 = abx * abx + aby * aby;
    let t = if l2 > 0.0 {
        (((p[0] - a[0]) * abx + (p[1] - a[1]) * aby) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let (x, y) = (a[0] + t * abx, a[1] + t * aby);
    ((p[0] - x).powi(2) + (p[1] - y).powi(2)).sqrt()
}

/// Small circle (ring) at p.
pub fn draw_ring(img: &mut RgbImage, p: [f64; 2], radius: f64, c: Rgb<u8>) {
    let n = 24;
    for k in 0..n {
        let a0 = std::f64::consts::TAU * k as f64 / n as f64;
        let a1 = std::f64::consts::TAU * (k + 1) as f64 / n as f64;
        draw_line(
            img,
            [p[0] + radius * a0.cos(), p[1] + radius * a0.sin()],
            [p[0] + radius * a1.cos(), p[1] + radius * a1.sin()],
            c,
            1.5,
        );
    }
}
