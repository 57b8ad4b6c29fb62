//! The built-in learned vehicle detector: YOLOX-nano trained on COCO (Apache-2.0, shipped in
//! `models/yolox_nano_coco/` with its licence and a notice of its source, embedded in the
//! binary), run by the pure-Rust `tract` runtime.
//!
//! # The model's convention
//! Input `[1, 3, 416, 416]` `f32`, channels **BGR**, values 0-255 (not normalised); the image
//! is resized keeping its aspect ratio into the top-left corner and the rest is 114. Output
//! `[1, A, 5 + C]`: one row per anchor point of the strides 8, 16, 32 (52² + 26² + 13² = 3549
//! rows at 416 px; row-major, x fastest), `dx, dy, log w, log h, objectness, C class scores`.
//! A box's centre is `(grid + (dx, dy)) × stride`, its size `exp(log w, log h) × stride`, in
//! input pixels. These are the pure functions [`Letterbox`], [`letterbox_input`] and
//! [`decode`].
//!
//! # Resampling
//! A region of the frame goes into the input by exact area averaging (each input pixel is the
//! mean of the frame area it covers; pixels it covers in part count by their overlap). It
//! keeps thin far vehicles that point sampling would alias away, and it is defined exactly,
//! so the golden outputs of `scripts/yolox_goldens.py` (onnxruntime, numpy) can be matched.
//!
//! # Vehicles, tiles and merging
//! A candidate's score is objectness × its best score among [`YoloxConfig::classes`] (COCO
//! car 2, bus 5, truck 7 by default; motorcycle 3 on request). At 416 px a 1080p frame shrinks
//! 4.6 times and far vehicles vanish, so besides the whole frame the detector can look at
//! square tiles ([`tile_regions`]: `tiles` columns, overlapping, as many rows as cover the
//! height). A tile's candidates that touch one of its inner borders (a side not on the frame's
//! border) are dropped: that vehicle continues in the neighbouring tile or is whole in the
//! frame pass. All candidates then go through one class-agnostic greedy NMS (a truck and a
//! car box on one vehicle are one vehicle).

use std::fmt;
use std::path::Path;
use std::sync::Arc;

use image::RgbImage;
use tract_onnx::prelude::*;
use vpcal_geom::BoxPx;

use super::{non_max_suppression, Detection, Detector};
use crate::error::{Result, VideoError};
use crate::source::Frame;

/// The bundled model file (`models/yolox_nano_coco/yolox_nano.onnx`).
pub const BUNDLED_YOLOX: &[u8] = include_bytes!(concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../models/yolox_nano_coco/yolox_nano.onnx"
));

/// SHA-1 of [`BUNDLED_YOLOX`] as published (models/yolox_nano_coco/NOTICE).
pub const BUNDLED_YOLOX_SHA1: &str = "4f899f1b95f82fad5e09732f91c82b4da0f3cb03";

/// Strides of the YOLOX heads, in the order of the output rows.
pub const STRIDES: [u32; 3] = [8, 16, 32];

/// The value of the input pixels outside the resized image (the YOLOX convention).
pub const PAD_VALUE: f32 = 114.0;

/// COCO classes (0-based) that are vehicles by default: car, bus, truck.
pub const COCO_CAR_BUS_TRUCK: [usize; 3] = [2, 5, 7];

/// COCO class index of motorcycles.
pub const COCO_MOTORCYCLE: usize = 3;

/// Settings of [`YoloxDetector`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct YoloxConfig {
    /// COCO class indices that count as vehicles.
    pub classes: Vec<usize>,
    /// Keep candidates whose score is above this.
    pub min_score: f32,
    /// IoU above which the weaker of two boxes is suppressed.
    pub nms_iou: f64,
    /// Columns of square tiles looked at besides the whole frame (0: the whole frame only).
    pub tiles: u32,
    /// Overlap of neighbouring tiles, as a fraction of the tile side.
    pub tile_overlap: f64,
    /// Look at one tile per frame, the tiles in turn (with the whole frame every frame),
    /// instead of every tile in every frame: a far vehicle, which only a tile finds, is
    /// then seen in every second frame of two tiles (the tracks bridge gaps of 8 frames),
    /// for a third of the detector's time at 1080p with two columns of tiles. Off by
    /// default: on the demo's 720p scene it found 20 % fewer boxes, and the roll, for want
    /// of their edgelets, came out 2.5° off.
    pub tile_rotation: bool,
    /// Keep at most this many boxes per frame, best first.
    pub max_detections: usize,
}

