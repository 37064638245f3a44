//! `visnav odometry`: camera trajectory of a KITTI sequence (odometry layout or raw drive), an
//! EuRoC (ASL), TUM RGB-D or TUM monoVO sequence, a folder of PNG/JPEG images or a video file
//! (`--camera FILE` gives the calibration where the input has none; see `visnav_io::calibration`
//! and `visnav_io::tum_mono`). Distorted or
//! unrectified inputs are undistorted / rectified on load.
//!
//! `--mode stereo` runs the RotROCC stereo odometry (`visnav_odometry::stereo`); `--mode mono`
//! runs the monocular odometry from dense flow with uncertainty (`visnav_flow` +
//! `visnav_odometry::mono`, Ng, Li & Kim 2021) on the left images only. Output: one KITTI pose
//! line per input frame (`world_from_cam` of the left camera, frame 0 = identity), the effective
//! configuration beside it (`<output>.config.toml`), and optionally a JSON report with per-frame
//! timings by stage, feature counts per phase and a status per frame.
//!
//! Mono extras: `--palindrome` plays the frames `0..N` forward then back (§6.2 drift test, `2N−1`
//! pose lines) and reports the end-point error and the scale drift; `--save-flow DIR` writes the
//! flow of each frame pair (`PPPPPP_CCCCCC.flo` + `PPPPPP_CCCCCC.info.pfm`, information matrix
//! `Yxx Yxy Yyy` in 1/px²); `--save-depth DIR` writes the fused depth map of each frame
//! (`NNNNNN.pfm`, `NNNNNN_back.pfm` on the way back of a palindrome) on the pipeline's depth grid
//! (one pixel per `depth_stride_px` image pixels, metres, NaN = unknown); `--save-every K` keeps
//! only every K-th frame's files. `--save-tracks DIR` (stereo) writes the feature tracks of each
//! frame as `NNNNNN.tracks.csv` ([`TRACKS_CSV_HEADER`]).
//!
//! `--report` makes the output's directory a run directory (see [`crate::report`]): the JSON
//! report goes to `report.json` there unless `--json` is given, mono runs save the flow and depth
//! of a few gallery frames to `flow/` and `depth/`, stereo runs their tracks to `tracks/`, unless
//! a `--save-*` option is given, and `report.html` is written there after the run.
//!
//! `--loop-closure` (mono) adds the loop-closure stage (`visnav_loop::LoopCloser`, §5 of the
//! paper): candidates every 10 frames by position and SSIM, verification by dense flow with
//! uncertainty, relative pose by the monocular motion estimation, robust pose graph. The corrected
//! trajectory goes to `--output`, the odometry-only one beside it (`NAME.odometry.txt`), and the
//! JSON report lists every verified closure (SSIM, reliable-pixel share, relative pose, verdict).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::live::{LiveFrame, LiveView};
use anyhow::{Context as _, bail};
use serde::{Deserialize, Serialize};
use visnav_core::{GrayImage, Pose};
use visnav_flow::{DenseFlow, FlowTimings};
use visnav_geometry::fundamental::Estimator;
use visnav_io::Sequence;
use visnav_io::pfm::{PfmImage, write_pfm};
use visnav_loop::{ClosureReport, LoopCloser, LoopConfig};
use visnav_odometry::mono::palindrome::{PalindromeDrift, palindrome_drift, palindrome_order};
use visnav_odometry::mono::{
    FrameStatus as MonoStatus, MonoConfig, MonoError, MonoFlow, MonoFrameResult, MonoOdometry,
    PoseSource, ScaleSource, StageTimings as MonoStageTimings,
};
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

/// The eight-point variant of the monocular pipeline (overrides the config file).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum EstimatorArg {
    /// Mahalanobis-weighted eight-point (paper eq. 9–12, default).
    Mahalanobis,
    /// Sampson-weighted eight-point (eq. 7–8).
    Sampson,
    /// Plain Hartley-normalised eight-point (eq. 6).
    Algebraic,
}

impl From<EstimatorArg> for Estimator {
    fn from(a: EstimatorArg) -> Self {
        match a {
            EstimatorArg::Mahalanobis => Self::Mahalanobis,
            EstimatorArg::Sampson => Self::Sampson,
            EstimatorArg::Algebraic => Self::Algebraic,
        }
    }
}

