//! `vpcal calibrate`: footage of a fixed traffic camera to a calibrated camera.
//!
//! The whole data flow of DESIGN.md §2, streaming:
//!
//! ```text
//! frames (ffmpeg | folder | image) -> detector (motion | file | onnx) -> per-frame filter
//!   -> crops (bicubic, network input) -> VP network, batched -> decode with scale selection
//!   -> VPs in frame pixels, one record per vehicle box -> aggregation (robust | reference)
//!   -> calib.json, system.json (BCS), vehicles (VPout), overlay PNG
//! ```
//!
//! Memory stays bounded: frames are dropped as soon as their crops are cut; only the
//! per-vehicle records (a few hundred bytes each) and one picture for the overlay are kept.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use image::RgbImage;
use serde_json::{json, Value};
use vpcal_formats::bcs::{write_system, SystemCalibration, SystemFile};
use vpcal_formats::fs::write_atomic;
use vpcal_formats::reference::{write_vpout, VpOutItem};
use vpcal_geom::aggregate::edgelets::{near_rays, Edgelet, EdgeletFitOptions};
use vpcal_geom::aggregate::VehicleVps;
use vpcal_geom::camera::Calibration;
use vpcal_geom::heatmap::VpPrediction;
use vpcal_geom::{BoxPx, Point2};
use vpcal_net::VpNet;
use vpcal_video::crop::{CropFilter, CropResizer};
use vpcal_video::detect::{FileDetector, MotionConfig, MotionDetector};
use vpcal_video::edgelets::{edgelets_in_box, EdgeletOptions};
use vpcal_video::filter::{DropReason, FilterConfig, FrameFilter};
use vpcal_video::{Detector, Frame, SourceInfo, SourceKind, SourceOptions, Start};

use super::aggregate::{aggregate, Aggregated, Method};
use super::args;
use super::overlay;

/// The model shipped with vpcal (see `models/default/MODEL.md`), embedded in the binary.
pub const BUNDLED_MODEL: &[u8] = include_bytes!(concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../models/default/model.safetensors"
));

/// IoU above which a box of a still is the vehicle a box of an earlier still was (parked cars
/// in a folder of pictures of one camera move by a few pixels at most between detections).
const STILLS_SEEN_IOU: f64 = 0.7;

/// Exit code of a run that completed but could not support a calibration.
pub const EXIT_NOT_ENOUGH_EVIDENCE: u8 = 3;

/// Calibrate a fixed traffic camera from a video, an image folder or an image.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Video file (anything FFmpeg reads), folder of images, or one image.
    pub input: PathBuf,
    /// Write the calibration (vpcal's JSON schema) here.
    #[arg(short, long, value_name = "FILE")]
    pub output: Option<PathBuf>,
    /// Also write the camera as a BrnoCompSpeed system file.
    #[arg(long, value_name = "FILE")]
    pub bcs_json: Option<PathBuf>,
    /// Also write the per-vehicle records (deep_vp `VPout` JSON).
    #[arg(long, value_name = "FILE")]
    pub vehicles: Option<PathBuf>,
    /// Also write a frame with the horizon, vehicle VP directions and a road grid (PNG).
    #[arg(long, value_name = "PNG")]
    pub overlay: Option<PathBuf>,
    #[command(flatten)]
    pub pipeline: PipelineArgs,
    /// Print the calibration as JSON on stdout (the summary stays on stderr).
    #[arg(long)]
    pub json: bool,
}

