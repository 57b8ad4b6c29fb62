//! BoxCars-like training crops: one vehicle per crop, seen by a random traffic camera, with its
//! projected 3D box and both vanishing points in crop pixels.
//!
//! Sample `(vehicle v, instance i)` of seed `s` is a pure function of `(s, v, i)` and the
//! configuration: the vehicle, camera, world and light depend on `(s, v)` only (like one
//! tracked vehicle in one BoxCars camera), the position, neighbours and artefacts on `(s, v, i)`.
//! The split follows BoxCars: `v % 10 == 0` validation, `== 1` test, else train.

use std::collections::HashMap;
use std::f64::consts::{FRAC_PI_2, PI};
use std::sync::{Arc, Mutex};

use rand::Rng;
use vpcal_data::{Sample, SampleId, Split};

use crate::camera::Camera;
use crate::math::{hull, rng_for, RngExt, V3};
use crate::mesh::Pose;
use crate::post::{self, Effects};
use crate::raster::{Backdrop, Target};
use crate::realbg::RealBackground;
use crate::shade::Lighting;
use crate::vehicle::{project_box, VehicleKind, VehicleModel, VehicleSpec};
use crate::world::{generate_world, LayoutKind, World, WorldParams};
use crate::SynthError;

/// Object ids in crop renders.
const ID_TARGET: u32 = 1;
const ID_PROP: u32 = 9_999;

/// Parameters of the crop generator. The defaults are the documented training distribution.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct CropConfig {
    /// Virtual frame sizes the cameras are drawn from (pixels).
    pub frame_sizes: Vec<[u32; 2]>,
    /// Focal length as a fraction of the frame width (log-uniform).
    pub focal_rel: [f64; 2],
    /// Camera height above the road (m).
    pub height_m: [f64; 2],
    /// Camera pitch below the horizon (degrees).
    pub pitch_deg: [f64; 2],
    /// Roll standard deviation (degrees).
    pub roll_sigma_deg: f64,
    /// Size of the vehicle's projected 3D box (its larger side, pixels).
    pub box_px: [f64; 2],
    /// Context margin on each side of the 3D box, as a fraction of the box size.
    pub margin: [f64; 2],
    /// Instances (crops) per vehicle.
    pub instances: u32,
    /// Relative frequency of the layouts highway, curve, intersection, parking.
    pub layout_weights: [f64; 4],
    /// Fraction of crops rendered into real backgrounds (when some are loaded).
    pub real_fraction: f64,
    /// Supersampling factor per axis.
    pub supersample: u32,
    /// Minimum visible fraction of the target vehicle (others may occlude it).
    pub min_visible: f64,
    /// Apply camera artefacts (blur, noise, JPEG at random quality); otherwise JPEG 95.
    pub artefacts: bool,
}

impl Default for CropConfig {
    fn default() -> Self {
        CropConfig {
            frame_sizes: vec![[1920, 1080], [1280, 720], [1600, 1200], [1920, 1080]],
            focal_rel: [0.45, 2.4],
            height_m: [4.0, 18.0],
            pitch_deg: [8.0, 60.0],
            roll_sigma_deg: 3.0,
            box_px: [50.0, 300.0],
            margin: [0.06, 0.3],
            instances: 4,
            layout_weights: [0.42, 0.13, 0.2, 0.25],
            real_fraction: 0.2,
            supersample: 2,
            min_visible: 0.65,
            artefacts: true,
        }
    }
}

