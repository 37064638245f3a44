//! `visnav odometry`: camera trajectory of a KITTI sequence (odometry layout or raw drive), an
//! EuRoC (ASL), TUM RGB-D or TUM monoVO sequence, a folder of PNG/JPEG images or a video file
//! (`--camera FILE` gives the calibration where the input has none; see `visnav_io::calibration`
//! and `visnav_io::tum_mono`). Distorted or unrectified inputs are undistorted / rectified on load.
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
//! frame as `NNNNNN.tracks.csv` (`visnav_io::tracks::TRACKS_CSV_HEADER`).
//!
//! `--report` makes the output's directory a run directory (see `visnav_report`): the JSON
//! report goes to `report.json` there unless `--json` is given, mono runs save the flow and depth
//! of a few gallery frames to `flow/` and `depth/`, stereo runs their tracks to `tracks/`, unless
//! a `--save-*` option is given, and `report.html` is written there after the run.
//!
//! `--loop-closure` adds the loop-closure stage (`visnav_loop::LoopCloser`, §5 of the mono
//! paper): candidates every 10 frames by position and SSIM, verification by dense flow with
//! uncertainty, relative pose by PnP from the earlier frame's depth (stereo: its stereo points),
//! robust pose graph. The corrected trajectory goes to `--output`, the odometry-only one beside it
//! (`NAME.odometry.txt`), and the JSON report lists every verified closure (SSIM, reliable-pixel
//! share, relative pose, verdict).

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use crate::live::{LiveFrame, LiveView};
use anyhow::{Context as _, bail};
use nalgebra::Matrix6;
use visnav_core::Pose;
use visnav_geometry::fundamental::Estimator;
use visnav_io::atomic::{check_writable, write_atomic};
use visnav_io::journal::PoseJournal;
use visnav_io::pfm::write_pfm;
use visnav_io::tracks::TrackRow;
use visnav_io::{FrameSource, Sequence};
use visnav_odometry::stereo::OutlierMode;
use visnav_pipeline::job::{ConfigSource, DrivenRun, PreparedRun, RunOutcome, RunSpec, tum_poses};
use visnav_pipeline::report::RunReport;
use visnav_pipeline::{Control, FrameResult, Outputs};

/// Which pipeline to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Mode {
    /// Stereo RotROCC (needs image_0 + image_1, or image_00 + image_01).
    Stereo,
    /// Monocular VO from dense flow with uncertainty.
    Mono,
}

