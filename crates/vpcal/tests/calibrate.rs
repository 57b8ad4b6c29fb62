#![allow(clippy::unwrap_used, clippy::expect_used)]
//! End-to-end tests of `vpcal calibrate`, `demo`, `scale` and `measure`. Tests on the real
//! clips in `VPCAL_DATA` (default `../shared/data`) skip with a message when it is absent.

use crate::common;

use common::{read_calibration, read_json, real_data, stderr, text, vpcal};
use std::path::Path;
use vpcal_geom::Point2;

/// Files in `dir` (to check that no temporary file is left behind).
fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

#[test]
fn calibrate_a_real_clip_writes_consistent_outputs() {
    let Some(dir) = real_data("traffic_video") else {
        return;
    };
    let clip = dir.join("bgslibrary_video02_highway_cam_320x240.avi");
    let out = tempfile::tempdir().unwrap();
    let o = |n: &str| out.path().join(n).to_str().unwrap().to_string();
    let r = vpcal(&[
        "calibrate",
        clip.to_str().unwrap(),
        "-o",
        &o("calib.json"),
        "--overlay",
        &o("overlay.png"),
        "--vehicles",
        &o("vehicles.json"),
        "--scene-edgelets",
        &o("scene.json"),
        "--bcs-json",
        &o("system.json"),
        "--max-frames",
        "200",
        "--detector",
        "motion",
        "--quiet",
    ]);
    // This clip calibrates (VP1 from 18 straight tracks of the motion detector's boxes).
    let code = r.status.code().unwrap();
    assert_eq!(code, 0, "exit {code}: {}", text(&r));
    assert!(text(&r).contains("200 processed (320x240)"), "{}", text(&r));
    let calib = read_json(&out.path().join("calib.json"));
    assert_eq!(calib["format"], "vpcal-calibration/3");
    assert_eq!(calib["image_size"], serde_json::json!([320, 240]));
    assert_eq!(calib["input"]["frames_processed"], 200);
    // The motion detector's warm-up (3 s) is looked at again once its background is built;
    // those frames' vehicles come first in the records.
    let replayed = calib["input"]["frames_replayed"].as_u64().unwrap();
    assert!((30..200).contains(&replayed), "{replayed}");
    // Every kept box became one vehicle record (VPout JSON; strict: serde_json read it),
    // those the network did not see without VPs.
    let vehicles = vpcal_formats::reference::read_vpout(&out.path().join("vehicles.json")).unwrap();
    let input = &calib["input"];
    assert_eq!(
        vehicles.len() as u64,
        input["vehicle_boxes"].as_u64().unwrap() + input["followed_boxes"].as_u64().unwrap()
    );
    assert_eq!(
        vehicles.iter().filter(|v| v.vp1.is_finite()).count() as u64,
        input["vehicle_boxes"].as_u64().unwrap()
    );
    assert!(vehicles
        .windows(2)
        .all(|w| w[0].frame_cnt <= w[1].frame_cnt));
    assert!(
        vehicles.iter().any(|v| v.frame_cnt < replayed as f64),
        "no vehicle in the replayed frames"
    );
    if code == 0 {
        assert_eq!(calib["status"], "calibrated");
        let f = calib["focal_px"].as_f64().unwrap();
        assert!(f.is_finite() && f > 0.0);
        assert_eq!(calib["K"][0][0].as_f64().unwrap(), f);
        let img = image::open(out.path().join("overlay.png")).unwrap();
        assert_eq!((img.width(), img.height()), (320, 240));
        let sys = read_json(&out.path().join("system.json"));
        assert_eq!(sys["camera_calibration"]["vp1"], calib["vp1"]);
        // The vehicles file carries the edgelets and the scene file the background's, so
        // `aggregate` on them finds the same camera (boxes go through centre and half size in
        // the file: equal up to rounding).
        assert!(
            vehicles.iter().any(|v| !v.edgelets.is_empty()),
            "no edgelets written"
        );
        // (On these 200 frames the edgelet fit runs: 1,996 edgelets with the bundled model.)
        assert!(
            calib["evidence"]["edgelets"].as_u64().unwrap() > 0,
            "{}",
            calib["evidence"]
        );
        // On a straight road the lane lines and rails of the background move VP1 (5.6 px on
        // the whole clip); this road bends in the distance, and on these 200 frames the motion
        // tracks may call it curved, when the scene's lines are not used.
        let ev = &calib["evidence"];
        if ev["road_curved"] == true {
            assert_eq!(ev["vp1_from_scene_lines"], false, "{ev}");
        } else {
            assert_eq!(ev["vp1_from_scene_lines"], true, "{ev}");
            assert!(ev["vp1_scene_edgelets"].as_u64().unwrap() > 500, "{ev}");
        }
        let pp = &calib["pp"];
        let r = vpcal(&[
            "aggregate",
            &o("vehicles.json"),
            "--scene-edgelets",
            &o("scene.json"),
            "--pp",
            &format!("{},{}", pp[0], pp[1]),
            "-o",
            &o("calib_again.json"),
        ]);
        assert!(r.status.success(), "{}", text(&r));
        // The same calibration file, its frame size inferred from the records' boxes.
        let again = read_json(&out.path().join("calib_again.json"));
        assert_eq!(again["image_size"], serde_json::json!([320, 240]));
        assert_eq!(again["input"]["kind"], "vehicle_records");
        for vp in ["vp1", "vp2"] {
            for k in 0..2 {
                let (a, b) = (
                    again[vp][k].as_f64().unwrap(),
                    calib[vp][k].as_f64().unwrap(),
                );
                assert!((a - b).abs() <= 1e-6 * b.abs().max(1.0), "{vp}: {a} vs {b}");
            }
        }
    } else {
        assert_eq!(calib["status"], "not_enough_evidence");
        assert!(!out.path().join("system.json").exists());
    }
    assert!(
        names(out.path()).iter().all(|n| !n.contains("tmp")),
        "{:?}",
        names(out.path())
    );
}

