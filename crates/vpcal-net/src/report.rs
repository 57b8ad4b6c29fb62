//! Human-readable outputs: per-epoch metrics as CSV and JSONL, loss/VP-error curves as a PNG,
//! and heatmap grids as PNG images.
//!
//! Text is drawn with DejaVu Sans, embedded in the binary (`assets/DejaVuSans.ttf`, Bitstream
//! Vera licence in `assets/DejaVuSans-LICENSE.txt`), so no system font is needed.

use std::path::Path;
use std::sync::Once;

use image::{Rgb, RgbImage};
use plotters::prelude::*;
use serde::{Deserialize, Serialize};

use crate::fsutil::write_atomic;
use crate::metrics::VpMetrics;
use crate::NetError;

/// Metrics of one finished epoch.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpochRecord {
    /// 1-based epoch number.
    pub epoch: usize,
    pub lr: f64,
    /// Optimizer steps taken so far (cumulative).
    pub steps: u64,
    pub train_samples: usize,
    /// Mean training loss (sum of the terms) per crop-weighted batch.
    pub train_loss: f64,
    /// Mean of each loss term (one per stack for the heatmap model).
    pub train_loss_terms: Vec<f64>,
    /// Loss of the first and of the last batch of the epoch.
    pub first_batch_loss: f64,
    pub last_batch_loss: f64,
    /// Validation loss (sum of the terms), when the source has a validation split.
    pub val_loss: Option<f64>,
    /// Validation VP errors.
    pub val: Option<VpMetrics>,
    /// Wall time of training plus validation, seconds.
    pub seconds: f64,
    /// Training throughput, crops per second.
    pub samples_per_s: f64,
}

static FONT: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");
static REGISTER: Once = Once::new();

fn register_font() {
    REGISTER.call_once(|| {
        // A failure leaves plotters without the font: text is then not drawn, which the
        // chart code below tolerates (it only loses labels).
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT);
    });
}

fn fmt_opt(v: Option<f64>) -> String {
    match v {
        Some(x) if x.is_finite() => format!("{x:.6e}"),
        Some(x) => format!("{x}"),
        None => String::new(),
    }
}

/// The metrics table as CSV text (one row per epoch).
pub fn metrics_csv(history: &[EpochRecord]) -> String {
    let scales = history
        .iter()
        .filter_map(|r| r.val.as_ref())
        .map(|m| m.vp1_median_rel_per_scale.len())
        .max()
        .unwrap_or(0);
    let mut head = vec![
        "epoch".to_string(),
        "lr".into(),
        "steps".into(),
        "train_samples".into(),
        "train_loss".into(),
        "val_loss".into(),
        "vp1_median_rel".into(),
        "vp2_median_rel".into(),
    ];
    for vp in 1..=2 {
        for s in 0..scales {
            head.push(format!("vp{vp}_median_rel_scale{s}"));
        }
    }
    head.extend(["seconds".to_string(), "samples_per_s".into()]);
    let mut out = head.join(",");
    out.push('\n');
    for r in history {
        let mut row = vec![
            r.epoch.to_string(),
            format!("{:e}", r.lr),
            r.steps.to_string(),
            r.train_samples.to_string(),
            fmt_opt(Some(r.train_loss)),
            fmt_opt(r.val_loss),
            fmt_opt(r.val.as_ref().map(|m| m.vp1_median_rel)),
            fmt_opt(r.val.as_ref().map(|m| m.vp2_median_rel)),
        ];
        for vp in 0..2 {
            for s in 0..scales {
                let v = r.val.as_ref().and_then(|m| {
                    let per = if vp == 0 {
                        &m.vp1_median_rel_per_scale
                    } else {
                        &m.vp2_median_rel_per_scale
                    };
                    per.get(s).copied()
                });
                row.push(fmt_opt(v));
            }
        }
        row.push(format!("{:.3}", r.seconds));
        row.push(format!("{:.3}", r.samples_per_s));
        out.push_str(&row.join(","));
        out.push('\n');
    }
    out
}

/// Write `metrics.csv`, `metrics.jsonl` and `curves.png` into `out` (each atomically).
///
/// # Errors
/// [`NetError::Io`] naming the file; [`NetError::Format`] when the PNG cannot be drawn.
pub fn write_metrics(out: &Path, history: &[EpochRecord]) -> Result<(), NetError> {
    write_atomic(&out.join("metrics.csv"), metrics_csv(history).as_bytes())?;
    let mut jsonl = String::new();
    for r in history {
        jsonl.push_str(&serde_json::to_string(r)?);
        jsonl.push('\n');
    }
    write_atomic(&out.join("metrics.jsonl"), jsonl.as_bytes())?;
    let png = encode_png(&curves_image(history)?)?;
    write_atomic(&out.join("curves.png"), &png)
}

