//! `vpcal eval`: score calibrations against BrnoCompSpeed and BrnoCarPark ground truth
//! (DESIGN.md §8).
//!
//! For each video and system: the pure-calibration ratio error over every pair of ground-truth
//! distances (independent of the scale), and the distance error with the file's scale (BCS) or
//! with the optimal per-session scale (BrnoCarPark). Pooled rows concatenate all pairs, as the
//! paper does.
//!
//! `eval speed` runs the official speed evaluation (`vpcal_formats::bcs_speed`) on the systems'
//! vehicle tracks, with the file's camera and scale, or with a reference camera and a scale
//! fitted to the taped distances.

use anyhow::{bail, Context, Result};
use rayon::prelude::*;
use serde::Serialize;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use vpcal::aggregate::{aggregate, edgelets_of, Method, Scene};
use vpcal_formats::bcp::read_gt_pairs;
use vpcal_formats::bcs::{
    self, read_gt, read_system, write_system, GtData, SystemCalibration, SystemFile,
};
use vpcal_formats::bcs_speed::{
    evaluate_video, pool as pool_speed, read_camera_truth, CameraTruth, PooledSpeed, Road,
    SpeedError, SpeedMode, VideoSpeed,
};
use vpcal_formats::reference::{read_vpout, SceneRecord};
use vpcal_geom::aggregate::{line_angle_diff, VehicleVps};
use vpcal_geom::camera::Calibration;
use vpcal_geom::metrics::{
    optimal_scale, ratio_errors, scaled_distance_errors, summarize, RoadMeasurement, Summary,
};
use vpcal_video::background::{keep_inside, scene_edgelet_options, scene_edgelets};
use vpcal_video::segments::{line_segments, SegmentOptions};

/// Evaluate calibrations against BrnoCompSpeed or BrnoCarPark ground truth.
#[derive(Debug, clap::Subcommand)]
pub enum EvalCommand {
    /// BrnoCompSpeed: DATASET/<video>/gt_data.pkl (or gt_data.json) against
    /// RESULTS/<video>/system_<name>.json.
    Bcs(BcsArgs),
    /// BrnoCarPark: GROUND_TRUTH/<session>/gt_pairs.json against RESULTS/<session>/system_<name>.json.
    Bcp(BcpArgs),
    /// Aggregate per-vehicle VP files (VP_OUTPUTS/<video>/VPout_*.json) with several methods
    /// and compare their BrnoCompSpeed ratio errors, per video and pooled.
    Vpout(VpoutArgs),
    /// BrnoCompSpeed speed evaluation (the official protocol of the dataset's eval.py): the
    /// vehicle tracks ("cars") of RESULTS/<video>/system_<name>.json measured with the file's
    /// camera and scale, matched to the ground-truth cars of DATASET/<video>/gt_data.pkl.
    Speed(SpeedArgs),
    /// Per-vehicle VP direction errors on real KITTI vehicles with exact VPs
    /// (DATA/vp_gt.json): the network, the guess "VP1 at the principal point", VP2 from
    /// edgelets.
    Kitti(super::kitti::KittiArgs),
    /// The automatic metric scale's cuboid fit on real KITTI cars with exact 3D labels and
    /// road planes: the metres per plane unit each car implies, over the truth, with its own
    /// labelled dimensions and with the typical car's.
    KittiScale(super::kitti::KittiScaleArgs),
}

