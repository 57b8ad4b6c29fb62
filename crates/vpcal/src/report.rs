//! The HTML report of a calibration (`vpcal calibrate --report`, Python's
//! `Calibration.report`): one self-contained page that a person can read to judge the
//! calibration, and that works offline. The overlay picture is inlined as a `data:` PNG,
//! plots are inline SVG, the style sheet is inline; nothing refers to the network.
//!
//! [`render`] is pure: the calibration file, the overlay PNG and the tracks in, the page out.
//! It shows the overlay, the focal length with its 68 % interval against the plausible range
//! of traffic cameras and the estimates that carried it, the horizon and the evidence for
//! VP1, the metric scale with the tracks' summary and a speed histogram, and every warning in
//! plain words with what to do about it ([`explain_warning`]). A run without a camera gets a
//! page that says why, with the boxes-only picture.

use std::fmt::Write as _;
use std::path::Path;

use serde_json::Value;
use vpcal_formats::calib::{CalibrationFile, Status};
use vpcal_geom::aggregate::focal::{focal_prior_range_widths, TRAFFIC_FOV_DEG};

use crate::overlay::nice_step;
use crate::tracks::VehicleTrack;

/// What a report shows besides the calibration file.
#[derive(Debug, Clone, Copy, Default)]
pub struct ReportInput<'a> {
    /// The overlay picture, PNG bytes (`calibrate --overlay`'s picture).
    pub overlay_png: Option<&'a [u8]>,
    /// The vehicle tracks of the run, when they were computed.
    pub tracks: Option<&'a [VehicleTrack]>,
    /// Why the tracks have no speeds, when they have none (the tracks file's `note`).
    pub tracks_note: Option<&'a str>,
    /// What the run said about its input (a truncated video, ...): shown with the warnings.
    pub run_warnings: &'a [String],
}

/// The report page of calibration `file` with the overlay picture `overlay_png` (PNG bytes)
/// and the run's `tracks` (see [`render_with`] for the run's other notes).
pub fn render(
    file: &CalibrationFile,
    overlay_png: Option<&[u8]>,
    tracks: Option<&[VehicleTrack]>,
) -> String {
    render_with(
        file,
        &ReportInput {
            overlay_png,
            tracks,
            ..ReportInput::default()
        },
    )
}

/// Write a report page atomically (the project's atomic writer).
///
/// # Errors
/// The file cannot be written.
pub fn write(path: &Path, html: &str) -> anyhow::Result<()> {
    vpcal_formats::fs::write_atomic(path, html.as_bytes())?;
    Ok(())
}

// -- text helpers --------------------------------------------------------------------------

/// `text` escaped for HTML text and attribute values.
pub fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// Standard base64 (RFC 4648, with padding).
pub fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            chunk.get(1).copied().unwrap_or(0),
            chunk.get(2).copied().unwrap_or(0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(char::from(ALPHABET[((n >> (18 - 6 * k)) & 63) as usize]));
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// A number with `digits` decimals, or "–" when missing or not finite.
fn num(v: Option<f64>, digits: usize) -> String {
    match v {
        Some(x) if x.is_finite() => format!("{x:.digits$}"),
        _ => "–".to_string(),
    }
}

fn ev<'a>(file: &'a CalibrationFile, key: &str) -> Option<&'a Value> {
    file.evidence.as_ref()?.get(key).filter(|v| !v.is_null())
}

fn ev_f64(file: &CalibrationFile, key: &str) -> Option<f64> {
    ev(file, key)?.as_f64().filter(|v| v.is_finite())
}

fn ev_bool(file: &CalibrationFile, key: &str) -> bool {
    ev(file, key).and_then(Value::as_bool).unwrap_or(false)
}

fn ev_u64(file: &CalibrationFile, key: &str) -> Option<u64> {
    ev(file, key)?.as_u64()
}

/// The setting `key` of `file` as a pair of numbers (e.g. `focal_range`), if it is one.
pub(crate) fn setting_pair(file: &CalibrationFile, key: &str) -> Option<[f64; 2]> {
    let v = file.settings.get(key)?.as_array()?;
    match v.as_slice() {
        [a, b] => Some([a.as_f64()?, b.as_f64()?]),
        _ => None,
    }
}

/// Horizontal field of view, degrees, of focal length `f` for frames `width` pixels wide.
fn fov_deg(f: f64, width: u32) -> f64 {
    2.0 * (f64::from(width) / (2.0 * f)).atan().to_degrees()
}

/// The name of the input for the title: its file name.
fn input_name(file: &CalibrationFile) -> String {
    let p = Path::new(&file.input.path);
    p.file_name().map_or_else(
        || file.input.path.clone(),
        |n| n.to_string_lossy().into_owned(),
    )
}

// -- warnings ------------------------------------------------------------------------------

/// A kind of warning a calibration can carry, recognised from its text.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WarningKind {
    /// The focal length came from the prior (`aggregate::Aggregated::warnings`).
    AssumedFocal,
    /// A measured focal length outside the user's `--focal-range`.
    FocalOutsideRange,
    /// VP1 from the network's scattered VP1 rays alone.
    WeakVp1,
    /// The curved-road fit and the straight fit of the same edges disagree on f.
    CurvedFitDisagrees,
    /// The edges across the vehicles are parallel (a view straight down).
    ParallelEdges,
    /// The metric scale came from the vehicles' sizes (`output::calibrated_run_file`).
    AutomaticScale,
    /// The input stopped early or had damaged data (`pipeline::run_pipeline_on`).
    InputDamaged,
    /// The tracks' median speed is atypical or impossible for road traffic
    /// (`plausible::check_speeds`).
    MedianSpeed,
    /// Some tracks are faster than any road vehicle (`plausible::check_speeds`).
    ImpossibleSpeeds,
    /// The camera's height above the road is atypical or impossible
    /// (`plausible::check_camera`).
    CameraHeight,
    /// The camera's tilt is impossible (`plausible::check_camera`).
    Tilt,
    /// Anything else.
    Other,
}

/// Which kind of warning `text` is (the texts of `aggregate::Aggregated::warnings`,
/// `output::calibrated_run_file` and the pipeline's input warnings).
pub fn warning_kind(text: &str) -> WarningKind {
    let has = |s: &str| text.contains(s);
    if has("focal length is assumed") {
        WarningKind::AssumedFocal
    } else if has("lies outside the given range") {
        WarningKind::FocalOutsideRange
    } else if has("VP1 rests on the network's VP1 rays alone") {
        WarningKind::WeakVp1
    } else if has("curved-road fit gives a focal length") {
        WarningKind::CurvedFitDisagrees
    } else if has("edges across the vehicles are parallel") {
        WarningKind::ParallelEdges
    } else if text.starts_with(vpcal_formats::calib::AUTOMATIC_SCALE_WARNING)
        || has("metric scale is automatic")
    {
        WarningKind::AutomaticScale
    } else if has("the median speed of") {
        WarningKind::MedianSpeed
    } else if has("faster than any road vehicle") {
        WarningKind::ImpossibleSpeeds
    } else if has("the camera comes out") && has("above the road") {
        WarningKind::CameraHeight
    } else if has("the camera comes out tilted") {
        WarningKind::Tilt
    } else if has("stopped reading after") || has("damaged") || has("could not be read") {
        WarningKind::InputDamaged
    } else {
        WarningKind::Other
    }
}

