//! Vehicle crops for the network.
//!
//! A detection's continuous box becomes the reference's integer box (deep_vp
//! `eval/extract_vp_utils.py`): `x_min = floor(x0)`, `x_max = floor(x1 + 1)` (likewise y),
//! clamped to the frame, covering pixels `x_min..x_max` (end exclusive). The box frame of the
//! network's output is that integer box: centre `((x_min + x_max)/2, (y_min + y_max)/2)`, half
//! sizes `((x_max − x_min)/2, (y_max − y_min)/2)` — exactly what the reference used, except that
//! we clamp to the frame first (the reference cropped the clamped region but kept the unclamped
//! box, so for boxes over the border its box frame did not match its crop).
//!
//! The crop is resized to the network input (square, 128 by default) and written as planar
//! RGB `f32` in [0, 1], the per-crop layout of `vpcal_data::Batch::images`
//! (`[3, size, size]`, row-major).
//!
//! Resampling ([`CropFilter`]): the default is OpenCV's `INTER_CUBIC` (Keys cubic,
//! a = −0.75, fixed 4×4 support, no antialiasing), the filter `vpcal-data` trains with
//! (`Resample::Bicubic`). The reference *meant* `INTER_CUBIC` but passed it as `cv2.resize`'s
//! third positional argument, which is `dst`, so it actually resized with the default
//! `INTER_LINEAR`; that one is available too, and an antialiased Catmull-Rom convolution.
//! Use the filter the network was trained with.

use fast_image_resize as fir;
use image::RgbImage;
use vpcal_geom::BoxPx;

use crate::error::{Result, VideoError};

/// The network input size of the paper.
pub const DEFAULT_INPUT_SIZE: u32 = 128;

/// An integer pixel box, half-open: pixels `x0..x1` × `y0..y1`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct IntBox {
    pub x0: u32,
    pub y0: u32,
    pub x1: u32,
    pub y1: u32,
}

impl IntBox {
    pub fn width(&self) -> u32 {
        self.x1 - self.x0
    }

    pub fn height(&self) -> u32 {
        self.y1 - self.y0
    }

    pub fn area(&self) -> u64 {
        u64::from(self.width()) * u64::from(self.height())
    }

    /// The same box as continuous coordinates: the box whose box frame the crop has.
    pub fn to_box_px(&self) -> BoxPx {
        BoxPx::new(
            f64::from(self.x0),
            f64::from(self.y0),
            f64::from(self.x1),
            f64::from(self.y1),
        )
    }
}

/// The reference's integer box of `b` in a `width` × `height` frame (see the module docs), or
/// `None` when it is empty after clamping or not finite.
pub fn integer_box(b: &BoxPx, width: u32, height: u32) -> Option<IntBox> {
    let vals = [b.x0, b.y0, b.x1, b.y1];
    if vals.iter().any(|v| !v.is_finite()) {
        return None;
    }
    // Why: clamped to [0, size] before the cast.
    let clamp = |v: f64, max: u32| v.floor().clamp(0.0, f64::from(max)) as u32;
    let ib = IntBox {
        x0: clamp(b.x0, width),
        y0: clamp(b.y0, height),
        x1: clamp(b.x1 + 1.0, width),
        y1: clamp(b.y1 + 1.0, height),
    };
    (ib.x1 > ib.x0 && ib.y1 > ib.y0).then_some(ib)
}

/// The box the network's crop is cut at for the detection `b`: `b` itself where its larger
/// side is at least `min_side` pixels (or `min_side` is 0), else `b` scaled about its centre
/// until that side is `min_side`, so a small vehicle's crop also holds the road around it,
/// whose lane lines and neighbours point at VP1 as the vehicle's few pixels cannot
/// (models/default/MODEL.md, "Context does fix it"). The VPs are decoded in this box's frame;
/// [`integer_box`] clamps it to the picture when it is cut.
pub fn context_box(b: &BoxPx, min_side: f64) -> BoxPx {
    let side = b.width().max(b.height());
    if !(side > 0.0 && side.is_finite() && min_side > side) {
        return *b;
    }
    let (c, half) = (b.center(), b.half_size() * (min_side / side));
    BoxPx::new(c.x - half.x, c.y - half.y, c.x + half.x, c.y + half.y)
}

