#![allow(clippy::unwrap_used, clippy::expect_used)]
//! The HTML report (`calibrate --report`, `vpcal::report`) and the overlay it shows: a
//! well-formed, self-contained page whose pictures decode, with the focal length and every
//! warning with its remedy; warnings of every producer are recognised; the overlay draws the
//! boxes of its own frame only.

use crate::common::{text, vpcal};

use image::RgbImage;
use vpcal::aggregate::{Aggregated, FocalSource};
use vpcal::overlay::{self, Scene};
use vpcal::pipeline::{PipelineOutput, PipelineStats, TrackBox, VehicleRecord};
use vpcal::report::{self, explain_warning, warning_kind, ReportInput, WarningKind};
use vpcal::tracks::{SpeedEstimate, TrackPoint, VehicleTrack};
use vpcal_formats::calib::{CalibrationFile, InputSummary};
use vpcal_geom::aggregate::robust::Evidence;
use vpcal_geom::camera::Calibration;
use vpcal_geom::heatmap::VpPrediction;
use vpcal_geom::{BoxPx, Point2};
use vpcal_video::{SourceInfo, SourceKind, SourceOptions, Start};

// -- a minimal HTML checker ------------------------------------------------------------------

/// Elements without an end tag.
const VOID: [&str; 4] = ["meta", "img", "br", "hr"];

/// Checks that every opened tag is closed, in order (void elements and `<x/>` excepted), that
/// attribute values are quoted, and that no text holds a bare `<`; the text of `<style>` is
/// skipped. Returns the tags opened, in order.
fn check_well_formed(html: &str) -> Result<Vec<String>, String> {
    let mut stack: Vec<String> = Vec::new();
    let mut opened = Vec::new();
    let mut rest = html;
    let mut at = 0usize;
    while let Some(i) = rest.find('<') {
        let tag_start = &rest[i..];
        if tag_start.starts_with("<!DOCTYPE") || tag_start.starts_with("<!doctype") {
            let end = tag_start.find('>').ok_or("unterminated doctype")?;
            at += i + end + 1;
            rest = &tag_start[end + 1..];
            continue;
        }
        if tag_start.starts_with("<!--") {
            let end = tag_start.find("-->").ok_or("unterminated comment")?;
            at += i + end + 3;
            rest = &tag_start[end + 3..];
            continue;
        }
        let end = tag_start
            .find('>')
            .ok_or_else(|| format!("unterminated tag at byte {}", at + i))?;
        let inner = &tag_start[1..end];
        if inner.contains('<') {
            return Err(format!(
                "a '<' inside a tag at byte {}: {inner:.80}",
                at + i
            ));
        }
        // Attribute values are quoted: an even number of quotes.
        if inner.matches('"').count() % 2 != 0 {
            return Err(format!("unbalanced quotes in <{inner:.80}>"));
        }
        let after = &tag_start[end + 1..];
        if let Some(name) = inner.strip_prefix('/') {
            let name = name.trim().to_ascii_lowercase();
            match stack.pop() {
                Some(open) if open == name => {}
                Some(open) => {
                    return Err(format!(
                        "</{name}> closes <{open}> at byte {} (open: {stack:?})",
                        at + i
                    ))
                }
                None => return Err(format!("</{name}> closes nothing at byte {}", at + i)),
            }
            at += i + end + 1;
            rest = after;
            continue;
        }
        let name: String = inner
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric())
            .collect::<String>()
            .to_ascii_lowercase();
        if name.is_empty() {
            return Err(format!("a bare '<' in text at byte {}", at + i));
        }
        opened.push(name.clone());
        let self_closing = inner.ends_with('/');
        if name == "style" || name == "script" {
            let close = format!("</{name}>");
            let j = after
                .find(&close)
                .ok_or_else(|| format!("<{name}> is not closed"))?;
            at += i + end + 1 + j + close.len();
            rest = &after[j + close.len()..];
            continue;
        }
        if !self_closing && !VOID.contains(&name.as_str()) {
            stack.push(name);
        }
        at += i + end + 1;
        rest = after;
    }
    if !stack.is_empty() {
        return Err(format!("not closed: {stack:?}"));
    }
    if rest.contains('>') && !html.is_empty() {
        // A stray '>' in text is legal HTML but means something was not escaped.
        return Err(format!("a bare '>' in the trailing text: {rest:.80}"));
    }
    Ok(opened)
}

