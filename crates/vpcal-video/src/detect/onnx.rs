//! A learned detector from a user-supplied ONNX file, run by the pure-Rust `tract` runtime
//! (cargo feature `onnx`). No weights ship with vpcal: bring a model whose licence suits you
//! (many YOLO weights are AGPL).
//!
//! # Input
//! One input, `[1, 3, H, W]` `f32`, RGB in [0, 1]. The frame is stretched to `W × H` (no
//! letterbox padding) with bilinear filtering; boxes are scaled back per axis. `W × H` comes
//! from the model when its input shape is fixed, else from [`OnnxConfig::input_size`]
//! (default 640 × 640).
//!
//! # Output layouts ([`OnnxLayout`])
//! - `Yolo` (YOLOv8/v11 and YOLOv5u exports, `yolo export format=onnx`): one output
//!   `[1, 4 + C, N]`: per candidate `cx, cy, w, h` in input pixels, then `C` class scores. The score of a
//!   candidate is its best score among [`OnnxConfig::classes`] (all classes when `None`).
//! - `YoloV5` (classic YOLOv5 exports): one output `[1, N, 5 + C]`: `cx, cy, w, h` in input
//!   pixels, objectness, `C` class scores; score = objectness × best class score.
//! - `BoxesScores` (models exported with their own post-processing, e.g. CenterNet or
//!   DETR-style heads): two outputs, boxes `[1, N, 4]` as `x0, y0, x1, y1` normalised to
//!   [0, 1] and scores `[1, N]` (or `[1, N, 1]`).
//!
//! Candidates with a score above [`OnnxConfig::min_score`] go through greedy non-maximum
//! suppression ([`OnnxConfig::nms_iou`]) and at most [`OnnxConfig::max_detections`] are kept.
//! COCO vehicle classes for 80-class YOLO models (0-based): car 2, motorcycle 3, bus 5,
//! truck 7 ([`COCO_VEHICLES`]).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use fast_image_resize as fir;
use tract_onnx::prelude::*;
use vpcal_geom::BoxPx;

use super::{non_max_suppression, Detection, Detector};
use crate::error::{Result, VideoError};
use crate::source::Frame;

/// COCO class indices (0-based, as in YOLO exports) of car, motorcycle, bus and truck.
pub const COCO_VEHICLES: &[usize] = &[2, 3, 5, 7];

/// How the model's outputs are laid out (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum OnnxLayout {
    Yolo,
    YoloV5,
    BoxesScores,
}

impl std::str::FromStr for OnnxLayout {
    type Err = VideoError;

    fn from_str(s: &str) -> Result<OnnxLayout> {
        match s.to_ascii_lowercase().replace(['-', '_'], "").as_str() {
            "yolo" | "yolov8" | "yolo11" => Ok(OnnxLayout::Yolo),
            "yolov5" => Ok(OnnxLayout::YoloV5),
            "boxesscores" => Ok(OnnxLayout::BoxesScores),
            _ => Err(VideoError::InvalidOption {
                name: "ONNX output layout",
                value: s.to_string(),
                expected: "yolo, yolov5 or boxes-scores",
            }),
        }
    }
}

/// Settings of [`OnnxDetector`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct OnnxConfig {
    pub layout: OnnxLayout,
    /// `(width, height)` of the input when the model does not fix it.
    pub input_size: Option<(u32, u32)>,
    /// Class indices that are vehicles (`Yolo`, `YoloV5`); `None` = every class.
    pub classes: Option<Vec<usize>>,
    /// Keep candidates with a score above this.
    pub min_score: f32,
    /// IoU above which the weaker of two boxes is suppressed.
    pub nms_iou: f64,
    /// Keep at most this many boxes per frame.
    pub max_detections: usize,
}

impl Default for OnnxConfig {
    fn default() -> Self {
        OnnxConfig {
            layout: OnnxLayout::Yolo,
            input_size: None,
            classes: Some(COCO_VEHICLES.to_vec()),
            min_score: 0.25,
            nms_iou: 0.45,
            max_detections: 100,
        }
    }
}

type Plan = Arc<TypedRunnableModel>;

/// A detector running an ONNX model (see the module docs).
#[derive(Debug)]
pub struct OnnxDetector {
    path: PathBuf,
    config: OnnxConfig,
    plan: Plan,
    input_w: u32,
    input_h: u32,
    resizer: fir::Resizer,
    resized: Vec<u8>,
}