#[derive(Debug, clap::Args)]
pub struct SpeedArgs {
    /// The dataset directory (holds sessionN_{left,center,right}/gt_data.pkl).
    #[arg(long)]
    pub dataset: PathBuf,
    /// The results directory (holds sessionN_{...}/system_<name>.json with "cars" tracks).
    #[arg(long)]
    pub results: PathBuf,
    /// Systems to evaluate (the <name> of system_<name>.json); default: every system found.
    #[arg(long, num_args = 1..)]
    pub system: Vec<String>,
    /// Only the sessions of an official split: A (1-6), B (3-6) or C (4-6).
    #[arg(long, value_parser = parse_split)]
    pub split: Option<char>,
    /// How a car's speed is measured: median (of the speeds over 5-point steps of its track,
    /// the official default) or full (between its crossings of the first and last
    /// measurement lines).
    #[arg(long, default_value = "median", value_parser = speed_mode())]
    pub mode: SpeedMode,
    /// Measure the tracks with another camera: FILE's cameras[<video>] {vp1, vp2, pp} (the
    /// layout of camera_truth.json) with a scale fitted to the video's taped distances
    /// (gt distanceMeasurement), instead of the system file's camera and scale. With the
    /// reference cameras this gives the tracks' own error floor.
    #[arg(long, value_name = "FILE")]
    pub camera_truth: Option<PathBuf>,
    /// Keep the system file's camera but fit its scale to the video's taped distances
    /// (always so with --camera-truth).
    #[arg(long)]
    pub fit_scale: bool,
    /// Image size WxH of the videos: points within 10 px of its border are not used.
    #[arg(long, value_parser = super::args::size, default_value = "1920x1080")]
    pub image_size: (u32, u32),
    /// Print machine-readable JSON instead of tables.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, clap::Args)]
pub struct VpoutArgs {
    /// Directory of per-video folders holding VPout_*.json files.
    #[arg(long)]
    pub vp_outputs: PathBuf,
    /// The BrnoCompSpeed dataset directory (ground truth).
    #[arg(long)]
    pub dataset: PathBuf,
    /// Aggregation methods to compare (robust, robust-network, reference).
    #[arg(long, num_args = 1.., default_values = ["reference", "robust"], value_parser = super::args::method())]
    pub methods: Vec<Method>,
    /// Only the sessions of an official split: A (1-6), B (3-6) or C (4-6).
    #[arg(long, value_parser = parse_split)]
    pub split: Option<char>,
    /// Image size WxH of the videos (principal point: the BrnoCompSpeed convention).
    #[arg(long, value_parser = super::args::size, default_value = "1920x1080")]
    pub image_size: (u32, u32),
    /// Keep vehicles whose detector score is above this.
    #[arg(long, default_value_t = 0.1)]
    pub min_score: f64,
    /// Also write every calibration as <DIR>/<video>/system_<variant>_<method>.json.
    #[arg(long)]
    pub write_results: Option<PathBuf>,
    /// Do not take the scene's lines from each video's `screen.png` (a frame of the video in
    /// the dataset folder): neither its lines along the road (inside `video_mask.png`) nor
    /// its vertical lines (the whole frame); VP1 and the focal length then come from the
    /// VPout records alone.
    #[arg(long)]
    pub no_scene: bool,
    /// The roads' marking standard, PERIOD,LANE in metres or a key (as `calibrate --markings`): the
    /// lane lines of each video's `screen.png` then measure the focal length and join each
    /// calibration's own (`vpcal::road_focal::combine`).
    #[arg(long, value_name = "PERIOD,LANE|KEY")]
    pub markings: Option<vpcal::markings::MarkingStandard>,
    /// The reference cameras (FILE's cameras[<video>] {vp1, vp2, pp}, the layout of
    /// camera_truth.json): each calibration's focal length is then compared with theirs, and
    /// each variant's summary says the median focal error, how many 68 % intervals hold the
    /// reference and their median width (long end over short).
    #[arg(long, value_name = "FILE")]
    pub camera_truth: Option<PathBuf>,
    /// Print machine-readable JSON instead of tables.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, clap::Args)]
pub struct BcsArgs {
    /// The dataset directory (holds sessionN_{left,center,right}/gt_data.pkl).
    #[arg(long)]
    pub dataset: PathBuf,
    /// The results directory (holds sessionN_{...}/system_<name>.json).
    #[arg(long)]
    pub results: PathBuf,
    /// Only the sessions of an official split: A (1-6), B (3-6) or C (4-6).
    #[arg(long, value_parser = parse_split)]
    pub split: Option<char>,
    /// Systems to evaluate (the <name> of system_<name>.json); default: every system found.
    #[arg(long, num_args = 1..)]
    pub system: Vec<String>,
    /// Print machine-readable JSON instead of tables.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, clap::Args)]
pub struct BcpArgs {
    /// The ground-truth directory (holds SXX/gt_pairs.json).
    #[arg(long)]
    pub ground_truth: PathBuf,
    /// The results directory (holds SXX/system_<name>.json).
    #[arg(long)]
    pub results: PathBuf,
    /// Systems to evaluate; default: every system found.
    #[arg(long, num_args = 1..)]
    pub system: Vec<String>,
    /// Print machine-readable JSON instead of tables.
    #[arg(long)]
    pub json: bool,
}

fn speed_mode() -> impl clap::builder::TypedValueParser<Value = SpeedMode> {
    use clap::builder::TypedValueParser as _;
    clap::builder::PossibleValuesParser::new(["median", "full"])
        .map(|s| s.parse().unwrap_or(SpeedMode::Median))
}

fn parse_split(s: &str) -> Result<char, String> {
    let c = s.chars().next().unwrap_or(' ').to_ascii_uppercase();
    if s.len() == 1 && bcs::split_sessions(c).is_some() {
        Ok(c)
    } else {
        Err(format!("expected a split A, B or C, got {s:?}"))
    }
}

pub fn run(cmd: EvalCommand) -> Result<()> {
    match cmd {
        EvalCommand::Bcs(args) => run_bcs(&args),
        EvalCommand::Bcp(args) => run_bcp(&args),
        EvalCommand::Vpout(args) => run_vpout(&args),
        EvalCommand::Speed(args) => run_speed(&args),
        EvalCommand::Kitti(args) => super::kitti::run(args),
        EvalCommand::KittiScale(args) => super::kitti::run_scale(args),
    }
}

/// The outcome for one video (or session) and one system.
#[derive(Debug, Clone, Serialize)]
pub struct VideoResult {
    pub video: String,
    /// `ok`, `missing` (no system file) or `invalid` (no camera from the file).
    pub status: &'static str,
    /// Why the calibration is invalid, when it is.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ratio: Option<Summary>,
    /// Distance errors with the file's scale (BCS) or the optimal scale (BrnoCarPark).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub distance: Option<Summary>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scale: Option<f64>,
    #[serde(skip)]
    ratio_values: Vec<f64>,
    #[serde(skip)]
    distance_values: Vec<f64>,
}

/// All videos of one system and the pooled errors.
#[derive(Debug, Clone, Serialize)]
pub struct SystemResult {
    pub system: String,
    pub videos: Vec<VideoResult>,
    pub pooled_ratio: Option<Summary>,
    pub pooled_distance: Option<Summary>,
    pub evaluated: usize,
    pub missing: usize,
    pub invalid: usize,
}

enum ScaleMode {
    FromFile,
    Optimal,
}

fn evaluate_one(
    video: &str,
    system: Option<&SystemFile>,
    measurements: &[RoadMeasurement],
    mode: &ScaleMode,
) -> VideoResult {
    let mut r = VideoResult {
        video: video.to_string(),
        status: "missing",
        reason: None,
        ratio: None,
        distance: None,
        scale: None,
        ratio_values: vec![],
        distance_values: vec![],
    };
    let Some(system) = system else {
        return r;
    };
    let c = &system.calibration;
    let calib = match Calibration::from_vps(c.vp1, c.vp2, c.pp) {
        Ok(calib) => calib,
        Err(e) => {
            r.status = "invalid";
            r.reason = Some(e.to_string());
            return r;
        }
    };
    let Some(ratios) = ratio_errors(&calib, measurements) else {
        r.status = "invalid";
        r.reason = Some("a ground-truth point cannot be projected onto the road".into());
        return r;
    };
    let scale = match mode {
        ScaleMode::FromFile => Some(c.scale),
        ScaleMode::Optimal => optimal_scale(&calib, measurements),
    };
    let distances = scale
        .and_then(|s| scaled_distance_errors(&calib, s, measurements))
        .unwrap_or_default();
    r.status = "ok";
    r.ratio = summarize(&ratios);
    r.distance = summarize(&distances);
    r.scale = scale;
    r.ratio_values = ratios;
    r.distance_values = distances;
    r
}

fn pool(system: String, videos: Vec<VideoResult>) -> SystemResult {
    let ratio: Vec<f64> = videos
        .iter()
        .flat_map(|v| v.ratio_values.iter().copied())
        .collect();
    let distance: Vec<f64> = videos
        .iter()
        .flat_map(|v| v.distance_values.iter().copied())
        .collect();
    let count = |s: &str| videos.iter().filter(|v| v.status == s).count();
    SystemResult {
        system,
        pooled_ratio: summarize(&ratio),
        pooled_distance: summarize(&distance),
        evaluated: count("ok"),
        missing: count("missing"),
        invalid: count("invalid"),
        videos,
    }
}

/// System names found as `system_<name>.json` in the given directories.
/// The systems to evaluate: the ones asked for, or every `system_<name>.json` found in `dirs`
/// (one per video or session, `what` in the error when there is none).
fn system_names(
    systems: &[String],
    dirs: impl Iterator<Item = PathBuf>,
    results: &Path,
    what: &str,
) -> Result<Vec<String>> {
    if !systems.is_empty() {
        return Ok(systems.to_vec());
    }
    let names: Vec<String> = find_systems(dirs).into_iter().collect();
    if names.is_empty() {
        bail!(
            "no system_<name>.json under {} for these {what}",
            results.display()
        );
    }
    Ok(names)
}

fn find_systems(dirs: impl Iterator<Item = PathBuf>) -> BTreeSet<String> {
    let mut names = BTreeSet::new();
    for dir in dirs {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for e in entries.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            if let Some(n) = name
                .strip_prefix("system_")
                .and_then(|n| n.strip_suffix(".json"))
            {
                names.insert(n.to_string());
            }
        }
    }
    names
}

fn read_system_opt(path: &Path) -> Result<Option<SystemFile>> {
    if path.is_file() {
        Ok(Some(read_system(path)?))
    } else {
        Ok(None)
    }
}

/// The video directories of a BrnoCompSpeed dataset, only those of `split`'s sessions when
/// given.
fn split_videos(dataset: &Path, split: Option<char>) -> Result<Vec<(String, PathBuf)>> {
    let mut videos = bcs::list_videos(dataset)
        .with_context(|| format!("listing the BrnoCompSpeed dataset {}", dataset.display()))?;
    if let Some(split) = split {
        let sessions = bcs::split_sessions(split).unwrap_or(&[]);
        videos.retain(|(name, _)| {
            bcs::parse_video_name(name).is_some_and(|(s, _)| sessions.contains(&s))
        });
    }
    Ok(videos)
}

/// [`split_videos`], at least one.
fn dataset_videos(dataset: &Path, split: Option<char>) -> Result<Vec<(String, PathBuf)>> {
    let videos = split_videos(dataset, split)?;
    if videos.is_empty() {
        bail!(
            "no video with gt_data.pkl or gt_data.json under {}{}",
            dataset.display(),
            split.map_or(String::new(), |s| format!(" in split {s}"))
        );
    }
    Ok(videos)
}

/// Evaluate BrnoCompSpeed results; the library entry point of `vpcal eval bcs`.
///
/// # Errors
/// Unreadable directories or ground-truth files, malformed system files, or no video found.
pub fn evaluate_bcs(
    dataset: &Path,
    results: &Path,
    split: Option<char>,
    systems: &[String],
) -> Result<Vec<SystemResult>> {
    let videos = dataset_videos(dataset, split)?;
    let names = system_names(
        systems,
        videos.iter().map(|(v, _)| results.join(v)),
        results,
        "videos",
    )?;
    let mut gts = Vec::with_capacity(videos.len());
    for (name, dir) in &videos {
        let gt = read_gt(dir)?;
        gts.push((name.clone(), gt.road_measurements()));
    }
    let mut out = Vec::new();
    for system in names {
        let mut rows = Vec::new();
        for (video, measurements) in &gts {
            let path = results.join(video).join(format!("system_{system}.json"));
            let file = read_system_opt(&path)?;
            rows.push(evaluate_one(
                video,
                file.as_ref(),
                measurements,
                &ScaleMode::FromFile,
            ));
        }
        out.push(pool(system, rows));
    }
    Ok(out)
}

/// Evaluate BrnoCarPark results; the library entry point of `vpcal eval bcp`.
///
/// # Errors
/// Unreadable directories or ground-truth files, malformed system files, or no session found.
pub fn evaluate_bcp(
    ground_truth: &Path,
    results: &Path,
    systems: &[String],
) -> Result<Vec<SystemResult>> {
    let mut sessions = Vec::new();
    for e in std::fs::read_dir(ground_truth).with_context(|| {
        format!(
            "listing the BrnoCarPark ground truth {}",
            ground_truth.display()
        )
    })? {
        let e = e?;
        let gt = e.path().join("gt_pairs.json");
        if gt.is_file() {
            sessions.push((e.file_name().to_string_lossy().into_owned(), gt));
        }
    }
    sessions.sort();
    if sessions.is_empty() {
        bail!(
            "no <session>/gt_pairs.json under {}",
            ground_truth.display()
        );
    }
    let names = system_names(
        systems,
        sessions.iter().map(|(s, _)| results.join(s)),
        results,
        "sessions",
    )?;
    let mut gts = Vec::new();
    for (name, path) in &sessions {
        gts.push((name.clone(), read_gt_pairs(path)?));
    }
    let mut out = Vec::new();
    for system in names {
        let mut rows = Vec::new();
        for (session, measurements) in &gts {
            let path = results.join(session).join(format!("system_{system}.json"));
            let file = read_system_opt(&path)?;
            rows.push(evaluate_one(
                session,
                file.as_ref(),
                measurements,
                &ScaleMode::Optimal,
            ));
        }
        out.push(pool(system, rows));
    }
    Ok(out)
}

fn run_bcs(args: &BcsArgs) -> Result<()> {
    let results = evaluate_bcs(&args.dataset, &args.results, args.split, &args.system)?;
    print_results(&results, args.json, "distance error with the file's scale")
}

fn run_bcp(args: &BcpArgs) -> Result<()> {
    let results = evaluate_bcp(&args.ground_truth, &args.results, &args.system)?;
    print_results(&results, args.json, "distance error with the optimal scale")
}

fn print_results(results: &[SystemResult], json: bool, distance_label: &str) -> Result<()> {
    if json {
        println!("{}", serde_json::to_string_pretty(results)?);
        return Ok(());
    }
    for (k, s) in results.iter().enumerate() {
        if k > 0 {
            println!();
        }
        println!("system {}", s.system);
        println!("  ratio error % (pairs of distances) | {distance_label} %");
        println!(
            "{:<18} {:>6} {:>8} {:>8} {:>8} {:>8} | {:>4} {:>8} {:>8}",
            "video", "pairs", "mean", "median", "p95", "max", "n", "mean", "median"
        );
        for v in &s.videos {
            print_row(&v.video, v.ratio.as_ref(), v.distance.as_ref(), v);
        }
        let pooled = format!("pooled ({}/{})", s.evaluated, s.videos.len());
        match &s.pooled_ratio {
            Some(r) => println!(
                "{:<18} {:>6} {:>8.3} {:>8.3} {:>8.3} {:>8.3} | {}",
                pooled,
                r.n,
                r.mean,
                r.median,
                r.p95,
                r.max,
                fmt_distance(s.pooled_distance.as_ref())
            ),
            None => println!("{pooled:<18} no evaluable video"),
        }
    }
    Ok(())
}

fn fmt_distance(d: Option<&Summary>) -> String {
    match d {
        Some(d) => format!("{:>4} {:>8.3} {:>8.3}", d.n, d.mean, d.median),
        None => format!("{:>4} {:>8} {:>8}", "-", "-", "-"),
    }
}

fn print_row(name: &str, ratio: Option<&Summary>, distance: Option<&Summary>, v: &VideoResult) {
    match (v.status, ratio) {
        ("ok", Some(r)) => println!(
            "{:<18} {:>6} {:>8.3} {:>8.3} {:>8.3} {:>8.3} | {}",
            name,
            r.n,
            r.mean,
            r.median,
            r.p95,
            r.max,
            fmt_distance(distance)
        ),
        ("ok", None) => println!("{name:<18} fewer than two distances: no pair to compare"),
        ("missing", _) => println!("{name:<18} missing (no system file)"),
        _ => println!(
            "{name:<18} invalid: {}",
            v.reason.as_deref().unwrap_or("no camera")
        ),
    }
}

/// The focal length the lane lines (`bars` of the screen) give under `standard` on the camera
/// of `vp1`, `vp2` and `pp` (frames `width` wide), combined with the aggregation's focal
/// length (`prior`: its value, interval and source): the camera's new VP2, focal length and
/// its interval, or `None` where the markings measure nothing.
fn with_markings(
    bars: &[vpcal_video::markings::Bar],
    standard: &vpcal::markings::MarkingStandard,
    (vp1, vp2, pp): (vpcal_geom::Point2, vpcal_geom::Point2, vpcal_geom::Point2),
    width: f64,
    prior: vpcal::road_focal::PriorFocal,
) -> Option<(vpcal_geom::Point2, f64, Option<[f64; 2]>)> {
    use vpcal::road_focal::{
        camera_with_focal, combine, fit_focal_from_lengths, CameraSpread, LengthFocalFit,
    };
    let cal = vpcal_geom::camera::Calibration::from_vps(vp1, vp2, pp).ok()?;
    let lines = vpcal::markings::lane_lines(bars, vp1);
    let inputs = vpcal::markings::standard_lengths(&lines, &cal, standard);
    let LengthFocalFit::Measured(m) =
        fit_focal_from_lengths(&cal, &inputs, CameraSpread::floored(None, width), width)
    else {
        return None;
    };
    let range = vpcal_geom::aggregate::focal::focal_prior_range_widths(None).map(|r| r * width);
    let c = combine(&m, &prior, "markings", range).ok()?;
    let camera = camera_with_focal(&cal, c.focal_px)?;
    Some((camera.vp2, c.focal_px, Some(c.interval_px)))
}

/// The bright bars of a BrnoCompSpeed video's `screen.png` inside its `video_mask.png`
/// (road markings); none without a screen.
///
/// # Errors
/// A screen or mask that cannot be read.
fn video_bars(dir: &Path) -> Result<Vec<vpcal_video::markings::Bar>> {
    let screen = dir.join("screen.png");
    if !screen.exists() {
        return Ok(Vec::new());
    }
    let grey = image::open(&screen)
        .with_context(|| format!("reading {}", screen.display()))?
        .to_luma8();
    let mask_path = dir.join("video_mask.png");
    let mask = if mask_path.exists() {
        Some(
            image::open(&mask_path)
                .with_context(|| format!("reading {}", mask_path.display()))?
                .to_luma8(),
        )
    } else {
        None
    };
    let options = vpcal_video::markings::BarOptions::default();
    Ok(vpcal_video::markings::bright_bars(
        &grey,
        mask.as_ref(),
        &options,
    ))
}

/// What a BrnoCompSpeed video's `screen.png` (one frame of the video) shows: its edgelets
/// without those where its `video_mask.png` is black (the mask keeps the road, whose lines
/// place VP1), and its line segments over the whole frame (as `calibrate` sees it: the
/// mask would leave out the poles and posts beside the road, the vertical lines that
/// measure the focal length); nothing without a screen.
///
/// # Errors
/// A screen or mask that cannot be read, or a mask of another size.
fn video_scene(dir: &Path) -> Result<SceneRecord> {
    let screen = dir.join("screen.png");
    if !screen.exists() {
        return Ok(SceneRecord::default());
    }
    // The grey `calibrate` takes from a video's frames.
    let image = vpcal_video::edges::grey_opencv(
        &image::open(&screen)
            .with_context(|| format!("reading {}", screen.display()))?
            .to_rgb8(),
    );
    let mut edgelets = scene_edgelets(&image, &scene_edgelet_options());
    let mask_path = dir.join("video_mask.png");
    if mask_path.exists() {
        let mask = image::open(&mask_path)
            .with_context(|| format!("reading {}", mask_path.display()))?
            .to_luma8();
        if mask.dimensions() != image.dimensions() {
            bail!(
                "{}: {}x{}, expected the size of screen.png ({}x{})",
                mask_path.display(),
                mask.width(),
                mask.height(),
                image.width(),
                image.height()
            );
        }
        keep_inside(&mut edgelets, &mask);
    }
    Ok(SceneRecord {
        edgelets,
        segments: line_segments(&image, &SegmentOptions::default()),
    })
}

/// One variant (VPout file stem) and method, over all videos.
#[derive(Debug, Clone, Serialize)]
pub struct VpoutResult {
    pub variant: String,
    pub method: &'static str,
    #[serde(flatten)]
    pub result: SystemResult,
    /// Focal length per video, pixels (`None` when the method gave no calibration).
    pub focal_px: Vec<Option<f64>>,
    /// Its 68 % interval per video, pixels.
    pub focal_interval_px: Vec<Option<[f64; 2]>>,
    /// With `--camera-truth`: the reference camera's focal length per video (`None` where
    /// the file has no camera for it), and the summary against them.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub focal_truth_px: Option<Vec<Option<f64>>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub focal_summary: Option<FocalSummary>,
}

/// A variant's focal lengths against the reference cameras.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FocalSummary {
    /// Videos with both a calibration and a reference camera.
    pub videos: usize,
    /// Median of |focal / reference - 1|, percent.
    pub median_abs_error_pct: f64,
    /// Videos whose 68 % interval holds the reference focal length.
    pub covered: usize,
    /// Median of the intervals' long end over their short end.
    pub median_hi_lo: f64,
    /// Median of |horizon angle - reference's|, degrees (the roll's error).
    pub median_abs_roll_error_deg: f64,
}

/// The focal lengths `focal` (with their `interval`s) and horizon angles `roll` (degrees)
/// against the references `truth` (focal length, horizon angle).
fn focal_summary(
    focal: &[Option<f64>],
    interval: &[Option<[f64; 2]>],
    roll: &[Option<f64>],
    truth: &[Option<(f64, f64)>],
) -> Option<FocalSummary> {
    let (mut errors, mut ratios, mut covered, mut rolls) = (Vec::new(), Vec::new(), 0, Vec::new());
    for (((f, iv), r), t) in focal.iter().zip(interval).zip(roll).zip(truth) {
        let (Some(f), Some((t, t_roll))) = (f, t) else {
            continue;
        };
        if let Some(r) = r {
            rolls.push(
                line_angle_diff((r - t_roll).to_radians())
                    .to_degrees()
                    .abs(),
            );
        }
        errors.push(100.0 * (f / t - 1.0).abs());
        if let Some([lo, hi]) = iv {
            ratios.push(hi / lo);
            covered += usize::from(*lo <= *t && *t <= *hi);
        }
    }
    Some(FocalSummary {
        videos: errors.len(),
        median_abs_error_pct: vpcal_geom::metrics::median(&errors)?,
        covered,
        median_hi_lo: vpcal_geom::metrics::median(&ratios).unwrap_or(f64::NAN),
        median_abs_roll_error_deg: vpcal_geom::metrics::median(&rolls).unwrap_or(f64::NAN),
    })
}

/// The angle of the horizon through `vp1` and `vp2`, degrees.
fn horizon_deg(vp1: vpcal_geom::Point2, vp2: vpcal_geom::Point2) -> f64 {
    (vp2.y - vp1.y).atan2(vp2.x - vp1.x).to_degrees()
}

/// The focal length and horizon angle (degrees) of a reference camera.
fn truth_camera(c: &CameraTruth) -> Option<(f64, f64)> {
    Some((
        vpcal_geom::camera::focal_from_vps(c.vp1, c.vp2, c.pp)?,
        horizon_deg(c.vp1, c.vp2),
    ))
}

/// Aggregate every VPout file with every method and evaluate it; the library entry point of
/// `vpcal eval vpout`.
///
/// # Errors
/// Unreadable directories, ground truth or VPout files; no video with both.
pub fn evaluate_vpout(args: &VpoutArgs) -> Result<Vec<VpoutResult>> {
    let videos = split_videos(&args.dataset, args.split)?;
    let truth = args
        .camera_truth
        .as_deref()
        .map(read_camera_truth)
        .transpose()?;
    // (video, measurements, [(variant, file)], the scene's edgelets: empty without a screen,
    // the screen's bright bars with --markings)
    let mut work = Vec::new();
    let mut variants = BTreeSet::new();
    for (video, dir) in &videos {
        let vdir = args.vp_outputs.join(video);
        let Ok(entries) = std::fs::read_dir(&vdir) else {
            continue;
        };
        let mut files = Vec::new();
        for e in entries {
            let path = e
                .with_context(|| format!("listing {}", vdir.display()))?
                .path();
            let name = path.file_name().map(|n| n.to_string_lossy().into_owned());
            if let Some(stem) = name.as_deref().and_then(|n| n.strip_suffix(".json")) {
                if stem.starts_with("VPout") {
                    variants.insert(stem.to_string());
                    files.push((stem.to_string(), path));
                }
            }
        }
        if !files.is_empty() {
            let gt = read_gt(dir)?;
            let scene = if args.no_scene {
                SceneRecord::default()
            } else {
                video_scene(dir)?
            };
            let bars = if args.markings.is_some() {
                video_bars(dir)?
            } else {
                Vec::new()
            };
            work.push((video.clone(), gt.road_measurements(), files, scene, bars));
        }
    }
    if work.is_empty() {
        bail!(
            "no video has both ground truth under {} and VPout_*.json under {}",
            args.dataset.display(),
            args.vp_outputs.display()
        );
    }
    // The BrnoCompSpeed protocol: its files' principal point convention.
    let pp = vpcal::pipeline::PrincipalPoint::Bcs.resolve(args.image_size.0, args.image_size.1);
    // Every (video, file, method) job, run in parallel.
    let jobs: Vec<(usize, String, PathBuf, Method)> = work
        .iter()
        .enumerate()
        .flat_map(|(vi, (_, _, files, _, _))| {
            files.iter().flat_map(move |(stem, path)| {
                args.methods
                    .iter()
                    .map(move |m| (vi, stem.clone(), path.clone(), *m))
            })
        })
        .collect();
    /// One scored job: video index, VPout file stem, method, its row, focal length, its
    /// interval and the horizon's angle (degrees).
    type Outcome = (
        usize,
        String,
        Method,
        VideoResult,
        Option<(f64, Option<[f64; 2]>, f64)>,
    );
    let outcomes: Vec<Result<Outcome>> = jobs
        .par_iter()
        .map(|(vi, stem, path, method)| {
            let (video, measurements, _, scene, bars) = &work[*vi];
            let items = read_vpout(path)?;
            let vehicles: Vec<VehicleVps> = items.iter().map(|i| i.to_vehicle()).collect();
            // The table shows no confidence: skip the bootstrap.
            let agg = aggregate(
                &vehicles,
                &edgelets_of(&items),
                Scene {
                    edgelets: &scene.edgelets,
                    segments: &scene.segments,
                },
                pp,
                args.image_size,
                *method,
                args.min_score,
                0,
                None,
            );
            let (row, focal) = match agg {
                Ok(a) => {
                    let marked = args.markings.as_ref().and_then(|standard| {
                        let prior = vpcal::road_focal::PriorFocal {
                            focal_px: a.focal_px,
                            interval_px: a.focal_interval_px,
                            source: a.focal_source.name().to_string(),
                        };
                        let width = f64::from(args.image_size.0);
                        with_markings(bars, standard, (a.vp1, a.vp2, pp), width, prior)
                    });
                    let (vp2, focal_px, interval) =
                        marked.unwrap_or((a.vp2, a.focal_px, a.focal_interval_px));
                    let system = SystemFile::new(SystemCalibration {
                        vp1: a.vp1,
                        vp2,
                        pp,
                        scale: 1.0,
                    });
                    if let Some(dir) = &args.write_results {
                        let out = dir.join(video);
                        std::fs::create_dir_all(&out)
                            .with_context(|| format!("creating {}", out.display()))?;
                        write_system(
                            &out.join(format!("system_{stem}_{}.json", method.name())),
                            &system,
                        )?;
                    }
                    (
                        evaluate_one(video, Some(&system), measurements, &ScaleMode::FromFile),
                        Some((focal_px, interval, horizon_deg(a.vp1, vp2))),
                    )
                }
                Err(e) => {
                    let mut r = evaluate_one(video, None, measurements, &ScaleMode::FromFile);
                    r.status = "invalid";
                    r.reason = Some(e.to_string());
                    (r, None)
                }
            };
            Ok((*vi, stem.clone(), *method, row, focal))
        })
        .collect();
    let mut rows = Vec::with_capacity(outcomes.len());
    for o in outcomes {
        rows.push(o?);
    }
    let mut out = Vec::new();
    for variant in &variants {
        for method in &args.methods {
            let mut videos_rows = Vec::new();
            let mut focals = Vec::new();
            let mut intervals = Vec::new();
            let mut rolls = Vec::new();
            let mut truths = Vec::new();
            for (vi, (video, measurements, _, _, _)) in work.iter().enumerate() {
                match rows
                    .iter()
                    .find(|r| r.0 == vi && &r.1 == variant && r.2 == *method)
                {
                    Some(r) => {
                        videos_rows.push(r.3.clone());
                        focals.push(r.4.map(|f| f.0));
                        intervals.push(r.4.and_then(|f| f.1));
                        rolls.push(r.4.map(|f| f.2));
                    }
                    None => {
                        videos_rows.push(evaluate_one(
                            video,
                            None,
                            measurements,
                            &ScaleMode::FromFile,
                        ));
                        focals.push(None);
                        intervals.push(None);
                        rolls.push(None);
                    }
                }
                truths.push(
                    truth
                        .as_ref()
                        .and_then(|t| t.get(video))
                        .and_then(truth_camera),
                );
            }
            let focal_summary = truth
                .is_some()
                .then(|| focal_summary(&focals, &intervals, &rolls, &truths))
                .flatten();
            out.push(VpoutResult {
                variant: variant.clone(),
                method: method.name(),
                result: pool(format!("{variant}_{}", method.name()), videos_rows),
                focal_px: focals,
                focal_interval_px: intervals,
                focal_truth_px: truth
                    .is_some()
                    .then(|| truths.iter().map(|t| t.map(|t| t.0)).collect()),
                focal_summary,
            });
        }
    }
    Ok(out)
}

fn run_vpout(args: &VpoutArgs) -> Result<()> {
    let results = evaluate_vpout(args)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&results)?);
        return Ok(());
    }
    let variants: BTreeSet<&str> = results.iter().map(|r| r.variant.as_str()).collect();
    for (k, variant) in variants.iter().enumerate() {
        if k > 0 {
            println!();
        }
        let rows: Vec<&VpoutResult> = results.iter().filter(|r| r.variant == *variant).collect();
        println!("{variant}");
        println!("  mean ratio error % (focal length px) per method; '-' = no VPout file");
        let mut header = format!("{:<18}", "video");
        for r in &rows {
            header.push_str(&format!(" {:>20}", r.method));
        }
        println!("{header}");
        let n_videos = rows.first().map_or(0, |r| r.result.videos.len());
        for vi in 0..n_videos {
            let mut line = format!("{:<18}", rows[0].result.videos[vi].video);
            for r in &rows {
                let v = &r.result.videos[vi];
                let cell = match (v.status, &v.ratio, r.focal_px[vi]) {
                    ("ok", Some(s), Some(f)) => format!("{:8.2} ({:>7.0})", s.mean, f),
                    ("missing", _, _) => "-".to_string(),
                    _ => "no calibration".to_string(),
                };
                line.push_str(&format!(" {cell:>20}"));
            }
            println!("{line}");
        }
        let mut pooled = format!("{:<18}", "pooled");
        for r in &rows {
            let cell = match &r.result.pooled_ratio {
                Some(s) => format!(
                    "{:8.2} [{}/{}]",
                    s.mean,
                    r.result.evaluated,
                    r.result.evaluated + r.result.invalid
                ),
                None => "-".into(),
            };
            pooled.push_str(&format!(" {cell:>20}"));
        }
        println!("{pooled}");
        if rows.iter().any(|r| r.focal_summary.is_some()) {
            let mut focal = format!("{:<18}", "focal vs truth");
            for r in &rows {
                let cell = match &r.focal_summary {
                    Some(f) => format!(
                        "{:.1} % {}/{} x{:.2} {:.2}°",
                        f.median_abs_error_pct,
                        f.covered,
                        f.videos,
                        f.median_hi_lo,
                        f.median_abs_roll_error_deg
                    ),
                    None => "-".into(),
                };
                focal.push_str(&format!(" {cell:>20}"));
            }
            println!("{focal}");
            println!(
                "  (median |focal error|, 68 % intervals holding the reference / videos, their \
                 median long/short end, median |horizon angle error|)"
            );
        }
    }
    Ok(())
}