/// Frame selection, detection, filtering, network and aggregation settings.
#[derive(Debug, Clone, clap::Args)]
pub struct PipelineArgs {
    /// VP network weights (.safetensors, checkpoint or `vpcal train` run folder). Default: the
    /// bundled model.
    #[arg(long, value_name = "PATH")]
    pub model: Option<PathBuf>,
    /// Device for the network: `cpu`, or `wgpu` in builds with the `wgpu` feature.
    #[arg(long, default_value = "cpu")]
    pub device: String,
    /// Crops per network batch.
    #[arg(long, default_value_t = 32)]
    pub batch: usize,
    /// Also run every crop mirrored and average its heatmaps with the crop's own (test-time
    /// augmentation: cancels a network's one-sided rotation of the VP rays; twice the network
    /// work). Off by default: with the bundled model it did not help on the synthetic suite.
    #[arg(long)]
    pub flip_average: bool,
    /// Do not look for edgelets (edges across the vehicles, which point at VP2) inside the
    /// boxes: the horizon's roll and the focal length then come from the network's VP2 rays
    /// alone.
    #[arg(long)]
    pub no_edgelets: bool,
    /// Do not look again at the frames the motion detector spent building its background (by
    /// default the input is read a second time for them once the background is known: the
    /// first 3 seconds would otherwise give no vehicles).
    #[arg(long)]
    pub no_replay: bool,
    #[command(flatten)]
    pub frames: FrameArgs,
    #[command(flatten)]
    pub detect: DetectorArgs,
    /// Drop boxes whose detector score is not above this.
    #[arg(long, default_value_t = 0.1)]
    pub min_score: f64,
    /// Keep vehicles that do not move between processed frames (the reference drops them).
    #[arg(long)]
    pub keep_static: bool,
    /// At most this many boxes per frame, best scores first (0: no limit).
    #[arg(long, default_value_t = 10)]
    pub max_per_frame: usize,
    /// Aggregation of the per-vehicle VPs.
    #[arg(long, value_enum, default_value_t = Method::Robust)]
    pub method: Method,
    /// Bootstrap resamples for the confidence of the robust method (0 to skip).
    #[arg(long, default_value_t = 30)]
    pub bootstrap: usize,
    /// Principal point x,y in pixels. Default: the image centre.
    #[arg(long, value_parser = args::point)]
    pub pp: Option<Point2>,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// Which frames of the input are processed.
#[derive(Debug, Clone, clap::Args)]
pub struct FrameArgs {
    /// Process every K-th frame.
    #[arg(long, default_value_t = 1, value_name = "K")]
    pub every: u64,
    /// Stop after this many processed frames.
    #[arg(long, value_name = "N")]
    pub max_frames: Option<u64>,
    /// Frame rate of an image folder: its pictures are then consecutive frames, treated as a
    /// video (times, tracks and speeds need it). Without it a folder is a set of stills of one
    /// camera, and a vehicle at the same place in several of them counts once. Videos carry
    /// their own rate.
    #[arg(long, value_name = "FPS")]
    pub fps: Option<f64>,
    /// Where to start: a frame index (`120`) or a time (`4.5s`).
    #[arg(long, value_parser = parse_start)]
    pub start: Option<Start>,
}

impl FrameArgs {
    /// The frame selection as source options.
    pub fn options(&self) -> SourceOptions {
        SourceOptions {
            every: self.every,
            max_frames: self.max_frames,
            start: self.start.unwrap_or_default(),
            image_fps: self.fps,
            ..SourceOptions::default()
        }
    }

    /// Opens `input` with this selection, checked (a bad selection, or `--fps` for a video,
    /// is an error naming the flag).
    pub fn open(&self, input: &Path) -> Result<Box<dyn vpcal_video::FrameSource>> {
        let options = self.options();
        options
            .validate()
            .map_err(|e| anyhow::anyhow!("invalid frame selection: {e}"))?;
        let source = vpcal_video::open_source(input, &options)
            .with_context(|| format!("opening {}", input.display()))?;
        if self.fps.is_some() && source.info().kind == SourceKind::Video {
            bail!(
                "--fps applies to image folders; the video {} has its own frame rate",
                input.display()
            );
        }
        Ok(source)
    }
}

/// Which vehicle detector, and its settings.
#[derive(Debug, Clone, clap::Args)]
pub struct DetectorArgs {
    /// Vehicle detector: `auto` (the built-in learned detector, which gave better boxes than
    /// the motion detector on every real road clip measured), `yolox` (the built-in
    /// YOLOX-nano, COCO), `motion` (weight-free background subtraction; consecutive frames
    /// only), `file:PATH` (boxes of any detector: deep_vp's
    /// detections.json or CSV/JSON rows of frame, box, score), `yolox:PATH` (another YOLOX
    /// ONNX export) or `onnx:PATH` (an ONNX model of the layout --onnx-layout).
    #[arg(long, default_value = "auto", value_name = "NAME", value_parser = parse_detector)]
    pub detector: DetectorChoice,
    /// Same as `--detector file:FILE`.
    #[arg(long, value_name = "FILE")]
    pub detections: Option<PathBuf>,
    /// Columns of square tiles the learned detector looks at besides the whole frame, for
    /// small vehicles in large frames (0: the whole frame only). Default: by frame width
    /// (0 up to 960 px, 2 above).
    #[arg(long, value_name = "N")]
    pub tiles: Option<u32>,
    /// Output layout of an `onnx:PATH` detector: yolo (v8/11), yolov5 or boxes-scores.
    #[arg(long, default_value = "yolo", value_parser = parse_layout)]
    pub onnx_layout: vpcal_video::detect::OnnxLayout,
    /// Count COCO motorcycles as vehicles too (learned detectors).
    #[arg(long)]
    pub motorcycles: bool,
    /// Road mask for the motion detector (white = road), e.g. BrnoCompSpeed's video_mask.png.
    #[arg(long, value_name = "PNG")]
    pub road_mask: Option<PathBuf>,
}

fn parse_layout(s: &str) -> Result<vpcal_video::detect::OnnxLayout, String> {
    s.parse()
        .map_err(|e: vpcal_video::VideoError| e.to_string())
}

/// The vehicle detector `--detector` names.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DetectorChoice {
    /// The built-in learned detector (the measured default).
    Auto,
    /// The built-in YOLOX-nano.
    Yolox,
    /// The weight-free motion detector.
    Motion,
    /// Boxes from a file.
    File(PathBuf),
    /// A YOLOX model file.
    YoloxFile(PathBuf),
    /// An ONNX model of the `--onnx-layout` layout.
    Onnx(PathBuf),
}

