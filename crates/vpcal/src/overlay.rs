//! The overlay picture of a calibration: horizon, a road-plane grid aligned with the traffic
//! direction, vehicle boxes with the VP directions the network gave them, vehicle tracks, and
//! a legend, so that a calibration can be checked by eye.
//!
//! Colours: horizon yellow, road grid cyan, boxes white, directions towards VP1 red and
//! towards VP2 green (the same colours as the synthetic ground-truth pictures), tracks orange.
//!
//! The picture is one frame of the run (the last one the pipeline read). When that frame's
//! index is known ([`picture_frame`]) only the boxes, directions and tracks of that frame are
//! drawn, so every box should sit on a vehicle of the picture. Without it (callers that only
//! have the records) a sample of vehicles from the whole run is drawn, with the straight
//! tracks the aggregation found, and the legend says the boxes are a composite.
//!
//! A horizon above or below the frame is shown by an arrow at the frame's edge with its
//! distance ("horizon 340 px above"). Text is drawn with DejaVu Sans, the font `vpcal-net`
//! embeds for its plots (`crates/vpcal-net/assets`, Bitstream Vera licence there).

use std::sync::OnceLock;

use ab_glyph::{point, Font, FontRef, PxScale, ScaleFont};
use image::{Rgb, RgbImage};
use vpcal_geom::aggregate::tracks::TrackLine;
use vpcal_geom::camera::Calibration;
use vpcal_geom::Point2;
use vpcal_video::draw::{draw_line, draw_ring};
use vpcal_video::SourceOptions;

use crate::pipeline::{PipelineOutput, TrackBox, VehicleRecord};
use crate::tracks::VehicleTrack;

const YELLOW: Rgb<u8> = Rgb([255, 220, 0]);
const CYAN: Rgb<u8> = Rgb([0, 220, 255]);
const RED: Rgb<u8> = Rgb([255, 40, 40]);
const GREEN: Rgb<u8> = Rgb([40, 230, 40]);
const WHITE: Rgb<u8> = Rgb([255, 255, 255]);
const ORANGE: Rgb<u8> = Rgb([255, 140, 0]);
const BLACK: Rgb<u8> = Rgb([0, 0, 0]);

/// How many vehicles get their boxes and VP directions drawn in a composite.
const SAMPLE_VEHICLES: usize = 16;

/// DejaVu Sans (Bitstream Vera licence: `crates/vpcal-net/assets/DejaVuSans-LICENSE.txt`).
static FONT_TTF: &[u8] = include_bytes!("../../vpcal-net/assets/DejaVuSans.ttf");

fn font() -> Option<&'static FontRef<'static>> {
    static FONT: OnceLock<Option<FontRef<'static>>> = OnceLock::new();
    FONT.get_or_init(|| FontRef::try_from_slice(FONT_TTF).ok())
        .as_ref()
}

fn line_width(img: &RgbImage) -> f64 {
    (f64::from(img.width().max(img.height())) / 640.0).clamp(1.0, 4.0)
}

/// The legend's text height in pixels for a picture.
fn text_size(img: &RgbImage) -> f32 {
    (img.height() as f32 / 26.0).clamp(9.0, 24.0)
}

/// What the overlay shows besides the calibration: the run's vehicles and where the picture
/// sits in it.
#[derive(Debug, Clone, Copy, Default)]
pub struct Scene<'a> {
    /// The source frame index of the picture, when known ([`picture_frame`]): only that
    /// frame's boxes and tracks are drawn. `None`: a composite of the whole run.
    pub picture_frame: Option<u64>,
    /// Every detector box of the run ([`PipelineOutput::boxes`]).
    pub boxes: &'a [TrackBox],
    /// The vehicles the network saw (boxes and VP directions).
    pub records: &'a [VehicleRecord],
    /// The vehicle tracks of the run ([`crate::output::run_tracks`]); drawn for the
    /// picture's frame.
    pub tracks: &'a [VehicleTrack],
    /// The straight tracks the aggregation found (drawn in a composite).
    pub track_lines: &'a [TrackLine],
    /// Metres per road unit, for the grid's spacing.
    pub scale_m_per_unit: Option<f64>,
    /// The lane lines found in the scene's background ([`crate::markings`]).
    pub markings: &'a [crate::markings::LaneLine],
}