/// Resampling filter for crops (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum CropFilter {
    /// Catmull-Rom bicubic convolution, antialiased when shrinking.
    Bicubic,
    /// OpenCV `INTER_CUBIC`: Keys cubic with a = −0.75, a fixed 4×4 support (no antialiasing).
    #[default]
    OpenCvCubic,
    /// OpenCV `INTER_LINEAR`: bilinear with a fixed 2×2 support (what the reference ran).
    OpenCvLinear,
}

/// OpenCV's cubic kernel (Keys, a = −0.75).
fn keys_cubic(x: f64) -> f64 {
    const A: f64 = -0.75;
    let x = x.abs();
    if x <= 1.0 {
        ((A + 2.0) * x - (A + 3.0)) * x * x + 1.0
    } else if x < 2.0 {
        ((A * x - 5.0 * A) * x + 8.0 * A) * x - 4.0 * A
    } else {
        0.0
    }
}

impl CropFilter {
    fn resize_alg(self) -> Result<fir::ResizeAlg> {
        Ok(match self {
            CropFilter::Bicubic => fir::ResizeAlg::Convolution(fir::FilterType::CatmullRom),
            CropFilter::OpenCvLinear => fir::ResizeAlg::Interpolation(fir::FilterType::Bilinear),
            CropFilter::OpenCvCubic => {
                let f = fir::Filter::new("OpenCV cubic", keys_cubic, 2.0).map_err(|e| {
                    VideoError::InvalidOption {
                        name: "crop filter",
                        value: format!("{e:?}"),
                        expected: "a valid filter",
                    }
                })?;
                fir::ResizeAlg::Interpolation(fir::FilterType::Custom(f))
            }
        })
    }
}

/// Crops boxes out of frames and resizes them to the network input; reuses its buffers.
#[derive(Debug)]
pub struct CropResizer {
    size: u32,
    filter: CropFilter,
    alg: fir::ResizeAlg,
    resizer: fir::Resizer,
    src: Vec<u8>,
    dst: Vec<u8>,
}

impl CropResizer {
    /// A resizer to `size` × `size` crops.
    ///
    /// # Errors
    /// [`VideoError::InvalidOption`] for a zero size.
    pub fn new(size: u32, filter: CropFilter) -> Result<CropResizer> {
        if size == 0 {
            return Err(VideoError::InvalidOption {
                name: "input size",
                value: "0".into(),
                expected: "a positive number of pixels",
            });
        }
        Ok(CropResizer {
            size,
            filter,
            alg: filter.resize_alg()?,
            resizer: fir::Resizer::new(),
            src: Vec::new(),
            dst: vec![0; 3 * size as usize * size as usize],
        })
    }

    /// The crop side in pixels.
    pub fn size(&self) -> u32 {
        self.size
    }

    pub fn filter(&self) -> CropFilter {
        self.filter
    }

    /// Number of `f32` values one crop takes: `3 × size × size`.
    pub fn crop_len(&self) -> usize {
        3 * self.size as usize * self.size as usize
    }

