//! Camera artefacts applied after rendering: blur (optics, motion), sensor noise, JPEG.

use image::RgbImage;
use rand::Rng;

use crate::math::RngExt;

/// Sensor and compression settings for one image.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Effects {
    /// Gaussian blur sigma in pixels (0 = none).
    pub blur_sigma: f64,
    /// Motion blur: length in pixels and direction (radians) (0 = none).
    pub motion_px: f64,
    pub motion_dir: f64,
    /// Gaussian noise sigma in 8-bit levels (luminance) and chroma fraction.
    pub noise_sigma: f64,
    pub chroma_noise: f64,
    /// Contrast and gamma adjustment (1 = none).
    pub contrast: f64,
    pub gamma: f64,
    /// JPEG quality 1..100.
    pub jpeg_quality: u8,
}

impl Effects {
    /// Random artefacts typical of traffic-camera footage.
    pub fn random<R: Rng>(rng: &mut R) -> Effects {
        Effects {
            blur_sigma: if rng.chance(0.7) {
                rng.uni(0.2, 1.1)
            } else {
                0.0
            },
            motion_px: if rng.chance(0.25) {
                rng.uni(1.0, 3.5)
            } else {
                0.0
            },
            motion_dir: rng.uni(0.0, std::f64::consts::PI),
            noise_sigma: rng.uni(0.5, 5.0),
            chroma_noise: rng.uni(0.1, 0.5),
            contrast: rng.uni(0.85, 1.15),
            gamma: rng.uni(0.85, 1.15),
            jpeg_quality: rng.int(35, 95) as u8,
        }
    }

    /// No artefacts, lossless-looking JPEG.
    pub fn none() -> Effects {
        Effects {
            blur_sigma: 0.0,
            motion_px: 0.0,
            motion_dir: 0.0,
            noise_sigma: 0.0,
            chroma_noise: 0.0,
            contrast: 1.0,
            gamma: 1.0,
            jpeg_quality: 95,
        }
    }
}

/// Apply blur, tone and noise in place (JPEG is separate: see [`encode_jpeg`]).
pub fn apply<R: Rng>(img: &mut RgbImage, fx: &Effects, rng: &mut R) {
    let (w, h) = (img.width() as usize, img.height() as usize);
    if w == 0 || h == 0 {
        return;
    }
    let mut buf: Vec<f32> = img.as_raw().iter().map(|&v| f32::from(v)).collect();
    if fx.blur_sigma > 0.05 {
        gaussian_blur(&mut buf, w, h, fx.blur_sigma as f32);
    }
    if fx.motion_px > 0.5 {
        motion_blur(&mut buf, w, h, fx.motion_px, fx.motion_dir);
    }
    // Tone curve as a table over [0, 255] (linear interpolation between entries).
    let lut: Vec<f32> = (0..=256)
        .map(|i| {
            let x = (i as f64 / 256.0).powf(fx.gamma);
            (((x - 0.5) * fx.contrast + 0.5) * 255.0) as f32
        })
        .collect();
    let tone = |v: f32| {
        let x = v.clamp(0.0, 255.0) * (256.0 / 255.0);
        let i = (x as usize).min(255);
        let t = x - i as f32;
        lut[i] + (lut[i + 1] - lut[i]) * t
    };
    let ns = fx.noise_sigma as f32;
    let chroma = (fx.noise_sigma * fx.chroma_noise) as f32;
    let mut state: u64 = rng.random();
    // Approximately normal noise: a sum of four uniforms, rescaled to unit variance.
    let mut gauss = move || {
        state = crate::math::splitmix(state);
        let mut acc = 0.0f32;
        for k in 0..4 {
            acc += ((state >> (16 * k)) & 0xFFFF) as f32 / 65536.0;
        }
        (acc - 2.0) * 1.732_050_8
    };
    for px in buf.chunks_exact_mut(3) {
        let lum_n = if ns > 0.0 { gauss() * ns } else { 0.0 };
        for v in px.iter_mut() {
            let cn = if chroma > 0.0 { gauss() * chroma } else { 0.0 };
            *v = tone(*v) + lum_n + cn;
        }
    }
    for (d, s) in img.iter_mut().zip(&buf) {
        *d = (s.clamp(0.0, 255.0) + 0.5) as u8;
    }
}