impl Default for YoloxConfig {
    fn default() -> Self {
        YoloxConfig {
            classes: COCO_CAR_BUS_TRUCK.to_vec(),
            min_score: 0.25,
            nms_iou: 0.45,
            tiles: 0,
            tile_overlap: 0.2,
            tile_rotation: false,
            max_detections: 100,
        }
    }
}

/// A rectangle of whole frame pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Region {
    pub x0: u32,
    pub y0: u32,
    pub width: u32,
    pub height: u32,
}

impl Region {
    /// The whole of a `width × height` frame.
    pub fn whole(width: u32, height: u32) -> Region {
        Region {
            x0: 0,
            y0: 0,
            width,
            height,
        }
    }
}

/// Evenly spread starts of `count` windows of length `len` covering `0..total` (the first at
/// 0, the last ending at `total`).
fn spread(total: u32, len: u32, count: u32) -> Vec<u32> {
    if count <= 1 || len >= total {
        return vec![0];
    }
    let room = f64::from(total - len);
    (0..count)
        .map(|i| (room * f64::from(i) / f64::from(count - 1)).round() as u32)
        .collect()
}

/// Square tiles over a `width × height` frame: `columns` of them across, overlapping by
/// `overlap` of their side, as many rows as it takes to cover the height (the side is at
/// most the frame's shorter side). Empty for `columns == 0`.
pub fn tile_regions(width: u32, height: u32, columns: u32, overlap: f64) -> Vec<Region> {
    if columns == 0 || width == 0 || height == 0 {
        return Vec::new();
    }
    let overlap = overlap.clamp(0.0, 0.9);
    let side = (f64::from(width) / f64::from(columns) * (1.0 + overlap)).ceil() as u32;
    let side = side.min(width).min(height).max(1);
    let step = (f64::from(side) * (1.0 - overlap)).max(1.0);
    let count = |total: u32| -> u32 {
        if total <= side {
            1
        } else {
            1 + (f64::from(total - side) / step).ceil() as u32
        }
    };
    let xs = spread(width, side, count(width));
    let ys = spread(height, side, count(height));
    let mut out = Vec::with_capacity(xs.len() * ys.len());
    for &y0 in &ys {
        for &x0 in &xs {
            out.push(Region {
                x0,
                y0,
                width: side,
                height: side,
            });
        }
    }
    out
}

/// Where a region of the frame lands in the model input.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Letterbox {
    pub region: Region,
    /// The side of the square model input.
    pub input: u32,
    /// Size of the resized region in the input (its top-left corner is the input's).
    pub resized: (u32, u32),
}

impl Letterbox {
    /// The largest size that fits the input keeping the region's aspect ratio.
    pub fn new(region: Region, input: u32) -> Letterbox {
        let (w, h) = (f64::from(region.width), f64::from(region.height));
        let r = (f64::from(input) / w).min(f64::from(input) / h);
        let fit = |v: f64| ((v * r + 0.5).floor() as u32).clamp(1, input);
        Letterbox {
            region,
            input,
            resized: (fit(w), fit(h)),
        }
    }

    /// Frame pixels per input pixel along x and y.
    pub fn scale(&self) -> (f64, f64) {
        (
            f64::from(self.region.width) / f64::from(self.resized.0),
            f64::from(self.region.height) / f64::from(self.resized.1),
        )
    }

    /// A box in input pixels `[x0, y0, x1, y1]`, in frame pixels, clamped to the region.
    pub fn to_frame(&self, b: [f64; 4]) -> BoxPx {
        let (sx, sy) = self.scale();
        let r = &self.region;
        let (x0, y0) = (f64::from(r.x0), f64::from(r.y0));
        let (x1, y1) = (x0 + f64::from(r.width), y0 + f64::from(r.height));
        BoxPx::new(
            (x0 + b[0] * sx).clamp(x0, x1),
            (y0 + b[1] * sy).clamp(y0, y1),
            (x0 + b[2] * sx).clamp(x0, x1),
            (y0 + b[3] * sy).clamp(y0, y1),
        )
    }
}

/// Area-averaging weights along one axis: for each output index, the first source index and
/// the weights of the source pixels from there on (they sum to 1).
fn area_weights(offset: u32, length: u32, out_len: u32) -> Vec<(usize, Vec<f32>)> {
    let s = f64::from(length) / f64::from(out_len);
    (0..out_len)
        .map(|i| {
            let a = f64::from(offset) + f64::from(i) * s;
            let b = a + s;
            let j0 = a.floor() as usize;
            // `b` may exceed the region's end by a rounding error.
            let j1 = (b.ceil() as usize).min((offset + length) as usize);
            let w = (j0..j1)
                .map(|j| {
                    let ov = b.min(j as f64 + 1.0) - a.max(j as f64);
                    (ov.max(0.0) / s) as f32
                })
                .collect();
            (j0, w)
        })
        .collect()
}