/// A warning of `kind` in plain words: a headline, and what to do about it.
pub fn explain_warning(kind: WarningKind) -> (&'static str, &'static str) {
    match kind {
        WarningKind::AssumedFocal => (
            "The focal length is assumed, not measured",
            "Nothing in the footage fixed the focal length, so the middle of the plausible range \
             was taken; distances and speeds carry its error. Give it with --focal PX when it is \
             known (the lens's focal length divided by the sensor's pixel pitch, from the \
             camera's data sheet), or the lens's range with --focal-range SHORT,LONG. Measuring \
             known lengths both along and across the road with `vpcal scale` (--points/--distance \
             and --lane-points/--lane-width) shows in their residuals whether the focal length \
             holds. More footage with vehicles seen from the side or front (whose edges across \
             them point to VP2) lets the edgelets measure it.",
        ),
        WarningKind::FocalOutsideRange => (
            "The measured focal length is outside the range you gave",
            "Check the --focal-range values (pixels, not millimetres: focal length / pixel \
             pitch), or give the focal length with --focal PX if it is known. Otherwise the \
             footage's evidence may be misleading: look at the overlay's grid and VP directions.",
        ),
        WarningKind::WeakVp1 => (
            "The road direction (VP1) is weakly supported",
            "VP1 rests only on the network's per-vehicle guesses, which scatter. Use longer \
             footage of moving traffic (at least a minute, every frame: --every 1) so that \
             vehicles form straight tracks; check in the overlay that the vehicles are detected \
             (white boxes), and try --detector motion or --tiles 2 for small vehicles.",
        ),
        WarningKind::CurvedFitDisagrees => (
            "The curved-road and straight-road fits disagree on the focal length",
            "The road was called curved but a straight fit of the same edges gives another focal \
             length; the interval spans both. Use footage of a straight stretch of road, or give \
             the focal length with --focal PX or --focal-range SHORT,LONG.",
        ),
        WarningKind::ParallelEdges => (
            "The view looks nearly straight down: the focal length cannot be observed",
            "Edges across the vehicles are parallel in the image, so VP2 (and with it the focal \
             length) cannot be placed. Give the focal length with --focal PX or the lens's range \
             with --focal-range SHORT,LONG.",
        ),
        WarningKind::AutomaticScale => (
            "The metric scale is automatic (from the vehicles' sizes)",
            "Distances and speeds assume the vehicles are typical cars, and inherit the focal \
             length's error. For measurements give a known road distance: --scale-points \
             X1,Y1,X2,Y2 --scale-distance M when calibrating, or `vpcal scale CALIB --points \
             X1,Y1,X2,Y2 --distance M` (lane widths with --lane-points/--lane-width) afterwards.",
        ),
        WarningKind::InputDamaged => (
            "The input stopped early or has damaged data",
            "Only the frames read before the problem were used. Check the file (e.g. `ffmpeg -v \
             error -i FILE -f null -`), re-encode or re-download it, or start after the damage \
             with --start.",
        ),
        WarningKind::MedianSpeed => (
            "The vehicles' speeds are implausible for road traffic",
            "Speeds scale with the frame rate and the metric scale. If the clip is a time-lapse \
             or its container states a wrong rate, give the true rate with --fps; give a known \
             road distance (--scale-points/--scale-distance, or `vpcal scale`) instead of the \
             automatic scale; check the focal length (--focal PX).",
        ),
        WarningKind::ImpossibleSpeeds => (
            "Some tracks are faster than any road vehicle",
            "Those tracks are left out of the BrnoCompSpeed cars. Usually a box jumped between \
             vehicles; if many tracks are affected, check the frame rate (--fps) and the metric \
             scale (a known distance with `vpcal scale`).",
        ),
        WarningKind::CameraHeight => (
            "The camera's height above the road is implausible",
            "The height follows from the metric scale and the focal length. Give a known road \
             distance (`vpcal scale`, or --scale-points/--scale-distance) and, when known, the \
             focal length (--focal PX or --focal-range SHORT,LONG).",
        ),
        WarningKind::Tilt => (
            "The camera's tilt is impossible: the horizon is misplaced",
            "Use longer footage of moving traffic, so that straight vehicle tracks place VP1 and \
             the horizon; check in the picture that the yellow horizon lies where the road \
             meets the sky.",
        ),
        WarningKind::Other => (
            "Note",
            "See the calibration file's summary and evidence for details.",
        ),
    }
}

// -- plots ---------------------------------------------------------------------------------

/// An x position on a log axis over `[lo, hi]` mapped to `[x0, x1]`.
fn log_x(v: f64, lo: f64, hi: f64, x0: f64, x1: f64) -> f64 {
    x0 + (v.ln() - lo.ln()) / (hi.ln() - lo.ln()) * (x1 - x0)
}

/// One value marked on the focal plot, with its label.
struct Marker {
    label: String,
    value: f64,
    colour: &'static str,
}

