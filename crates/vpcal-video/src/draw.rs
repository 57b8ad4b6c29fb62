//! Debug pictures: frames with detection boxes drawn on them.

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
    let mut bytes = Vec::new();
    image::DynamicImage::ImageRgb8(image.clone())
        .write_to(
            &mut std::io::Cursor::new(&mut bytes),
            image::ImageFormat::Png,
        )
        .map_err(|e| VideoError::Image {
            path: path.to_path_buf(),
            message: format!("cannot encode PNG ({e})"),
        })?;
    crate::detect::file::write_atomic(path, &bytes)
}
