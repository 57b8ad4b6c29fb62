//! `vpcal calibrate`: footage of a fixed traffic camera to a calibrated camera.
//!
//! Parses the flags into a [`PipelineConfig`], runs the library's pipeline
//! ([`vpcal::pipeline`]) and writes what the flags ask for.

use std::path::{Path, PathBuf};

use anyhow::{bail, Result};
use vpcal::aggregate::{Aggregated, Method};
use vpcal::detector::{DetectorChoice, DetectorSettings};
use vpcal::output::{self, check_destination, check_distinct_paths};
use vpcal::overlay;
use vpcal::pipeline::{open_input, PipelineConfig, PipelineOutput, PrincipalPoint};
use vpcal::road::KnownDistance;
use vpcal_geom::camera::Calibration;
use vpcal_geom::Point2;
use vpcal_video::{SourceOptions, Start};

use super::{Exit, UsageError};

/// Calibrate a fixed traffic camera from a video, an image folder or an image.
#[derive(Debug, clap::Args)]
#[command(after_help = "Examples:\n  \
    vpcal calibrate clip.mp4 -o calib.json --overlay overlay.png\n  \
    vpcal calibrate clip.mp4 -o calib.json --tracks tracks.csv \\\n      \
    --scale-points 412,610,530,598 --scale-distance 6.0      # speeds in km/h\n\n\
Exit codes: 0 calibrated (read `status` and the warnings); 1 an error; 2 a wrong command \
line; 3 the footage could not support a calibration (the file says why).")]
pub struct Args {
    /// Video file (anything FFmpeg reads), folder of images, or one image.
    pub input: PathBuf,
    /// Write the calibration file here (strict JSON, vpcal-calibration/3; its fields:
    /// docs/calibration-file.md).
    #[arg(short, long, value_name = "FILE")]
    pub output: Option<PathBuf>,
    /// Also write the camera as a BrnoCompSpeed system file.
    #[arg(long, value_name = "FILE")]
    pub bcs_json: Option<PathBuf>,
    /// Also write the per-vehicle records (deep_vp's `VPout` JSON; non-finite numbers as null).
    #[arg(long, value_name = "FILE")]
    pub vehicles: Option<PathBuf>,
    /// Also write the edgelets and line segments of the scene's background (the median of
    /// frames sampled over the input), which move VP1 to where the lines along the road meet
    /// and measure the focal length where vertical lines meet: with the `--vehicles` file,
    /// `vpcal aggregate --scene-edgelets FILE` finds the same camera.
    #[arg(long, value_name = "FILE")]
    pub scene_edgelets: Option<PathBuf>,
    /// Also write the scene's background (the median of frames sampled over the input: the
    /// road without its traffic), grey levels, PNG: where `calibrate --markings` finds the
    /// lane lines, and a picture for `vpcal scale --markings --image`.
    #[arg(long, value_name = "PNG")]
    pub background: Option<PathBuf>,
    /// Also write the vehicle tracks: `.csv` (one row per track point: id, frame, time_s,
    /// x_px, y_px (the box's bottom centre, where the vehicle meets the road), clipped,
    /// road_x_m, road_y_m, and the track's speed_kmh, speed_uncertainty_kmh, speed_fit_kmh,
    /// lateral_m, lane, direction) or JSON (any other name; vpcal-tracks/1, the same fields
    /// per track). Road points, speeds and lanes need a metric scale (given, or the automatic
    /// one). Needs consecutive frames: a video, or an image folder with --fps.
    #[arg(long, value_name = "FILE")]
    pub tracks: Option<PathBuf>,
    /// Two road points a known distance apart, pixels x1,y1,x2,y2 (as `vpcal scale
    /// --points`): gives the calibration its metric scale, the tracks their speeds, the
    /// BrnoCompSpeed file its scale. Repeat (each with its --scale-distance) for several; a
    /// length along the road and one across it also measure the focal length.
    #[arg(long, value_name = "X1,Y1,X2,Y2", value_parser = parse_points, allow_hyphen_values = true, requires = "scale_distance")]
    pub scale_points: Vec<[f64; 4]>,
    /// The distance between --scale-points on the road, metres; one per --scale-points.
    #[arg(long, value_name = "M", requires = "scale_points", value_parser = super::args::positive_f64, allow_negative_numbers = true)]
    pub scale_distance: Vec<f64>,
    /// Also write a frame with the horizon, vehicle VP directions and a road grid (PNG).
    #[arg(long, value_name = "PNG")]
    pub overlay: Option<PathBuf>,
    /// Also write the camera as an OpenCV FileStorage YAML file (road units until `vpcal
    /// scale`; `vpcal export` writes it again from a scaled calibration).
    #[arg(long, value_name = "YML")]
    pub opencv: Option<PathBuf>,
    /// Also write a self-contained HTML report (the overlay picture, the focal length and its
    /// interval, the horizon, the evidence for VP1, the scale, tracks and speeds, and every
    /// warning with what to do about it); it opens offline.
    #[arg(long, value_name = "HTML")]
    pub report: Option<PathBuf>,
    #[command(flatten)]
    pub pipeline: PipelineArgs,
    /// Print the calibration as JSON on stdout (the summary stays on stderr).
    #[arg(long)]
    pub json: bool,
}