/// Where the camera and scale of a speed evaluation come from.
enum SpeedCamera {
    /// The system file's camera; its scale, or one fitted to the taped distances.
    System { fit_scale: bool },
    /// The reference cameras of a file, with fitted scales.
    Truth {
        path: PathBuf,
        cameras: BTreeMap<String, CameraTruth>,
    },
}

impl SpeedCamera {
    fn describe(&self) -> String {
        match self {
            SpeedCamera::System { fit_scale: false } => {
                "camera and scale from the system file".into()
            }
            SpeedCamera::System { fit_scale: true } => {
                "the system file's camera, scale fitted to the taped distances".into()
            }
            SpeedCamera::Truth { path, .. } => format!(
                "cameras of {}, scale fitted to the taped distances",
                path.display()
            ),
        }
    }
}

/// One video of a speed evaluation.
#[derive(Debug, Clone, Serialize)]
pub struct SpeedVideoResult {
    pub video: String,
    /// `ok`, `missing` (no system file), `invalid` (no camera or scale) or `skipped` (no
    /// speed ground truth).
    pub status: &'static str,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// Metres per road-plane unit used.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scale: Option<f64>,
    #[serde(flatten)]
    pub speed: Option<VideoSpeed>,
}

/// One system's speed evaluation over all videos.
#[derive(Debug, Clone, Serialize)]
pub struct SpeedSystemResult {
    pub system: String,
    pub mode: SpeedMode,
    /// Where the camera and the scale came from.
    pub camera: String,
    pub videos: Vec<SpeedVideoResult>,
    /// Over the `ok` videos.
    pub pooled: PooledSpeed,
    pub evaluated: usize,
    pub missing: usize,
    pub invalid: usize,
    /// Videos without speed ground truth (fewer than 2 measurement lines: a curve, a
    /// junction).
    pub skipped: usize,
}