/// Fills `out` (`3 × input × input`, NCHW, BGR, 0-255) with the letterboxed region of
/// `image` (see the module docs).
///
/// # Panics
/// Never for a region inside the image; a region outside it is clamped by the caller
/// ([`tile_regions`] and [`Region::whole`] give regions inside).
pub fn letterbox_input(image: &RgbImage, lb: &Letterbox, out: &mut Vec<f32>) {
    let n = lb.input as usize;
    out.clear();
    out.resize(3 * n * n, PAD_VALUE);
    let (ow, oh) = (lb.resized.0 as usize, lb.resized.1 as usize);
    let r = lb.region;
    let wx = area_weights(r.x0, r.width, lb.resized.0);
    let wy = area_weights(r.y0, r.height, lb.resized.1);
    let (iw, ih) = (image.width() as usize, image.height() as usize);
    let raw = image.as_raw();
    // Vertical pass first, one output row at a time: each tap adds a whole contiguous row
    // span of the region (`width × 3` bytes), a loop the compiler vectorises; then the
    // horizontal pass reads only that one averaged row. (Horizontal first, over every row of
    // the region, took about a fifth of the detector's time at 1080p.)
    let x_lo = (r.x0 as usize).min(iw);
    let x_hi = ((r.x0 + r.width) as usize).min(iw);
    let mut row = vec![0f32; (x_hi - x_lo) * 3];
    let plane = n * n;
    for (yo, (j0, w)) in wy.iter().enumerate().take(oh) {
        row.fill(0.0);
        for (k, &wk) in w.iter().enumerate() {
            let y = j0 + k;
            if y >= ih {
                break;
            }
            let line = &raw[(y * iw + x_lo) * 3..(y * iw + x_hi) * 3];
            for (acc, &p) in row.iter_mut().zip(line) {
                *acc += wk * f32::from(p);
            }
        }
        for (xo, (j0, w)) in wx.iter().enumerate().take(ow) {
            let mut acc = [0f32; 3];
            for (k, &wk) in w.iter().enumerate() {
                let j = (j0 + k).wrapping_sub(x_lo);
                if let Some(p) = row.get(j * 3..j * 3 + 3) {
                    acc[0] += wk * p[0];
                    acc[1] += wk * p[1];
                    acc[2] += wk * p[2];
                }
            }
            // RGB -> BGR planes.
            out[yo * n + xo] = acc[2];
            out[plane + yo * n + xo] = acc[1];
            out[2 * plane + yo * n + xo] = acc[0];
        }
    }
}

/// A decoded candidate, in model-input pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Candidate {
    /// `[x0, y0, x1, y1]` in input pixels.
    pub bbox: [f64; 4],
    /// Objectness × the best score among the vehicle classes.
    pub score: f32,
    /// That class (COCO index).
    pub class: usize,
}

/// Why a model output cannot be decoded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DecodeError(pub String);

impl fmt::Display for DecodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

/// Number of anchor points of a square input of side `input`.
pub fn anchor_count(input: u32) -> usize {
    STRIDES
        .iter()
        .map(|s| {
            let n = (input / s) as usize;
            n * n
        })
        .sum()
}

/// Decodes the raw output (`rows × cols`, row-major; `cols = 5 + classes`) of a square
/// input of side `input`: candidates whose score is above `min_score`.
///
/// # Errors
/// When the output's size does not match the input's anchor points or has no class scores.
pub fn decode(
    raw: &[f32],
    cols: usize,
    input: u32,
    classes: &[usize],
    min_score: f32,
) -> std::result::Result<Vec<Candidate>, DecodeError> {
    let rows = anchor_count(input);
    if cols <= 5 || raw.len() != rows * cols {
        return Err(DecodeError(format!(
            "{} values in rows of {cols}, expected {rows} rows (strides 8, 16, 32 at {input} px) \
             of 5 + class scores",
            raw.len()
        )));
    }
    if let Some(&c) = classes.iter().find(|&&c| 5 + c >= cols) {
        return Err(DecodeError(format!(
            "class {c} asked for, but the model has {} classes",
            cols - 5
        )));
    }
    let mut out = Vec::new();
    let mut r = 0usize;
    for &stride in &STRIDES {
        let n = input / stride;
        let s = f64::from(stride);
        for gy in 0..n {
            for gx in 0..n {
                let row = &raw[r * cols..(r + 1) * cols];
                r += 1;
                let Some((class, cls)) = classes
                    .iter()
                    .map(|&c| (c, row[5 + c]))
                    .max_by(|a, b| a.1.total_cmp(&b.1))
                else {
                    continue;
                };
                let score = row[4] * cls;
                if score.is_nan() || score <= min_score {
                    continue;
                }
                let cx = (f64::from(gx) + f64::from(row[0])) * s;
                let cy = (f64::from(gy) + f64::from(row[1])) * s;
                let w = f64::from(row[2]).exp() * s;
                let h = f64::from(row[3]).exp() * s;
                if !(w.is_finite() && h.is_finite()) {
                    continue;
                }
                out.push(Candidate {
                    bbox: [cx - w / 2.0, cy - h / 2.0, cx + w / 2.0, cy + h / 2.0],
                    score,
                    class,
                });
            }
        }
    }
    Ok(out)
}

