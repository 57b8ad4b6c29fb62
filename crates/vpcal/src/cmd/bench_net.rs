//! `vpcal bench-net` (hidden): throughput of the VP network, forward (batch 10) and one
//! training step (batch 8), optionally against the same network in PyTorch run in the same
//! invocation with the same thread count (`--torch PYTHON`), printing crops/s and the ratio.

use std::io::Write;
use std::path::PathBuf;
use std::process::Command;

use anyhow::{bail, Context, Result};
use clap::Args as ClapArgs;
use vpcal_net::bench::{BenchOptions, BenchResult};
use vpcal_net::ModelConfig;

/// The PyTorch peer, embedded so that the binary runs it from anywhere.
const TORCH_SCRIPT: &str = include_str!("../../../../scripts/bench_net.py");

#[derive(Debug, ClapArgs)]
pub struct Args {
    /// Model size: `paper` or `tiny`.
    #[arg(long, default_value = "paper")]
    pub preset: String,
    /// Crops per forward pass.
    #[arg(long, default_value_t = 10)]
    pub forward_batch: usize,
    /// Crops per training step.
    #[arg(long, default_value_t = 8)]
    pub train_batch: usize,
    /// Untimed runs before measuring.
    #[arg(long, default_value_t = 1)]
    pub warmup: usize,
    /// Timed runs (the median is reported).
    #[arg(long, default_value_t = 3)]
    pub runs: usize,
    /// CPU threads for both frameworks (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Python interpreter with torch installed: also run the PyTorch peer and print ratios.
    #[arg(long, value_name = "PYTHON")]
    pub torch: Option<PathBuf>,
    /// Device for vpcal: `cpu` or `wgpu` (the PyTorch peer always runs on the CPU).
    #[arg(long, default_value = "cpu", value_parser = super::args::device)]
    pub device: String,
    /// Print the results as JSON.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, serde::Deserialize, serde::Serialize)]
struct TorchResult {
    framework: String,
    threads: usize,
    params: usize,
    forward_s: f64,
    forward_crops_per_s: f64,
    train_step_s: f64,
    train_crops_per_s: f64,
}

fn run_torch(python: &PathBuf, a: &Args, threads: usize) -> Result<TorchResult> {
    let script = tempfile_path("vpcal-bench-net", ".py");
    let mut f =
        std::fs::File::create(&script).with_context(|| format!("writing {}", script.display()))?;
    f.write_all(TORCH_SCRIPT.as_bytes())?;
    drop(f);
    let out = Command::new(python)
        .arg(&script)
        .args(["--threads", &threads.to_string()])
        .args(["--forward-batch", &a.forward_batch.to_string()])
        .args(["--train-batch", &a.train_batch.to_string()])
        .args(["--warmup", &a.warmup.to_string()])
        .args(["--runs", &a.runs.to_string()])
        .args(["--preset", &a.preset])
        .output()
        .with_context(|| format!("running {}", python.display()));
    let _ = std::fs::remove_file(&script);
    let out = out?;
    if !out.status.success() {
        bail!(
            "the PyTorch benchmark failed ({}): {}",
            out.status,
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let stdout = String::from_utf8_lossy(&out.stdout);
    let line = stdout
        .lines()
        .rev()
        .find(|l| l.trim_start().starts_with('{'))
        .context("the PyTorch benchmark printed no JSON result")?;
    serde_json::from_str(line).context("parsing the PyTorch benchmark result")
}

fn tempfile_path(prefix: &str, suffix: &str) -> PathBuf {
    std::env::temp_dir().join(format!("{prefix}-{}{suffix}", std::process::id()))
}

/// Run `vpcal bench-net`.
pub fn run(a: Args) -> Result<()> {
    let threads = a
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    // burn's CPU backend uses rayon's global pool.
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build_global()
        .context("configuring the thread pool")?;
    let config = ModelConfig::preset(&a.preset)?;
    let device = vpcal_net::device::select(&a.device)?;
    let opts = BenchOptions {
        forward_batch: a.forward_batch,
        train_batch: a.train_batch,
        warmup: a.warmup,
        runs: a.runs,
    };
    eprintln!(
        "vpcal: {} model, forward batch {}, train batch {}, {} threads ...",
        a.preset, a.forward_batch, a.train_batch, threads
    );
    let ours: BenchResult = vpcal_net::bench::run(&config, &device, &opts)?;
    let torch = match &a.torch {
        Some(py) => {
            eprintln!("PyTorch ({}) ...", py.display());
            Some(run_torch(py, &a, threads)?)
        }
        None => None,
    };
    if a.json {
        println!(
            "{}",
            serde_json::json!({ "threads": threads, "device": a.device, "vpcal": ours, "torch": torch })
        );
        return Ok(());
    }
    println!(
        "model {} ({} parameters), {threads} threads, vpcal device {}",
        a.preset, ours.params, a.device
    );
    println!(
        "{:<28} {:>12} {:>12} {:>10}",
        "", "vpcal", "PyTorch", "ratio"
    );
    let row = |name: &str, v: f64, t: Option<f64>| {
        let (ts, rs) = match t {
            Some(t) => (format!("{t:.2}"), format!("{:.2}x", v / t)),
            None => ("-".into(), "-".into()),
        };
        println!("{name:<28} {v:>12.2} {ts:>12} {rs:>10}");
    };
    row(
        &format!("forward b{} crops/s", a.forward_batch),
        ours.forward_crops_per_s,
        torch.as_ref().map(|t| t.forward_crops_per_s),
    );
    row(
        &format!("train step b{} crops/s", a.train_batch),
        ours.train_crops_per_s,
        torch.as_ref().map(|t| t.train_crops_per_s),
    );
    println!(
        "(vpcal forward {:.3} s, train step {:.3} s{})",
        ours.forward_s,
        ours.train_step_s,
        torch.as_ref().map_or(String::new(), |t| format!(
            "; {} forward {:.3} s, train step {:.3} s, {} parameters",
            t.framework, t.forward_s, t.train_step_s, t.params
        ))
    );
    Ok(())
}