impl From<Mode> for visnav_pipeline::Mode {
    fn from(m: Mode) -> Self {
        match m {
            Mode::Stereo => Self::Stereo,
            Mode::Mono => Self::Mono,
        }
    }
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
    /// JPEG images (or `left/` + `right/`), or video file; or a live input (mono, needs
    /// --camera): `rtsp://…`, `udp://…`, `srt://…`, `tcp://…`, `v4l2:///dev/video0` or
    /// `/dev/video0`, `-` (a stream on standard input: MJPEG, MPEG-TS, y4m …).
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
    /// The defaults under `--config`: `paper` (the papers' pipelines, the default) or
    /// `realtime` (mono on the fast flow, about 3x faster a frame at the same accuracy on KITTI;
    /// stereo is real time with the paper's settings and stays as it is).
    #[arg(long, value_enum, default_value = "paper")]
    pub preset: PresetArg,
    /// Outlier criterion (stereo), overriding the configuration.
    #[arg(long, value_enum)]
    pub outlier: Option<OutlierArg>,
    /// Stereo: frame-to-frame RotROCC, no persistent tracks and window bundle adjustment.
    #[arg(long)]
    pub no_ba: bool,
    /// Process only the first N frames.
    #[arg(long)]
    pub max_frames: Option<usize>,
    /// Camera height above the ground, metres (mono scale; KITTI 1.7).
    #[arg(long)]
    pub camera_height: Option<f64>,
    /// Aerial vehicle (mono): ground-plane scale for the first frame only, depth ratios after,
    /// and the window bundle adjustment over refined tracks (`[mono.window] mode`, `auto`).
    #[arg(long)]
    pub aerial: bool,
    /// With --aerial: the ground's normal in the camera of a level flight, X,Y,Z (x right, y
    /// down, z along the optical axis): `0,0,1` for a small drone's camera looking straight
    /// down. Every frame's motion is then the ground plane's with this normal held
    /// (`[mono.homography] ground_normal`; see docs/guide/aerial.md).
    #[arg(
        long,
        requires = "aerial",
        value_parser = parse_vector3,
        allow_hyphen_values = true,
        value_name = "X,Y,Z"
    )]
    pub ground_normal: Option<[f64; 3]>,
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
    /// Image topic of a ROS 2 bag (`visnav info BAG` lists them); default: the bag's only one.
    #[arg(long, value_name = "TOPIC")]
    pub topic: Option<String>,
    /// Right image topic of a ROS 2 bag (stereo), paired with --topic by header stamp.
    #[arg(long, value_name = "TOPIC")]
    pub right_topic: Option<String>,
    /// Also write the trajectory as `geometry_msgs/msg/PoseStamped` messages (topic
    /// `/visnav/pose`, frame `visnav_world` = the first camera frame) into this MCAP file.
    #[arg(long, value_name = "FILE")]
    pub output_mcap: Option<PathBuf>,
    /// Loop closure (paper §5; stereo: PnP from the stereo points): the corrected trajectory goes
    /// to --output, the odometry-only one to NAME.odometry.txt; `[loop_closure]` in --config tunes it.
    #[arg(long)]
    pub loop_closure: bool,
    /// Write one JSON line a frame as it happens (step, index, timestamp, `world_from_cam` 3x4
    /// row-major, status, latency from the frame's arrival, frames dropped before it): `-`
    /// (standard output, flushed per line; the human output then goes to stderr) or
    /// `udp://HOST:PORT` (one datagram a line).
    #[arg(long, value_name = "TARGET")]
    pub poses_out: Option<String>,
    /// Live input: what to do with the frames that arrive while the odometry is busy: `newest`
    /// (keep the newest, drop and count the rest; the default for live input) or `all` (queue
    /// every frame; recordings always process every frame).
    #[arg(long, value_enum, value_name = "POLICY")]
    pub frames_policy: Option<FramesPolicyArg>,
    /// Live input: reconnection attempts after the stream is lost (doubling waits from 0.5 s
    /// up to 8 s; a connection that delivered frames resets the count).
    #[arg(long, default_value = "3", value_name = "N")]
    pub reconnect: usize,
    /// Live input: ffmpeg's connect and read timeout, seconds (a stream silent for longer is
    /// lost).
    #[arg(long, default_value = "5", value_name = "SECONDS")]
    pub stream_timeout: f64,
}

/// The `--frames-policy` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum FramesPolicyArg {
    /// Keep the newest frame, drop the others (real time).
    Newest,
    /// Process every frame.
    All,
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

/// Runs the subcommand on a recording (a live input goes to [`super::odometry_live::run`]).
///
/// # Errors
/// An unreadable sequence or configuration, a sequence without stereo for `--mode stereo`, or an
/// output that cannot be written (checked before the run starts). Frames that fail inside the
/// pipeline are not errors: they get the constant-velocity prediction and a status in the
/// report (one pose per input frame, always).
pub fn run(args: &Args, ctx: &super::Context) -> anyhow::Result<()> {
    if args.frames_policy == Some(FramesPolicyArg::Newest) {
        bail!(
            "--frames-policy newest applies to live input only (a recording gives every frame to the odometry)"
        );
    }
    if args.report {
        return run_with_report(args, ctx);
    }
    check_mode_options(args)?;
    check_outputs(args)?;
    let spec = run_spec(args);
    let mut prepared = spec.prepare(outputs(args))?;
    let interrupted = crate::interrupt::install_handler();
    let driven = drive(args, ctx, &mut prepared, &interrupted)?;
    finish_run(args, ctx, &spec, &prepared, driven)
}