fn model_error(path: &Path, what: &str, e: impl std::fmt::Display) -> VideoError {
    VideoError::Model {
        path: path.to_path_buf(),
        message: format!("{what}: {e}"),
    }
}

impl OnnxDetector {
    /// Loads and optimises the model at `path`.
    ///
    /// # Errors
    /// [`VideoError::Io`] when the file is missing, [`VideoError::Model`] when it is not a
    /// usable ONNX model (not ONNX, unsupported operators, wrong input rank).
    pub fn open(path: &Path, config: OnnxConfig) -> Result<OnnxDetector> {
        std::fs::metadata(path).map_err(|e| VideoError::io("cannot open ONNX model", path, e))?;
        let model = tract_onnx::onnx()
            .model_for_path(path)
            .map_err(|e| model_error(path, "not a readable ONNX model", e))?;
        let declared = model
            .input_fact(0)
            .ok()
            .and_then(|f| f.shape.as_concrete_finite().ok().flatten());
        let (input_w, input_h) = match declared.as_deref() {
            Some([1, 3, h, w]) => (
                u32::try_from(*w).map_err(|e| model_error(path, "input width", e))?,
                u32::try_from(*h).map_err(|e| model_error(path, "input height", e))?,
            ),
            Some(other) => {
                return Err(model_error(
                    path,
                    "unsupported input",
                    format!("shape {other:?}, expected [1, 3, H, W]"),
                ))
            }
            None => config.input_size.unwrap_or((640, 640)),
        };
        if input_w == 0 || input_h == 0 {
            return Err(model_error(path, "unsupported input", "zero size"));
        }
        let plan = model
            .with_input_fact(
                0,
                f32::fact([1, 3, input_h as usize, input_w as usize]).into(),
            )
            .and_then(|m| m.into_optimized())
            .and_then(|m| m.into_runnable())
            .map_err(|e| model_error(path, "cannot prepare the model", format!("{e:#}")))?;
        Ok(OnnxDetector {
            path: path.to_path_buf(),
            config,
            plan,
            input_w,
            input_h,
            resizer: fir::Resizer::new(),
            resized: Vec::new(),
        })
    }

    /// `(width, height)` of the model input.
    pub fn input_size(&self) -> (u32, u32) {
        (self.input_w, self.input_h)
    }

    fn input_tensor(&mut self, image: &image::RgbImage) -> Result<Tensor> {
        let (w, h) = (self.input_w, self.input_h);
        let n = w as usize * h as usize;
        let pixels: &[u8] = if image.dimensions() == (w, h) {
            image.as_raw()
        } else {
            let err =
                |e: &dyn std::fmt::Display| model_error(&self.path, "cannot resize the frame", e);
            let src = fir::images::ImageRef::new(
                image.width(),
                image.height(),
                image.as_raw(),
                fir::PixelType::U8x3,
            )
            .map_err(|e| err(&e))?;
            self.resized.resize(3 * n, 0);
            let mut dst =
                fir::images::Image::from_slice_u8(w, h, &mut self.resized, fir::PixelType::U8x3)
                    .map_err(|e| err(&e))?;
            let opts = fir::ResizeOptions::new()
                .resize_alg(fir::ResizeAlg::Convolution(fir::FilterType::Bilinear));
            self.resizer
                .resize(&src, &mut dst, &opts)
                .map_err(|e| err(&e))?;
            &self.resized
        };
        let mut data = vec![0f32; 3 * n];
        for (i, px) in pixels.chunks_exact(3).enumerate() {
            data[i] = f32::from(px[0]) / 255.0;
            data[n + i] = f32::from(px[1]) / 255.0;
            data[2 * n + i] = f32::from(px[2]) / 255.0;
        }
        Tensor::from_shape(&[1, 3, h as usize, w as usize], &data)
            .map_err(|e| model_error(&self.path, "cannot build the input", e))
    }

    fn class_score(&self, scores: impl Iterator<Item = (usize, f32)>) -> f32 {
        let mut best = f32::NEG_INFINITY;
        for (c, s) in scores {
            if self
                .config
                .classes
                .as_ref()
                .is_none_or(|cl| cl.contains(&c))
            {
                best = best.max(s);
            }
        }
        best
    }

