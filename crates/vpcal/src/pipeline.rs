//! The calibration pipeline, in process: footage of a fixed traffic camera to per-vehicle
//! VP records, and the records to a camera.
//!
//! ```text
//! frames (ffmpeg | folder | image) -> detector (learned | motion | file) -> per-frame filter
//!   -> crops (bicubic, network input) -> VP network, batched -> decode with scale selection
//!   -> VPs in frame pixels, one record per vehicle box -> aggregation (robust | reference)
//! ```
//!
//! Memory stays bounded: frames are dropped as soon as their crops are cut; only the
//! per-vehicle records (a few hundred bytes each) and one picture for the overlay are kept.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use image::RgbImage;
use vpcal_formats::reference::{edgelet_row, VpOutItem};
use vpcal_geom::aggregate::edgelets::{near_rays, Edgelet, EdgeletFitOptions};
use vpcal_geom::aggregate::verticals::Segment;
use vpcal_geom::aggregate::VehicleVps;
use vpcal_geom::camera::Calibration;
use vpcal_geom::heatmap::VpPrediction;
use vpcal_geom::{BoxPx, Point2};
use vpcal_net::VpNet;
use vpcal_video::background::{scene_edgelet_options, scene_edgelets, BackgroundSampler};
use vpcal_video::crop::{context_box, integer_box, CropFilter, CropResizer};
use vpcal_video::detect::Detection;
use vpcal_video::edgelets::{edgelets_in_box, EdgeletOptions};
use vpcal_video::filter::{DropReason, FilterConfig, FrameFilter};
use vpcal_video::segments::{line_segments, SegmentOptions};
use vpcal_video::{Detector, Frame, FrameSource, SourceInfo, SourceKind, SourceOptions};

use crate::aggregate::{aggregate, Aggregated, Method, Scene};
use crate::crop_plan::{CropPlanSettings, CropPlanner};
pub use crate::detector::is_stills;
use crate::detector::{open_detector, DetectorSettings};
use crate::model::load_model;
use crate::progress::{FrameProgress, Progress};

/// IoU above which a box of a still is the vehicle a box of an earlier still was (parked cars
/// in a folder of pictures of one camera move by a few pixels at most between detections).
pub const STILLS_SEEN_IOU: f64 = 0.7;

/// Frames the scene's background is the median of (at most; at least half as many on inputs
/// that long), spread evenly over the input.
const BACKGROUND_FRAMES: usize = 32;

/// At most this many records keep their edgelets (see [`EdgeletBudget`]): the aggregation
/// fits at most 20,000 edgelets, which 4096 vehicles' near-ray edgelets cover many times.
pub const EDGELET_RECORDS: usize = 4096;

/// At most this many vehicle records are kept by default (`--max-records`; see
/// [`RecordBudget`]): about 50 MB with their boxes. A dense 1080p motorway gives about ten
/// records a frame, so this is some 10,000 frames of it (several hundred vehicles, far more
/// than the aggregation needs) and about an hour of light traffic.
pub const MAX_RECORDS: usize = 100_000;

/// The blocks of consecutive frames [`RecordBudget`] keeps or drops whole (20 s at 25
/// frames/s: a vehicle's track is cut only at a block's ends).
pub const RECORD_BLOCK_FRAMES: u64 = 500;

/// The principal point when none is given.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PrincipalPoint {
    /// The image centre `(W/2, H/2)`: pixel `(i, j)` covers `[i, i+1) x [j, j+1)`, the
    /// coordinates of vpcal's frames, boxes and crops.
    Centre,
    /// BrnoCompSpeed's `(W/2 + 0.5, H/2 + 0.5)`, for VPs computed in its convention.
    Bcs,
    /// A given point, pixels.
    At(Point2),
}

impl PrincipalPoint {
    /// The point for a `width` x `height` image.
    pub fn resolve(self, width: u32, height: u32) -> Point2 {
        let (w, h) = (f64::from(width), f64::from(height));
        match self {
            PrincipalPoint::Centre => Point2::new(w / 2.0, h / 2.0),
            PrincipalPoint::Bcs => Point2::new(w / 2.0 + 0.5, h / 2.0 + 0.5),
            PrincipalPoint::At(p) => p,
        }
    }

    /// How settings files record it: `centre`, `bcs` or `[x, y]`.
    pub fn to_json(self) -> serde_json::Value {
        match self {
            PrincipalPoint::Centre => "centre".into(),
            PrincipalPoint::Bcs => "bcs".into(),
            PrincipalPoint::At(p) => serde_json::json!([p.x, p.y]),
        }
    }
}

impl std::str::FromStr for PrincipalPoint {
    type Err = String;

    fn from_str(s: &str) -> Result<PrincipalPoint, String> {
        match s {
            "centre" | "center" => Ok(PrincipalPoint::Centre),
            "bcs" => Ok(PrincipalPoint::Bcs),
            _ => {
                let parts: Vec<Option<f64>> = s
                    .split(',')
                    .map(|v| v.trim().parse::<f64>().ok().filter(|v| v.is_finite()))
                    .collect();
                match parts[..] {
                    [Some(x), Some(y)] => Ok(PrincipalPoint::At(Point2::new(x, y))),
                    _ => Err(format!(
                        "expected `centre`, `bcs` or a point x,y (finite numbers), got {s:?}"
                    )),
                }
            }
        }
    }
}

/// Which vehicle boxes go through the VP network.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CropPolicy {
    /// A few per followed vehicle on frames wider than [`FEW_CROPS_ABOVE_WIDTH`], every box
    /// on smaller ones.
    Auto,
    /// Every box of every frame.
    All,
    /// A few boxes per followed vehicle ([`crate::crop_plan`]).
    Few,
}

/// Frames wider than this send a few boxes per vehicle to the network by default. There the
/// network on every box is half the pipeline's time (1080p: 2,959 crops in 300 frames of a
/// motorway, 56 ms a frame against the detector's 121) and a vehicle stays in view for tens
/// of frames. At and below it every box goes, as the calibrations of the small real clips
/// were measured (on a 320x240 highway with the motion detector, 200 frames, a few crops per
/// vehicle led the aggregation to a horizon the vehicles' sizes contradict, where every box
/// calibrates), and those clips already run at 10-20 frames/s. The width at which the learned
/// detector starts to tile the frame ([`crate::detector::default_tiles`]).
pub const FEW_CROPS_ABOVE_WIDTH: u32 = 960;

