//! Scenes: a fixed camera over a road layout with moving (and parked) traffic, rendered to a
//! video and described by BrnoCompSpeed-like ground truth.
//!
//! Output layout for a scene named `<name>` under `OUT`:
//! ```text
//! OUT/dataset/<name>/video.mp4            H.264 (ffmpeg), frame k = k-th rendered frame
//! OUT/dataset/<name>/frames/000000.png    (optional frame folder)
//! OUT/dataset/<name>/screen.png           frame 0
//! OUT/dataset/<name>/overlay.png          frame 0 with the true horizon, VPs and 3D boxes
//! OUT/dataset/<name>/gt_data.json         {"fps", "distanceMeasurement": [{p1, p2, distance, toVP1}],
//!                                          "measurementLines", "laneDivLines", "invalidLanes": [],
//!                                          "cars": [{carId, speed, valid, laneIndex, intersections}]}
//!                                          (speed truth: see `speed_truth`; empty on curves)
//! OUT/dataset/<name>/detections.csv       frame,x0,y0,x1,y1,score (true boxes, score 1.0)
//! OUT/dataset/<name>/vehicles.jsonl       per frame and vehicle: box, bb3d, vp1, vp2, pose, ...
//! OUT/dataset/<name>/camera.json          K, R, position, height, vp1, vp2, vp3, horizon, ...
//! OUT/results/<name>/system_groundtruth.json  {"camera_calibration": {vp1, vp2, pp, scale},
//!                                          "cars": true tracks (contact points of the true boxes)}
//! ```
//! All image coordinates use the crate's pixel convention (pixel (i, j) covers
//! [i, i+1) x [j, j+1)); the principal point written is the true one (the image centre).

use std::f64::consts::{FRAC_PI_2, PI};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Arc;

use rand::Rng;
use rayon::prelude::*;

use crate::camera::Camera;
use crate::error::write_atomic;
use crate::math::{hull, rng_for, RngExt, V3};
use crate::mesh::{Mesh, Pose};
use crate::raster::{Backdrop, Target, NEAR_M};
use crate::shade::Lighting;
use crate::speed_truth::{SpeedGeometry, SpeedTruth};
use crate::vehicle::{project_box, VehicleKind, VehicleModel, VehicleSpec};
use crate::view::clear_view;
use crate::world::{generate_world, Ground, LayoutKind, World, WorldParams};
use crate::SynthError;

/// Everything that defines a scene. Unset camera parameters are drawn from the seed.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SceneSpec {
    pub name: String,
    pub layout: LayoutKind,
    pub seed: u64,
    pub width: u32,
    pub height: u32,
    pub fps: f64,
    pub frames: u32,
    pub focal_px: Option<f64>,
    pub height_m: Option<f64>,
    pub pitch_deg: Option<f64>,
    pub roll_deg: Option<f64>,
    /// Camera yaw relative to the main road direction (degrees).
    pub yaw_rel_deg: Option<f64>,
    /// Supersampling per axis (1 is fine for video; 2 for stills).
    pub supersample: u32,
    /// Gaussian blur sigma (px) and noise sigma (8-bit levels) applied to every frame.
    pub blur_sigma: f64,
    pub noise_sigma: f64,
}

impl SceneSpec {
    /// A scene with every camera parameter drawn from the seed.
    pub fn new(name: &str, layout: LayoutKind, seed: u64) -> SceneSpec {
        SceneSpec {
            name: name.to_string(),
            layout,
            seed,
            width: 1280,
            height: 720,
            fps: 25.0,
            frames: 100,
            focal_px: None,
            height_m: None,
            pitch_deg: None,
            roll_deg: None,
            yaw_rel_deg: None,
            supersample: 1,
            blur_sigma: 0.55,
            noise_sigma: 2.0,
        }
    }

    /// Check the parameters.
    ///
    /// # Errors
    /// [`SynthError::Config`] naming the bad value.
    pub fn validate(&self) -> Result<(), SynthError> {
        let bad = |m: String| Err(SynthError::Config(m));
        if self.name.is_empty() || self.name.contains(['/', '\\']) || self.name.starts_with('.') {
            return bad(format!(
                "scene name {:?} must be a plain directory name",
                self.name
            ));
        }
        if self.width < 64
            || self.height < 64
            || self.width % 2 != 0
            || self.height % 2 != 0
            || self.width > 8192
            || self.height > 8192
        {
            return bad(format!(
                "size {}x{}: width and height must be even, 64..8192",
                self.width, self.height
            ));
        }
        if !(self.fps > 0.0 && self.fps <= 240.0) {
            return bad(format!("fps {} must be in (0, 240]", self.fps));
        }
        if self.frames == 0 {
            return bad("frames must be >= 1".into());
        }
        if let Some(f) = self.focal_px {
            if !(50.0..=50_000.0).contains(&f) {
                return bad(format!("focal {f} px outside 50..50000"));
            }
        }
        if let Some(h) = self.height_m {
            if !(1.0..=200.0).contains(&h) {
                return bad(format!("camera height {h} m outside 1..200"));
            }
        }
        if let Some(p) = self.pitch_deg {
            if !(2.0..=85.0).contains(&p) {
                return bad(format!(
                    "pitch {p} deg outside 2..85 (the camera must look down at the road)"
                ));
            }
        }
        if !(1..=4).contains(&self.supersample) {
            return bad(format!("supersample {} outside 1..=4", self.supersample));
        }
        Ok(())
    }
}

/// (layout, width, height, focal px, camera height m, pitch deg, roll deg, yaw relative to the road deg)
type SuiteRow = (LayoutKind, u32, u32, f64, f64, f64, f64, f64);