impl CropConfig {
    /// Check ranges.
    ///
    /// # Errors
    /// [`SynthError::Config`] naming the bad field.
    pub fn validate(&self) -> Result<(), SynthError> {
        let bad = |f: &str, v: String| Err(SynthError::Config(format!("{f} = {v}")));
        if self.frame_sizes.is_empty() || self.frame_sizes.iter().any(|s| s[0] < 64 || s[1] < 64) {
            return bad(
                "frame_sizes",
                format!("{:?} (need at least one, each >= 64x64)", self.frame_sizes),
            );
        }
        for (name, r, lo) in [
            ("focal_rel", self.focal_rel, 0.05),
            ("height_m", self.height_m, 0.5),
            ("pitch_deg", self.pitch_deg, 0.5),
            ("box_px", self.box_px, 8.0),
        ] {
            if !(r[0] >= lo && r[1] >= r[0]) {
                return bad(name, format!("{r:?} (need {lo} <= min <= max)"));
            }
        }
        if self.pitch_deg[1] > 89.0 {
            return bad("pitch_deg", format!("{:?} (max < 89)", self.pitch_deg));
        }
        if self.instances == 0 {
            return bad("instances", "0 (need >= 1)".into());
        }
        if !(self.margin[0] >= 0.0 && self.margin[1] >= self.margin[0]) {
            return bad("margin", format!("{:?}", self.margin));
        }
        if self.layout_weights.iter().any(|w| *w < 0.0)
            || self.layout_weights.iter().sum::<f64>() <= 0.0
        {
            return bad("layout_weights", format!("{:?}", self.layout_weights));
        }
        if !(1..=4).contains(&self.supersample) {
            return bad("supersample", format!("{} (1..=4)", self.supersample));
        }
        Ok(())
    }
}

/// Extra ground truth and provenance of one crop (written to `samples.jsonl`).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CropMeta {
    pub kind: VehicleKind,
    /// Layout name, or `real:<view>` for a real background.
    pub scene: String,
    pub focal_px: f64,
    pub pp: [f64; 2],
    pub frame_size: [u32; 2],
    /// Frame pixel of the crop's top-left corner.
    pub crop_origin: [f64; 2],
    pub camera_height_m: f64,
    pub pitch_deg: f64,
    pub roll_deg: f64,
    /// Vehicle heading relative to the camera's yaw (degrees; 0 = driving away from it).
    pub heading_rel_deg: f64,
    pub dims_m: [f64; 3],
    pub visible_fraction: f64,
    pub jpeg_quality: u8,
}

/// One generated crop: the training sample, its JPEG bytes and metadata.
#[derive(Debug, Clone)]
pub struct CropSample {
    pub sample: Sample,
    pub jpeg: Vec<u8>,
    pub meta: CropMeta,
}

/// What lies behind the vehicles of one setup.
enum SetupBackdrop {
    World(Box<World>),
    Real(usize),
}

struct Candidate {
    pose: Pose,
    /// The parking stall it occupies, if parked.
    stall: Option<usize>,
}

/// What is fixed for one vehicle (all its instances).
struct Setup {
    camera: Camera,
    backdrop: SetupBackdrop,
    light: Lighting,
    spec: VehicleSpec,
    model: VehicleModel,
    candidates: Vec<Candidate>,
    /// Mean gap between neighbouring vehicles on a lane (m) and parking occupancy.
    gap_m: f64,
    occupancy: f64,
}

/// Deterministic generator of training crops.
#[derive(Clone)]
pub struct CropGenerator {
    cfg: CropConfig,
    seed: u64,
    backgrounds: Arc<Vec<RealBackground>>,
    /// Recently built per-vehicle setups (instances of a vehicle share one).
    cache: Arc<Mutex<HashMap<u64, Arc<Setup>>>>,
}

impl std::fmt::Debug for CropGenerator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CropGenerator")
            .field("cfg", &self.cfg)
            .field("seed", &self.seed)
            .field("backgrounds", &self.backgrounds.len())
            .finish()
    }
}

const CACHE_MAX: usize = 256;

impl CropGenerator {
    /// # Errors
    /// [`SynthError::Config`] when the configuration is out of range.
    pub fn new(
        cfg: CropConfig,
        seed: u64,
        backgrounds: Arc<Vec<RealBackground>>,
    ) -> Result<CropGenerator, SynthError> {
        cfg.validate()?;
        Ok(CropGenerator {
            cfg,
            seed,
            backgrounds,
            cache: Arc::new(Mutex::new(HashMap::new())),
        })
    }

    pub fn config(&self) -> &CropConfig {
        &self.cfg
    }
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// The sample at global index `i` (vehicle `i / instances`, instance `i % instances`).
    ///
    /// # Errors
    /// See [`CropGenerator::generate`].
    pub fn generate_index(&self, i: u64) -> Result<CropSample, SynthError> {
        let k = u64::from(self.cfg.instances);
        self.generate(i / k, (i % k) as u32)
    }