/// Encode an RGB image as PNG bytes.
///
/// # Errors
/// [`NetError::Format`] from the encoder.
pub fn encode_png(img: &RgbImage) -> Result<Vec<u8>, NetError> {
    vpcal_formats::fs::encode_png(img).map_err(NetError::Format)
}

type Series = (String, RGBColor, Vec<(f64, f64)>);

fn finite_points(
    history: &[EpochRecord],
    f: impl Fn(&EpochRecord) -> Option<f64>,
) -> Vec<(f64, f64)> {
    history
        .iter()
        .filter_map(|r| f(r).map(|v| (r.epoch as f64, v)))
        .filter(|(_, v)| v.is_finite() && *v > 0.0)
        .collect()
}

fn draw_panel(
    area: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
    title: &str,
    series: &[Series],
    max_epoch: f64,
) -> Result<(), String> {
    let values: Vec<f64> = series
        .iter()
        .flat_map(|s| s.2.iter().map(|p| p.1))
        .collect();
    if values.is_empty() {
        return Ok(());
    }
    let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = values.iter().copied().fold(0.0f64, f64::max);
    let (lo, hi) = if hi > lo {
        (lo / 1.2, hi * 1.2)
    } else {
        (lo / 2.0, hi * 2.0)
    };
    let mut chart = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(30)
        .y_label_area_size(70)
        .build_cartesian_2d(0.5f64..max_epoch + 0.5, (lo..hi).log_scale())
        .map_err(|e| e.to_string())?;
    chart
        .configure_mesh()
        .x_desc("epoch")
        .y_label_formatter(&|v| format!("{v:.1e}"))
        .draw()
        .map_err(|e| e.to_string())?;
    for (name, color, pts) in series {
        let color = *color;
        chart
            .draw_series(LineSeries::new(pts.iter().copied(), color.stroke_width(2)))
            .map_err(|e| e.to_string())?
            .label(name.as_str())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
            });
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(|e| e.to_string())?;
    Ok(())
}

/// The loss (left) and median relative VP error (right) curves.
///
/// # Errors
/// [`NetError::Format`] when drawing fails.
pub fn curves_image(history: &[EpochRecord]) -> Result<RgbImage, NetError> {
    register_font();
    let (w, h) = (1200u32, 450u32);
    let mut buf = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        let (left, right) = root.split_horizontally(w / 2);
        let max_epoch = history.iter().map(|r| r.epoch).max().unwrap_or(1) as f64;
        let losses = vec![
            (
                "train loss".to_string(),
                BLUE,
                finite_points(history, |r| Some(r.train_loss)),
            ),
            (
                "validation loss".to_string(),
                RED,
                finite_points(history, |r| r.val_loss),
            ),
        ];
        let errors = vec![
            (
                "VP1 median rel. error".to_string(),
                BLUE,
                finite_points(history, |r| r.val.as_ref().map(|m| m.vp1_median_rel)),
            ),
            (
                "VP2 median rel. error".to_string(),
                RED,
                finite_points(history, |r| r.val.as_ref().map(|m| m.vp2_median_rel)),
            ),
        ];
        draw_panel(&left, "loss", &losses, max_epoch).map_err(NetError::Format)?;
        draw_panel(
            &right,
            "validation VP error (box frame)",
            &errors,
            max_epoch,
        )
        .map_err(NetError::Format)?;
        root.present()
            .map_err(|e| NetError::Format(e.to_string()))?;
    }
    RgbImage::from_raw(w, h, buf).ok_or_else(|| NetError::Format("plot buffer size".into()))
}

/// A colour map from `[0, 1]` to dark blue - red - yellow.
fn heat_colour(v: f32) -> Rgb<u8> {
    let t = v.clamp(0.0, 1.0);
    let r = (t * 3.0).clamp(0.0, 1.0);
    let g = (t * 3.0 - 1.0).clamp(0.0, 1.0);
    let b = if t < 1.0 / 3.0 {
        0.35 + t * 1.5
    } else {
        (1.0 - (t - 1.0 / 3.0) * 3.0).clamp(0.0, 1.0) * 0.85
    };
    Rgb([(r * 255.0) as u8, (g * 255.0) as u8, (b * 255.0) as u8])
}