/// Arguments of `visnav odometry`.
#[derive(Debug, Clone, clap::Args)]
pub struct Args {
    /// Pipeline.
    #[arg(long, value_enum, default_value = "stereo")]
    pub mode: Mode,
    /// KITTI odometry sequence or raw drive directory, EuRoC sequence (`mav0/`), TUM RGB-D folder
    /// (`rgb.txt`), TUM monoVO sequence (`times.txt` + `camera.txt` + `images/`), folder of PNG or
    /// JPEG images (or `left/` + `right/`), or video file.
    pub sequence: PathBuf,
    /// Camera file (`.yaml`/`.toml`, Kalibr keys: cam0 [+ cam1 with T_cn_cnm1]) for TUM RGB-D,
    /// image folders and video (or `camera.yaml` in the folder); overrides EuRoC's `sensor.yaml`
    /// and TUM monoVO's `camera.txt` (there also a DSO-style `.txt`).
    #[arg(long, value_name = "FILE")]
    pub camera: Option<PathBuf>,
    /// Output trajectory (KITTI format: 12 numbers a line, one line per frame). Inputs with
    /// timestamps (EuRoC, TUM RGB-D, TUM monoVO) also get `<output stem>.tum.txt` (TUM format, image timestamps;
    /// EuRoC: the body frame of `T_BS`, like its ground truth).
    #[arg(long, short)]
    pub output: PathBuf,
    /// Also write a JSON report (per-frame timings, counts, status).
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Configuration file (TOML; stereo: `StereoConfig` fields; mono: a `[mono]` = `MonoConfig`
    /// table, the flow in `[mono.flow]`; missing fields take the defaults).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Outlier criterion (stereo), overriding the configuration.
    #[arg(long, value_enum)]
    pub outlier: Option<OutlierArg>,
    /// Process only the first N frames.
    #[arg(long)]
    pub max_frames: Option<usize>,
    /// Camera height above the ground, metres (mono scale; KITTI 1.7).
    #[arg(long)]
    pub camera_height: Option<f64>,
    /// Aerial vehicle (mono): ground-plane scale for the first frame only, depth ratios after.
    #[arg(long)]
    pub aerial: bool,
    /// Eight-point variant (mono), overriding the configuration.
    #[arg(long, value_enum)]
    pub estimator: Option<EstimatorArg>,
    /// Write the fused depth map of each frame as PFM (metres) into this directory (mono).
    #[arg(long)]
    pub save_depth: Option<PathBuf>,
    /// Write the dense flow of each frame pair (.flo + information PFM) into this directory (mono).
    #[arg(long)]
    pub save_flow: Option<PathBuf>,
    /// Palindrome drift test (mono, paper §6.2): frames 0..N..0, 2N-1 pose lines, end-point error
    /// and scale drift in the summary and the JSON report.
    #[arg(long)]
    pub palindrome: bool,
    /// Write the feature tracks of each frame (`NNNNNN.tracks.csv`: previous and current left
    /// pixel, depth in metres, inlier flag) into this directory (stereo).
    #[arg(long)]
    pub save_tracks: Option<PathBuf>,
    /// With --save-flow / --save-depth / --save-tracks: save only every K-th frame of the run.
    #[arg(long, default_value = "1", value_name = "K")]
    pub save_every: std::num::NonZeroUsize,
    /// Also write an HTML report (`report.html`, with `report.json` and a few frames of flow/ and
    /// depth/ (mono) or tracks/ (stereo)) in the output's directory.
    #[arg(long)]
    pub report: bool,
    /// Record a live 3-D view (camera path, frame, flow, uncertainty, points) into this Rerun
    /// `.rrd` file (needs the `rerun` cargo feature).
    #[arg(long, value_name = "FILE")]
    pub rerun_save: Option<PathBuf>,
    /// Stream the live 3-D view to a running Rerun viewer (needs the `rerun` cargo feature).
    #[arg(long)]
    pub rerun_connect: bool,
    /// Loop closure (mono, paper §5): the corrected trajectory goes to --output, the
    /// odometry-only one to NAME.odometry.txt beside it; `[loop_closure]` in --config tunes it.
    #[arg(long)]
    pub loop_closure: bool,
}

impl Args {
    /// The live-view options.
    fn live(&self) -> crate::live::LiveOptions<'_> {
        crate::live::LiveOptions {
            save: self.rerun_save.as_deref(),
            connect: self.rerun_connect,
        }
    }
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
    if args.report {
        return run_with_report(args, ctx);
    }
    match args.mode {
        Mode::Stereo => {
            let mono_only = [
                (args.camera_height.is_some(), "--camera-height"),
                (args.aerial, "--aerial"),
                (args.estimator.is_some(), "--estimator"),
                (args.save_depth.is_some(), "--save-depth"),
                (args.save_flow.is_some(), "--save-flow"),
                (args.palindrome, "--palindrome"),
                (args.loop_closure, "--loop-closure"),
            ];
            if let Some((_, name)) = mono_only.iter().find(|(set, _)| *set) {
                bail!("{name} applies to --mode mono only");
            }
            run_stereo(args, ctx)
        }
        Mode::Mono => {
            if args.outlier.is_some() {
                bail!("--outlier applies to --mode stereo only");
            }
            if args.save_tracks.is_some() {
                bail!("--save-tracks applies to --mode stereo only");
            }
            run_mono(args, ctx)
        }
    }
}

/// Frames of the report's gallery saved by `--report` in mono mode.
const REPORT_GALLERY_FRAMES: usize = 4;