#[test]
fn calibrate_refuses_bad_input_without_leaving_files() {
    let out = tempfile::tempdir().unwrap();
    let calib = out.path().join("calib.json");
    let missing = out.path().join("no_such_video.mp4");
    let r = vpcal(&[
        "calibrate",
        missing.to_str().unwrap(),
        "-o",
        calib.to_str().unwrap(),
    ]);
    assert_eq!(r.status.code(), Some(1), "{}", text(&r));
    assert!(text(&r).contains("no_such_video.mp4"), "{}", text(&r));
    // An empty folder has no frames.
    let empty = out.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    let r = vpcal(&[
        "calibrate",
        empty.to_str().unwrap(),
        "-o",
        calib.to_str().unwrap(),
    ]);
    assert_eq!(r.status.code(), Some(1), "{}", text(&r));
    assert!(text(&r).contains("empty"), "{}", text(&r));
    // A model file that is not a network.
    let junk = out.path().join("junk.safetensors");
    std::fs::write(&junk, b"not weights").unwrap();
    let img = out.path().join("frame.png");
    image::RgbImage::new(64, 48).save(&img).unwrap();
    let r = vpcal(&[
        "calibrate",
        img.to_str().unwrap(),
        "--model",
        junk.to_str().unwrap(),
        "-o",
        calib.to_str().unwrap(),
    ]);
    assert_eq!(r.status.code(), Some(1), "{}", text(&r));
    assert!(text(&r).contains("junk.safetensors"), "{}", text(&r));
    assert!(!calib.exists());
    // An output in a folder that does not exist is refused before the run, naming both.
    let r = vpcal(&[
        "calibrate",
        img.to_str().unwrap(),
        "-o",
        calib.to_str().unwrap(),
        "--bcs-json",
        out.path().join("no_dir/system.json").to_str().unwrap(),
    ]);
    assert_eq!(r.status.code(), Some(1), "{}", text(&r));
    assert!(
        text(&r).contains("--bcs-json") && text(&r).contains("no_dir"),
        "{}",
        text(&r)
    );
    assert!(!calib.exists());
    // Detectors: an unknown name is a usage error listing the choices; a model file that
    // does not exist is named.
    let r = vpcal(&[
        "calibrate",
        img.to_str().unwrap(),
        "--detector",
        "centernet",
    ]);
    assert_eq!(r.status.code(), Some(2), "{}", text(&r));
    assert!(text(&r).contains("yolox:PATH"), "{}", text(&r));
    let r = vpcal(&[
        "calibrate",
        img.to_str().unwrap(),
        "--detector",
        "yolox:no_such_model.onnx",
        "-o",
        calib.to_str().unwrap(),
    ]);
    assert_eq!(r.status.code(), Some(1), "{}", text(&r));
    assert!(text(&r).contains("no_such_model.onnx"), "{}", text(&r));
    assert!(!calib.exists());
    // --every 0 is a wrong command line (exit 2, naming the flag).
    let r = vpcal(&[
        "calibrate",
        img.to_str().unwrap(),
        "--every",
        "0",
        "-o",
        calib.to_str().unwrap(),
    ]);
    assert_eq!(r.status.code(), Some(2), "{}", text(&r));
    assert!(text(&r).contains("every"), "{}", text(&r));
    // Without an output the result would be lost: refused before the run (usage, exit 2).
    let r = vpcal(&["calibrate", img.to_str().unwrap()]);
    assert_eq!(r.status.code(), Some(2), "{}", text(&r));
    assert!(text(&r).contains("-o FILE"), "{}", text(&r));
    assert!(!calib.exists());
}

/// A synthetic highway frame (640x360) in which the built-in detector finds vehicles, copied
/// `copies` times into a fresh folder.
fn folder_of_one_still(dir: &Path, copies: usize) -> std::path::PathBuf {
    let scene = dir.join("scene");
    let r = vpcal(&[
        "synth",
        "scene",
        "--supersample",
        "1",
        "--layout",
        "highway",
        "--frames",
        "12",
        "--frames-dir",
        "--no-video",
        "--width",
        "640",
        "--height",
        "360",
        "--seed",
        "3",
        "--out",
        scene.to_str().unwrap(),
    ]);
    assert!(r.status.success(), "{}", text(&r));
    let frame = scene.join("dataset/highway_s3/frames/000011.png");
    let stills = dir.join("stills");
    std::fs::create_dir_all(&stills).unwrap();
    for k in 0..copies {
        std::fs::copy(&frame, stills.join(format!("{k:02}.png"))).unwrap();
    }
    stills
}

