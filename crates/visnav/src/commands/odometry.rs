//! `visnav odometry`: camera trajectory of a KITTI sequence (odometry layout or raw drive).
//!
//! `--mode stereo` runs the RotROCC stereo odometry (`visnav_odometry::stereo`); `--mode mono`
//! is wired by the monocular pipeline. Output: one KITTI pose line per input frame
//! (`world_from_cam` of the left camera, frame 0 = identity), the effective configuration beside
//! it (`<output>.config.toml`), and optionally a JSON report with per-frame timings by stage,
//! feature counts per phase and a status per frame.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context as _, bail};
use serde::Serialize;
use visnav_core::{GrayImage, Pose};
use visnav_io::Sequence;
use visnav_odometry::stereo::{
    FrameCounts, FrameStatus, OutlierMode, StageTimings, StereoConfig, StereoOdometry,
};

/// Which pipeline to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Mode {
    /// Stereo RotROCC (needs image_0 + image_1, or image_00 + image_01).
    Stereo,
    /// Monocular VO from dense flow with uncertainty.
    Mono,
}

/// The outlier criterion of the stereo estimation (overrides the config file).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum OutlierArg {
    /// Rotation phase on the reprojection error, translation phase on the DNRE (default).
    Dnre,
    /// Reprojection error only (phase 1).
    Re,
    /// Mean-based rule (paper eq. 31).
    Mean,
    /// Rule of paper eq. 32.
    Std,
}

impl From<OutlierArg> for OutlierMode {
    fn from(a: OutlierArg) -> Self {
        match a {
            OutlierArg::Dnre => Self::Dnre,
            OutlierArg::Re => Self::Re,
            OutlierArg::Mean => Self::Mean,
            OutlierArg::Std => Self::Std,
        }
    }
}

/// Arguments of `visnav odometry`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Pipeline.
    #[arg(long, value_enum, default_value = "stereo")]
    pub mode: Mode,
    /// KITTI odometry sequence directory or KITTI raw drive directory.
    pub sequence: PathBuf,
    /// Output trajectory (KITTI format: 12 numbers a line, one line per frame).
    #[arg(long, short)]
    pub output: PathBuf,
    /// Also write a JSON report (per-frame timings, counts, status).
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Configuration file (TOML, `StereoConfig` fields; missing fields take the defaults).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Outlier criterion (stereo), overriding the configuration.
    #[arg(long, value_enum)]
    pub outlier: Option<OutlierArg>,
    /// Process only the first N frames.
    #[arg(long)]
    pub max_frames: Option<usize>,
}

#[derive(Debug, Serialize)]
struct FrameReport {
    index: usize,
    #[serde(flatten)]
    status: FrameStatus,
    counts: FrameCounts,
    timings: StageTimings,
    /// Time spent waiting for the decoded images (PNG decoding runs ahead on a thread).
    wait_ms: f64,
    median_translation_flow_px: f64,
}

#[derive(Debug, Default, Serialize)]
struct MeanTimings {
    pyramid_ms: f64,
    corners_ms: f64,
    stereo_ms: f64,
    tracking_ms: f64,
    estimation_ms: f64,
    process_ms: f64,
    wait_ms: f64,
    wall_ms_per_frame: f64,
}

#[derive(Debug, Serialize)]
struct Report<'a> {
    sequence: &'a Path,
    mode: &'static str,
    frames: usize,
    failed_frames: usize,
    low_speed_frames: usize,
    wall_s: f64,
    mean: MeanTimings,
    config: &'a StereoConfig,
    per_frame: Vec<FrameReport>,
}

/// Runs the subcommand.
///
/// # Errors
/// An unreadable sequence or configuration, a sequence without stereo for `--mode stereo`, or an
/// output that cannot be written. Frames that fail inside the pipeline are not errors: they get
/// the constant-velocity prediction and a status in the report.
pub fn run(args: &Args, ctx: &super::Context) -> anyhow::Result<()> {
    match args.mode {
        Mode::Stereo => run_stereo(args, ctx),
        Mode::Mono => bail!(
            "monocular mode is not built yet (the dense-flow mono pipeline is wired in separately)"
        ),
    }
}

/// Loads the stereo config: defaults, then the TOML file, then `--outlier`.
fn load_config(args: &Args) -> anyhow::Result<StereoConfig> {
    let mut config = match &args.config {
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("reading config {}", p.display()))?;
            toml::from_str::<StereoConfig>(&text)
                .with_context(|| format!("parsing config {}", p.display()))?
        }
        None => StereoConfig::default(),
    };
    if let Some(o) = args.outlier {
        config.outlier = o.into();
    }
    config.validate().context("invalid stereo configuration")?;
    Ok(config)
}