/// The benchmark suite: 14 scenes with different cameras (focal 600-4000 px, pitch, roll,
/// height) and layouts. Deterministic for `seed`.
pub fn suite_specs(frames: u32, seed: u64) -> Vec<SceneSpec> {
    // (layout, width, height, focal, height_m, pitch, roll, yaw_rel)
    let table: [SuiteRow; 14] = [
        (
            LayoutKind::Highway,
            1920,
            1080,
            4000.0,
            12.0,
            9.0,
            0.5,
            12.0,
        ),
        (
            LayoutKind::Highway,
            1920,
            1080,
            2600.0,
            9.0,
            12.0,
            -2.0,
            25.0,
        ),
        (
            LayoutKind::Highway,
            1920,
            1080,
            1800.0,
            7.0,
            16.0,
            1.5,
            -18.0,
        ),
        (
            LayoutKind::Highway,
            1280,
            720,
            1100.0,
            10.0,
            24.0,
            -3.5,
            35.0,
        ),
        (LayoutKind::Highway, 1280, 720, 600.0, 6.0, 30.0, 4.0, -8.0),
        (
            LayoutKind::Highway,
            1920,
            1080,
            3200.0,
            15.0,
            14.0,
            -1.0,
            172.0,
        ),
        (LayoutKind::Curve, 1920, 1080, 2200.0, 11.0, 15.0, 2.5, 20.0),
        (LayoutKind::Curve, 1280, 720, 900.0, 8.0, 28.0, -1.5, -30.0),
        (
            LayoutKind::Curve,
            1920,
            1080,
            1400.0,
            18.0,
            35.0,
            0.0,
            150.0,
        ),
        (
            LayoutKind::Intersection,
            1920,
            1080,
            1200.0,
            12.0,
            32.0,
            1.0,
            40.0,
        ),
        (
            LayoutKind::Intersection,
            1280,
            720,
            700.0,
            9.0,
            42.0,
            -2.5,
            -55.0,
        ),
        (
            LayoutKind::Parking,
            1920,
            1080,
            1000.0,
            14.0,
            38.0,
            2.0,
            30.0,
        ),
        (
            LayoutKind::Parking,
            1280,
            720,
            650.0,
            20.0,
            50.0,
            -3.0,
            -65.0,
        ),
        (LayoutKind::Highway, 1280, 720, 2000.0, 25.0, 20.0, 3.0, 5.0),
    ];
    table
        .iter()
        .enumerate()
        .map(|(i, &(layout, w, h, f, hm, pitch, roll, yaw))| SceneSpec {
            width: w,
            height: h,
            frames,
            focal_px: Some(f),
            height_m: Some(hm),
            pitch_deg: Some(pitch),
            roll_deg: Some(roll),
            yaw_rel_deg: Some(yaw),
            ..SceneSpec::new(
                &format!("synth{:02}_{}", i + 1, layout.name()),
                layout,
                seed.wrapping_mul(1000).wrapping_add(i as u64 + 1),
            )
        })
        .collect()
}

/// A vehicle in the simulation.
#[derive(Debug, Clone)]
struct Agent {
    id: u32,
    spec: VehicleSpec,
    model: Arc<VehicleModel>,
    /// Lane index and arc length, or a fixed pose when parked.
    lane: Option<usize>,
    s: f64,
    v: f64,
    v0: f64,
    headway_s: f64,
    accel: f64,
    pose: Pose,
}

/// Camera, world, light and traffic of a scene, ready to render.
#[derive(Debug)]
pub struct SceneState {
    pub spec: SceneSpec,
    pub camera: Camera,
    pub world: World,
    pub light: Lighting,
    agents: Vec<Agent>,
    next_id: u32,
    time_s: f64,
    rng: rand_chacha::ChaCha8Rng,
}

pub use crate::truth::VehicleTruth;

