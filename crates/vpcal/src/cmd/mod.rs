//! Subcommands: one module each, with `Args` and `run`; they parse flags, call the library
//! ([`vpcal`]) and print.

pub mod aggregate;
pub mod args;
pub mod bench_net;
pub mod bench_pipeline;
pub mod calibrate;
pub mod data;
pub mod demo;
pub mod detect;
pub mod eval;
pub mod kitti;
pub mod label;
pub mod measure;
pub mod predict;
pub mod synth;
pub mod train;

/// A progress bar on stderr (hidden with `quiet`); `len` may be unknown.
pub fn progress_bar(len: Option<u64>, what: &str, quiet: bool) -> indicatif::ProgressBar {
    if quiet {
        return indicatif::ProgressBar::hidden();
    }
    let (pb, template) = match len {
        Some(n) => (
            indicatif::ProgressBar::new(n),
            format!("{what} {{bar:30}} {{pos}}/{{len}} [{{elapsed_precise}} eta {{eta}}] {{msg}}"),
        ),
        None => (
            indicatif::ProgressBar::new_spinner(),
            format!("{what} {{spinner}} {{pos}} [{{elapsed_precise}}] {{msg}}"),
        ),
    };
    if let Ok(style) = indicatif::ProgressStyle::with_template(&template) {
        pb.set_style(style);
    }
    pb
}

/// How a command ended, beyond plain success and errors (see the README's exit code table).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Exit {
    /// 0: done.
    Success,
    /// 3: the run completed, but the footage or records could not support a calibration.
    NotEnoughEvidence,
}

/// Exit code of a run that completed but could not support a calibration.
pub const EXIT_NOT_ENOUGH_EVIDENCE: u8 = 3;
/// Exit code of a command line that is wrong (clap uses it too).
pub const EXIT_USAGE: u8 = 2;

impl Exit {
    pub fn code(self) -> std::process::ExitCode {
        match self {
            Exit::Success => std::process::ExitCode::SUCCESS,
            Exit::NotEnoughEvidence => std::process::ExitCode::from(EXIT_NOT_ENOUGH_EVIDENCE),
        }
    }
}

/// A command line that cannot work (exit code 2, like clap's own usage errors).
#[derive(Debug)]
pub struct UsageError(pub String);

impl std::fmt::Display for UsageError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for UsageError {}

/// The pipeline's progress as a terminal bar with the frame rate and box count.
pub struct FrameBar {
    bar: std::sync::OnceLock<indicatif::ProgressBar>,
    what: &'static str,
    quiet: bool,
}

impl FrameBar {
    pub fn new(what: &'static str, quiet: bool) -> FrameBar {
        FrameBar {
            bar: std::sync::OnceLock::new(),
            what,
            quiet,
        }
    }

    fn with(&self, f: impl FnOnce(&indicatif::ProgressBar)) {
        if let Some(bar) = self.bar.get() {
            f(bar);
        }
    }
}

impl vpcal::progress::Progress for FrameBar {
    fn start(&self, frames: Option<u64>) {
        let _ = self.bar.set(progress_bar(frames, self.what, self.quiet));
    }

    fn add_frames(&self, more: u64) {
        self.with(|b| b.inc_length(more));
    }

    fn frame_done(&self, at: &vpcal::progress::FrameProgress) {
        self.with(|b| {
            b.inc(1);
            b.set_message(format!(
                "{:.1} frames/s, {} vehicle boxes",
                at.frames_per_second(),
                at.vehicle_boxes
            ));
        });
    }

    fn finish(&self) {
        self.with(indicatif::ProgressBar::finish_and_clear);
    }
}
