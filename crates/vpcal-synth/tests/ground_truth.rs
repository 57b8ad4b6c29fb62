//! Ground truth of the synthetic data, checked against independent computations:
//! projections recomputed from the stored camera and poses, VPs recovered from the box edges,
//! focal lengths from VP pairs (vpcal-geom), the BCS files read by vpcal-formats and scored
//! with vpcal-geom's metrics.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};
use std::sync::Arc;

use vpcal_data::{SampleSource, Split};
use vpcal_geom::camera::{focal_from_vps, orthogonal_vp_on_line, Calibration};
use vpcal_geom::Point2;
use vpcal_synth::scene::{render_scene, SceneSpec, WriteOptions};
use vpcal_synth::world::LayoutKind;
use vpcal_synth::{CropConfig, CropDirSource, CropGenerator, RealBackground, SynthCropSource};

fn p(v: [f64; 2]) -> Point2 {
    Point2::from(v)
}

/// A small, fast scene of the layout (geometry does not depend on the image size).
fn small_scene(layout: LayoutKind, seed: u64, frames: u32) -> SceneSpec {
    SceneSpec {
        width: 480,
        height: 270,
        frames,
        blur_sigma: 0.0,
        noise_sigma: 0.0,
        ..SceneSpec::new(&format!("t_{}", layout.name()), layout, seed)
    }
}

fn write_scene(spec: &SceneSpec) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    render_scene(
        spec,
        dir.path(),
        WriteOptions {
            video: false,
            frames_dir: false,
        },
        &|_| {},
    )
    .unwrap();
    let ds = dir.path().join("dataset").join(&spec.name);
    (dir, ds)
}

fn read_json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn arr<const N: usize>(v: &serde_json::Value) -> [f64; N] {
    let a = v.as_array().unwrap();
    assert_eq!(a.len(), N, "{v}");
    std::array::from_fn(|i| a[i].as_f64().unwrap())
}

/// The camera of camera.json, used through plain matrix algebra (independent of the crate).
struct Cam {
    k: [[f64; 3]; 3],
    r: [[f64; 3]; 3],
    c: [f64; 3],
    pp: [f64; 2],
    focal: f64,
    horizon: [f64; 3],
}

impl Cam {
    fn load(path: &Path) -> Cam {
        let j = read_json(path);
        let m3 =
            |v: &serde_json::Value| -> [[f64; 3]; 3] { std::array::from_fn(|i| arr::<3>(&v[i])) };
        Cam {
            k: m3(&j["K"]),
            r: m3(&j["R"]),
            c: arr(&j["position_m"]),
            pp: arr(&j["pp"]),
            focal: j["focal_px"].as_f64().unwrap(),
            horizon: arr(&j["horizon"]),
        }
    }
    fn project_h(&self, x: [f64; 3], w: f64) -> [f64; 3] {
        let d = [
            x[0] - w * self.c[0],
            x[1] - w * self.c[1],
            x[2] - w * self.c[2],
        ];
        let rc: [f64; 3] = std::array::from_fn(|i| (0..3).map(|j| self.r[i][j] * d[j]).sum());
        std::array::from_fn(|i| (0..3).map(|j| self.k[i][j] * rc[j]).sum())
    }
    fn project(&self, x: [f64; 3]) -> [f64; 2] {
        let h = self.project_h(x, 1.0);
        [h[0] / h[2], h[1] / h[2]]
    }
    /// Vanishing point of a direction (a point at infinity).
    fn vp(&self, d: [f64; 3]) -> [f64; 2] {
        let h = self.project_h(d, 0.0);
        [h[0] / h[2], h[1] / h[2]]
    }
}

fn close(a: [f64; 2], b: [f64; 2], tol: f64) -> bool {
    let scale = 1.0 + a[0].abs().max(a[1].abs());
    (a[0] - b[0]).abs() <= tol * scale && (a[1] - b[1]).abs() <= tol * scale
}

