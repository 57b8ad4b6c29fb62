//! `vpcal scale` and `vpcal measure`: metric distances on the road plane of a calibration.
//!
//! A calibration from vanishing points fixes the road plane up to scale (DESIGN.md §3: the
//! BrnoCompSpeed back-projection onto `n·X + 10 = 0`). Known distances between road points,
//! or lane widths, fix the scale (`scale_m_per_unit`; several: their geometric mean, each
//! with its residual); lengths in two directions (along and across the road) also measure
//! the focal length (`vpcal::road_focal`); then any pair of pixels on the road has a
//! distance in metres, and any road pixel a place on the road.

use std::path::PathBuf;

use anyhow::{Context, Result};
use serde_json::Value;
use vpcal::road::{FocalRefit, KnownDistance, RoadCamera, RoadMeasure, ScaleInput};

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
#[command(
    after_help = "Examples (pixels read off a frame of the clip, e.g. the overlay):\n  \
    vpcal scale calib.json --points 412,610,530,598 --distance 6.0\n  \
    vpcal scale calib.json --lane-points 300,650,420,655 --lane-width 3.5\n  \
    # a length along the road and one across it also measure the focal length:\n  \
    vpcal scale calib.json --points 412,610,530,598 --distance 6.0 \\\n      \
    --points 380,640,520,645 --distance 3.5\n  \
    # the lane lines of a quiet frame, under the road's marking standard (period, lane):\n  \
    vpcal scale calib.json --markings 9,3.5 --image quiet_frame.png\n\n\
Exit codes: 0 done; 1 an error (a pixel above the horizon, a file without a camera); 2 a wrong \
command line."
)]
pub struct ScaleArgs {
    /// A calibration written by `vpcal calibrate -o`.
    pub calib: PathBuf,
    /// The two ends of a known distance, in pixels, on the road: x1,y1,x2,y2; repeat for
    /// several (each with its --distance, in the same order).
    #[arg(long, value_parser = parse_pair, allow_hyphen_values = true)]
    pub points: Vec<PointPair>,
    /// The distance between the --points on the road, metres; one per --points.
    #[arg(long, value_parser = super::args::positive_f64, allow_negative_numbers = true)]
    pub distance: Vec<f64>,
    /// Two pixels on two neighbouring lane lines, x1,y1,x2,y2, anywhere along them (only the
    /// part across the road counts); repeat for several lanes.
    #[arg(long, value_parser = parse_pair, allow_hyphen_values = true)]
    pub lane_points: Vec<PointPair>,
    /// The lane width, metres: one for every --lane-points, or one per --lane-points.
    #[arg(long, value_parser = super::args::positive_f64, allow_negative_numbers = true)]
    pub lane_width: Vec<f64>,
    /// The road's marking standard, PERIOD,LANE in metres (the period of its dashed lane
    /// lines, one line plus one gap, and its lane width; or a standard's key, e.g. us; see
    /// `calibrate --markings`): the lane lines in --image become known lengths (`markings` in
    /// the sources).
    #[arg(long, value_name = "PERIOD,LANE|KEY", requires = "image")]
    pub markings: Option<vpcal::markings::MarkingStandard>,
    /// A picture of the road from the calibrated camera, its frames' size, with little
    /// traffic (a quiet frame of the clip), where --markings finds the lane lines.
    #[arg(long, value_name = "IMAGE", requires = "markings")]
    pub image: Option<PathBuf>,
    /// Keep the calibration's focal length even when the lengths lie in two directions (by
    /// default they measure it: `focal_source: distances`).
    #[arg(long)]
    pub keep_focal: bool,
    /// Write the scaled calibration here (default: update CALIB in place, atomically).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Print the scale as JSON on stdout.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, clap::Args)]
#[command(after_help = "Examples:\n  \
    vpcal measure calib.json --points 412,610,530,598      # a distance on the road\n  \
    vpcal measure calib.json --at 640,700 --json            # where a pixel is on the road\n\n\
Exit codes: 0 done; 1 an error (a pixel outside the frame or above the horizon, a file whose \
fields disagree); 2 a wrong command line.")]
pub struct MeasureArgs {
    /// A calibration written by `vpcal calibrate -o` (with `vpcal scale` for metres).
    pub calib: PathBuf,
    /// Pixel pairs on the road, x1,y1,x2,y2; repeat for several distances.
    #[arg(long, value_parser = parse_pair, required_unless_present = "at", allow_hyphen_values = true)]
    pub points: Vec<PointPair>,
    /// A road pixel, x,y: where it is on the road (x along the road towards VP1, y across,
    /// from the point under the camera) and how far from the camera's foot; repeat for
    /// several.
    #[arg(long, value_parser = parse_point, allow_hyphen_values = true)]
    pub at: Vec<Point2>,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

fn parse_point(s: &str) -> Result<Point2, String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>().ok().filter(|v| v.is_finite()))
        .collect::<Option<Vec<f64>>>()
        .ok_or_else(|| format!("expected x,y (finite numbers), got {s:?}"))?;
    let [x, y] = v[..] else {
        return Err(format!("expected 2 numbers x,y, got {} in {s:?}", v.len()));
    };
    Ok(Point2::new(x, y))
}