#[test]
fn the_checker_finds_what_it_should() {
    assert!(check_well_formed("<div><p>a</p></div>").is_ok());
    assert!(check_well_formed("<p><img src=\"x\"><br><line x=\"1\"/></p>").is_ok());
    assert!(check_well_formed("<div><p></div></p>").is_err());
    assert!(check_well_formed("<div><p></p>").is_err());
    assert!(check_well_formed("<p>1 < 2</p>").is_err());
    assert!(check_well_formed("<p a=\"x>y</p>").is_err());
    assert!(check_well_formed("<style>a>b{}</style><p></p>").is_ok());
}

/// The `data:image/png;base64,` images of a page, decoded.
fn png_images(html: &str) -> Vec<image::DynamicImage> {
    const PREFIX: &str = "data:image/png;base64,";
    let mut out = Vec::new();
    for (i, _) in html.match_indices(PREFIX) {
        let start = i + PREFIX.len();
        let len = html[start..]
            .find('"')
            .expect("the data URI ends with a quote");
        let bytes = decode_base64(&html[start..start + len]);
        out.push(image::load_from_memory_with_format(&bytes, image::ImageFormat::Png).unwrap());
    }
    out
}

/// A base64 decoder independent of the encoder under test.
fn decode_base64(s: &str) -> Vec<u8> {
    let value = |c: u8| -> u32 {
        match c {
            b'A'..=b'Z' => u32::from(c - b'A'),
            b'a'..=b'z' => u32::from(c - b'a') + 26,
            b'0'..=b'9' => u32::from(c - b'0') + 52,
            b'+' => 62,
            b'/' => 63,
            _ => panic!("not base64: {c}"),
        }
    };
    let s = s.as_bytes();
    assert_eq!(s.len() % 4, 0, "base64 length");
    let mut out = Vec::new();
    for chunk in s.chunks(4) {
        let pad = chunk.iter().filter(|&&c| c == b'=').count();
        let n = chunk
            .iter()
            .take(4 - pad)
            .enumerate()
            .fold(0u32, |n, (k, &c)| n | (value(c) << (18 - 6 * k)));
        let bytes = [(n >> 16) as u8, (n >> 8) as u8, n as u8];
        out.extend_from_slice(&bytes[..3 - pad]);
    }
    out
}

/// Nothing in the page reaches the network (the inlined images' base64 aside, which can
/// spell anything of its alphabet).
fn assert_offline(html: &str) {
    let mut text = String::new();
    let mut rest = html;
    while let Some(i) = rest.find("base64,") {
        text.push_str(&rest[..i]);
        let end = rest[i..].find('"').map_or(rest.len(), |e| i + e);
        rest = &rest[end..];
    }
    text.push_str(rest);
    let lower = text.to_ascii_lowercase();
    for bad in [
        "http://", "https://", "//cdn", "<script", "<link", "@import", "url(",
    ] {
        assert!(!lower.contains(bad), "the page holds {bad:?}");
    }
}

// -- a synthetic calibration -------------------------------------------------------------------

const W: u32 = 640;
const H: u32 = 360;

/// A camera with its horizon above the frame: VP1 (300, -120), f about 700 px.
fn camera() -> Calibration {
    let pp = Point2::new(320.0, 180.0);
    let vp1 = Point2::new(300.0, -120.0);
    let f: f64 = 700.0;
    // VP2 on the level line through VP1 with (vp1 - pp)·(vp2 - pp) = -f².
    let d = vp1.x - pp.x;
    let dy = vp1.y - pp.y;
    let vp2x = pp.x + (-f * f - dy * dy) / d;
    Calibration::from_vps(vp1, Point2::new(vp2x, vp1.y), pp).unwrap()
}

fn input() -> InputSummary {
    InputSummary {
        path: "/data/clips/<odd> & \"named\".mp4".into(),
        kind: Some("video".into()),
        width: W,
        height: H,
        fps: Some(25.0),
        frames_processed: 300,
        detections: 900,
        vehicle_boxes: 700,
        seconds: 12.5,
        ..InputSummary::default()
    }
}

fn evidence() -> Evidence {
    Evidence {
        vp1_ray_scatter_deg: Some(12.8),
        vp1_inliers: 10,
        edgelet_vp2_widths: Some(5e9),
        ..Evidence::default()
    }
}