impl CropPolicy {
    /// Whether frames `width` pixels wide send a few boxes per vehicle.
    pub fn few(self, width: u32) -> bool {
        match self {
            CropPolicy::Auto => width > FEW_CROPS_ABOVE_WIDTH,
            CropPolicy::All => false,
            CropPolicy::Few => true,
        }
    }
}

impl std::str::FromStr for CropPolicy {
    type Err = String;

    fn from_str(s: &str) -> Result<CropPolicy, String> {
        match s {
            "auto" => Ok(CropPolicy::Auto),
            "all" => Ok(CropPolicy::All),
            "few" => Ok(CropPolicy::Few),
            other => Err(format!("{other:?}: expected auto, all or few")),
        }
    }
}

/// Everything the pipeline needs to know, validated by [`PipelineConfig::validate`].
#[derive(Debug, Clone)]
pub struct PipelineConfig {
    /// VP network weights; `None`: the bundled model.
    pub model: Option<PathBuf>,
    /// `cpu`, or `wgpu` in builds with that feature.
    pub device: String,
    /// Crops per network batch.
    pub batch: usize,
    /// Average every crop's heatmaps with its mirror image's.
    pub flip_average: bool,
    /// Boxes whose larger side is under this many pixels are cut for the network with the
    /// road around them ([`context_box`]); 0: every crop is cut at its box.
    pub min_crop_px: f64,
    /// Look for edgelets inside the boxes (VP2 evidence for the roll and focal length).
    pub edgelets: bool,
    /// Look again at the frames the motion detector spent learning its background.
    pub replay: bool,
    /// Which frames are processed (`image_fps` makes a folder a frame sequence).
    pub frames: SourceOptions,
    pub detector: DetectorSettings,
    /// Drop boxes whose detector score is not above this.
    pub min_score: f64,
    /// Keep vehicles that do not move between processed frames.
    pub keep_static: bool,
    /// At most this many boxes per frame, best first (0: no limit).
    pub max_per_frame: usize,
    /// Which boxes go through the network: every box, or a few per followed vehicle
    /// ([`crate::crop_plan`]; stills always send every box).
    pub crops: CropPolicy,
    pub method: Method,
    /// Bootstrap resamples of the robust method (0: none).
    pub bootstrap: usize,
    pub pp: PrincipalPoint,
    /// A known focal length, pixels (from the camera's data sheet): VP1 and the horizon
    /// still come from the footage.
    pub focal_px: Option<f64>,
    /// The focal lengths the camera can have, `[short, long]` pixels (e.g. a zoom lens's
    /// range): the prior the evidence is weighed against, instead of 15-90° views.
    pub focal_range_px: Option<[f64; 2]>,
    /// At most this many vehicle records are kept ([`RecordBudget`]).
    pub max_records: usize,
    /// The road's marking standard: its lane lines become known lengths for the focal
    /// length and the scale ([`crate::markings`]).
    pub markings: Option<crate::markings::MarkingStandard>,
}

impl Default for PipelineConfig {
    fn default() -> PipelineConfig {
        PipelineConfig {
            model: None,
            device: "cpu".to_string(),
            batch: 32,
            flip_average: false,
            min_crop_px: 0.0,
            edgelets: true,
            replay: true,
            frames: SourceOptions::default(),
            detector: DetectorSettings::default(),
            min_score: 0.1,
            keep_static: false,
            max_per_frame: 10,
            crops: CropPolicy::Auto,
            method: Method::Robust,
            bootstrap: 30,
            pp: PrincipalPoint::Centre,
            focal_px: None,
            focal_range_px: None,
            max_records: MAX_RECORDS,
            markings: None,
        }
    }
}

impl PipelineConfig {
    /// Check the settings that do not depend on the input.
    ///
    /// # Errors
    /// A message naming the setting (by its flag) and what was expected.
    pub fn validate(&self) -> Result<()> {
        if self.batch == 0 {
            bail!("--batch must be at least 1");
        }
        if self.max_records == 0 {
            bail!("--max-records must be at least 1");
        }
        if !self.min_score.is_finite() {
            bail!("--min-score must be a number");
        }
        if !(self.min_crop_px.is_finite() && self.min_crop_px >= 0.0) {
            bail!(
                "--min-crop-px {}: expected a number of pixels, 0 or more",
                self.min_crop_px
            );
        }
        if let Some(f) = self.focal_px {
            if !(f.is_finite() && f > 0.0) {
                bail!("--focal {f}: expected a positive number of pixels");
            }
        }
        crate::aggregate::check_focal_settings(self.focal_px, self.focal_range_px)
            .map_err(anyhow::Error::msg)?;
        self.frames
            .validate()
            .map_err(|e| anyhow::anyhow!("invalid frame selection: {e}"))?;
        self.detector.validate()
    }
}

/// Open `input` with frame selection `options`, checked (a bad selection is an error naming
/// the flag). A frame rate (`--fps`) makes an image folder a frame sequence, and times a
/// video's frames at that rate instead of the one its container states.
///
/// # Errors
/// The selection's or the source's error, naming the input.
pub fn open_input(input: &Path, options: &SourceOptions) -> Result<Box<dyn FrameSource>> {
    options
        .validate()
        .map_err(|e| anyhow::anyhow!("invalid frame selection: {e}"))?;
    // The source's errors name the input.
    let source = vpcal_video::open_source(input, options)?;
    match options.image_fps {
        Some(fps) if source.info().kind == SourceKind::Video => {
            Ok(vpcal_video::source::with_frame_rate(source, fps).0)
        }
        _ => Ok(source),
    }
}

/// A detector box that may belong to a moving vehicle: kept for the network, or dropped only
/// by the per-frame limit (the network's budget, not the tracks').
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackBox {
    /// 0-based frame index in the source.
    pub frame: u64,
    pub bbox: BoxPx,
    pub score: f32,
}

/// One vehicle box seen by the network.
#[derive(Debug, Clone)]
pub struct VehicleRecord {
    /// 0-based frame index in the source.
    pub frame: u64,
    /// Detector score.
    pub score: f32,
    /// The box frame of the crop (clamped integer box), frame pixels.
    pub crop_box: BoxPx,
    /// The detector's box as it gave it (sub-pixel, not rounded to the crop's integer box),
    /// frame pixels: what tracks and speeds use.
    pub det_box: BoxPx,
    /// The decoded network output, box frame; `None` for a box of a followed vehicle the
    /// network did not see ([`crate::crop_plan`]).
    pub prediction: Option<VpPrediction>,
    /// VP1 and VP2 in frame pixels: the network's for this box, or without a prediction
    /// copied from the latest box of the same vehicle it saw (NaN when it saw none).
    pub vp1: Point2,
    pub vp2: Point2,
    /// Edgelets inside the box near the VP rays (empty with `--no-edgelets`).
    pub edgelets: Vec<Edgelet>,
}