#[test]
fn stills_are_calibrated_with_the_learned_detector_and_a_parked_vehicle_counts_once() {
    let dir = tempfile::tempdir().unwrap();
    let stills = folder_of_one_still(dir.path(), 3);
    let calib = dir.path().join("calib.json");
    let run = |extra: &[&str]| {
        let mut args = vec![
            "calibrate",
            stills.to_str().unwrap(),
            "-o",
            calib.to_str().unwrap(),
            "--quiet",
        ];
        args.extend_from_slice(extra);
        let r = vpcal(&args);
        (r.status.code(), text(&r), read_json(&calib))
    };
    // Three pictures of the same scene: every vehicle is parked, and counts once.
    let (code, out, doc) = run(&[]);
    assert!(code == Some(0) || code == Some(3), "{out}");
    assert!(out.contains("yolox"), "{out}");
    let kept = doc["input"]["vehicle_boxes"].as_u64().unwrap();
    assert!(kept >= 1, "no vehicle found: {out}");
    assert_eq!(
        doc["input"]["dropped"]["seen_before"].as_u64().unwrap(),
        2 * kept,
        "{out}"
    );
    assert_eq!(
        doc["input"]["dropped"]["static"].as_u64().unwrap(),
        0,
        "{out}"
    );
    if code == Some(3) {
        assert_eq!(doc["status"], "not_enough_evidence");
        assert!(doc["reason"].as_str().unwrap().contains("vehicle"), "{out}");
    }
    // With a frame rate the folder is a frame sequence: the static rule applies instead
    // (identical frames: nothing moves after the first).
    let (_, out, doc) = run(&["--fps", "25"]);
    assert_eq!(
        doc["input"]["dropped"]["seen_before"].as_u64().unwrap(),
        0,
        "{out}"
    );
    assert_eq!(doc["input"]["fps"].as_f64(), Some(25.0), "{out}");
    // One still alone.
    let one = stills.join("00.png");
    let r = vpcal(&[
        "calibrate",
        one.to_str().unwrap(),
        "-o",
        calib.to_str().unwrap(),
        "--quiet",
    ]);
    let doc = read_json(&calib);
    assert_eq!(
        doc["input"]["vehicle_boxes"].as_u64().unwrap(),
        kept,
        "{}",
        text(&r)
    );
    // The motion detector cannot work on stills: a clear error, no output file.
    std::fs::remove_file(&calib).unwrap();
    let r = vpcal(&[
        "calibrate",
        stills.to_str().unwrap(),
        "--detector",
        "motion",
        "-o",
        calib.to_str().unwrap(),
    ]);
    assert_eq!(r.status.code(), Some(1), "{}", text(&r));
    assert!(
        text(&r).contains("needs consecutive frames"),
        "{}",
        text(&r)
    );
    assert!(!calib.exists());
}

#[test]
fn a_still_image_without_vehicles_is_not_enough_evidence() {
    let out = tempfile::tempdir().unwrap();
    let img = out.path().join("frame.png");
    image::RgbImage::from_fn(160, 120, |x, y| {
        image::Rgb([(x % 256) as u8, (y % 256) as u8, 80])
    })
    .save(&img)
    .unwrap();
    let calib = out.path().join("calib.json");
    let r = vpcal(&[
        "calibrate",
        img.to_str().unwrap(),
        "-o",
        calib.to_str().unwrap(),
        "--quiet",
    ]);
    assert_eq!(r.status.code(), Some(3), "{}", text(&r));
    assert!(text(&r).contains("not enough evidence"), "{}", text(&r));
    let doc = read_json(&calib);
    assert_eq!(doc["status"], "not_enough_evidence");
    assert!(doc["reason"].as_str().unwrap().len() > 10);
}

/// A camera with f = 1000 px, pp (640, 360), horizon y = 0: vp1 (840, 0), vp2 (-5008, 0)
/// satisfy (vp1 - pp)·(vp2 - pp) = -f².
fn write_known_calib(path: &Path) {
    let doc = serde_json::json!({
        "format": "vpcal-calibration/1",
        "status": "calibrated",
        "image_size": [1280, 720],
        "pp": [640.0, 360.0],
        "vp1": [840.0, 0.0],
        "vp2": [-5008.0, 0.0],
        "focal_px": 1000.0,
        "scale_m_per_unit": null,
    });
    std::fs::write(path, serde_json::to_string_pretty(&doc).unwrap()).unwrap();
}

/// [`write_known_calib`] at `path`, and the true camera: the file's VP1 and horizon but
/// f = 1400 px (the file says 1000).
fn known_calib_and_truth(path: &Path) -> vpcal_geom::camera::Calibration {
    write_known_calib(path);
    let file = vpcal::CalibrationFile::read(path).unwrap();
    vpcal::road_focal::camera_with_focal(&file.camera().unwrap(), 1400.0).unwrap()
}