/// Whether a box (frame pixels) touches a side of `region` that is not on the frame's border
/// (within `margin` pixels).
pub fn touches_inner_border(b: &BoxPx, region: &Region, frame: (u32, u32), margin: f64) -> bool {
    let (x0, y0) = (f64::from(region.x0), f64::from(region.y0));
    let (x1, y1) = (x0 + f64::from(region.width), y0 + f64::from(region.height));
    (region.x0 > 0 && b.x0 <= x0 + margin)
        || (region.y0 > 0 && b.y0 <= y0 + margin)
        || (region.x0 + region.width < frame.0 && b.x1 >= x1 - margin)
        || (region.y0 + region.height < frame.1 && b.y1 >= y1 - margin)
}

/// Pixels from a tile's inner border within which a box counts as cut by it.
const INNER_BORDER_MARGIN_PX: f64 = 2.0;

/// The detections of all passes (frame pass first, then tiles), merged (see the module docs).
pub fn merge_passes(
    passes: Vec<(Letterbox, Vec<Candidate>)>,
    frame: (u32, u32),
    nms_iou: f64,
    max_detections: usize,
) -> Vec<Detection> {
    let mut all = Vec::new();
    for (lb, cands) in passes {
        let whole = lb.region == Region::whole(frame.0, frame.1);
        for c in cands {
            let bbox = lb.to_frame(c.bbox);
            if !bbox.is_valid()
                || (!whole
                    && touches_inner_border(&bbox, &lb.region, frame, INNER_BORDER_MARGIN_PX))
            {
                continue;
            }
            all.push(Detection {
                bbox,
                score: c.score.clamp(0.0, 1.0),
            });
        }
    }
    let mut kept = non_max_suppression(all, nms_iou);
    kept.truncate(max_detections);
    kept
}

/// The SHA-1 of `bytes`, lowercase hex.
pub fn sha1_hex(bytes: &[u8]) -> String {
    sha1_smol::Sha1::from(bytes).digest().to_string()
}

type Plan = Arc<TypedRunnableModel>;

/// The YOLOX detector (see the module docs).
pub struct YoloxDetector {
    label: String,
    sha1: String,
    config: YoloxConfig,
    plan: Plan,
    input: u32,
    cols: usize,
    /// Frames looked at so far: which tile is next with `tile_rotation`.
    frames_seen: u64,
}

impl fmt::Debug for YoloxDetector {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("YoloxDetector")
            .field("label", &self.label)
            .field("sha1", &self.sha1)
            .field("config", &self.config)
            .field("input", &self.input)
            .finish_non_exhaustive()
    }
}

impl YoloxDetector {
    /// The bundled YOLOX-nano (its SHA-1 checked).
    ///
    /// # Errors
    /// [`VideoError::Model`] when the embedded bytes are not the published model.
    pub fn bundled(config: YoloxConfig) -> Result<YoloxDetector> {
        YoloxDetector::from_bytes(
            BUNDLED_YOLOX,
            "bundled:models/yolox_nano_coco/yolox_nano.onnx",
            Some(BUNDLED_YOLOX_SHA1),
            config,
        )
    }

    /// A YOLOX model (any size of the family, exported to ONNX with a fixed square input)
    /// from a file.
    ///
    /// # Errors
    /// [`VideoError::Io`] when the file cannot be read, [`VideoError::Model`] when it is not
    /// a YOLOX-layout ONNX model.
    pub fn open(path: &Path, config: YoloxConfig) -> Result<YoloxDetector> {
        let bytes = std::fs::read(path)
            .map_err(|e| VideoError::io("cannot read the YOLOX model", path, e))?;
        YoloxDetector::from_bytes(&bytes, &path.display().to_string(), None, config)
    }

