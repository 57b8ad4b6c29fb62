//! Subcommands: one module each, with `Args` and `run`.

pub mod aggregate;
pub mod args;
pub mod bench_net;
pub mod calibrate;
pub mod data;
pub mod demo;
pub mod detect;
pub mod eval;
pub mod measure;
pub mod overlay;
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