/// An aggregation with an assumed focal length, a weak VP1 and parallel edges.
fn aggregated(cal: &Calibration, focal_source: FocalSource, e: Evidence) -> Aggregated {
    Aggregated {
        vp1: cal.vp1,
        vp2: cal.vp2,
        focal_px: cal.focal_px,
        summary: "VP1 from the network's rays; focal length ASSUMED".to_string(),
        evidence: serde_json::json!({
            "method": "robust",
            "pairs_in": 700,
            "pairs_used": 640,
            "vp1_inliers": 10,
            "track_lines": 2,
            "vp1_from_tracks": false,
            "vp1_ray_scatter_deg": 12.8,
            "edgelet_focal_px": 1830.0,
            "rays_focal_px": 455.0,
            "rays_posterior_px": [520.0, 610.0, 790.0],
            "focal_from_rays": false,
        }),
        confidence: None,
        track_lines: Vec::new(),
        focal_source,
        focal_interval_px: Some([442.6, 1757.2]),
        robust_evidence: Some(e),
        focal_range_px: None,
    }
}

fn track(id: u64, kmh: f64, towards: bool, lane: usize) -> VehicleTrack {
    let points = (0..20u64)
        .map(|k| {
            let image = Point2::new(200.0 + 4.0 * k as f64, 300.0 - 5.0 * k as f64);
            TrackPoint {
                frame: 10 * id + k,
                time_s: (10 * id + k) as f64 / 25.0,
                image,
                clipped: false,
                road_m: Some([k as f64, 3.5 * lane as f64]),
            }
        })
        .collect();
    VehicleTrack {
        id,
        points,
        speed: Some(SpeedEstimate {
            kmh,
            uncertainty_kmh: 1.5,
            fit_kmh: kmh + 0.5,
            windows: 10,
        }),
        lateral_m: Some(3.5 * lane as f64),
        lane: Some(lane),
        towards_vp1: Some(towards),
        path: Vec::new(),
    }
}

fn picture() -> RgbImage {
    RgbImage::from_fn(W, H, |x, y| {
        image::Rgb([(x / 3 % 256) as u8, (y / 2 % 256) as u8, 90])
    })
}

fn png(img: &RgbImage) -> Vec<u8> {
    vpcal_formats::fs::encode_png(img).unwrap()
}

fn calibrated_file() -> (CalibrationFile, Calibration) {
    let cal = camera();
    let agg = aggregated(&cal, FocalSource::Prior, evidence());
    let mut file = vpcal::output::aggregated_file(input(), &cal, &agg);
    file.set_vehicle_scale(0.05, [0.045, 0.056]).unwrap();
    file.warnings.push(format!(
        "{} the vehicles' sizes read as typical 4.4 x 1.8 x 1.5 m cars; give a known road \
         distance (--scale-points/--scale-distance or `vpcal scale`) for measurements",
        vpcal_formats::calib::AUTOMATIC_SCALE_WARNING
    ));
    (file, cal)
}

