//! `visnav`: the command-line tool. A thin layer over the library crates: argument parsing,
//! progress bars, file output and exit codes live here; the algorithms live in the crates.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod commands;
mod interrupt;
mod live;
mod progress;

/// Robust visual navigation: camera in, trajectory, depth and uncertainty out.
#[derive(Debug, Parser)]
#[command(name = "visnav", version, about, long_about = None, propagate_version = true)]
struct Cli {
    /// No progress bars, tables or info lines; warnings (skipped frames, dropped inputs) and
    /// errors are still printed.
    #[arg(long, short, global = true)]
    quiet: bool,
    /// Worker threads for the parallel stages (default: one per core; at most 4 per core).
    #[arg(long, global = true, value_name = "N")]
    threads: Option<std::num::NonZeroUsize>,
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run the main job on a built-in synthetic scene: render, estimate, evaluate, plot.
    Demo(commands::demo::Args),
    /// Score an estimated trajectory against ground truth (KITTI devkit metric, ATE, RPE).
    Eval(commands::eval::Args),
    /// Render a synthetic sequence with exact ground truth (poses, depth, flow) in KITTI layout.
    Synth(commands::synth::Args),
    /// Estimate the camera trajectory of a sequence (stereo or monocular).
    Odometry(Box<commands::odometry::Args>),
    /// Dense optical flow with per-pixel uncertainty between two images.
    Flow(commands::flow::Args),
    /// Evaluate dense flow and its uncertainty on Middlebury, KITTI or Sintel layouts.
    FlowEval(commands::flow_eval::Args),
    /// Optimise a pose graph (g2o format), robust to wrong loop closures.
    Posegraph(commands::posegraph::Args),
    /// Write a self-contained HTML report of an odometry run (plots, timings, flow/depth gallery).
    Report(commands::report::Args),
    /// Run lines of a batch manifest (one odometry run per JSON line; Slurm, Kubernetes, Ray).
    Batch(commands::batch::Args),
    /// Gather the status and KITTI scores of batch runs into one table (CSV, JSON).
    Summarize(commands::batch::SummarizeArgs),
    /// What visnav sees in an input: a bag's topics, or a sequence's frames and camera
    /// (`--check` decodes every frame).
    Info(commands::info::Args),
}

/// mimalloc: the flow stage frees and reallocates image-sized buffers many times a pair.
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// Keeps freed memory (`MIMALLOC_PURGE_DELAY=-1`, not mimalloc 3's 1000 ms;
/// docs/notes/2026-12-02-realtime-history.md, #24 step 4):
/// read as the process loads, so unless set the process `exec`s itself once with it set.
fn keep_freed_memory() {
    #[cfg(unix)]
    {
        use std::os::unix::process::CommandExt;
        const VAR: &str = "MIMALLOC_PURGE_DELAY";
        if let (Ok(exe), None) = (std::env::current_exe(), std::env::var_os(VAR)) {
            let mut args = std::env::args_os();
            let arg0 = args.next().unwrap_or_else(|| exe.clone().into());
            let mut command = std::process::Command::new(&exe);
            // returns only on failure: the run goes on with mimalloc's default
            let _ = command.arg0(arg0).args(args).env(VAR, "-1").exec();
        }
    }
}

/// Worker threads beyond this many per core only add start-up time and memory (issue 53:
/// `--threads 2000` on three frames ran past 60 s).
const MAX_THREADS_PER_CORE: usize = 4;

/// `--threads N` clamped to [`MAX_THREADS_PER_CORE`] times the cores, with a warning.
fn clamp_threads(requested: std::num::NonZeroUsize) -> usize {
    let cores = std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get);
    let max = MAX_THREADS_PER_CORE * cores;
    if requested.get() > max {
        log::warn!(
            "--threads {requested}: more than {MAX_THREADS_PER_CORE} per core ({cores} cores); using {max}"
        );
        max
    } else {
        requested.get()
    }
}

fn main() -> ExitCode {
    keep_freed_memory();
    let cli = Cli::parse();
    // --quiet silences progress, never warnings: a skipped frame must not pass unnoticed
    let level = if cli.quiet { "warn" } else { "info" };
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or(level))
        .format_timestamp(None)
        .format_target(false)
        .init();
    if let Some(n) = cli.threads.map(clamp_threads)
        && let Err(e) = rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
    {
        eprintln!("error: --threads {n}: {e}");
        return ExitCode::FAILURE;
    }
    let ctx = commands::Context { quiet: cli.quiet };
    let result = match &cli.command {
        Command::Demo(a) => commands::demo::run(a, &ctx),
        Command::Eval(a) => commands::eval::run(a, &ctx),
        Command::Synth(a) => commands::synth::run(a, &ctx),
        // a live input (`rtsp://…`, `/dev/video0`, `-`) has its own driver, on the same options
        Command::Odometry(a) if visnav_io::live::is_live_input(&a.sequence) => {
            commands::odometry_live::run(a, &ctx)
        }
        Command::Odometry(a) => commands::odometry::run(a, &ctx),
        Command::Flow(a) => commands::flow::run(a, &ctx),
        Command::FlowEval(a) => commands::flow_eval::run(a, &ctx),
        Command::Posegraph(a) => commands::posegraph::run(a, &ctx),
        Command::Report(a) => commands::report::run(a, &ctx),
        Command::Batch(a) => commands::batch::run(a, &ctx),
        Command::Summarize(a) => commands::batch::run_summarize(a, &ctx),
        Command::Info(a) => commands::info::run(a, &ctx),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", error_chain(&e));
            // batch runs tell bad input (2) from I/O failures (3)
            e.downcast_ref::<commands::batch::ExitWith>()
                .map_or(ExitCode::FAILURE, |x| ExitCode::from(x.code))
        }
    }
}

/// The error and its causes joined by `: `, each cause left out when the message so far already
/// ends with it (an error that prints its source, e.g. `path: Is a directory`, would otherwise
/// repeat it).
fn error_chain(e: &anyhow::Error) -> String {
    let mut out = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if out.ends_with(&text) {
            continue;
        }
        if !out.is_empty() {
            out.push_str(": ");
        }
        out.push_str(&text);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn error_chain_does_not_repeat_a_cause_its_error_already_prints() {
        let io = std::io::Error::from(std::io::ErrorKind::IsADirectory);
        let io_text = io.to_string();
        let inner = visnav_io::IoError::Io {
            path: "some/dir".into(),
            source: io,
        };
        let e = anyhow::Error::new(inner).context("reading trajectory some/dir");
        let msg = error_chain(&e);
        assert_eq!(msg.matches(&io_text).count(), 1, "{msg}");
        assert!(
            msg.starts_with("reading trajectory some/dir: some/dir: "),
            "{msg}"
        );
    }
}