#[test]
fn several_distances_and_lane_widths_give_one_scale_with_residuals() {
    let dir = tempfile::tempdir().unwrap();
    let calib = dir.path().join("calib.json");
    write_known_calib(&calib);
    let c = calib.to_str().unwrap();
    let json = |r: &std::process::Output| -> serde_json::Value {
        assert!(r.status.success(), "{}", text(r));
        serde_json::from_slice(&r.stdout).unwrap()
    };
    let v = json(&vpcal(&[
        "scale",
        c,
        "--points",
        "600,500,700,650",
        "--distance",
        "12.5",
        "--json",
    ]));
    let s1 = v["scale_m_per_unit"].as_f64().unwrap();
    // A second distance and two road points, in metres with that scale.
    let m = json(&vpcal(&[
        "measure",
        c,
        "--points",
        "300,600,900,640",
        "--at",
        "500,550",
        "--at",
        "800,560",
        "--json",
    ]));
    let d2 = m[0]["distance"].as_f64().unwrap();
    let (a, b) = (&m[1]["road"], &m[2]["road"]);
    assert_eq!(m[1]["unit"], "m");
    let across = (a[1].as_f64().unwrap() - b[1].as_f64().unwrap()).abs();
    let along = a[0].as_f64().unwrap();
    assert!(along > 0.0, "{m}");
    let ground = m[1]["ground_distance"].as_f64().unwrap();
    assert!((ground - along.hypot(a[1].as_f64().unwrap())).abs() < 1e-9);
    // The second distance 2 % long: the scale is the geometric mean, each residual about 1 %.
    let d2s = format!("{}", d2 * 1.02);
    let v = json(&vpcal(&[
        "scale",
        c,
        "--points",
        "600,500,700,650",
        "--distance",
        "12.5",
        "--points",
        "300,600,900,640",
        "--distance",
        &d2s,
        "--keep-focal",
        "--json",
    ]));
    let s = v["scale_m_per_unit"].as_f64().unwrap();
    assert!((s / (s1 * 1.02f64.sqrt()) - 1.0).abs() < 1e-9, "{v}");
    let r = &v["measurements"];
    assert!(
        (r[0]["residual_pct"].as_f64().unwrap() - 0.995).abs() < 0.01,
        "{v}"
    );
    assert!(
        (r[1]["residual_pct"].as_f64().unwrap() + 0.985).abs() < 0.01,
        "{v}"
    );
    assert_eq!(v["scale_source"], "distance");
    // A lane width alone: only the part across the road counts, whatever the pixels' place
    // along it.
    let v = json(&vpcal(&[
        "scale",
        c,
        "--lane-points",
        "500,550,800,560",
        "--lane-width",
        &format!("{}", across * 1.02f64.sqrt()),
        "--json",
    ]));
    let s3 = v["scale_m_per_unit"].as_f64().unwrap();
    assert!((s3 / s1 - 1.02f64.sqrt()).abs() < 1e-9, "{s3} vs {s1}");
    assert_eq!(read_json(&calib)["scale_source"], "lane_width");
    // Counts that do not pair up are refused, and leave the file alone.
    let before = std::fs::read(&calib).unwrap();
    let r = vpcal(&["scale", c, "--points", "600,500,700,650"]);
    assert!(!r.status.success());
    assert!(text(&r).contains("--distance"), "{}", text(&r));
    let r = vpcal(&[
        "scale",
        c,
        "--lane-points",
        "500,550,500,550",
        "--lane-width",
        "3.5",
    ]);
    assert!(!r.status.success());
    assert!(text(&r).contains("across"), "{}", text(&r));
    assert_eq!(std::fs::read(&calib).unwrap(), before);
}

#[test]
fn known_lengths_along_and_across_the_road_measure_the_focal_length() {
    let dir = tempfile::tempdir().unwrap();
    let calib = dir.path().join("calib.json");
    let truth = known_calib_and_truth(&calib);
    let c = calib.to_str().unwrap();
    // Road points 12 m along and 3.5 m across, seen through the true camera (0.05 m per unit).
    let s = 0.05;
    let o = truth.road_point(Point2::new(600.0, 600.0)).unwrap();
    let px = |dx: f64, dy: f64| {
        let p = truth
            .pixel_of_road_point([o[0] + dx / s, o[1] + dy / s])
            .unwrap();
        format!("{},{}", p.x, p.y)
    };
    let pair = |a: String, b: String| format!("{a},{b}");
    let along = pair(px(0.0, 0.0), px(12.0, 0.0));
    let across = pair(px(0.0, 0.0), px(0.0, 3.5));
    let run = |extra: &[&str]| {
        let mut a = vec!["scale", c, "--points", &along, "--distance", "12"];
        a.extend_from_slice(extra);
        a.push("--json");
        let r = vpcal(&a);
        assert!(r.status.success(), "{}", text(&r));
        serde_json::from_slice::<serde_json::Value>(&r.stdout).unwrap()
    };
    // One direction fixes only the scale, and says so.
    let v = run(&[]);
    assert_eq!(v["focal"]["changed"], false, "{v}");
    assert!((v["focal"]["focal_px"].as_f64().unwrap() - 1000.0).abs() < 1e-6);
    // Across too: the focal length is measured, and a diagonal then measures true.
    let v = run(&["--points", &across, "--distance", "3.5"]);
    assert_eq!(v["focal"]["changed"], true, "{v}");
    let f = v["focal"]["focal_px"].as_f64().unwrap();
    assert!((f / 1400.0 - 1.0).abs() < 1e-3, "{v}");
    let doc = read_json(&calib);
    assert_eq!(doc["focal_source"], "distances");
    assert!((doc["focal_px"].as_f64().unwrap() - f).abs() < 1e-6);
    let [lo, hi] = [0, 1].map(|i| doc["focal_interval_px"][i].as_f64().unwrap());
    assert!(lo < 1400.0 && 1400.0 < hi && hi / lo < 1.5, "{lo}-{hi}");
    assert!(doc["evidence"]["distances_focal"]["lengths"] == 2, "{doc}");
    assert!((doc["scale_m_per_unit"].as_f64().unwrap() / s - 1.0).abs() < 1e-3);
    let diagonal = pair(px(0.0, 0.0), px(9.0, 3.0));
    let m = vpcal(&["measure", c, "--points", &diagonal, "--json"]);
    assert!(m.status.success(), "{}", text(&m));
    let m: serde_json::Value = serde_json::from_slice(&m.stdout).unwrap();
    let d = m[0]["distance"].as_f64().unwrap();
    assert!((d - 90f64.hypot(30.0) / 10.0).abs() < 0.01, "{d}");
    // --keep-focal keeps the file's.
    write_known_calib(&calib);
    let v = run(&["--points", &across, "--distance", "3.5", "--keep-focal"]);
    assert_eq!(v["focal"]["changed"], false);
    assert!((read_json(&calib)["focal_px"].as_f64().unwrap() - 1000.0).abs() < 1e-6);
}