/// The source frame index of the run's picture ([`PipelineOutput::picture`], the last frame
/// of the main pass). Every frame source numbers the frames it yields `first + k · every`
/// (`first` the start frame), so the k-th of `stats.frames` frames is known; `None` when
/// there is no picture, when a box of the run contradicts that numbering (a frame after the
/// picture, or off the `every` grid: a caller's own frame source), or for a video retimed with
/// `--fps` that starts at a time (its start frame follows the file's own rate).
pub fn picture_frame(out: &PipelineOutput, frames: &SourceOptions) -> Option<u64> {
    if out.picture.is_none() || out.stats.frames == 0 {
        return None;
    }
    // A video timed at another rate (`--fps`) seeks a start time at its own rate, which the
    // run does not record.
    let retimed = out.info.kind == vpcal_video::SourceKind::Video && frames.image_fps.is_some();
    if retimed && matches!(frames.start, vpcal_video::Start::Seconds(_)) {
        return None;
    }
    let every = frames.every.max(1);
    let first = frames.start.to_frame_index(out.info.fps.unwrap_or(1.0));
    let last = first.checked_add((out.stats.frames - 1).checked_mul(every)?)?;
    let fits = |f: u64| f >= first && f <= last && (f - first) % every == 0;
    let ok = out.boxes.iter().all(|b| fits(b.frame)) && out.records.iter().all(|r| fits(r.frame));
    ok.then_some(last)
}

/// Up to `n` records spread evenly over the run, with finite VPs.
fn sample(records: &[VehicleRecord], n: usize) -> Vec<&VehicleRecord> {
    let ok: Vec<&VehicleRecord> = records
        .iter()
        .filter(|r| r.prediction.is_some() && r.vp1.is_finite() && r.vp2.is_finite())
        .collect();
    if ok.len() <= n {
        return ok;
    }
    (0..n).map(|i| ok[i * ok.len() / n]).collect()
}

/// A point `len` pixels from `from` towards `to`.
fn towards(from: Point2, to: Point2, len: f64) -> [f64; 2] {
    let d = Point2 {
        x: to.x - from.x,
        y: to.y - from.y,
    };
    let n = d.norm();
    if n < 1e-9 {
        return [from.x, from.y];
    }
    let l = len.min(n);
    [from.x + d.x / n * l, from.y + d.y / n * l]
}

fn draw_rect(img: &mut RgbImage, b: &vpcal_geom::BoxPx, colour: Rgb<u8>, width: f64) {
    let corners = [[b.x0, b.y0], [b.x1, b.y0], [b.x1, b.y1], [b.x0, b.y1]];
    for k in 0..4 {
        draw_line(img, corners[k], corners[(k + 1) % 4], colour, width);
    }
}

/// The box and the VP directions of one vehicle record.
fn draw_record(img: &mut RgbImage, r: &VehicleRecord) {
    let w = line_width(img);
    let b = &r.crop_box;
    draw_rect(img, b, WHITE, w * 0.75);
    // Only the network's own VPs (a box it did not see carries its vehicle's, copied).
    if r.prediction.is_some() && r.vp1.is_finite() && r.vp2.is_finite() {
        let c = b.center();
        let len = 1.5 * b.width().max(b.height());
        draw_line(img, [c.x, c.y], towards(c, r.vp1, len), RED, w);
        draw_line(img, [c.x, c.y], towards(c, r.vp2, len), GREEN, w);
    }
}

/// Percentile (0..1) of values; `None` when there are none.
fn percentile(v: &[f64], q: f64) -> Option<f64> {
    Some(vpcal_geom::solve::percentile(v.to_vec(), q * 100.0)).filter(|p| p.is_finite())
}

/// The smallest of 1, 2, 5 × 10^k at least `x` (`x > 0`).
pub fn nice_step(x: f64) -> f64 {
    if !(x.is_finite() && x > 0.0) {
        return 1.0;
    }
    let p = 10f64.powf(x.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * p)
        .find(|s| *s >= x * (1.0 - 1e-9))
        .unwrap_or(10.0 * p)
}