/// The focal-length plot: a log axis, the plausible range as a grey band, the 68 % interval
/// as a blue band, the value as a red line, and the other estimates as dots in rows below.
fn focal_svg(
    f: Option<f64>,
    interval: Option<[f64; 2]>,
    range: [f64; 2],
    range_label: (&str, &str),
    markers: &[Marker],
) -> String {
    let (w, x0, x1) = (760.0, 24.0, 736.0);
    let mut all: Vec<f64> = vec![range[0], range[1]];
    all.extend(f);
    all.extend(interval.into_iter().flatten());
    all.extend(markers.iter().map(|m| m.value));
    let all: Vec<f64> = all
        .into_iter()
        .filter(|v| v.is_finite() && *v > 0.0)
        .collect();
    let lo = all.iter().copied().fold(f64::INFINITY, f64::min) / 1.3;
    let hi = all.iter().copied().fold(0.0, f64::max) * 1.3;
    if !(lo.is_finite() && hi > lo) {
        return String::new();
    }
    let x = |v: f64| log_x(v, lo, hi, x0, x1);
    let (band_top, band_bottom, axis_y) = (34.0, 78.0, 82.0);
    let row_h = 17.0;
    let rows_top = 112.0;
    let h = rows_top + row_h * markers.len() as f64 + 6.0;
    let mut s = String::new();
    let _ = write!(
        s,
        "<svg class=\"plot\" viewBox=\"0 0 {w} {h}\" \
         width=\"{w}\" height=\"{h}\" role=\"img\" aria-label=\"focal length on a log axis\">"
    );
    // The plausible range.
    let (ra, rb) = (x(range[0]), x(range[1]));
    let _ = write!(
        s,
        "<rect x=\"{ra:.1}\" y=\"{band_top}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"#e4e4e4\"></rect>",
        rb - ra,
        band_bottom - band_top
    );
    let _ = write!(
        s,
        "<text x=\"{ra:.1}\" y=\"{:.1}\" class=\"small\">{}</text>\
         <text x=\"{rb:.1}\" y=\"{:.1}\" class=\"small\" text-anchor=\"end\">{}</text>",
        band_top - 4.0,
        escape(range_label.0),
        band_top - 4.0,
        escape(range_label.1)
    );
    if let Some([a, b]) = interval.filter(|[a, b]| a.is_finite() && b.is_finite() && b > a) {
        let (xa, xb) = (x(a), x(b));
        let _ = write!(
            s,
            "<rect x=\"{xa:.1}\" y=\"{:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"#3b7dd8\" \
             fill-opacity=\"0.45\"></rect>",
            band_top + 6.0,
            (xb - xa).max(1.0),
            band_bottom - band_top - 12.0
        );
        // Beside the value's line, not under it.
        let (lx, anchor) = match f.map(x) {
            Some(xf) if xf - x0 > 120.0 => (xf - 6.0, "end"),
            Some(xf) => (xf + 6.0, "start"),
            None => ((xa + xb) / 2.0, "middle"),
        };
        let _ = write!(
            s,
            "<text x=\"{lx:.1}\" y=\"{:.1}\" class=\"small\" text-anchor=\"{anchor}\" \
             fill=\"#1d4f91\">68% {:.0}-{:.0} px</text>",
            band_bottom - 9.0,
            a,
            b
        );
    }
    if let Some(f) = f.filter(|f| f.is_finite() && *f > 0.0) {
        let xf = x(f);
        let _ = write!(
            s,
            "<line x1=\"{xf:.1}\" y1=\"{:.1}\" x2=\"{xf:.1}\" y2=\"{:.1}\" stroke=\"#c0261b\" \
             stroke-width=\"3\"></line>",
            band_top - 2.0,
            band_bottom + 2.0
        );
        let anchor = if xf > x1 - 80.0 { "end" } else { "start" };
        let dx = if anchor == "end" { -5.0 } else { 5.0 };
        let _ = write!(
            s,
            "<text x=\"{:.1}\" y=\"{:.1}\" class=\"label\" text-anchor=\"{anchor}\" \
             fill=\"#c0261b\">f = {f:.0} px</text>",
            xf + dx,
            band_top + 16.0
        );
    }
    // The axis with 1-2-5 ticks.
    let _ = write!(
        s,
        "<line x1=\"{x0}\" y1=\"{axis_y}\" x2=\"{x1}\" y2=\"{axis_y}\" stroke=\"#333\"></line>"
    );
    let mut decade = 10f64.powf(lo.log10().floor());
    while decade <= hi {
        for m in [1.0, 2.0, 5.0] {
            let v = decade * m;
            if v < lo || v > hi {
                continue;
            }
            let xv = x(v);
            let _ = write!(
                s,
                "<line x1=\"{xv:.1}\" y1=\"{axis_y}\" x2=\"{xv:.1}\" y2=\"{:.1}\" stroke=\"#333\"></line>\
                 <text x=\"{xv:.1}\" y=\"{:.1}\" class=\"small\" text-anchor=\"middle\">{v}</text>",
                axis_y + 5.0,
                axis_y + 17.0
            );
        }
        decade *= 10.0;
    }
    let _ = write!(
        s,
        "<text x=\"{x1}\" y=\"{:.1}\" class=\"small\" text-anchor=\"end\">focal length, px \
         (log scale)</text>",
        axis_y + 30.0
    );
    for (i, m) in markers.iter().enumerate() {
        let y = rows_top + row_h * i as f64 + row_h / 2.0;
        let xm = x(m.value);
        let _ = write!(
            s,
            "<line x1=\"{x0}\" y1=\"{y:.1}\" x2=\"{x1}\" y2=\"{y:.1}\" stroke=\"#eee\"></line>\
             <circle cx=\"{xm:.1}\" cy=\"{y:.1}\" r=\"4.5\" fill=\"{}\"></circle>",
            m.colour
        );
        let (anchor, dx) = if xm > (x0 + x1) / 2.0 {
            ("end", -8.0)
        } else {
            ("start", 8.0)
        };
        let _ = write!(
            s,
            "<text x=\"{:.1}\" y=\"{:.1}\" class=\"small\" text-anchor=\"{anchor}\">{}: {:.0} px</text>",
            xm + dx,
            y + 4.0,
            escape(&m.label),
            m.value
        );
    }
    s.push_str("</svg>");
    s
}

/// The speed histogram: bars of a round width, stacked by direction, and the median.
fn speed_svg(tracks: &[VehicleTrack]) -> String {
    let rows: Vec<(f64, Option<bool>)> = tracks
        .iter()
        .filter_map(|t| t.speed.map(|s| (s.kmh, t.towards_vp1)))
        .filter(|(v, _)| v.is_finite())
        .collect();
    if rows.is_empty() {
        return String::new();
    }
    let min = rows.iter().map(|r| r.0).fold(f64::INFINITY, f64::min);
    let max = rows.iter().map(|r| r.0).fold(f64::NEG_INFINITY, f64::max);
    // Bins from the spread of the bulk (10th-90th percentile), so that one outlier does not
    // make them coarse; at most 40 bins, the last one holding everything beyond.
    let speeds: Vec<f64> = rows.iter().map(|r| r.0).collect();
    let spread = percentile(&speeds, 90.0) - percentile(&speeds, 10.0);
    let bin = nice_step((spread / 8.0).max((max - min) / 40.0).max(1.0));
    let start = (min / bin).floor() * bin;
    let nbins = (((max - start) / bin).floor() as usize + 1).clamp(1, 40);
    let overflow = start + nbins as f64 * bin <= max;
    // Per bin: towards VP1, from VP1, unknown.
    let mut counts = vec![[0usize; 3]; nbins];
    for (v, dir) in &rows {
        let k = (((v - start) / bin).floor() as usize).min(nbins - 1);
        let c = match dir {
            Some(true) => 0,
            Some(false) => 1,
            None => 2,
        };
        counts[k][c] += 1;
    }
    let top = counts
        .iter()
        .map(|c| c.iter().sum::<usize>())
        .max()
        .unwrap_or(1)
        .max(1);
    let (w, h) = (760.0, 250.0);
    let (x0, x1, y0, y1) = (48.0, 740.0, 28.0, 200.0);
    let bw = (x1 - x0) / nbins as f64;
    let y = |n: f64| y1 - n / top as f64 * (y1 - y0);
    let colours = ["#d9480f", "#1971c2", "#868e96"];
    let mut s = String::new();
    let _ = write!(
        s,
        "<svg class=\"plot\" viewBox=\"0 0 {w} {h}\" \
         width=\"{w}\" height=\"{h}\" role=\"img\" aria-label=\"histogram of track speeds\">"
    );
    for (k, c) in counts.iter().enumerate() {
        let mut base = 0usize;
        for (j, &n) in c.iter().enumerate() {
            if n == 0 {
                continue;
            }
            let (ya, yb) = (y((base + n) as f64), y(base as f64));
            let _ = write!(
                s,
                "<rect x=\"{:.1}\" y=\"{ya:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"{}\"></rect>",
                x0 + k as f64 * bw + 1.0,
                (bw - 2.0).max(1.0),
                yb - ya,
                colours[j]
            );
            base += n;
        }
    }
    // Axes.
    let _ = write!(
        s,
        "<line x1=\"{x0}\" y1=\"{y1}\" x2=\"{x1}\" y2=\"{y1}\" stroke=\"#333\"></line>\
         <line x1=\"{x0}\" y1=\"{y0}\" x2=\"{x0}\" y2=\"{y1}\" stroke=\"#333\"></line>"
    );
    let label_every = (nbins / 12).max(1);
    for k in (0..=nbins).step_by(label_every) {
        if overflow && k == nbins {
            continue;
        }
        let xv = x0 + k as f64 * bw;
        let v = start + k as f64 * bin;
        let _ = write!(
            s,
            "<line x1=\"{xv:.1}\" y1=\"{y1}\" x2=\"{xv:.1}\" y2=\"{:.1}\" stroke=\"#333\"></line>\
             <text x=\"{xv:.1}\" y=\"{:.1}\" class=\"small\" text-anchor=\"middle\">{}</text>",
            y1 + 5.0,
            y1 + 18.0,
            num(Some(v), if bin < 1.0 { 1 } else { 0 })
        );
    }
    let ystep = nice_step(top as f64 / 5.0).max(1.0);
    let mut n = 0.0;
    while n <= top as f64 + 1e-9 {
        let yv = y(n);
        let _ = write!(
            s,
            "<line x1=\"{:.1}\" y1=\"{yv:.1}\" x2=\"{x0}\" y2=\"{yv:.1}\" stroke=\"#333\"></line>\
             <text x=\"{:.1}\" y=\"{:.1}\" class=\"small\" text-anchor=\"end\">{n:.0}</text>",
            x0 - 5.0,
            x0 - 8.0,
            yv + 4.0
        );
        n += ystep;
    }
    let _ = write!(
        s,
        "<text x=\"{:.1}\" y=\"{:.1}\" class=\"small\" text-anchor=\"middle\">speed, km/h (bins \
         of {} km/h{})</text>\
         <text x=\"14\" y=\"{:.1}\" class=\"small\" text-anchor=\"middle\" \
         transform=\"rotate(-90 14 {:.1})\">tracks</text>",
        (x0 + x1) / 2.0,
        y1 + 36.0,
        num(Some(bin), if bin < 1.0 { 1 } else { 0 }),
        if overflow {
            format!(
                "; the last bar holds every speed from {} up to {max:.0}",
                num(Some(start + (nbins - 1) as f64 * bin), 0)
            )
        } else {
            String::new()
        },
        (y0 + y1) / 2.0,
        (y0 + y1) / 2.0
    );
    if let Some(m) = vpcal_geom::solve::median(&speeds) {
        let xm = x0 + (m - start) / bin * bw;
        let _ = write!(
            s,
            "<line x1=\"{xm:.1}\" y1=\"{:.1}\" x2=\"{xm:.1}\" y2=\"{y1}\" stroke=\"#000\" \
             stroke-dasharray=\"5 4\"></line>\
             <text x=\"{:.1}\" y=\"{:.1}\" class=\"small\">median {m:.1} km/h</text>",
            y0 - 10.0,
            xm + 4.0,
            y0 - 12.0
        );
    }
    // Key.
    let mut kx = x1 - 330.0;
    for (label, c) in [
        ("towards VP1", colours[0]),
        ("from VP1", colours[1]),
        ("direction unknown", colours[2]),
    ] {
        let _ = write!(
            s,
            "<rect x=\"{kx:.1}\" y=\"4\" width=\"12\" height=\"12\" fill=\"{c}\"></rect>\
             <text x=\"{:.1}\" y=\"14\" class=\"small\">{label}</text>",
            kx + 16.0
        );
        kx += 110.0;
    }
    s.push_str("</svg>");
    s
}