/// Checks every vehicle of vehicles.jsonl; returns the headings seen.
fn check_vehicles(ds: &Path) -> Vec<f64> {
    let cam = Cam::load(&ds.join("camera.json"));
    let text = std::fs::read_to_string(ds.join("vehicles.jsonl")).unwrap();
    let mut headings = Vec::new();
    for line in text.lines() {
        let v: serde_json::Value = serde_json::from_str(line).unwrap();
        let pose = &v["pose"];
        let (x, y, h) = (
            pose["x"].as_f64().unwrap(),
            pose["y"].as_f64().unwrap(),
            pose["heading"].as_f64().unwrap(),
        );
        let [l, w, ht] = arr::<3>(&v["dims_m"]);
        // Corner order: bottom FL, FR, RR, RL, then the top ones.
        let local = [
            [l / 2.0, w / 2.0, 0.0],
            [l / 2.0, -w / 2.0, 0.0],
            [-l / 2.0, -w / 2.0, 0.0],
            [-l / 2.0, w / 2.0, 0.0],
            [l / 2.0, w / 2.0, ht],
            [l / 2.0, -w / 2.0, ht],
            [-l / 2.0, -w / 2.0, ht],
            [-l / 2.0, w / 2.0, ht],
        ];
        let (s, c) = h.sin_cos();
        let bb: Vec<[f64; 2]> = local
            .iter()
            .map(|q| cam.project([x + c * q[0] - s * q[1], y + s * q[0] + c * q[1], q[2]]))
            .collect();
        let stored: Vec<[f64; 2]> = v["bb3d"].as_array().unwrap().iter().map(arr::<2>).collect();
        for (a, b) in bb.iter().zip(&stored) {
            assert!(
                close(*a, *b, 1e-9),
                "bb3d corner {a:?} != stored {b:?} in {line}"
            );
        }
        let hull = [
            bb.iter().map(|q| q[0]).fold(f64::MAX, f64::min),
            bb.iter().map(|q| q[1]).fold(f64::MAX, f64::min),
            bb.iter().map(|q| q[0]).fold(f64::MIN, f64::max),
            bb.iter().map(|q| q[1]).fold(f64::MIN, f64::max),
        ];
        let stored_box = arr::<4>(&v["box"]);
        for k in 0..4 {
            assert!(
                (hull[k] - stored_box[k]).abs() < 1e-6,
                "box {stored_box:?} vs hull {hull:?}"
            );
        }
        // VP1 = image of the heading direction, VP2 = of its horizontal normal.
        let vp1 = cam.vp([c, s, 0.0]);
        let vp2 = cam.vp([-s, c, 0.0]);
        let svp1 = arr::<2>(&v["vp1"]);
        let svp2 = arr::<2>(&v["vp2"]);
        assert!(close(vp1, svp1, 1e-9), "vp1 {vp1:?} vs {svp1:?}");
        assert!(close(vp2, svp2, 1e-9), "vp2 {vp2:?} vs {svp2:?}");
        // Both lie on the true horizon.
        for vp in [svp1, svp2] {
            let r = cam.horizon[0] * vp[0] + cam.horizon[1] * vp[1] + cam.horizon[2];
            assert!(
                r.abs() < 1e-8 * (1.0 + vp[0].abs().max(vp[1].abs())),
                "VP {vp:?} off the horizon by {r}"
            );
        }
        // The focal length from the vehicle's own VP pair is the camera's.
        let f = focal_from_vps(p(svp1), p(svp2), p(cam.pp)).unwrap();
        assert!(
            (f - cam.focal).abs() < 1e-6 * cam.focal,
            "focal {f} vs {}",
            cam.focal
        );
        headings.push(h);
    }
    headings
}