/// A length for the legend: `12 m`, `0.5 m`, `0.02 road units`.
fn length_text(v: f64, unit: &str) -> String {
    let digits = if v >= 1.0 {
        0
    } else {
        (-v.log10().floor()) as usize
    };
    format!("{v:.digits$} {unit}")
}

/// The road grid: lines along the traffic direction (VP1) and across it (VP2) over the area
/// where vehicles were seen (5th-95th percentile of their box bottoms on the road plane), at
/// round spacings (metres with a scale, road units without). Returns the legend's text.
fn draw_grid(
    img: &mut RgbImage,
    cal: &Calibration,
    feet: &[Point2],
    scale: Option<f64>,
) -> Option<String> {
    let u1 = [cal.rotation[0][0], cal.rotation[1][0], cal.rotation[2][0]];
    let u2 = [cal.rotation[0][1], cal.rotation[1][1], cal.rotation[2][1]];
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let (mut along, mut across) = (Vec::new(), Vec::new());
    let mut origin = None;
    for &foot in feet {
        if let Some(x) = cal.project_to_road(foot) {
            origin.get_or_insert(x);
            along.push(dot(x, u1));
            across.push(dot(x, u2));
        }
    }
    // Without vehicles on the road: a grid around the road point below the image centre.
    let (a0, a1, b0, b1, base) = match (
        percentile(&along, 0.05),
        percentile(&along, 0.95),
        percentile(&across, 0.05),
        percentile(&across, 0.95),
        origin,
    ) {
        (Some(a0), Some(a1), Some(b0), Some(b1), Some(o)) if a1 > a0 && b1 > b0 => {
            (a0, a1, b0, b1, o)
        }
        _ => {
            let p = Point2 {
                x: f64::from(img.width()) / 2.0,
                y: f64::from(img.height()) * 0.8,
            };
            let o = cal.project_to_road(p)?;
            let (a, b) = (dot(o, u1), dot(o, u2));
            let s = (o[0] * o[0] + o[1] * o[1] + o[2] * o[2]).sqrt() * 0.3;
            (a - s, a + s, b - s, b + s, o)
        }
    };
    // Round spacings: about 8 cells each way, in metres when scaled.
    let unit = scale.filter(|s| s.is_finite() && *s > 0.0);
    let m = unit.unwrap_or(1.0);
    let step_a = nice_step((a1 - a0) * m / 8.0) / m;
    let step_b = nice_step((b1 - b0) * m / 8.0) / m;
    let (ka0, ka1) = ((a0 / step_a).floor(), (a1 / step_a).ceil());
    let (kb0, kb1) = ((b0 / step_b).floor(), (b1 / step_b).ceil());
    if !(ka1 - ka0 <= 60.0 && kb1 - kb0 <= 60.0) {
        return None;
    }
    let (a0, a1, b0, b1) = (ka0 * step_a, ka1 * step_a, kb0 * step_b, kb1 * step_b);
    // A road point from its (along, across) coordinates: base + (a - a_base) u1 + (b - b_base) u2.
    let (ab, bb) = (dot(base, u1), dot(base, u2));
    let road = |a: f64, b: f64| -> [f64; 3] {
        [
            base[0] + (a - ab) * u1[0] + (b - bb) * u2[0],
            base[1] + (a - ab) * u1[1] + (b - bb) * u2[1],
            base[2] + (a - ab) * u1[2] + (b - bb) * u2[2],
        ]
    };
    let w = line_width(img);
    let segment = |img: &mut RgbImage, p: [f64; 3], q: [f64; 3]| {
        // Short pieces, so that a line partly behind the camera is drawn where it is visible.
        let n = 24;
        let mut prev: Option<Point2> = None;
        for k in 0..=n {
            let t = f64::from(k) / f64::from(n);
            let x = [
                p[0] + (q[0] - p[0]) * t,
                p[1] + (q[1] - p[1]) * t,
                p[2] + (q[2] - p[2]) * t,
            ];
            // Road points on the far side of the camera centre (depth of the other sign than
            // the vehicles' road) are not seen.
            let cur = if x[2] * base[2] > 0.0 {
                cal.image_of_road_point(x)
            } else {
                None
            };
            if let (Some(a), Some(b)) = (prev, cur) {
                draw_line(img, [a.x, a.y], [b.x, b.y], CYAN, w);
            }
            prev = cur;
        }
    };
    for k in 0..=((kb1 - kb0) as i64) {
        let b = b0 + k as f64 * step_b;
        segment(img, road(a0, b), road(a1, b));
    }
    for k in 0..=((ka1 - ka0) as i64) {
        let a = a0 + k as f64 * step_a;
        segment(img, road(a, b0), road(a, b1));
    }
    let unit_name = if unit.is_some() { "m" } else { "road units" };
    let (sa, sb) = (step_a * m, step_b * m);
    Some(if (sa - sb).abs() < 1e-9 * sa {
        format!("road grid {} squares", length_text(sa, unit_name))
    } else {
        format!(
            "road grid {} along × {} across",
            length_text(sa, unit_name),
            length_text(sb, unit_name)
        )
    })
}