#[cfg(test)]
impl VehicleRecord {
    /// A record of the box `b` alone (score 0.9, no network output, no edgelets), for tests.
    pub(crate) fn of_box(frame: u64, b: BoxPx) -> VehicleRecord {
        VehicleRecord {
            frame,
            score: 0.9,
            crop_box: b,
            det_box: b,
            prediction: None,
            vp1: Point2::new(0.0, 0.0),
            vp2: Point2::new(0.0, 0.0),
            edgelets: vec![],
        }
    }
}

impl VehicleRecord {
    pub fn to_vehicle(&self) -> VehicleVps {
        VehicleVps {
            vp1: self.vp1,
            vp2: self.vp2,
            score: f64::from(self.score),
            box_px: Some(self.crop_box),
            frame: Some(self.frame as f64),
            vp1_spread: self.prediction.as_ref().map(VpPrediction::vp1_spread),
            vp2_spread: self.prediction.as_ref().map(VpPrediction::vp2_spread),
            copied: self.prediction.is_none(),
        }
    }

    /// The record in deep_vp's `VPout` layout (frame-normalised box `[ymin, xmin, ymax, xmax]`).
    pub fn to_vpout(&self, width: u32, height: u32) -> VpOutItem {
        let b = &self.crop_box;
        let (w, h) = (f64::from(width), f64::from(height));
        let p = self.prediction.as_ref();
        VpOutItem {
            frame_cnt: self.frame as f64,
            score: f64::from(self.score),
            vp1: self.vp1,
            vp2: self.vp2,
            box_norm: Some([b.y0 / h, b.x0 / w, b.y1 / h, b.x1 / w]),
            box_center: Some(b.center()),
            box_scale: Some(b.half_size()),
            vp_box: Some([b.y0, b.x0, b.y1, b.x1]),
            vp1_box: p.map(|p| p.vp1),
            vp2_box: p.map(|p| p.vp2),
            pred_vps: p.map_or_else(Vec::new, |p| {
                p.per_scale
                    .iter()
                    .map(|[a, b]| [a.x, a.y, b.x, b.y])
                    .collect()
            }),
            pred_vars: p.map_or_else(Vec::new, |p| p.spreads.clone()),
            vp1_var: p.map(VpPrediction::vp1_spread),
            vp2_var: p.map(VpPrediction::vp2_spread),
            vps_copied: p.is_none() && self.vp1.is_finite(),
            edgelets: self.edgelets.iter().map(edgelet_row).collect(),
        }
    }
}

/// Counts of what the pipeline saw.
#[derive(Debug, Clone, Default)]
pub struct PipelineStats {
    pub frames: u64,
    /// Frames looked at a second time, after the detector's warm-up (see [`run_pipeline_on`]).
    pub replayed_frames: u64,
    pub detections: u64,
    pub dropped_low_score: u64,
    pub dropped_static: u64,
    pub dropped_over_limit: u64,
    pub dropped_outside: u64,
    /// Boxes of a still-image folder at the place of a box kept in an earlier picture.
    pub dropped_seen: u64,
    pub crops: u64,
    /// Boxes of followed vehicles the network did not see again (records without VPs).
    pub crops_skipped: u64,
    /// Every how many blocks of [`RECORD_BLOCK_FRAMES`] frames one kept its records (1: all).
    pub record_block_stride: u64,
    pub seconds: f64,
    /// Where the time went, per stage.
    pub stages: StageSeconds,
}

/// Seconds spent in each stage of the pipeline (wall time, summed over frames).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct StageSeconds {
    /// Reading and decoding frames (both passes).
    pub decode: f64,
    /// The detector.
    pub detect: f64,
    /// The per-frame filter of its boxes (score, static vehicles, per-frame limit).
    pub filter: f64,
    /// Cutting and resizing the crops for the network.
    pub crop: f64,
    /// The edgelets inside the vehicle boxes.
    pub edgelets: f64,
    /// The VP network on the batched crops, and decoding its heatmaps.
    pub network: f64,
    /// Sampling frames for the background, its median and the scene's edgelets.
    pub background: f64,
}

impl StageSeconds {
    /// The stages by name, in pipeline order.
    pub fn named(&self) -> [(&'static str, f64); 7] {
        [
            ("decode", self.decode),
            ("detect", self.detect),
            ("filter", self.filter),
            ("crop", self.crop),
            ("edgelets", self.edgelets),
            ("network", self.network),
            ("background", self.background),
        ]
    }
}

/// Everything the pipeline produced before aggregation.
#[derive(Debug)]
pub struct PipelineOutput {
    pub info: SourceInfo,
    pub detector: String,
    pub model: String,
    pub records: Vec<VehicleRecord>,
    /// Every detector box of a possibly moving vehicle, in frame order (the records' boxes
    /// and those the per-frame limit kept from the network): what tracks are linked from.
    pub boxes: Vec<TrackBox>,
    pub stats: PipelineStats,
    /// A picture of the scene for the overlay: the last frame.
    pub picture: Option<RgbImage>,
    /// The edgelets of the scene's background (the median of frames sampled over the input,
    /// `vpcal_video::background`): the lines along the road that place VP1. Empty with
    /// `--no-edgelets`.
    pub scene_edgelets: Vec<Edgelet>,
    /// The straight line segments of the scene's background (`vpcal_video::segments`): its
    /// vertical lines measure the focal length. Empty with `--no-edgelets`.
    pub scene_segments: Vec<Segment>,
    /// The scene's background: the median of frames sampled over the input (grey levels),
    /// where its road markings are found. `None` with `--no-edgelets`.
    pub background: Option<image::GrayImage>,
    /// What the user should know about the input (a truncated video, unreadable pictures).
    pub warnings: Vec<String>,
}

/// Records keep their edgelets for an evenly spaced subset of at most `cap` of them: every
/// record at first; whenever more than `cap` hold edgelets, only every second of those keeps
/// them, and so on. The aggregation fits at most 20,000 edgelets (a few hundred vehicles), so
/// this bounds memory and time on long inputs (an hour at every frame is ~450,000 records) and
/// changes nothing on short ones.
#[derive(Debug)]
pub struct EdgeletBudget {
    cap: usize,
    stride: usize,
    holding: usize,
}

impl EdgeletBudget {
    pub fn new(cap: usize) -> EdgeletBudget {
        EdgeletBudget {
            cap,
            stride: 1,
            holding: 0,
        }
    }