/// The known measurements of `a`, in the order distances then lane widths.
fn scale_inputs(a: &ScaleArgs) -> Result<Vec<ScaleInput>> {
    if a.points.len() != a.distance.len() {
        return Err(super::UsageError(format!(
            "{} --points but {} --distance: give one distance per pair of points",
            a.points.len(),
            a.distance.len()
        ))
        .into());
    }
    let widths: Vec<f64> = match (a.lane_points.len(), a.lane_width.len()) {
        (n, 1) => vec![a.lane_width[0]; n],
        (n, m) if n == m => a.lane_width.clone(),
        (n, m) => {
            return Err(super::UsageError(format!(
                "{n} --lane-points but {m} --lane-width: give one width for all, or one per \
                 pair of points"
            ))
            .into())
        }
    };
    let known = |PointPair(p1, p2): &PointPair, d: f64| KnownDistance {
        p1: *p1,
        p2: *p2,
        distance_m: d,
    };
    let mut inputs: Vec<ScaleInput> = a
        .points
        .iter()
        .zip(&a.distance)
        .map(|(p, d)| ScaleInput {
            kind: RoadMeasure::Distance,
            known: known(p, *d),
        })
        .collect();
    inputs.extend(a.lane_points.iter().zip(&widths).map(|(p, w)| ScaleInput {
        kind: RoadMeasure::LaneWidth,
        known: known(p, *w),
    }));
    if inputs.is_empty() && a.markings.is_none() {
        return Err(super::UsageError(
            "no known length: give --points with --distance, --lane-points with --lane-width, \
             or --markings with --image"
                .into(),
        )
        .into());
    }
    Ok(inputs)
}

/// The known lengths the lane lines of `image` make under marking standard `standard` on
/// camera `f` (an error when the picture is unreadable, not of the calibration's size, or
/// shows no dashed lane line of the standard).
fn marking_inputs(
    f: &RoadCamera,
    image: &std::path::Path,
    standard: &vpcal::markings::MarkingStandard,
) -> Result<Vec<ScaleInput>> {
    let grey = image::open(image)
        .with_context(|| format!("--image {}: not a readable picture", image.display()))?
        .to_luma8();
    let size = [grey.width(), grey.height()];
    if size != f.file.image_size {
        anyhow::bail!(
            "--image {}: {}x{} pixels, but the calibration's frames are {}x{}",
            image.display(),
            size[0],
            size[1],
            f.file.image_size[0],
            f.file.image_size[1]
        );
    }
    let lines = vpcal::markings::lines_in(&grey, f.cal.vp1);
    let inputs = vpcal::markings::standard_lengths(&lines, &f.cal, standard);
    if inputs.is_empty() {
        anyhow::bail!(
            "--image {}: no dashed lane line of the standard found ({} lines along the road, {} \
             dashed); give known lengths with --points or --lane-points instead",
            image.display(),
            lines.len(),
            lines.iter().filter(|l| l.dashes.is_some()).count()
        );
    }
    if let Some(why) = vpcal::road_focal::disagreement(&f.cal, &inputs, f64::from(size[0])) {
        anyhow::bail!(
            "--image {}: the {} lengths its lane lines make under the standard disagree with \
             each other on this camera ({why}); check the standard, or give known lengths with \
             --points or --lane-points instead",
            image.display(),
            inputs.len()
        );
    }
    Ok(inputs)
}