    /// Generate instance `instance` of vehicle `vehicle`.
    ///
    /// # Errors
    /// [`SynthError::Exhausted`] if no valid placement was found (not expected with the
    /// default configuration), [`SynthError::Image`] if JPEG encoding fails.
    pub fn generate(&self, vehicle: u64, instance: u32) -> Result<CropSample, SynthError> {
        let setup = self.cached_setup(vehicle)?;
        let setup = setup.as_ref();
        let mut rng = rng_for(self.seed, &[vehicle, u64::from(instance) + 1]);
        let mut best: Option<(f64, Rendered)> = None;
        for _ in 0..8 {
            let r = self.render_instance(setup, &mut rng);
            let vis = r.visible;
            if best.as_ref().is_none_or(|b| vis > b.0) {
                best = Some((vis, r));
            }
            if vis >= self.cfg.min_visible {
                break;
            }
        }
        let Some((_, r)) = best else {
            return Err(SynthError::Exhausted {
                what: format!("vehicle {vehicle} instance {instance}"),
                attempts: 8,
            });
        };
        let fx = if self.cfg.artefacts {
            Effects::random(&mut rng)
        } else {
            Effects::none()
        };
        let mut img = r.image;
        post::apply(&mut img, &fx, &mut rng);
        let jpeg = post::encode_jpeg(&img, fx.jpeg_quality).map_err(|e| SynthError::Image {
            path: "<crop>".into(),
            source: e,
        })?;
        let image = post::decode_jpeg(&jpeg).map_err(|e| SynthError::Image {
            path: "<crop>".into(),
            source: e,
        })?;
        let cam = &setup.camera;
        let (yaw, pitch, roll) = cam.angles();
        let meta = CropMeta {
            kind: setup.spec.kind,
            scene: match &setup.backdrop {
                SetupBackdrop::World(w) => w.layout.name().to_string(),
                SetupBackdrop::Real(i) => format!(
                    "real:{}",
                    self.backgrounds.get(*i).map_or("?", |b| b.name.as_str())
                ),
            },
            focal_px: cam.focal_px,
            pp: cam.pp,
            frame_size: [cam.width, cam.height],
            crop_origin: r.origin,
            camera_height_m: cam.height_m(),
            pitch_deg: pitch.to_degrees(),
            roll_deg: roll.to_degrees(),
            heading_rel_deg: crate::world::wrap_angle(r.pose.heading - yaw).to_degrees(),
            dims_m: [setup.spec.length, setup.spec.width, setup.spec.height],
            visible_fraction: r.visible,
            jpeg_quality: fx.jpeg_quality,
        };
        Ok(CropSample {
            sample: Sample {
                id: SampleId { vehicle, instance },
                image,
                bb3d: r.bb3d,
                vp1: r.vp1,
                vp2: r.vp2,
                label_weight: vpcal_data::EXACT_LABELS,
            },
            jpeg,
            meta,
        })
    }

    fn cached_setup(&self, vehicle: u64) -> Result<Arc<Setup>, SynthError> {
        if let Ok(c) = self.cache.lock() {
            if let Some(s) = c.get(&vehicle) {
                return Ok(Arc::clone(s));
            }
        }
        let s = Arc::new(self.setup(vehicle)?);
        if let Ok(mut c) = self.cache.lock() {
            if c.len() >= CACHE_MAX {
                c.clear();
            }
            c.insert(vehicle, Arc::clone(&s));
        }
        Ok(s)
    }