    /// Whether the record with this index keeps its edgelets.
    pub fn keeps(&self, index: usize) -> bool {
        index % self.stride == 0
    }

    /// Account for the record just pushed (the last one); `edgelets` gives a record's list.
    pub fn pushed<T>(&mut self, records: &mut [T], edgelets: impl Fn(&mut T) -> &mut Vec<Edgelet>) {
        let Some(i) = records.len().checked_sub(1) else {
            return;
        };
        if !self.keeps(i) {
            *edgelets(&mut records[i]) = Vec::new();
            return;
        }
        if !edgelets(&mut records[i]).is_empty() {
            self.holding += 1;
        }
        self.within_cap(records, &edgelets);
    }

    /// After records were removed (by [`RecordBudget`]): only every stride-th of those left
    /// keeps its edgelets, within the cap.
    pub fn reindexed<T>(
        &mut self,
        records: &mut [T],
        edgelets: impl Fn(&mut T) -> &mut Vec<Edgelet>,
    ) {
        self.restride(records, &edgelets);
        self.within_cap(records, &edgelets);
    }

    fn within_cap<T>(
        &mut self,
        records: &mut [T],
        edgelets: &impl Fn(&mut T) -> &mut Vec<Edgelet>,
    ) {
        while self.holding > self.cap {
            self.stride *= 2;
            self.restride(records, edgelets);
        }
    }

    /// Drop the edgelets of records off the stride and count those holding some.
    fn restride<T>(&mut self, records: &mut [T], edgelets: &impl Fn(&mut T) -> &mut Vec<Edgelet>) {
        self.holding = 0;
        for (j, r) in records.iter_mut().enumerate() {
            let list = edgelets(r);
            if j % self.stride != 0 {
                *list = Vec::new();
            } else if !list.is_empty() {
                self.holding += 1;
            }
        }
    }
}

/// Bounds the vehicle records and track boxes a long input leaves in memory: every frame's at
/// first; whenever more than `cap` records are kept, only every second block of
/// [`RECORD_BLOCK_FRAMES`] frames of those kept keeps its records and boxes, and so on. What
/// is kept is then blocks of whole tracks spread evenly over the input (like processing one
/// stretch of footage out of every 2, 4, ...), so memory stays flat however long the input,
/// and nothing changes on inputs that stay under the cap.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RecordBudget {
    cap: usize,
    /// Every `stride`-th block is kept.
    stride: u64,
}

impl RecordBudget {
    pub fn new(cap: usize) -> RecordBudget {
        RecordBudget {
            cap: cap.max(1),
            stride: 1,
        }
    }

    /// Whether the records and boxes of source frame `frame` are kept.
    pub fn keeps(&self, frame: u64) -> bool {
        (frame / RECORD_BLOCK_FRAMES) % self.stride == 0
    }

    /// Every how many blocks one is kept (1: all).
    pub fn stride(&self) -> u64 {
        self.stride
    }

    /// Thin `records` and `boxes` (blocks at a doubled stride) while more than the cap of
    /// records are kept and they span more than the first block (which is always kept: a cap
    /// below one block's records keeps that block); `frame_of` gives a record's frame.
    /// Returns whether anything went.
    pub fn thin<R>(
        &mut self,
        records: &mut Vec<R>,
        boxes: &mut Vec<TrackBox>,
        frame_of: impl Fn(&R) -> u64,
    ) -> bool {
        let mut thinned = false;
        while records.len() > self.cap && records.iter().any(|r| frame_of(r) >= RECORD_BLOCK_FRAMES)
        {
            self.stride *= 2;
            records.retain(|r| self.keeps(frame_of(r)));
            boxes.retain(|b| self.keeps(b.frame));
            thinned = true;
        }
        thinned
    }
}

/// Only the edgelets of box `b` near the rays to `vp1` and `vp2` (the `gate` options) are
/// kept (memory).
fn near_vps(
    gate: &EdgeletFitOptions,
    b: &BoxPx,
    vp1: Point2,
    vp2: Point2,
    edgelets: &[Edgelet],
) -> Vec<Edgelet> {
    near_rays(
        b.center(),
        vp1,
        vp2,
        edgelets,
        gate.gate_vp2_deg,
        gate.max_per_vehicle,
    )
}

/// A crop waiting for its batch: frame, score, the record's box (the detection's
/// integer box), the detector's box, edgelets, vehicle, and the box the crop was cut at
/// (the VPs' frame; larger than the record's box for small boxes with `min_crop_px`).
type Pending = (u64, f32, BoxPx, BoxPx, Vec<Edgelet>, Option<u64>, BoxPx);

/// A box the network does not see, waiting for its vehicle's first network VPs (its
/// edgelets not yet gated by them).
#[derive(Debug)]
struct Waiting {
    frame: u64,
    score: f32,
    crop_box: BoxPx,
    det_box: BoxPx,
    vehicle: u64,
    edgelets: Vec<Edgelet>,
}

/// Everything after the detector: filter, crops, edgelets, batched network, records.
struct Stages<'a> {
    net: &'a VpNet,
    config: &'a PipelineConfig,
    resizer: CropResizer,
    crop_len: usize,
    /// Crops waiting for a full batch, and their (frame, score, box, edgelets).
    pending: Vec<f32>,
    pending_meta: Vec<Pending>,
    records: Vec<VehicleRecord>,
    boxes: Vec<TrackBox>,
    /// Boxes not sent to the network, until their vehicle has network VPs.
    waiting: Vec<Waiting>,
    /// The latest network VPs of each followed vehicle.
    vehicle_vps: std::collections::HashMap<u64, (Point2, Point2)>,
    budget: EdgeletBudget,
    records_budget: RecordBudget,
    edgelet_options: EdgeletOptions,
    gate: EdgeletFitOptions,
    stats: PipelineStats,
}