/// The ground-truth file of a video directory (the one `read_gt` reads), for messages.
fn gt_file(dir: &Path) -> PathBuf {
    let pkl = dir.join("gt_data.pkl");
    if pkl.is_file() {
        pkl
    } else {
        dir.join("gt_data.json")
    }
}

fn speed_video(
    video: &str,
    dir: &Path,
    gt: &GtData,
    system_path: &Path,
    camera: &SpeedCamera,
    mode: SpeedMode,
    image: [f64; 2],
) -> Result<SpeedVideoResult> {
    let mut r = SpeedVideoResult {
        video: video.to_string(),
        status: "missing",
        reason: None,
        scale: None,
        speed: None,
    };
    if gt.measurement_lines.len() < 2 {
        r.status = "skipped";
        r.reason = Some(format!(
            "no speed ground truth: {} measurementLines in {} (2 needed)",
            gt.measurement_lines.len(),
            gt_file(dir).display()
        ));
        return Ok(r);
    }
    let Some(system) = read_system_opt(system_path)? else {
        return Ok(r);
    };
    r.status = "invalid";
    let c = &system.calibration;
    let (vp1, vp2, pp, file_scale) = match camera {
        SpeedCamera::System { fit_scale } => (c.vp1, c.vp2, c.pp, (!fit_scale).then_some(c.scale)),
        SpeedCamera::Truth { path, cameras } => match cameras.get(video) {
            Some(t) => (t.vp1, t.vp2, t.pp, None),
            None => {
                r.reason = Some(format!("no camera for {video} in {}", path.display()));
                return Ok(r);
            }
        },
    };
    let calib = match Calibration::from_vps(vp1, vp2, pp) {
        Ok(calib) => calib,
        Err(e) => {
            r.reason = Some(e.to_string());
            return Ok(r);
        }
    };
    let scale = match file_scale {
        Some(s) => s,
        None => match optimal_scale(&calib, &gt.road_measurements()) {
            Some(s) => s,
            None => {
                r.reason = Some(format!(
                    "no scale fits the taped distances (distanceMeasurement) of {}",
                    gt_file(dir).display()
                ));
                return Ok(r);
            }
        },
    };
    let road = Road {
        calib: &calib,
        scale,
    };
    let speed = evaluate_video(gt, &system.cars, &road, mode, image).map_err(|e| {
        let file = match e {
            SpeedError::TrackLengths { .. } => system_path.to_path_buf(),
            _ => gt_file(dir),
        };
        anyhow::anyhow!("{}: {e}", file.display())
    })?;
    r.status = "ok";
    r.scale = Some(scale);
    r.speed = Some(speed);
    Ok(r)
}