// -- sections ------------------------------------------------------------------------------

const STYLE: &str = "body{font-family:system-ui,-apple-system,'Segoe UI',Roboto,sans-serif;\
margin:0 auto;max-width:1200px;padding:16px 24px;color:#1f2328;background:#fff;line-height:1.45}\
h1{font-size:1.6em;margin:0.2em 0}h2{font-size:1.25em;margin-top:1.6em;border-bottom:1px solid #d0d7de;\
padding-bottom:4px}.sub{color:#59636e;margin-top:0}\
.banner{padding:10px 14px;border-radius:6px;margin:12px 0;font-size:1.05em}\
.ok{background:#dafbe1;border:1px solid #4ac26b}.fail{background:#ffebe9;border:1px solid #ff8182}\
.assumed{background:#fff8c5;border:1px solid #d4a72c}\
table{border-collapse:collapse;margin:8px 0}td,th{border:1px solid #d0d7de;padding:3px 8px;\
text-align:left;vertical-align:top}th{background:#f6f8fa;font-weight:600}td.n{text-align:right;\
font-variant-numeric:tabular-nums}\
figure{margin:8px 0}figure img{max-width:100%;height:auto;border:1px solid #d0d7de}\
figcaption{color:#59636e;font-size:0.92em;margin-top:4px}\
ul.warnings{padding-left:0;list-style:none}ul.warnings li{border-left:4px solid #d4a72c;\
background:#fff8c5;padding:8px 12px;margin:8px 0}ul.warnings li p{margin:4px 0}\
.what{color:#3d444d}.quote{font-size:0.9em;color:#59636e}\
svg.plot{max-width:100%;height:auto;font-family:inherit}svg .small{font-size:12px;fill:#333}\
svg .label{font-size:14px;font-weight:600}\
.swatch{display:inline-block;width:14px;height:4px;vertical-align:middle;margin-right:4px}\
details{margin:8px 0}summary{cursor:pointer;color:#0969da}code{background:#f6f8fa;padding:0 3px}";

/// Rows of a two-column table (`key`, already escaped HTML value).
fn table(rows: &[(&str, String)]) -> String {
    let mut s = String::from("<table>");
    for (k, v) in rows {
        let _ = write!(s, "<tr><th>{}</th><td>{v}</td></tr>", escape(k));
    }
    s.push_str("</table>");
    s
}

/// The file's warnings, then the run's that it does not hold (a calibrate run's warnings
/// about its input are in its file too): each once.
fn all_warnings<'a>(file: &'a CalibrationFile, run_warnings: &'a [String]) -> Vec<&'a String> {
    file.warnings
        .iter()
        .chain(run_warnings.iter().filter(|w| !file.warnings.contains(w)))
        .collect()
}

/// The warnings section: every warning in plain words with what to do about it.
fn warnings_section(file: &CalibrationFile, run_warnings: &[String]) -> String {
    let all = all_warnings(file, run_warnings);
    if all.is_empty() {
        return "<section id=\"warnings\"><h2>Warnings</h2><p>None: the calibration carries no \
                warning.</p></section>"
            .to_string();
    }
    let mut s = format!(
        "<section id=\"warnings\"><h2>Warnings ({})</h2><ul class=\"warnings\">",
        all.len()
    );
    for w in all {
        let (title, remedy) = explain_warning(warning_kind(w));
        let _ = write!(
            s,
            "<li><p><strong>{}</strong></p><p class=\"quote\">{}</p><p class=\"what\">\
             <strong>What to do:</strong> {}</p></li>",
            escape(title),
            escape(w),
            escape(remedy)
        );
    }
    s.push_str("</ul></section>");
    s
}

/// In plain words, where a focal length of `source` came from.
fn focal_source_words(source: &str) -> &'static str {
    match source {
        "edgelets" => "measured: edges across the vehicles (edgelets) placed VP2",
        "network" => "measured: the network's VP2 points and rays agreed",
        "network_rays" => "measured: the network's VP2 rays, weighed against the plausible range",
        "verticals" => "measured: the scene's vertical lines (poles, posts, walls) placed VP3",
        "prior" => "ASSUMED: the evidence weighed less than the plausible range; its middle",
        "given" => "given by the user (--focal)",
        "per_vehicle_median" => "the median of the per-vehicle focal lengths (reference method)",
        _ => "(unknown source)",
    }
}

