//! `vpcal predict`: run a trained VP network on vehicle crops, print the VPs and write the
//! heatmaps as a PNG grid (crate `vpcal-net`).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::{Args as ClapArgs, ValueEnum};
use image::{Rgb, RgbImage};
use vpcal_geom::heatmap::DecodeMode;
use vpcal_geom::{BoxPx, Point2};
use vpcal_net::report::heatmap_grid;

/// How the spreads `D^s` decode the near-maximum pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Decode {
    /// Pixel centres (consistent with the maximum).
    Centre,
    /// Pixel corners, as the reference implementation.
    Reference,
}

#[derive(Debug, ClapArgs)]
#[command(
    after_help = "Example:\n  vpcal predict car.png --box 410,220,530,300 --frame frame.png\n\n\
Exit codes: 0 done; 1 an error; 2 a wrong command line."
)]
pub struct Args {
    /// Vehicle crop images (any size; each is resized to the network input).
    #[arg(required = true, value_name = "CROP")]
    pub crops: Vec<PathBuf>,
    /// Trained weights: a `.safetensors` file, a checkpoint folder, or a `vpcal train` run
    /// folder (its latest checkpoint). Default: the bundled model.
    #[arg(long = "model", alias = "weights", value_name = "PATH")]
    pub weights: Option<PathBuf>,
    /// Where the (single) crop was cut from in its frame, `x0,y0,x1,y1` pixels: the VPs are
    /// also printed in frame pixels.
    #[arg(long = "box", value_name = "X0,Y0,X1,Y1", value_parser = parse_box)]
    pub bbox: Option<BoxPx>,
    /// The frame the crop came from (needs --box): writes `<crop>.frame.png` with the box and
    /// the directions to both VPs drawn on it.
    #[arg(long, value_name = "IMG", requires = "bbox")]
    pub frame: Option<PathBuf>,
    /// Folder for the heatmap grids (`<crop>.heatmaps.png`); default: next to each crop.
    #[arg(short = 'o', long = "output", alias = "out", value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Print one JSON object per crop instead of text.
    #[arg(long)]
    pub json: bool,
    /// Decoding of the spreads.
    #[arg(long, value_enum, default_value_t = Decode::Centre)]
    pub decode: Decode,
    /// Device: `cpu`, or `wgpu` in builds with the `wgpu` feature.
    #[arg(long, default_value = "cpu", value_parser = super::args::device)]
    pub device: String,
}

/// `x0,y0,x1,y1` in pixels with `x1 > x0`, `y1 > y0`.
fn parse_box(s: &str) -> Result<BoxPx, String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>().ok().filter(|v| v.is_finite()))
        .collect::<Option<Vec<f64>>>()
        .ok_or_else(|| format!("expected a box x0,y0,x1,y1 of finite numbers, got {s:?}"))?;
    let [x0, y0, x1, y1] = v[..] else {
        return Err(format!("expected a box x0,y0,x1,y1 (4 numbers), got {s:?}"));
    };
    if x1 > x0 && y1 > y0 {
        Ok(BoxPx { x0, y0, x1, y1 })
    } else {
        Err(format!("the box {s:?} is empty: need x1 > x0 and y1 > y0"))
    }
}

fn fmt_point(p: Point2) -> String {
    if p.is_finite() {
        format!("({:.4}, {:.4})", p.x, p.y)
    } else {
        "at infinity (not decodable)".to_string()
    }
}

fn json_point(p: Point2) -> serde_json::Value {
    if p.is_finite() {
        serde_json::json!([p.x, p.y])
    } else {
        serde_json::Value::Null
    }
}

fn output_path(crop: &Path, out: Option<&Path>, suffix: &str) -> PathBuf {
    let stem = crop
        .file_stem()
        .map_or_else(|| "crop".to_string(), |s| s.to_string_lossy().into_owned());
    let dir = match out {
        Some(d) => d.to_path_buf(),
        None => crop.parent().map_or_else(PathBuf::new, Path::to_path_buf),
    };
    dir.join(format!("{stem}.{suffix}.png"))
}

/// Draw a line segment (clipped to the image), 2 px wide.
fn draw_line(img: &mut RgbImage, a: Point2, b: Point2, colour: Rgb<u8>) {
    let (w, h) = (f64::from(img.width()), f64::from(img.height()));
    let d = b - a;
    let steps = d.x.abs().max(d.y.abs()).ceil().clamp(1.0, 20_000.0) as usize;
    for k in 0..=steps {
        let p = a + d * (k as f64 / steps as f64);
        for (ox, oy) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0)] {
            let (x, y) = (p.x + ox, p.y + oy);
            if x >= 0.0 && y >= 0.0 && x < w && y < h {
                img.put_pixel(x as u32, y as u32, colour);
            }
        }
    }
}