impl SceneState {
    /// Build the scene from its spec (deterministic) and run the traffic warm-up.
    ///
    /// # Errors
    /// [`SynthError::Config`] for invalid specs; [`SynthError::Exhausted`] when no camera could
    /// be placed to see the road.
    pub fn new(spec: &SceneSpec) -> Result<SceneState, SynthError> {
        spec.validate()?;
        let mut rng = rng_for(spec.seed, &[0x5CE4E]);
        let w = f64::from(spec.width);
        for _attempt in 0..50 {
            let f = spec.focal_px.unwrap_or_else(|| w * rng.log_uni(0.5, 2.5));
            let hm = spec.height_m.unwrap_or_else(|| rng.uni(5.0, 20.0));
            let pitch = spec.pitch_deg.unwrap_or_else(|| match spec.layout {
                LayoutKind::Parking | LayoutKind::Intersection => rng.uni(20.0, 50.0),
                _ => rng.uni(8.0, 30.0),
            });
            let roll = spec.roll_deg.unwrap_or_else(|| rng.normal() * 2.5);
            let yaw_rel = spec.yaw_rel_deg.unwrap_or_else(|| match spec.layout {
                LayoutKind::Parking | LayoutKind::Intersection => rng.uni(-80.0, 80.0),
                _ => rng.uni(-35.0, 35.0) + if rng.chance(0.3) { 180.0 } else { 0.0 },
            });
            let heading = rng.uni(-PI, PI);
            let yaw = heading + yaw_rel.to_radians();
            // The image centre looks at the focus point (origin of the layout).
            let dist = hm / pitch.to_radians().tan();
            let pos = V3::new(-dist * yaw.cos(), -dist * yaw.sin(), hm);
            let camera = Camera::from_angles(
                spec.width,
                spec.height,
                f,
                pos,
                yaw,
                pitch.to_radians(),
                roll.to_radians(),
            );
            let world_rng_seed: u64 = rng.random();
            let mut wrng = rng_for(world_rng_seed, &[]);
            let mut world = generate_world(
                &mut wrng,
                WorldParams {
                    layout: spec.layout,
                    focus: [0.0, 0.0],
                    heading,
                    clutter: rng.uni(0.3, 0.9),
                },
            );
            clear_view(&mut world, &camera);
            // The main road's VP must be finite and the road visible.
            let (Some(_), Some(_)) = (
                camera.vp_of_heading(world.main_heading),
                camera.vp_of_heading(world.main_heading + FRAC_PI_2),
            ) else {
                continue;
            };
            let visible_lanes = world.lanes.iter().filter(|l| {
                let len = l.path.length();
                (0..20).any(|k| {
                    let p = l.path.pose_at(len * f64::from(k) / 19.0);
                    camera
                        .project(V3::new(p.x, p.y, 0.0))
                        .is_some_and(|q| camera.in_image(q))
                })
            });
            if visible_lanes.count() == 0 {
                continue;
            }
            let mut light = Lighting::random(&mut rng);
            light.exposure = rng.uni(0.8, 1.15) as f32 / light.ground_irradiance(0.0)[1];
            let sim_seed: u64 = rng.random();
            let mut state = SceneState {
                spec: spec.clone(),
                camera,
                world,
                light,
                agents: Vec::new(),
                next_id: 0,
                time_s: 0.0,
                rng: rng_for(sim_seed, &[]),
            };
            state.park();
            // Warm up so the road is already busy at frame 0.
            for _ in 0..600 {
                state.step(0.1);
            }
            state.time_s = 0.0;
            return Ok(state);
        }
        Err(SynthError::Exhausted {
            what: format!("a camera that sees the {} road", spec.layout.name()),
            attempts: 50,
        })
    }

    fn park(&mut self) {
        let occupancy = self.rng.uni(0.4, 0.9);
        let stalls = self.world.stalls.clone();
        for st in stalls {
            if !self.rng.chance(occupancy) {
                continue;
            }
            let kind = if self.rng.chance(0.88) {
                [
                    VehicleKind::Sedan,
                    VehicleKind::Hatchback,
                    VehicleKind::Wagon,
                    VehicleKind::Suv,
                ][self.rng.int(0, 3) as usize]
            } else {
                VehicleKind::Van
            };
            let spec = VehicleSpec::random(&mut self.rng, kind);
            let mut pose = st;
            if self.rng.chance(0.35) {
                pose.heading += PI;
            }
            pose.heading =
                crate::world::wrap_angle(pose.heading + (self.rng.normal() * 2.5).to_radians());
            let model = Arc::new(spec.build_model());
            let id = self.next_id;
            self.next_id += 1;
            self.agents.push(Agent {
                id,
                spec,
                model,
                lane: None,
                s: 0.0,
                v: 0.0,
                v0: 0.0,
                headway_s: 0.0,
                accel: 0.0,
                pose,
            });
        }
    }

    /// Advance the traffic by `dt` seconds (intelligent-driver model, signals, spawning).
    fn step(&mut self, dt: f64) {
        let t = self.time_s;
        let phase = if self.world.signal_cycle_s > 0.0 {
            ((t / self.world.signal_cycle_s).floor() as i64).rem_euclid(2) as u32
        } else {
            0
        };
        // Amber: the last 3 s of a phase nobody new enters.
        let amber = self.world.signal_cycle_s > 0.0
            && (t % self.world.signal_cycle_s) > self.world.signal_cycle_s - 3.0;
        let mut acc = vec![0.0; self.agents.len()];
        for (i, a) in self.agents.iter().enumerate() {
            let Some(li) = a.lane else { continue };
            let lane = &self.world.lanes[li];
            let mut gap = f64::INFINITY;
            let mut lead_v = 0.0;
            let (sn, cs) = a.pose.heading.sin_cos();
            for (j, b) in self.agents.iter().enumerate() {
                if j == i {
                    continue;
                }
                let dx = b.pose.x - a.pose.x;
                let dy = b.pose.y - a.pose.y;
                let lx = dx * cs + dy * sn;
                let ly = -dx * sn + dy * cs;
                if lx <= 0.0 || lx > 80.0 || ly.abs() > (a.spec.width + b.spec.width) / 2.0 + 0.3 {
                    continue;
                }
                let g = lx - (a.spec.length + b.spec.length) / 2.0;
                if g < gap {
                    gap = g;
                    lead_v = b.v * (b.pose.heading - a.pose.heading).cos();
                }
            }
            if let Some((p, stop)) = lane.signal {
                let front = a.s + a.spec.length / 2.0;
                if (p != phase || amber) && front < stop + 0.5 {
                    let g = stop - front;
                    // Can we stop? Otherwise go through.
                    let need = a.v * a.v / (2.0 * 4.0);
                    if (g > need * 0.8 || p != phase) && g.max(0.01) < gap {
                        gap = g.max(0.01);
                        lead_v = 0.0;
                    }
                }
            }
            // IDM.
            let (s0, b_comf) = (2.0, 2.5);
            let dv = a.v - lead_v;
            let s_star = s0 + a.v * a.headway_s + a.v * dv / (2.0 * (a.accel * b_comf).sqrt());
            let free = 1.0 - (a.v / a.v0.max(0.1)).powi(4);
            let inter = if gap.is_finite() {
                (s_star.max(0.0) / gap.max(0.1)).powi(2)
            } else {
                0.0
            };
            acc[i] = (a.accel * (free - inter)).max(-9.0);
        }
        for (a, ac) in self.agents.iter_mut().zip(acc) {
            let Some(li) = a.lane else { continue };
            a.v = (a.v + ac * dt).max(0.0);
            a.s += a.v * dt;
            a.pose = self.world.lanes[li].path.pose_at(a.s);
        }
        // Despawn at the end of the path.
        let lanes = &self.world.lanes;
        self.agents
            .retain(|a| a.lane.is_none_or(|li| a.s < lanes[li].path.length()));
        // Spawn.
        for li in 0..self.world.lanes.len() {
            let lane = &self.world.lanes[li];
            if !self.rng.chance(lane.rate * dt) {
                continue;
            }
            let spec = VehicleSpec::random_any(&mut self.rng);
            let start = lane.path.pose_at(0.0);
            let clear = self.agents.iter().all(|b| {
                let d = ((b.pose.x - start.x).powi(2) + (b.pose.y - start.y).powi(2)).sqrt();
                d > (spec.length + b.spec.length) / 2.0 + 8.0
            });
            if !clear {
                continue;
            }
            let heavy = matches!(spec.kind, VehicleKind::Truck | VehicleKind::Bus);
            let v0 = lane.speed_mps * self.rng.uni(0.85, 1.12) * if heavy { 0.8 } else { 1.0 };
            let model = Arc::new(spec.build_model());
            let id = self.next_id;
            self.next_id += 1;
            let headway_s = self.rng.uni(1.0, 1.8);
            let accel = if heavy { 0.8 } else { self.rng.uni(1.2, 2.0) };
            self.agents.push(Agent {
                id,
                spec,
                model,
                lane: Some(li),
                s: 0.0,
                v: v0 * 0.9,
                v0,
                headway_s,
                accel,
                pose: start,
            });
        }
        self.time_s += dt;
    }