fn focal_section(file: &CalibrationFile) -> String {
    let width = file.image_size[0].max(1);
    let f = file.focal_px.filter(|f| f.is_finite() && *f > 0.0);
    let source = file.focal_source.as_deref().unwrap_or("unknown");
    let given_range = setting_pair(file, "focal_range");
    let (range, range_name, range_label) = match given_range {
        Some(r) => (
            r,
            format!("the given range {:.0}-{:.0} px", r[0], r[1]),
            ("given range: short".to_string(), "long".to_string()),
        ),
        None => {
            let [a, b] = focal_prior_range_widths(None).map(|r| r * f64::from(width));
            (
                [a, b],
                format!(
                    "the focal lengths of traffic cameras, {}-{}° horizontal views ({:.0}-{:.0} \
                     px at {} px width)",
                    TRAFFIC_FOV_DEG[1], TRAFFIC_FOV_DEG[0], a, b, width
                ),
                (
                    format!("{}° view", TRAFFIC_FOV_DEG[1]),
                    format!("{}° view", TRAFFIC_FOV_DEG[0]),
                ),
            )
        }
    };
    let interval = file.focal_interval_px;
    let assumed = source == "prior";
    let mut markers: Vec<Marker> = Vec::new();
    let mut rows: Vec<(&str, String)> = Vec::new();
    // The estimates behind the focal length (evidence and bootstrap), used or not.
    let edgelet = ev_f64(file, "edgelet_focal_px");
    if let Some(v) = edgelet {
        // On a curved road the focal length comes from the curved fit; this is the straight
        // one's.
        let curved = ev_bool(file, "curved_fit");
        let used = ev_bool(file, "focal_from_edgelets") && !curved;
        markers.push(Marker {
            label: format!(
                "{}edgelet fit{}",
                if curved { "straight-road " } else { "" },
                if used { " (used)" } else { "" }
            ),
            value: v,
            colour: "#2b8a3e",
        });
        rows.push((
            if curved {
                "straight-road edgelet fit (edges across the vehicles)"
            } else {
                "edgelet fit (edges across the vehicles)"
            },
            format!(
                "{} px{}",
                num(Some(v), 0),
                if used { ", used" } else { ", not used" }
            ),
        ));
    }
    if let Some(v) = ev_f64(file, "rays_focal_px") {
        markers.push(Marker {
            label: "network's VP2 rays, own fit".to_string(),
            value: v,
            colour: "#7048e8",
        });
        rows.push((
            "network's VP2 rays, their own fit",
            format!(
                "{} px (scatter {}°, taken as ±{}° off)",
                num(Some(v), 0),
                num(ev_f64(file, "rays_scatter_deg"), 1),
                num(ev_f64(file, "rays_vp2_sd_deg"), 1)
            ),
        ));
    }
    if let Some(p) = ev(file, "rays_focal_posterior_p16_p50_p84_px").and_then(Value::as_array) {
        let vals: Vec<f64> = p.iter().filter_map(Value::as_f64).collect();
        if let [lo, med, hi] = vals[..] {
            let used = ev_bool(file, "focal_from_rays");
            markers.push(Marker {
                label: format!(
                    "VP2 rays within the range{}",
                    if used { " (used)" } else { "" }
                ),
                value: med,
                colour: "#ae3ec9",
            });
            rows.push((
                "network's VP2 rays within the range (posterior)",
                format!(
                    "{} px, 68% {}-{} px{}",
                    num(Some(med), 0),
                    num(Some(lo), 0),
                    num(Some(hi), 0),
                    if used { ", used" } else { ", not used" }
                ),
            ));
        }
    }
    // Each cue of the focal posterior: its own focal length, its interval with the prior
    // alone, its share of the evidence.
    for c in ev(file, "focal_cues")
        .and_then(Value::as_array)
        .into_iter()
        .flatten()
    {
        let interval: Vec<f64> = c["interval_px"]
            .as_array()
            .map(|a| a.iter().filter_map(Value::as_f64).collect())
            .unwrap_or_default();
        let (lo, hi) = match interval[..] {
            [lo, hi] => (Some(lo), Some(hi)),
            _ => (None, None),
        };
        rows.push((
            "cue of the focal posterior",
            format!(
                "{}: {} px; with the prior alone 68% {}-{} px; {}",
                c["source"].as_str().unwrap_or("?"),
                num(c["focal_px"].as_f64(), 0),
                num(lo, 0),
                num(hi, 0),
                if c["used"].as_bool() == Some(true) {
                    format!(
                        "{} % of the evidence",
                        num(c["share"].as_f64().map(|v| 100.0 * v), 0)
                    )
                } else {
                    format!(
                        "contradicts {}: not used",
                        crate::aggregate::contradicted_words(c["contradicts"].as_str())
                    )
                }
            ),
        ));
    }
    if let Some(v) = ev_f64(file, "vp2_rays_only_focal_px").filter(|v| v.is_finite() && *v > 0.0) {
        markers.push(Marker {
            label: "VP2 rays alone (bootstrap)".to_string(),
            value: v,
            colour: "#868e96",
        });
    }
    if let (Some(c), Some(b)) = (
        &file.confidence,
        ev(file, "bootstrap_focal_p16_p84_px").and_then(Value::as_array),
    ) {
        let b: Vec<f64> = b.iter().filter_map(Value::as_f64).collect();
        if let [lo, hi] = b[..] {
            rows.push((
                "bootstrap",
                format!(
                    "16th-84th percentile {}-{} px over {} resamples; VP2 rays alone {} px",
                    num(Some(lo), 0),
                    num(Some(hi), 0),
                    c.resamples,
                    num(ev_f64(file, "vp2_rays_only_focal_px"), 0)
                ),
            ));
        }
    }
    let mut s = String::from("<section id=\"focal\"><h2>Focal length</h2>");
    match f {
        Some(f) => {
            let _ = write!(
                s,
                "<p class=\"banner {}\"><strong>{:.0} px</strong> (a {:.1}° horizontal view) — \
                 source <code>{}</code>: {}.{}</p>",
                if assumed { "assumed" } else { "ok" },
                f,
                fov_deg(f, width),
                escape(source),
                escape(focal_source_words(source)),
                match interval {
                    Some([a, b]) if b > a => format!(
                        " 68% interval {a:.0}-{b:.0} px{}.",
                        if assumed {
                            " (the middle 68 % of the focal lengths traffic cameras have, not a \
                             measurement)"
                        } else {
                            ""
                        }
                    ),
                    _ => String::new(),
                }
            );
        }
        None => s.push_str("<p>No focal length: the run found no camera.</p>"),
    }
    s.push_str(&focal_svg(
        f,
        interval,
        range,
        (&range_label.0, &range_label.1),
        &markers,
    ));
    let _ = write!(
        s,
        "<p class=\"what\">Grey band: {}. Blue band: the 68 % interval. Red line: the focal \
         length. Dots: the estimates the evidence gave.</p>",
        escape(&range_name)
    );
    let mut all_rows: Vec<(&str, String)> = vec![
        (
            "focal length",
            format!("{} px ({})", num(f, 1), escape(source)),
        ),
        (
            "68% interval",
            match interval {
                Some([a, b]) => format!("{}-{} px", num(Some(a), 0), num(Some(b), 0)),
                None => "–".to_string(),
            },
        ),
    ];
    all_rows.extend(rows.into_iter().map(|(k, v)| (k, escape(&v))));
    s.push_str(&table(&all_rows));
    s.push_str("</section>");
    s
}

