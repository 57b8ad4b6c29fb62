//! `vpcal eval kitti`: per-vehicle VP direction errors on real KITTI vehicles with exact truth
//! (the network's VP1 and VP2, the "VP1 at the principal point" guess, VP2 from edgelets).

use std::path::PathBuf;

use anyhow::Result;
use vpcal::kitti::{self, EdgeletRule, ErrorSummary, VehicleResult};

#[derive(Debug, clap::Args)]
pub struct KittiArgs {
    /// The folder holding `vp_gt.json` and `image_2/` (`$VPCAL_DATA/real/kitti_object`).
    #[arg(long)]
    pub data: PathBuf,
    /// VP network weights; default: the bundled model.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Also measure occluded, truncated and small vehicles (summarised apart).
    #[arg(long)]
    pub all: bool,
    /// Write every vehicle's measurements, with all the edgelets found in its box, as JSON.
    #[arg(long, value_name = "FILE")]
    pub vehicles: Option<PathBuf>,
    /// Print machine-readable JSON instead of a table.
    #[arg(long)]
    pub json: bool,
    /// The per-vehicle edgelet VP2 lies at least this many box diagonals from the box centre.
    #[arg(long, value_name = "DIAGONALS", default_value_t = kitti::MIN_VP_DISTANCE_DIAGONALS)]
    pub edgelet_reach: f64,
    /// Device: `cpu`, or `wgpu` in builds with the `wgpu` feature.
    #[arg(long, default_value = "cpu", value_parser = super::args::device)]
    pub device: String,
    /// Also run every crop mirrored and average its heatmaps with the crop's own, as
    /// `calibrate --flip-average` does (twice the network work).
    #[arg(long)]
    pub flip_average: bool,
}

#[derive(Debug, serde::Serialize)]
struct Subset {
    vehicles: usize,
    network_vp1: Option<ErrorSummary>,
    network_vp2: Option<ErrorSummary>,
    pp_vp1: Option<ErrorSummary>,
    edgelet_vp2: Option<ErrorSummary>,
    /// Median of the signed edgelet VP2 direction errors (towards VP1 positive), degrees: the
    /// edges' systematic turn (the scatter averages out over many vehicles, this does not).
    edgelet_vp2_median_signed_deg: Option<f64>,
    /// The same for the network's VP2: its systematic turn on real cars.
    network_vp2_median_signed_deg: Option<f64>,
}

fn subset(results: &[&VehicleResult]) -> Subset {
    let s = |f: fn(&VehicleResult) -> Option<f64>| kitti::summarize(results.iter().map(|r| f(r)));
    Subset {
        vehicles: results.len(),
        network_vp1: s(|r| r.network_vp1_deg),
        network_vp2: s(|r| r.network_vp2_deg),
        pp_vp1: s(|r| r.pp_vp1_deg),
        edgelet_vp2: s(|r| r.edgelet_vp2_deg),
        edgelet_vp2_median_signed_deg: signed(results, |r| r.edgelet_vp2_signed_deg),
        network_vp2_median_signed_deg: signed(results, |r| r.network_vp2_signed_deg),
    }
}

/// The median of a signed error over `results` (those with a value).
fn signed(results: &[&VehicleResult], f: fn(&VehicleResult) -> Option<f64>) -> Option<f64> {
    vpcal_geom::solve::median(&results.iter().filter_map(|r| f(r)).collect::<Vec<_>>())
}