/// The paths of the straight vehicle tracks, each from its first to its last box centre
/// along the fitted line.
fn draw_track_lines(img: &mut RgbImage, tracks: &[TrackLine]) {
    let w = line_width(img);
    for t in tracks {
        let (p, d, h) = (t.point, t.dir, t.travel / 2.0);
        draw_line(
            img,
            [p.x - d.x * h, p.y - d.y * h],
            [p.x + d.x * h, p.y + d.y * h],
            ORANGE,
            w,
        );
    }
}

/// The whole path (contact points) of each track that has a point in `frame`, with a dot
/// where the vehicle is in that frame. Returns how many tracks were drawn.
fn draw_tracks_of_frame(img: &mut RgbImage, tracks: &[VehicleTrack], frame: u64) -> usize {
    let w = line_width(img);
    let mut n = 0;
    for t in tracks {
        let Some(now) = t.points.iter().find(|p| p.frame == frame) else {
            continue;
        };
        n += 1;
        for pair in t.points.windows(2) {
            let (a, b) = (pair[0].image, pair[1].image);
            draw_line(img, [a.x, a.y], [b.x, b.y], ORANGE, w);
        }
        draw_ring(img, [now.image.x, now.image.y], 1.5 * w, ORANGE);
    }
    n
}

/// Where the horizon is when it misses the frame: `Some((above, pixels))`, measured at the
/// frame's middle column from its top (above) or bottom (below) edge.
pub fn horizon_outside(cal: &Calibration, width: u32, height: u32) -> Option<(bool, f64)> {
    let [a, b, c] = cal.horizon.0;
    if b.abs() < 1e-9 {
        return None;
    }
    let y = |x: f64| -(a * x + c) / b;
    let (w, h) = (f64::from(width), f64::from(height));
    let (y0, y1, ym) = (y(0.0), y(w), y(w / 2.0));
    if y0 < 0.0 && y1 < 0.0 {
        Some((true, -ym))
    } else if y0 > h && y1 > h {
        Some((false, ym - h))
    } else {
        None
    }
    .filter(|(_, d)| d.is_finite())
}