/// The frame with the box and, from the box centre, the directions to VP1 (red) and VP2
/// (green), drawn up to the VP or the frame border.
fn frame_overlay(frame: &RgbImage, bbox: &BoxPx, vp1: Point2, vp2: Point2) -> RgbImage {
    let mut img = frame.clone();
    let yellow = Rgb([255, 220, 0]);
    let corners = [
        Point2::new(bbox.x0, bbox.y0),
        Point2::new(bbox.x1, bbox.y0),
        Point2::new(bbox.x1, bbox.y1),
        Point2::new(bbox.x0, bbox.y1),
    ];
    for i in 0..4 {
        draw_line(&mut img, corners[i], corners[(i + 1) % 4], yellow);
    }
    let c = bbox.center();
    let reach = f64::from(frame.width() + frame.height()) * 2.0;
    for (vp, colour) in [(vp1, Rgb([255, 40, 40])), (vp2, Rgb([40, 255, 40]))] {
        if !vp.is_finite() {
            continue;
        }
        let d = vp - c;
        let n = d.norm();
        if n == 0.0 {
            continue;
        }
        let end = if n < reach { vp } else { c + d * (reach / n) };
        draw_line(&mut img, c, end, colour);
    }
    img
}

/// Run `vpcal predict`.
pub fn run(a: Args) -> Result<()> {
    if a.bbox.is_some() && a.crops.len() != 1 {
        bail!(
            "--box locates one crop, but {} crops were given",
            a.crops.len()
        );
    }
    let (net, _) = vpcal::model::load_model(a.weights.as_deref(), &a.device)?;
    let net = net.with_decode_mode(match a.decode {
        Decode::Centre => DecodeMode::Centre,
        Decode::Reference => DecodeMode::Reference,
    });
    let mut crops = Vec::with_capacity(a.crops.len());
    for path in &a.crops {
        let img = image::open(path)
            .with_context(|| format!("reading the crop {}", path.display()))?
            .to_rgb8();
        crops.push(img);
    }
    if let Some(dir) = &a.out {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let preds = net.predict(&crops)?;
    let config = net.config();
    let scales = &config.scales;
    for ((path, crop), p) in a.crops.iter().zip(&crops).zip(&preds) {
        let grid_path = output_path(path, a.out.as_deref(), "heatmaps");
        // Cells of at least 128 px, whatever the heatmap resolution.
        let zoom = (128 / config.heatmap_size.max(1)).max(2) as u32;
        let grid = heatmap_grid(
            &p.heatmaps,
            config.outputs(),
            config.heatmap_size,
            zoom,
            Some(crop),
        );
        vpcal_video::draw::save_png(&grid, &grid_path)?;
        let vp = &p.vp;
        let frame_vps = a
            .bbox
            .map(|b| (b.frame_from_box(vp.vp1), b.frame_from_box(vp.vp2)));
        if let (Some(frame_path), Some(b), Some((f1, f2))) = (&a.frame, &a.bbox, frame_vps) {
            let frame = image::open(frame_path)
                .with_context(|| format!("reading the frame {}", frame_path.display()))?
                .to_rgb8();
            let overlay_path = output_path(path, a.out.as_deref(), "frame");
            vpcal_video::draw::save_png(&frame_overlay(&frame, b, f1, f2), &overlay_path)?;
            if !a.json {
                println!("  overlay: {}", overlay_path.display());
            }
        }
        let scale = |i: usize| scales.get(i).copied().unwrap_or(f64::NAN);
        if a.json {
            let mut obj = serde_json::json!({
                "crop": path.display().to_string(),
                "vp1_box": json_point(vp.vp1),
                "vp2_box": json_point(vp.vp2),
                "vp1_scale": scale(vp.vp1_scale),
                "vp2_scale": scale(vp.vp2_scale),
                "spreads": vp.spreads.iter().map(|s| [
                    if s[0].is_finite() { serde_json::json!(s[0]) } else { serde_json::Value::Null },
                    if s[1].is_finite() { serde_json::json!(s[1]) } else { serde_json::Value::Null },
                ]).collect::<Vec<_>>(),
                "heatmaps_png": grid_path.display().to_string(),
            });
            if let Some((f1, f2)) = frame_vps {
                obj["vp1_frame"] = json_point(f1);
                obj["vp2_frame"] = json_point(f2);
            }
            println!("{obj}");
        } else {
            println!("{}:", path.display());
            println!(
                "  VP1 (box frame) {}  scale {} (D = {:.4})",
                fmt_point(vp.vp1),
                scale(vp.vp1_scale),
                vp.vp1_spread()
            );
            println!(
                "  VP2 (box frame) {}  scale {} (D = {:.4})",
                fmt_point(vp.vp2),
                scale(vp.vp2_scale),
                vp.vp2_spread()
            );
            if let Some((f1, f2)) = frame_vps {
                println!("  VP1 (frame px)  {}", fmt_point(f1));
                println!("  VP2 (frame px)  {}", fmt_point(f2));
            }
            println!("  heatmaps: {}", grid_path.display());
        }
    }
    Ok(())
}