#[test]
fn a_calibrated_report_is_well_formed_self_contained_and_says_everything() {
    let (file, cal) = calibrated_file();
    assert!(file.warnings.len() >= 4, "{:?}", file.warnings);
    let tracks: Vec<VehicleTrack> = (1..=12)
        .map(|i| track(i, 60.0 + 3.0 * i as f64, i % 3 != 0, 1 + (i as usize % 2)))
        .collect();
    let scene = Scene {
        scale_m_per_unit: file.scale_m_per_unit,
        ..Scene::default()
    };
    let overlay_img = overlay::draw_scene(&picture(), Some(&cal), &scene);
    let overlay_png = png(&overlay_img);
    let run_warnings = ["clip.mp4: stopped reading after 300 frames: damaged data".to_string()];
    let html = report::render_with(
        &file,
        &ReportInput {
            overlay_png: Some(&overlay_png),
            tracks: Some(&tracks),
            tracks_note: None,
            run_warnings: &run_warnings,
        },
    );
    let tags = check_well_formed(&html).unwrap_or_else(|e| panic!("{e}"));
    for t in [
        "html", "head", "title", "style", "body", "img", "svg", "table",
    ] {
        assert!(tags.iter().any(|x| x == t), "no <{t}>");
    }
    // Two plots: the focal length and the speed histogram.
    assert_eq!(tags.iter().filter(|t| *t == "svg").count(), 2);
    assert_offline(&html);
    let images = png_images(&html);
    assert_eq!(images.len(), 1);
    assert_eq!((images[0].width(), images[0].height()), (W, H));
    assert_eq!(
        images[0].to_rgb8(),
        overlay_img,
        "the picture is the overlay, byte for byte"
    );
    // The focal length, its source and interval.
    let f = format!("{:.0} px", cal.focal_px);
    assert!(html.contains(&f), "no {f}");
    assert!(html.contains("<code>prior</code>") && html.contains("ASSUMED"));
    assert!(html.contains("443-1757 px"), "no interval");
    // The estimates the evidence recorded.
    assert!(html.contains("1830") && html.contains("455") && html.contains("610"));
    // Every warning, escaped, with its remedy.
    for w in file.warnings.iter().chain(&run_warnings) {
        let kind = warning_kind(w);
        assert_ne!(kind, WarningKind::Other, "{w}");
        assert!(html.contains(&report::escape(w)), "warning missing: {w}");
        assert!(
            html.contains(&report::escape(explain_warning(kind).1)),
            "remedy missing: {w}"
        );
    }
    assert!(html.contains("--focal PX") && html.contains("--focal-range SHORT,LONG"));
    // Text is escaped: the odd input name appears only escaped.
    assert!(html.contains("&lt;odd&gt; &amp; &quot;named&quot;.mp4"));
    assert!(!html.contains("<odd>"));
    // The horizon lies above the frame, and the page says by how much.
    let (above, d) = overlay::horizon_outside(&cal, W, H).unwrap();
    assert!(above);
    assert!(html.contains(&format!("{d:.0} px above the frame")), "{d}");
    // Tracks: the summary, both lanes and the median speed.
    assert!(html.contains("12 tracks, 12 with a speed"));
    let speeds: Vec<f64> = tracks.iter().map(|t| t.speed.unwrap().kmh).collect();
    let median = vpcal_geom::solve::median(&speeds).unwrap();
    assert!(html.contains(&format!("median speed {median:.1} km/h")));
    assert!(html.contains("towards VP1") && html.contains("from VP1"));
    // The scale and its source.
    assert!(html.contains("0.05000 m per road unit") && html.contains("automatic"));
}

#[test]
fn a_failed_run_gets_a_report_that_says_why_with_the_boxes() {
    let file = CalibrationFile::not_calibrated(
        input(),
        "not enough evidence: 2 vehicles < 5 needed".to_string(),
    );
    let records = [record(3, BoxPx::new(100.0, 100.0, 160.0, 150.0))];
    let img = overlay::draw_records_only(&picture(), &records);
    let bytes = png(&img);
    let html = report::render(&file, Some(&bytes), None);
    check_well_formed(&html).unwrap_or_else(|e| panic!("{e}"));
    assert_offline(&html);
    assert!(html.contains("Not calibrated") && html.contains("not_enough_evidence"));
    assert!(html.contains("2 vehicles &lt; 5 needed"));
    assert!(html.contains("What to do:"));
    let images = png_images(&html);
    assert_eq!(images.len(), 1);
    assert_eq!(images[0].to_rgb8(), img);
    // No camera, so no focal section.
    assert!(!html.contains("id=\"focal\""));
}

#[test]
fn every_warning_the_library_writes_has_a_remedy() {
    let cal = camera();
    let mut seen = Vec::new();
    let weak = aggregated(&cal, FocalSource::Prior, evidence()).warnings();
    assert_eq!(weak.len(), 3, "{weak:?}");
    seen.extend(weak);
    // A measured focal length outside the given range.
    seen.extend(
        Aggregated {
            focal_range_px: Some([2000.0, 3000.0]),
            ..aggregated(&cal, FocalSource::Edgelets, Evidence::default())
        }
        .warnings(),
    );
    // A curved-road fit that the straight fit contradicts.
    seen.extend(
        aggregated(
            &cal,
            FocalSource::Edgelets,
            Evidence {
                curved_fit: true,
                curved_focal: true,
                vp1_from_tracks: true,
                edgelet_focal_px: Some(cal.focal_px * 3.0),
                ..Evidence::default()
            },
        )
        .warnings(),
    );
    // Plausibility: an impossible camera height and tilt, impossible speeds.
    let mut file = CalibrationFile::calibrated(input(), &cal);
    file.camera_height_m = Some(800.0);
    file.tilt_deg = Some(-40.0);
    seen.extend(
        vpcal::plausible::check_camera(&file)
            .into_iter()
            .map(|c| c.warning),
    );
    let fast: Vec<VehicleTrack> = (1..=4).map(|i| track(i, 900.0, true, 1)).collect();
    seen.extend(
        vpcal::plausible::check_speeds(&fast, &file, false)
            .into_iter()
            .map(|c| c.warning),
    );
    let kinds: Vec<WarningKind> = seen.iter().map(|w| warning_kind(w)).collect();
    for (w, k) in seen.iter().zip(&kinds) {
        assert_ne!(*k, WarningKind::Other, "no remedy for: {w}");
        let (title, remedy) = explain_warning(*k);
        assert!(!title.is_empty() && remedy.len() > 40);
    }
    for k in [
        WarningKind::AssumedFocal,
        WarningKind::WeakVp1,
        WarningKind::ParallelEdges,
        WarningKind::FocalOutsideRange,
        WarningKind::CurvedFitDisagrees,
        WarningKind::CameraHeight,
        WarningKind::Tilt,
        WarningKind::MedianSpeed,
        WarningKind::ImpossibleSpeeds,
    ] {
        assert!(kinds.contains(&k), "{k:?} not produced: {seen:?}");
    }
}