/// The run the arguments describe (the same setup as Python's `visnav.run_odometry` and a batch
/// manifest line: `visnav_pipeline::job`).
pub(super) fn run_spec(args: &Args) -> RunSpec {
    RunSpec {
        sequence: args.sequence.clone(),
        mode: args.mode.into(),
        camera: args.camera.clone(),
        preset: args.preset.into(),
        config: args.config.clone().map(ConfigSource::File),
        camera_height: args.camera_height,
        max_frames: args.max_frames,
        aerial: args.aerial,
        ground_normal: args.ground_normal,
        estimator: args.estimator.map(Into::into),
        outlier: args.outlier.map(Into::into),
        no_ba: args.no_ba,
        palindrome: args.palindrome,
        loop_closure: args.loop_closure,
        topic: args.topic.clone(),
        right_topic: args.right_topic.clone(),
    }
}

/// `X,Y,Z`: three finite numbers.
fn parse_vector3(s: &str) -> Result<[f64; 3], String> {
    let values: Vec<f64> = s
        .split(',')
        .map(|v| v.trim().parse::<f64>().map_err(|e| format!("'{v}': {e}")))
        .collect::<Result<_, _>>()?;
    match <[f64; 3]>::try_from(values) {
        Ok(v) if v.iter().all(|x| x.is_finite()) => Ok(v),
        _ => Err(format!("expected three finite numbers X,Y,Z, got '{s}'")),
    }
}

/// The `--preset` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum PresetArg {
    /// The papers' pipelines.
    Paper,
    /// Real time: mono on the fast flow.
    Realtime,
}

impl From<PresetArg> for visnav_pipeline::Preset {
    fn from(p: PresetArg) -> Self {
        match p {
            PresetArg::Paper => Self::Paper,
            PresetArg::Realtime => Self::Realtime,
        }
    }
}

/// The per-frame outputs the saving options and the live view need.
fn outputs(args: &Args) -> Outputs {
    let live = args.rerun_save.is_some() || args.rerun_connect;
    Outputs {
        flow: args.save_flow.is_some() || live,
        depth: args.save_depth.is_some() || live,
        tracks: args.save_tracks.is_some(),
        image: live,
    }
}

/// Options that belong to the other mode are errors.
fn check_mode_options(args: &Args) -> anyhow::Result<()> {
    if args.palindrome && args.output_mcap.is_some() {
        bail!(
            "--output-mcap does not apply to --palindrome (the way back has no timestamps of its own)"
        );
    }
    let wrong: &[(bool, &str)] = match args.mode {
        Mode::Stereo => &[
            (args.camera_height.is_some(), "--camera-height"),
            (args.aerial, "--aerial"),
            (args.ground_normal.is_some(), "--ground-normal"),
            (args.estimator.is_some(), "--estimator"),
            (args.save_depth.is_some(), "--save-depth"),
            (args.save_flow.is_some(), "--save-flow"),
            (args.palindrome, "--palindrome"),
        ],
        Mode::Mono => &[
            (args.outlier.is_some(), "--outlier"),
            (args.no_ba, "--no-ba"),
            (args.save_tracks.is_some(), "--save-tracks"),
        ],
    };
    if let Some((_, name)) = wrong.iter().find(|(set, _)| *set) {
        let other = match args.mode {
            Mode::Stereo => "mono",
            Mode::Mono => "stereo",
        };
        bail!("{name} applies to --mode {other} only");
    }
    Ok(())
}