pub fn run_scale(a: ScaleArgs) -> Result<()> {
    let mut inputs = scale_inputs(&a)?;
    let mut f = RoadCamera::read(&a.calib)?;
    let n_dist = a.points.len();
    let given = inputs.len();
    if let (Some(standard), Some(image)) = (&a.markings, &a.image) {
        inputs.extend(marking_inputs(&f, image, standard)?);
        if given == 0 {
            f.lengths_source = "markings";
        }
    }
    let flag_of = |i: usize| {
        if i < n_dist {
            format!("--points #{}", i + 1)
        } else if i < given {
            format!("--lane-points #{}", i - n_dist + 1)
        } else {
            format!("--markings (length {})", i - given + 1)
        }
    };
    let before = (f.cal.focal_px, f.file.focal_source.clone());
    let origin = a.calib.display().to_string();
    let (focal, fit) = f.apply_lengths(&inputs, flag_of, &origin, a.keep_focal)?;
    let out = a.output.as_deref().unwrap_or(&a.calib);
    f.file.write(out)?;
    let height = f.file.camera_height_m.unwrap_or(f64::NAN);
    let kind = |k: RoadMeasure| match k {
        RoadMeasure::Distance => "distance",
        RoadMeasure::LaneWidth => "lane_width",
    };
    if a.json {
        let rows: Vec<Value> = inputs
            .iter()
            .enumerate()
            .map(|(i, m)| {
                serde_json::json!({
                    "kind": kind(m.kind),
                    "from": if i < given { "given" } else { "markings" },
                    "points": [[m.known.p1.x, m.known.p1.y], [m.known.p2.x, m.known.p2.y]],
                    "known_m": m.known.distance_m,
                    "own_scale": fit.own_scales[i],
                    "residual_m": fit.residuals_m[i],
                    "residual_pct": fit.residuals_pct[i],
                })
            })
            .collect();
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({
                "focal": focal_json(focal.as_ref(), &f, &before),
                "scale_m_per_unit": fit.scale,
                "scale_source": f.file.scale_source,
                "camera_height_m": height,
                "measurements": rows,
                "output": out.display().to_string(),
            }))?
        );
    } else {
        println!(
            "scale {:.6} m per road unit (camera {height:.2} m above the road) -> {}",
            fit.scale,
            out.display()
        );
        println!("{}", focal_line(focal.as_ref(), &f, &before));
        if inputs.len() > 1 {
            for (i, m) in inputs.iter().enumerate() {
                println!(
                    "  {:<10} {:>8.3} m known, {:>+8.3} m ({:+.1} %) with this scale",
                    kind(m.kind),
                    m.known.distance_m,
                    fit.residuals_m[i],
                    fit.residuals_pct[i]
                );
            }
        }
    }
    Ok(())
}

/// What `vpcal scale` did with the focal length, in words: measured from the lengths, or kept
/// and why. `before` is the file's focal length and source before.
fn focal_line(
    refit: Option<&FocalRefit>,
    f: &RoadCamera,
    before: &(f64, Option<String>),
) -> String {
    let source = before.1.as_deref().unwrap_or("unknown source");
    match refit {
        Some(FocalRefit::Measured { lengths, combined }) => format!(
            "focal length {:.0} px (68% {:.0}-{:.0} px, {}): the known lengths give {:.0} px \
             (68% {:.0}-{:.0}), the footage gave {:.0} px ({source})",
            combined.focal_px,
            combined.interval_px[0],
            combined.interval_px[1],
            combined.source,
            lengths.focal_px,
            lengths.interval_px[0],
            lengths.interval_px[1],
            before.0
        ),
        Some(FocalRefit::Kept(why)) => format!(
            "focal length kept: {:.0} px ({source}); {why}",
            f.cal.focal_px
        ),
        None => format!(
            "focal length kept: {:.0} px ({source}; --keep-focal)",
            f.cal.focal_px
        ),
    }
}

