//! The library in process: calibrate a video, print the camera, write the calibration file.
//!
//! `cargo run --release --example calibrate -- VIDEO [CALIB.json]`

use std::path::Path;

use vpcal::progress::Silent;
use vpcal::{calibrate, run_pipeline, PipelineConfig};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(video) = args.first() else {
        anyhow::bail!("usage: calibrate VIDEO [CALIB.json]");
    };
    // What `vpcal calibrate` does without flags.
    let config = PipelineConfig::default();
    let out = run_pipeline(Path::new(video), &config, &Silent)?;
    let (camera, aggregated) = calibrate(&out, &config)?;
    println!(
        "f = {:.0} px, horizon {:.2}°; {}",
        camera.focal_px,
        camera.roll().to_degrees(),
        aggregated.summary
    );
    if let Some(path) = args.get(1) {
        vpcal::output::calibration_file(&out, &config, &camera, &aggregated)
            .write(Path::new(path))?;
    }
    Ok(())
}