/// `--report`: the run with the report's inputs made sure of, then `report.html` beside the output.
fn run_with_report(args: &Args, ctx: &super::Context) -> anyhow::Result<()> {
    let dir = args
        .output
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf);
    let mut run_args = args.clone();
    run_args.report = false;
    run_args.json.get_or_insert_with(|| dir.join("report.json"));
    let saves_nothing =
        args.save_flow.is_none() && args.save_depth.is_none() && args.save_tracks.is_none();
    if saves_nothing {
        // a few frames for the gallery, not the whole run
        let n = args
            .max_frames
            .unwrap_or_else(|| Sequence::open(&args.sequence).map_or(0, |s| s.len()));
        let every = (n.saturating_sub(1) / REPORT_GALLERY_FRAMES).max(1);
        run_args.save_every = std::num::NonZeroUsize::new(every).unwrap_or(args.save_every);
        match args.mode {
            Mode::Mono => {
                run_args.save_flow = Some(dir.join("flow"));
                run_args.save_depth = Some(dir.join("depth"));
            }
            Mode::Stereo => run_args.save_tracks = Some(dir.join("tracks")),
        }
    }
    run(&run_args, ctx)?;
    let inputs = crate::report::ReportInputs {
        poses: run_args.output.clone(),
        run_json: run_args
            .json
            .clone()
            .unwrap_or_else(|| dir.join("report.json")),
        flow_dir: run_args.save_flow.clone(),
        depth_dir: run_args.save_depth.clone(),
        tracks_dir: run_args.save_tracks.clone(),
        ground_truth: None,
        sequence: Some(args.sequence.clone()),
        lengths_m: None,
        gallery_frames: REPORT_GALLERY_FRAMES,
    };
    let output = dir.join("report.html");
    crate::report::write(&inputs, &output)?;
    if !ctx.quiet {
        println!("report: {}", output.display());
    }
    Ok(())
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
    let seq = open_sequence(args)?;
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
    if let Some(dir) = &args.save_tracks {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let mut live = LiveView::open(&args.live(), rig.left)?;
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
        let result = match &pair {
            Ok((l, r)) => vo.process(l, r),
            Err(e) => {
                // a bad image is not fatal: an empty pair falls back to the constant velocity
                log::warn!("frame {i}: {e:#}");
                let empty = GrayImage::new(0, 0, 0.0);
                vo.process(&empty, &empty)
            }
        };
        if let (Some(live), Ok((l, _))) = (&mut live, &pair) {
            live.log(&LiveFrame {
                step: i,
                image: l,
                world_from_cam: &result.world_from_cam,
                flow: None,
                depth: None,
            });
        }
        if let Some(dir) = &args.save_tracks
            && i % args.save_every == 0
            && !result.tracks.is_empty()
        {
            save_tracks(dir, i, &result.tracks)?;
        }
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
    let tum_path = write_tum_beside(&args.output, &seq, &poses)?;
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
        print_output_paths(&args.output, &config_path, tum_path.as_deref());
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
        write_json(json, &report)?;
    }
    Ok(())
}

/// Opens the input with its camera file, if any.
/// Prints where a run wrote its poses, its configuration and (when asked for) its TUM poses.
fn print_output_paths(output: &Path, config: &Path, tum: Option<&Path>) {
    println!("poses: {}  config: {}", output.display(), config.display());
    if let Some(p) = tum {
        println!("poses with timestamps (TUM): {}", p.display());
    }
}

/// Writes a run report as pretty JSON to `path`.
fn write_json<T: Serialize>(path: &Path, report: &T) -> anyhow::Result<()> {
    let text = serde_json::to_string_pretty(report)?;
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}

fn open_sequence(args: &Args) -> anyhow::Result<Sequence> {
    Sequence::open_with_camera(&args.sequence, args.camera.as_deref())
        .with_context(|| format!("opening sequence {}", args.sequence.display()))
}

/// For inputs with timestamps, writes `poses` (one per frame, frame 0 = identity) in TUM format
/// beside `output` as `<stem>.tum.txt`: in the body frame when the dataset defines one
/// (`body0_from_bodyk = B · cam0_from_camk · B⁻¹`, `B = body_from_cam`), else the camera frame.
/// Returns the path written, `None` when the input has no timestamps or the poses do not map
/// one-to-one onto frames (palindrome).
fn write_tum_beside(
    output: &Path,
    seq: &Sequence,
    poses: &[Pose],
) -> anyhow::Result<Option<PathBuf>> {
    if !seq.timestamped || poses.len() > seq.timestamps.len() {
        return Ok(None);
    }
    let stem = output
        .file_stem()
        .map_or_else(|| "poses".into(), |s| s.to_string_lossy().into_owned());
    let path = output.with_file_name(format!("{stem}.tum.txt"));
    let poses: Vec<Pose> = match seq.body_from_cam {
        Some(b) => poses.iter().map(|p| b * p * b.inverse()).collect(),
        None => poses.to_vec(),
    };
    visnav_io::trajectory::write_tum(&path, &poses, &seq.timestamps[..poses.len()])
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(Some(path))
}