#[test]
fn scene_truth_reprojects_for_every_layout() {
    for (i, layout) in LayoutKind::ALL.into_iter().enumerate() {
        let (_tmp, ds) = write_scene(&small_scene(layout, 11 + i as u64, 3));
        let headings = check_vehicles(&ds);
        assert!(!headings.is_empty(), "{layout:?}: no vehicle in view");
        // detections.csv: header, frames in range, boxes inside the image.
        let dets = std::fs::read_to_string(ds.join("detections.csv")).unwrap();
        let mut lines = dets.lines();
        assert_eq!(lines.next(), Some("frame,x0,y0,x1,y1,score"));
        for l in lines {
            let v: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
            assert!(
                v[0] >= 0.0
                    && v[0] < 3.0
                    && v[1] >= 0.0
                    && v[2] >= 0.0
                    && v[3] <= 480.0
                    && v[4] <= 270.0
                    && v[3] > v[1]
                    && v[4] > v[2]
            );
            assert_eq!(v[5], 1.0);
        }
    }
}

#[test]
fn parking_vp1_is_the_heading_vp_for_every_heading_and_lies_on_the_horizon() {
    let spec = SceneSpec {
        pitch_deg: Some(40.0),
        height_m: Some(14.0),
        ..small_scene(LayoutKind::Parking, 5, 1)
    };
    let (_tmp, ds) = write_scene(&spec);
    let headings = check_vehicles(&ds);
    let mut bins = std::collections::HashSet::new();
    for h in &headings {
        bins.insert((h.rem_euclid(std::f64::consts::TAU) / 30f64.to_radians()) as i64);
    }
    assert!(
        bins.len() >= 4,
        "parked vehicles should face many directions: {headings:?}"
    );
}

#[test]
fn bcs_files_score_zero_with_the_truth_and_not_with_a_wrong_focal() {
    let (tmp, ds) = write_scene(&small_scene(LayoutKind::Highway, 21, 1));
    // gt_data.json and system_groundtruth.json in the BrnoCompSpeed schema.
    let gt = read_json(&ds.join("gt_data.json"));
    // One frame: the speed lines, but no crossing yet.
    for key in ["invalidLanes", "cars"] {
        assert!(gt[key].as_array().is_some_and(|a| a.is_empty()), "{key}");
    }
    for key in ["measurementLines", "laneDivLines"] {
        assert!(gt[key].as_array().is_some_and(|a| a.len() >= 2), "{key}");
    }
    assert_eq!(gt["fps"].as_f64(), Some(25.0));
    let dm = gt["distanceMeasurement"].as_array().unwrap();
    assert!(dm.len() >= 10, "{}", dm.len());
    let mut m = Vec::new();
    let (mut along, mut across) = (0, 0);
    for d in dm {
        let p1 = arr::<3>(&d["p1"]);
        let p2 = arr::<3>(&d["p2"]);
        assert!(p1[2] == 1.0 && p2[2] == 1.0);
        if d["toVP1"].as_bool().unwrap() {
            along += 1;
        } else {
            across += 1;
        }
        m.push(vpcal_geom::metrics::RoadMeasurement {
            p1: p([p1[0], p1[1]]),
            p2: p([p2[0], p2[1]]),
            distance_m: d["distance"].as_f64().unwrap(),
        });
    }
    assert!(along > 0 && across > 0);
    let sys = read_json(&tmp.path().join("results/t_highway/system_groundtruth.json"));
    let cc = &sys["camera_calibration"];
    let (vp1, vp2, pp) = (
        p(arr::<2>(&cc["vp1"])),
        p(arr::<2>(&cc["vp2"])),
        p(arr::<2>(&cc["pp"])),
    );
    let scale = cc["scale"].as_f64().unwrap();
    assert!(sys["cars"].as_array().is_some_and(|a| a.is_empty()));
    let calib = Calibration::from_vps(vp1, vp2, pp).unwrap();
    let cam = Cam::load(&ds.join("camera.json"));
    assert!((calib.focal_px - cam.focal).abs() < 1e-6 * cam.focal);
    assert_eq!(
        [pp.x, pp.y],
        [240.0, 135.0],
        "the true principal point is the image centre"
    );
    // The scale turns BCS road distances into metres.
    for d in &m {
        let bcs = calib.road_distance(d.p1, d.p2).unwrap();
        assert!(
            (scale * bcs - d.distance_m).abs() < 1e-6 * d.distance_m,
            "{} vs {}",
            scale * bcs,
            d.distance_m
        );
    }
    let errs = vpcal_geom::metrics::ratio_errors(&calib, &m).unwrap();
    let worst = errs.iter().cloned().fold(0.0, f64::max);
    assert!(
        worst < 1e-6,
        "true calibration should give ~0 % error, worst {worst} %"
    );
    // Same horizon, 5 % longer focal.
    let line = vpcal_geom::Line::through(vp1, vp2).unwrap();
    let vp2b = orthogonal_vp_on_line(vp1, line, 1.05 * calib.focal_px, pp).unwrap();
    let wrong = Calibration::from_vps(vp1, vp2b, pp).unwrap();
    let errs = vpcal_geom::metrics::ratio_errors(&wrong, &m).unwrap();
    let mean = errs.iter().sum::<f64>() / errs.len() as f64;
    assert!(
        mean > 0.3,
        "a 5 % focal error should show, mean ratio error {mean} %"
    );
}