/// The horizon line, or an arrow at the frame edge pointing to it with its distance.
fn draw_horizon(img: &mut RgbImage, cal: &Calibration) -> Option<()> {
    let w = line_width(img);
    let [a, b, c] = cal.horizon.0;
    let (width, height) = (f64::from(img.width()), f64::from(img.height()));
    if b.abs() > 1e-12 {
        let y = |x: f64| -(a * x + c) / b;
        draw_line(
            img,
            [-width, y(-width)],
            [2.0 * width, y(2.0 * width)],
            YELLOW,
            w * 1.5,
        );
    }
    let (above, d) = horizon_outside(cal, img.width(), img.height())?;
    let x = width / 2.0;
    let len = (height * 0.12).clamp(12.0, 80.0);
    let head = (len * 0.35).max(5.0);
    let (tip, tail) = if above {
        (2.0, 2.0 + len)
    } else {
        (height - 2.0, height - 2.0 - len)
    };
    let dir = if above { 1.0 } else { -1.0 };
    // A dark outline under the yellow arrow, so that it shows on a bright sky.
    for (col, wd) in [(BLACK, 2.5 * w), (YELLOW, 1.5 * w)] {
        draw_line(img, [x, tip], [x, tail], col, wd);
        draw_line(img, [x, tip], [x - head, tip + dir * head], col, wd);
        draw_line(img, [x, tip], [x + head, tip + dir * head], col, wd);
    }
    let label = format!(
        "horizon {:.0} px {}",
        d,
        if above { "above" } else { "below" }
    );
    let size = text_size(img);
    let tw = text_width(&label, size);
    let pad = f64::from(size) * 0.25;
    // Right of the arrow, kept inside the frame.
    let lx = f64::max(f64::min(x + head + pad, width - tw - 2.0 * pad), 0.0);
    let ly = if above {
        2.0
    } else {
        height - 2.0 - f64::from(size) * 1.3
    };
    let h = f64::from(size) * 1.3;
    blend_rect(img, lx, ly, lx + tw + 2.0 * pad, ly + h, BLACK, 0.6);
    draw_text(
        img,
        lx + pad,
        ly + f64::from(size) * 0.1,
        &label,
        size,
        YELLOW,
    );
    Some(())
}

// -- text ----------------------------------------------------------------------------------

/// The advance width of `text` at `size` pixels.
fn text_width(text: &str, size: f32) -> f64 {
    let Some(font) = font() else {
        return 0.0;
    };
    let f = font.as_scaled(PxScale::from(size));
    let mut w = 0.0f32;
    let mut prev = None;
    for ch in text.chars() {
        let id = f.glyph_id(ch);
        if let Some(p) = prev {
            w += f.kern(p, id);
        }
        w += f.h_advance(id);
        prev = Some(id);
    }
    f64::from(w)
}

/// Draws `text` with its top at `y` (the font's ascent below it is the baseline).
fn draw_text(img: &mut RgbImage, x: f64, y: f64, text: &str, size: f32, colour: Rgb<u8>) {
    let Some(font) = font() else {
        return;
    };
    let scale = PxScale::from(size);
    let f = font.as_scaled(scale);
    let baseline = y as f32 + f.ascent();
    let mut pen = x as f32;
    let mut prev = None;
    let (iw, ih) = (img.width() as i64, img.height() as i64);
    for ch in text.chars() {
        let id = f.glyph_id(ch);
        if let Some(p) = prev {
            pen += f.kern(p, id);
        }
        let glyph = id.with_scale_and_position(scale, point(pen, baseline));
        pen += f.h_advance(id);
        prev = Some(id);
        let Some(outline) = font.outline_glyph(glyph) else {
            continue;
        };
        let bounds = outline.px_bounds();
        outline.draw(|gx, gy, cov| {
            let px = bounds.min.x as i64 + i64::from(gx);
            let py = bounds.min.y as i64 + i64::from(gy);
            if px < 0 || py < 0 || px >= iw || py >= ih {
                return;
            }
            // Why: checked against the image size above.
            let o = img.get_pixel_mut(px as u32, py as u32);
            let cov = cov.clamp(0.0, 1.0);
            for k in 0..3 {
                let v = f32::from(o[k]) * (1.0 - cov) + f32::from(colour[k]) * cov;
                o[k] = v.round() as u8;
            }
        });
    }
}

/// Blends the rectangle [x0, x1) x [y0, y1) towards `colour` by `alpha`.
fn blend_rect(img: &mut RgbImage, x0: f64, y0: f64, x1: f64, y1: f64, colour: Rgb<u8>, alpha: f32) {
    let (w, h) = (f64::from(img.width()), f64::from(img.height()));
    // Why: clamped to the image before the casts.
    let (x0, x1) = (x0.clamp(0.0, w) as u32, x1.clamp(0.0, w) as u32);
    let (y0, y1) = (y0.clamp(0.0, h) as u32, y1.clamp(0.0, h) as u32);
    for y in y0..y1 {
        for x in x0..x1 {
            let o = img.get_pixel_mut(x, y);
            for ch in 0..3 {
                let v = f32::from(o[ch]) * (1.0 - alpha) + f32::from(colour[ch]) * alpha;
                o[ch] = v.round() as u8;
            }
        }
    }
}