    /// Main-road VP pair (vp1 = road direction, vp2 = its horizontal normal), image pixels.
    pub fn main_vps(&self) -> Option<([f64; 2], [f64; 2])> {
        let h = self.world.main_heading;
        Some((
            self.camera.vp_of_heading(h)?,
            self.camera.vp_of_heading(h + FRAC_PI_2)?,
        ))
    }
}

/// The static part of the picture (road, props, their shadows), in horizontal bands.
struct StaticLayer {
    bands: Vec<Target>,
    /// Per band: (vehicle id, samples it covers when drawn alone) of the parked vehicles,
    /// which are baked into the layer.
    parked: Vec<Vec<(u32, usize)>>,
}

const BAND_ROWS: usize = 48;

impl StaticLayer {
    fn new(state: &SceneState) -> StaticLayer {
        let cam = &state.camera;
        let light = &state.light;
        let (w, h) = (cam.width as usize, cam.height as usize);
        let ss = state.spec.supersample;
        let parked: Vec<(&Agent, Mesh, Mesh)> = state
            .agents
            .iter()
            .filter(|a| a.lane.is_none())
            .map(|a| {
                (
                    a,
                    a.model.mesh.placed(&a.pose),
                    a.model.shadow.placed(&a.pose),
                )
            })
            .collect();
        let ao = 0.35 + 0.3 * (1.0 - light.shadow_strength);
        let starts: Vec<usize> = (0..h).step_by(BAND_ROWS).collect();
        let done: Vec<(Target, Vec<(u32, usize)>)> = starts
            .par_iter()
            .map(|&y0| {
                let rows = BAND_ROWS.min(h - y0);
                let mut t = Target::new(0.0, y0 as f64, w, rows, ss);
                for p in &state.world.props {
                    t.draw(cam, light, &p.mesh.tris, 1);
                }
                for (a, mesh, _) in &parked {
                    t.draw(cam, light, &mesh.tris, 1000 + a.id);
                }
                for p in state.world.props.iter().filter(|p| p.casts_shadow) {
                    t.draw_shadow(cam, light, &p.mesh.tris);
                }
                for (a, _, shadow) in &parked {
                    t.draw_shadow(cam, light, &shadow.tris);
                    t.draw_contact_shadow(cam, &a.pose, a.spec.length, a.spec.width, ao);
                }
                t.fill_background(cam, light, Backdrop::World(&state.world));
                t.shade.iter_mut().for_each(|s| *s = 1.0);
                let alone = parked
                    .iter()
                    .map(|(a, mesh, _)| (a.id, t.coverage(cam, &mesh.tris)))
                    .filter(|&(_, n)| n > 0)
                    .collect();
                (t, alone)
            })
            .collect();
        let (bands, parked) = done.into_iter().unzip();
        StaticLayer { bands, parked }
    }
}

/// A rendered frame and the truth of the vehicles in it.
#[derive(Debug)]
pub struct Frame {
    pub image: image::RgbImage,
    pub vehicles: Vec<VehicleTruth>,
}

/// A vehicle prepared for one frame.
struct Placed<'a> {
    agent: &'a Agent,
    mesh: Mesh,
    shadow: Mesh,
    /// Image rows (min, max) that the vehicle or its shadow may cover.
    rows: (f64, f64),
}