#[test]
fn tracks_read_back_from_their_json_keep_what_the_report_shows() {
    let tracks: Vec<VehicleTrack> = (1..=3)
        .map(|i| track(i, 50.0 + i as f64, i == 2, 1))
        .collect();
    let header = vpcal::output::TracksHeader {
        input: "clip.mp4".into(),
        fps: Some(25.0),
        size: (W, H),
        scale_m_per_unit: Some(0.05),
        window_points: 10,
        note: None,
        speed_factor: None,
    };
    let doc = vpcal::output::tracks_json(&header, &tracks);
    let back = vpcal::output::tracks_from_doc(&doc).unwrap();
    // Road points come back too, null where a point has none.
    for (a, b) in tracks.iter().zip(&back) {
        for (p, q) in a.points.iter().zip(&b.points) {
            assert_eq!(p.road_m, q.road_m);
        }
    }
    assert_eq!(back.len(), 3);
    for (a, b) in tracks.iter().zip(&back) {
        assert_eq!(a.id, b.id);
        assert_eq!(a.lane, b.lane);
        assert_eq!(a.towards_vp1, b.towards_vp1);
        assert_eq!(a.speed.unwrap().kmh, b.speed.unwrap().kmh);
        assert_eq!(a.points.len(), b.points.len());
        assert_eq!(a.points[4].frame, b.points[4].frame);
        assert_eq!(a.points[4].image, b.points[4].image);
    }
}

// -- the overlay -------------------------------------------------------------------------------

fn record(frame: u64, b: BoxPx) -> VehicleRecord {
    let c = b.center();
    VehicleRecord {
        frame,
        score: 0.9,
        crop_box: b,
        det_box: b,
        prediction: Some(VpPrediction {
            vp1: Point2::new(0.0, -3.0),
            vp2: Point2::new(-3.0, 0.0),
            vp1_scale: 0,
            vp2_scale: 0,
            spreads: vec![[0.1, 0.1]],
            per_scale: vec![[Point2::new(0.0, -3.0), Point2::new(-3.0, 0.0)]],
            peaks: vec![[1.0, 1.0]],
        }),
        vp1: Point2::new(c.x, c.y - 500.0),
        vp2: Point2::new(c.x - 2000.0, c.y),
        edgelets: Vec::new(),
    }
}

fn run_output(records: Vec<VehicleRecord>, frames: u64) -> PipelineOutput {
    let boxes = records
        .iter()
        .map(|r| TrackBox {
            frame: r.frame,
            bbox: r.det_box,
            score: r.score,
        })
        .collect();
    PipelineOutput {
        info: SourceInfo {
            path: "clip.mp4".into(),
            kind: SourceKind::Video,
            width: W,
            height: H,
            fps: Some(25.0),
            frame_count: None,
            codec: None,
        },
        detector: "test".into(),
        model: "test".into(),
        records,
        boxes,
        stats: PipelineStats {
            frames,
            ..PipelineStats::default()
        },
        picture: Some(RgbImage::new(W, H)),
        scene_edgelets: Vec::new(),
        scene_segments: Vec::new(),
        background: None,
        warnings: Vec::new(),
    }
}

/// Pixels of `img` inside box `b` (shrunk by 3 px) that are not black.
fn lit_inside(img: &RgbImage, b: &BoxPx) -> usize {
    let mut n = 0;
    for y in (b.y0 as u32 - 2)..=(b.y1 as u32 + 2) {
        for x in (b.x0 as u32 - 2)..=(b.x1 as u32 + 2) {
            if img.get_pixel(x, y).0.iter().any(|&v| v > 60) {
                n += 1;
            }
        }
    }
    n
}