impl<'a> Stages<'a> {
    fn new(net: &'a VpNet, config: &'a PipelineConfig) -> Result<Stages<'a>> {
        let resizer = CropResizer::new(net.config().input_size as u32, CropFilter::default())?;
        let crop_len = resizer.crop_len();
        Ok(Stages {
            net,
            config,
            resizer,
            crop_len,
            pending: Vec::with_capacity(config.batch * crop_len),
            pending_meta: Vec::with_capacity(config.batch),
            records: Vec::new(),
            boxes: Vec::new(),
            waiting: Vec::new(),
            vehicle_vps: std::collections::HashMap::new(),
            budget: EdgeletBudget::new(EDGELET_RECORDS),
            records_budget: RecordBudget::new(config.max_records),
            edgelet_options: EdgeletOptions::default(),
            gate: EdgeletFitOptions::default(),
            stats: PipelineStats::default(),
        })
    }

    /// The crop planner of one pass over consecutive frames; `None` (every box to the
    /// network) for stills or where the policy sends every box.
    fn planner(&self, info: &SourceInfo) -> Option<CropPlanner> {
        (self.config.crops.few(info.width) && !is_stills(info))
            .then(|| CropPlanner::new(CropPlanSettings::for_step(self.config.frames.every.max(1))))
    }

    /// The per-frame filter (each pass over the frames gets its own: it compares a frame's
    /// boxes with the previous frame's). Stills are not consecutive frames: there a vehicle
    /// that stays in place (parked) counts once instead of being dropped as static.
    fn filter(&self, info: &SourceInfo) -> FrameFilter {
        let stills = is_stills(info);
        FrameFilter::new(FilterConfig {
            min_score: Some(self.config.min_score as f32),
            drop_static: !self.config.keep_static && !stills,
            drop_seen_iou: (stills && !self.config.keep_static).then_some(STILLS_SEEN_IOU),
            max_per_frame: (self.config.max_per_frame > 0).then_some(self.config.max_per_frame),
            ..FilterConfig::default()
        })
    }

    /// Detect, filter and crop the vehicles of one frame; full batches go through the network.
    fn frame(
        &mut self,
        frame: &Frame,
        detector: &mut dyn Detector,
        filter: &mut FrameFilter,
        planner: Option<&mut CropPlanner>,
    ) -> Result<()> {
        let t = Instant::now();
        let dets = detector
            .detect(frame)
            .with_context(|| format!("detecting vehicles in frame {}", frame.index))?;
        self.stats.stages.detect += t.elapsed().as_secs_f64();
        self.detected(frame, dets, filter, planner)
    }

    /// Filter and crop the vehicles `dets` the detector found in `frame`; full batches go
    /// through the network.
    fn detected(
        &mut self,
        frame: &Frame,
        dets: Vec<Detection>,
        filter: &mut FrameFilter,
        planner: Option<&mut CropPlanner>,
    ) -> Result<()> {
        self.stats.detections += dets.len() as u64;
        let t = Instant::now();
        let filtered = filter.apply(frame, dets);
        self.stats.stages.filter += t.elapsed().as_secs_f64();
        for (_, why) in &filtered.dropped {
            match why {
                DropReason::LowScore => self.stats.dropped_low_score += 1,
                DropReason::Static => self.stats.dropped_static += 1,
                DropReason::OverLimit => self.stats.dropped_over_limit += 1,
                DropReason::OutsideFrame => self.stats.dropped_outside += 1,
                DropReason::SeenBefore => self.stats.dropped_seen += 1,
            }
        }
        // A frame of a block the record budget has dropped keeps nothing: it only moves the
        // filter on (and a followed vehicle's gap ends it in the crop planner).
        if !self.records_budget.keeps(frame.index) {
            return Ok(());
        }
        let over_limit = filtered
            .dropped
            .iter()
            .filter(|(_, why)| *why == DropReason::OverLimit)
            .map(|(d, _)| d);
        self.boxes
            .extend(filtered.kept.iter().chain(over_limit).map(|d| TrackBox {
                frame: frame.index,
                bbox: d.bbox,
                score: d.score,
            }));
        if filtered.kept.is_empty() {
            return Ok(());
        }
        let boxes: Vec<BoxPx> = filtered.kept.iter().map(|d| d.bbox).collect();
        let plan: Vec<(bool, Option<u64>)> = match planner {
            Some(p) => p
                .plan(frame.index, &boxes)
                .into_iter()
                .map(|(send, id)| (send, Some(id)))
                .collect(),
            None => vec![(true, None); boxes.len()],
        };
        // The boxes the network does not see this time still make records (the tracks and
        // the aggregation's vehicle links use every box), with their edgelets, which their
        // vehicle's network VPs gate once it has them.
        let (w, h) = frame.image.dimensions();
        for (d, (_, vehicle)) in filtered.kept.iter().zip(&plan).filter(|(_, p)| !p.0) {
            let (Some(ib), Some(vehicle)) = (integer_box(&d.bbox, w, h), *vehicle) else {
                continue;
            };
            let crop_box = ib.to_box_px();
            let edgelets = self.box_edgelets(&frame.image, &crop_box);
            self.waiting.push(Waiting {
                frame: frame.index,
                score: d.score,
                crop_box,
                det_box: d.bbox,
                vehicle,
                edgelets,
            });
            self.stats.crops_skipped += 1;
        }
        self.resolve_waiting(false);
        let sent: Vec<usize> = (0..boxes.len()).filter(|&i| plan[i].0).collect();
        if sent.is_empty() {
            return Ok(());
        }
        let sent_boxes: Vec<BoxPx> = sent.iter().map(|&i| boxes[i]).collect();
        let t = Instant::now();
        let cut_boxes: Vec<BoxPx> = sent_boxes
            .iter()
            .map(|b| context_box(b, self.config.min_crop_px))
            .collect();
        let batch = self.resizer.crop_batch(&frame.image, &cut_boxes)?;
        self.stats.stages.crop += t.elapsed().as_secs_f64();
        let len = self.crop_len;
        for (k, (&cut, &cut_box)) in batch.source.iter().zip(&batch.boxes).enumerate() {
            let src = sent[cut];
            // The record keeps the detection's own integer box (sizes, tracks, edgelets).
            let bp = integer_box(&sent_boxes[cut], w, h).map_or(cut_box, |ib| ib.to_box_px());
            self.pending
                .extend_from_slice(&batch.images[k * len..(k + 1) * len]);
            let edgelets = self.box_edgelets(&frame.image, &bp);
            let kept = &filtered.kept[src];
            self.pending_meta.push((
                frame.index,
                kept.score,
                bp,
                kept.bbox,
                edgelets,
                plan[src].1,
                cut_box,
            ));
            self.stats.crops += 1;
            if self.pending_meta.len() >= self.config.batch {
                self.flush()?;
            }
        }
        Ok(())
    }

    /// Run the waiting crops through the network and keep their records.
    fn flush(&mut self) -> Result<()> {
        if self.pending_meta.is_empty() {
            return Ok(());
        }
        let t = Instant::now();
        let preds = self.net.predict_prepared(&self.pending)?;
        let mut meta = std::mem::take(&mut self.pending_meta);
        for ((frame, score, crop_box, det_box, edgelets, vehicle, cut_box), p) in
            meta.drain(..).zip(preds)
        {
            let prediction = p.vp;
            let vp1 = cut_box.frame_from_box(prediction.vp1);
            let vp2 = cut_box.frame_from_box(prediction.vp2);
            if let Some(id) = vehicle {
                self.vehicle_vps.insert(id, (vp1, vp2));
            }
            let edgelets = near_vps(&self.gate, &crop_box, vp1, vp2, &edgelets);
            self.keep(VehicleRecord {
                frame,
                score,
                crop_box,
                det_box,
                vp1,
                vp2,
                prediction: Some(prediction),
                edgelets,
            });
        }
        self.pending_meta = meta;
        self.pending.clear();
        self.stats.stages.network += t.elapsed().as_secs_f64();
        self.resolve_waiting(false);
        Ok(())
    }

    /// The edgelets in box `b` of `image` for the record about to be made (none with
    /// `--no-edgelets` or where the edgelet budget skips it).
    fn box_edgelets(&mut self, image: &RgbImage, b: &BoxPx) -> Vec<Edgelet> {
        let index = self.records.len() + self.pending_meta.len() + self.waiting.len();
        if !self.config.edgelets || !self.budget.keeps(index) {
            return Vec::new();
        }
        let t = Instant::now();
        let found = edgelets_in_box(image, b, &self.edgelet_options);
        self.stats.stages.edgelets += t.elapsed().as_secs_f64();
        found
    }

    /// Records for the waiting boxes whose vehicle has network VPs now (copied to them;
    /// their edgelets gated by them); with `last`, also for the rest, without VPs.
    fn resolve_waiting(&mut self, last: bool) {
        let waiting = std::mem::take(&mut self.waiting);
        for w in waiting {
            let vps = self.vehicle_vps.get(&w.vehicle).copied();
            if vps.is_none() && !last {
                self.waiting.push(w);
                continue;
            }
            let t = Instant::now();
            let nan = Point2::new(f64::NAN, f64::NAN);
            let (vp1, vp2) = vps.unwrap_or((nan, nan));
            let edgelets = match vps {
                Some(_) => near_vps(&self.gate, &w.crop_box, vp1, vp2, &w.edgelets),
                None => Vec::new(),
            };
            self.stats.stages.edgelets += t.elapsed().as_secs_f64();
            self.keep(VehicleRecord {
                frame: w.frame,
                score: w.score,
                crop_box: w.crop_box,
                det_box: w.det_box,
                prediction: None,
                vp1,
                vp2,
                edgelets,
            });
        }
    }

    /// Keep a record, within the edgelet and record budgets (a record of a frame whose block
    /// was dropped while it waited for its batch or its vehicle's VPs goes).
    fn keep(&mut self, record: VehicleRecord) {
        if !self.records_budget.keeps(record.frame) {
            return;
        }
        self.records.push(record);
        self.budget.pushed(&mut self.records, |r| &mut r.edgelets);
        if self
            .records_budget
            .thin(&mut self.records, &mut self.boxes, |r| r.frame)
        {
            self.waiting.retain(|w| self.records_budget.keeps(w.frame));
            self.budget
                .reindexed(&mut self.records, |r| &mut r.edgelets);
        }
    }
}

