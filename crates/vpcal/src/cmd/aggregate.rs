//! `vpcal aggregate`: per-vehicle VP pairs (a VPout JSON file) to a calibration.

use std::path::PathBuf;

use anyhow::Result;
use vpcal::aggregate::Method;
use vpcal::output::{
    aggregate_records, check_destination, write_bcs_system, RecordSettings, RecordsCalibration,
};
use vpcal::pipeline::PrincipalPoint;
use vpcal_formats::reference::{read_scene_edgelets, read_vpout, SceneRecord};

use super::{Exit, UsageError};

/// Turn per-vehicle VP pairs (a VPout JSON file) into a camera calibration.
#[derive(Debug, clap::Args)]
#[command(
    after_help = "Example (the same camera as calibrate, from its saved records):\n  \
    vpcal calibrate clip.mp4 -o calib.json --vehicles vehicles.json --scene-edgelets scene.json\n  \
    vpcal aggregate vehicles.json --scene-edgelets scene.json -o calib2.json\n\n\
Exit codes: 0 calibrated; 1 an error; 2 a wrong command line; 3 the records could not support \
a calibration."
)]
pub struct Args {
    /// Per-vehicle VP records: the reference's VPout_*.json, or `vpcal calibrate --vehicles`.
    pub vpout: PathBuf,
    /// The scene's edgelets and line segments from `vpcal calibrate --scene-edgelets` (the
    /// lines along the road that place VP1, the vertical ones that measure the focal length);
    /// without them VP1 and the focal length come from the records alone.
    #[arg(long, value_name = "FILE")]
    pub scene_edgelets: Option<PathBuf>,
    /// Write the calibration file here (the same file `vpcal calibrate -o` writes).
    #[arg(short, long, value_name = "FILE")]
    pub output: Option<PathBuf>,
    /// Also write the camera as a BrnoCompSpeed system file.
    #[arg(long, value_name = "FILE")]
    pub bcs_json: Option<PathBuf>,
    /// Print the calibration file on stdout (the summary stays on stderr).
    #[arg(long)]
    pub json: bool,
    /// Aggregation method: `robust` (the default), `robust-network` or `reference`.
    #[arg(long, default_value = "robust", value_parser = super::args::method())]
    pub method: Method,
    /// Principal point: `centre` (W/2, H/2), `bcs` (W/2 + 0.5, H/2 + 0.5: the convention of
    /// the reference's VPout files of BrnoCompSpeed) or x,y in pixels.
    #[arg(long, default_value = "centre", value_name = "PP")]
    pub pp: PrincipalPoint,
    /// Size WxH of the frames the VPs were measured in. Default: inferred from the records'
    /// boxes (an error names this flag when they do not fix it).
    #[arg(long, value_parser = super::args::size)]
    pub image_size: Option<(u32, u32)>,
    /// Keep vehicles whose detector score is above this.
    #[arg(long, default_value_t = 0.1)]
    pub min_score: f64,
    /// Bootstrap resamples for the robust method's confidence (0 to skip).
    #[arg(long, default_value_t = 30)]
    pub bootstrap: usize,
    /// The camera's focal length in pixels, when known: VP1 and the horizon still come from
    /// the records.
    #[arg(long, value_name = "PX", value_parser = super::args::positive_f64, allow_negative_numbers = true)]
    pub focal: Option<f64>,
    /// The focal lengths the camera can have, SHORT,LONG in pixels (e.g. a zoom lens's
    /// shortest and longest focal length over the pixel pitch, from its data sheet): the range
    /// the evidence is weighed against instead of 15-90° views; an assumed focal length is its
    /// geometric middle.
    #[arg(long, value_name = "SHORT,LONG", value_parser = super::args::focal_range, conflicts_with = "focal")]
    pub focal_range: Option<[f64; 2]>,
}

pub fn run(args: Args) -> Result<Exit> {
    if args.output.is_none() && args.bcs_json.is_none() && !args.json {
        return Err(UsageError(
            "nothing would keep the calibration: give -o FILE (the calibration file), \
             --bcs-json FILE or --json"
                .to_string(),
        )
        .into());
    }
    let outputs: Vec<(&str, &std::path::Path)> =
        [("--output", &args.output), ("--bcs-json", &args.bcs_json)]
            .into_iter()
            .filter_map(|(flag, path)| path.as_deref().map(|p| (flag, p)))
            .collect();
    for (flag, path) in &outputs {
        check_destination(flag, path)?;
    }
    let mut inputs: Vec<(&str, &std::path::Path)> = vec![("input", args.vpout.as_path())];
    if let Some(scene) = &args.scene_edgelets {
        inputs.push(("--scene-edgelets", scene));
    }
    vpcal::output::check_distinct_paths(&inputs, &outputs).map_err(UsageError)?;
    let items = read_vpout(&args.vpout)?;
    let scene = match &args.scene_edgelets {
        Some(path) => read_scene_edgelets(path)?,
        None => SceneRecord::default(),
    };
    let settings = RecordSettings {
        method: args.method,
        pp: args.pp,
        image_size: args.image_size,
        min_score: args.min_score,
        bootstrap: args.bootstrap,
        focal_px: args.focal,
        focal_range_px: args.focal_range,
    };
    let RecordsCalibration {
        file,
        result,
        image_size: (width, height),
    } = aggregate_records(&items, &scene, &args.vpout.display().to_string(), &settings)?;
    let exit = match &result {
        Ok((cal, agg)) => {
            eprintln!("{}", agg.summary);
            for w in &file.warnings {
                eprintln!("warning: {w}");
            }
            eprintln!(
                "f = {:.1} px, vp1 = ({:.2}, {:.2}), vp2 = ({:.2}, {:.2}), {width}x{height} frames",
                cal.focal_px, cal.vp1.x, cal.vp1.y, cal.vp2.x, cal.vp2.y
            );
            Exit::Success
        }
        Err(e) => {
            eprintln!("vpcal: no calibration: {e:#}");
            Exit::NotEnoughEvidence
        }
    };
    if let Some(path) = &args.output {
        file.write(path)?;
    }
    if let (Some(path), Ok((cal, _))) = (&args.bcs_json, &result) {
        write_bcs_system(path, cal, file.scale_m_per_unit)?;
    }
    if args.json {
        print!("{}", file.to_json_string());
    }
    Ok(exit)
}