/// `poses.txt` → `poses.config.toml` in the same directory.
fn config_path_for(output: &Path) -> PathBuf {
    let stem = output
        .file_stem()
        .map_or_else(|| "poses".into(), |s| s.to_string_lossy().into_owned());
    output.with_file_name(format!("{stem}.config.toml"))
}

/// `poses.txt` → `poses.odometry.txt` in the same directory (odometry-only trajectory of a
/// `--loop-closure` run).
fn odometry_path_for(output: &Path) -> PathBuf {
    let stem = output
        .file_stem()
        .map_or_else(|| "poses".into(), |s| s.to_string_lossy().into_owned());
    output.with_file_name(format!("{stem}.odometry.txt"))
}

/// The monocular configuration file: a `[mono]` table (with the flow in `[mono.flow]`) and a
/// `[loop_closure]` table.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct MonoFileConfig {
    /// The monocular odometry and its flow (paper defaults, see `MonoConfig`).
    mono: MonoConfig,
    /// Loop closure (see `LoopConfig`; used with `--loop-closure`).
    loop_closure: LoopConfig,
}

/// Loads the mono config: defaults, then the TOML file, then the command-line overrides.
fn load_mono_config(args: &Args) -> anyhow::Result<MonoFileConfig> {
    let mut config = match &args.config {
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("reading config {}", p.display()))?;
            toml::from_str::<MonoFileConfig>(&text)
                .with_context(|| format!("parsing config {}", p.display()))?
        }
        None => MonoFileConfig::default(),
    };
    if let Some(h) = args.camera_height {
        config.mono.scale.camera_height_m = h;
    }
    if args.aerial {
        config.mono.scale.aerial = true;
    }
    if let Some(e) = args.estimator {
        config.mono.eight_point.estimator = e.into();
    }
    config
        .mono
        .validate()
        .context("invalid mono configuration")?;
    config
        .loop_closure
        .validate()
        .context("invalid loop_closure configuration")?;
    Ok(config)
}

/// Time per stage of one mono frame, milliseconds.
#[derive(Debug, Default, Serialize)]
struct MonoFrameTimings {
    /// Waiting for the decoded image.
    wait_ms: f64,
    /// Dense flow from the previous image, by stage (absent for the first frame or a failure).
    /// It runs on its own thread during the previous frame's odometry (pipelining), so these
    /// times overlap with the previous frame's.
    flow: Option<FlowTimings>,
    /// Time this frame waited for its flow (the part of the flow not hidden behind the previous
    /// frame's odometry).
    flow_wait_ms: f64,
    /// The odometry stages.
    vo: Option<MonoStageTimings>,
    /// Saving flow and depth files.
    save_ms: f64,
    /// The whole frame (waiting for the flow + odometry + saving, waiting for the image
    /// excluded).
    frame_ms: f64,
}

/// One line of the mono JSON report.
#[derive(Debug, Serialize)]
struct MonoFrameReport {
    /// Position in the run (equals `index` except on the way back of a palindrome).
    step: usize,
    /// Frame of the sequence.
    index: usize,
    /// Outcome; `failed` frames get the constant-velocity prediction.
    status: MonoStatus,
    /// Why the frame failed in the driver (unreadable image, flow error), if it did.
    error: Option<String>,
    /// Which estimator produced the pose.
    source: PoseSource,
    /// Where the translation scale came from.
    scale_source: ScaleSource,
    /// Translation length of the step, metres.
    step_m: f64,
    /// Eight-point scale, ground-plane and depth-ratio candidates, metres.
    scale_m: Option<f64>,
    scale_ground_m: Option<f64>,
    scale_depth_m: Option<f64>,
    /// Parallax measures, pixels.
    klt_median_px: Option<f64>,
    flow_p75_px: Option<f64>,
    /// Fraction of pixels with a valid flow.
    flow_valid_fraction: Option<f64>,
    correspondences: usize,
    eight_point_inliers: usize,
    pnp_correspondences: usize,
    pnp_inliers: usize,
    depth_cells: usize,
    timings: MonoFrameTimings,
}

impl MonoFrameReport {
    fn from_result(
        step: usize,
        index: usize,
        r: &MonoFrameResult,
        flow: Option<&DenseFlow>,
        timings: MonoFrameTimings,
    ) -> Self {
        Self {
            step,
            index,
            status: r.status,
            error: None,
            source: r.source,
            scale_source: r.scale_source,
            step_m: r.cur_from_prev.translation.vector.norm(),
            scale_m: r.scale_m.is_finite().then_some(r.scale_m),
            scale_ground_m: r.scale_ground_m,
            scale_depth_m: r.scale_depth_m,
            klt_median_px: r.klt_median_px,
            flow_p75_px: flow.map(|_| r.flow_p75_px),
            flow_valid_fraction: flow.map(DenseFlow::valid_fraction),
            correspondences: r.correspondences,
            eight_point_inliers: r.eight_point_inliers,
            pnp_correspondences: r.pnp_correspondences,
            pnp_inliers: r.pnp_inliers,
            depth_cells: r.depth_cells,
            timings,
        }
    }