/// A grid image of one crop's heatmaps: one row per VP, one column per scale, each cell the
/// `R x R` heatmap (first axis `h0` down... see below) magnified `zoom` times; when given, the
/// crop itself is shown at the start of each row. Each cell is normalised to its own maximum.
///
/// Heatmap pixel `(h0, h1)` is drawn at column `h0`, row `h1`: `h0` grows with the
/// diamond coordinate `a = u - v` and `h1` with `b = u + v`.
pub fn heatmap_grid(
    heat: &[f32],
    channels: usize,
    resolution: usize,
    zoom: u32,
    crop: Option<&RgbImage>,
) -> RgbImage {
    let scales = channels / 2;
    let cell = resolution as u32 * zoom;
    let gap = 4u32;
    let lead = if crop.is_some() { cell + gap } else { 0 };
    let w = lead + scales as u32 * (cell + gap);
    let h = 2 * (cell + gap);
    let mut img = RgbImage::from_pixel(w.max(1), h.max(1), Rgb([255, 255, 255]));
    let plane = resolution * resolution;
    for row in 0..2u32 {
        let y0 = row * (cell + gap);
        if let Some(c) = crop {
            let resized =
                image::imageops::resize(c, cell, cell, image::imageops::FilterType::Triangle);
            image::imageops::overlay(&mut img, &resized, 0, i64::from(y0));
        }
        for s in 0..scales {
            let ch = row as usize * scales + s;
            let Some(data) = heat.get(ch * plane..(ch + 1) * plane) else {
                continue;
            };
            let max = data.iter().copied().fold(f32::NEG_INFINITY, f32::max);
            let min = data.iter().copied().fold(f32::INFINITY, f32::min);
            let span = if max > min { max - min } else { 1.0 };
            let x0 = lead + s as u32 * (cell + gap);
            for h0 in 0..resolution {
                for h1 in 0..resolution {
                    let v = (data[h0 * resolution + h1] - min) / span;
                    let colour = heat_colour(v);
                    for dy in 0..zoom {
                        for dx in 0..zoom {
                            img.put_pixel(
                                x0 + h0 as u32 * zoom + dx,
                                y0 + h1 as u32 * zoom + dy,
                                colour,
                            );
                        }
                    }
                }
            }
        }
    }
    img
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::VpMetrics;

    fn record(epoch: usize, loss: f64) -> EpochRecord {
        EpochRecord {
            epoch,
            lr: 1e-3,
            steps: epoch as u64 * 10,
            train_samples: 40,
            train_loss: loss,
            train_loss_terms: vec![loss / 2.0; 2],
            first_batch_loss: loss,
            last_batch_loss: loss,
            val_loss: Some(loss * 1.1),
            val: Some(VpMetrics {
                crops: 8,
                vp1_median_rel: 0.5 / epoch as f64,
                vp2_median_rel: f64::INFINITY,
                vp1_median_rel_per_scale: vec![0.4, 0.3],
                vp2_median_rel_per_scale: vec![0.2, 0.1],
                vp1_scale_counts: vec![4, 4],
                vp2_scale_counts: vec![8, 0],
            }),
            seconds: 1.0,
            samples_per_s: 40.0,
        }
    }

    #[test]
    fn csv_has_a_row_per_epoch_and_per_scale_columns() {
        let csv = metrics_csv(&[record(1, 0.1), record(2, 0.05)]);
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines.len(), 3);
        assert!(lines[0].contains("vp2_median_rel_scale1"), "{}", lines[0]);
        assert!(
            lines[2].starts_with("2,1e-3,20,40,5.000000e-2"),
            "{}",
            lines[2]
        );
        assert!(lines[1].contains(",inf,"), "{}", lines[1]);
        let cols = lines[0].split(',').count();
        assert!(lines.iter().all(|l| l.split(',').count() == cols));
    }

    #[test]
    fn curves_draw_text_and_lines() {
        let img = curves_image(&[record(1, 0.1), record(2, 0.05), record(3, 0.02)]).unwrap();
        let blue = img.pixels().filter(|p| p.0 == [0, 0, 255]).count();
        let dark = img.pixels().filter(|p| p.0.iter().all(|&c| c < 60)).count();
        assert!(blue > 50, "no train-loss line ({blue} blue pixels)");
        assert!(dark > 200, "no text or axes ({dark} dark pixels)");
        let dir = tempfile::tempdir().unwrap();
        write_metrics(dir.path(), &[record(1, 0.1)]).unwrap();
        for f in ["metrics.csv", "metrics.jsonl", "curves.png"] {
            assert!(dir.path().join(f).is_file(), "{f}");
        }
    }

    #[test]
    fn heatmap_grid_layout() {
        let mut heat = vec![0.0f32; 4 * 8 * 8];
        heat[3 * 64 + 2 * 8 + 5] = 1.0; // VP2, scale 1, h0 = 2, h1 = 5
        let img = heatmap_grid(&heat, 4, 8, 2, None);
        assert_eq!(img.dimensions(), (2 * (16 + 4), 2 * (16 + 4)));
        let hot = img.get_pixel(20 + 2 * 2, 20 + 5 * 2);
        assert_eq!(hot.0, [255, 255, 0]);
    }
}