    fn setup(&self, vehicle: u64) -> Result<Setup, SynthError> {
        let cfg = &self.cfg;
        let mut rng = rng_for(self.seed, &[vehicle, 0]);
        const ATTEMPTS: usize = 60;
        for _ in 0..ATTEMPTS {
            let use_real = !self.backgrounds.is_empty() && rng.chance(cfg.real_fraction);
            let kind = VehicleKind::random(&mut rng);
            let spec = VehicleSpec::random(&mut rng, kind);
            let (camera, backdrop, light) = if use_real {
                let i = rng.int(0, self.backgrounds.len() as i64 - 1) as usize;
                let bg = &self.backgrounds[i];
                let mut light = Lighting::overcast(&mut rng);
                light.exposure = 1.0 / light.ground_irradiance(0.0)[1];
                (bg.camera.clone(), SetupBackdrop::Real(i), light)
            } else {
                let [fw, fh] =
                    cfg.frame_sizes[rng.int(0, cfg.frame_sizes.len() as i64 - 1) as usize];
                let f = f64::from(fw) * rng.log_uni(cfg.focal_rel[0], cfg.focal_rel[1]);
                let h = rng.uni(cfg.height_m[0], cfg.height_m[1]);
                let pitch = rng.uni(cfg.pitch_deg[0], cfg.pitch_deg[1]).to_radians();
                let roll = (rng.normal() * cfg.roll_sigma_deg).to_radians();
                let yaw = rng.uni(-PI, PI);
                let cam = Camera::from_angles(fw, fh, f, V3::new(0.0, 0.0, h), yaw, pitch, roll);
                let layout = LayoutKind::ALL[rng.weighted(&cfg.layout_weights)];
                let fu = f64::from(fw) * rng.uni(0.25, 0.75);
                let fv = f64::from(fh) * rng.uni(0.4, 0.85);
                let Some(focus) = cam.ground_point(fu, fv) else {
                    continue;
                };
                if (focus - cam.position).norm() > 400.0 {
                    continue;
                }
                let rel = match layout {
                    LayoutKind::Parking | LayoutKind::Intersection => rng.uni(-PI, PI),
                    _ => {
                        let d = rng.uni(-75f64, 75.0).to_radians();
                        if rng.chance(0.5) {
                            d
                        } else {
                            d + PI
                        }
                    }
                };
                let params = WorldParams {
                    layout,
                    focus: [focus.x, focus.y],
                    heading: yaw + rel,
                    clutter: rng.uni(0.0, 1.0),
                };
                let mut world = generate_world(&mut rng, params);
                crate::view::clear_view(&mut world, &cam);
                let mut light = Lighting::random(&mut rng);
                light.exposure = rng.uni(0.75, 1.2) as f32 / light.ground_irradiance(0.0)[1];
                (cam, SetupBackdrop::World(Box::new(world)), light)
            };
            let candidates = self.candidates(&camera, &backdrop, &spec, &mut rng);
            if candidates.is_empty() {
                continue;
            }
            let model = spec.build_model();
            return Ok(Setup {
                camera,
                backdrop,
                light,
                spec,
                model,
                candidates,
                gap_m: rng.log_uni(4.0, 60.0),
                occupancy: rng.uni(0.3, 0.95),
            });
        }
        Err(SynthError::Exhausted {
            what: format!("a camera and placement for vehicle {vehicle}"),
            attempts: ATTEMPTS,
        })
    }

    /// Placements where the whole 3D box is in the frame and its size is in range.
    fn candidates<R: Rng>(
        &self,
        cam: &Camera,
        backdrop: &SetupBackdrop,
        spec: &VehicleSpec,
        rng: &mut R,
    ) -> Vec<Candidate> {
        let mut out = Vec::new();
        let ok = |pose: &Pose| self.placement_ok(cam, spec, pose);
        match backdrop {
            SetupBackdrop::World(world) => {
                let parked = world.layout == LayoutKind::Parking && rng.chance(0.75);
                if parked {
                    for (i, st) in world.stalls.iter().enumerate() {
                        for flip in [false, true] {
                            let pose = Pose {
                                heading: if flip { st.heading + PI } else { st.heading },
                                ..*st
                            };
                            if ok(&pose) {
                                out.push(Candidate {
                                    pose,
                                    stall: Some(i),
                                });
                            }
                        }
                    }
                } else {
                    for lane in &world.lanes {
                        let len = lane.path.length();
                        let mut s = 0.0;
                        while s < len {
                            let pose = lane.path.pose_at(s);
                            if ok(&pose) {
                                out.push(Candidate { pose, stall: None });
                            }
                            s += 1.0;
                        }
                    }
                }
            }
            SetupBackdrop::Real(i) => {
                let Some(bg) = self.backgrounds.get(*i) else {
                    return out;
                };
                let flip = rng.chance(0.5);
                for _ in 0..400 {
                    if bg.road_points.is_empty() {
                        break;
                    }
                    let p = bg.road_points[rng.int(0, bg.road_points.len() as i64 - 1) as usize];
                    let Some(g) = cam.ground_point(p[0], p[1]) else {
                        continue;
                    };
                    let heading = if flip { PI } else { 0.0 };
                    let pose = Pose {
                        x: g.x,
                        y: g.y,
                        heading,
                    };
                    if ok(&pose) {
                        out.push(Candidate { pose, stall: None });
                    }
                }
            }
        }
        out
    }