    fn failed(
        step: usize,
        index: usize,
        error: String,
        step_m: f64,
        timings: MonoFrameTimings,
    ) -> Self {
        Self {
            step,
            index,
            status: MonoStatus::Failed,
            error: Some(error),
            source: PoseSource::ConstantVelocity,
            scale_source: ScaleSource::None,
            step_m,
            scale_m: None,
            scale_ground_m: None,
            scale_depth_m: None,
            klt_median_px: None,
            flow_p75_px: None,
            flow_valid_fraction: None,
            correspondences: 0,
            eight_point_inliers: 0,
            pnp_correspondences: 0,
            pnp_inliers: 0,
            depth_cells: 0,
            timings,
        }
    }
}

/// Mean time per frame over the run, milliseconds.
#[derive(Debug, Default, Serialize)]
struct MonoMeanTimings {
    flow_features_ms: f64,
    flow_matching_ms: f64,
    flow_uncertainty_ms: f64,
    flow_refinement_ms: f64,
    flow_ms: f64,
    flow_wait_ms: f64,
    correspondences_ms: f64,
    parallax_ms: f64,
    eight_point_ms: f64,
    triangulation_ms: f64,
    scale_ms: f64,
    pnp_ms: f64,
    depth_ms: f64,
    vo_ms: f64,
    save_ms: f64,
    wait_ms: f64,
    frame_ms: f64,
    wall_ms_per_frame: f64,
}

impl MonoMeanTimings {
    fn over(frames: &[MonoFrameReport], wall_s: f64) -> Self {
        let nf = frames.len().max(1) as f64;
        let mean = |f: &dyn Fn(&MonoFrameTimings) -> f64| {
            frames.iter().map(|r| f(&r.timings)).sum::<f64>() / nf
        };
        let flow =
            |g: fn(&FlowTimings) -> f64| move |t: &MonoFrameTimings| t.flow.as_ref().map_or(0.0, g);
        let vo = |g: fn(&MonoStageTimings) -> f64| {
            move |t: &MonoFrameTimings| t.vo.as_ref().map_or(0.0, g)
        };
        Self {
            flow_features_ms: mean(&flow(|t| t.features_ms)),
            flow_matching_ms: mean(&flow(|t| t.matching_ms)),
            flow_uncertainty_ms: mean(&flow(|t| t.uncertainty_ms)),
            flow_refinement_ms: mean(&flow(|t| t.refinement_ms)),
            flow_ms: mean(&flow(|t| t.total_ms)),
            flow_wait_ms: mean(&|t| t.flow_wait_ms),
            correspondences_ms: mean(&vo(|t| t.correspondences_ms)),
            parallax_ms: mean(&vo(|t| t.parallax_ms)),
            eight_point_ms: mean(&vo(|t| t.eight_point_ms)),
            triangulation_ms: mean(&vo(|t| t.triangulation_ms)),
            scale_ms: mean(&vo(|t| t.scale_ms)),
            pnp_ms: mean(&vo(|t| t.pnp_ms)),
            depth_ms: mean(&vo(|t| t.depth_ms)),
            vo_ms: mean(&vo(|t| t.total_ms)),
            save_ms: mean(&|t| t.save_ms),
            wait_ms: mean(&|t| t.wait_ms),
            frame_ms: mean(&|t| t.frame_ms),
            wall_ms_per_frame: wall_s * 1e3 / nf,
        }
    }
}

/// Count of frames per pose source.
#[derive(Debug, Default, Serialize)]
struct SourceCounts {
    eight_point: usize,
    pnp: usize,
    fused: usize,
    constant_velocity: usize,
}

#[derive(Debug, Serialize)]
struct MonoReport<'a> {
    sequence: &'a Path,
    mode: &'static str,
    /// Pose lines written (`2N−1` with `--palindrome`).
    frames: usize,
    /// Input frames `N`.
    input_frames: usize,
    palindrome: Option<PalindromeDrift>,
    loop_closure: Option<LoopClosureReport>,
    failed_frames: usize,
    low_parallax_frames: usize,
    sources: SourceCounts,
    wall_s: f64,
    mean: MonoMeanTimings,
    config: &'a MonoFileConfig,
    per_frame: Vec<MonoFrameReport>,
}

/// The loop-closure part of the mono JSON report.
#[derive(Debug, Serialize)]
struct LoopClosureReport {
    /// The odometry-only trajectory.
    odometry_output: PathBuf,
    /// Palindrome drift of the odometry-only trajectory (the report's `palindrome` is the
    /// corrected one's).
    odometry_palindrome: Option<PalindromeDrift>,
    accepted: usize,
    rejected: usize,
    /// Accepted closures the robust pose graph set aside.
    rejected_by_graph: usize,
    optimisations: usize,
    /// Every verified candidate.
    closures: Vec<ClosureReport>,
}