#[test]
fn the_overlay_draws_only_the_boxes_of_its_own_frame() {
    let old = BoxPx::new(200.0, 200.0, 260.0, 240.0);
    let now = BoxPx::new(380.0, 200.0, 440.0, 240.0);
    // Frames 10, 12, ..., 28 with --start 10 --every 2: the picture is frame 28.
    let out = run_output(vec![record(14, old), record(28, now)], 10);
    let frames = SourceOptions {
        every: 2,
        start: Start::Frame(10),
        ..SourceOptions::default()
    };
    assert_eq!(overlay::picture_frame(&out, &frames), Some(28));
    let img = overlay::draw_run(&out, &frames, None, &[], None).unwrap();
    assert!(
        lit_inside(&img, &now) > 50,
        "the picture's box is not drawn"
    );
    assert_eq!(lit_inside(&img, &old), 0, "a box of another frame is drawn");
    // A box the numbering cannot place (frame 29, off the every-2 grid): a composite, which
    // draws both.
    let mut odd = run_output(vec![record(14, old), record(29, now)], 10);
    odd.records[1].frame = 29;
    assert_eq!(overlay::picture_frame(&odd, &frames), None);
    let img = overlay::draw_run(&odd, &frames, None, &[], None).unwrap();
    assert!(lit_inside(&img, &now) > 50 && lit_inside(&img, &old) > 50);
}

// -- the command -------------------------------------------------------------------------------

#[test]
fn calibrate_checks_the_report_path_first_and_reports_a_failed_run() {
    let out = tempfile::tempdir().unwrap();
    let img = out.path().join("frame.png");
    RgbImage::from_fn(160, 120, |x, y| {
        image::Rgb([(x % 256) as u8, (y % 256) as u8, 80])
    })
    .save(&img)
    .unwrap();
    let calib = out.path().join("calib.json");
    let missing = out.path().join("no/such/folder/report.html");
    let r = vpcal(&[
        "calibrate",
        img.to_str().unwrap(),
        "-o",
        calib.to_str().unwrap(),
        "--report",
        missing.to_str().unwrap(),
        "--quiet",
    ]);
    assert_eq!(r.status.code(), Some(1), "{}", text(&r));
    assert!(text(&r).contains("--report"), "{}", text(&r));
    assert!(!calib.exists(), "the run went ahead");
    let html_path = out.path().join("report.html");
    let r = vpcal(&[
        "calibrate",
        img.to_str().unwrap(),
        "-o",
        calib.to_str().unwrap(),
        "--report",
        html_path.to_str().unwrap(),
        "--quiet",
    ]);
    assert_eq!(r.status.code(), Some(3), "{}", text(&r));
    let html = std::fs::read_to_string(&html_path).unwrap();
    check_well_formed(&html).unwrap_or_else(|e| panic!("{e}"));
    assert_offline(&html);
    assert!(html.contains("Not calibrated"));
    let images = png_images(&html);
    assert_eq!(images.len(), 1);
    assert_eq!((images[0].width(), images[0].height()), (160, 120));
}

/// A run that stopped early on a damaged input says so in its calibration file (calibrated or
/// not), and its report shows the warning once, not once from the file and once from the run.
#[test]
fn the_input_warnings_of_a_run_are_in_its_file_and_once_in_its_report() {
    let warning = "clip.mp4: stopped reading after 10 frames: damaged data; the frames before \
                   it are used"
        .to_string();
    let mut out = run_output(vec![record(3, BoxPx::new(100.0, 100.0, 160.0, 150.0))], 10);
    out.warnings = vec![warning.clone()];
    let config = vpcal::pipeline::PipelineConfig::default();
    let cal = camera();
    let agg = aggregated(&cal, FocalSource::Edgelets, evidence());
    let calibrated = vpcal::output::calibration_file(&out, &config, &cal, &agg);
    let failed = vpcal::output::failure_file(&out, &config, "not enough evidence".into());
    for file in [&calibrated, &failed] {
        assert_eq!(file.warnings.first(), Some(&warning), "{:?}", file.warnings);
        assert_eq!(file.warnings.iter().filter(|w| **w == warning).count(), 1);
        let html = report::render_with(
            file,
            &ReportInput {
                overlay_png: None,
                tracks: None,
                tracks_note: None,
                run_warnings: &out.warnings,
            },
        );
        assert_eq!(html.matches("stopped reading after 10 frames").count(), 1);
    }
    // The other warnings stay, after it.
    assert_eq!(calibrated.warnings[1..], agg.warnings()[..]);
}