    /// Resizes the integer box `ib` of `image` into `self.dst` (interleaved RGB).
    fn resize_box(&mut self, image: &RgbImage, ib: IntBox) -> Result<()> {
        let (w, h) = (ib.width(), ib.height());
        // Copy the crop so that resampling sees only its pixels (as numpy slicing did).
        self.src.clear();
        self.src.reserve(3 * w as usize * h as usize);
        let raw = image.as_raw();
        let stride = 3 * image.width() as usize;
        for y in ib.y0..ib.y1 {
            let start = y as usize * stride + 3 * ib.x0 as usize;
            self.src
                .extend_from_slice(&raw[start..start + 3 * w as usize]);
        }
        let err = |e: &dyn std::fmt::Display| VideoError::Image {
            path: std::path::PathBuf::from("crop"),
            message: format!("cannot resize a {w}x{h} crop ({e})"),
        };
        let src = fir::images::ImageRef::new(w, h, &self.src, fir::PixelType::U8x3)
            .map_err(|e| err(&e))?;
        let mut dst = fir::images::Image::from_slice_u8(
            self.size,
            self.size,
            &mut self.dst,
            fir::PixelType::U8x3,
        )
        .map_err(|e| err(&e))?;
        let opts = fir::ResizeOptions::new().resize_alg(self.alg);
        self.resizer
            .resize(&src, &mut dst, &opts)
            .map_err(|e| err(&e))
    }

    /// Crops `bbox` from `image`, resizes it and writes it to `out` as planar RGB in [0, 1]
    /// (`[3, size, size]`). Returns the box whose box frame the crop has (the clamped integer
    /// box), or `None`, leaving `out` untouched, when the box misses the frame.
    ///
    /// # Errors
    /// [`VideoError::InvalidOption`] when `out` is not [`CropResizer::crop_len`] long.
    pub fn crop_into(
        &mut self,
        image: &RgbImage,
        bbox: &BoxPx,
        out: &mut [f32],
    ) -> Result<Option<BoxPx>> {
        if out.len() != self.crop_len() {
            return Err(VideoError::InvalidOption {
                name: "crop output length",
                value: out.len().to_string(),
                expected: "3 × size × size values",
            });
        }
        let Some(ib) = integer_box(bbox, image.width(), image.height()) else {
            return Ok(None);
        };
        self.resize_box(image, ib)?;
        let plane = self.size as usize * self.size as usize;
        let (r, rest) = out.split_at_mut(plane);
        let (g, b) = rest.split_at_mut(plane);
        for (i, px) in self.dst.chunks_exact(3).enumerate() {
            r[i] = f32::from(px[0]) / 255.0;
            g[i] = f32::from(px[1]) / 255.0;
            b[i] = f32::from(px[2]) / 255.0;
        }
        Ok(Some(ib.to_box_px()))
    }

    /// Like [`CropResizer::crop_into`] but returns the resized crop as an image (for
    /// pictures and debugging).
    ///
    /// # Errors
    /// As [`CropResizer::crop_into`].
    pub fn crop_image(
        &mut self,
        image: &RgbImage,
        bbox: &BoxPx,
    ) -> Result<Option<(RgbImage, BoxPx)>> {
        let Some(ib) = integer_box(bbox, image.width(), image.height()) else {
            return Ok(None);
        };
        self.resize_box(image, ib)?;
        let img = RgbImage::from_raw(self.size, self.size, self.dst.clone()).ok_or(
            VideoError::InvalidOption {
                name: "crop",
                value: String::new(),
                expected: "a consistent buffer",
            },
        )?;
        Ok(Some((img, ib.to_box_px())))
    }

    /// Crops every box of one frame into a new batch buffer (`[n, 3, size, size]`); boxes that
    /// miss the frame are skipped. Returns the buffer, the box of each crop and the index in
    /// `boxes` each crop came from.
    ///
    /// # Errors
    /// As [`CropResizer::crop_into`].
    pub fn crop_batch(&mut self, image: &RgbImage, boxes: &[BoxPx]) -> Result<CropBatch> {
        let len = self.crop_len();
        let mut batch = CropBatch {
            size: self.size,
            images: vec![0.0; len * boxes.len()],
            boxes: Vec::with_capacity(boxes.len()),
            source: Vec::with_capacity(boxes.len()),
        };
        for (i, b) in boxes.iter().enumerate() {
            let n = batch.boxes.len();
            let out = &mut batch.images[n * len..(n + 1) * len];
            if let Some(bp) = self.crop_into(image, b, out)? {
                batch.boxes.push(bp);
                batch.source.push(i);
            }
        }
        batch.images.truncate(batch.boxes.len() * len);
        Ok(batch)
    }
}