fn line_through(a: [f64; 2], b: [f64; 2]) -> [f64; 3] {
    [a[1] - b[1], b[0] - a[0], a[0] * b[1] - a[1] * b[0]]
}

fn meet(l: [f64; 3], m: [f64; 3]) -> [f64; 2] {
    let x = l[1] * m[2] - l[2] * m[1];
    let y = l[2] * m[0] - l[0] * m[2];
    let w = l[0] * m[1] - l[1] * m[0];
    [x / w, y / w]
}

fn generator(seed: u64) -> CropGenerator {
    CropGenerator::new(CropConfig::default(), seed, Arc::new(Vec::new())).unwrap()
}

#[test]
fn crop_vps_are_where_the_box_edges_meet_and_give_the_camera_focal() {
    let g = generator(3);
    for i in 0..24u64 {
        let c = g.generate_index(i).unwrap();
        let s = &c.sample;
        assert_eq!(
            (s.image.width(), s.image.height()),
            (s.image.width().max(1), s.image.height().max(1))
        );
        for (edges, vp) in [
            (vpcal_synth::sheet::EDGES_VP1, s.vp1),
            (vpcal_synth::sheet::EDGES_VP2, s.vp2),
        ] {
            // Any two of the four parallel edges meet at the VP.
            let l0 = line_through(s.bb3d[edges[0].0], s.bb3d[edges[0].1]);
            let l3 = line_through(s.bb3d[edges[3].0], s.bb3d[edges[3].1]);
            let x = meet(l0, l3);
            let d = (vp[0] - s.bb3d[0][0]).hypot(vp[1] - s.bb3d[0][1]);
            assert!(
                (x[0] - vp[0]).hypot(x[1] - vp[1]) < 1e-6 * (1.0 + d),
                "sample {i}: edges meet at {x:?}, stored VP {vp:?}"
            );
        }
        // VPs in crop pixels + the crop origin give the camera focal with the frame's pp.
        let pp_crop = [
            c.meta.pp[0] - c.meta.crop_origin[0],
            c.meta.pp[1] - c.meta.crop_origin[1],
        ];
        let f = focal_from_vps(p(s.vp1), p(s.vp2), p(pp_crop)).unwrap();
        assert!(
            (f - c.meta.focal_px).abs() < 1e-6 * c.meta.focal_px,
            "sample {i}: {f} vs {}",
            c.meta.focal_px
        );
        // The box is inside the crop, with some context around it.
        let (x0, y0, x1, y1) = vpcal_synth::math::hull(&s.bb3d);
        assert!(
            x0 >= -1e-9
                && y0 >= -1e-9
                && x1 <= f64::from(s.image.width()) + 1e-9
                && y1 <= f64::from(s.image.height()) + 1e-9
        );
        assert!(
            c.meta.visible_fraction > 0.3,
            "sample {i} is mostly hidden: {}",
            c.meta.visible_fraction
        );
    }
}