/// The horizon's y at column `x`, from the file's line.
fn horizon_y(file: &CalibrationFile, x: f64) -> Option<f64> {
    let [a, b, c] = file.horizon.as_ref()?.line;
    (b.abs() > 1e-12).then(|| -(a * x + c) / b)
}

fn horizon_section(file: &CalibrationFile) -> String {
    let [w, h] = file.image_size.map(f64::from);
    let mut rows: Vec<(&str, String)> = Vec::new();
    rows.push((
        "roll (horizon angle)",
        format!("{}°", num(file.roll_deg, 2)),
    ));
    rows.push((
        "tilt (optical axis below the horizon)",
        format!("{}°", num(file.tilt_deg, 2)),
    ));
    if let Some(c) = &file.confidence {
        rows.push((
            "horizon angle spread (bootstrap)",
            format!("±{}°", num(Some(c.horizon_angle_sd_deg), 2)),
        ));
    }
    let (yl, ym, yr) = (
        horizon_y(file, 0.0),
        horizon_y(file, w / 2.0),
        horizon_y(file, w),
    );
    let place = match (yl, yr, ym) {
        (Some(a), Some(b), Some(m)) if a < 0.0 && b < 0.0 => {
            format!("{:.0} px above the frame (at its middle column)", -m)
        }
        (Some(a), Some(b), Some(m)) if a > h && b > h => {
            format!("{:.0} px below the frame (at its middle column)", m - h)
        }
        (Some(_), Some(_), Some(_)) => "crosses the frame".to_string(),
        _ => "–".to_string(),
    };
    rows.push(("where", place));
    rows.push((
        "y at the left edge, middle, right edge",
        format!("{}, {}, {} px", num(yl, 1), num(ym, 1), num(yr, 1)),
    ));
    let pt = |p: Option<[f64; 2]>| match p {
        Some([x, y]) => format!("({}, {})", num(Some(x), 1), num(Some(y), 1)),
        None => "at infinity".to_string(),
    };
    rows.push(("VP1 (along the road)", pt(file.vp1)));
    rows.push(("VP2 (across the road)", pt(file.vp2)));
    rows.push(("VP3 (vertical)", pt(file.vp3)));
    rows.push(("principal point", pt(file.pp)));
    if ev_bool(file, "curved_fit") {
        rows.push((
            "roll from",
            format!(
                "the curved-road fit ({} vehicles' track tangents and edgelets)",
                ev_u64(file, "curved_vehicles").unwrap_or(0)
            ),
        ));
    } else if ev_bool(file, "roll_from_edgelets") {
        rows.push((
            "roll from",
            format!(
                "{} edgelets on {} vehicles",
                ev_u64(file, "edgelets").unwrap_or(0),
                ev_u64(file, "edgelet_vehicles").unwrap_or(0)
            ),
        ));
    } else if file.evidence.is_some() {
        let rays = format!(
            "the network's VP2 rays ({} vehicles)",
            ev_u64(file, "vp2_inliers").unwrap_or(0)
        );
        let from = match ev_f64(file, "rays_roll_own_deg") {
            Some(own) => format!("{rays}, their own {own:.2}° pulled towards level by its prior"),
            None => rays,
        };
        rows.push(("roll from", from));
    }
    let rows: Vec<(&str, String)> = rows.into_iter().map(|(k, v)| (k, escape(&v))).collect();
    format!(
        "<section id=\"horizon\"><h2>Horizon and vanishing points</h2>{}</section>",
        table(&rows)
    )
}

fn vp1_section(file: &CalibrationFile) -> String {
    let mut items: Vec<String> = Vec::new();
    let scatter = ev_f64(file, "vp1_ray_scatter_deg");
    let tracks = ev_u64(file, "track_lines").unwrap_or(0);
    if ev_bool(file, "vp1_from_tracks") {
        items.push(format!(
            "VP1 comes from {tracks} straight vehicle tracks (median angle between a track and \
             VP1: {}°).",
            num(ev_f64(file, "track_residual_deg"), 2)
        ));
    } else if ev_bool(file, "vp1_from_edgelets") {
        items.push(format!(
            "VP1 comes from {} edgelets along the vehicles ({tracks} straight vehicle tracks{}).",
            ev_u64(file, "vp1_edgelets").unwrap_or(0),
            if ev_bool(file, "road_curved") {
                ", not used: the road curves"
            } else {
                " were not enough"
            }
        ));
    } else if file.evidence.is_some() {
        items.push(format!(
            "VP1 comes from the network's per-vehicle VP1 rays ({} vehicles agree); {tracks} \
             straight vehicle tracks were found{}.",
            ev_u64(file, "vp1_inliers").unwrap_or(0),
            if ev_bool(file, "road_curved") {
                ", not used: the road curves"
            } else {
                ", too few"
            }
        ));
    }
    if let Some(s) = scatter {
        items.push(format!(
            "The network's VP1 rays scatter by a median {s:.1}° around VP1 (above 5° they are \
             weak evidence on their own)."
        ));
    }
    if ev_bool(file, "vp1_from_scene_lines") {
        items.push(format!(
            "The scene's lines along the road ({} edgelets of the background) moved VP1 by {} px.",
            ev_u64(file, "vp1_scene_edgelets").unwrap_or(0),
            num(ev_f64(file, "vp1_scene_shift_px"), 1)
        ));
    }
    if ev_bool(file, "road_curved") {
        items.push(format!(
            "The road curves: {} tracks bend alike{}.",
            ev_u64(file, "curved_tracks").unwrap_or(0),
            if ev_bool(file, "curved_fit") {
                format!(
                    "; horizon and focal length came from the track tangents and edgelets of {} \
                     vehicles",
                    ev_u64(file, "curved_vehicles").unwrap_or(0)
                )
            } else {
                String::new()
            }
        ));
    }
    if let Some(c) = &file.confidence {
        items.push(format!(
            "VP1 moves by {} px between bootstrap resamples (standard deviation).",
            num(Some(c.vp1_sd_px), 1)
        ));
    }
    if let (Some(a), Some(b)) = (ev_u64(file, "pairs_used"), ev_u64(file, "pairs_in")) {
        items.push(format!(
            "{a} of {b} vehicle records were used{}.",
            ev_f64(file, "effective_vehicles").map_or(String::new(), |e| format!(
                " (about {e:.0} independent vehicles)"
            ))
        ));
    }
    let mut s = String::from("<section id=\"vp1\"><h2>Evidence for VP1 (the road direction)</h2>");
    if items.is_empty() {
        s.push_str("<p>The calibration file records no evidence.</p>");
    } else {
        s.push_str("<ul>");
        for i in items {
            let _ = write!(s, "<li>{}</li>", escape(&i));
        }
        s.push_str("</ul>");
    }
    if let Some(Value::Object(m)) = &file.evidence {
        s.push_str("<details><summary>All evidence in the calibration file</summary><table>");
        for (k, v) in m {
            let _ = write!(
                s,
                "<tr><th>{}</th><td>{}</td></tr>",
                escape(k),
                escape(&v.to_string())
            );
        }
        s.push_str("</table></details>");
    }
    if let Some(summary) = &file.summary {
        let _ = write!(
            s,
            "<details><summary>The aggregation's summary</summary><p>{}</p></details>",
            escape(summary)
        );
    }
    s.push_str("</section>");
    s
}