/// [`focal_line`] as JSON: whether the lengths changed it, the focal length, its interval
/// and source now, the lengths' own, what it was, and why it was kept.
fn focal_json(refit: Option<&FocalRefit>, f: &RoadCamera, before: &(f64, Option<String>)) -> Value {
    let (why, lengths) = match refit {
        Some(FocalRefit::Kept(why)) => (Some(why.clone()), None),
        None => (Some("--keep-focal".to_string()), None),
        Some(FocalRefit::Measured { lengths, .. }) => (
            None,
            Some(serde_json::json!({
                "focal_px": lengths.focal_px,
                "interval_px": lengths.interval_px,
                "chi2": lengths.chi2,
                "dof": lengths.dof,
            })),
        ),
    };
    serde_json::json!({
        "changed": why.is_none(),
        "focal_px": f.cal.focal_px,
        "focal_interval_px": f.file.focal_interval_px,
        "focal_source": f.file.focal_source,
        "from_lengths": lengths,
        "previous_focal_px": before.0,
        "previous_focal_source": before.1,
        "kept_because": why,
    })
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
    // Every pixel is checked before anything is printed: a pixel outside the frame or above
    // the horizon has no place on the road.
    let mut named: Vec<(String, Point2)> = Vec::new();
    for (i, PointPair(p1, p2)) in a.points.iter().enumerate() {
        named.push((format!("--points #{} first pixel", i + 1), *p1));
        named.push((format!("--points #{} second pixel", i + 1), *p2));
    }
    for (i, p) in a.at.iter().enumerate() {
        named.push((format!("--at #{}", i + 1), *p));
    }
    for (what, p) in &named {
        let below = f.check_measurable(*p, what)?;
        if below < vpcal::road::NEAR_HORIZON_PX {
            eprintln!(
                "warning: {what} ({:.1}, {:.1}) is {below:.1} px below the horizon: there 1 px \
                 moves its distance by about {:.0} %; a pixel lower on the road measures better",
                p.x,
                p.y,
                100.0 / below
            );
        }
    }
    let mut rows = Vec::new();
    for PointPair(p1, p2) in &a.points {
        rows.push((*p1, *p2, f.distance(*p1, *p2)));
    }
    let places: Vec<(Point2, Option<[f64; 2]>)> =
        a.at.iter().map(|p| (*p, f.road_point(*p))).collect();
    if a.json {
        let mut v: Vec<Value> = rows
            .iter()
            .map(|(p1, p2, d)| {
                serde_json::json!({"points": [[p1.x, p1.y], [p2.x, p2.y]], "distance": d, "unit": unit})
            })
            .collect();
        v.extend(places.iter().map(|(p, q)| {
            serde_json::json!({
                "at": [p.x, p.y],
                "road": q,
                "ground_distance": q.map(|q| q[0].hypot(q[1])),
                "unit": unit,
            })
        }));
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
        for (p, q) in &places {
            match q {
                Some(q) => println!(
                    "({:.1}, {:.1}): {:.3} {unit} along the road, {:.3} {unit} across, {:.3} {unit} \
                     from the point under the camera",
                    p.x,
                    p.y,
                    q[0],
                    q[1],
                    q[0].hypot(q[1])
                ),
                None => println!(
                    "({:.1}, {:.1}): not on the road (above the horizon)",
                    p.x, p.y
                ),
            }
        }
    }
    Ok(())
}