/// Separable Gaussian blur of an interleaved RGB float buffer (edges clamped).
pub fn gaussian_blur(buf: &mut [f32], w: usize, h: usize, sigma: f32) {
    let r = (sigma * 3.0).ceil().max(1.0) as usize;
    let k: Vec<f32> = (0..=2 * r)
        .map(|i| {
            let d = i as f32 - r as f32;
            (-(d * d) / (2.0 * sigma * sigma)).exp()
        })
        .collect();
    let ks: f32 = k.iter().sum();
    let k: Vec<f32> = k.iter().map(|v| v / ks).collect();
    let mut tmp = vec![0.0f32; buf.len()];
    // Horizontal: a padded copy of each row, then a straight convolution.
    let mut padded = vec![0.0f32; (w + 2 * r) * 3];
    for (src, dst) in buf.chunks_exact(w * 3).zip(tmp.chunks_exact_mut(w * 3)) {
        blur_row(src, dst, &k, r, &mut padded);
    }
    // Vertical: accumulate whole rows.
    for y in 0..h {
        let out = &mut buf[y * w * 3..(y + 1) * w * 3];
        out.iter_mut().for_each(|v| *v = 0.0);
        for (t, kv) in k.iter().enumerate() {
            let yy = (y + t).saturating_sub(r).min(h - 1);
            let src = &tmp[yy * w * 3..(yy + 1) * w * 3];
            for (o, s) in out.iter_mut().zip(src) {
                *o += kv * s;
            }
        }
    }
}

/// One row of the horizontal pass (interleaved RGB); `padded` is scratch of (w + 2r) * 3.
pub fn blur_row(src: &[f32], dst: &mut [f32], k: &[f32], r: usize, padded: &mut [f32]) {
    let n = src.len();
    let w = n / 3;
    padded[r * 3..r * 3 + n].copy_from_slice(src);
    for i in 0..r {
        padded[i * 3..i * 3 + 3].copy_from_slice(&src[0..3]);
        let o = (r + w + i) * 3;
        padded[o..o + 3].copy_from_slice(&src[n - 3..n]);
    }
    dst.iter_mut().for_each(|v| *v = 0.0);
    for (t, kv) in k.iter().enumerate() {
        let s = &padded[t * 3..t * 3 + n];
        for (o, v) in dst.iter_mut().zip(s) {
            *o += kv * v;
        }
    }
}

/// Linear motion blur (box filter along a direction).
fn motion_blur(buf: &mut [f32], w: usize, h: usize, len: f64, dir: f64) {
    let n = len.ceil() as i64;
    let (dx, dy) = (dir.cos(), dir.sin());
    let src = buf.to_vec();
    for y in 0..h {
        for x in 0..w {
            let mut acc = [0.0f32; 3];
            let mut cnt = 0.0f32;
            for t in -n..=n {
                let f = t as f64 * len / (2.0 * n as f64);
                let xx = (x as f64 + f * dx).round() as i64;
                let yy = (y as f64 + f * dy).round() as i64;
                if xx < 0 || yy < 0 || xx >= w as i64 || yy >= h as i64 {
                    continue;
                }
                let i = (yy as usize * w + xx as usize) * 3;
                acc[0] += src[i];
                acc[1] += src[i + 1];
                acc[2] += src[i + 2];
                cnt += 1.0;
            }
            let o = (y * w + x) * 3;
            if cnt > 0.0 {
                buf[o] = acc[0] / cnt;
                buf[o + 1] = acc[1] / cnt;
                buf[o + 2] = acc[2] / cnt;
            }
        }
    }
}

/// Encode as JPEG with the given quality.
///
/// # Errors
/// The encoder's error (practically only for empty images).
pub fn encode_jpeg(img: &RgbImage, quality: u8) -> Result<Vec<u8>, image::ImageError> {
    let mut out = Vec::new();
    let enc = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, quality.clamp(1, 100));
    img.write_with_encoder(enc)?;
    Ok(out)
}

/// Decode JPEG bytes to RGB.
///
/// # Errors
/// Decoder errors for corrupt data.
pub fn decode_jpeg(bytes: &[u8]) -> Result<RgbImage, image::ImageError> {
    Ok(image::load_from_memory_with_format(bytes, image::ImageFormat::Jpeg)?.to_rgb8())
}