/// Image rows covered by a vehicle's box and its shadow; `None` when it cannot be seen.
fn touched_rows(
    cam: &Camera,
    light: &Lighting,
    spec: &VehicleSpec,
    pose: &Pose,
) -> Option<(f64, f64)> {
    let l = light.sun_dir;
    let lz = l.z.max(0.08);
    let mut pts = Vec::with_capacity(16);
    for c in spec.bb3d_world(pose) {
        pts.push(c);
        pts.push(V3::new(c.x - l.x * c.z / lz, c.y - l.y * c.z / lz, 0.0));
    }
    let mut lo = f64::MAX;
    let mut hi = f64::MIN;
    let mut any_front = false;
    let mut any_behind = false;
    let mut xs = (f64::MAX, f64::MIN);
    for p in pts {
        let c = cam.to_camera(p);
        if c.z < NEAR_M {
            any_behind = true;
            continue;
        }
        any_front = true;
        let q = cam.project_cam(c)?;
        lo = lo.min(q[1]);
        hi = hi.max(q[1]);
        xs = (xs.0.min(q[0]), xs.1.max(q[0]));
    }
    if !any_front {
        return None;
    }
    if any_behind {
        // Partly behind the camera: the projection is unbounded.
        return Some((f64::MIN, f64::MAX));
    }
    let (w, h) = (f64::from(cam.width), f64::from(cam.height));
    if xs.1 < 0.0 || xs.0 > w || hi < 0.0 || lo > h {
        return None;
    }
    Some((lo, hi))
}

/// A rendered band and, per vehicle id, (visible samples, samples when drawn alone).
type BandResult = (image::RgbImage, Vec<(u32, usize, usize)>);

/// Renders the frames of a scene one by one.
pub struct SceneRenderer {
    pub state: SceneState,
    layer: StaticLayer,
    frame: u32,
}

impl std::fmt::Debug for SceneRenderer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SceneRenderer")
            .field("scene", &self.state.spec.name)
            .field("frame", &self.frame)
            .finish()
    }
}

impl SceneRenderer {
    /// # Errors
    /// As [`SceneState::new`].
    pub fn new(spec: &SceneSpec) -> Result<SceneRenderer, SynthError> {
        let state = SceneState::new(spec)?;
        let layer = StaticLayer::new(&state);
        Ok(SceneRenderer {
            state,
            layer,
            frame: 0,
        })
    }

    /// Render the next frame (and then advance the traffic by one frame interval).
    pub fn next_frame(&mut self) -> Frame {
        let st = &self.state;
        let cam = &st.camera;
        let light = &st.light;
        // Vehicles worth drawing: placed meshes, shadow proxies and the image rows they (and
        // their shadows) may touch.
        let placed: Vec<Placed> = st
            .agents
            .iter()
            .filter(|a| a.lane.is_some())
            .filter_map(|a| {
                let mesh = a.model.mesh.placed(&a.pose);
                let shadow = a.model.shadow.placed(&a.pose);
                let rows = touched_rows(cam, light, &a.spec, &a.pose)?;
                Some(Placed {
                    agent: a,
                    mesh,
                    shadow,
                    rows,
                })
            })
            .collect();
        let ao = 0.35 + 0.3 * (1.0 - light.shadow_strength);
        let results: Vec<BandResult> = self
            .layer
            .bands
            .par_iter()
            .zip(&self.layer.parked)
            .map(|(band, parked)| {
                let s = f64::from(band.ss);
                let (r0, r1) = (band.y0, band.y0 + band.h as f64 / s);
                let here: Vec<&Placed> = placed
                    .iter()
                    .filter(|p| p.rows.1 >= r0 && p.rows.0 <= r1)
                    .collect();
                let mut t = band.clone();
                for p in &here {
                    t.draw(cam, light, &p.mesh.tris, 1000 + p.agent.id);
                }
                for p in &here {
                    t.draw_shadow(cam, light, &p.shadow.tris);
                    t.draw_contact_shadow(
                        cam,
                        &p.agent.pose,
                        p.agent.spec.length,
                        p.agent.spec.width,
                        ao,
                    );
                }
                t.apply_shade();
                let mut counts = Vec::with_capacity(here.len());
                let mut seen = std::collections::HashMap::new();
                for &id in &t.id {
                    if id >= 1000 {
                        *seen.entry(id - 1000).or_insert(0usize) += 1;
                    }
                }
                for p in &here {
                    let vis = seen.get(&p.agent.id).copied().unwrap_or(0);
                    let alone = t.coverage(cam, &p.mesh.tris);
                    counts.push((p.agent.id, vis, alone));
                }
                for &(id, alone) in parked {
                    counts.push((id, seen.get(&id).copied().unwrap_or(0), alone));
                }
                (t.resolve(light), counts)
            })
            .collect();
        let (w, h) = (cam.width, cam.height);
        let mut image = image::RgbImage::new(w, h);
        let mut vis_total: std::collections::HashMap<u32, (usize, usize)> =
            std::collections::HashMap::new();
        let mut y = 0u32;
        for (band, counts) in &results {
            image::imageops::replace(&mut image, band, 0, i64::from(y));
            y += band.height();
            for &(id, v, a) in counts {
                let e = vis_total.entry(id).or_insert((0, 0));
                e.0 += v;
                e.1 += a;
            }
        }
        // Silhouette parts outside the image count as invisible.
        let mut vehicles = Vec::new();
        for a in st.agents.iter() {
            let Some(b) = project_box(cam, &a.spec, &a.pose) else {
                continue;
            };
            let (x0, y0, x1, y1) = hull(&b);
            let (fw, fh) = (f64::from(w), f64::from(h));
            let clipped = [x0.max(0.0), y0.max(0.0), x1.min(fw), y1.min(fh)];
            if clipped[2] <= clipped[0] || clipped[3] <= clipped[1] {
                continue;
            }
            let (v, alone) = vis_total.get(&a.id).copied().unwrap_or((0, 0));
            // `alone` only counts samples inside the image; scale by the box area inside.
            let inside = ((clipped[2] - clipped[0]) * (clipped[3] - clipped[1]))
                / ((x1 - x0) * (y1 - y0)).max(1e-9);
            let visible_fraction = if alone > 0 {
                (v as f64 / alone as f64) * inside
            } else {
                0.0
            };
            vehicles.push(VehicleTruth {
                frame: self.frame,
                id: a.id,
                kind: a.spec.kind,
                box2d: [x0, y0, x1, y1],
                box_clipped: clipped,
                bb3d: b,
                vp1: cam.vp_of_heading(a.pose.heading),
                vp2: cam.vp_of_heading(a.pose.heading + FRAC_PI_2),
                pose: a.pose,
                dims_m: [a.spec.length, a.spec.width, a.spec.height],
                speed_mps: a.v,
                parked: a.lane.is_none(),
                visible_fraction: visible_fraction.min(1.0),
            });
        }
        vehicles.sort_by_key(|v| v.id);
        let mut rng = rng_for(st.spec.seed, &[0xF4A3E, u64::from(self.frame)]);
        post_frame(
            &mut image,
            st.spec.blur_sigma,
            st.spec.noise_sigma,
            &mut rng,
        );
        let dt = 1.0 / st.spec.fps;
        self.state.step(dt);
        self.frame += 1;
        Frame { image, vehicles }
    }
}

