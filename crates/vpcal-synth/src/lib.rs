//! vpcal-synth: a CPU software renderer of traffic seen by fixed cameras, with exact ground
//! truth, for training (BoxCars-like crops) and end-to-end calibration benchmarks
//! (BrnoCompSpeed-like scenes).
//!
//! # Entry points
//! - [`crops::CropGenerator`]: deterministic training crops (`(seed, vehicle, instance)` ->
//!   image, 3D box, VP1, VP2); [`crops::SynthCropSource`] serves them on the fly as a
//!   [`vpcal_data::SampleSource`]; [`dataset::write_crops`] / [`dataset::CropDirSource`] write
//!   and read the on-disk format documented in `FORMAT.md`.
//! - [`scene::SceneSpec`] + [`scene::render_scene`]: a video of moving traffic from a fixed camera
//!   with BrnoCompSpeed-style ground truth; [`scene::suite_specs`] is the benchmark suite.
//! - [`sheet`]: contact sheets and overlays to check the ground truth by eye.
//!
//! From the command line (crate `vpcal`):
//! ```text
//! vpcal synth crops --count 10000 --out crops/ --seed 1 [--real-bg ../shared/data/bcs] [--sheet]
//! vpcal synth scene --layout highway --frames 300 --out scenes/ --seed 2 [--width 1920 --height 1080]
//! vpcal synth suite --out suite/ [--frames 150]        # 14 scenes, focal 600-4000 px
//! vpcal synth sheet --out sheet.png [--from crops/]     # crops with 3D boxes and VP rays
//! vpcal synth bench                                     # crops/s and frames/s
//! vpcal eval bcs --dataset suite/dataset --results suite/results   # scores system_*.json
//! ```
//! A training flag can use [`crops::SynthCropSource::from_spec`]
//! (`seed=S,len=N[,real=BCS_ROOT]`) or [`dataset::CropDirSource`] (a crops directory).
//!
//! # What is modelled
//! Cars (sedan, hatchback, wagon, SUV, pickup), vans, trucks (rigid and semi) and buses as
//! lofted bodies (cars smooth-shaded, others faceted) with glass cabins, pillars, wheels in arches, lamps, grille and
//! plates, random sizes and colours; roads with lane markings, tyre tracks, patches,
//! crossings, parking stalls; poles, rails, walls, gantries, signs, trees, buildings; sun/sky/
//! overcast/dusk light with cast and contact shadows and haze; optional real BrnoCompSpeed
//! views as backgrounds; blur, motion blur, sensor noise, tone changes and JPEG artefacts.
//! Not modelled: night, rain, lens distortion, interiors, textures on the vehicles.
//!
//! # Conventions
//! - World: metres, z up, the road is the plane z = 0. Vehicles: local x forward, y left, z up,
//!   origin at the centre of the footprint; heading in radians from world +x towards +y.
//! - Camera ([`camera::Camera`]): `X_cam = R (X_world - C)`, camera x right, y down, z forward;
//!   image point = `(f x/z + px, f y/z + py)`.
//! - Pixels: x right, y down; pixel (i, j) covers [i, i+1) x [j, j+1) in continuous image
//!   coordinates, so its centre is (i + 0.5, j + 0.5). The renderer samples exactly there. The
//!   true principal point of generated cameras is the image centre (W/2, H/2) in this
//!   convention and is written into every ground-truth file (note: BrnoCompSpeed's own files
//!   use (W/2 + 0.5, H/2 + 0.5)).
//! - VP1 of a vehicle: vanishing point of its heading (the direction it faces); VP2: of the
//!   horizontal direction orthogonal to it; VP3: of the vertical. The horizon passes through
//!   every vehicle's VP1 and VP2.
//! - BrnoCompSpeed `scale` (DESIGN.md §3): the BCS back-projection puts the road plane at
//!   distance |n.C + 10| from the camera centre C = (px, py, 0), so
//!   `scale = camera height / |n.C + 10|` ([`camera::Camera::bcs_scale`]).
//! - Colours are computed in linear RGB and encoded to sRGB at the end.

pub mod camera;
pub mod crops;
pub mod dataset;
mod error;
pub mod math;
pub mod mesh;
pub mod post;
pub mod raster;
pub mod realbg;
pub mod scene;
pub mod shade;
pub mod sheet;
pub mod speed_truth;
pub mod truth;
pub mod vehicle;
pub mod view;
pub mod world;

pub use crops::{CropConfig, CropGenerator, CropSample, SynthCropSource};
pub use dataset::{write_crops, write_index, CropDirSource, RealMeta, SampleMeta, SampleRecord};
pub use error::SynthError;
pub use realbg::RealBackground;