/// Loads the images of the run in `order`: the forward part is prefetched on a thread, the way
/// back of a palindrome is decoded inline (a few ms against the seconds of the flow).
struct MonoFrames<'a> {
    seq: &'a Sequence,
    forward: crate::prefetch::Prefetcher,
    forward_len: usize,
}

impl MonoFrames<'_> {
    fn load(&mut self, step: usize, index: usize) -> anyhow::Result<GrayImage> {
        if step < self.forward_len {
            let Some((i, loaded)) = self.forward.next() else {
                bail!("the frame loader stopped early");
            };
            debug_assert_eq!(i, index);
            Ok(loaded?.left)
        } else {
            Ok(self.seq.load_left(index)?)
        }
    }
}

/// The dense flow of the next frame pair, computed on its own thread while the current frame's
/// odometry runs (the flow does not depend on the odometry; both share rayon's pool, so the
/// sequential parts of one overlap with the other). Keyed by the steps of the pair: it is used
/// only when the frame it starts from was accepted.
struct FlowAhead {
    from_step: usize,
    to_step: usize,
    handle: std::thread::JoinHandle<Result<(DenseFlow, FlowTimings), MonoError>>,
}

impl FlowAhead {
    fn spawn(
        estimator: &std::sync::Arc<MonoFlow>,
        from: &GrayImage,
        to: &GrayImage,
        from_step: usize,
        to_step: usize,
    ) -> Self {
        let (estimator, from, to) = (std::sync::Arc::clone(estimator), from.clone(), to.clone());
        let handle = std::thread::spawn(move || estimator.compute_timed(&from, &to));
        Self {
            from_step,
            to_step,
            handle,
        }
    }

    fn join(self) -> anyhow::Result<(DenseFlow, FlowTimings)> {
        match self.handle.join() {
            Ok(r) => Ok(r?),
            Err(panic) => std::panic::resume_unwind(panic),
        }
    }
}

/// The fused depth map of the latest frame as a one-channel PFM on the depth grid.
fn depth_pfm(vo: &MonoOdometry) -> Option<PfmImage> {
    let d = vo.depth_map()?;
    Some(PfmImage {
        width: d.cols,
        height: d.rows,
        channels: 1,
        data: d.depth_m.clone(),
    })
}

/// Header of a `NNNNNN.tracks.csv` file (`--save-tracks`).
pub const TRACKS_CSV_HEADER: &str = "prev_u,prev_v,u,v,depth_m,inlier";

/// Writes the tracks of frame `index` into `dir` as `NNNNNN.tracks.csv` ([`TRACKS_CSV_HEADER`]).
fn save_tracks(
    dir: &Path,
    index: usize,
    tracks: &[visnav_odometry::stereo::Track],
) -> anyhow::Result<()> {
    let path = dir.join(format!("{index:06}.tracks.csv"));
    let mut text = String::with_capacity(48 * (tracks.len() + 1));
    text.push_str(TRACKS_CSV_HEADER);
    text.push('\n');
    for t in tracks {
        let _ = writeln!(
            text,
            "{:.3},{:.3},{:.3},{:.3},{:.4},{}",
            t.prev_left_px.x,
            t.prev_left_px.y,
            t.left_px.x,
            t.left_px.y,
            t.depth_m,
            u8::from(t.inlier)
        );
    }
    std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))
}

/// Writes the flow of the pair `prev → cur` into `dir`.
fn save_flow(dir: &Path, prev: usize, cur: usize, flow: &DenseFlow) -> anyhow::Result<()> {
    let stem = format!("{prev:06}_{cur:06}");
    visnav_io::flo::write_flo(
        &dir.join(format!("{stem}.flo")),
        &super::flow::to_flow_field(flow),
    )?;
    write_pfm(
        &dir.join(format!("{stem}.info.pfm")),
        &super::flow::information_pfm(flow),
    )?;
    Ok(())
}