/// Every output path is checked before the run: writable, not a directory, not one of the
/// inputs, and no two outputs the same file.
pub(super) fn check_outputs(args: &Args) -> anyhow::Result<()> {
    refuse_standard_output(args)?;
    let mut outputs = vec![
        ("--output", args.output.clone()),
        ("the configuration", sibling(&args.output, "config.toml")),
    ];
    if let Some(j) = &args.json {
        outputs.push(("--json", j.clone()));
    }
    if let Some(m) = &args.output_mcap {
        outputs.push(("--output-mcap", m.clone()));
    }
    if args.loop_closure {
        outputs.push((
            "the odometry-only poses",
            sibling(&args.output, "odometry.txt"),
        ));
    }
    let canon = |p: &Path| {
        let abs = std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
        std::fs::canonicalize(&abs).unwrap_or(abs)
    };
    let sequence = canon(&args.sequence);
    let inputs: Vec<PathBuf> = [args.camera.as_ref(), args.config.as_ref()]
        .into_iter()
        .flatten()
        .map(|p| canon(p))
        .chain([sequence.clone()])
        .collect();
    let mut checked: Vec<(&str, PathBuf)> = Vec::with_capacity(outputs.len());
    for (name, path) in &outputs {
        check_writable(path).with_context(|| format!("{name} {}", path.display()))?;
        let c = canon(path);
        if let Some((other, _)) = checked.iter().find(|(_, p)| *p == c) {
            bail!("{name} and {other} are the same file ({})", path.display());
        }
        if inputs.contains(&c) || c.starts_with(&sequence) && path.exists() {
            bail!(
                "{name} {} would overwrite an input of the run",
                path.display()
            );
        }
        checked.push((name, c));
    }
    Ok(())
}

/// `-` as an output path is the Unix name of standard output, which the run does not write to
/// (the poses, the configuration beside them and the report are files): refused with the option
/// named, rather than writing a file called `-`.
fn refuse_standard_output(args: &Args) -> anyhow::Result<()> {
    let outputs = [
        ("--output", "poses", Some(&args.output)),
        ("--json", "the JSON report", args.json.as_ref()),
        ("--output-mcap", "the MCAP file", args.output_mcap.as_ref()),
    ];
    for (name, what, path) in outputs {
        if path.is_some_and(|p| p.as_os_str() == "-") {
            bail!("{name} -: writing {what} to standard output is not supported; give a file path");
        }
    }
    Ok(())
}

