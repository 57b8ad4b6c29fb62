//! `vpcal eval`: score calibrations against BrnoCompSpeed and BrnoCarPark ground truth
//! (DESIGN.md §8).
//!
//! For each video and system: the pure-calibration ratio error over every pair of ground-truth
//! distances (independent of the scale), and the distance error with the file's scale (BCS) or
//! with the optimal per-session scale (BrnoCarPark). Pooled rows concatenate all pairs, as the
//! paper does.

use anyhow::{bail, Context, Result};
use rayon::prelude::*;
use serde::Serialize;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use vpcal::aggregate::{aggregate, edgelets_of, Method};
use vpcal_formats::bcp::read_gt_pairs;
use vpcal_formats::bcs::{self, read_gt, read_system, write_system, SystemCalibration, SystemFile};
use vpcal_formats::reference::read_vpout;
use vpcal_geom::aggregate::VehicleVps;
use vpcal_geom::camera::Calibration;
use vpcal_geom::metrics::{
    optimal_scale, ratio_errors, scaled_distance_errors, summarize, RoadMeasurement, Summary,
};

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
    let mut videos = bcs::list_videos(dataset)
        .with_context(|| format!("listing the BrnoCompSpeed dataset {}", dataset.display()))?;
    if let Some(split) = split {
        let sessions = bcs::split_sessions(split).unwrap_or(&[]);
        videos.retain(|(name, _)| {
            bcs::parse_video_name(name).is_some_and(|(s, _)| sessions.contains(&s))
        });
    }
    if videos.is_empty() {
        bail!(
            "no video with gt_data.pkl or gt_data.json under {}{}",
            dataset.display(),
            split.map_or(String::new(), |s| format!(" in split {s}"))
        );
    }
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

/// One variant (VPout file stem) and method, over all videos.
#[derive(Debug, Clone, Serialize)]
pub struct VpoutResult {
    pub variant: String,
    pub method: &'static str,
    #[serde(flatten)]
    pub result: SystemResult,
    /// Focal length per video, pixels (`None` when the method gave no calibration).
    pub focal_px: Vec<Option<f64>>,
}

/// Aggregate every VPout file with every method and evaluate it; the library entry point of
/// `vpcal eval vpout`.
///
/// # Errors
/// Unreadable directories, ground truth or VPout files; no video with both.
pub fn evaluate_vpout(args: &VpoutArgs) -> Result<Vec<VpoutResult>> {
    let mut videos = bcs::list_videos(&args.dataset).with_context(|| {
        format!(
            "listing the BrnoCompSpeed dataset {}",
            args.dataset.display()
        )
    })?;
    if let Some(split) = args.split {
        let sessions = bcs::split_sessions(split).unwrap_or(&[]);
        videos.retain(|(name, _)| {
            bcs::parse_video_name(name).is_some_and(|(s, _)| sessions.contains(&s))
        });
    }
    // (video, measurements, [(variant, file)])
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
            work.push((video.clone(), gt.road_measurements(), files));
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
        .flat_map(|(vi, (_, _, files))| {
            files.iter().flat_map(move |(stem, path)| {
                args.methods
                    .iter()
                    .map(move |m| (vi, stem.clone(), path.clone(), *m))
            })
        })
        .collect();
    /// One scored job: video index, VPout file stem, method, its row and focal length.
    type Outcome = (usize, String, Method, VideoResult, Option<f64>);
    let outcomes: Vec<Result<Outcome>> = jobs
        .par_iter()
        .map(|(vi, stem, path, method)| {
            let (video, measurements, _) = &work[*vi];
            let items = read_vpout(path)?;
            let vehicles: Vec<VehicleVps> = items.iter().map(|i| i.to_vehicle()).collect();
            // The table shows no confidence: skip the bootstrap.
            let agg = aggregate(
                &vehicles,
                &edgelets_of(&items),
                pp,
                args.image_size,
                *method,
                args.min_score,
                0,
            );
            let (row, focal) = match agg {
                Ok(a) => {
                    let system = SystemFile::new(SystemCalibration {
                        vp1: a.vp1,
                        vp2: a.vp2,
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
                        Some(a.focal_px),
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
            for (vi, (video, measurements, _)) in work.iter().enumerate() {
                match rows
                    .iter()
                    .find(|r| r.0 == vi && &r.1 == variant && r.2 == *method)
                {
                    Some(r) => {
                        videos_rows.push(r.3.clone());
                        focals.push(r.4);
                    }
                    None => {
                        videos_rows.push(evaluate_one(
                            video,
                            None,
                            measurements,
                            &ScaleMode::FromFile,
                        ));
                        focals.push(None);
                    }
                }
            }
            out.push(VpoutResult {
                variant: variant.clone(),
                method: method.name(),
                result: pool(format!("{variant}_{}", method.name()), videos_rows),
                focal_px: focals,
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
    }
    Ok(())
}