fn parse_detector(s: &str) -> Result<DetectorChoice, String> {
    let path = |p: &str, what: &str| {
        if p.is_empty() {
            Err(format!("`{s}`: give the {what} after the colon"))
        } else {
            Ok(PathBuf::from(p))
        }
    };
    match s.split_once(':') {
        None => match s {
            "auto" => Ok(DetectorChoice::Auto),
            "yolox" => Ok(DetectorChoice::Yolox),
            "motion" => Ok(DetectorChoice::Motion),
            _ => Err(format!(
                "unknown detector `{s}`: expected auto, yolox, motion, file:PATH, yolox:PATH or onnx:PATH"
            )),
        },
        Some(("file", p)) => path(p, "detections file").map(DetectorChoice::File),
        Some(("yolox", p)) => path(p, "YOLOX ONNX file").map(DetectorChoice::YoloxFile),
        Some(("onnx", p)) => path(p, "ONNX file").map(DetectorChoice::Onnx),
        Some((kind, _)) => Err(format!(
            "unknown detector kind `{kind}:` in `{s}`: expected file:PATH, yolox:PATH or onnx:PATH"
        )),
    }
}

fn parse_start(s: &str) -> Result<Start, String> {
    s.parse::<Start>().map_err(|e| e.to_string())
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
    /// The decoded network output, box frame.
    pub prediction: VpPrediction,
    /// VP1 and VP2 in frame pixels.
    pub vp1: Point2,
    pub vp2: Point2,
    /// Edgelets inside the box near the network's VP rays (empty with `--no-edgelets`).
    pub edgelets: Vec<Edgelet>,
}

impl VehicleRecord {
    pub fn to_vehicle(&self) -> VehicleVps {
        VehicleVps {
            vp1: self.vp1,
            vp2: self.vp2,
            score: f64::from(self.score),
            box_px: Some(self.crop_box),
            frame: Some(self.frame as f64),
            vp1_spread: Some(self.prediction.vp1_spread()),
            vp2_spread: Some(self.prediction.vp2_spread()),
        }
    }

    /// The record in deep_vp's `VPout` layout (frame-normalised box `[ymin, xmin, ymax, xmax]`).
    fn to_vpout(&self, width: u32, height: u32) -> VpOutItem {
        let b = &self.crop_box;
        let (w, h) = (f64::from(width), f64::from(height));
        let p = &self.prediction;
        VpOutItem {
            frame_cnt: self.frame as f64,
            score: f64::from(self.score),
            vp1: self.vp1,
            vp2: self.vp2,
            box_norm: Some([b.y0 / h, b.x0 / w, b.y1 / h, b.x1 / w]),
            box_center: Some(b.center()),
            box_scale: Some(b.half_size()),
            vp_box: Some([b.y0, b.x0, b.y1, b.x1]),
            vp1_box: Some(p.vp1),
            vp2_box: Some(p.vp2),
            pred_vps: p
                .per_scale
                .iter()
                .map(|[a, b]| [a.x, a.y, b.x, b.y])
                .collect(),
            pred_vars: p.spreads.clone(),
            vp1_var: Some(p.vp1_spread()),
            vp2_var: Some(p.vp2_spread()),
            edgelets: self
                .edgelets
                .iter()
                .map(|e| [e.x, e.y, e.angle, e.strength])
                .collect(),
        }
    }
}

/// Counts of what the pipeline saw.
#[derive(Debug, Clone, Default)]
pub struct PipelineStats {
    pub frames: u64,
    /// Frames looked at a second time, after the detector's warm-up (see [`run_pipeline`]).
    pub replayed_frames: u64,
    pub detections: u64,
    pub dropped_low_score: u64,
    pub dropped_static: u64,
    pub dropped_over_limit: u64,
    pub dropped_outside: u64,
    /// Boxes of a still-image folder at the place of a box kept in an earlier picture.
    pub dropped_seen: u64,
    pub crops: u64,
    pub seconds: f64,
}

/// Everything the pipeline produced before aggregation.
pub struct PipelineOutput {
    pub info: SourceInfo,
    pub detector: String,
    pub model: String,
    pub records: Vec<VehicleRecord>,
    pub stats: PipelineStats,
    /// A picture of the scene for the overlay: the detector's background model when it has
    /// one (no vehicles in the way), else the last frame.
    pub picture: Option<RgbImage>,
}

