//! `vpcal`: calibrate fixed traffic cameras from the vanishing points of the vehicles they see.
//!
//! A thin binary: flags are parsed by clap into one `Args` struct per subcommand (in `cmd/`),
//! each subcommand validates its flags and calls the library crates. Errors are printed with
//! their whole context chain and give exit code 1; bad flags give clap's exit code 2.

mod cmd;

use clap::{Parser, Subcommand};

/// Calibrate fixed traffic cameras from the vanishing points of the vehicles they see.
#[derive(Debug, Parser)]
#[command(name = "vpcal", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

// One variant per subcommand; each lives in `cmd/<name>.rs` with `Args` and `run`.
#[derive(Debug, Subcommand)]
enum Command {
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
    /// Train the VP network (or a regression baseline) with checkpoints and exact resume.
    Train(cmd::train::Args),
    /// Predict the VPs of vehicle crops with trained weights; writes heatmap PNGs.
    Predict(cmd::predict::Args),
    /// Throughput of the VP network, optionally against PyTorch (developer tool).
    #[command(hide = true)]
    BenchNet(cmd::bench_net::Args),
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Aggregate(args) => cmd::aggregate::run(args),
        Command::Data(args) => cmd::data::run(args),
        Command::Eval(args) => cmd::eval::run(args),
        Command::Synth(args) => cmd::synth::run(args),
        Command::Train(args) => cmd::train::run(args),
        Command::Predict(args) => cmd::predict::run(args),
        Command::BenchNet(args) => cmd::bench_net::run(args),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("error: {err:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