#[test]
fn crops_are_deterministic_and_the_directory_round_trips() {
    let g = generator(9);
    let a = g.generate_index(13).unwrap();
    let b = generator(9).generate_index(13).unwrap();
    assert_eq!(a.jpeg, b.jpeg);
    assert_eq!(a.sample.bb3d, b.sample.bb3d);
    let other = generator(10).generate_index(13).unwrap();
    assert_ne!(a.jpeg, other.jpeg);

    let dir = tempfile::tempdir().unwrap();
    vpcal_synth::write_crops(dir.path(), &g, 40, &|_| {}).unwrap();
    assert!(dir.path().join("FORMAT.md").is_file());
    let mut seen = 0;
    for split in [Split::Train, Split::Validation, Split::Test] {
        let src = CropDirSource::open(dir.path(), split).unwrap();
        for i in 0..src.len() {
            let s = src.get(i).unwrap();
            assert_eq!(Split::of_vehicle(s.id.vehicle), split);
            let fresh = g.generate(s.id.vehicle, s.id.instance).unwrap();
            assert_eq!(s.image, fresh.sample.image, "{:?}", s.id);
            assert_eq!(s.bb3d, fresh.sample.bb3d);
            assert_eq!(s.vp1, fresh.sample.vp1);
            seen += 1;
        }
    }
    assert_eq!(seen, 40);
    // An interrupted directory (no samples.jsonl) is refused with a message naming the file.
    std::fs::remove_file(dir.path().join("samples.jsonl")).unwrap();
    let err = CropDirSource::open(dir.path(), Split::Train)
        .unwrap_err()
        .to_string();
    assert!(err.contains("samples.jsonl"), "{err}");
}

#[test]
fn on_the_fly_source_keeps_to_its_split() {
    for split in [Split::Train, Split::Validation, Split::Test] {
        let src = SynthCropSource::new(generator(4), split, 10);
        assert_eq!(src.len(), 10);
        assert_eq!(src.split(), split);
        for i in [0, 5, 9] {
            let s = src.get(i).unwrap();
            assert_eq!(Split::of_vehicle(s.id.vehicle), split, "{:?}", s.id);
            assert!(s.vp1.iter().chain(&s.vp2).all(|v| v.is_finite()));
        }
        assert!(src.get(10).is_err());
    }
}

fn data_root() -> PathBuf {
    std::env::var_os("VPCAL_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data"))
        })
}

#[test]
fn real_backgrounds_reproduce_their_calibration() {
    let root = data_root().join("bcs");
    if !root.join("dataset").is_dir() {
        eprintln!(
            "SKIP: no BrnoCompSpeed data at {} (set VPCAL_DATA)",
            root.display()
        );
        return;
    }
    let bgs = RealBackground::load_bcs_root(&root).unwrap();
    assert!(!bgs.is_empty());
    for bg in &bgs {
        let sys = read_json(
            &root
                .join("results")
                .join(&bg.name)
                .join("system_dubska_bmvc14.json"),
        );
        let vp1 = arr::<2>(&sys["camera_calibration"]["vp1"]);
        let vp2 = arr::<2>(&sys["camera_calibration"]["vp2"]);
        let pp = arr::<2>(&sys["camera_calibration"]["pp"]);
        let f = focal_from_vps(p(vp1), p(vp2), p(pp)).unwrap();
        assert!((bg.camera.focal_px - f).abs() < 1e-6 * f, "{}", bg.name);
        let v = bg.camera.vp_of_heading(0.0).unwrap();
        assert!(close(v, vp1, 1e-6), "{}: {v:?} vs {vp1:?}", bg.name);
        assert!(!bg.road_points.is_empty(), "{}", bg.name);
    }
    let cfg = CropConfig {
        real_fraction: 1.0,
        ..CropConfig::default()
    };
    let g = CropGenerator::new(cfg, 1, Arc::new(bgs)).unwrap();
    for i in 0..6 {
        let c = g.generate_index(i * 4).unwrap();
        assert!(c.meta.scene.starts_with("real:"), "{}", c.meta.scene);
        let pp_crop = [
            c.meta.pp[0] - c.meta.crop_origin[0],
            c.meta.pp[1] - c.meta.crop_origin[1],
        ];
        let f = focal_from_vps(p(c.sample.vp1), p(c.sample.vp2), p(pp_crop)).unwrap();
        assert!((f - c.meta.focal_px).abs() < 1e-6 * f);
    }
}