    fn placement_ok(&self, cam: &Camera, spec: &VehicleSpec, pose: &Pose) -> bool {
        let Some(b) = project_box(cam, spec, pose) else {
            return false;
        };
        let (x0, y0, x1, y1) = hull(&b);
        let (w, h) = (f64::from(cam.width), f64::from(cam.height));
        let size = (x1 - x0).max(y1 - y0);
        x0 >= 1.0
            && y0 >= 1.0
            && x1 <= w - 1.0
            && y1 <= h - 1.0
            && size >= self.cfg.box_px[0]
            && size <= self.cfg.box_px[1]
    }

    fn render_instance<R: Rng>(&self, setup: &Setup, rng: &mut R) -> Rendered {
        let cam = &setup.camera;
        let cfg = &self.cfg;
        let cand = &setup.candidates[rng.int(0, setup.candidates.len() as i64 - 1) as usize];
        // Small lateral offset and heading jitter (lane keeping is imperfect).
        let mut pose = cand.pose;
        if cand.stall.is_none() {
            let lat = rng.uni(-0.35, 0.35);
            pose.x -= pose.heading.sin() * lat;
            pose.y += pose.heading.cos() * lat;
            pose.heading += (rng.normal() * 1.2).to_radians();
        } else {
            pose.heading += (rng.normal() * 2.0).to_radians();
        }
        let b = project_box(cam, &setup.spec, &pose).unwrap_or([[0.0; 2]; 8]);
        let (bx0, by0, bx1, by1) = hull(&b);
        let (bw, bh) = (bx1 - bx0, by1 - by0);
        let m = |r: &mut R| r.uni(cfg.margin[0], cfg.margin[1]);
        let cx0 = (bx0 - m(rng) * bw).floor().max(0.0);
        let cy0 = (by0 - m(rng) * bh).floor().max(0.0);
        let cx1 = (bx1 + m(rng) * bw).ceil().min(f64::from(cam.width));
        let cy1 = (by1 + m(rng) * bh).ceil().min(f64::from(cam.height));
        let (cw, ch) = ((cx1 - cx0).max(1.0) as usize, (cy1 - cy0).max(1.0) as usize);
        // Large crops are downscaled by the network anyway: no supersampling needed there.
        let ss = if cw.max(ch) > 220 { 1 } else { cfg.supersample };
        let mut target = Target::new(cx0, cy0, cw, ch, ss);

        // Neighbouring vehicles.
        let neighbours = self.neighbours(setup, cand, &pose, rng);
        let target_mesh = setup.model.mesh.placed(&pose);
        let light = &setup.light;
        target.draw(cam, light, &target_mesh.tris, ID_TARGET);
        let mut placed = Vec::with_capacity(neighbours.len());
        for (k, (spec, p)) in neighbours.iter().enumerate() {
            if !box_may_overlap(cam, spec, p, &target) {
                // Still needed for shadows if close.
                placed.push((spec, *p, None));
                continue;
            }
            let mesh = spec.build().placed(p);
            target.draw(cam, light, &mesh.tris, 2 + k as u32);
            placed.push((spec, *p, Some(mesh)));
        }
        if let SetupBackdrop::World(world) = &setup.backdrop {
            for prop in &world.props {
                if prop_may_overlap(cam, prop.lo, prop.hi, &target) {
                    target.draw(cam, light, &prop.mesh.tris, ID_PROP);
                }
            }
        }
        // Shadows: sun shadows (from low-poly proxies) and contact shadows of the vehicles,
        // shadows of thin props.
        target.draw_shadow(cam, light, &setup.model.shadow.placed(&pose).tris);
        let ao = 0.35 + 0.3 * (1.0 - light.shadow_strength);
        target.draw_contact_shadow(cam, &pose, setup.spec.length, setup.spec.width, ao);
        for (spec, p, _) in &placed {
            let d = ((p.x - pose.x).powi(2) + (p.y - pose.y).powi(2)).sqrt();
            if d > 40.0 {
                continue;
            }
            target.draw_shadow(cam, light, &spec.shadow_box().placed(p).tris);
            target.draw_contact_shadow(cam, p, spec.length, spec.width, ao);
        }
        if let SetupBackdrop::World(world) = &setup.backdrop {
            for prop in world.props.iter().filter(|p| p.casts_shadow) {
                let c = (prop.lo + prop.hi) * 0.5;
                if ((c.x - pose.x).powi(2) + (c.y - pose.y).powi(2)).sqrt() < 40.0 {
                    target.draw_shadow(cam, light, &prop.mesh.tris);
                }
            }
        }
        let visible_px = target.count_id(ID_TARGET);
        let alone = target.coverage(cam, &target_mesh.tris).max(1);
        let backdrop = match &setup.backdrop {
            SetupBackdrop::World(w) => Backdrop::World(w),
            // The index was drawn from this very list.
            SetupBackdrop::Real(i) => Backdrop::Photo(&self.backgrounds[*i].image),
        };
        target.fill_background(cam, light, backdrop);
        let image = target.resolve(light);
        let origin = [cx0, cy0];
        let vp1 = cam.vp_of_heading(pose.heading).unwrap_or([f64::NAN; 2]);
        let vp2 = cam
            .vp_of_heading(pose.heading + FRAC_PI_2)
            .unwrap_or([f64::NAN; 2]);
        let rel = |p: [f64; 2]| [p[0] - origin[0], p[1] - origin[1]];
        Rendered {
            image,
            origin,
            pose,
            bb3d: b.map(rel),
            vp1: rel(vp1),
            vp2: rel(vp2),
            visible: (visible_px as f64 / alone as f64).min(1.0),
        }
    }

