//! `vpcal aggregate`: per-vehicle VP pairs (a VPout JSON file) to a BrnoCompSpeed system file.

use super::args;
use anyhow::{Context, Result};
use std::path::PathBuf;
use vpcal_formats::bcs::{write_system, SystemCalibration, SystemFile};
use vpcal_formats::reference::read_vpout;
use vpcal_geom::aggregate::reference::{self, ReferenceOptions};
use vpcal_geom::aggregate::VehicleVps;
use vpcal_geom::Point2;

/// Turn per-vehicle VP pairs (a VPout JSON file) into a camera calibration.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Per-vehicle VP outputs (the reference's VPout_*.json format).
    pub vpout: PathBuf,
    /// Principal point x,y in frame pixels. Default: the BrnoCompSpeed convention for
    /// --image-size, (W/2 + 0.5, H/2 + 0.5).
    #[arg(long, value_parser = args::point)]
    pub pp: Option<Point2>,
    /// Image size WxH, used for the default principal point.
    #[arg(long, value_parser = args::size, default_value = "1920x1080")]
    pub image_size: (u32, u32),
    /// Keep vehicles whose detector score is above this.
    #[arg(long, default_value_t = 0.1)]
    pub min_score: f64,
    /// Output BrnoCompSpeed system file (system_<name>.json).
    #[arg(short, long)]
    pub output: PathBuf,
}

pub fn run(args: Args) -> Result<()> {
    let items = read_vpout(&args.vpout)?;
    let pp = args
        .pp
        .unwrap_or_else(|| args::bcs_principal_point(args.image_size.0, args.image_size.1));
    let vehicles: Vec<VehicleVps> = items.iter().map(|i| i.to_vehicle()).collect();
    let options = ReferenceOptions {
        min_score: args.min_score,
    };
    let result = reference::aggregate(&vehicles, pp, &options)
        .with_context(|| format!("aggregating {}", args.vpout.display()))?;
    let system = SystemFile::new(SystemCalibration {
        vp1: result.vp1,
        vp2: result.vp2,
        pp,
        scale: 1.0,
    });
    write_system(&args.output, &system)?;
    eprintln!(
        "{} vehicles, {} above score {}, {} used; f = {:.1} px, vp1 = ({:.2}, {:.2}), vp2 = ({:.2}, {:.2}) -> {}",
        result.pairs_in,
        result.pairs_scored,
        args.min_score,
        result.pairs_used,
        result.focal_px,
        result.vp1.x,
        result.vp1.y,
        result.vp2.x,
        result.vp2.y,
        args.output.display()
    );
    Ok(())
}