/// Crops of one frame, ready for the network.
#[derive(Debug, Clone)]
pub struct CropBatch {
    /// Crop side in pixels.
    pub size: u32,
    /// `[n, 3, size, size]`, RGB in [0, 1].
    pub images: Vec<f32>,
    /// The box frame of each crop (clamped integer box, frame pixels).
    pub boxes: Vec<BoxPx>,
    /// For each crop, its index in the boxes given.
    pub source: Vec<usize>,
}

impl CropBatch {
    pub fn len(&self) -> usize {
        self.boxes.len()
    }

    pub fn is_empty(&self) -> bool {
        self.boxes.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_boxes_get_context_about_their_centre_and_large_ones_are_cut_as_they_are() {
        let small = BoxPx::new(100.0, 50.0, 120.0, 60.0); // 20 x 10
        let c = context_box(&small, 64.0);
        assert!((c.center().x - 110.0).abs() < 1e-9 && (c.center().y - 55.0).abs() < 1e-9);
        assert!((c.x1 - c.x0 - 64.0).abs() < 1e-9, "{c:?}");
        assert!(
            (c.y1 - c.y0 - 32.0).abs() < 1e-9,
            "the aspect is kept: {c:?}"
        );
        let tall = BoxPx::new(0.0, 0.0, 10.0, 40.0);
        let t = context_box(&tall, 64.0);
        assert!((t.y1 - t.y0 - 64.0).abs() < 1e-9 && (t.x1 - t.x0 - 16.0).abs() < 1e-9);
        let large = BoxPx::new(0.0, 0.0, 100.0, 30.0);
        assert_eq!(context_box(&large, 64.0), large);
        assert_eq!(context_box(&small, 0.0), small);
        let empty = BoxPx::new(5.0, 5.0, 5.0, 5.0);
        assert_eq!(context_box(&empty, 64.0), empty);
    }

    #[test]
    fn integer_box_follows_the_reference() {
        // Normalised reference box -> continuous box -> reference integers.
        let (w, h) = (1920u32, 1080u32);
        let b = [
            0.4385480284690857,
            0.21754090487957,
            0.5421082973480225,
            0.27849507331848145,
        ];
        let cont = BoxPx::new(b[1] * 1920.0, b[0] * 1080.0, b[3] * 1920.0, b[2] * 1080.0);
        let ib = integer_box(&cont, w, h).unwrap();
        let x_min = (1920.0 * b[1]) as u32;
        let x_max = (1920.0 * b[3] + 1.0) as u32;
        let y_min = (1080.0 * b[0]) as u32;
        let y_max = (1080.0 * b[2] + 1.0) as u32;
        assert_eq!(
            ib,
            IntBox {
                x0: x_min,
                y0: y_min,
                x1: x_max,
                y1: y_max
            }
        );
    }

    #[test]
    fn integer_box_clamps_and_rejects_empty() {
        let ib = integer_box(&BoxPx::new(-5.0, -1.0, 10.0, 2.0), 8, 8).unwrap();
        assert_eq!(
            ib,
            IntBox {
                x0: 0,
                y0: 0,
                x1: 8,
                y1: 3
            }
        );
        assert!(integer_box(&BoxPx::new(10.0, 0.0, 20.0, 5.0), 8, 8).is_none());
        assert!(integer_box(&BoxPx::new(f64::NAN, 0.0, 2.0, 5.0), 8, 8).is_none());
    }

    #[test]
    fn keys_cubic_is_interpolating() {
        assert!((keys_cubic(0.0) - 1.0).abs() < 1e-12);
        assert!(keys_cubic(1.0).abs() < 1e-12);
        assert!(keys_cubic(2.0).abs() < 1e-12);
        // The weights of a half-pixel shift sum to 1.
        let s: f64 = [-1.5, -0.5, 0.5, 1.5].iter().map(|&x| keys_cubic(x)).sum();
        assert!((s - 1.0).abs() < 1e-12);
    }
}