#[derive(Debug, clap::Args)]
#[command(
    after_help = "Example:\n  vpcal export calib.json --opencv camera.yml\n\n\
Exit codes: 0 done; 1 an error; 2 a wrong command line."
)]
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
    vpcal::output::check_distinct_paths(&[("input", &a.calib)], &[("--opencv", &a.opencv)])
        .map_err(super::UsageError)?;
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

#[derive(Debug, clap::Args)]
#[command(
    after_help = "Example (after `vpcal calibrate clip.mp4 -o calib.json --tracks \
tracks.json`):\n  \
    vpcal scale calib.json --points 412,610,530,598 --distance 6.0\n  \
    vpcal speeds calib.json tracks.json -o tracks_scaled.csv\n\n\
Exit codes: 0 done; 1 an error; 2 a wrong command line."
)]
pub struct SpeedsArgs {
    /// A calibration with a metric scale (`vpcal calibrate -o`, then `vpcal scale`).
    pub calib: PathBuf,
    /// Tracks written by `vpcal calibrate --tracks` (CSV or JSON).
    pub tracks: PathBuf,
    /// Write the re-measured tracks here: CSV when it ends in `.csv`, else JSON.
    #[arg(short, long, value_name = "FILE")]
    pub output: PathBuf,
    /// Also write the camera and the tracks as a BrnoCompSpeed system file.
    #[arg(long, value_name = "FILE")]
    pub bcs_json: Option<PathBuf>,
}

/// `vpcal speeds`: saved tracks measured again with a calibration (after `vpcal scale`),
/// without processing the video again.
pub fn run_speeds(a: SpeedsArgs) -> Result<()> {
    let mut outputs: Vec<(&str, &std::path::Path)> = vec![("--output", &a.output)];
    if let Some(b) = &a.bcs_json {
        outputs.push(("--bcs-json", b));
    }
    for (flag, path) in &outputs {
        vpcal::output::check_destination(flag, path)?;
    }
    vpcal::output::check_distinct_paths(
        &[("calibration", &a.calib), ("tracks file", &a.tracks)],
        &outputs,
    )
    .map_err(super::UsageError)?;
    let f = RoadCamera::read(&a.calib)?;
    let Some(scale) = f.scale else {
        anyhow::bail!(
            "{}: no metric scale: give it a known distance first (`vpcal scale {} --points \
             X1,Y1,X2,Y2 --distance M`)",
            a.calib.display(),
            a.calib.display()
        );
    };
    let saved = vpcal::output::read_tracks(&a.tracks)?;
    let [w, h] = f.file.image_size;
    if let Some((tw, th)) = saved.size.filter(|s| *s != (w, h)) {
        anyhow::bail!(
            "{}: the tracks are of {tw}x{th} frames, the calibration {} of {w}x{h}: they are \
             not of the same camera view",
            a.tracks.display(),
            a.calib.display()
        );
    }
    let settings = vpcal::tracks::TrackSettings::default();
    let tracks = vpcal::tracks::remeasure_tracks(saved.tracks, (&f.cal, scale), &settings);
    let header = vpcal::output::TracksHeader {
        input: saved
            .input
            .unwrap_or_else(|| a.tracks.display().to_string()),
        fps: saved.fps.or(f.file.input.fps),
        size: (w, h),
        scale_m_per_unit: Some(scale),
        window_points: settings.window_points,
        note: None,
        speed_factor: Some(vpcal::plausible::along_factor(&f.file)),
    };
    for finding in vpcal::plausible::check_speeds(&tracks, &f.file, false) {
        eprintln!("warning ({}): {}", finding.status.name(), finding.warning);
    }
    vpcal::output::write_tracks(&a.output, &header, &tracks)?;
    let mut line = vpcal::output::tracks_line(&tracks, &header);
    if let Some(path) = &a.bcs_json {
        let cars = vpcal::output::write_bcs_system_with_tracks(
            path,
            &f.cal,
            Some(scale),
            &tracks,
            &header,
        )?;
        line.push_str(&format!("; {cars} in the BrnoCompSpeed cars"));
    }
    println!("{line} -> {}", a.output.display());
    Ok(())
}