/// Run frames -> detections -> filter -> crops -> network on the video, image folder or image
/// at `input`, returning per-vehicle records.
///
/// # Errors
/// Bad settings, an unreadable input, a failing detector or network.
pub fn run_pipeline(
    input: &Path,
    config: &PipelineConfig,
    progress: &dyn Progress,
) -> Result<PipelineOutput> {
    let mut open = || open_input(input, &config.frames);
    run_pipeline_on(&mut open, config, progress)
}

/// [`run_pipeline`] on frames from `open`, which gives a fresh source each time it is called
/// (twice when the detector's warm-up frames are looked at again).
///
/// A detector that spends the first frames learning (the motion detector's warm-up) gets a
/// second look at them once the main pass is done: the input is opened again and those
/// frames go through [`Detector::replay`] (unless `replay` is off).
///
/// # Errors
/// As [`run_pipeline`].
pub fn run_pipeline_on(
    open: &mut dyn FnMut() -> Result<Box<dyn FrameSource>>,
    config: &PipelineConfig,
    progress: &dyn Progress,
) -> Result<PipelineOutput> {
    config.validate()?;
    let mut source = open()?;
    let (net, model) = load_model(config.model.as_deref(), &config.device)?;
    let net = net.with_flip_average(config.flip_average);
    let info = source.info().clone();
    let input = info.path.clone();
    let mut detector = open_detector(&config.detector, &info)?;
    let detector_name = detector.name();
    let mut stages = Stages::new(&net, config)?;
    let mut filter = stages.filter(&info);
    let mut planner = stages.planner(&info);

    progress.start(info.expected_frames(&config.frames));
    let t0 = Instant::now();
    let mut last_frame: Option<RgbImage> = None;
    let mut background = BackgroundSampler::new(BACKGROUND_FRAMES);
    let mut warnings = Vec::new();
    // Frames of the main pass that only taught the detector.
    let mut learning_frames = 0u64;
    let report = |stages: &Stages| {
        let s = &stages.stats;
        progress.frame_done(&FrameProgress {
            frames: s.frames + s.replayed_frames,
            seconds: t0.elapsed().as_secs_f64(),
            vehicle_boxes: s.crops,
        });
    };
    // The detector runs ahead in a thread of its own: while it looks at the next frames, this
    // thread decodes and sends the frames it has finished through the filter, the network and
    // the edgelets, which fill the core a learned detector leaves idle when its regions do not
    // divide evenly over the cores. A detector that gains from several frames at a time
    // ([`Detector::batch_frames`]) gets them: up to that many frames wait for it, and twice
    // that many are in flight. Frames are detected and processed in stream order, as before.
    let batch = detector.batch_frames().max(1);
    let (main, detector) = std::thread::scope(|scope| {
        let (to_detector, frames_in) = std::sync::mpsc::sync_channel::<Frame>(batch);
        let (detections_out, from_detector) = std::sync::mpsc::sync_channel::<Detected>(batch);
        let worker = scope.spawn(move || {
            while let Ok(first) = frames_in.recv() {
                let mut frames = vec![first];
                while frames.len() < batch {
                    match frames_in.try_recv() {
                        Ok(f) => frames.push(f),
                        Err(_) => break,
                    }
                }
                let t = Instant::now();
                let results = detector.detect_batch(&frames);
                let seconds = t.elapsed().as_secs_f64() / frames.len() as f64;
                let learned_until = detector.learned_until();
                for (frame, dets) in frames.into_iter().zip(results) {
                    let out = Detected {
                        frame,
                        dets,
                        seconds,
                        learned_until,
                    };
                    if detections_out.send(out).is_err() {
                        return detector;
                    }
                }
            }
            detector
        });
        let main = (|| -> Result<()> {
            let mut in_flight = 0usize;
            let mut read = 0u64;
            let mut ended = false;
            loop {
                if !ended {
                    let t = Instant::now();
                    let next = source.next();
                    stages.stats.stages.decode += t.elapsed().as_secs_f64();
                    match next {
                        None => ended = true,
                        Some(Ok(frame)) => {
                            read += 1;
                            if config.edgelets {
                                let t = Instant::now();
                                background.push(&frame.image);
                                stages.stats.stages.background += t.elapsed().as_secs_f64();
                            }
                            if to_detector.send(frame).is_err() {
                                bail!("the vehicle detector stopped");
                            }
                            in_flight += 1;
                        }
                        // A damaged or truncated input keeps the frames it gave.
                        Some(Err(e)) if read > 0 => {
                            warnings.push(format!(
                                "{}: stopped reading after {read} frames: {e}; the frames \
                                 before it are used",
                                input.display(),
                            ));
                            ended = true;
                        }
                        Some(Err(e)) => {
                            return Err(e).with_context(|| format!("reading {}", input.display()))
                        }
                    }
                }
                if in_flight == 0 {
                    return Ok(());
                }
                if in_flight < 2 * batch && !ended {
                    continue;
                }
                let Ok(d) = from_detector.recv() else {
                    bail!("the vehicle detector stopped");
                };
                in_flight -= 1;
                // Counted when processed, so that progress reports frames done.
                stages.stats.frames += 1;
                stages.stats.stages.detect += d.seconds;
                let index = d.frame.index;
                let dets = d
                    .dets
                    .with_context(|| format!("detecting vehicles in frame {index}"))?;
                stages.detected(&d.frame, dets, &mut filter, planner.as_mut())?;
                if d.learned_until.is_none_or(|until| index < until) {
                    learning_frames += 1;
                }
                report(&stages);
                last_frame = Some(d.frame.image);
            }
        })();
        // Closing both channels ends the detector's loop, whether it waits for a frame or
        // to hand one back.
        drop(to_detector);
        drop(from_detector);
        (main, worker.join())
    });
    main?;
    let Ok(detector) = detector else {
        bail!("the vehicle detector's thread panicked");
    };
    for w in source.warnings() {
        warnings.push(format!("{}: {w}", input.display()));
    }
    drop(source);
    let replay = match (detector.learned_until(), detector.replay()) {
        (Some(until), Some(replay)) if config.replay && learning_frames > 0 => {
            Some((until, replay))
        }
        _ => None,
    };
    if let Some((until, mut replay)) = replay {
        progress.add_frames(learning_frames);
        let mut source = open().with_context(|| format!("opening {} again", input.display()))?;
        let mut filter = stages.filter(&info);
        let mut planner = stages.planner(&info);
        loop {
            let t = Instant::now();
            let Some(Ok(frame)) = source.next() else {
                break;
            };
            stages.stats.stages.decode += t.elapsed().as_secs_f64();
            if frame.index >= until {
                break;
            }
            stages.stats.replayed_frames += 1;
            stages.frame(&frame, replay.as_mut(), &mut filter, planner.as_mut())?;
            report(&stages);
        }
    }
    stages.flush()?;
    stages.resolve_waiting(true);
    progress.finish();
    stages.stats.record_block_stride = stages.records_budget.stride();
    let Stages {
        mut records,
        mut boxes,
        mut stats,
        ..
    } = stages;
    if stats.record_block_stride > 1 {
        warnings.push(format!(
            "{}: more than {} vehicle records (--max-records): to keep memory flat, the \
             records, tracks and speeds are those of one block of {RECORD_BLOCK_FRAMES} frames \
             in every {}, spread evenly over the input",
            input.display(),
            config.max_records,
            stats.record_block_stride,
        ));
    }
    if stats.frames == 0 {
        bail!(
            "{}: no frames to process (empty input, or --start/--max-frames select none)",
            input.display()
        );
    }
    // The replayed frames come first in the stream.
    records.sort_by_key(|r| r.frame);
    boxes.sort_by_key(|b| b.frame);
    let t = Instant::now();
    let background = background.median();
    let scene_edgelets = background
        .as_ref()
        .map_or_else(Vec::new, |bg| scene_edgelets(bg, &scene_edgelet_options()));
    let scene_segments = background
        .as_ref()
        .map_or_else(Vec::new, |bg| line_segments(bg, &SegmentOptions::default()));
    stats.stages.background += t.elapsed().as_secs_f64();
    stats.seconds = t0.elapsed().as_secs_f64();
    Ok(PipelineOutput {
        info,
        detector: detector_name,
        model,
        records,
        boxes,
        stats,
        picture: last_frame,
        scene_edgelets,
        scene_segments,
        background,
        warnings,
    })
}