// -- legend --------------------------------------------------------------------------------

/// How a legend line shows its colour.
#[derive(Debug, Clone, Copy)]
enum Swatch {
    Line(Rgb<u8>),
    Box(Rgb<u8>),
}

/// The legend box in the corner of the picture where the overlay drew least (compared with
/// the `original` picture), so that it hides as little of the drawing as possible.
fn draw_legend(img: &mut RgbImage, original: &RgbImage, lines: &[(Vec<Swatch>, String)]) {
    if lines.is_empty() {
        return;
    }
    let size = text_size(img);
    let s = f64::from(size);
    let line_h = s * 1.3;
    let pad = s * 0.4;
    let sw = s * 1.4; // swatch width
    let widths: Vec<f64> = lines
        .iter()
        .map(|(sws, t)| sws.len() as f64 * (sw + pad * 0.5) + pad * 0.5 + text_width(t, size))
        .collect();
    let bw = widths.iter().copied().fold(0.0, f64::max) + 2.0 * pad;
    let bh = lines.len() as f64 * line_h + 2.0 * pad;
    let (iw, ih) = (f64::from(img.width()), f64::from(img.height()));
    let m = 3.0;
    let corners = [
        (m, ih - bh - m),
        (iw - bw - m, ih - bh - m),
        (m, m),
        (iw - bw - m, m),
    ];
    // Pixels the overlay changed under a legend at (x, y).
    let covered = |(x, y): (f64, f64)| {
        let (xa, ya) = (x.max(0.0) as u32, y.max(0.0) as u32);
        let (xb, yb) = (
            ((x + bw) as u32).min(img.width()),
            ((y + bh) as u32).min(img.height()),
        );
        (ya..yb)
            .flat_map(|py| (xa..xb).map(move |px| (px, py)))
            .filter(|&(px, py)| img.get_pixel(px, py) != original.get_pixel(px, py))
            .count()
    };
    let (x0, y0) = corners
        .iter()
        .copied()
        .min_by_key(|c| covered(*c))
        .unwrap_or(corners[0]);
    let (x0, y0) = (x0.max(0.0), y0.max(0.0));
    blend_rect(img, x0, y0, x0 + bw, y0 + bh, BLACK, 0.62);
    let lw = line_width(img);
    for (i, (sws, text)) in lines.iter().enumerate() {
        let top = y0 + pad + i as f64 * line_h;
        let mid = top + line_h * 0.5;
        let mut x = x0 + pad;
        for sw_kind in sws {
            match *sw_kind {
                Swatch::Line(c) => draw_line(img, [x, mid], [x + sw, mid], c, lw * 1.5),
                Swatch::Box(c) => {
                    let b = vpcal_geom::BoxPx::new(
                        x + sw * 0.15,
                        mid - s * 0.35,
                        x + sw * 0.85,
                        mid + s * 0.35,
                    );
                    draw_rect(img, &b, c, lw);
                }
            }
            x += sw + pad * 0.5;
        }
        draw_text(
            img,
            x + pad * 0.5,
            top + (line_h - s * 1.17) * 0.5,
            text,
            size,
            WHITE,
        );
    }
}

// -- the overlay ---------------------------------------------------------------------------

