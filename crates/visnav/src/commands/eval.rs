//! `visnav eval GT EST [GT2 EST2 ...]`: scores estimated trajectories against ground truth with
//! the KITTI odometry metric (as the official devkit), ATE after SE(3)/Sim(3) alignment and RPE.
//! Trajectory files may be KITTI (12 numbers a line) or TUM (`t tx ty tz qx qy qz qw`); frames
//! are matched by timestamp when both files carry them, else by index.

use std::path::PathBuf;

use anyhow::{Context as _, bail};
use serde::Serialize;
use visnav_eval::kitti::{BinScore, KittiMetricConfig};
use visnav_eval::plot::{plot_errors_vs_length, plot_top_view};
use visnav_eval::{EvalConfig, EvalReport, TrajectoryPair, evaluate};
use visnav_io::trajectory::read_pose_matrices;

/// Arguments of `visnav eval`.
#[derive(Debug, clap::Args)]
#[command(after_long_help = "\
    The KITTI odometry metric is computed exactly as the official devkit (evaluate_odometry.cpp): \
    segments start every 10 frames, a segment of length L ends at the first frame whose \
    ground-truth path length exceeds the start's + L, t_err = |t(E)|/L in %, r_err = angle(E)/L \
    in deg/100 m, averaged over all segments of all pairs. Also reported: ATE (RMSE of positions \
    after SE(3) and Sim(3) Umeyama alignment) and RPE (frame-to-frame relative pose error).\n\n\
    Files are KITTI (12 numbers a line) or TUM ('t tx ty tz qx qy qz qw'), detected per file. \
    An estimate shorter than its ground truth is scored on the common prefix with a warning \
    (--strict: an error).\n\n\
    Example: visnav eval poses/00.txt my_00.txt --lengths 100,200 --json --plot out/")]
pub struct Args {
    /// Pairs of trajectory files: GT EST [GT2 EST2 ...].
    #[arg(required = true, num_args = 2.., value_name = "GT_EST")]
    pub files: Vec<PathBuf>,
    /// Segment lengths in metres (default: the devkit's 100,200,...,800).
    #[arg(long, value_delimiter = ',', value_name = "M,M,...")]
    pub lengths: Option<Vec<f64>>,
    /// Print one JSON object with every figure instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Write plots (top view, errors against segment length) as PNG and SVG into this directory.
    #[arg(long, value_name = "DIR")]
    pub plot: Option<PathBuf>,
    /// Fail when estimate and ground truth differ in length instead of scoring the common prefix.
    #[arg(long)]
    pub strict: bool,
    /// Also report the RPE over this many frames (besides frame to frame).
    #[arg(long, value_name = "FRAMES")]
    pub rpe_delta: Option<usize>,
    /// Largest timestamp difference for matching TUM frames, seconds.
    #[arg(long, default_value_t = 0.01, value_name = "S")]
    pub max_time_diff: f64,
}

/// What `--json` prints: the report plus the inputs and written plots.
#[derive(Serialize)]
struct JsonOutput<'a> {
    #[serde(flatten)]
    report: &'a EvalReport,
    /// `[ground truth, estimate]` per pair.
    files: Vec<[String; 2]>,
    /// Files written: the effective config and the plots (with `--plot`).
    written: Vec<String>,
    /// The effective configuration.
    config: &'a EvalConfig,
}

/// Runs the subcommand.
///
/// # Errors
/// An odd number of files, an unreadable or malformed file, an invalid option, a length mismatch
/// with `--strict`, or a plot that cannot be written.
pub fn run(args: &Args, ctx: &super::Context) -> anyhow::Result<()> {
    if !args.files.len().is_multiple_of(2) {
        bail!(
            "expected pairs of files GT EST [GT2 EST2 ...], got {} files",
            args.files.len()
        );
    }
    let config = EvalConfig {
        kitti: KittiMetricConfig {
            lengths_m: args
                .lengths
                .clone()
                .unwrap_or_else(|| KittiMetricConfig::default().lengths_m),
            ..KittiMetricConfig::default()
        },
        rpe_delta_frames: args.rpe_delta,
        strict: args.strict,
        max_time_diff_s: args.max_time_diff,
    };
    config.validate()?;
    let mut loaded = Vec::with_capacity(args.files.len());
    for f in &args.files {
        loaded.push(
            read_pose_matrices(f).with_context(|| format!("reading trajectory {}", f.display()))?,
        );
    }
    let pairs: Vec<TrajectoryPair<'_>> = loaded
        .chunks_exact(2)
        .map(|p| TrajectoryPair {
            gt: &p[0].poses,
            est: &p[1].poses,
            gt_timestamps: p[0].timestamps.as_deref(),
            est_timestamps: p[1].timestamps.as_deref(),
        })
        .collect();
    let report = evaluate(&pairs, &config)?;
    let mut plots = Vec::new();
    if let Some(dir) = &args.plot {
        // the effective configuration beside the plots
        let config_path = dir.join("eval_config.json");
        visnav_io::trajectory::write_atomically(
            &config_path,
            serde_json::to_string_pretty(&config)?.as_bytes(),
        )?;
        plots.push(config_path);
        let several = report.matched.len() > 1;
        for (k, m) in report.matched.iter().enumerate() {
            let suffix = if several {
                format!("_{k}")
            } else {
                String::new()
            };
            let name = args.files[2 * k + 1].file_name().map_or_else(
                || format!("sequence {k}"),
                |n| n.to_string_lossy().into_owned(),
            );
            plots.extend(plot_top_view(
                dir,
                &format!("top_view{suffix}"),
                &m.gt,
                &m.est,
                &format!("{name}: top view (x-z)"),
            )?);
            plots.extend(plot_errors_vs_length(
                dir,
                &format!("errors_vs_length{suffix}"),
                &report.sequences[k].per_length,
                &format!("{name}: KITTI error against segment length"),
            )?);
        }
    }
    if args.json {
        let out = JsonOutput {
            report: &report,
            files: args
                .files
                .chunks_exact(2)
                .map(|p| [p[0].display().to_string(), p[1].display().to_string()])
                .collect(),
            written: plots.iter().map(|p| p.display().to_string()).collect(),
            config: &config,
        };
        emit(&format!("{}\n", serde_json::to_string_pretty(&out)?))?;
    } else if !ctx.quiet {
        let mut text = table(&report, &args.files);
        for p in &plots {
            text.push_str(&format!("wrote {}\n", p.display()));
        }
        emit(&text)?;
    }
    Ok(())
}

