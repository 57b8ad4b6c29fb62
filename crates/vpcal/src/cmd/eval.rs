//! `vpcal eval`: score calibrations against BrnoCompSpeed and BrnoCarPark ground truth
//! (DESIGN.md §8).
//!
//! For each video and system: the pure-calibration ratio error over every pair of ground-truth
//! distances (independent of the scale), and the distance error with the file's scale (BCS) or
//! with the optimal per-session scale (BrnoCarPark). Pooled rows concatenate all pairs, as the
//! paper does.

use anyhow::{bail, Context, Result};
use serde::Serialize;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use vpcal_formats::bcp::read_gt_pairs;
use vpcal_formats::bcs::{self, read_gt, read_system, SystemFile};
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
    let names: Vec<String> = if systems.is_empty() {
        find_systems(videos.iter().map(|(v, _)| results.join(v)))
            .into_iter()
            .collect()
    } else {
        systems.to_vec()
    };
    if names.is_empty() {
        bail!(
            "no system_<name>.json under {} for these videos",
            results.display()
        );
    }
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
    let names: Vec<String> = if systems.is_empty() {
        find_systems(sessions.iter().map(|(s, _)| results.join(s)))
            .into_iter()
            .collect()
    } else {
        systems.to_vec()
    };
    if names.is_empty() {
        bail!(
            "no system_<name>.json under {} for these sessions",
            results.display()
        );
    }
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