/// A picture of a road through camera `truth` at `s` metres per road unit: grey asphalt, two
/// solid edge lines and two dashed lane lines (3 m dashes every `period` m), lanes `lane` m
/// wide, 0.15 m lines; a white block beside the road (not a line).
fn road_picture(
    truth: &vpcal_geom::camera::Calibration,
    s: f64,
    period: f64,
    lane: f64,
) -> image::RgbImage {
    let o = truth.road_point(Point2::new(640.0, 650.0)).unwrap();
    image::RgbImage::from_fn(1280, 720, |x, y| {
        let texture = ((x * 7 + y * 13) % 9) as u8;
        let Some(q) = truth.road_point(Point2::new(f64::from(x) + 0.5, f64::from(y) + 0.5)) else {
            return image::Rgb([150, 170, 200]);
        };
        let (along, across) = ((q[0] - o[0]) * s, (q[1] - o[1]) * s);
        let on_line = |centre: f64| (across - centre).abs() < 0.075;
        let solid = on_line(-2.0 * lane) || on_line(2.0 * lane);
        let dash = (on_line(-lane) || on_line(0.0) || on_line(lane))
            && along > -20.0
            && (along + 20.0).rem_euclid(period) < 3.0;
        let block = (8.0..10.0).contains(&across) && (5.0..9.0).contains(&along);
        let v = if solid || dash || block {
            225
        } else {
            85 + texture
        };
        image::Rgb([v, v, v])
    })
}

#[test]
fn a_marking_standard_measures_the_focal_length_and_the_scale() {
    let dir = tempfile::tempdir().unwrap();
    let calib = dir.path().join("calib.json");
    let truth = known_calib_and_truth(&calib);
    let c = calib.to_str().unwrap();
    let s = 0.05;
    let picture = dir.path().join("road.png");
    road_picture(&truth, s, 12.0, 3.5).save(&picture).unwrap();
    let p = picture.to_str().unwrap();
    let r = vpcal(&["scale", c, "--markings", "12,3.5", "--image", p, "--json"]);
    assert!(r.status.success(), "{}", text(&r));
    let v: serde_json::Value = serde_json::from_slice(&r.stdout).unwrap();
    let f = v["focal"]["focal_px"].as_f64().unwrap();
    assert!((f / 1400.0 - 1.0).abs() < 0.03, "{v}");
    let scale = v["scale_m_per_unit"].as_f64().unwrap();
    assert!((scale / s - 1.0).abs() < 0.03, "{v}");
    let rows = v["measurements"].as_array().unwrap();
    assert!(rows.iter().all(|m| m["from"] == "markings"), "{v}");
    let kinds = |k: &str| rows.iter().filter(|m| m["kind"] == k).count();
    assert!(kinds("distance") >= 2 && kinds("lane_width") >= 3, "{v}");
    let doc = read_json(&calib);
    assert_eq!(doc["focal_source"], "markings", "{doc}");
    assert_eq!(doc["scale_source"], "markings", "{doc}");
    assert_eq!(v["scale_source"], "markings", "{v}");
    // The focal length follows the ratio of period to lane: a standard with 10 % wider lanes
    // gives another one (shorter: the road must look less foreshortened).
    write_known_calib(&calib);
    let r = vpcal(&["scale", c, "--markings", "12,3.85", "--image", p, "--json"]);
    assert!(r.status.success(), "{}", text(&r));
    let v: serde_json::Value = serde_json::from_slice(&r.stdout).unwrap();
    assert!(v["focal"]["focal_px"].as_f64().unwrap() < 0.95 * f, "{v}");
    // A picture without lane lines is an error that says so, and the file stays.
    write_known_calib(&calib);
    let before = std::fs::read(&calib).unwrap();
    let blank = dir.path().join("blank.png");
    image::RgbImage::from_pixel(1280, 720, image::Rgb([90, 90, 90]))
        .save(&blank)
        .unwrap();
    let r = vpcal(&[
        "scale",
        c,
        "--markings",
        "12,3.5",
        "--image",
        blank.to_str().unwrap(),
    ]);
    assert!(!r.status.success());
    assert!(stderr(&r).contains("no dashed lane line"), "{}", text(&r));
    assert_eq!(std::fs::read(&calib).unwrap(), before);
    // The wrong size, and a bad standard, are refused by name.
    let small = dir.path().join("small.png");
    image::RgbImage::new(640, 360).save(&small).unwrap();
    let r = vpcal(&[
        "scale",
        c,
        "--markings",
        "12,3.5",
        "--image",
        small.to_str().unwrap(),
    ]);
    assert!(
        !r.status.success() && stderr(&r).contains("640x360"),
        "{}",
        text(&r)
    );
    let r = vpcal(&["scale", c, "--markings", "12", "--image", p]);
    assert_eq!(r.status.code(), Some(2), "{}", text(&r));
    assert!(stderr(&r).contains("PERIOD,LANE"), "{}", text(&r));
}

