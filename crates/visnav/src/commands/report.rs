//! `visnav report RUN_DIR [--output report.html]`: one self-contained HTML page about an odometry
//! run (trajectory against ground truth, KITTI errors, time per stage, inliers and status per
//! frame, a gallery of flow, uncertainty and depth). See `visnav_report` for what a run
//! directory holds.

use std::path::PathBuf;

use anyhow::bail;

use visnav_report::{ReportInputs, write};

/// Arguments of `visnav report`.
#[derive(Debug, clap::Args)]
#[command(
    after_help = "A run directory holds poses.txt and report.json (from `visnav odometry \
    --output DIR/poses.txt --json DIR/report.json`, or `--report`), optionally flow/ and depth/ \
    (--save-flow DIR/flow --save-depth DIR/depth).\n\
    Example: visnav report run06 --output run06/report.html"
)]
pub struct Args {
    /// Run directory (poses.txt, report.json, optional flow/ and depth/).
    pub run_dir: PathBuf,
    /// Output HTML file (default RUN_DIR/report.html).
    #[arg(long, short)]
    pub output: Option<PathBuf>,
    /// Ground-truth trajectory (KITTI or TUM); default: poses.txt in the sequence directory, or
    /// poses/XX.txt of a KITTI odometry sequences/XX directory.
    #[arg(long)]
    pub ground_truth: Option<PathBuf>,
    /// Estimated trajectory instead of RUN_DIR/poses.txt.
    #[arg(long)]
    pub poses: Option<PathBuf>,
    /// Odometry JSON report instead of RUN_DIR/report.json.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Sequence directory (frames of the gallery, ground truth) instead of the one in the JSON
    /// report.
    #[arg(long)]
    pub sequence: Option<PathBuf>,
    /// KITTI segment lengths in metres (default: 100..800 for paths of 800 m or more, else five
    /// round lengths up to half the path).
    #[arg(long, value_delimiter = ',')]
    pub lengths: Option<Vec<f64>>,
    /// Frames in the gallery (at most).
    #[arg(long, default_value_t = 4)]
    pub gallery: usize,
}

/// Runs the subcommand.
///
/// # Errors
/// A missing run directory, an unreadable trajectory or JSON report, an unreadable given ground
/// truth, or an output that cannot be written.
pub fn run(args: &Args, ctx: &super::Context) -> anyhow::Result<()> {
    match std::fs::metadata(&args.run_dir) {
        Ok(m) if m.is_dir() => {}
        Ok(_) => bail!(
            "run directory {} is not a directory",
            args.run_dir.display()
        ),
        Err(_) if !visnav_io::text::entry_exists(&args.run_dir) => {
            bail!("run directory {} does not exist", args.run_dir.display())
        }
        // a symlink loop or a dangling link, named as such
        Err(e) => bail!("run directory {}", visnav_io::IoError::io(&args.run_dir, e)),
    }
    let mut inputs = ReportInputs::from_run_dir(&args.run_dir);
    if let Some(p) = &args.poses {
        inputs.poses.clone_from(p);
    }
    if let Some(p) = &args.json {
        inputs.run_json.clone_from(p);
    }
    inputs.ground_truth.clone_from(&args.ground_truth);
    inputs.sequence.clone_from(&args.sequence);
    inputs.lengths_m.clone_from(&args.lengths);
    inputs.gallery_frames = args.gallery;
    let output = args
        .output
        .clone()
        .unwrap_or_else(|| args.run_dir.join("report.html"));
    write(&inputs, &output)?;
    if !ctx.quiet {
        println!("report: {}", output.display());
    }
    Ok(())
}