/// The overlay of `picture`: the calibration `cal` when there is one (grid, horizon, VPs),
/// the vehicles of `scene`, and the legend.
pub fn draw_scene(picture: &RgbImage, cal: Option<&Calibration>, scene: &Scene<'_>) -> RgbImage {
    let mut img = picture.clone();
    let mut legend: Vec<(Vec<Swatch>, String)> = Vec::new();
    let feet: Vec<Point2> = scene
        .records
        .iter()
        .map(|r| Point2::new((r.crop_box.x0 + r.crop_box.x1) / 2.0, r.crop_box.y1))
        .collect();
    if let Some(cal) = cal {
        if let Some(text) = draw_grid(&mut img, cal, &feet, scene.scale_m_per_unit) {
            legend.push((vec![Swatch::Line(CYAN)], text));
        }
    }
    match scene.picture_frame {
        Some(frame) => {
            let n_tracks = draw_tracks_of_frame(&mut img, scene.tracks, frame);
            let w = line_width(&img);
            let mut n_boxes = 0usize;
            let records: Vec<&VehicleRecord> =
                scene.records.iter().filter(|r| r.frame == frame).collect();
            // Detector boxes the network did not see (over the per-frame limit) too.
            for b in scene.boxes.iter().filter(|b| b.frame == frame) {
                let seen = records.iter().any(|r| r.det_box == b.bbox);
                if !seen {
                    draw_rect(&mut img, &b.bbox, WHITE, w * 0.75);
                    n_boxes += 1;
                }
            }
            for r in &records {
                draw_record(&mut img, r);
                n_boxes += 1;
            }
            if records.iter().any(|r| r.prediction.is_some()) {
                legend.push((
                    vec![Swatch::Line(RED), Swatch::Line(GREEN)],
                    "to VP1 / VP2 (network)".to_string(),
                ));
            }
            if n_tracks > 0 {
                legend.push((
                    vec![Swatch::Line(ORANGE)],
                    format!(
                        "{n_tracks} track{} (box bottoms)",
                        if n_tracks == 1 { "" } else { "s" }
                    ),
                ));
            }
            legend.push((
                vec![Swatch::Box(WHITE)],
                if n_boxes == 0 {
                    format!("no vehicle boxes in this frame ({frame})")
                } else {
                    format!(
                        "{n_boxes} box{} of this frame ({frame})",
                        if n_boxes == 1 { "" } else { "es" }
                    )
                },
            ));
        }
        None => {
            draw_track_lines(&mut img, scene.track_lines);
            let shown = sample(scene.records, SAMPLE_VEHICLES);
            for r in &shown {
                draw_record(&mut img, r);
            }
            if !shown.is_empty() {
                legend.push((
                    vec![Swatch::Line(RED), Swatch::Line(GREEN)],
                    "to VP1 / VP2 (network)".to_string(),
                ));
            }
            if !scene.track_lines.is_empty() {
                legend.push((
                    vec![Swatch::Line(ORANGE)],
                    format!("{} straight tracks (VP1 evidence)", scene.track_lines.len()),
                ));
            }
            let frames = shown.iter().map(|r| r.frame);
            let (lo, hi) = (frames.clone().min(), frames.max());
            legend.push((
                vec![Swatch::Box(WHITE)],
                match (lo, hi) {
                    (Some(lo), Some(hi)) if lo == hi => {
                        format!("{} boxes of frame {lo}, maybe not this one", shown.len())
                    }
                    (Some(lo), Some(hi)) => format!(
                        "{} boxes from frames {lo}-{hi}: composite, not this frame",
                        shown.len()
                    ),
                    _ => "no vehicle boxes".to_string(),
                },
            ));
        }
    }
    if !scene.markings.is_empty() {
        let w = line_width(&img);
        let mut dashed = 0usize;
        for l in scene.markings {
            dashed += usize::from(l.dashes.is_some());
            let (colour, width) = if l.dashes.is_some() {
                (GREEN, w)
            } else {
                (WHITE, 0.5 * w)
            };
            for b in &l.bars {
                let [p, q] = b.ends;
                draw_line(&mut img, [p.x, p.y], [q.x, q.y], colour, width);
            }
        }
        legend.push((
            vec![Swatch::Line(GREEN), Swatch::Line(WHITE)],
            format!(
                "{} lines along the road in the background ({dashed} dashed / other)",
                scene.markings.len()
            ),
        ));
    }
    if let Some(cal) = cal {
        draw_horizon(&mut img, cal);
        let w = line_width(&img);
        for (vp, col) in [(cal.vp1, RED), (cal.vp2, GREEN)] {
            draw_ring(&mut img, [vp.x, vp.y], 6.0 * w, col);
        }
        legend.insert(0, (vec![Swatch::Line(YELLOW)], "horizon".to_string()));
    } else {
        legend.insert(0, (Vec::new(), "not calibrated: boxes only".to_string()));
    }
    // Legend lines: horizon (or the failure), grid, directions, tracks, boxes.
    draw_legend(&mut img, picture, &legend);
    img
}