    /// Other vehicles around the target: traffic on the lanes or parked cars in the stalls.
    fn neighbours<R: Rng>(
        &self,
        setup: &Setup,
        cand: &Candidate,
        pose: &Pose,
        rng: &mut R,
    ) -> Vec<(VehicleSpec, Pose)> {
        let mut out: Vec<(VehicleSpec, Pose)> = Vec::new();
        let fits = |spec: &VehicleSpec, p: &Pose, out: &Vec<(VehicleSpec, Pose)>| {
            !overlaps(&setup.spec, pose, spec, p)
                && out.iter().all(|(s, q)| !overlaps(s, q, spec, p))
        };
        match &setup.backdrop {
            SetupBackdrop::World(world) => {
                let near =
                    |p: &Pose| ((p.x - pose.x).powi(2) + (p.y - pose.y).powi(2)).sqrt() < 90.0;
                if world.layout == LayoutKind::Parking {
                    for (i, st) in world.stalls.iter().enumerate() {
                        if Some(i) == cand.stall || !near(st) || !rng.chance(setup.occupancy) {
                            continue;
                        }
                        let kind = if rng.chance(0.9) {
                            car_kind(rng)
                        } else {
                            VehicleKind::Van
                        };
                        let spec = VehicleSpec::random(rng, kind);
                        let mut p = *st;
                        if rng.chance(0.35) {
                            p.heading += PI;
                        }
                        p.heading += (rng.normal() * 2.0).to_radians();
                        if fits(&spec, &p, &out) {
                            out.push((spec, p));
                        }
                    }
                }
                for lane in &world.lanes {
                    let len = lane.path.length();
                    let gap = if world.layout == LayoutKind::Parking {
                        setup.gap_m * 3.0
                    } else {
                        setup.gap_m
                    };
                    let mut s = rng.uni(0.0, gap);
                    while s < len {
                        let p = lane.path.pose_at(s);
                        let spec = VehicleSpec::random_any(rng);
                        let adv = spec.length + 1.5 + rng.uni(0.0, 2.0 * gap);
                        if near(&p) && fits(&spec, &p, &out) {
                            out.push((spec, p));
                        }
                        s += adv;
                    }
                }
            }
            SetupBackdrop::Real(i) => {
                let Some(bg) = self.backgrounds.get(*i) else {
                    return out;
                };
                let n = rng.int(0, 2);
                for _ in 0..n {
                    if bg.road_points.is_empty() {
                        break;
                    }
                    let q = bg.road_points[rng.int(0, bg.road_points.len() as i64 - 1) as usize];
                    let Some(g) = setup.camera.ground_point(q[0], q[1]) else {
                        continue;
                    };
                    let spec = VehicleSpec::random_any(rng);
                    let p = Pose {
                        x: g.x,
                        y: g.y,
                        heading: if rng.chance(0.5) { 0.0 } else { PI },
                    };
                    if fits(&spec, &p, &out) {
                        out.push((spec, p));
                    }
                }
            }
        }
        out
    }
}