/// One frame back from the detector's thread, with what the detector found in it.
struct Detected {
    frame: Frame,
    dets: vpcal_video::Result<Vec<Detection>>,
    seconds: f64,
    /// [`Detector::learned_until`] after this frame.
    learned_until: Option<u64>,
}

/// The network's VPs for one vehicle box of a picture (see [`predict_boxes`]).
#[derive(Debug, Clone)]
pub struct BoxVps {
    /// The box's index in the boxes given.
    pub source: usize,
    /// The crop's box frame (clamped integer box), frame pixels.
    pub crop_box: BoxPx,
    /// The decoded network output, box frame.
    pub prediction: VpPrediction,
    /// VP1 and VP2 in frame pixels.
    pub vp1: Point2,
    pub vp2: Point2,
}

/// The network's VPs for vehicle `boxes` (any detector's) of one picture, cut and resized as
/// the pipeline cuts them; boxes that leave no crop inside the picture are left out.
///
/// # Errors
/// A failing crop or network.
pub fn predict_boxes(net: &VpNet, image: &RgbImage, boxes: &[BoxPx]) -> Result<Vec<BoxVps>> {
    let mut resizer = CropResizer::new(net.config().input_size as u32, CropFilter::default())?;
    let batch = resizer.crop_batch(image, boxes)?;
    if batch.boxes.is_empty() {
        return Ok(Vec::new());
    }
    let preds = net.predict_prepared(&batch.images)?;
    Ok(batch
        .source
        .iter()
        .zip(&batch.boxes)
        .zip(preds)
        .map(|((&source, &crop_box), p)| BoxVps {
            source,
            crop_box,
            vp1: crop_box.frame_from_box(p.vp.vp1),
            vp2: crop_box.frame_from_box(p.vp.vp2),
            prediction: p.vp,
        })
        .collect())
}