    /// A YOLOX model from its bytes; `expected_sha1` checks them first.
    ///
    /// # Errors
    /// [`VideoError::Model`] for a SHA-1 mismatch, an unreadable model, an input that is not
    /// `[1, 3, S, S]` or an output that is not `[1, anchors, 5 + classes]`.
    pub fn from_bytes(
        bytes: &[u8],
        label: &str,
        expected_sha1: Option<&str>,
        config: YoloxConfig,
    ) -> Result<YoloxDetector> {
        let err = |message: String| VideoError::Model {
            path: label.into(),
            message,
        };
        let sha1 = sha1_hex(bytes);
        if let Some(expected) = expected_sha1 {
            if sha1 != expected {
                return Err(err(format!(
                    "SHA-1 {sha1} ({} bytes), expected {expected}: the model file is damaged or \
                     not the one vpcal ships",
                    bytes.len()
                )));
            }
        }
        let model = tract_onnx::onnx()
            .model_for_read(&mut std::io::Cursor::new(bytes))
            .map_err(|e| err(format!("not a readable ONNX model: {e}")))?;
        let shape = model
            .input_fact(0)
            .ok()
            .and_then(|f| f.shape.as_concrete_finite().ok().flatten());
        let input = match shape.as_deref() {
            Some([1, 3, h, w]) if h == w && *h >= 32 => *h as u32,
            other => {
                return Err(err(format!(
                    "input shape {other:?}, expected a fixed square [1, 3, S, S]"
                )))
            }
        };
        let plan = model
            .into_optimized()
            .and_then(|m| m.into_runnable())
            .map_err(|e| err(format!("cannot prepare the model: {e:#}")))?;
        let mut det = YoloxDetector {
            label: label.to_string(),
            sha1,
            config,
            plan,
            input,
            cols: 0,
            frames_seen: 0,
        };
        // One run on a blank input learns the output's width and checks its layout.
        let blank = vec![PAD_VALUE; 3 * (input as usize).pow(2)];
        let out = det.run(&blank)?;
        let rows = anchor_count(input);
        if out.len() % rows != 0 || out.len() / rows <= 5 {
            return Err(err(format!(
                "output of {} values, expected [1, {rows}, 5 + classes] (YOLOX layout)",
                out.len()
            )));
        }
        det.cols = out.len() / rows;
        if let Some(&c) = det.config.classes.iter().find(|&&c| 5 + c >= det.cols) {
            return Err(err(format!(
                "class {c} asked for, but the model has {} classes",
                det.cols - 5
            )));
        }
        Ok(det)
    }

    /// An error about this model.
    fn error(&self, message: String) -> VideoError {
        VideoError::Model {
            path: self.label.clone().into(),
            message,
        }
    }

    /// The side of the model's square input.
    pub fn input_size(&self) -> u32 {
        self.input
    }

    /// SHA-1 of the model file.
    pub fn sha1(&self) -> &str {
        &self.sha1
    }

    /// The settings.
    pub fn config(&self) -> &YoloxConfig {
        &self.config
    }

    fn run(&self, input: &[f32]) -> Result<Vec<f32>> {
        let n = self.input as usize;
        let err = |what: &str, e: String| self.error(format!("{what}: {e}"));
        let tensor = Tensor::from_shape(&[1, 3, n, n], input)
            .map_err(|e| err("cannot build the input", e.to_string()))?;
        let outputs = self
            .plan
            .run(tvec!(tensor.into()))
            .map_err(|e| err("inference failed", format!("{e:#}")))?;
        let view = outputs
            .first()
            .ok_or_else(|| err("unexpected model output", "no output".into()))?
            .to_plain_array_view::<f32>()
            .map_err(|e| err("unexpected model output", e.to_string()))?;
        Ok(view.iter().copied().collect())
    }

    /// Candidates of one region of `image`, in input pixels.
    ///
    /// # Errors
    /// A failed model run or an output that does not decode.
    pub fn candidates(
        &self,
        image: &RgbImage,
        region: Region,
    ) -> Result<(Letterbox, Vec<Candidate>)> {
        let lb = Letterbox::new(region, self.input);
        let mut input = Vec::new();
        letterbox_input(image, &lb, &mut input);
        let raw = self.run(&input)?;
        let cands = decode(
            &raw,
            self.cols,
            self.input,
            &self.config.classes,
            self.config.min_score,
        )
        .map_err(|e| self.error(format!("unexpected model output: {e}")))?;
        Ok((lb, cands))
    }