/// Run the BrnoCompSpeed speed evaluation; the library entry point of `vpcal eval speed`.
///
/// # Errors
/// Unreadable directories, ground truth, system or camera files; ground truth the protocol
/// cannot use; no video found.
pub fn evaluate_speed(args: &SpeedArgs) -> Result<Vec<SpeedSystemResult>> {
    let videos = dataset_videos(&args.dataset, args.split)?;
    let names = system_names(
        &args.system,
        videos.iter().map(|(v, _)| args.results.join(v)),
        &args.results,
        "videos",
    )?;
    let camera = match &args.camera_truth {
        Some(path) => SpeedCamera::Truth {
            path: path.clone(),
            cameras: read_camera_truth(path)?,
        },
        None => SpeedCamera::System {
            fit_scale: args.fit_scale,
        },
    };
    let gts: Vec<GtData> = videos
        .par_iter()
        .map(|(_, dir)| Ok(read_gt(dir)?))
        .collect::<Result<_>>()?;
    let image = [f64::from(args.image_size.0), f64::from(args.image_size.1)];
    let mut out = Vec::new();
    for system in names {
        let rows: Vec<SpeedVideoResult> = videos
            .par_iter()
            .zip(&gts)
            .map(|((video, dir), gt)| {
                let path = args
                    .results
                    .join(video)
                    .join(format!("system_{system}.json"));
                speed_video(video, dir, gt, &path, &camera, args.mode, image)
            })
            .collect::<Result<_>>()?;
        let count = |s: &str| rows.iter().filter(|v| v.status == s).count();
        out.push(SpeedSystemResult {
            system,
            mode: args.mode,
            camera: camera.describe(),
            pooled: pool_speed(rows.iter().filter_map(|r| r.speed.as_ref())),
            evaluated: count("ok"),
            missing: count("missing"),
            invalid: count("invalid"),
            skipped: count("skipped"),
            videos: rows,
        });
    }
    Ok(out)
}

