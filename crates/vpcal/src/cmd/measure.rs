//! `vpcal scale` and `vpcal measure`: metric distances on the road plane of a calibration.
//!
//! A calibration from vanishing points fixes the road plane up to scale (DESIGN.md §3: the
//! BrnoCompSpeed back-projection onto `n·X + 10 = 0`). One known distance between two road
//! points fixes the scale (`scale_m_per_unit`); then any pair of pixels on the road has a
//! distance in metres.

use std::path::PathBuf;

use anyhow::{bail, Result};
use serde_json::Value;
use vpcal::road::{scale_from_points, RoadCamera};
use vpcal_geom::Point2;

/// Two road points in pixels, `x1,y1,x2,y2`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointPair(pub Point2, pub Point2);

fn parse_pair(s: &str) -> Result<PointPair, String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>().ok().filter(|v| v.is_finite()))
        .collect::<Option<Vec<f64>>>()
        .ok_or_else(|| format!("expected x1,y1,x2,y2 (finite numbers), got {s:?}"))?;
    let [x1, y1, x2, y2] = v[..] else {
        return Err(format!(
            "expected 4 numbers x1,y1,x2,y2, got {} in {s:?}",
            v.len()
        ));
    };
    Ok(PointPair(Point2::new(x1, y1), Point2::new(x2, y2)))
}

#[derive(Debug, clap::Args)]
pub struct ScaleArgs {
    /// A calibration written by `vpcal calibrate -o`.
    pub calib: PathBuf,
    /// The two ends of the known distance, in pixels, on the road: x1,y1,x2,y2.
    #[arg(long, value_parser = parse_pair, allow_hyphen_values = true)]
    pub points: PointPair,
    /// The distance between them on the road, in metres.
    #[arg(long)]
    pub distance: f64,
    /// Write the scaled calibration here (default: update CALIB in place, atomically).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Print the scale as JSON on stdout.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, clap::Args)]
pub struct MeasureArgs {
    /// A calibration written by `vpcal calibrate -o` (with `vpcal scale` for metres).
    pub calib: PathBuf,
    /// Pixel pairs on the road, x1,y1,x2,y2; repeat for several distances.
    #[arg(long, value_parser = parse_pair, required = true, allow_hyphen_values = true)]
    pub points: Vec<PointPair>,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

pub fn run_scale(a: ScaleArgs) -> Result<()> {
    if !(a.distance.is_finite() && a.distance > 0.0) {
        bail!(
            "--distance {} must be a positive number of metres",
            a.distance
        );
    }
    let mut f = RoadCamera::read(&a.calib)?;
    let PointPair(p1, p2) = a.points;
    let (scale, reference) = scale_from_points(&f.cal, p1, p2, a.distance, "--points")?;
    f.file
        .set_scale(scale, Some(reference))
        .map_err(|e| anyhow::anyhow!("{}: {e}", a.calib.display()))?;
    let out = a.output.as_deref().unwrap_or(&a.calib);
    f.file.write(out)?;
    let height = f.file.camera_height_m.unwrap_or(f64::NAN);
    if a.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({
                "scale_m_per_unit": scale,
                "camera_height_m": height,
                "output": out.display().to_string(),
            }))?
        );
    } else {
        println!(
            "scale {scale:.6} m per road unit (camera {height:.2} m above the road) -> {}",
            out.display()
        );
    }
    Ok(())
}

pub fn run_measure(a: MeasureArgs) -> Result<()> {
    let f = RoadCamera::read(&a.calib)?;
    if f.scale.is_none() {
        eprintln!(
            "warning: {} has no metric scale (run `vpcal scale`): distances are in road-plane units",
            a.calib.display()
        );
    }
    let unit = if f.scale.is_some() { "m" } else { "units" };
    let mut rows = Vec::new();
    for PointPair(p1, p2) in &a.points {
        rows.push((*p1, *p2, f.distance(*p1, *p2)));
    }
    if a.json {
        let v: Vec<Value> = rows
            .iter()
            .map(|(p1, p2, d)| {
                serde_json::json!({"points": [[p1.x, p1.y], [p2.x, p2.y]], "distance": d, "unit": unit})
            })
            .collect();
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        for (p1, p2, d) in &rows {
            match d {
                Some(d) => println!(
                    "({:.1}, {:.1}) - ({:.1}, {:.1}): {d:.3} {unit}",
                    p1.x, p1.y, p2.x, p2.y
                ),
                None => println!(
                    "({:.1}, {:.1}) - ({:.1}, {:.1}): not on the road (above the horizon)",
                    p1.x, p1.y, p2.x, p2.y
                ),
            }
        }
    }
    Ok(())
}

#[derive(Debug, clap::Args)]
pub struct ExportArgs {
    /// A calibration written by `vpcal calibrate -o` (with `vpcal scale` for metres).
    pub calib: PathBuf,
    /// Write the camera as an OpenCV FileStorage YAML file (camera_matrix,
    /// distortion_coefficients, rvec, tvec of the road frame, image size).
    #[arg(long, value_name = "YML")]
    pub opencv: PathBuf,
}

pub fn run_export(a: ExportArgs) -> Result<()> {
    vpcal::output::check_destination("--opencv", &a.opencv)?;
    let mut f = RoadCamera::read(&a.calib)?;
    f.file
        .refresh_export()
        .map_err(|e| anyhow::anyhow!("{}: {e}", a.calib.display()))?;
    vpcal::output::write_opencv_yaml(&a.opencv, &f.file)?;
    println!(
        "{} -> {} ({})",
        a.calib.display(),
        a.opencv.display(),
        if f.scale.is_some() {
            "metres"
        } else {
            "road units: no metric scale yet"
        }
    );
    Ok(())
}