#[test]
fn a_source_spec_selects_seed_length_and_split() {
    let train = SynthCropSource::from_spec("seed=5,len=80,clean", Split::Train).unwrap();
    assert_eq!(train.len(), 80);
    let val = SynthCropSource::from_spec("seed=5,len=80", Split::Validation).unwrap();
    assert_eq!(val.len(), 10);
    let again = SynthCropSource::from_spec("len=80,seed=5,clean", Split::Train).unwrap();
    assert_eq!(train.get(3).unwrap().image, again.get(3).unwrap().image);
    for bad in ["seed=5", "seed=x,len=3", "len=3,colour=red"] {
        let err = SynthCropSource::from_spec(bad, Split::Train)
            .unwrap_err()
            .to_string();
        assert!(err.contains(bad), "{err}");
    }
}

/// The speed truth of a highway scene: `vpcal eval speed`'s protocol (vpcal-formats) on the
/// true tracks (system_groundtruth.json: contact points of the true boxes) with the true
/// camera finds nearly every valid car at nearly its true speed.
#[test]
fn true_tracks_with_the_true_camera_measure_the_true_speeds() {
    use vpcal_formats::bcs::{read_gt, read_system};
    use vpcal_formats::bcs_speed::{evaluate_video, Road, SpeedMode};
    let spec = SceneSpec {
        fps: 25.0,
        ..small_scene(LayoutKind::Highway, 4, 120)
    };
    let (tmp, ds) = write_scene(&spec);
    let gt = read_gt(&ds).unwrap();
    assert_eq!(gt.measurement_lines.len(), 3);
    assert!(gt.lane_div_lines.len() >= 4, "{}", gt.lane_div_lines.len());
    let valid: Vec<_> = gt.cars.iter().filter(|c| c.valid).collect();
    assert!(valid.len() >= 3, "only {} valid cars", valid.len());
    for c in &gt.cars {
        // The last listed crossing is the one of line 0 (what the evaluation matches).
        assert_eq!(c.intersections.last().unwrap().0, 0, "{c:?}");
        assert!(c.speed_kmh > 0.0 && c.speed_kmh < 200.0, "{c:?}");
    }
    for c in &valid {
        assert_eq!(c.intersections.len(), 3, "{c:?}");
        assert!(!c.lane_index.is_empty());
    }
    let sys = read_system(&tmp.path().join("results/t_highway/system_groundtruth.json")).unwrap();
    assert!(!sys.cars.is_empty());
    let c = sys.calibration;
    let calib = Calibration::from_vps(c.vp1, c.vp2, c.pp).unwrap();
    let road = Road {
        calib: &calib,
        scale: c.scale,
    };
    let image = [f64::from(spec.width), f64::from(spec.height)];
    for mode in [SpeedMode::Median, SpeedMode::Full] {
        let v = evaluate_video(&gt, &sys.cars, &road, mode, image).unwrap();
        let recall = v.recall.unwrap();
        let median = v.abs_kmh.as_ref().unwrap().median;
        assert!(recall >= 0.9, "{mode:?}: recall {recall}: {v:?}");
        assert!(median < 1.5, "{mode:?}: median error {median} km/h: {v:?}");
    }
}