#[test]
fn scale_then_measure_gives_metres_on_the_road() {
    let dir = tempfile::tempdir().unwrap();
    let calib = dir.path().join("calib.json");
    write_known_calib(&calib);
    let c = calib.to_str().unwrap();
    // Without a scale, distances are in plane units, with a warning.
    let r = vpcal(&["measure", c, "--points", "600,500,700,650"]);
    assert!(r.status.success(), "{}", text(&r));
    assert!(text(&r).contains("units") && text(&r).contains("no metric scale"));

    let r = vpcal(&[
        "scale",
        c,
        "--points",
        "600,500,700,650",
        "--distance",
        "12.5",
    ]);
    assert!(r.status.success(), "{}", text(&r));
    let doc = read_json(&calib);
    assert!(doc["scale_m_per_unit"].as_f64().unwrap() > 0.0);
    assert_eq!(doc["scale_reference"]["distance_m"], 12.5);

    let r = vpcal(&[
        "measure",
        c,
        "--points",
        "600,500,700,650",
        "--points",
        "700,650,600,500",
        "--json",
    ]);
    assert!(r.status.success(), "{}", text(&r));
    let v: serde_json::Value = serde_json::from_slice(&r.stdout).unwrap();
    for k in 0..2 {
        let d = v[k]["distance"].as_f64().unwrap();
        assert!((d - 12.5).abs() < 1e-9, "{d}");
        assert_eq!(v[k]["unit"], "m");
    }
    // A point above the horizon (here: outside the frame, whose top row is the horizon) is
    // refused (exit 1) with the reason, nothing measured; one just below it is measured with
    // a warning.
    let r = vpcal(&["measure", c, "--points", "10,-50,20,600", "--json"]);
    assert_eq!(r.status.code(), Some(1), "{}", text(&r));
    assert!(
        text(&r).contains("outside the 1280x720 frame"),
        "{}",
        text(&r)
    );
    assert!(r.stdout.is_empty());
    let r = vpcal(&["measure", c, "--points", "600,2,700,650"]);
    assert!(r.status.success(), "{}", text(&r));
    assert!(
        stderr(&r).contains("2.0 px below the horizon"),
        "{}",
        text(&r)
    );
    // The scaled camera for OpenCV: metres, and the camera's height.
    let yml = dir.path().join("camera.yml");
    let r = vpcal(&["export", c, "--opencv", yml.to_str().unwrap()]);
    assert!(r.status.success(), "{}", text(&r));
    let yaml = std::fs::read_to_string(&yml).unwrap();
    assert!(yaml.starts_with("%YAML:1.0\n---\n"), "{yaml}");
    for key in [
        "camera_matrix: !!opencv-matrix",
        "rvec:",
        "tvec:",
        "units: \"m\"",
        "camera_height_m:",
    ] {
        assert!(yaml.contains(key), "{key}: {yaml}");
    }
    let scaled = read_calibration(&calib);
    assert!(scaled.camera_height_m.unwrap() > 0.0);
    assert_eq!(scaled.opencv.unwrap().units, "m");

    // Scaling from a pixel above the horizon is refused and leaves the file as it was.
    let before = std::fs::read(&calib).unwrap();
    let r = vpcal(&["scale", c, "--points", "600,-20,700,650", "--distance", "3"]);
    assert_eq!(r.status.code(), Some(1), "{}", text(&r));
    assert!(text(&r).contains("horizon"), "{}", text(&r));
    assert_eq!(std::fs::read(&calib).unwrap(), before);
    // Malformed files name the field; other JSON files are not taken for calibrations.
    std::fs::write(
        dir.path().join("bad.json"),
        r#"{"format": "vpcal-calibration/3", "status": "calibrated", "image_size": [64, 48],
            "vp1": [1, 2], "pp": [0, 0]}"#,
    )
    .unwrap();
    std::fs::write(
        dir.path().join("system.json"),
        r#"{"camera_calibration": {"vp1": [1, 2], "vp2": [3, 4], "pp": [0, 0]}}"#,
    )
    .unwrap();
    let r = vpcal(&[
        "measure",
        dir.path().join("system.json").to_str().unwrap(),
        "--points",
        "1,2,3,4",
    ]);
    assert_eq!(r.status.code(), Some(1), "{}", text(&r));
    assert!(
        text(&r).contains("system.json") && text(&r).contains("not a vpcal calibration"),
        "{}",
        text(&r)
    );
    let r = vpcal(&[
        "measure",
        dir.path().join("bad.json").to_str().unwrap(),
        "--points",
        "1,2,3,4",
    ]);
    assert_eq!(r.status.code(), Some(1), "{}", text(&r));
    assert!(text(&r).contains("\"vp2\""), "{}", text(&r));
}