/// Aggregate the records of `out` into a camera.
///
/// # Errors
/// "Not enough evidence" (or a degenerate camera) as an error message.
pub fn calibrate(
    out: &PipelineOutput,
    config: &PipelineConfig,
) -> Result<(Calibration, Aggregated)> {
    let pp = config.pp.resolve(out.info.width, out.info.height);
    let vehicles: Vec<VehicleVps> = out.records.iter().map(VehicleRecord::to_vehicle).collect();
    let edgelets: Vec<Vec<Edgelet>> = out.records.iter().map(|r| r.edgelets.clone()).collect();
    let agg = aggregate(
        &vehicles,
        &edgelets,
        Scene {
            edgelets: &out.scene_edgelets,
            segments: &out.scene_segments,
        },
        pp,
        (out.info.width, out.info.height),
        config.method,
        config.min_score,
        config.bootstrap,
        config.focal_range_px,
    )?;
    agg.into_camera(pp, config.focal_px)
        .map_err(anyhow::Error::msg)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_edgelet_budget_keeps_an_evenly_spaced_bounded_subset() {
        let one = vec![Edgelet {
            x: 1.0,
            y: 2.0,
            angle: 0.0,
            strength: 9.0,
        }];
        let mut budget = EdgeletBudget::new(10);
        let mut records: Vec<Vec<Edgelet>> = Vec::new();
        for n in 1..=1000usize {
            // The pipeline computes edgelets only for the records the budget keeps.
            let list = if budget.keeps(records.len()) {
                one.clone()
            } else {
                Vec::new()
            };
            records.push(list);
            budget.pushed(&mut records, |r| r);
            let holding: Vec<usize> = (0..n).filter(|&i| !records[i].is_empty()).collect();
            assert!(holding.len() <= 10, "{n}: {}", holding.len());
            // Every stride-th record, from the first: evenly spaced over all pushed so far.
            assert!(holding.iter().all(|i| i % budget.stride == 0));
            assert_eq!(holding.len(), n.div_ceil(budget.stride));
            assert!(holding.len() > 5 || n <= 10, "{n}: only {}", holding.len());
        }
        assert_eq!(budget.stride, 128);
    }

    #[test]
    fn the_record_budget_keeps_whole_blocks_spread_over_the_input_within_its_cap() {
        let cap = 3_000;
        let mut budget = RecordBudget::new(cap);
        let mut records: Vec<u64> = Vec::new();
        let mut boxes: Vec<TrackBox> = Vec::new();
        let mut edgelets = EdgeletBudget::new(100);
        let mut lists: Vec<Vec<Edgelet>> = Vec::new();
        // Two boxes a frame for 20 blocks: 20,000 records offered.
        let frames = 20 * RECORD_BLOCK_FRAMES;
        for frame in 0..frames {
            for _ in 0..2 {
                // As `Stages::keep`: a block may be dropped between two boxes of a frame.
                if !budget.keeps(frame) {
                    continue;
                }
                records.push(frame);
                boxes.push(TrackBox {
                    frame,
                    bbox: BoxPx::new(0.0, 0.0, 10.0, 10.0),
                    score: 0.5,
                });
                lists.push(vec![Edgelet {
                    x: 0.0,
                    y: 0.0,
                    angle: 0.0,
                    strength: 1.0,
                }]);
                edgelets.pushed(&mut lists, |l| l);
                let mut paired: Vec<(u64, Vec<Edgelet>)> =
                    records.iter().copied().zip(lists.drain(..)).collect();
                if budget.thin(&mut paired, &mut boxes, |r| r.0) {
                    edgelets.reindexed(&mut paired, |r| &mut r.1);
                }
                records = paired.iter().map(|r| r.0).collect();
                lists = paired.into_iter().map(|r| r.1).collect();
                assert!(records.len() <= cap);
                assert!(lists.iter().filter(|l| !l.is_empty()).count() <= 100);
            }
        }
        // 20,000 offered against a cap of 3,000 (1,000 a block): one block in 8 kept.
        assert_eq!(budget.stride(), 8);
        assert_eq!(records.len(), 3_000);
        assert_eq!(boxes.len(), records.len());
        // Whole blocks, every 8th from the first, and nothing of the others.
        let blocks: std::collections::BTreeSet<u64> =
            records.iter().map(|f| f / RECORD_BLOCK_FRAMES).collect();
        assert_eq!(blocks.into_iter().collect::<Vec<_>>(), vec![0, 8, 16]);
        assert!(records.iter().all(|&f| budget.keeps(f)));
        for b in [0, 8, 16] {
            let n = records
                .iter()
                .filter(|&&f| f / RECORD_BLOCK_FRAMES == b)
                .count();
            assert_eq!(n as u64, 2 * RECORD_BLOCK_FRAMES);
        }
        // The edgelets stay on the stride over the records that are left, within their cap.
        let holding: Vec<usize> = (0..lists.len()).filter(|&i| !lists[i].is_empty()).collect();
        assert!((30..=100).contains(&holding.len()), "{}", holding.len());
        assert!(holding.iter().all(|i| i % edgelets.stride == 0));
    }

    #[test]
    fn under_its_cap_the_record_budget_keeps_everything() {
        let mut budget = RecordBudget::new(10_000);
        let mut records: Vec<u64> = (0..10_000).collect();
        let mut boxes = Vec::new();
        assert!(!budget.thin(&mut records, &mut boxes, |&f| f));
        assert_eq!(records.len(), 10_000);
        assert!((0..100_000).all(|f| budget.keeps(f)));
    }

    #[test]
    fn a_cap_below_one_block_keeps_the_first_block() {
        let mut budget = RecordBudget::new(10);
        let mut records: Vec<u64> = Vec::new();
        let mut boxes = Vec::new();
        for frame in 0..10 * RECORD_BLOCK_FRAMES {
            if budget.keeps(frame) {
                records.push(frame);
                budget.thin(&mut records, &mut boxes, |&f| f);
            }
        }
        assert_eq!(records, (0..RECORD_BLOCK_FRAMES).collect::<Vec<_>>());
        assert_eq!(budget.stride(), 16);
    }
}