#[allow(clippy::too_many_lines)]
fn run_mono(args: &Args, ctx: &super::Context) -> anyhow::Result<()> {
    let config = load_mono_config(args)?;
    let seq = open_sequence(args)?;
    let n = args.max_frames.map_or(seq.len(), |m| m.min(seq.len()));
    if n == 0 {
        bail!("no frames to process");
    }
    for dir in [&args.save_flow, &args.save_depth].into_iter().flatten() {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let order: Vec<usize> = if args.palindrome {
        palindrome_order(n)
    } else {
        (0..n).collect()
    };
    let flow_estimator = std::sync::Arc::new(MonoFlow::new(&config.mono.flow)?);
    let mut vo = MonoOdometry::new(seq.camera, config.mono.clone())?;
    let mut live = LiveView::open(&args.live(), seq.camera)?;
    let mut closer = if args.loop_closure {
        Some(LoopCloser::new(
            seq.camera,
            config.loop_closure.clone(),
            config.mono.clone(),
            config.mono.flow.flow.clone(),
        )?)
    } else {
        None
    };
    let bar = crate::progress::bar(order.len() as u64, "mono", ctx.quiet);
    let mut frames = MonoFrames {
        seq: &seq,
        forward: crate::prefetch::Prefetcher::new(&seq, 0..n, false, 2),
        forward_len: n,
    };
    let mut poses: Vec<Pose> = Vec::with_capacity(order.len());
    let mut per_frame: Vec<MonoFrameReport> = Vec::with_capacity(order.len());
    // the last image the pipeline accepted, its frame index and its step in `order`
    let mut prev: Option<(usize, GrayImage, usize)> = None;
    // pipelining: the flow of (this step → the next) runs on a thread while this step's
    // odometry runs; the next step's image, loaded for it
    let mut ahead: Option<FlowAhead> = None;
    let mut next_loaded: Option<anyhow::Result<GrayImage>> = None;
    // the pipeline's last motion `cur_from_prev` (constant-velocity prediction of a failed frame)
    let mut last_motion = Pose::identity();
    let start = Instant::now();
    for (step, &index) in order.iter().enumerate() {
        let t_wait = Instant::now();
        let loaded = match next_loaded.take() {
            Some(l) => l,
            None => frames.load(step, index),
        };
        let mut timings = MonoFrameTimings {
            wait_ms: t_wait.elapsed().as_secs_f64() * 1e3,
            ..MonoFrameTimings::default()
        };
        let t_frame = Instant::now();
        let outcome = (|| -> anyhow::Result<(GrayImage, MonoFrameResult, Option<DenseFlow>)> {
            let image = loaded?;
            let flow = match &prev {
                Some((prev_index, prev_image, prev_step)) => {
                    let t_flow = Instant::now();
                    // the flow computed ahead is this pair's unless the frame in between failed
                    let computed = match ahead.take() {
                        Some(a) if a.from_step == *prev_step && a.to_step == step => a.join(),
                        other => {
                            drop(other.map(FlowAhead::join));
                            flow_estimator
                                .compute_timed(prev_image, &image)
                                .map_err(anyhow::Error::from)
                        }
                    };
                    let (flow, flow_timings) =
                        computed.with_context(|| format!("flow {prev_index} -> {index}"))?;
                    timings.flow_wait_ms = t_flow.elapsed().as_secs_f64() * 1e3;
                    timings.flow = Some(flow_timings);
                    Some(flow)
                }
                None => None,
            };
            // start the next pair's flow (this image → the next) before this frame's odometry
            if let Some(&next_index) = order.get(step + 1) {
                let next = frames.load(step + 1, next_index);
                if let Ok(next_image) = &next {
                    ahead = Some(FlowAhead::spawn(
                        &flow_estimator,
                        &image,
                        next_image,
                        step,
                        step + 1,
                    ));
                }
                next_loaded = Some(next);
            }
            let result = vo.process(&image, flow.as_ref())?;
            Ok((image, result, flow))
        })();
        match outcome {
            Ok((image, result, flow)) => {
                let t_save = Instant::now();
                let save_now = step % args.save_every == 0;
                if let (true, Some(dir), Some(f), Some((p, _, _))) =
                    (save_now, &args.save_flow, &flow, &prev)
                {
                    save_flow(dir, *p, index, f)?;
                }
                if let (true, Some(dir), Some(pfm)) = (save_now, &args.save_depth, depth_pfm(&vo)) {
                    let back = if step >= n { "_back" } else { "" };
                    let path = dir.join(format!("{index:06}{back}.pfm"));
                    write_pfm(&path, &pfm)?;
                }
                timings.save_ms = t_save.elapsed().as_secs_f64() * 1e3;
                timings.vo = Some(result.timings);
                timings.frame_ms = t_frame.elapsed().as_secs_f64() * 1e3;
                if let Some(live) = &mut live {
                    live.log(&LiveFrame {
                        step,
                        image: &image,
                        world_from_cam: &result.world_from_cam,
                        flow: flow.as_ref(),
                        depth: vo.depth_map(),
                    });
                }
                last_motion = result.cur_from_prev;
                poses.push(result.world_from_cam);
                if let Some(c) = &mut closer {
                    let motion =
                        poses[poses.len().saturating_sub(2)].inverse() * result.world_from_cam;
                    c.process(Some(&image), &motion.inverse(), vo.depth_map(), |s| {
                        seq.load_left(order[s])
                    })?;
                }
                per_frame.push(MonoFrameReport::from_result(
                    step,
                    index,
                    &result,
                    flow.as_ref(),
                    timings,
                ));
                prev = Some((index, image, step));
            }
            Err(e) => {
                // the pipeline does not see this frame: the next good frame is matched against
                // the last accepted image, so its pose stays consistent; this one is predicted
                let error = format!("{e:#}");
                log::warn!("frame {index}: {error}; constant-velocity prediction");
                let world_from_prev = poses.last().copied().unwrap_or_else(Pose::identity);
                let predicted = if poses.is_empty() {
                    world_from_prev
                } else {
                    world_from_prev * last_motion.inverse()
                };
                poses.push(predicted);
                if let Some(c) = &mut closer {
                    let motion = world_from_prev.inverse() * predicted;
                    c.process(None, &motion.inverse(), None, |s| seq.load_left(order[s]))?;
                }
                timings.frame_ms = t_frame.elapsed().as_secs_f64() * 1e3;
                let step_m =
                    (predicted.translation.vector - world_from_prev.translation.vector).norm();
                per_frame.push(MonoFrameReport::failed(step, index, error, step_m, timings));
            }
        }
        bar.inc(1);
    }
    drop(ahead.map(FlowAhead::join));
    drop(frames);
    bar.finish_and_clear();
    let wall_s = start.elapsed().as_secs_f64();
    let mut loop_report = None;
    if let Some(c) = &closer {
        // the odometry-only trajectory beside the corrected one
        let odometry_output = odometry_path_for(&args.output);
        visnav_io::trajectory::write_kitti(&odometry_output, &poses)
            .with_context(|| format!("writing {}", odometry_output.display()))?;
        let closures = c.closures();
        let accepted = closures.iter().filter(|r| r.accepted).count();
        loop_report = Some(LoopClosureReport {
            odometry_output,
            odometry_palindrome: if args.palindrome {
                palindrome_drift(&poses)
            } else {
                None
            },
            accepted,
            rejected: closures.len() - accepted,
            rejected_by_graph: closures.iter().filter(|r| r.rejected_by_graph).count(),
            optimisations: c.optimisations(),
            closures,
        });
        poses = c.corrected_poses();
    }
    visnav_io::trajectory::write_kitti(&args.output, &poses)
        .with_context(|| format!("writing {}", args.output.display()))?;
    let tum_path = write_tum_beside(&args.output, &seq, &poses)?;
    let config_path = config_path_for(&args.output);
    std::fs::write(&config_path, toml::to_string_pretty(&config)?)
        .with_context(|| format!("writing {}", config_path.display()))?;

    let count = |f: &dyn Fn(&MonoFrameReport) -> bool| per_frame.iter().filter(|r| f(r)).count();
    let failed = count(&|r| r.status == MonoStatus::Failed);
    let low_parallax = count(&|r| r.status == MonoStatus::LowParallax);
    let sources = SourceCounts {
        eight_point: count(&|r| r.source == PoseSource::EightPoint),
        pnp: count(&|r| r.source == PoseSource::Pnp),
        fused: count(&|r| r.source == PoseSource::Fused),
        constant_velocity: count(&|r| r.source == PoseSource::ConstantVelocity),
    };
    let drift = if args.palindrome {
        palindrome_drift(&poses)
    } else {
        None
    };
    let mean = MonoMeanTimings::over(&per_frame, wall_s);
    if !ctx.quiet {
        println!(
            "mono odometry: {} poses ({n} frames{}) in {:.2} s ({:.1} ms/frame wall: flow {:.1} ms, odometry {:.1} ms), {failed} failed, {low_parallax} low-parallax",
            per_frame.len(),
            if args.palindrome { ", palindrome" } else { "" },
            wall_s,
            mean.wall_ms_per_frame,
            mean.flow_ms,
            mean.vo_ms,
        );
        println!(
            "pose sources: {} eight-point, {} PnP, {} fused, {} constant velocity",
            sources.eight_point, sources.pnp, sources.fused, sources.constant_velocity
        );
        if let Some(l) = &loop_report {
            println!(
                "loop closure: {} accepted ({} set aside by the pose graph), {} rejected, {} optimisations; odometry only: {}",
                l.accepted,
                l.rejected_by_graph,
                l.rejected,
                l.optimisations,
                l.odometry_output.display()
            );
            if let Some(d) = &l.odometry_palindrome {
                println!(
                    "  odometry only: end-point error {:.3} m ({:.2} % of the distance)",
                    d.end_point_error_m,
                    100.0 * d.end_point_error_relative
                );
            }
        }
        if let Some(d) = &drift {
            println!("palindrome drift (§6.2)");
            println!("  distance travelled   {:>10.3} m", d.distance_travelled_m);
            println!(
                "  end-point error      {:>10.3} m  ({:.2} % of the distance)",
                d.end_point_error_m,
                100.0 * d.end_point_error_relative
            );
            println!(
                "  scale drift          {:>10.4}    (mean step back {:.3} m / out {:.3} m)",
                d.scale_drift_ratio, d.mean_step_back_m, d.mean_step_out_m
            );
        }
        print_output_paths(&args.output, &config_path, tum_path.as_deref());
    }
    if let Some(json) = &args.json {
        let report = MonoReport {
            sequence: &args.sequence,
            mode: "mono",
            frames: per_frame.len(),
            input_frames: n,
            palindrome: drift,
            loop_closure: loop_report,
            failed_frames: failed,
            low_parallax_frames: low_parallax,
            sources,
            wall_s,
            mean,
            config: &config,
            per_frame,
        };
        write_json(json, &report)?;
    }
    Ok(())
}