fn car_kind<R: Rng>(rng: &mut R) -> VehicleKind {
    [
        VehicleKind::Sedan,
        VehicleKind::Hatchback,
        VehicleKind::Wagon,
        VehicleKind::Suv,
    ][rng.int(0, 3) as usize]
}

struct Rendered {
    image: image::RgbImage,
    origin: [f64; 2],
    pose: Pose,
    bb3d: [[f64; 2]; 8],
    vp1: [f64; 2],
    vp2: [f64; 2],
    visible: f64,
}

/// True when two vehicle footprints (with 0.4 m clearance) intersect (separating axis test).
fn overlaps(a: &VehicleSpec, pa: &Pose, b: &VehicleSpec, pb: &Pose) -> bool {
    let rect = |s: &VehicleSpec, p: &Pose| {
        let (hl, hw) = (s.length / 2.0 + 0.4, s.width / 2.0 + 0.3);
        [
            V3::new(hl, hw, 0.0),
            V3::new(hl, -hw, 0.0),
            V3::new(-hl, -hw, 0.0),
            V3::new(-hl, hw, 0.0),
        ]
        .map(|c| p.apply(c))
    };
    let ra = rect(a, pa);
    let rb = rect(b, pb);
    for p in [pa, pb] {
        for axis in [p.heading, p.heading + FRAC_PI_2] {
            let (s, c) = axis.sin_cos();
            let proj = |q: &[V3; 4]| {
                let v: Vec<f64> = q.iter().map(|v| v.x * c + v.y * s).collect();
                (
                    v.iter().cloned().fold(f64::MAX, f64::min),
                    v.iter().cloned().fold(f64::MIN, f64::max),
                )
            };
            let (a0, a1) = proj(&ra);
            let (b0, b1) = proj(&rb);
            if a1 < b0 || b1 < a0 {
                return false;
            }
        }
    }
    true
}

fn box_may_overlap(cam: &Camera, spec: &VehicleSpec, pose: &Pose, t: &Target) -> bool {
    let lo = V3::new(-spec.length / 2.0 - 0.3, -spec.width / 2.0 - 0.4, 0.0);
    let hi = V3::new(spec.length / 2.0 + 0.3, spec.width / 2.0 + 0.4, spec.height);
    let corners = corners(lo, hi).map(|c| pose.apply(c));
    points_may_overlap(cam, &corners, t)
}

fn prop_may_overlap(cam: &Camera, lo: V3, hi: V3, t: &Target) -> bool {
    points_may_overlap(cam, &corners(lo, hi), t)
}

fn corners(lo: V3, hi: V3) -> [V3; 8] {
    [
        V3::new(lo.x, lo.y, lo.z),
        V3::new(hi.x, lo.y, lo.z),
        V3::new(hi.x, hi.y, lo.z),
        V3::new(lo.x, hi.y, lo.z),
        V3::new(lo.x, lo.y, hi.z),
        V3::new(hi.x, lo.y, hi.z),
        V3::new(hi.x, hi.y, hi.z),
        V3::new(lo.x, hi.y, hi.z),
    ]
}

fn points_may_overlap(cam: &Camera, pts: &[V3], t: &Target) -> bool {
    let mut h = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    let mut behind = 0;
    for p in pts {
        let c = cam.to_camera(*p);
        if c.z < crate::raster::NEAR_M {
            behind += 1;
            continue;
        }
        let Some(q) = cam.project_cam(c) else {
            continue;
        };
        h = (h.0.min(q[0]), h.1.min(q[1]), h.2.max(q[0]), h.3.max(q[1]));
    }
    if behind == pts.len() {
        return false;
    }
    if behind > 0 {
        return true;
    }
    let s = f64::from(t.ss);
    let (x1, y1) = (t.x0 + t.w as f64 / s, t.y0 + t.h as f64 / s);
    h.2 >= t.x0 && h.0 <= x1 && h.3 >= t.y0 && h.1 <= y1
}

