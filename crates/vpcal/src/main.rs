//! `vpcal`: calibrate fixed traffic cameras from the vanishing points of the vehicles they see.
//!
//! A thin binary: flags are parsed by clap into one `Args` struct per subcommand (in `cmd/`),
//! each subcommand turns its flags into the library's settings, calls the library (`vpcal`,
//! the other crates) and prints. Exit codes: 0 done; 1 an error (bad input, I/O), printed with
//! its whole context chain; 2 a wrong command line; 3 the run completed but could not support
//! a calibration (`calibrate`, `aggregate`, `demo`).

mod cmd;

/// The exit codes, for every command's help.
const EXIT_CODES: &str = "Exit codes: 0 done; 1 an error (bad input, I/O), with its message; 2 a \
wrong command line; 3 the footage could not support a calibration (calibrate, aggregate, demo).\n\
Guide: README.md; the calibration file's fields: docs/calibration-file.md.";

use clap::{Parser, Subcommand};

/// Calibrate fixed traffic cameras from the vanishing points of the vehicles they see.
#[derive(Debug, Parser)]
#[command(name = "vpcal", version, about, long_about = None, after_help = EXIT_CODES)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

// One variant per subcommand; each lives in `cmd/<name>.rs` with `Args` and `run`.
#[derive(Debug, Subcommand)]
enum Command {
    /// Calibrate a fixed traffic camera from a video, an image folder or an image.
    Calibrate(Box<cmd::calibrate::Args>),
    /// Render a synthetic traffic clip with a known camera, calibrate it and compare.
    Demo(cmd::demo::Args),
    /// Find the vehicles in footage with a detector and write their boxes.
    Detect(cmd::detect::Args),
    /// Add a metric scale to a calibration from one known distance on the road.
    Scale(cmd::measure::ScaleArgs),
    /// Measure distances on the road with a calibration.
    Measure(cmd::measure::MeasureArgs),
    /// Export a calibration for other tools (OpenCV FileStorage YAML).
    Export(cmd::measure::ExportArgs),
    /// Measure saved vehicle tracks again with a calibration (after `vpcal scale`).
    Speeds(cmd::measure::SpeedsArgs),
    /// Turn per-vehicle VP pairs (a VPout JSON file) into a camera calibration.
    Aggregate(cmd::aggregate::Args),
    /// Training data: preview the augmentation, benchmark the batch pipeline.
    #[command(subcommand)]
    Data(cmd::data::DataCommand),
    /// Evaluate calibrations against BrnoCompSpeed or BrnoCarPark ground truth.
    #[command(subcommand)]
    Eval(cmd::eval::EvalCommand),
    /// Synthetic data: training crops, traffic scenes with ground truth, benchmark suite.
    #[command(subcommand)]
    Synth(cmd::synth::SynthCommand),
    /// Label the vehicles of real footage with its calibrated camera's VPs (training crops).
    Label(cmd::label::Args),
    /// Train the VP network (or a regression baseline) with checkpoints and exact resume.
    Train(cmd::train::Args),
    /// Predict the VPs of vehicle crops with trained weights; writes heatmap PNGs.
    Predict(cmd::predict::Args),
    /// Throughput of the VP network, optionally against PyTorch (developer tool).
    #[command(hide = true)]
    BenchNet(cmd::bench_net::Args),
    /// Frames/s of `calibrate` on a clip, and the time of each stage (developer tool).
    #[command(hide = true)]
    BenchPipeline(cmd::bench_pipeline::Args),
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Calibrate(args) => return exit_code(cmd::calibrate::run(*args)),
        Command::Demo(args) => return exit_code(cmd::demo::run(args)),
        Command::Aggregate(args) => return exit_code(cmd::aggregate::run(args)),
        Command::Label(args) => return exit_code(cmd::label::run(args)),
        Command::Detect(args) => cmd::detect::run(args),
        Command::Scale(args) => cmd::measure::run_scale(args),
        Command::Measure(args) => cmd::measure::run_measure(args),
        Command::Export(args) => cmd::measure::run_export(args),
        Command::Speeds(args) => cmd::measure::run_speeds(args),
        Command::Data(args) => cmd::data::run(args),
        Command::Eval(args) => cmd::eval::run(args),
        Command::Synth(args) => cmd::synth::run(args),
        Command::Train(args) => cmd::train::run(args),
        Command::Predict(args) => cmd::predict::run(args),
        Command::BenchNet(args) => cmd::bench_net::run(args),
        Command::BenchPipeline(args) => cmd::bench_pipeline::run(args),
    };
    exit_code(result.map(|()| cmd::Exit::Success))
}

/// The exit code of a subcommand's result; errors are printed with their context chain.
fn exit_code(result: anyhow::Result<cmd::Exit>) -> std::process::ExitCode {
    match result {
        Ok(exit) => exit.code(),
        Err(err) if err.downcast_ref::<cmd::UsageError>().is_some() => {
            eprintln!("error: {err:#}");
            std::process::ExitCode::from(cmd::EXIT_USAGE)
        }
        Err(err) => {
            eprintln!("error: {err:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