/// The overlay of a calibration on `picture`, with a sample of the run's vehicles and the
/// straight vehicle tracks the aggregation found (a composite of the run: the legend says
/// so). [`draw_run`] draws only the picture's own frame when it can.
pub fn draw(
    picture: &RgbImage,
    cal: &Calibration,
    records: &[VehicleRecord],
    tracks: &[TrackLine],
) -> RgbImage {
    let scene = Scene {
        records,
        track_lines: tracks,
        ..Scene::default()
    };
    draw_scene(picture, Some(cal), &scene)
}

/// Boxes and per-vehicle VP directions only (for runs without a calibration), a composite.
pub fn draw_records_only(picture: &RgbImage, records: &[VehicleRecord]) -> RgbImage {
    let scene = Scene {
        records,
        ..Scene::default()
    };
    draw_scene(picture, None, &scene)
}

/// The overlay of a pipeline run on its picture: the camera `cal` with the aggregation's
/// straight tracks when calibrated, the boxes and `tracks` of the picture's own frame
/// ([`picture_frame`], from the run's frame selection `frames`), or a composite when that
/// frame is not known. `None` when the run has no picture.
pub fn draw_run(
    out: &PipelineOutput,
    frames: &SourceOptions,
    cal: Option<(&Calibration, &[TrackLine])>,
    tracks: &[VehicleTrack],
    scale_m_per_unit: Option<f64>,
) -> Option<RgbImage> {
    let picture = out.picture.as_ref()?;
    let markings = match (cal, &out.background) {
        (Some((c, _)), Some(bg)) => crate::markings::lines_in(bg, c.vp1),
        _ => Vec::new(),
    };
    let scene = Scene {
        markings: &markings,
        picture_frame: picture_frame(out, frames),
        boxes: &out.boxes,
        records: &out.records,
        tracks,
        track_lines: cal.map_or(&[][..], |c| c.1),
        scale_m_per_unit,
    };
    Some(draw_scene(picture, cal.map(|c| c.0), &scene))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steps_are_round() {
        assert_eq!(nice_step(3.2), 5.0);
        assert_eq!(nice_step(5.0), 5.0);
        assert_eq!(nice_step(0.13), 0.2);
        assert_eq!(nice_step(11.0), 20.0);
        assert_eq!(nice_step(0.0), 1.0);
        assert_eq!(length_text(0.2, "m"), "0.2 m");
        assert_eq!(length_text(10.0, "m"), "10 m");
    }

    #[test]
    fn text_is_drawn() {
        let mut img = RgbImage::new(120, 30);
        draw_text(&mut img, 2.0, 2.0, "horizon 12 px", 14.0, WHITE);
        let lit = img.pixels().filter(|p| p[0] > 128).count();
        assert!(lit > 50, "{lit} lit pixels");
        assert!(text_width("horizon", 14.0) > 30.0);
    }

    #[test]
    fn a_horizon_above_the_frame_is_found_and_marked() {
        // VP1 and VP2 on a level horizon 300 px above a 640x480 frame (f = 600 px).
        let cal = Calibration::from_vps(
            Point2::new(300.0, -300.0),
            Point2::new(32900.0, -300.0),
            Point2::new(320.0, 240.0),
        )
        .unwrap();
        let (above, d) = horizon_outside(&cal, 640, 480).unwrap();
        assert!(above && (d - 300.0).abs() < 1e-6, "{above} {d}");
        let img = draw_scene(&RgbImage::new(640, 480), Some(&cal), &Scene::default());
        // The yellow arrow at the top edge, in the middle column.
        let yellow = (0..40)
            .filter(|&y| {
                let p = img.get_pixel(320, y);
                p[0] > 200 && p[1] > 180 && p[2] < 80
            })
            .count();
        assert!(yellow > 10, "{yellow}");
    }
}