/// Writes to stdout; a closed pipe (`visnav eval ... | head`) is not an error.
fn emit(text: &str) -> anyhow::Result<()> {
    use std::io::Write as _;
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(e.into()),
        _ => Ok(()),
    }
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "-".into(), |x| format!("{x:.digits$}"))
}

fn bins_table(out: &mut String, label: &str, unit: &str, bins: &[BinScore], scale: f64) {
    use std::fmt::Write as _;
    if bins.is_empty() {
        return;
    }
    let _ = writeln!(
        out,
        "\n{label:>14}  {:>9}  {:>16}  {:>8}",
        "t_err [%]", "r_err [deg/100m]", "segments"
    );
    for b in bins {
        let _ = writeln!(
            out,
            "{:>11.0} {unit:<2}  {:>9.4}  {:>16.4}  {:>8}",
            b.key * scale,
            b.t_err_percent,
            b.r_err_deg_per_100m,
            b.segments
        );
    }
}

fn table(report: &EvalReport, files: &[PathBuf]) -> String {
    use std::fmt::Write as _;
    let mut out = String::new();
    let lengths: Vec<String> = report.lengths_m.iter().map(|l| format!("{l}")).collect();
    let _ = writeln!(
        out,
        "KITTI odometry metric (devkit semantics; lengths {} m, segments every 10 frames)\n",
        lengths.join(",")
    );
    let _ = writeln!(
        out,
        "{:<28} {:>6} {:>8} {:>9} {:>16} {:>10} {:>11} {:>9} {:>10}",
        "estimate",
        "poses",
        "segments",
        "t_err [%]",
        "r_err [deg/100m]",
        "ATE SE3[m]",
        "ATE Sim3[m]",
        "RPE t[m]",
        "RPE r[deg]"
    );
    for s in &report.sequences {
        let name = files[2 * s.sequence + 1]
            .file_name()
            .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
        let _ = writeln!(
            out,
            "{:<28} {:>6} {:>8} {:>9.4} {:>16.4} {:>10} {:>11} {:>9} {:>10}",
            name,
            s.scored_poses,
            s.segments,
            s.t_err_percent,
            s.r_err_deg_per_100m,
            opt(s.ate_se3.map(|a| a.rmse_m), 3),
            opt(s.ate_sim3.map(|a| a.rmse_m), 3),
            opt(s.rpe.map(|r| r.trans_rmse_m), 4),
            opt(s.rpe.map(|r| r.rot_rmse_deg), 4),
        );
    }
    if report.sequences.len() > 1 {
        let _ = writeln!(
            out,
            "{:<28} {:>6} {:>8} {:>9.4} {:>16.4} {:>10} {:>11} {:>9} {:>10}",
            "all (pooled)",
            report
                .sequences
                .iter()
                .map(|s| s.scored_poses)
                .sum::<usize>(),
            report.segments,
            report.t_err_percent,
            report.r_err_deg_per_100m,
            opt(report.ate_se3_m, 3),
            opt(report.ate_sim3_m, 3),
            opt(report.rpe.map(|r| r.trans_rmse_m), 4),
            opt(report.rpe.map(|r| r.rot_rmse_deg), 4),
        );
    }
    if let Some(r) = report.rpe_delta {
        let _ = writeln!(
            out,
            "\nRPE over {} frames: {:.4} m, {:.4} deg (RMSE, {} pairs)",
            r.delta_frames, r.trans_rmse_m, r.rot_rmse_deg, r.pairs
        );
    }
    bins_table(&mut out, "length", "m", &report.per_length, 1.0);
    bins_table(&mut out, "speed", "kmh", &report.per_speed, 3.6);
    out
}
