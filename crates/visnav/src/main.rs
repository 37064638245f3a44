//! `visnav`: the command-line tool. A thin layer over the library crates: argument parsing,
//! progress bars, file output and exit codes live here; the algorithms live in the crates.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod commands;
mod live;
mod progress;

/// Robust visual navigation: camera in, trajectory, depth and uncertainty out.
#[derive(Debug, Parser)]
#[command(name = "visnav", version, about, long_about = None, propagate_version = true)]
struct Cli {
    /// Print nothing but errors (no progress bars, no tables).
    #[arg(long, short, global = true)]
    quiet: bool,
    /// Worker threads for the parallel stages (default: one per core).
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
    Odometry(commands::odometry::Args),
    /// Dense optical flow with per-pixel uncertainty between two images.
    Flow(commands::flow::Args),
    /// Evaluate dense flow and its uncertainty on Middlebury, KITTI or Sintel layouts.
    FlowEval(commands::flow_eval::Args),
    /// Optimise a pose graph (g2o format), robust to wrong loop closures.
    Posegraph(commands::posegraph::Args),
    /// Write a self-contained HTML report of an odometry run (plots, timings, flow/depth gallery).
    Report(commands::report::Args),
}

/// mimalloc as the allocator: the flow stage allocates and frees image-sized buffers (up to
/// ≈ 17 MB) many times a pair; with glibc's allocator each is a fresh `mmap` whose pages fault in
/// on first write (142 000 page faults and 12 % more CPU time on a KITTI pair, `perf stat`),
/// mimalloc reuses them (341 faults; docs/benchmarks.md).
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() -> ExitCode {
    let cli = Cli::parse();
    let level = if cli.quiet { "error" } else { "info" };
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or(level))
        .format_timestamp(None)
        .format_target(false)
        .init();
    if let Some(n) = cli.threads
        && let Err(e) = rayon::ThreadPoolBuilder::new()
            .num_threads(n.get())
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
        Command::Odometry(a) => commands::odometry::run(a, &ctx),
        Command::Flow(a) => commands::flow::run(a, &ctx),
        Command::FlowEval(a) => commands::flow_eval::run(a, &ctx),
        Command::Posegraph(a) => commands::posegraph::run(a, &ctx),
        Command::Report(a) => commands::report::run(a, &ctx),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