/// The frame loop: pushes every frame, journals each pose, saves the requested files.
fn drive(
    args: &Args,
    ctx: &super::Context,
    prepared: &mut PreparedRun,
    interrupted: &AtomicBool,
) -> anyhow::Result<(DrivenRun, PoseJournal)> {
    for dir in [&args.save_flow, &args.save_depth, &args.save_tracks]
        .into_iter()
        .flatten()
    {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let mut live = LiveView::open(&args.live(), prepared.sequence.camera)?;
    let mut poses_out = args
        .poses_out
        .as_deref()
        .map(super::poses_out::PosesOut::open)
        .transpose()?;
    let mut journal = PoseJournal::create(&args.output)?;
    let source = Arc::clone(&prepared.source);
    let bar = crate::progress::bar(
        source.len() as u64,
        visnav_pipeline::Mode::from(args.mode).name(),
        ctx.quiet,
    );
    let driven: anyhow::Result<DrivenRun> = prepared.drive_with(|r, arrival| {
        if let Some(p) = &mut poses_out {
            p.send(r, arrival);
        }
        let saved = journal
            .append(&r.world_from_cam)
            .map_err(anyhow::Error::from)
            .and_then(|()| save_frame_files(args, source.as_ref(), r));
        if let (Some(live), Some(image)) = (&mut live, &r.image) {
            live.log(&LiveFrame {
                step: r.position,
                image,
                world_from_cam: &r.world_from_cam,
                flow: r.flow.as_ref(),
                depth: r.depth.as_ref(),
            });
        }
        bar.inc(1);
        saved?;
        Ok(if interrupted.load(Ordering::SeqCst) {
            Control::Stop
        } else {
            Control::Continue
        })
    });
    bar.finish_and_clear();
    match driven {
        Ok(d) => Ok((d, journal)),
        Err(e) => Err(e.context(format!(
            "the run stopped; the poses of the frames done are in {}",
            journal.path().display()
        ))),
    }
}

/// The flow, depth and tracks files of one frame, when asked for (every `--save-every`-th).
fn save_frame_files(args: &Args, source: &dyn FrameSource, r: &FrameResult) -> anyhow::Result<()> {
    if r.position % args.save_every != 0 {
        return Ok(());
    }
    let index = source.index_of(r.position);
    if let (Some(dir), Some(flow), Some(p)) = (&args.save_flow, &r.flow, r.reference_position) {
        let stem = format!("{:06}_{index:06}", source.index_of(p));
        visnav_io::flo::write_flo(
            &dir.join(format!("{stem}.flo")),
            &super::flow::to_flow_field(flow),
        )?;
        write_pfm(
            &dir.join(format!("{stem}.info.pfm")),
            &super::flow::information_pfm(flow),
        )?;
    }
    if let (Some(dir), Some(d)) = (&args.save_depth, &r.depth) {
        let back = if r.position != index { "_back" } else { "" };
        let pfm = visnav_io::pfm::PfmImage {
            width: d.cols,
            height: d.rows,
            channels: 1,
            data: d.depth_m.clone(),
        };
        write_pfm(&dir.join(format!("{index:06}{back}.pfm")), &pfm)?;
    }
    if let (Some(dir), Some(tracks)) = (&args.save_tracks, &r.tracks)
        && !tracks.is_empty()
    {
        let rows: Vec<TrackRow> = tracks
            .iter()
            .map(|t| TrackRow {
                prev_px: [t.prev_left_px.x, t.prev_left_px.y],
                cur_px: [t.left_px.x, t.left_px.y],
                depth_m: t.depth_m,
                inlier: t.inlier,
            })
            .collect();
        visnav_io::tracks::write_tracks_csv(&dir.join(format!("{index:06}.tracks.csv")), &rows)?;
    }
    Ok(())
}

/// Writes the poses (atomically, replacing the journal), the TUM poses, the configuration and
/// the JSON report, and prints the summary.
fn finish_run(
    args: &Args,
    ctx: &super::Context,
    spec: &RunSpec,
    prepared: &PreparedRun,
    (driven, journal): (DrivenRun, PoseJournal),
) -> anyhow::Result<()> {
    let interrupted = driven.interrupted;
    let RunOutcome {
        poses,
        odometry_poses,
        mut report,
    } = prepared.finish(spec, driven);
    if let Some(summary) = &mut report.loop_closure {
        let odometry_output = sibling(&args.output, "odometry.txt");
        visnav_io::trajectory::write_kitti(&odometry_output, &odometry_poses)
            .with_context(|| format!("writing {}", odometry_output.display()))?;
        summary.odometry_output = Some(odometry_output);
    }
    journal
        .commit(&poses)
        .with_context(|| format!("writing {}", args.output.display()))?;
    let tum_path = write_tum_beside(&args.output, &prepared.sequence, &poses)?;
    if let Some(path) = &args.output_mcap {
        let covariances: Vec<_> = (report.per_frame.iter())
            .map(|f| {
                f.prev_from_cur_covariance
                    .map(|c| Matrix6::from_fn(|r, k| c[r][k]))
            })
            .collect();
        write_pose_mcap(path, &prepared.sequence, &poses, &covariances)?;
    }
    let config_path = sibling(&args.output, "config.toml");
    let toml = report.config.to_toml().map_err(anyhow::Error::msg)?;
    write_atomic(&config_path, toml.as_bytes())?;
    if let Some(json) = &args.json {
        write_atomic(
            json,
            report.to_json().map_err(anyhow::Error::msg)?.as_bytes(),
        )?;
    }
    if !ctx.quiet {
        let mut out = human_output(args);
        print_summary(&mut out, &report)?;
        print_output_paths(&mut out, &args.output, &config_path, tum_path.as_deref())?;
    }
    if interrupted {
        bail!(
            "interrupted: {} of {} poses written to {} (the frames done)",
            poses.len(),
            prepared.expected_poses(),
            args.output.display()
        );
    }
    Ok(())
}

/// Where the summary goes: standard output, or standard error when `--poses-out -` writes the
/// pose lines there.
pub(super) fn human_output(args: &Args) -> Box<dyn std::io::Write> {
    if super::poses_out::PosesOut::is_stdout(args.poses_out.as_deref()) {
        Box::new(std::io::stderr())
    } else {
        Box::new(std::io::stdout())
    }
}

/// The run's summary lines.
pub(super) fn print_summary(out: &mut dyn std::io::Write, r: &RunReport) -> std::io::Result<()> {
    let m = &r.mean;
    writeln!(
        out,
        "{} odometry: {} poses ({} frames{}) in {:.2} s ({:.1} ms/frame wall: flow {:.1} ms, odometry {:.1} ms), {} fallback, {} skipped, {} low-parallax",
        r.mode.name(),
        r.frames,
        r.input_frames,
        if r.palindrome.is_some() {
            ", palindrome"
        } else {
            ""
        },
        r.wall_s,
        m.wall_ms_per_frame,
        m.flow_ms,
        m.odometry_ms,
        r.failed_frames,
        r.skipped_frames,
        r.low_parallax_frames,
    )?;
    if let Some(s) = &r.sources {
        writeln!(
            out,
            "pose sources: {} eight-point, {} PnP, {} fused, {} constant velocity",
            s.eight_point, s.pnp, s.fused, s.constant_velocity
        )?;
    }
    if let Some(l) = &r.loop_closure {
        writeln!(
            out,
            "loop closure: {} accepted ({} set aside by the pose graph), {} rejected, {} optimisations; odometry only: {}",
            l.accepted,
            l.rejected_by_graph,
            l.rejected,
            l.optimisations,
            l.odometry_output
                .as_deref()
                .unwrap_or(Path::new("-"))
                .display()
        )?;
        if let Some(d) = &l.odometry_palindrome {
            writeln!(
                out,
                "  odometry only: end-point error {:.3} m ({:.2} % of the distance)",
                d.end_point_error_m,
                100.0 * d.end_point_error_relative
            )?;
        }
    }
    if let Some(d) = &r.palindrome {
        write!(out, "{d}")?;
    }
    Ok(())
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
    let inputs = visnav_report::ReportInputs {
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
    visnav_report::write(&inputs, &output)?;
    if !ctx.quiet {
        writeln!(human_output(args), "report: {}", output.display())?;
    }
    Ok(())
}

/// Prints where a run wrote its poses, its configuration and (when asked for) its TUM poses.
pub(super) fn print_output_paths(
    out: &mut dyn std::io::Write,
    output: &Path,
    config: &Path,
    tum: Option<&Path>,
) -> std::io::Result<()> {
    writeln!(
        out,
        "poses: {}  config: {}",
        output.display(),
        config.display()
    )?;
    if let Some(p) = tum {
        writeln!(out, "poses with timestamps (TUM): {}", p.display())?;
    }
    Ok(())
}

/// `poses` in TUM format as `<stem>.tum.txt` beside `output` (`visnav_pipeline::job::tum_poses`);
/// `None` without timestamps or one pose per frame (palindrome).
fn write_tum_beside(
    output: &Path,
    seq: &Sequence,
    poses: &[Pose],
) -> anyhow::Result<Option<PathBuf>> {
    let Some((poses, times)) = tum_poses(seq, poses) else {
        return Ok(None);
    };
    let path = sibling(output, "tum.txt");
    visnav_io::trajectory::write_tum(&path, &poses, &times)
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(Some(path))
}

/// The poses as an MCAP file of `PoseStamped` messages stamped with the frames' timestamps, and
/// `nav_msgs/Odometry` ones with each step's covariance (`visnav_io::bag::writer`); a palindrome
/// run's way back has no timestamps of its own.
fn write_pose_mcap(
    path: &Path,
    seq: &Sequence,
    poses: &[Pose],
    covariances: &[Option<Matrix6<f64>>],
) -> anyhow::Result<()> {
    let Some(stamps) = seq.timestamps.get(..poses.len()) else {
        bail!(
            "--output-mcap: {} poses but {} frame timestamps (a palindrome run has no timestamps for its way back)",
            poses.len(),
            seq.timestamps.len()
        );
    };
    visnav_io::bag::writer::write_odometry_mcap(path, poses, stamps, Some(covariances))
        .with_context(|| format!("writing {}", path.display()))
}

/// `poses.txt` → `poses.<suffix>` in the same directory.
pub(super) fn sibling(output: &Path, suffix: &str) -> PathBuf {
    let stem = output
        .file_stem()
        .map_or_else(|| "poses".into(), |s| s.to_string_lossy().into_owned());
    output.with_file_name(format!("{stem}.{suffix}"))
}