/// Blur and noise for a whole frame, parallel over rows.
fn post_frame<R: Rng>(img: &mut image::RgbImage, blur: f64, noise: f64, rng: &mut R) {
    let (w, h) = (img.width() as usize, img.height() as usize);
    let mut buf: Vec<f32> = img.as_raw().iter().map(|&v| f32::from(v)).collect();
    if blur > 0.05 {
        let s = blur as f32;
        let r = (s * 3.0).ceil().max(1.0) as usize;
        let k: Vec<f32> = (0..=2 * r)
            .map(|i| {
                let d = i as f32 - r as f32;
                (-(d * d) / (2.0 * s * s)).exp()
            })
            .collect();
        let ks: f32 = k.iter().sum();
        let k: Vec<f32> = k.iter().map(|v| v / ks).collect();
        let mut tmp = vec![0.0f32; buf.len()];
        tmp.par_chunks_mut(w * 3)
            .zip(buf.par_chunks(w * 3))
            .for_each_init(
                || vec![0.0f32; (w + 2 * r) * 3],
                |pad, (dst, src)| crate::post::blur_row(src, dst, &k, r, pad),
            );
        buf.par_chunks_mut(w * 3).enumerate().for_each(|(y, out)| {
            out.iter_mut().for_each(|v| *v = 0.0);
            for (t, kv) in k.iter().enumerate() {
                let yy = (y + t).saturating_sub(r).min(h - 1);
                let src = &tmp[yy * w * 3..(yy + 1) * w * 3];
                for (o, s) in out.iter_mut().zip(src) {
                    *o += kv * s;
                }
            }
        });
    }
    let seed: u64 = rng.random();
    img.par_chunks_mut(w * 3)
        .zip(buf.par_chunks(w * 3))
        .enumerate()
        .for_each(|(y, (dst, src))| {
            let mut state = crate::math::splitmix(seed ^ (y as u64).wrapping_mul(0x9E37_79B9));
            let ns = noise as f32;
            for (px, sp) in dst.chunks_exact_mut(3).zip(src.chunks_exact(3)) {
                // Approximately normal: a sum of four 16-bit uniforms, unit variance.
                state = crate::math::splitmix(state);
                let u: f32 = (0..4)
                    .map(|k| ((state >> (16 * k)) & 0xFFFF) as f32)
                    .sum::<f32>()
                    / 65536.0;
                let n = (u - 2.0) * 1.732_050_8 * ns;
                for (d, s) in px.iter_mut().zip(sp) {
                    *d = ((s + n).clamp(0.0, 255.0) + 0.5) as u8;
                }
            }
        });
}

/// A pair of road points with their metric distance, BCS style.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct DistanceMeasurement {
    pub p1: [f64; 3],
    pub p2: [f64; 3],
    pub distance: f64,
    #[serde(rename = "toVP1")]
    pub to_vp1: bool,
}

/// Road point pairs (along and across the main road) seen in the image, with exact distances.
pub fn distance_measurements(state: &SceneState, count: usize) -> Vec<DistanceMeasurement> {
    let cam = &state.camera;
    let mut rng = rng_for(state.spec.seed, &[0xD15]);
    let (w, h) = (f64::from(cam.width), f64::from(cam.height));
    let hz = cam.horizon();
    let margin = 0.04 * w.min(h);
    let inside =
        |p: [f64; 2]| p[0] > margin && p[1] > margin && p[0] < w - margin && p[1] < h - margin;
    let main = state.world.main_heading;
    let mut out = Vec::new();
    let mut along = 0;
    let mut across = 0;
    for _ in 0..4000 {
        if out.len() >= count {
            break;
        }
        let u = rng.uni(margin, w - margin);
        let v = rng.uni(margin, h - margin);
        // Stay clearly below the horizon so that distances are well conditioned.
        if hz[0] * u + hz[1] * v + hz[2] < 0.12 * h {
            continue;
        }
        let Some(g) = cam.ground_point(u, v) else {
            continue;
        };
        if (g - cam.position).norm() > 250.0 {
            continue;
        }
        let want_along = along <= across;
        let (heading, lo, hi) = match &state.world.ground {
            Ground::Road(road) => {
                let (s, _) = road.local(g.x, g.y);
                (road.pose(s, 0.0).heading, 5.0, 30.0)
            }
            _ => (main, 3.0, 20.0),
        };
        let dir = if want_along {
            heading
        } else {
            heading + FRAC_PI_2
        };
        let len = rng.uni(lo, hi) * if rng.chance(0.5) { 1.0 } else { -1.0 };
        let g2 = match &state.world.ground {
            Ground::Road(road) if want_along => {
                // Follow the road (curves too); the distance is the straight chord.
                let (s, t) = road.local(g.x, g.y);
                let p = road.pose(s + len, t);
                V3::new(p.x, p.y, 0.0)
            }
            _ => g + V3::new(dir.cos(), dir.sin(), 0.0) * len,
        };
        let (Some(p1), Some(p2)) = (cam.project(g), cam.project(g2)) else {
            continue;
        };
        if !inside(p1) || !inside(p2) || hz[0] * p2[0] + hz[1] * p2[1] + hz[2] < 0.12 * h {
            continue;
        }
        // Pixel length at least 40 px so the pair is measurable.
        if ((p1[0] - p2[0]).powi(2) + (p1[1] - p2[1]).powi(2)).sqrt() < 40.0 {
            continue;
        }
        out.push(DistanceMeasurement {
            p1: [p1[0], p1[1], 1.0],
            p2: [p2[0], p2[1], 1.0],
            distance: (g - g2).norm(),
            to_vp1: want_along,
        });
        if want_along {
            along += 1;
        } else {
            across += 1;
        }
    }
    out
}