#[test]
fn demo_renders_calibrates_and_compares_with_the_truth() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo");
    let r = vpcal(&[
        "demo",
        "--out",
        out.to_str().unwrap(),
        "--frames",
        "40",
        "--size",
        "320x240",
        "--true-boxes",
        "--bootstrap",
        "0",
        "--quiet",
    ]);
    assert_eq!(r.status.code(), Some(0), "{}", text(&r));
    assert!(out.join("dataset/demo_highway_s3/video.mp4").is_file());
    // Bounds around what this scene gave when the test was written (focal +10.7 % from the
    // scene's poles; horizon +2.60°, ratio error 4.27 % mean): a broken calibration fails
    // them.
    let doc = read_calibration(&out.join("calib.json"));
    let demo = doc.demo.as_ref().unwrap();
    // This VP2 is too far for the vehicles' evidence to place it; the poles beside the road
    // place VP3, with an interval that holds the truth.
    assert_eq!(doc.focal_source.as_deref(), Some("verticals"));
    let [lo, hi] = doc.focal_interval_px.unwrap();
    assert!(
        lo < demo.true_focal_px && demo.true_focal_px < hi,
        "{lo}-{hi}"
    );
    assert!(demo.focal_error_pct.abs() < 15.0, "{demo:?}");
    assert!(demo.horizon_angle_error_deg.abs() < 4.0, "{demo:?}");
    assert!(demo.bcs_ratio_error_pct.mean < 8.0, "{demo:?}");
    assert_eq!(demo.bcs_ratio_error_pct.pairs, 780);
    assert!(text(&r).contains("BCS ratio error"), "{}", text(&r));
    assert!(out.join("overlay.png").is_file());
    // The OpenCV block agrees with K.
    let cv = doc.opencv.as_ref().unwrap();
    assert_eq!(Some(cv.camera_matrix), doc.k);
    assert_eq!(cv.dist_coeffs, [0.0; 5]);
}

/// From frames to a speed table: a synthetic highway (frame folder at 25 frames/s, true
/// boxes), `calibrate --tracks --bcs-json` with a scale from one taped distance, then
/// `eval speed` against the scene's speed ground truth.
#[test]
fn calibrate_writes_tracks_and_bcs_cars_that_eval_speed_measures() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("scene");
    let r = vpcal(&[
        "synth",
        "scene",
        "--supersample",
        "1",
        "--layout",
        "highway",
        "--frames",
        "120",
        "--frames-dir",
        "--no-video",
        "--width",
        "480",
        "--height",
        "270",
        "--seed",
        "4",
        "--out",
        root.to_str().unwrap(),
    ]);
    assert!(r.status.success(), "{}", text(&r));
    let ds = root.join("dataset/highway_s4");
    let gt = read_json(&ds.join("gt_data.json"));
    assert!(gt["measurementLines"].as_array().unwrap().len() >= 2);
    assert!(gt["cars"]
        .as_array()
        .unwrap()
        .iter()
        .any(|c| c["valid"] == true));
    let d = &gt["distanceMeasurement"][0];
    let points = format!(
        "{},{},{},{}",
        d["p1"][0], d["p1"][1], d["p2"][0], d["p2"][1]
    );
    let distance = d["distance"].as_f64().unwrap().to_string();
    let results = dir.path().join("results");
    std::fs::create_dir_all(results.join("highway_s4")).unwrap();
    let system = results.join("highway_s4/system_vpcal.json");
    let tracks_csv = dir.path().join("tracks.csv");
    let tracks_json = dir.path().join("tracks.json");
    let run = |tracks: &Path| {
        vpcal(&[
            "calibrate",
            ds.join("frames").to_str().unwrap(),
            "--fps",
            "25",
            "--detections",
            ds.join("detections.csv").to_str().unwrap(),
            "--scale-points",
            &points,
            "--scale-distance",
            &distance,
            "--tracks",
            tracks.to_str().unwrap(),
            "--bcs-json",
            system.to_str().unwrap(),
            "--bootstrap",
            "0",
            "--quiet",
        ])
    };
    let r = run(&tracks_json);
    assert_eq!(r.status.code(), Some(0), "{}", text(&r));
    assert!(
        common::stdout(&r).contains("with a speed, median speed"),
        "{}",
        text(&r)
    );
    let doc = read_json(&tracks_json);
    assert_eq!(doc["format"], "vpcal-tracks/1");
    assert_eq!(doc["fps"].as_f64(), Some(25.0));
    let tracks = doc["tracks"].as_array().unwrap();
    let speeds: Vec<f64> = tracks
        .iter()
        .filter_map(|t| t["speed_kmh"].as_f64())
        .collect();
    assert!(speeds.len() >= 3, "{} tracks with a speed", speeds.len());
    // Highway traffic: 50-160 km/h.
    assert!(speeds.iter().all(|s| *s > 20.0 && *s < 250.0), "{speeds:?}");
    let t0 = &tracks[0];
    assert_eq!(
        t0["frames"].as_array().unwrap().len(),
        t0["road_x_m"].as_array().unwrap().len()
    );
    // The BrnoCompSpeed file has the cars and the scale.
    let sys = read_json(&system);
    assert!(!sys["cars"].as_array().unwrap().is_empty());
    assert!(sys["camera_calibration"]["scale"].as_f64().unwrap() != 1.0);
    // CSV: a header and one row per track point.
    let r = run(&tracks_csv);
    assert_eq!(r.status.code(), Some(0), "{}", text(&r));
    let csv = std::fs::read_to_string(&tracks_csv).unwrap();
    assert!(csv.starts_with("id,frame,time_s,x_px,y_px,clipped,road_x_m,road_y_m,speed_kmh"));
    let points: usize = tracks
        .iter()
        .map(|t| t["frames"].as_array().unwrap().len())
        .sum();
    assert_eq!(csv.lines().count(), points + 1);
    let r = vpcal(&[
        "eval",
        "speed",
        "--dataset",
        root.join("dataset").to_str().unwrap(),
        "--results",
        results.to_str().unwrap(),
        "--image-size",
        "480x270",
        "--json",
    ]);
    assert_eq!(r.status.code(), Some(0), "{}", text(&r));
    let v: serde_json::Value = serde_json::from_str(&common::stdout(&r)).unwrap();
    let speed = &v[0]["videos"][0];
    let recall = speed["recall"].as_f64().unwrap();
    let median = speed["abs_kmh"]["median"].as_f64().unwrap();
    assert!(recall > 0.5, "recall {recall}: {speed}");
    assert!(median.is_finite(), "{speed}");
    eprintln!("eval speed: recall {recall}, median abs error {median} km/h");
    // Every matched car is listed, with both speeds: the median comes from them.
    let matches = speed["matches"].as_array().unwrap();
    assert_eq!(matches.len() as u64, speed["matched"].as_u64().unwrap());
    let mut errors: Vec<f64> = matches
        .iter()
        .map(|m| (m["measured_kmh"].as_f64().unwrap() - m["gt_kmh"].as_f64().unwrap()).abs())
        .collect();
    errors.sort_by(f64::total_cmp);
    let n = errors.len();
    let mid = if n % 2 == 1 {
        errors[n / 2]
    } else {
        0.5 * (errors[n / 2 - 1] + errors[n / 2])
    };
    assert!((mid - median).abs() < 1e-9, "{mid} vs {median}");
    // Without a known distance the scale is automatic, from the vehicles' sizes, and says
    // so. Measured when written: 0.0922 m per unit against the taped distance's 0.0774
    // (+19 %): this camera's focal length is assumed (661 px, truth 471 px) and the cars'
    // proportions do not survive the wrong geometry; a broken scale is off by far more.
    let calib = dir.path().join("auto.json");
    let r = vpcal(&[
        "calibrate",
        ds.join("frames").to_str().unwrap(),
        "--fps",
        "25",
        "--detections",
        ds.join("detections.csv").to_str().unwrap(),
        "-o",
        calib.to_str().unwrap(),
        "--bootstrap",
        "0",
        "--quiet",
    ]);
    assert_eq!(r.status.code(), Some(0), "{}", text(&r));
    assert!(
        text(&r).contains("metric scale is automatic"),
        "{}",
        text(&r)
    );
    let auto = read_json(&calib);
    assert_eq!(auto["scale_source"], "vehicles");
    let s = auto["scale_m_per_unit"].as_f64().unwrap();
    let known = sys["camera_calibration"]["scale"].as_f64().unwrap();
    eprintln!("automatic scale {s} m per unit, taped {known}");
    assert!((s / known).ln().abs() < 0.3, "{s} vs {known}");
    let [lo, hi] = [0, 1].map(|i| auto["scale_interval_m_per_unit"][i].as_f64().unwrap());
    assert!(lo < s && s < hi, "{lo}-{hi}");
    assert!(auto["road_homography"].is_array());
    // How the distances move over the focal length's interval: along the road they grow
    // with the focal length (less foreshortening), and the warning says so.
    let sens = &auto["scale_focal_sensitivity"];
    let ratio = |k: &str, i: usize| sens[k][i].as_f64().unwrap();
    assert!(ratio("along", 0) < 1.0 && ratio("along", 1) > 1.0, "{sens}");
    assert_eq!(
        sens["focal_px"][0].as_f64(),
        auto["focal_interval_px"][0].as_f64()
    );
    // The camera's height: its interval holds it and is at least as wide, relatively, as the
    // scale's own (the focal length's move adds to it), and the run prints it.
    let h = auto["camera_height_m"].as_f64().unwrap();
    let [hlo, hhi] = [0, 1].map(|i| auto["camera_height_interval_m"][i].as_f64().unwrap());
    assert!(hlo < h && h < hhi, "{hlo}-{h}-{hhi}");
    assert!(hhi / hlo >= hi / lo - 1e-9, "{hlo}-{hhi} vs {lo}-{hi}");
    assert!(
        ratio("height", 0) > 0.0 && ratio("height", 1) > 0.0,
        "{sens}"
    );
    assert!(
        text(&r).contains(&format!("(68% {hlo:.1}-{hhi:.1} m)")),
        "{}",
        text(&r)
    );
    assert!(
        text(&r).contains("distances along the road"),
        "{}",
        text(&r)
    );
}