fn scale_section(file: &CalibrationFile) -> String {
    let mut s = String::from("<section id=\"scale\"><h2>Metric scale</h2>");
    let Some(scale) = file.scale_m_per_unit.filter(|v| v.is_finite()) else {
        s.push_str(
            "<p>No metric scale: road points are in road units and tracks have no speeds. Give \
             a known road distance (<code>--scale-points X1,Y1,X2,Y2 --scale-distance M</code>, \
             or <code>vpcal scale</code>).</p></section>",
        );
        return s;
    };
    let source = match file.scale_source.as_deref() {
        Some("distance") => match &file.scale_reference {
            Some(r) => format!(
                "a known road distance: {} m between ({:.1}, {:.1}) and ({:.1}, {:.1})",
                r.distance_m, r.points[0][0], r.points[0][1], r.points[1][0], r.points[1][1]
            ),
            None => "known road lengths".to_string(),
        },
        Some("vehicles") => {
            "automatic: the vehicles' sizes, read as typical cars (not a measurement)".to_string()
        }
        Some(other) => other.to_string(),
        None => "not recorded".to_string(),
    };
    let mut rows: Vec<(&str, String)> = vec![
        ("scale", format!("{scale:.5} m per road unit")),
        ("source", source),
    ];
    if let Some([a, b]) = file.scale_interval_m_per_unit {
        rows.push((
            "68% interval",
            format!("{a:.5}-{b:.5} m per unit (±{:.0} %)", 50.0 * (b / a - 1.0)),
        ));
    }
    if file.camera_height_m.is_some() {
        let text = file
            .height_text()
            .unwrap_or_else(|| format!("{} m", num(None, 1)));
        rows.push(("camera height above the road", text));
    }
    if let Some(fs) = &file.scale_focal_sensitivity {
        rows.push(("with the focal length's interval", fs.describe()));
    }
    let rows: Vec<(&str, String)> = rows.into_iter().map(|(k, v)| (k, escape(&v))).collect();
    s.push_str(&table(&rows));
    s.push_str("</section>");
    s
}

fn percentile(v: &[f64], q: f64) -> f64 {
    vpcal_geom::solve::percentile(v.to_vec(), q)
}

fn tracks_section(file: &CalibrationFile, tracks: &[VehicleTrack], note: Option<&str>) -> String {
    let mut s = String::from("<section id=\"tracks\"><h2>Vehicle tracks and speeds</h2>");
    let (n, counts) = crate::output::tracks_counts(tracks);
    let (_, with_speed, _) = crate::tracks::summary(tracks);
    let _ = write!(s, "<p>{n} tracks{counts}.</p>");
    if let Some(note) = note {
        let _ = write!(s, "<p class=\"what\">{}</p>", escape(note));
    }
    if file.scale_m_per_unit.is_none() || with_speed == 0 {
        s.push_str("</section>");
        return s;
    }
    // Per lane and direction.
    let mut groups: Vec<(Option<usize>, Option<bool>)> = tracks
        .iter()
        .filter(|t| t.speed.is_some())
        .map(|t| (t.lane, t.towards_vp1))
        .collect();
    groups.sort();
    groups.dedup();
    s.push_str(
        "<table><tr><th>lane</th><th>direction</th><th>tracks</th><th>median km/h</th>\
         <th>10th-90th percentile km/h</th><th>median lateral position, m</th></tr>",
    );
    for (lane, dir) in groups {
        let of: Vec<&VehicleTrack> = tracks
            .iter()
            .filter(|t| t.speed.is_some() && t.lane == lane && t.towards_vp1 == dir)
            .collect();
        let speeds: Vec<f64> = of.iter().filter_map(|t| t.speed.map(|v| v.kmh)).collect();
        let lateral: Vec<f64> = of.iter().filter_map(|t| t.lateral_m).collect();
        let _ = write!(
            s,
            "<tr><td>{}</td><td>{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td>\
             <td class=\"n\">{}-{}</td><td class=\"n\">{}</td></tr>",
            lane.map_or("–".to_string(), |l| l.to_string()),
            match dir {
                Some(true) => "towards VP1",
                Some(false) => "from VP1",
                None => "–",
            },
            of.len(),
            num(vpcal_geom::solve::median(&speeds), 1),
            num(Some(percentile(&speeds, 10.0)), 1),
            num(Some(percentile(&speeds, 90.0)), 1),
            num(vpcal_geom::solve::median(&lateral), 1)
        );
    }
    s.push_str("</table>");
    s.push_str(&speed_svg(tracks));
    let _ =
        write!(
        s,
        "<p class=\"what\">Speeds rest on the metric scale ({}); a track's speed is the median \
         over windows of 10 points of its distance along the road against time.</p>",
        escape(file.scale_source.as_deref().unwrap_or("source not recorded"))
    );
    s.push_str(
        "<details><summary>Every track with a speed</summary><table><tr><th>id</th>\
         <th>first frame</th><th>points</th><th>seconds</th><th>km/h</th><th>±</th>\
         <th>one-line fit km/h</th><th>lane</th><th>direction</th></tr>",
    );
    for t in tracks.iter().filter(|t| t.speed.is_some()) {
        let Some(sp) = t.speed else { continue };
        let (first, last) = (t.points.first(), t.points.last());
        let _ = write!(
            s,
            "<tr><td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td>\
             <td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td>\
             <td class=\"n\">{}</td><td>{}</td><td>{}</td></tr>",
            t.id,
            first.map_or("–".to_string(), |p| p.frame.to_string()),
            t.points.len(),
            num(first.zip(last).map(|(a, b)| b.time_s - a.time_s), 1),
            num(Some(sp.kmh), 1),
            num(Some(sp.uncertainty_kmh), 1),
            num(Some(sp.fit_kmh), 1),
            t.lane.map_or("–".to_string(), |l| l.to_string()),
            match t.towards_vp1 {
                Some(true) => "towards VP1",
                Some(false) => "from VP1",
                None => "–",
            }
        );
    }
    s.push_str("</table></details></section>");
    s
}

fn run_section(file: &CalibrationFile) -> String {
    let i = &file.input;
    let mut rows: Vec<(&str, String)> = vec![
        ("input", i.path.clone()),
        ("kind", i.kind.clone().unwrap_or_default()),
        ("frame size", format!("{} x {} px", i.width, i.height)),
        (
            "frame rate",
            i.fps
                .map_or("–".to_string(), |f| format!("{f:.3} frames/s")),
        ),
        (
            "frames",
            format!(
                "{} processed{}",
                i.frames_processed,
                if i.frames_replayed > 0 {
                    format!(
                        ", {} of them again after the detector's warm-up",
                        i.frames_replayed
                    )
                } else {
                    String::new()
                }
            ),
        ),
        (
            "vehicle boxes",
            format!(
                "{} detected, {} kept (dropped: {} low score, {} static, {} over the per-frame \
                 limit, {} outside the frame, {} seen before)",
                i.detections,
                i.vehicle_boxes,
                i.dropped.low_score,
                i.dropped.r#static,
                i.dropped.over_limit,
                i.dropped.outside_frame,
                i.dropped.seen_before
            ),
        ),
        ("run time", format!("{:.1} s", i.seconds)),
        ("vpcal", file.vpcal_version.clone()),
    ];
    for (k, v) in &file.settings {
        match v {
            Value::Null => {}
            Value::String(text) => rows.push((k.as_str(), text.clone())),
            v => rows.push((k.as_str(), v.to_string())),
        }
    }
    let rows: Vec<(&str, String)> = rows.into_iter().map(|(k, v)| (k, escape(&v))).collect();
    format!(
        "<section id=\"run\"><h2>The run</h2>{}</section>",
        table(&rows)
    )
}