    /// Candidates in input pixels `(x0, y0, x1, y1, score)`.
    fn decode(&self, outputs: &TVec<TValue>) -> Result<Vec<([f64; 4], f32)>> {
        let bad = |msg: String| model_error(&self.path, "unexpected model output", msg);
        let view = |i: usize| -> Result<tract_ndarray::ArrayViewD<'_, f32>> {
            outputs
                .get(i)
                .ok_or_else(|| {
                    bad(format!(
                        "the model has {} outputs, layout needs {}",
                        outputs.len(),
                        i + 1
                    ))
                })?
                .to_plain_array_view::<f32>()
                .map_err(|e| bad(format!("output {i} is not f32 ({e})")))
        };
        let mut out = Vec::new();
        match self.config.layout {
            OnnxLayout::Yolo | OnnxLayout::YoloV5 => {
                let a = view(0)?;
                let shape = a.shape().to_vec();
                let channels_first = self.config.layout == OnnxLayout::Yolo;
                let (rows, cols) = match (shape.as_slice(), channels_first) {
                    ([1, c, n], true) => (*n, *c),
                    ([1, n, c], false) => (*n, *c),
                    _ => {
                        return Err(bad(format!(
                            "shape {shape:?}, expected {}",
                            if channels_first {
                                "[1, 4 + C, N]"
                            } else {
                                "[1, N, 5 + C]"
                            }
                        )))
                    }
                };
                let extra = if self.config.layout == OnnxLayout::YoloV5 {
                    5
                } else {
                    4
                };
                if cols <= extra {
                    return Err(bad(format!("shape {shape:?} has no class scores")));
                }
                let flat: Vec<f32> = a.iter().copied().collect();
                let at = |r: usize, c: usize| {
                    if channels_first {
                        flat[c * rows + r]
                    } else {
                        flat[r * cols + c]
                    }
                };
                for r in 0..rows {
                    let cls = self.class_score((extra..cols).map(|c| (c - extra, at(r, c))));
                    let score = if extra == 5 { at(r, 4) * cls } else { cls };
                    if score.is_nan() || score <= self.config.min_score {
                        continue;
                    }
                    let (cx, cy, w, h) = (
                        f64::from(at(r, 0)),
                        f64::from(at(r, 1)),
                        f64::from(at(r, 2)),
                        f64::from(at(r, 3)),
                    );
                    out.push((
                        [cx - w / 2.0, cy - h / 2.0, cx + w / 2.0, cy + h / 2.0],
                        score,
                    ));
                }
            }
            OnnxLayout::BoxesScores => {
                let boxes = view(0)?;
                let scores = view(1)?;
                let n = scores.len();
                if boxes.len() != 4 * n {
                    return Err(bad(format!(
                        "boxes {:?} and scores {:?} disagree: expected [1, N, 4] and [1, N]",
                        boxes.shape(),
                        scores.shape()
                    )));
                }
                let b: Vec<f32> = boxes.iter().copied().collect();
                let (iw, ih) = (f64::from(self.input_w), f64::from(self.input_h));
                for (i, &s) in scores.iter().enumerate() {
                    if s.is_nan() || s <= self.config.min_score {
                        continue;
                    }
                    let q = &b[4 * i..4 * i + 4];
                    out.push((
                        [
                            f64::from(q[0]) * iw,
                            f64::from(q[1]) * ih,
                            f64::from(q[2]) * iw,
                            f64::from(q[3]) * ih,
                        ],
                        s,
                    ));
                }
            }
        }
        Ok(out)
    }
}

impl Detector for OnnxDetector {
    fn detect(&mut self, frame: &Frame) -> Result<Vec<Detection>> {
        let input = self.input_tensor(&frame.image)?;
        let outputs = self
            .plan
            .run(tvec!(input.into()))
            .map_err(|e| model_error(&self.path, "inference failed", format!("{e:#}")))?;
        let (fw, fh) = (
            f64::from(frame.image.width()),
            f64::from(frame.image.height()),
        );
        let sx = fw / f64::from(self.input_w);
        let sy = fh / f64::from(self.input_h);
        let dets: Vec<Detection> = self
            .decode(&outputs)?
            .into_iter()
            .filter_map(|(b, score)| {
                let bbox = BoxPx::new(
                    (b[0] * sx).clamp(0.0, fw),
                    (b[1] * sy).clamp(0.0, fh),
                    (b[2] * sx).clamp(0.0, fw),
                    (b[3] * sy).clamp(0.0, fh),
                );
                (bbox.is_valid() && score.is_finite()).then_some(Detection {
                    bbox,
                    score: score.clamp(0.0, 1.0),
                })
            })
            .collect();
        let mut kept = non_max_suppression(dets, self.config.nms_iou);
        kept.truncate(self.config.max_detections);
        Ok(kept)
    }

    fn name(&self) -> String {
        format!("onnx:{}", self.path.display())
    }
}
