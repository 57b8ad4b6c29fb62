//! vpcal: calibrate fixed traffic cameras from the vanishing points of the vehicles they see.
//!
//! The whole pipeline as a library, for the `vpcal` binary, the Python package and anyone who
//! calls it in process:
//!
//! - [`pipeline`]: [`PipelineConfig`], [`run_pipeline`] (footage to per-vehicle VP records)
//!   and [`calibrate`] (records to a camera).
//! - [`detector`]: which vehicle detector, and its settings.
//! - [`crop_plan`]: which boxes of a followed vehicle go through the VP network.
//! - [`aggregate`]: per-vehicle VP pairs to one camera, with a summary and evidence.
//! - [`output`]: the calibration file, the BrnoCompSpeed system file and vehicle records.
//! - [`overlay`]: the picture of a calibration (horizon, road grid, vehicle VP directions).
//! - [`report`]: the self-contained HTML report of a calibration (`calibrate --report`).
//! - [`model`]: the bundled VP network.
//! - [`progress`]: progress reports of long work.
//! - [`road`]: metric measurements on the road plane (scale, road points, distances).
//! - [`road_focal`]: the focal length from known road lengths in two directions.
//! - [`plausible`]: what traffic cameras and road traffic can be (a calibration's status).
//! - [`label`]: self-labelled training crops from real footage (`vpcal label`).
//!
//! The building blocks live in the other crates of the workspace: geometry and aggregation
//! (`vpcal-geom`), file formats (`vpcal-formats`, with the calibration file type), the network
//! (`vpcal-net`), footage and detectors (`vpcal-video`), the synthetic world (`vpcal-synth`).

pub mod aggregate;
pub mod autoscale;
pub mod crop_plan;
pub mod detector;
pub mod kitti;
pub mod label;
pub mod markings;
pub mod model;
pub mod output;
pub mod overlay;
pub mod pipeline;
pub mod plausible;
pub mod progress;
pub mod report;
pub mod road;
pub mod road_focal;
pub mod tracks;

pub use pipeline::{calibrate, run_pipeline, run_pipeline_on, PipelineConfig, PipelineOutput};
pub use vpcal_formats::calib::CalibrationFile;