impl Args {
    /// The files and folders the run reads, by role or flag.
    fn input_paths(&self) -> Vec<(&'static str, &Path)> {
        let mut v: Vec<(&'static str, &Path)> = vec![("input", self.input.as_path())];
        let p = &self.pipeline;
        if let Some(m) = &p.model {
            v.push(("--model", m));
        }
        if let Some(d) = &p.detect.detections {
            v.push(("--detections", d));
        }
        if let DetectorChoice::File(f) = &p.detect.detector {
            v.push(("--detector", f));
        }
        if let Some(m) = &p.detect.road_mask {
            v.push(("--road-mask", m));
        }
        v
    }

    /// The files the run writes, by flag.
    fn output_paths(&self) -> Vec<(&'static str, &Path)> {
        [
            ("--output", &self.output),
            ("--bcs-json", &self.bcs_json),
            ("--vehicles", &self.vehicles),
            ("--scene-edgelets", &self.scene_edgelets),
            ("--background", &self.background),
            ("--tracks", &self.tracks),
            ("--overlay", &self.overlay),
            ("--opencv", &self.opencv),
            ("--report", &self.report),
        ]
        .into_iter()
        .filter_map(|(flag, path)| path.as_deref().map(|p| (flag, p)))
        .collect()
    }
}

/// Frame selection, detection, filtering, network and aggregation settings.
#[derive(Debug, Clone, clap::Args)]
pub struct PipelineArgs {
    /// VP network weights (.safetensors, checkpoint or `vpcal train` run folder). Default: the
    /// bundled model.
    #[arg(long, value_name = "PATH")]
    pub model: Option<PathBuf>,
    /// Device for the network: `cpu`, or `wgpu` in builds with the `wgpu` feature.
    #[arg(long, default_value = "cpu", value_parser = super::args::device)]
    pub device: String,
    /// Crops per network batch.
    #[arg(long, default_value_t = 32, value_parser = super::args::positive_usize)]
    pub batch: usize,
    /// Also run every crop mirrored and average its heatmaps with the crop's own (test-time
    /// augmentation: cancels a network's one-sided rotation of the VP rays; twice the network
    /// work). Off by default: with the bundled model it narrows the VP1 rays on held-out real
    /// cameras by 6-9 % and VP2 on KITTI, but not VP1 on KITTI (models/default/MODEL.md).
    #[arg(long)]
    pub flip_average: bool,
    /// Cut boxes whose larger side is under PX pixels for the network with the road around
    /// them (the box scaled about its centre to PX): the lane lines and neighbours carry a far
    /// vehicle's VP1, which its few pixels do not. Off (0) by default while it is measured: at
    /// 64-96 px it halved the VP1 rays' scatter of small vehicles on held-out real cameras
    /// with the bundled model (models/default/MODEL.md, "Context does fix it").
    #[arg(long, default_value_t = 0.0, value_name = "PX")]
    pub min_crop_px: f64,
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
    /// Which boxes go through the VP network: `all` (every box of every frame), `few` (a
    /// few per followed vehicle: its first, each 1.5 times larger than the last sent, and
    /// boxes 2, 4, 8, ... of its track; the others carry their vehicle's VPs for their
    /// edgelets) or `auto` (few above 960 px wide, all below). Stills always send every box.
    #[arg(long, value_name = "POLICY", default_value = "auto")]
    pub crops: vpcal::pipeline::CropPolicy,
    /// Aggregation of the per-vehicle VPs: `robust` (VP1 from straight vehicle tracks when
    /// enough link up, else from the network's rays; the default), `robust-network` (VP1 from
    /// the network's rays) or `reference` (the paper's medians).
    #[arg(long, default_value = "robust", value_parser = super::args::method())]
    pub method: Method,
    /// Bootstrap resamples for the confidence of the robust method (0 to skip).
    #[arg(long, default_value_t = 30)]
    pub bootstrap: usize,
    /// At most this many vehicle records in memory. Past it, the records, tracks and speeds
    /// keep one block of 500 frames in every 2 (then 4, 8, ...), spread evenly over the
    /// input, and a warning says so: memory stays flat on inputs of any length.
    #[arg(long, value_name = "N", default_value_t = vpcal::pipeline::MAX_RECORDS)]
    pub max_records: usize,
    /// Principal point: `centre` (the image centre W/2, H/2, in the coordinates where pixel
    /// (i, j) covers [i, i+1) x [j, j+1)), `bcs` (BrnoCompSpeed's W/2 + 0.5, H/2 + 0.5) or
    /// x,y in pixels.
    #[arg(long, default_value = "centre", value_name = "PP")]
    pub pp: PrincipalPoint,
    /// The camera's focal length in pixels, when known (e.g. lens focal length / pixel pitch
    /// from its data sheet): VP1 and the horizon still come from the footage. Without it the
    /// focal length is measured when the evidence allows, else assumed (and said so).
    #[arg(long, value_name = "PX", value_parser = super::args::positive_f64, allow_negative_numbers = true)]
    pub focal: Option<f64>,
    /// The focal lengths the camera can have, SHORT,LONG in pixels (e.g. a zoom lens's
    /// shortest and longest focal length over the pixel pitch, from its data sheet): the range
    /// the evidence is weighed against instead of 15-90° views; an assumed focal length is its
    /// geometric middle.
    #[arg(long, value_name = "SHORT,LONG", value_parser = super::args::focal_range, conflicts_with = "focal")]
    pub focal_range: Option<[f64; 2]>,
    /// The road's marking standard, PERIOD,LANE in metres: the period of its dashed lane lines
    /// (one line plus one gap: 9 for 3 + 6 m, 12.19 for the US 10 + 30 ft) and its lane width.
    /// The lane lines found in the scene's background then measure the focal length (a period
    /// along the road against a lane across it) and the metric scale, as --scale-points
    /// lengths would (`focal_source`/`scale_source: markings`). Or a national standard's key:
    /// cz, uk, nl, us, fr, cn, de, jp (motorway figures; `evidence.markings.focal_by_standard`
    /// lists them). Read the road's own standard: a wrong one scales every distance and speed.
    #[arg(long, value_name = "PERIOD,LANE|KEY")]
    pub markings: Option<vpcal::markings::MarkingStandard>,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// Which frames of the input are processed.
#[derive(Debug, Clone, clap::Args)]
pub struct FrameArgs {
    /// Process every K-th frame.
    #[arg(long, default_value_t = 1, value_name = "K", value_parser = super::args::positive_u64, allow_negative_numbers = true)]
    pub every: u64,
    /// Stop after this many processed frames.
    #[arg(long, value_name = "N", value_parser = super::args::positive_u64, allow_negative_numbers = true)]
    pub max_frames: Option<u64>,
    /// Frames per second. An image folder's pictures are then consecutive frames (without it,
    /// stills of one camera). A video's frames are timed at this rate instead of the one its
    /// file states: for a time-lapse or an export with a wrong rate (speeds scale with it).
    #[arg(long, value_name = "FPS", value_parser = super::args::positive_f64, allow_negative_numbers = true)]
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
        open_input(input, &self.options())
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
    #[arg(long, default_value = "auto", value_name = "NAME")]
    pub detector: DetectorChoice,
    /// Same as `--detector file:FILE`.
    #[arg(long, value_name = "FILE")]
    pub detections: Option<PathBuf>,
    /// Columns of square tiles the learned detector looks at besides the whole frame, for
    /// small vehicles in large frames (0: the whole frame only). Default: by frame width
    /// (0 up to 960 px, 2 above).
    #[arg(long, value_name = "N")]
    pub tiles: Option<u32>,
    /// Look at the whole frame and one tile per frame, the tiles in turn, instead of every
    /// tile in every frame: a third of the detector's time at 1080p, but far vehicles are
    /// seen in every second frame only (on the demo's scene 20 % fewer boxes, and a roll
    /// 2.5° off for want of edgelets).
    #[arg(long)]
    pub tile_rotation: bool,
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

impl DetectorArgs {
    /// The detector settings (`--detections F` is `--detector file:F`).
    ///
    /// # Errors
    /// Flags that contradict each other.
    pub fn settings(&self) -> Result<DetectorSettings> {
        let choice = match (&self.detections, &self.detector) {
            (Some(_), c) if *c != DetectorChoice::Auto => {
                bail!("--detections FILE is --detector file:FILE: give one of them")
            }
            (Some(path), _) => DetectorChoice::File(path.clone()),
            (None, c) => c.clone(),
        };
        let settings = DetectorSettings {
            choice,
            tiles: self.tiles,
            tile_rotation: self.tile_rotation,
            onnx_layout: self.onnx_layout,
            motorcycles: self.motorcycles,
            road_mask: self.road_mask.clone(),
        };
        settings.validate()?;
        Ok(settings)
    }
}

impl PipelineArgs {
    /// The pipeline configuration of these flags, validated.
    ///
    /// # Errors
    /// A message naming the flag that is wrong.
    pub fn config(&self) -> Result<PipelineConfig> {
        let config = PipelineConfig {
            model: self.model.clone(),
            device: self.device.clone(),
            batch: self.batch,
            flip_average: self.flip_average,
            min_crop_px: self.min_crop_px,
            edgelets: !self.no_edgelets,
            replay: !self.no_replay,
            frames: self.frames.options(),
            detector: self.detect.settings()?,
            min_score: self.min_score,
            keep_static: self.keep_static,
            max_per_frame: self.max_per_frame,
            crops: self.crops,
            method: self.method,
            bootstrap: self.bootstrap,
            pp: self.pp,
            focal_px: self.focal,
            focal_range_px: self.focal_range,
            max_records: self.max_records,
            markings: self.markings,
        };
        config.validate()?;
        Ok(config)
    }
}

fn parse_points(s: &str) -> Result<[f64; 4], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>().ok().filter(|v| v.is_finite()))
        .collect::<Option<Vec<f64>>>()
        .ok_or_else(|| format!("expected x1,y1,x2,y2 (finite numbers), got {s:?}"))?;
    match v[..] {
        [a, b, c, d] => Ok([a, b, c, d]),
        _ => Err(format!(
            "expected 4 numbers x1,y1,x2,y2, got {} in {s:?}",
            v.len()
        )),
    }
}

fn parse_start(s: &str) -> Result<Start, String> {
    s.parse::<Start>().map_err(|e| e.to_string())
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
            "{} detected, {} kept, {} of them through the network (dropped: {} low score, {} \
             static, {} seen in an earlier picture, {} over the per-frame limit)",
            s.detections,
            s.crops + s.crops_skipped,
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
            // One clause of the aggregation's summary per line, not one 900-character line.
            for (i, clause) in agg.summary.split("; ").enumerate() {
                row(if i == 0 { "aggregation" } else { "" }, clause.to_string());
            }
            row(
                "focal length",
                format!(
                    "{:.1} px ({}{})",
                    cal.focal_px,
                    agg.focal_source.name(),
                    match agg.focal_interval_px {
                        Some([lo, hi]) if agg.focal_source.is_assumed() => {
                            format!(": ASSUMED, plausible {lo:.0}-{hi:.0} px")
                        }
                        Some([lo, hi]) if lo < hi => format!(", 68% interval {lo:.0}-{hi:.0} px"),
                        _ => String::new(),
                    }
                ),
            );
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
    if let Ok((_, agg)) = result {
        for w in agg.warnings() {
            eprintln!("warning: {w}");
        }
    }
}

/// Write the overlay picture (`--overlay`, when there is a picture) and the HTML report
/// (`--report`) of a run whose calibration file is `doc`.
fn write_picture_and_report(
    args: &Args,
    img: Option<&image::RgbImage>,
    doc: &vpcal_formats::calib::CalibrationFile,
    (tracks, header): (&[vpcal::tracks::VehicleTrack], &output::TracksHeader),
    out: &PipelineOutput,
) -> Result<()> {
    if let (Some(path), Some(img)) = (&args.overlay, img) {
        vpcal_video::draw::save_png(img, path)?;
    }
    if let Some(path) = &args.report {
        let png = img
            .map(vpcal_formats::fs::encode_png)
            .transpose()
            .map_err(anyhow::Error::msg)?;
        let input = vpcal::report::ReportInput {
            overlay_png: png.as_deref(),
            tracks: Some(tracks),
            tracks_note: header.note.as_deref(),
            run_warnings: &out.warnings,
        };
        vpcal::report::write(path, &vpcal::report::render_with(doc, &input))?;
    }
    Ok(())
}

pub fn run(args: Args) -> Result<Exit> {
    if args.output.is_none() && !args.json && args.bcs_json.is_none() {
        return Err(UsageError(
            "nothing would keep the calibration: give -o FILE (the calibration file), --json \
             (print it) or --bcs-json FILE"
                .to_string(),
        )
        .into());
    }
    // Fail before a long run, not after it, when an output cannot be written or would
    // overwrite an input or another output.
    for (flag, path) in args.output_paths() {
        check_destination(flag, path)?;
    }
    check_distinct_paths(&args.input_paths(), &args.output_paths()).map_err(UsageError)?;
    if args.scale_points.len() != args.scale_distance.len() {
        return Err(UsageError(format!(
            "{} --scale-points but {} --scale-distance: give one distance per pair of points",
            args.scale_points.len(),
            args.scale_distance.len()
        ))
        .into());
    }
    if args.pipeline.no_edgelets && (args.background.is_some() || args.pipeline.markings.is_some())
    {
        return Err(UsageError(
            "--background and --markings need the scene's background, which --no-edgelets skips"
                .to_string(),
        )
        .into());
    }
    let config = args.pipeline.config()?;
    let bar = super::FrameBar::new("frames", args.pipeline.quiet);
    let out = vpcal::run_pipeline(&args.input, &config, &bar)?;
    for w in &out.warnings {
        eprintln!("warning: {w}");
    }
    let result = vpcal::calibrate(&out, &config);
    print_summary(&out, &result);
    if let Some(path) = &args.vehicles {
        output::write_vehicles(path, &out)?;
    }
    if let Some(path) = &args.scene_edgelets {
        output::write_scene(path, &out)?;
    }
    if let (Some(path), Some(bg)) = (&args.background, &out.background) {
        vpcal_video::draw::save_png(&image::DynamicImage::ImageLuma8(bg.clone()).to_rgb8(), path)?;
    }
    // The tracks' summary goes to stdout, unless stdout carries the calibration's JSON.
    let say = |line: String| {
        if args.json {
            eprintln!("{line}");
        } else {
            println!("{line}");
        }
    };
    match result {
        Ok((cal, agg)) => {
            let known: Vec<KnownDistance> = args
                .scale_points
                .iter()
                .zip(&args.scale_distance)
                .map(|(p, d)| KnownDistance {
                    p1: Point2::new(p[0], p[1]),
                    p2: Point2::new(p[2], p[3]),
                    distance_m: *d,
                })
                .collect();
            let output::CalibratedRun {
                file: doc,
                camera: cal,
                scale,
                tracks,
                header,
            } = output::calibrated_run(&out, &config, &cal, &agg, &known)?;
            if let Some(d) = doc.evidence.as_ref().and_then(|e| e.get("distances_focal")) {
                let iv = doc.focal_interval_px.unwrap_or([f64::NAN; 2]);
                eprintln!(
                    "  {:<22} {:.0} px (68% {:.0}-{:.0} px, {}); the known lengths alone {:.0} px",
                    "focal length, refit",
                    cal.focal_px,
                    iv[0],
                    iv[1],
                    doc.focal_source.as_deref().unwrap_or("?"),
                    d.get("focal_px")
                        .and_then(|v| v.as_f64())
                        .unwrap_or(f64::NAN)
                );
            }
            if let (Some(s), Some(source)) = (scale, doc.scale_source.as_deref()) {
                let height = doc.height_text().unwrap_or_else(|| "NaN m".to_string());
                let interval = doc
                    .scale_interval_m_per_unit
                    .map(|[lo, hi]| format!(", 68% {lo:.4}-{hi:.4}"))
                    .unwrap_or_default();
                eprintln!(
                    "  {:<22} {s:.4} m per unit ({source}{interval}); camera {height} above the \
                     road",
                    "scale"
                );
            }
            // The warnings the summary has not printed yet (the scale's, the plausibility
            // checks').
            let shown = agg.warnings();
            let printed = |w: &&String| shown.contains(w) || out.warnings.contains(w);
            for w in doc.warnings.iter().filter(|w| !printed(w)) {
                eprintln!("warning: {w}");
            }
            if doc.status != vpcal_formats::calib::Status::Calibrated {
                eprintln!(
                    "  {:<22} {} (see the warnings)",
                    "status",
                    doc.status.name().to_uppercase()
                );
            }
            if args.tracks.is_some() || args.bcs_json.is_some() {
                if let Some(path) = &args.tracks {
                    output::write_tracks(path, &header, &tracks)?;
                }
                let mut line = output::tracks_line(&tracks, &header);
                if let Some(path) = &args.bcs_json {
                    let cars =
                        output::write_bcs_system_with_tracks(path, &cal, scale, &tracks, &header)?;
                    line.push_str(&format!(
                        "; {cars} in the BrnoCompSpeed cars (at least {} unclipped points, speed known to {:.0} % and possible for a road vehicle)",
                        header.window_points,
                        100.0 * vpcal::tracks::BCS_MAX_SPEED_REL_UNCERTAINTY
                    ));
                }
                say(line);
            }
            if let Some(path) = &args.output {
                doc.write(path)?;
            }
            if let Some(path) = &args.opencv {
                output::write_opencv_yaml(path, &doc)?;
            }
            if args.overlay.is_some() || args.report.is_some() {
                let cam = Some((&cal, agg.track_lines.as_slice()));
                let img = overlay::draw_run(&out, &config.frames, cam, &tracks, scale);
                if args.overlay.is_some() && img.is_none() {
                    bail!("no frame to draw the overlay on");
                }
                write_picture_and_report(&args, img.as_ref(), &doc, (&tracks, &header), &out)?;
            }
            if args.json {
                print!("{}", doc.to_json_string());
            }
            Ok(Exit::Success)
        }
        Err(e) => {
            let doc = output::failure_file(&out, &config, format!("{e:#}"));
            if let Some(path) = &args.output {
                doc.write(path)?;
            }
            let picture = args.overlay.is_some() || args.report.is_some();
            if args.tracks.is_some() || picture {
                // Tracks without road points, for the tracks file and the picture.
                let (tracks, header) = output::run_tracks(&out, None, false, false);
                if let Some(path) = &args.tracks {
                    output::write_tracks(path, &header, &tracks)?;
                    say(output::tracks_line(&tracks, &header));
                }
                if picture {
                    let img = overlay::draw_run(&out, &config.frames, None, &tracks, None);
                    write_picture_and_report(&args, img.as_ref(), &doc, (&tracks, &header), &out)?;
                }
            }
            if args.json {
                print!("{}", doc.to_json_string());
            }
            eprintln!("vpcal: no calibration: {e:#}");
            Ok(Exit::NotEnoughEvidence)
        }
    }
}