    /// The regions looked at in a `width × height` frame: the whole frame, then the tiles.
    pub fn regions(&self, width: u32, height: u32) -> Vec<Region> {
        let mut r = vec![Region::whole(width, height)];
        r.extend(tile_regions(
            width,
            height,
            self.config.tiles,
            self.config.tile_overlap,
        ));
        r
    }
}

/// One region's letterbox and candidates.
type Pass = (Letterbox, Vec<Candidate>);

/// The cores the detector spreads its work over.
fn cores() -> usize {
    std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
        .max(1)
}

impl YoloxDetector {
    /// The regions of the next frame, `width × height`: all of them, or with
    /// `tile_rotation` the whole frame and one tile in turn.
    fn next_regions(&mut self, width: u32, height: u32) -> Vec<Region> {
        let mut regions = self.regions(width, height);
        if self.config.tile_rotation && regions.len() > 2 {
            let tile = 1 + (self.frames_seen % (regions.len() as u64 - 1)) as usize;
            regions = vec![regions[0], regions[tile]];
        }
        self.frames_seen += 1;
        regions
    }
}

impl Detector for YoloxDetector {
    fn detect(&mut self, frame: &Frame) -> Result<Vec<Detection>> {
        self.detect_batch(std::slice::from_ref(frame))
            .pop()
            .unwrap_or_else(|| Err(self.error("no result for the frame".into())))
    }

    /// Two: a frame's regions (the whole frame and the tiles: three by default) rarely divide
    /// evenly over two cores, two frames' regions fill them better.
    fn batch_frames(&self) -> usize {
        2
    }

    fn detect_batch(&mut self, frames: &[Frame]) -> Vec<Result<Vec<Detection>>> {
        let work: Vec<(usize, Region)> = frames
            .iter()
            .enumerate()
            .flat_map(|(f, frame)| {
                let (w, h) = frame.image.dimensions();
                self.next_regions(w, h)
                    .into_iter()
                    .map(move |r| (f, r))
                    .collect::<Vec<_>>()
            })
            .collect();
        let this = &*self;
        // The regions are independent model runs (tract runs each on one thread): spread
        // those of all the frames over the cores, in a fixed assignment so that the result
        // does not depend on timing. Three regions of one frame on two cores leave one core
        // idle for the third; two frames' six fill both. (tract's multithreaded matrix
        // products did not pay here: one region on two cores ran at 0.92x, three regions one
        // after another at 0.74x of this; most of the model's time is in depthwise
        // convolutions and small products.)
        let threads = cores().clamp(1, work.len().max(1));
        let mut passes: Vec<Option<Result<Pass>>> = (0..work.len()).map(|_| None).collect();
        std::thread::scope(|s| {
            let handles: Vec<_> = (0..threads)
                .map(|t| {
                    let mine: Vec<(usize, (usize, Region))> = work
                        .iter()
                        .copied()
                        .enumerate()
                        .filter(|(i, _)| i % threads == t)
                        .collect();
                    s.spawn(move || {
                        mine.into_iter()
                            .map(|(i, (f, r))| (i, this.candidates(&frames[f].image, r)))
                            .collect::<Vec<_>>()
                    })
                })
                .collect();
            for handle in handles {
                for (i, pass) in handle.join().unwrap_or_default() {
                    passes[i] = Some(pass);
                }
            }
        });
        let mut per_frame: Vec<Result<Vec<Pass>>> = frames.iter().map(|_| Ok(Vec::new())).collect();
        for ((f, _), pass) in work.iter().zip(passes) {
            let pass = pass.unwrap_or_else(|| Err(self.error("a detector thread panicked".into())));
            match (&mut per_frame[*f], pass) {
                (Ok(list), Ok(p)) => list.push(p),
                (slot @ Ok(_), Err(e)) => *slot = Err(e),
                (Err(_), _) => {}
            }
        }
        frames
            .iter()
            .zip(per_frame)
            .map(|(frame, passes)| {
                Ok(merge_passes(
                    passes?,
                    frame.image.dimensions(),
                    self.config.nms_iou,
                    self.config.max_detections,
                ))
            })
            .collect()
    }