fn run_stereo(args: &Args, ctx: &super::Context) -> anyhow::Result<()> {
    let config = load_config(args)?;
    let seq = Sequence::open(&args.sequence)
        .with_context(|| format!("opening sequence {}", args.sequence.display()))?;
    let Some(rig) = seq.stereo_camera() else {
        bail!(
            "{} has no right camera or calibration: --mode stereo needs image_0 + image_1 (or image_00 + image_01) and P1",
            args.sequence.display()
        );
    };
    let n = args.max_frames.map_or(seq.len(), |m| m.min(seq.len()));
    if n == 0 {
        bail!("no frames to process");
    }
    let mut vo = StereoOdometry::new(rig, config.clone())?;
    let bar = crate::progress::bar(n as u64, "stereo", ctx.quiet);
    let mut poses: Vec<Pose> = Vec::with_capacity(n);
    let mut per_frame = Vec::with_capacity(n);
    let start = Instant::now();
    // PNG decoding runs ahead on the prefetch thread (2 pairs ahead).
    let mut frames = crate::prefetch::Prefetcher::new(&seq, 0..n, true, 2);
    for _ in 0..n {
        let t = Instant::now();
        let Some((i, loaded)) = frames.next() else {
            bail!("the frame loader stopped early");
        };
        let wait_ms = t.elapsed().as_secs_f64() * 1e3;
        let pair = loaded
            .map_err(anyhow::Error::from)
            .and_then(|f| match f.right {
                Some(r) => Ok((f.left, r)),
                None => Err(anyhow::anyhow!("frame {i} has no right image")),
            });
        let result = match pair {
            Ok((l, r)) => vo.process(&l, &r),
            Err(e) => {
                // a bad image is not fatal: an empty pair falls back to the constant velocity
                log::warn!("frame {i}: {e:#}");
                let empty = GrayImage::new(0, 0, 0.0);
                vo.process(&empty, &empty)
            }
        };
        poses.push(result.world_from_cam);
        per_frame.push(FrameReport {
            index: i,
            status: result.status,
            counts: result.counts,
            timings: result.timings,
            wait_ms,
            median_translation_flow_px: result.median_translation_flow_px,
        });
        bar.inc(1);
    }
    drop(frames);
    bar.finish_and_clear();
    let wall_s = start.elapsed().as_secs_f64();
    visnav_io::trajectory::write_kitti(&args.output, &poses)
        .with_context(|| format!("writing {}", args.output.display()))?;
    let config_path = config_path_for(&args.output);
    std::fs::write(&config_path, toml::to_string_pretty(&config)?)
        .with_context(|| format!("writing {}", config_path.display()))?;

    let failed = per_frame
        .iter()
        .filter(|f| matches!(f.status, FrameStatus::Fallback(_)))
        .count();
    let low_speed = per_frame
        .iter()
        .filter(|f| matches!(f.status, FrameStatus::LowSpeed))
        .count();
    let nf = per_frame.len().max(1) as f64;
    let mean = MeanTimings {
        pyramid_ms: per_frame.iter().map(|f| f.timings.pyramid_ms).sum::<f64>() / nf,
        corners_ms: per_frame.iter().map(|f| f.timings.corners_ms).sum::<f64>() / nf,
        stereo_ms: per_frame.iter().map(|f| f.timings.stereo_ms).sum::<f64>() / nf,
        tracking_ms: per_frame.iter().map(|f| f.timings.tracking_ms).sum::<f64>() / nf,
        estimation_ms: per_frame
            .iter()
            .map(|f| f.timings.estimation_ms)
            .sum::<f64>()
            / nf,
        process_ms: per_frame.iter().map(|f| f.timings.total_ms).sum::<f64>() / nf,
        wait_ms: per_frame.iter().map(|f| f.wait_ms).sum::<f64>() / nf,
        wall_ms_per_frame: wall_s * 1e3 / nf,
    };
    if !ctx.quiet {
        println!(
            "stereo odometry: {} frames in {:.2} s ({:.1} ms/frame wall, {:.1} ms in the pipeline), {} fallback, {} low-speed",
            per_frame.len(),
            wall_s,
            mean.wall_ms_per_frame,
            mean.process_ms,
            failed,
            low_speed
        );
        println!(
            "poses: {}  config: {}",
            args.output.display(),
            config_path.display()
        );
    }
    if let Some(json) = &args.json {
        let report = Report {
            sequence: &args.sequence,
            mode: "stereo",
            frames: per_frame.len(),
            failed_frames: failed,
            low_speed_frames: low_speed,
            wall_s,
            mean,
            config: &config,
            per_frame,
        };
        let text = serde_json::to_string_pretty(&report)?;
        std::fs::write(json, text).with_context(|| format!("writing {}", json.display()))?;
    }
    Ok(())
}

/// `poses.txt` → `poses.config.toml` in the same directory.
fn config_path_for(output: &Path) -> PathBuf {
    let stem = output
        .file_stem()
        .map_or_else(|| "poses".into(), |s| s.to_string_lossy().into_owned());
    output.with_file_name(format!("{stem}.config.toml"))
}
