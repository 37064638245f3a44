//! `visnav demo`: the main job on an embedded default (the scenario is `visnav_demo`): renders
//! a short synthetic stereo drive with exact ground truth, runs every estimator on it through
//! the streaming odometry, scores each with the KITTI metric, ATE and RPE, prints a table and
//! writes the trajectories, the plots and `scores.json` into the output directory; then drives
//! once around a rendered block with monocular VO, with and without loop closure.

use std::path::PathBuf;

use visnav_demo::{DemoReport, DemoSettings, run_demo};

/// Arguments of `visnav demo`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Output directory (created if missing).
    #[arg(long, default_value = "visnav-demo")]
    pub output: PathBuf,
    /// Frames of the rendered drive (10 Hz).
    #[arg(long, default_value_t = 50)]
    pub frames: usize,
    /// Image width in pixels (default: half KITTI resolution).
    #[arg(long, default_value_t = 620)]
    pub width: u32,
    /// Image height in pixels.
    #[arg(long, default_value_t = 188)]
    pub height: u32,
    /// Seed of the scene and the drive.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Frames the monocular pipeline runs on (a prefix of the drive; its dense flow is the
    /// slowest stage). Default: every frame.
    #[arg(long)]
    pub mono_frames: Option<usize>,
    /// Print the scores as JSON on stdout instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Frames of the loop-closure drive around a block (0 skips it; one lap is 89 frames, so
    /// with the default 91 the last frame is back at the start and closes the loop).
    #[arg(long, default_value_t = 91)]
    pub loop_frames: usize,
}

/// Runs the subcommand.
///
/// # Errors
/// Bad arguments, a file that cannot be written, or a scoring failure.
pub fn run(args: &Args, ctx: &super::Context) -> anyhow::Result<()> {
    let settings = DemoSettings {
        output: args.output.clone(),
        frames: args.frames,
        width: args.width,
        height: args.height,
        seed: args.seed,
        mono_frames: args.mono_frames,
        loop_frames: args.loop_frames,
    };
    let bars = crate::progress::Bars::new(ctx.quiet || args.json);
    let report = run_demo(&settings, &bars)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else if !ctx.quiet {
        print_table(&report);
    }
    Ok(())
}

fn print_table(r: &DemoReport) {
    let opt = |v: Option<f64>, prec: usize| v.map_or("-".into(), |v| format!("{v:.prec$}"));
    println!(
        "synthetic stereo drive: {} frames {}x{}, {:.1} m, rendered in {:.1} s ({:.0} ms a stereo frame); lengths {:?} m",
        r.frames,
        r.width,
        r.height,
        r.path_length_m,
        r.render_s,
        r.render_ms_per_frame,
        r.lengths_m
    );
    println!(
        "{:<16} {:>7} {:>6} {:>9} {:>13} {:>5} {:>10} {:>10} {:>10} {:>9}",
        "estimator",
        "frames",
        "failed",
        "t_err %",
        "r_err °/100m",
        "segs",
        "ATE SE3 m",
        "ATE Sim3 m",
        "RPE m",
        "ms/frame"
    );
    for s in &r.scores {
        println!(
            "{:<16} {:>7} {:>6} {:>9.4} {:>13.4} {:>5} {:>10} {:>10} {:>10} {:>9.2}",
            s.name,
            s.frames,
            s.failed_frames,
            s.t_err_percent,
            s.r_err_deg_per_100m,
            s.segments,
            opt(s.ate_se3_m, 4),
            opt(s.ate_sim3_m, 4),
            opt(s.rpe_trans_rmse_m, 4),
            s.ms_per_frame
        );
    }
    for s in r.scores.iter().filter(|s| s.frames < r.frames) {
        println!(
            "note: {} ran on the first {} of {} frames (lengths {:?} m); see --mono-frames",
            s.name, s.frames, r.frames, s.lengths_m
        );
    }
    for s in &r.scores {
        let flow = s.flow_ms_per_frame.map_or(String::new(), |f| {
            format!(" (dense flow {f:.0} ms/frame, on its own thread beside the odometry)")
        });
        println!("  {:<16} {}{flow}", s.name, s.description);
    }
    if let Some(l) = &r.loop_drive {
        let closes_at_end = l.final_frame == l.closing_frame;
        let after = if closes_at_end {
            String::new()
        } else {
            format!(
                "; at the last frame ({}): mono VO {:.3} m, with loop closure {:.3} m",
                l.final_frame, l.final_drift_odometry_m, l.final_drift_loop_closure_m
            )
        };
        println!(
            "loop-closure drive: {} frames {}x{} around a block, {:.1} m; drift where the loop closes (frame {}{}): mono VO {:.3} m, with loop closure {:.3} m{after} ({} closures accepted, {} rejected; {:.1} s)",
            l.frames,
            l.width,
            l.height,
            l.path_length_m,
            l.closing_frame,
            if closes_at_end { ", the last one" } else { "" },
            l.end_drift_odometry_m,
            l.end_drift_loop_closure_m,
            l.closures_accepted,
            l.closures_rejected,
            l.render_s + l.run_s
        );
    }
    for f in &r.failures {
        println!("FAILED {}: {}", f.name, f.error);
    }
    println!(
        "trajectories, plots and scores.json in {} ({:.1} s in all)",
        r.output.display(),
        r.total_s
    );
}