/// The overlay section: the picture and what its colours mean.
fn overlay_section(png: Option<&[u8]>, width: u32, calibrated: bool) -> String {
    let mut s = String::from("<section id=\"overlay\"><h2>Picture</h2>");
    match png {
        Some(bytes) => {
            // Small frames are shown larger (the browser scales the pixels).
            let shown = width.clamp(640, 1150);
            let _ = write!(
                s,
                "<figure><img src=\"data:image/png;base64,{}\" width=\"{shown}\" alt=\"{}\">\
                 <figcaption>",
                base64(bytes),
                if calibrated {
                    "the calibration drawn on a frame of the input"
                } else {
                    "the vehicle boxes found, on a frame of the input"
                }
            );
            if calibrated {
                s.push_str(
                    "<span class=\"swatch\" style=\"background:#ffdc00\"></span>horizon \
                     <span class=\"swatch\" style=\"background:#00dcff\"></span>road grid \
                     (spacing in the picture's legend) \
                     <span class=\"swatch\" style=\"background:#ff2828\"></span>towards VP1 \
                     <span class=\"swatch\" style=\"background:#28e628\"></span>towards VP2 \
                     <span class=\"swatch\" style=\"background:#ff8c00\"></span>tracks \
                     <span class=\"swatch\" style=\"background:#aaaaaa\"></span>vehicle boxes \
                     (white). The grid should lie flat on the road with its lines along the \
                     lanes; red lines should follow the road.",
                );
            } else {
                s.push_str("Vehicle boxes (white) and the network's VP directions (red, green).");
            }
            s.push_str("</figcaption></figure>");
        }
        None => s.push_str("<p>No picture was available for this report.</p>"),
    }
    s.push_str("</section>");
    s
}

/// [`render`] with the run's other notes.
pub fn render_with(file: &CalibrationFile, input: &ReportInput<'_>) -> String {
    let calibrated = file.status.has_camera();
    let name = input_name(file);
    let mut s = String::with_capacity(4096 + input.overlay_png.map_or(0, |b| b.len() * 4 / 3 + 16));
    let _ = write!(
        s,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\
         <title>vpcal report: {}</title><style>{STYLE}</style></head><body>",
        escape(&name)
    );
    let _ =
        write!(
        s,
        "<header><h1>Camera calibration: {}</h1><p class=\"sub\">{} · {} x {} px · {} frame{} · \
         vpcal {}</p></header>",
        escape(&name),
        escape(&file.input.path),
        file.image_size[0],
        file.image_size[1],
        file.input.frames_processed,
        if file.input.frames_processed == 1 { "" } else { "s" },
        escape(&file.vpcal_version)
    );
    if calibrated {
        let assumed = file.focal_source.as_deref() == Some("prior");
        let warnings = all_warnings(file, input.run_warnings).len();
        let (class, status) = match file.status {
            Status::Calibrated if assumed => ("assumed", "Calibrated"),
            Status::Calibrated => ("ok", "Calibrated"),
            Status::Rough => (
                "assumed",
                "Calibrated, but ROUGH (a result is atypical of traffic cameras or traffic)",
            ),
            _ => (
                "fail",
                "UNRELIABLE (a result is impossible for a traffic camera or road traffic: do \
                 not measure with it)",
            ),
        };
        let _ = write!(
            s,
            "<p class=\"banner {class}\"><strong>{status}</strong>: focal length {} px ({}{}), \
             roll {}°, tilt {}°{}; {} warning{}.</p>",
            num(file.focal_px, 0),
            escape(file.focal_source.as_deref().unwrap_or("unknown source")),
            if assumed { ", ASSUMED" } else { "" },
            num(file.roll_deg, 2),
            num(file.tilt_deg, 2),
            match (file.scale_m_per_unit, file.scale_source.as_deref()) {
                (Some(m), src) => format!(
                    ", scale {m:.4} m per unit ({})",
                    escape(src.unwrap_or("source not recorded"))
                ),
                (None, _) => ", no metric scale".to_string(),
            },
            warnings,
            if warnings == 1 { "" } else { "s" }
        );
    } else {
        let _ = write!(
            s,
            "<div class=\"banner fail\"><p><strong>Not calibrated</strong> (status \
             not_enough_evidence): {}</p><p><strong>What to do:</strong> {}</p></div>",
            escape(file.reason.as_deref().unwrap_or("no reason recorded")),
            escape(
                "look at the picture: are the vehicles found (white boxes)? Use longer footage \
                 with moving vehicles (every frame: --every 1), try another detector (--detector \
                 motion for a fixed camera with moving traffic, --tiles 2 or 3 for small \
                 vehicles in large frames), or a lower --min-score."
            )
        );
    }
    s.push_str(&warnings_section(file, input.run_warnings));
    s.push_str(&overlay_section(
        input.overlay_png,
        file.image_size[0],
        calibrated,
    ));
    if calibrated {
        s.push_str(&focal_section(file));
        s.push_str(&horizon_section(file));
        s.push_str(&vp1_section(file));
        s.push_str(&scale_section(file));
    }
    if let Some(tracks) = input.tracks {
        s.push_str(&tracks_section(file, tracks, input.tracks_note));
    }
    s.push_str(&run_section(file));
    s.push_str(
        "<footer><p class=\"sub\">Written by vpcal calibrate --report; this page is \
         self-contained (no network access).</p></footer></body></html>\n",
    );
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc_4648() {
        // RFC 4648 section 10.
        for (raw, enc) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(raw.as_bytes()), enc, "{raw}");
        }
        assert_eq!(base64(&[0xff, 0xfe, 0xfd]), "//79");
    }

    #[test]
    fn escaping_covers_markup() {
        assert_eq!(
            escape("<a href=\"x\">'&'</a>"),
            "&lt;a href=&quot;x&quot;&gt;&#39;&amp;&#39;&lt;/a&gt;"
        );
    }

    #[test]
    fn warnings_have_remedies() {
        assert_eq!(
            warning_kind("clip.avi: stopped reading after 12 frames: x"),
            WarningKind::InputDamaged
        );
        assert_eq!(warning_kind("something new"), WarningKind::Other);
        assert!(explain_warning(WarningKind::AssumedFocal)
            .1
            .contains("--focal PX"));
        assert!(explain_warning(WarningKind::AssumedFocal)
            .1
            .contains("--focal-range SHORT,LONG"));
        assert!(explain_warning(WarningKind::AutomaticScale)
            .1
            .contains("--scale-distance"));
    }
}