/// Options for writing a scene.
#[derive(Debug, Clone, Copy)]
pub struct WriteOptions {
    pub video: bool,
    pub frames_dir: bool,
}

/// Summary of a written scene.
#[derive(Debug, Clone)]
pub struct SceneSummary {
    pub name: String,
    pub frames: u32,
    pub render_s: f64,
    pub total_s: f64,
    pub detections: usize,
    pub focal_px: f64,
}

fn json_bytes<T: serde::Serialize>(v: &T, path: &Path) -> Result<Vec<u8>, SynthError> {
    serde_json::to_vec_pretty(v).map_err(|e| SynthError::Format {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}

fn save_png(img: &image::RgbImage, path: &Path) -> Result<(), SynthError> {
    let bytes = vpcal_formats::fs::encode_png(img).map_err(|message| SynthError::Format {
        path: path.to_path_buf(),
        message,
    })?;
    write_atomic(path, &bytes)
}

/// An ffmpeg subprocess encoding raw RGB frames to H.264.
struct VideoWriter {
    child: std::process::Child,
    tmp: PathBuf,
    path: PathBuf,
}

impl VideoWriter {
    fn start(path: &Path, w: u32, h: u32, fps: f64) -> Result<VideoWriter, SynthError> {
        let tmp = PathBuf::from(format!("{}.tmp.mp4", path.display()));
        let child = Command::new("ffmpeg")
            .args([
                "-loglevel",
                "error",
                "-y",
                "-f",
                "rawvideo",
                "-pix_fmt",
                "rgb24",
                "-s",
            ])
            .arg(format!("{w}x{h}"))
            .arg("-r")
            .arg(format!("{fps}"))
            .args([
                "-i",
                "-",
                "-c:v",
                "libx264",
                "-preset",
                "veryfast",
                "-crf",
                "20",
                "-pix_fmt",
                "yuv420p",
                "-fps_mode",
                "passthrough",
            ])
            .arg(&tmp)
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| SynthError::Ffmpeg {
                path: path.to_path_buf(),
                message: format!("cannot start `ffmpeg` ({e}); is it installed and on PATH?"),
            })?;
        Ok(VideoWriter {
            child,
            tmp,
            path: path.to_path_buf(),
        })
    }

    fn push(&mut self, img: &image::RgbImage) -> Result<(), SynthError> {
        let stdin = self
            .child
            .stdin
            .as_mut()
            .ok_or_else(|| SynthError::Ffmpeg {
                path: self.path.clone(),
                message: "stdin closed".into(),
            })?;
        stdin
            .write_all(img.as_raw())
            .map_err(|e| SynthError::Ffmpeg {
                path: self.path.clone(),
                message: format!("writing a frame: {e}"),
            })
    }

    fn finish(mut self) -> Result<(), SynthError> {
        drop(self.child.stdin.take());
        let out = self
            .child
            .wait_with_output()
            .map_err(|e| SynthError::Ffmpeg {
                path: self.path.clone(),
                message: e.to_string(),
            })?;
        if !out.status.success() {
            return Err(SynthError::Ffmpeg {
                path: self.path.clone(),
                message: format!(
                    "exit {}: {}",
                    out.status,
                    String::from_utf8_lossy(&out.stderr).trim()
                ),
            });
        }
        std::fs::rename(&self.tmp, &self.path).map_err(|e| SynthError::io(&self.path, e))
    }
}

/// Render and write a whole scene under `out` (see the module docs for the layout).
/// `progress` gets the number of frames done.
///
/// # Errors
/// Invalid specs, I/O and ffmpeg failures, naming the file.
pub fn render_scene(
    spec: &SceneSpec,
    out: &Path,
    opts: WriteOptions,
    progress: &dyn Fn(u32),
) -> Result<SceneSummary, SynthError> {
    let t_start = std::time::Instant::now();
    let ds = out.join("dataset").join(&spec.name);
    let res = out.join("results").join(&spec.name);
    for d in [&ds, &res] {
        std::fs::create_dir_all(d).map_err(|e| SynthError::io(d, e))?;
    }
    let frames_dir = ds.join("frames");
    if opts.frames_dir {
        std::fs::create_dir_all(&frames_dir).map_err(|e| SynthError::io(&frames_dir, e))?;
    }
    let mut renderer = SceneRenderer::new(spec)?;
    let st = &renderer.state;
    let cam = st.camera.clone();
    let Some((vp1, vp2)) = st.main_vps() else {
        return Err(SynthError::Exhausted {
            what: "finite main-road vanishing points".into(),
            attempts: 1,
        });
    };
    let scale = cam
        .bcs_scale(vp1, vp2)
        .ok_or_else(|| SynthError::Exhausted {
            what: "a BCS scale".into(),
            attempts: 1,
        })?;
    let measurements = distance_measurements(st, 40);
    // The speed ground truth needs the whole video: gt_data.json and system_groundtruth.json
    // are written after the frames.
    let speed_geometry = SpeedGeometry::new(&st.world, &cam);
    let mut speed_truth = SpeedTruth::new();
    let (yaw, pitch, roll) = cam.angles();
    let camera_json = serde_json::json!({
        "scene": spec.name,
        "layout": spec.layout.name(),
        "seed": spec.seed,
        "width": cam.width,
        "height": cam.height,
        "fps": spec.fps,
        "frames": spec.frames,
        "focal_px": cam.focal_px,
        "pp": cam.pp,
        "K": cam.k(),
        "R": cam.rotation,
        "R_convention": "camera-from-world: X_cam = R (X_world - C); world z up, road z = 0; camera x right, y down, z forward",
        "position_m": cam.position.to_array(),
        "height_m": cam.height_m(),
        "yaw_deg": yaw.to_degrees(),
        "pitch_deg": pitch.to_degrees(),
        "roll_deg": roll.to_degrees(),
        "roll_convention": "the camera's rotation about its optical axis; the horizon's angle in the image (calib.json's roll_deg and horizon.angle_deg) is horizon_angle_deg",
        "horizon_angle_deg": vpcal_geom::Line(cam.horizon()).angle().to_degrees(),
        "main_heading_deg": st.world.main_heading.to_degrees(),
        "vp1": vp1,
        "vp2": vp2,
        "vp3": cam.vp3(),
        "horizon": cam.horizon(),
        "bcs_scale": scale,
        "main_road_markings": match &st.world.ground {
            Ground::Road(r) | Ground::Cross { a: r, .. } | Ground::Parking { access: r, .. } => {
                r.xs.markings_json()
            }
        },
        "pixel_convention": "pixel (i, j) covers [i, i+1) x [j, j+1); pp is the image centre",
        "spec": spec,
    });
    let p = ds.join("camera.json");
    write_atomic(&p, &json_bytes(&camera_json, &p)?)?;

    let mut video = if opts.video {
        Some(VideoWriter::start(
            &ds.join("video.mp4"),
            cam.width,
            cam.height,
            spec.fps,
        )?)
    } else {
        None
    };
    let mut dets = String::from("frame,x0,y0,x1,y1,score\n");
    let mut jsonl = String::new();
    let mut n_det = 0usize;
    let mut render_s = 0.0;
    for k in 0..spec.frames {
        let t0 = std::time::Instant::now();
        let frame = renderer.next_frame();
        render_s += t0.elapsed().as_secs_f64();
        if k == 0 {
            save_png(&frame.image, &ds.join("screen.png"))?;
            let overlay = crate::sheet::overlay_frame(&frame.image, &cam, &frame.vehicles);
            save_png(&overlay, &ds.join("overlay.png"))?;
        }
        if opts.frames_dir {
            save_png(&frame.image, &frames_dir.join(format!("{k:06}.png")))?;
        }
        if let Some(v) = video.as_mut() {
            v.push(&frame.image)?;
        }
        speed_truth.push(&frame.vehicles);
        for v in &frame.vehicles {
            let b = v.box_clipped;
            if crate::speed_truth::detectable(v) {
                dets.push_str(&format!(
                    "{k},{:.2},{:.2},{:.2},{:.2},1.0\n",
                    b[0], b[1], b[2], b[3]
                ));
                n_det += 1;
            }
            let line = serde_json::to_string(v).map_err(|e| SynthError::Format {
                path: ds.join("vehicles.jsonl"),
                message: e.to_string(),
            })?;
            jsonl.push_str(&line);
            jsonl.push('\n');
        }
        progress(k + 1);
    }
    if let Some(v) = video {
        v.finish()?;
    }
    write_atomic(&ds.join("detections.csv"), dets.as_bytes())?;
    write_atomic(&ds.join("vehicles.jsonl"), jsonl.as_bytes())?;
    let (lines, lanes, cars) = match &speed_geometry {
        Some(g) => (
            g.measurement_lines.clone(),
            g.lane_div_lines.clone(),
            speed_truth.cars(g, spec.fps),
        ),
        None => (vec![], vec![], vec![]),
    };
    let gt = serde_json::json!({
        "fps": spec.fps,
        "distanceMeasurement": measurements,
        "measurementLines": lines,
        "laneDivLines": lanes,
        "invalidLanes": [],
        "cars": cars,
    });
    let p = ds.join("gt_data.json");
    write_atomic(&p, &json_bytes(&gt, &p)?)?;
    let sys = serde_json::json!({
        "camera_calibration": {"vp1": vp1, "vp2": vp2, "pp": cam.pp, "scale": scale},
        "cars": speed_truth.tracks(),
    });
    let p = res.join("system_groundtruth.json");
    write_atomic(&p, &json_bytes(&sys, &p)?)?;
    Ok(SceneSummary {
        name: spec.name.clone(),
        frames: spec.frames,
        render_s,
        total_s: t_start.elapsed().as_secs_f64(),
        detections: n_det,
        focal_px: cam.focal_px,
    })
}