/// Map the n-th vehicle of a split to a global vehicle id (so that `id % 10` gives the split).
pub fn vehicle_of_split(split: Split, n: u64) -> u64 {
    match split {
        Split::Validation => n * 10,
        Split::Test => n * 10 + 1,
        Split::Train => (n / 8) * 10 + 2 + n % 8,
    }
}

/// A [`vpcal_data::SampleSource`] that renders crops on the fly: sample `index` of a split is
/// always the same image for the same seed and configuration.
#[derive(Debug, Clone)]
pub struct SynthCropSource {
    generator: CropGenerator,
    split: Split,
    len: usize,
}

impl SynthCropSource {
    /// `len` samples of `split` (instances of consecutive vehicles of that split).
    pub fn new(generator: CropGenerator, split: Split, len: usize) -> SynthCropSource {
        SynthCropSource {
            generator,
            split,
            len,
        }
    }

    /// A source from a textual spec, for `--data synth:<spec>` style flags:
    /// `seed=S,len=N[,real=BCS_ROOT][,real_fraction=F][,instances=K][,clean]`.
    /// `len` is the size of the train split; validation and test get `len / 8` each (the
    /// vehicle ratio of the split rule).
    ///
    /// # Errors
    /// [`SynthError::Config`] for an unknown key or a bad value, loading errors for `real`.
    pub fn from_spec(spec: &str, split: Split) -> Result<SynthCropSource, SynthError> {
        let mut cfg = CropConfig::default();
        let mut seed = 0u64;
        let mut len: Option<usize> = None;
        let mut real: Option<std::path::PathBuf> = None;
        for part in spec.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let (k, v) = part.split_once('=').unwrap_or((part, ""));
            let num = |what: &str| -> Result<f64, SynthError> {
                v.parse::<f64>()
                    .ok()
                    .filter(|x| x.is_finite() && *x >= 0.0)
                    .ok_or_else(|| SynthError::Config(format!("synthetic source spec {spec:?}: {what} = {v:?} is not a non-negative number")))
            };
            match k {
                "seed" => seed = num("seed")? as u64,
                "len" => len = Some(num("len")? as usize),
                "real" => real = Some(v.into()),
                "real_fraction" => cfg.real_fraction = num("real_fraction")?.min(1.0),
                "instances" => cfg.instances = (num("instances")? as u32).max(1),
                "clean" => cfg.artefacts = false,
                other => {
                    return Err(SynthError::Config(format!(
                        "synthetic source spec {spec:?}: unknown key {other:?} (expected seed, len, real, real_fraction, instances, clean)"
                    )))
                }
            }
        }
        let len = len.ok_or_else(|| {
            SynthError::Config(format!("synthetic source spec {spec:?}: missing len=N"))
        })?;
        let backgrounds = match real {
            Some(root) => RealBackground::load_bcs_root(&root)?,
            None => Vec::new(),
        };
        let generator = CropGenerator::new(cfg, seed, Arc::new(backgrounds))?;
        let n = if split == Split::Train {
            len
        } else {
            (len / 8).max(1)
        };
        Ok(SynthCropSource::new(generator, split, n))
    }

    /// Generate with metadata.
    ///
    /// # Errors
    /// As [`CropGenerator::generate`].
    pub fn get_full(&self, index: usize) -> Result<CropSample, SynthError> {
        let k = u64::from(self.generator.cfg.instances);
        let n = index as u64 / k;
        let inst = (index as u64 % k) as u32;
        self.generator
            .generate(vehicle_of_split(self.split, n), inst)
    }
}

impl vpcal_data::SampleSource for SynthCropSource {
    fn len(&self) -> usize {
        self.len
    }
    fn split(&self) -> Split {
        self.split
    }
    fn get(&self, index: usize) -> Result<Sample, vpcal_data::DataError> {
        if index >= self.len {
            return Err(vpcal_data::DataError::Sample {
                path: "<synthetic>".into(),
                sample: index.to_string(),
                message: format!("index {index} out of range (len {})", self.len),
            });
        }
        self.get_full(index)
            .map(|c| c.sample)
            .map_err(|e| vpcal_data::DataError::Sample {
                path: "<synthetic>".into(),
                sample: index.to_string(),
                message: e.full_message(),
            })
    }
}