/// Load the network named by `--model`, or the bundled one.
pub fn load_model(model: Option<&Path>, device: &str) -> Result<(VpNet, String)> {
    let device = vpcal_net::device::select(device)?;
    match model {
        Some(path) => {
            let net = VpNet::load(path, &device)
                .with_context(|| format!("loading the VP network from {}", path.display()))?;
            Ok((net, path.display().to_string()))
        }
        None => {
            let label = Path::new("<bundled models/default/model.safetensors>");
            let net = VpNet::from_bytes(BUNDLED_MODEL, label, &device)
                .context("loading the bundled VP network")?;
            Ok((net, "bundled:models/default".to_string()))
        }
    }
}

/// Records keep their edgelets for an evenly spaced subset of at most `cap` of them: every
/// record at first; whenever more than `cap` hold edgelets, only every second of those keeps
/// them, and so on. The aggregation fits at most 20,000 edgelets (a few hundred vehicles), so
/// this bounds memory and time on long inputs (an hour at every frame is ~450,000 records) and
/// changes nothing on short ones.
struct EdgeletBudget {
    cap: usize,
    stride: usize,
    holding: usize,
}

impl EdgeletBudget {
    fn new(cap: usize) -> EdgeletBudget {
        EdgeletBudget {
            cap,
            stride: 1,
            holding: 0,
        }
    }

    /// Whether the record with this index keeps its edgelets.
    fn keeps(&self, index: usize) -> bool {
        index % self.stride == 0
    }

    /// Account for the record just pushed (the last one); `edgelets` gives a record's list.
    fn pushed<T>(&mut self, records: &mut [T], edgelets: impl Fn(&mut T) -> &mut Vec<Edgelet>) {
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
        while self.holding > self.cap {
            self.stride *= 2;
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
}

/// A crop waiting for its batch: frame, score, crop box, edgelets in the box.
type Pending = (u64, f32, BoxPx, Vec<Edgelet>);

/// Everything after the detector: filter, crops, edgelets, batched network, records.
struct Stages<'a> {
    net: &'a VpNet,
    a: &'a PipelineArgs,
    resizer: CropResizer,
    crop_len: usize,
    /// Crops waiting for a full batch, and their (frame, score, box, edgelets).
    pending: Vec<f32>,
    pending_meta: Vec<Pending>,
    records: Vec<VehicleRecord>,
    budget: EdgeletBudget,
    edgelet_options: EdgeletOptions,
    gate: EdgeletFitOptions,
    stats: PipelineStats,
}

impl<'a> Stages<'a> {
    fn new(net: &'a VpNet, a: &'a PipelineArgs) -> Result<Stages<'a>> {
        let resizer = CropResizer::new(net.config().input_size as u32, CropFilter::default())?;
        let crop_len = resizer.crop_len();
        Ok(Stages {
            net,
            a,
            resizer,
            crop_len,
            pending: Vec::with_capacity(a.batch * crop_len),
            pending_meta: Vec::with_capacity(a.batch),
            records: Vec::new(),
            budget: EdgeletBudget::new(4096),
            edgelet_options: EdgeletOptions::default(),
            gate: EdgeletFitOptions::default(),
            stats: PipelineStats::default(),
        })
    }

    /// The per-frame filter (each pass over the frames gets its own: it compares a frame's
    /// boxes with the previous frame's). Stills are not consecutive frames: there a vehicle
    /// that stays in place (parked) counts once instead of being dropped as static.
    fn filter(&self, info: &SourceInfo) -> FrameFilter {
        let stills = is_stills(info);
        FrameFilter::new(FilterConfig {
            min_score: Some(self.a.min_score as f32),
            drop_static: !self.a.keep_static && !stills,
            drop_seen_iou: (stills && !self.a.keep_static).then_some(STILLS_SEEN_IOU),
            max_per_frame: (self.a.max_per_frame > 0).then_some(self.a.max_per_frame),
            ..FilterConfig::default()
        })
    }