pub fn run(a: KittiArgs) -> Result<()> {
    if let Some(path) = &a.vehicles {
        vpcal::output::check_destination("--vehicles", path)?;
    }
    let frames = kitti::read_truth(&a.data)?;
    let (net, model) = vpcal::model::load_model(a.model.as_deref(), &a.device)?;
    let net = net.with_flip_average(a.flip_average);
    if a.edgelet_reach.is_nan() || a.edgelet_reach <= 0.0 {
        return Err(crate::cmd::UsageError(format!(
            "--edgelet-reach {}: expected a positive number of box diagonals",
            a.edgelet_reach
        ))
        .into());
    }
    let rule = EdgeletRule {
        min_vp_distance_diagonals: a.edgelet_reach,
        ..EdgeletRule::default()
    };
    let results = kitti::evaluate(&frames, &net, &rule, !a.all, a.vehicles.is_some())?;
    let clean: Vec<&VehicleResult> = results.iter().filter(|r| r.clean).collect();
    let rest: Vec<&VehicleResult> = results.iter().filter(|r| !r.clean).collect();
    let clean_s = subset(&clean);
    let rest_s = a.all.then(|| subset(&rest));
    if let Some(path) = &a.vehicles {
        let json = serde_json::to_string_pretty(&results)?;
        vpcal_formats::fs::write_atomic(path, json.as_bytes())?;
    }
    if a.json {
        let report = serde_json::json!({
            "model": model,
            "flip_average": a.flip_average,
            "edgelet_rule": rule,
            "clean": clean_s,
            "others": rest_s,
        });
        println!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    println!(
        "model: {model}{}",
        if a.flip_average {
            ", crops also mirrored (--flip-average)"
        } else {
            ""
        }
    );
    println!(
        "direction errors at the box centre, degrees (median / 90th percentile, vehicles with a value)"
    );
    let fmt = |s: &Option<ErrorSummary>| match s {
        Some(s) => format!("{:>6.2} / {:>6.2} ({:>2})", s.median_deg, s.p90_deg, s.n),
        None => format!("{:>22}", "-"),
    };
    println!(
        "{:<34} {:>22} {:>22} {:>22} {:>22}",
        "vehicles", "network VP1", "network VP2", "VP1 = principal point", "edgelet VP2"
    );
    let mut rows = vec![(
        format!(
            "clean (unoccluded, untruncated, >= {} px): {}",
            kitti::CLEAN_MIN_HEIGHT_PX,
            clean_s.vehicles
        ),
        &clean_s,
    )];
    if let Some(r) = &rest_s {
        rows.push((format!("others: {}", r.vehicles), r));
    }
    for (label, s) in rows {
        println!(
            "{label:<34} {} {} {} {}",
            fmt(&s.network_vp1),
            fmt(&s.network_vp2),
            fmt(&s.pp_vp1),
            fmt(&s.edgelet_vp2)
        );
    }
    for (label, s) in [("clean", Some(&clean_s)), ("others", rest_s.as_ref())] {
        if let Some(b) = s.and_then(|s| s.network_vp2_median_signed_deg) {
            println!("network VP2 turned towards VP1 ({label}, median signed error): {b:+.2} deg");
        }
        if let Some(b) = s.and_then(|s| s.edgelet_vp2_median_signed_deg) {
            println!("edgelet VP2 turned towards VP1 ({label}, median signed error): {b:+.2} deg");
        }
    }
    Ok(())
}

#[derive(Debug, clap::Args)]
pub struct KittiScaleArgs {
    /// The folder holding `vp_gt.json` (`$VPCAL_DATA/real/kitti_object`).
    #[arg(long)]
    pub data: PathBuf,
    /// Write every car's measurements as JSON.
    #[arg(long, value_name = "FILE")]
    pub vehicles: Option<PathBuf>,
    /// Print machine-readable JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Median and 16th-84th percentiles of ratios, with the median misfit.
#[derive(Debug, serde::Serialize)]
struct RatioSummary {
    n: usize,
    median: f64,
    p16: f64,
    p84: f64,
    median_fit_rms: f64,
}

fn ratio_summary(pairs: impl Iterator<Item = (Option<f64>, Option<f64>)>) -> Option<RatioSummary> {
    let (mut r, mut rms): (Vec<f64>, Vec<f64>) = pairs
        .filter_map(|(a, b)| Some((a?, b?)))
        .filter(|(a, b)| a.is_finite() && b.is_finite())
        .unzip();
    if r.is_empty() {
        return None;
    }
    r.sort_by(f64::total_cmp);
    rms.sort_by(f64::total_cmp);
    let p = vpcal_geom::solve::percentile_sorted;
    Some(RatioSummary {
        n: r.len(),
        median: p(&r, 50.0),
        p16: p(&r, 16.0),
        p84: p(&r, 84.0),
        median_fit_rms: p(&rms, 50.0),
    })
}

pub fn run_scale(a: KittiScaleArgs) -> Result<()> {
    if let Some(path) = &a.vehicles {
        vpcal::output::check_destination("--vehicles", path)?;
    }
    let frames = kitti::read_truth(&a.data)?;
    let cars = kitti::scale_check(&frames);
    if cars.is_empty() {
        anyhow::bail!(
            "{}: no clean car with a 3D label (dims_hwl, rotation_y) in a frame with fx and \
             ground_plane_avod",
            a.data.join("vp_gt.json").display()
        );
    }
    let own = ratio_summary(cars.iter().map(|c| (c.own_dims_ratio, c.own_dims_rms)));
    let typical = ratio_summary(cars.iter().map(|c| (c.typical_ratio, c.typical_rms)));
    if let Some(path) = &a.vehicles {
        let json = serde_json::to_string_pretty(&cars)?;
        vpcal_formats::fs::write_atomic(path, json.as_bytes())?;
    }
    if a.json {
        let report = serde_json::json!({
            "cars": cars.len(),
            "typical_car_m": vpcal_geom::vehicle_scale::PASSENGER_CAR,
            "cabin": {
                "length": vpcal_geom::vehicle_scale::PASSENGER_CAR_CABIN.length,
                "width": vpcal_geom::vehicle_scale::PASSENGER_CAR_CABIN.width,
                "belt": vpcal_geom::vehicle_scale::PASSENGER_CAR_CABIN.belt,
            },
            "own_dimensions": own,
            "typical_dimensions": typical,
        });
        println!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    println!(
        "{} clean KITTI cars: metres per plane unit from each car's outline fit (body and \
         cabin), over the truth",
        cars.len()
    );
    println!(
        "{:<34} {:>4} {:>8} {:>17} {:>10}",
        "dimensions", "n", "median", "16-84th pct", "fit rms"
    );
    let [l, w, h] = vpcal_geom::vehicle_scale::PASSENGER_CAR;
    for (label, s) in [
        ("the car's own (3D label)".to_string(), &own),
        (format!("typical car {l} x {w} x {h} m"), &typical),
    ] {
        match s {
            Some(s) => println!(
                "{label:<34} {:>4} {:>8.3} {:>8.3}-{:<8.3} {:>10.4}",
                s.n, s.median, s.p16, s.p84, s.median_fit_rms
            ),
            None => println!("{label:<34} {:>4}", 0),
        }
    }
    Ok(())
}