/// A scene without speed ground truth (a curve: no measurement lines) is skipped, with the
/// reason, not an error for the whole evaluation.
#[test]
fn eval_speed_skips_scenes_without_measurement_lines() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("curve");
    let r = vpcal(&[
        "synth",
        "scene",
        "--supersample",
        "1",
        "--layout",
        "curve",
        "--frames",
        "10",
        "--frames-dir",
        "--no-video",
        "--width",
        "320",
        "--height",
        "180",
        "--seed",
        "2",
        "--out",
        root.to_str().unwrap(),
    ]);
    assert!(r.status.success(), "{}", text(&r));
    let r = vpcal(&[
        "eval",
        "speed",
        "--dataset",
        root.join("dataset").to_str().unwrap(),
        "--results",
        root.join("results").to_str().unwrap(),
        "--system",
        "groundtruth",
        "--image-size",
        "320x180",
        "--json",
    ]);
    assert_eq!(r.status.code(), Some(0), "{}", text(&r));
    let v: serde_json::Value = serde_json::from_str(&common::stdout(&r)).unwrap();
    assert_eq!(v[0]["skipped"], 1, "{v}");
    assert_eq!(v[0]["videos"][0]["status"], "skipped");
    assert!(v[0]["videos"][0]["reason"]
        .as_str()
        .unwrap()
        .contains("measurementLines"));
}