    /// Detect, filter and crop the vehicles of one frame; full batches go through the network.
    fn frame(
        &mut self,
        frame: &Frame,
        detector: &mut dyn Detector,
        filter: &mut FrameFilter,
    ) -> Result<()> {
        let dets = detector
            .detect(frame)
            .with_context(|| format!("detecting vehicles in frame {}", frame.index))?;
        self.stats.detections += dets.len() as u64;
        let filtered = filter.apply(frame, dets);
        for (_, why) in &filtered.dropped {
            match why {
                DropReason::LowScore => self.stats.dropped_low_score += 1,
                DropReason::Static => self.stats.dropped_static += 1,
                DropReason::OverLimit => self.stats.dropped_over_limit += 1,
                DropReason::OutsideFrame => self.stats.dropped_outside += 1,
                DropReason::SeenBefore => self.stats.dropped_seen += 1,
            }
        }
        if filtered.kept.is_empty() {
            return Ok(());
        }
        let boxes: Vec<BoxPx> = filtered.kept.iter().map(|d| d.bbox).collect();
        let batch = self.resizer.crop_batch(&frame.image, &boxes)?;
        let len = self.crop_len;
        for (k, (&src, &bp)) in batch.source.iter().zip(&batch.boxes).enumerate() {
            self.pending
                .extend_from_slice(&batch.images[k * len..(k + 1) * len]);
            let index = self.records.len() + self.pending_meta.len();
            let edgelets = if self.a.no_edgelets || !self.budget.keeps(index) {
                Vec::new()
            } else {
                edgelets_in_box(&frame.image, &bp, &self.edgelet_options)
            };
            self.pending_meta
                .push((frame.index, filtered.kept[src].score, bp, edgelets));
            self.stats.crops += 1;
            if self.pending_meta.len() >= self.a.batch {
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
        let preds = self.net.predict_prepared(&self.pending)?;
        for ((frame, score, crop_box, edgelets), p) in self.pending_meta.drain(..).zip(preds) {
            let prediction = p.vp;
            let vp1 = crop_box.frame_from_box(prediction.vp1);
            let vp2 = crop_box.frame_from_box(prediction.vp2);
            // Only the edgelets near the network's VP rays are kept (memory).
            let edgelets = near_rays(
                crop_box.center(),
                vp1,
                vp2,
                &edgelets,
                self.gate.gate_vp2_deg,
                self.gate.max_per_vehicle,
            );
            self.records.push(VehicleRecord {
                frame,
                score,
                crop_box,
                vp1,
                vp2,
                prediction,
                edgelets,
            });
            self.budget.pushed(&mut self.records, |r| &mut r.edgelets);
        }
        self.pending.clear();
        Ok(())
    }
}

/// Run frames -> detections -> filter -> crops -> network, returning per-vehicle records.
///
/// A detector that spends the first frames learning (the motion detector's warm-up) gets a
/// second look at them once the main pass is done: the input is opened again and those
/// frames go through [`Detector::replay`] (unless `--no-replay`).
pub fn run_pipeline(input: &Path, a: &PipelineArgs) -> Result<PipelineOutput> {
    if a.batch == 0 {
        bail!("--batch must be at least 1");
    }
    let options = a.frames.options();
    let mut source = a.frames.open(input)?;
    let (net, model) = load_model(a.model.as_deref(), &a.device)?;
    let net = net.with_flip_average(a.flip_average);
    let info = source.info().clone();
    let mut detector = open_detector(&a.detect, &info)?;
    let detector_name = detector.name();
    let mut stages = Stages::new(&net, a)?;
    let mut filter = stages.filter(&info);

    let expected = info.expected_frames(&options);
    let pb = super::progress_bar(expected, "frames", a.quiet);
    let t0 = Instant::now();
    let mut last_frame: Option<RgbImage> = None;
    // Frames of the main pass that only taught the detector.
    let mut learning_frames = 0u64;
    let progress = |pb: &indicatif::ProgressBar, stages: &Stages| {
        pb.inc(1);
        let secs = t0.elapsed().as_secs_f64().max(1e-9);
        let s = &stages.stats;
        pb.set_message(format!(
            "{:.1} frames/s, {} vehicle boxes",
            (s.frames + s.replayed_frames) as f64 / secs,
            s.crops
        ));
    };
    for frame in source.by_ref() {
        let frame = frame.with_context(|| format!("reading {}", input.display()))?;
        stages.stats.frames += 1;
        stages.frame(&frame, detector.as_mut(), &mut filter)?;
        if detector
            .learned_until()
            .is_none_or(|until| frame.index < until)
        {
            learning_frames += 1;
        }
        progress(&pb, &stages);
        last_frame = Some(frame.image);
    }
    for w in source.warnings() {
        eprintln!("warning: {}: {w}", input.display());
    }
    drop(source);
    let replay = match (detector.learned_until(), detector.replay()) {
        (Some(until), Some(replay)) if !a.no_replay && learning_frames > 0 => Some((until, replay)),
        _ => None,
    };
    if let Some((until, mut replay)) = replay {
        pb.inc_length(learning_frames);
        let mut source = a
            .frames
            .open(input)
            .with_context(|| format!("opening {} again", input.display()))?;
        let mut filter = stages.filter(&info);
        for frame in source.by_ref() {
            let frame = frame.with_context(|| format!("reading {}", input.display()))?;
            if frame.index >= until {
                break;
            }
            stages.stats.replayed_frames += 1;
            stages.frame(&frame, replay.as_mut(), &mut filter)?;
            progress(&pb, &stages);
        }
    }
    stages.flush()?;
    pb.finish_and_clear();
    let Stages {
        mut records,
        mut stats,
        ..
    } = stages;
    if stats.frames == 0 {
        bail!(
            "{}: no frames to process (empty input, or --start/--max-frames select none)",
            input.display()
        );
    }
    // The replayed frames come first in the stream.
    records.sort_by_key(|r| r.frame);
    stats.seconds = t0.elapsed().as_secs_f64();
    Ok(PipelineOutput {
        info,
        detector: detector_name,
        model,
        records,
        stats,
        picture: last_frame,
    })
}

/// Whether the input is stills rather than consecutive frames: one image, or a folder of
/// images without `--fps` (with it, the folder is a frame sequence and is treated as video).
pub fn is_stills(info: &SourceInfo) -> bool {
    match info.kind {
        SourceKind::Video => false,
        SourceKind::SingleImage => true,
        SourceKind::ImageFolder => info.fps.is_none(),
    }
}

/// Tile columns for the learned detector when `--tiles` is not given: none up to 960 px
/// wide, 2 above (see the README's measurement of recall against cost).
pub fn default_tiles(width: u32) -> u32 {
    if width > 960 {
        2
    } else {
        0
    }
}

/// The detector `--detector` resolves to for this input: `auto` is the learned detector.
pub fn resolve_detector(a: &DetectorArgs) -> DetectorChoice {
    match (&a.detections, &a.detector) {
        (Some(path), _) => DetectorChoice::File(path.clone()),
        (None, DetectorChoice::Auto) => DetectorChoice::Yolox,
        (None, other) => other.clone(),
    }
}

/// The detector the flags ask for (see [`DetectorArgs::detector`]).
pub fn open_detector(a: &DetectorArgs, info: &SourceInfo) -> Result<Box<dyn Detector>> {
    use vpcal_video::detect::{YoloxConfig, YoloxDetector};
    if a.detections.is_some() && a.detector != DetectorChoice::Auto {
        bail!("--detections FILE is --detector file:FILE: give one of them");
    }
    let choice = resolve_detector(a);
    if a.road_mask.is_some() && choice != DetectorChoice::Motion {
        bail!("--road-mask applies to the motion detector (--detector motion) only");
    }
    // COCO classes that count as vehicles, for both kinds of learned detector.
    let mut classes = vpcal_video::detect::yolox::COCO_CAR_BUS_TRUCK.to_vec();
    if a.motorcycles {
        classes.push(vpcal_video::detect::yolox::COCO_MOTORCYCLE);
    }
    let yolox_config = || YoloxConfig {
        classes: classes.clone(),
        tiles: a.tiles.unwrap_or_else(|| default_tiles(info.width)),
        ..YoloxConfig::default()
    };
    match choice {
        DetectorChoice::File(path) => Ok(Box::new(FileDetector::open(&path)?)),
        DetectorChoice::Yolox | DetectorChoice::Auto => {
            Ok(Box::new(YoloxDetector::bundled(yolox_config())?))
        }
        DetectorChoice::YoloxFile(path) => {
            Ok(Box::new(YoloxDetector::open(&path, yolox_config())?))
        }
        DetectorChoice::Onnx(path) => {
            let config = vpcal_video::detect::OnnxConfig {
                layout: a.onnx_layout,
                classes: Some(classes.clone()),
                ..vpcal_video::detect::OnnxConfig::default()
            };
            Ok(Box::new(vpcal_video::detect::OnnxDetector::open(
                &path, config,
            )?))
        }
        DetectorChoice::Motion => {
            if is_stills(info) {
                bail!(
                    "--detector motion needs consecutive frames (it learns the background from \
                     them): {} is a still or a folder of stills; use --detector yolox, or give \
                     a folder of consecutive frames its rate with --fps",
                    info.path.display()
                );
            }
            let mut d = MotionDetector::new(MotionConfig::default())?;
            if let Some(mask) = &a.road_mask {
                let m = vpcal_video::detect::motion::load_road_mask(mask)?;
                if m.dimensions() != (info.width, info.height) {
                    bail!(
                        "--road-mask {}: {}x{} pixels, but the frames are {}x{}",
                        mask.display(),
                        m.width(),
                        m.height(),
                        info.width,
                        info.height
                    );
                }
                d = d.with_road_mask(m, mask.clone());
            }
            Ok(Box::new(d))
        }
    }
}

/// The principal point: `--pp` or the image centre.
pub fn principal_point(a: &PipelineArgs, info: &SourceInfo) -> Point2 {
    a.pp.unwrap_or(Point2 {
        x: f64::from(info.width) / 2.0,
        y: f64::from(info.height) / 2.0,
    })
}

fn pt(p: Point2) -> Value {
    if p.is_finite() {
        json!([p.x, p.y])
    } else {
        Value::Null
    }
}

/// The `calib.json` document of a successful calibration.
pub fn calibration_json(
    out: &PipelineOutput,
    a: &PipelineArgs,
    cal: &Calibration,
    agg: &Aggregated,
) -> Value {
    let hz = cal.horizon.0;
    json!({
        "format": "vpcal-calibration/1",
        "status": "calibrated",
        "vpcal_version": env!("CARGO_PKG_VERSION"),
        "input": input_json(out),
        "image_size": [out.info.width, out.info.height],
        "pp": pt(cal.pp),
        "focal_px": cal.focal_px,
        "K": cal.k(),
        "R": cal.rotation,
        "vp1": pt(cal.vp1),
        "vp2": pt(cal.vp2),
        "vp3": pt(cal.vp3),
        "horizon": {
            "line": hz,
            "angle_deg": cal.horizon.angle().to_degrees(),
        },
        "road_normal": cal.road_normal,
        "tilt_deg": cal.tilt().to_degrees(),
        "roll_deg": cal.roll().to_degrees(),
        "scale_m_per_unit": Value::Null,
        "evidence": agg.evidence.clone(),
        "confidence": agg.confidence.clone(),
        "summary": agg.summary,
        "settings": settings_json(out, a),
    })
}

fn input_json(out: &PipelineOutput) -> Value {
    json!({
        "path": out.info.path.display().to_string(),
        "width": out.info.width,
        "height": out.info.height,
        "fps": out.info.fps,
        "codec": out.info.codec,
        "frames_processed": out.stats.frames,
        "frames_replayed": out.stats.replayed_frames,
        "detections": out.stats.detections,
        "dropped": {
            "low_score": out.stats.dropped_low_score,
            "static": out.stats.dropped_static,
            "over_limit": out.stats.dropped_over_limit,
            "outside_frame": out.stats.dropped_outside,
            "seen_before": out.stats.dropped_seen,
        },
        "vehicle_boxes": out.stats.crops,
        "seconds": out.stats.seconds,
    })
}

fn settings_json(out: &PipelineOutput, a: &PipelineArgs) -> Value {
    json!({
        "model": out.model,
        "device": a.device,
        "detector": out.detector,
        "every": a.frames.every,
        "fps": a.frames.fps,
        "max_frames": a.frames.max_frames,
        "start": a.frames.start.map(|s| format!("{s:?}")),
        "min_score": a.min_score,
        "drop_static": !a.keep_static,
        "max_per_frame": a.max_per_frame,
        "method": a.method.name(),
        "flip_average": a.flip_average,
        "replay": !a.no_replay,
        "bootstrap": a.bootstrap,
        "pp": a.pp.map(pt),
    })
}

/// Aggregate the records of `out` into a camera.
///
/// # Errors
/// "Not enough evidence" (or a degenerate camera) as an error message.
pub fn calibrate(out: &PipelineOutput, a: &PipelineArgs) -> Result<(Calibration, Aggregated)> {
    let pp = principal_point(a, &out.info);
    let vehicles: Vec<VehicleVps> = out.records.iter().map(VehicleRecord::to_vehicle).collect();
    let edgelets: Vec<Vec<Edgelet>> = out.records.iter().map(|r| r.edgelets.clone()).collect();
    let agg = aggregate(
        &vehicles,
        &edgelets,
        pp,
        (out.info.width, out.info.height),
        a.method,
        a.min_score,
        a.bootstrap,
    )?;
    let cal = Calibration::from_vps(agg.vp1, agg.vp2, pp)
        .map_err(|e| anyhow::anyhow!("the aggregated vanishing points give no camera: {e}"))?;
    Ok((cal, agg))
}

/// Print the run's summary table on stderr.
pub fn print_summary(out: &PipelineOutput, result: &Result<(Calibration, Aggregated)>) {
    let s = &out.stats;
    let row = |k: &str, v: String| eprintln!("  {k:<22} {v}");
    eprintln!("vpcal calibrate: {}", out.info.path.display());
    row(
        "frames",
        format!(
            "{} processed ({}x{}){} in {:.1} s, {:.1} frames/s",
            s.frames,
            out.info.width,
            out.info.height,
            if s.replayed_frames > 0 {
                format!(
                    ", {} of them again after the detector's warm-up",
                    s.replayed_frames
                )
            } else {
                String::new()
            },
            s.seconds,
            (s.frames + s.replayed_frames) as f64 / s.seconds.max(1e-9)
        ),
    );
    row("detector", out.detector.clone());
    row(
        "boxes",
        format!(
            "{} detected, {} kept (dropped: {} low score, {} static, {} seen in an earlier \
             picture, {} over the per-frame limit)",
            s.detections,
            s.crops,
            s.dropped_low_score,
            s.dropped_static,
            s.dropped_seen,
            s.dropped_over_limit
        ),
    );
    row("model", out.model.clone());
    match result {
        Ok((cal, agg)) => {
            row("aggregation", agg.summary.clone());
            row("focal length", format!("{:.1} px", cal.focal_px));
            row(
                "vp1, vp2",
                format!(
                    "({:.1}, {:.1}), ({:.1}, {:.1})",
                    cal.vp1.x, cal.vp1.y, cal.vp2.x, cal.vp2.y
                ),
            );
            row(
                "horizon",
                format!(
                    "{:.2}° roll, camera tilt {:.2}° below the horizon",
                    cal.horizon.angle().to_degrees(),
                    cal.tilt().to_degrees()
                ),
            );
        }
        Err(e) => row("result", format!("NOT CALIBRATED: {e:#}")),
    }
}

pub fn run(args: Args) -> Result<std::process::ExitCode> {
    // Fail before a long run, not after it, when an output cannot be written.
    for (flag, path) in [
        ("--output", &args.output),
        ("--bcs-json", &args.bcs_json),
        ("--vehicles", &args.vehicles),
        ("--overlay", &args.overlay),
    ] {
        if let Some(path) = path {
            check_destination(flag, path)?;
        }
    }
    let out = run_pipeline(&args.input, &args.pipeline)?;
    let result = calibrate(&out, &args.pipeline);
    print_summary(&out, &result);
    let (w, h) = (out.info.width, out.info.height);
    if let Some(path) = &args.vehicles {
        let items: Vec<VpOutItem> = out.records.iter().map(|r| r.to_vpout(w, h)).collect();
        write_vpout(path, &items)?;
    }
    match result {
        Ok((cal, agg)) => {
            let doc = calibration_json(&out, &args.pipeline, &cal, &agg);
            if let Some(path) = &args.output {
                write_json_doc(path, &doc)?;
            }
            if let Some(path) = &args.bcs_json {
                write_bcs_system(path, &cal)?;
            }
            if let Some(path) = &args.overlay {
                let Some(picture) = &out.picture else {
                    bail!("no frame to draw the overlay on");
                };
                let img = overlay::draw(picture, &cal, &out.records, &agg.track_lines);
                vpcal_video::draw::save_png(&img, path)?;
            }
            if args.json {
                println!("{}", serde_json::to_string_pretty(&doc)?);
            }
            Ok(std::process::ExitCode::SUCCESS)
        }
        Err(e) => {
            let doc = json!({
                "format": "vpcal-calibration/1",
                "status": "not_enough_evidence",
                "reason": format!("{e:#}"),
                "vpcal_version": env!("CARGO_PKG_VERSION"),
                "input": input_json(&out),
                "image_size": [w, h],
                "settings": settings_json(&out, &args.pipeline),
            });
            if let Some(path) = &args.output {
                write_json_doc(path, &doc)?;
            }
            if let Some(path) = &args.overlay {
                if let Some(picture) = &out.picture {
                    let img = overlay::draw_records_only(picture, &out.records);
                    vpcal_video::draw::save_png(&img, path)?;
                }
            }
            if args.json {
                println!("{}", serde_json::to_string_pretty(&doc)?);
            }
            eprintln!("vpcal: no calibration: {e:#}");
            Ok(std::process::ExitCode::from(EXIT_NOT_ENOUGH_EVIDENCE))
        }
    }
}

/// An output file can be created at `path`: its folder exists and `path` is not a folder.
pub fn check_destination(flag: &str, path: &Path) -> Result<()> {
    if path.is_dir() {
        bail!(
            "{flag} {}: is a folder, expected a file name",
            path.display()
        );
    }
    match path.parent() {
        Some(dir) if !dir.as_os_str().is_empty() && !dir.is_dir() => bail!(
            "{flag} {}: the folder {} does not exist",
            path.display(),
            dir.display()
        ),
        _ => Ok(()),
    }
}

/// Write `cal` as a BrnoCompSpeed system file (scale 1: no metric scale yet).
pub fn write_bcs_system(path: &Path, cal: &Calibration) -> Result<()> {
    let system = SystemFile::new(SystemCalibration {
        vp1: cal.vp1,
        vp2: cal.vp2,
        pp: cal.pp,
        scale: 1.0,
    });
    write_system(path, &system)?;
    Ok(())
}

/// Write a JSON document atomically (temp file, then rename), pretty-printed.
pub fn write_json_doc(path: &Path, doc: &Value) -> Result<()> {
    let mut bytes = serde_json::to_vec_pretty(doc)?;
    bytes.push(b'\n');
    write_atomic(path, &bytes)?;
    Ok(())
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
}