    fn name(&self) -> String {
        let tiles = match self.config.tiles {
            0 => "whole frame".to_string(),
            n if self.config.tile_rotation => {
                format!("whole frame + {n}-column tiles, one per frame in turn")
            }
            n => format!("whole frame + {n}-column tiles"),
        };
        format!("yolox:{} ({tiles})", self.label)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn anchors_of_the_416_input() {
        assert_eq!(anchor_count(416), 52 * 52 + 26 * 26 + 13 * 13);
    }

    #[test]
    fn letterbox_of_a_1080p_frame() {
        let lb = Letterbox::new(Region::whole(1920, 1080), 416);
        assert_eq!(lb.resized, (416, 234));
        let b = lb.to_frame([0.0, 0.0, 416.0, 234.0]);
        assert!((b.x1 - 1920.0).abs() < 1e-9 && (b.y1 - 1080.0).abs() < 1e-9);
    }

    #[test]
    fn area_weights_sum_to_one_and_cover_the_region() {
        for (off, len, out) in [(0, 1920, 416), (700, 800, 416), (0, 320, 416), (5, 7, 3)] {
            let w = area_weights(off, len, out);
            for (j0, ws) in &w {
                let s: f32 = ws.iter().sum();
                assert!((s - 1.0).abs() < 1e-5, "{off} {len} {out}: {s}");
                assert!(*j0 >= off as usize);
            }
            let (j0, ws) = w.last().map(|(a, b)| (*a, b.len())).unwrap_or((0, 0));
            assert!(j0 + ws <= (off + len) as usize);
        }
    }

    /// The input pixel is the area average of the region's pixels it covers: checked against
    /// the average computed directly, pixel by pixel in f64, on a textured frame and a tile
    /// that does not start at the frame's corner.
    #[test]
    fn letterbox_input_is_the_area_average_of_the_region() {
        let img = RgbImage::from_fn(301, 173, |x, y| {
            image::Rgb([
                ((x * 7 + y * 3) % 256) as u8,
                ((x * x + 5 * y) % 251) as u8,
                ((x * y) % 253) as u8,
            ])
        });
        for region in [
            Region::whole(301, 173),
            Region {
                x0: 120,
                y0: 40,
                width: 133,
                height: 133,
            },
        ] {
            let lb = Letterbox::new(region, 64);
            let mut input = Vec::new();
            letterbox_input(&img, &lb, &mut input);
            let (sx, sy) = lb.scale();
            let n = 64usize;
            for yo in 0..lb.resized.1 as usize {
                for xo in 0..lb.resized.0 as usize {
                    let a = f64::from(region.x0) + xo as f64 * sx;
                    let c = f64::from(region.y0) + yo as f64 * sy;
                    let mut want = [0f64; 3];
                    for y in c.floor() as u32..(c + sy).ceil() as u32 {
                        let oy = (c + sy).min(f64::from(y) + 1.0) - c.max(f64::from(y));
                        for x in a.floor() as u32..(a + sx).ceil() as u32 {
                            let ox = (a + sx).min(f64::from(x) + 1.0) - a.max(f64::from(x));
                            let p = img.get_pixel(x, y).0;
                            for ch in 0..3 {
                                want[ch] += ox.max(0.0) * oy.max(0.0) * f64::from(p[ch]);
                            }
                        }
                    }
                    for ch in 0..3 {
                        // Planes are BGR.
                        let got = f64::from(input[(2 - ch) * n * n + yo * n + xo]);
                        let want = want[ch] / (sx * sy);
                        assert!(
                            (got - want).abs() < 1e-3,
                            "({xo}, {yo}) ch {ch}: {got} vs {want}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn a_uniform_frame_gives_a_uniform_input_and_padding_elsewhere() {
        let img = RgbImage::from_pixel(640, 360, image::Rgb([10, 20, 30]));
        let lb = Letterbox::new(Region::whole(640, 360), 416);
        let mut input = Vec::new();
        letterbox_input(&img, &lb, &mut input);
        let n = 416usize;
        let (ow, oh) = (lb.resized.0 as usize, lb.resized.1 as usize);
        assert_eq!((ow, oh), (416, 234));
        for y in 0..n {
            for x in 0..n {
                let inside = x < ow && y < oh;
                let bgr = [
                    input[y * n + x],
                    input[n * n + y * n + x],
                    input[2 * n * n + y * n + x],
                ];
                let want = if inside {
                    [30.0, 20.0, 10.0]
                } else {
                    [PAD_VALUE; 3]
                };
                for c in 0..3 {
                    assert!((bgr[c] - want[c]).abs() < 1e-3, "({x}, {y}) {bgr:?}");
                }
            }
        }
    }

    #[test]
    fn decode_places_a_box_on_its_anchor() {
        let input = 64;
        let rows = anchor_count(input);
        let cols = 5 + 8;
        let mut raw = vec![0f32; rows * cols];
        // Stride 16 grid starts after the 8x8 stride-8 grid; cell (1, 2) of the 4x4 grid.
        let r = 64 + 2 * 4 + 1;
        let row = &mut raw[r * cols..(r + 1) * cols];
        row[0] = 0.5;
        row[1] = 0.25;
        row[2] = 2f32.ln();
        row[3] = 0.0;
        row[4] = 0.9;
        row[5 + 2] = 0.8;
        row[5 + 7] = 0.5;
        let c = decode(&raw, cols, input, &[2, 5, 7], 0.25).unwrap_or_default();
        assert_eq!(c.len(), 1);
        let b = c[0].bbox;
        // centre ((1 + 0.5) * 16, (2 + 0.25) * 16) = (24, 36), size 32 x 16.
        assert!(
            (b[0] - 8.0).abs() < 1e-5 && (b[2] - 40.0).abs() < 1e-5,
            "{b:?}"
        );
        assert!(
            (b[1] - 28.0).abs() < 1e-5 && (b[3] - 44.0).abs() < 1e-5,
            "{b:?}"
        );
        assert!((c[0].score - 0.72).abs() < 1e-6);
        assert_eq!(c[0].class, 2);
        assert!(decode(&raw[1..], cols, input, &[2], 0.25).is_err());
        assert!(decode(&raw, cols, input, &[9], 0.25).is_err());
    }

    #[test]
    fn tiles_cover_the_frame_and_overlap() {
        for (w, h, n) in [
            (1920, 1080, 2),
            (1920, 1080, 3),
            (640, 352, 2),
            (320, 240, 1),
            (1242, 375, 3),
        ] {
            let t = tile_regions(w, h, n, 0.2);
            assert!(!t.is_empty());
            for r in &t {
                assert!(
                    r.x0 + r.width <= w && r.y0 + r.height <= h,
                    "{w}x{h} {n}: {r:?}"
                );
                assert_eq!(r.width, r.height);
            }
            // Every pixel is in some tile.
            for y in (0..h).step_by(7) {
                for x in (0..w).step_by(7) {
                    assert!(
                        t.iter().any(|r| x >= r.x0
                            && x < r.x0 + r.width
                            && y >= r.y0
                            && y < r.y0 + r.height),
                        "{w}x{h} {n}: ({x}, {y}) uncovered"
                    );
                }
            }
        }
        assert!(tile_regions(1920, 1080, 0, 0.2).is_empty());
        assert_eq!(tile_regions(1920, 1080, 2, 0.2).len(), 2);
        assert_eq!(tile_regions(1920, 1080, 3, 0.2).len(), 6);
    }

    #[test]
    fn tile_merge_drops_cut_boxes_and_keeps_one_box_per_vehicle() {
        let frame = (1920, 1080);
        let whole = Letterbox::new(Region::whole(1920, 1080), 416);
        let tile = Letterbox::new(
            Region {
                x0: 840,
                y0: 0,
                width: 1080,
                height: 1080,
            },
            416,
        );
        let (sx, _) = whole.scale();
        let (tx, _) = tile.scale();
        // One vehicle at x 1000-1100, y 500-560, seen by both passes; one far vehicle only in
        // the tile; one box cut by the tile's left border (x 840).
        let in_whole = |x0: f64, y0: f64, x1: f64, y1: f64| [x0 / sx, y0 / sx, x1 / sx, y1 / sx];
        let in_tile = |x0: f64, y0: f64, x1: f64, y1: f64| {
            [(x0 - 840.0) / tx, y0 / tx, (x1 - 840.0) / tx, y1 / tx]
        };
        let cand = |bbox, score| Candidate {
            bbox,
            score,
            class: 2,
        };
        let merged = merge_passes(
            vec![
                (
                    whole,
                    vec![cand(in_whole(1000.0, 500.0, 1100.0, 560.0), 0.7)],
                ),
                (
                    tile,
                    vec![
                        cand(in_tile(1002.0, 501.0, 1101.0, 560.0), 0.8),
                        cand(in_tile(1500.0, 200.0, 1520.0, 212.0), 0.5),
                        cand(in_tile(840.0, 700.0, 900.0, 760.0), 0.9),
                    ],
                ),
            ],
            frame,
            0.45,
            100,
        );
        assert_eq!(merged.len(), 2, "{merged:?}");
        assert!((merged[0].score - 0.8).abs() < 1e-6);
        assert!((merged[0].bbox.x0 - 1002.0).abs() < 1e-6);
        assert!((merged[1].bbox.x0 - 1500.0).abs() < 1e-6);
    }

    #[test]
    fn sha1_of_known_bytes() {
        assert_eq!(sha1_hex(b"abc"), "a9993e364706816aba3e25717850c26c9cd0d89d");
    }
}