fn run_speed(args: &SpeedArgs) -> Result<()> {
    let results = evaluate_speed(args)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&results)?);
        return Ok(());
    }
    let fmt = |x: Option<f64>, prec: usize| x.map_or("-".to_string(), |v| format!("{v:.prec$}"));
    for (k, s) in results.iter().enumerate() {
        if k > 0 {
            println!();
        }
        println!("system {}: {} mode, {}", s.system, s.mode.name(), s.camera);
        println!("  absolute error km/h (n, mean, median, p95, max) | mean relative error %");
        println!(
            "{:<18} {:>8} | {:>5} {:>7} {:>7} {:>7} {:>7} | {:>6} | {:>13} {:>6} {:>5}",
            "video",
            "scale",
            "n",
            "mean",
            "median",
            "p95",
            "max",
            "mean",
            "matched/valid",
            "recall",
            "FP"
        );
        let row = |name: &str,
                   scale: String,
                   abs: Option<&Summary>,
                   rel: Option<&Summary>,
                   matched: usize,
                   valid: usize,
                   recall: Option<f64>,
                   fp: usize| {
            println!(
                "{:<18} {:>8} | {:>5} {:>7} {:>7} {:>7} {:>7} | {:>6} | {:>13} {:>6} {:>5}",
                name,
                scale,
                abs.map_or(0, |a| a.n),
                fmt(abs.map(|a| a.mean), 2),
                fmt(abs.map(|a| a.median), 2),
                fmt(abs.map(|a| a.p95), 2),
                fmt(abs.map(|a| a.max), 2),
                fmt(rel.map(|r| r.mean), 2),
                format!("{matched}/{valid}"),
                fmt(recall, 3),
                fp
            );
        };
        for v in &s.videos {
            match (&v.speed, v.status) {
                (Some(sp), _) => row(
                    &v.video,
                    fmt(v.scale, 5),
                    sp.abs_kmh.as_ref(),
                    sp.rel_pct.as_ref(),
                    sp.matched,
                    sp.valid,
                    sp.recall,
                    sp.false_positives,
                ),
                (None, "missing") => println!("{:<18} missing (no system file)", v.video),
                (None, "skipped") => println!(
                    "{:<18} skipped: {}",
                    v.video,
                    v.reason.as_deref().unwrap_or("no speed ground truth")
                ),
                (None, _) => println!(
                    "{:<18} invalid: {}",
                    v.video,
                    v.reason.as_deref().unwrap_or("no camera")
                ),
            }
        }
        let p = &s.pooled;
        row(
            &format!("pooled ({}/{})", s.evaluated, s.videos.len()),
            String::new(),
            p.abs_kmh.as_ref(),
            p.rel_pct.as_ref(),
            p.matched,
            p.valid,
            p.recall,
            p.false_positives,
        );
    }
    println!(
        "\nrecall: matched valid GT cars / valid GT cars (pooled: mean over videos); FP: false \
         positives (pooled: sum)"
    );
    Ok(())
}
