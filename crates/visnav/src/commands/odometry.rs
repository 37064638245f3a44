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
//! frame as `NNNNNN.tracks.csv` (`visnav_io::tracks::TRACKS_CSV_HEADER`).
//!
//! `--report` makes the output's directory a run directory (see `visnav_report`): the JSON
//! report goes to `report.json` there unless `--json` is given, mono runs save the flow and depth
//! of a few gallery frames to `flow/` and `depth/`, stereo runs their tracks to `tracks/`, unless
//! a `--save-*` option is given, and `report.html` is written there after the run.
//!
//! `--loop-closure` (mono) adds the loop-closure stage (`visnav_loop::LoopCloser`, §5 of the
//! paper): candidates every 10 frames by position and SSIM, verification by dense flow with
//! uncertainty, relative pose by the monocular motion estimation, robust pose graph. The corrected
//! trajectory goes to `--output`, the odometry-only one beside it (`NAME.odometry.txt`), and the
//! JSON report lists every verified closure (SSIM, reliable-pixel share, relative pose, verdict).

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use crate::live::{LiveFrame, LiveView};
use anyhow::{Context as _, bail};
use visnav_core::Pose;
use visnav_eval::palindrome::palindrome_drift;
use visnav_geometry::fundamental::Estimator;
use visnav_io::atomic::{PoseJournal, check_writable, write_atomic};
use visnav_io::pfm::write_pfm;
use visnav_io::tracks::TrackRow;
use visnav_io::{FrameSource, Palindrome, Sequence, Take};
use visnav_odometry::stereo::{OutlierMode, StereoConfig};
use visnav_pipeline::report::{FrameRecord, LoopClosureSummary, RunReport};
use visnav_pipeline::{
    Control, FrameResult, MonoRunConfig, Odometry, Outputs, RunConfig, SourceStore, run_source,
};

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

/// Runs the subcommand.
///
/// # Errors
/// An unreadable sequence or configuration, a sequence without stereo for `--mode stereo`, or an
/// output that cannot be written (checked before the run starts). Frames that fail inside the
/// pipeline are not errors: they get the constant-velocity prediction and a status in the
/// report (one pose per input frame, always).
pub fn run(args: &Args, ctx: &super::Context) -> anyhow::Result<()> {
    if args.report {
        return run_with_report(args, ctx);
    }
    check_mode_options(args)?;
    check_outputs(args)?;
    let seq = open_sequence(args)?;
    let n = args.max_frames.map_or(seq.len(), |m| m.min(seq.len()));
    if n == 0 {
        bail!("no frames to process");
    }
    let source: Arc<dyn FrameSource> = if args.palindrome {
        Arc::new(Palindrome::new(seq.clone(), Some(n)))
    } else {
        Arc::new(Take::new(seq.clone(), n))
    };
    let (odometry, config) = build_odometry(args, &seq, &source)?;
    let interrupted = install_interrupt_handler();
    let run = drive(args, ctx, odometry, &source, &seq, &interrupted)?;
    finish_run(args, ctx, &seq, n, config, run)
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
            (args.estimator.is_some(), "--estimator"),
            (args.save_depth.is_some(), "--save-depth"),
            (args.save_flow.is_some(), "--save-flow"),
            (args.palindrome, "--palindrome"),
            (args.loop_closure, "--loop-closure"),
        ],
        Mode::Mono => &[
            (args.outlier.is_some(), "--outlier"),
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
fn check_outputs(args: &Args) -> anyhow::Result<()> {
    let mut outputs = vec![
        ("--output", args.output.clone()),
        ("the configuration", config_path_for(&args.output)),
    ];
    if let Some(j) = &args.json {
        outputs.push(("--json", j.clone()));
    }
    if let Some(m) = &args.output_mcap {
        outputs.push(("--output-mcap", m.clone()));
    }
    if args.loop_closure {
        outputs.push(("the odometry-only poses", odometry_path_for(&args.output)));
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

/// The odometry of the run with its effective configuration.
fn build_odometry(
    args: &Args,
    seq: &Sequence,
    source: &Arc<dyn FrameSource>,
) -> anyhow::Result<(Odometry, RunConfig)> {
    let live = args.rerun_save.is_some() || args.rerun_connect;
    let outputs = Outputs {
        flow: args.save_flow.is_some() || live,
        depth: args.save_depth.is_some() || live,
        tracks: args.save_tracks.is_some(),
        image: live,
    };
    match args.mode {
        Mode::Stereo => {
            let config = load_stereo_config(args)?;
            let Some(rig) = seq.stereo_camera() else {
                if seq.layout == visnav_io::SequenceLayout::RosBag {
                    bail!(
                        "{}: --mode stereo on a bag needs --right-topic (`visnav info` lists the image topics)",
                        args.sequence.display()
                    );
                }
                bail!(
                    "{} has no right camera or calibration: --mode stereo needs image_0 + image_1 (or image_00 + image_01) and P1",
                    args.sequence.display()
                );
            };
            let vo = Odometry::stereo(rig, config.clone())?.with_outputs(outputs);
            Ok((vo, RunConfig::Stereo(Box::new(config))))
        }
        Mode::Mono => {
            let config = load_mono_config(args)?;
            let mut vo = Odometry::mono(seq.camera, &config)?
                .with_outputs(outputs)
                .pipelined(true);
            if args.loop_closure {
                let store = Box::new(SourceStore(Arc::clone(source)));
                vo = vo.with_loop_closure(seq.camera, &config, store)?;
            }
            Ok((vo, RunConfig::Mono(Box::new(config))))
        }
    }
}

/// Ctrl-C stops the run after the frame in progress (the frames done are written); a second
/// Ctrl-C exits at once (the journal `<output>.partial` keeps the frames done).
fn install_interrupt_handler() -> Arc<AtomicBool> {
    let flag = Arc::new(AtomicBool::new(false));
    let f = Arc::clone(&flag);
    let installed = ctrlc::set_handler(move || {
        if f.swap(true, Ordering::SeqCst) {
            std::process::exit(130);
        }
        eprintln!("interrupted: finishing the frame in progress and writing the frames done");
    });
    if let Err(e) = installed {
        log::debug!("no Ctrl-C handler ({e})");
    }
    flag
}

/// What the frame loop produced.
struct Run {
    odometry: Odometry,
    per_frame: Vec<FrameRecord>,
    journal: PoseJournal,
    wall_s: f64,
    interrupted: bool,
}

/// The frame loop: pushes every frame, journals each pose, saves the requested files.
fn drive(
    args: &Args,
    ctx: &super::Context,
    mut odometry: Odometry,
    source: &Arc<dyn FrameSource>,
    seq: &Sequence,
    interrupted: &AtomicBool,
) -> anyhow::Result<Run> {
    for dir in [&args.save_flow, &args.save_depth, &args.save_tracks]
        .into_iter()
        .flatten()
    {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let mut live = LiveView::open(&args.live(), seq.camera)?;
    let mut journal = PoseJournal::create(&args.output)?;
    let bar = crate::progress::bar(
        source.len() as u64,
        visnav_pipeline::Mode::from(args.mode).name(),
        ctx.quiet,
    );
    let mut per_frame = Vec::with_capacity(source.len());
    let mut error: Option<anyhow::Error> = None;
    let start = Instant::now();
    run_source(&mut odometry, Arc::clone(source), |r, wait_ms| {
        let t_save = Instant::now();
        let saved = journal
            .append(&r.world_from_cam)
            .map_err(anyhow::Error::from)
            .and_then(|()| save_frame_files(args, source.as_ref(), &r));
        if let (Some(live), Some(image)) = (&mut live, &r.image) {
            live.log(&LiveFrame {
                step: r.position,
                image,
                world_from_cam: &r.world_from_cam,
                flow: r.flow.as_ref(),
                depth: r.depth.as_ref(),
            });
        }
        let save_ms = t_save.elapsed().as_secs_f64() * 1e3;
        per_frame.push(FrameRecord::new(
            &r,
            source.index_of(r.position),
            wait_ms,
            save_ms,
        ));
        bar.inc(1);
        if let Err(e) = saved {
            error.get_or_insert(e);
            return Control::Stop;
        }
        if interrupted.load(Ordering::SeqCst) {
            Control::Stop
        } else {
            Control::Continue
        }
    });
    bar.finish_and_clear();
    if let Some(e) = error {
        return Err(e.context(format!(
            "the run stopped; the poses of the frames done are in {}",
            journal.path().display()
        )));
    }
    Ok(Run {
        wall_s: start.elapsed().as_secs_f64(),
        interrupted: per_frame.len() < source.len(),
        odometry,
        per_frame,
        journal,
    })
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
    seq: &Sequence,
    n: usize,
    config: RunConfig,
    run: Run,
) -> anyhow::Result<()> {
    let odometry_poses = run.odometry.trajectory().to_vec();
    let mut report = RunReport::new(
        std::path::absolute(&args.sequence).unwrap_or_else(|_| args.sequence.clone()),
        config,
        n,
        run.per_frame,
        run.wall_s,
    );
    report.interrupted = run.interrupted;
    let mut poses = odometry_poses.clone();
    if let Some(closer) = run.odometry.loop_closer() {
        let odometry_output = odometry_path_for(&args.output);
        visnav_io::trajectory::write_kitti(&odometry_output, &odometry_poses)
            .with_context(|| format!("writing {}", odometry_output.display()))?;
        let mut summary = LoopClosureSummary::of(closer);
        summary.odometry_output = Some(odometry_output);
        summary.odometry_palindrome = args.palindrome.then(|| palindrome_drift(&poses)).flatten();
        report.loop_closure = Some(summary);
        poses = closer.corrected_poses();
    }
    report.palindrome = args.palindrome.then(|| palindrome_drift(&poses)).flatten();
    run.journal
        .commit(&poses)
        .with_context(|| format!("writing {}", args.output.display()))?;
    let tum_path = write_tum_beside(&args.output, seq, &poses)?;
    if let Some(path) = &args.output_mcap {
        write_pose_mcap(path, seq, &poses)?;
    }
    let config_path = config_path_for(&args.output);
    let toml = report.config.to_toml().map_err(anyhow::Error::msg)?;
    write_atomic(&config_path, toml.as_bytes())?;
    if let Some(json) = &args.json {
        write_atomic(
            json,
            report.to_json().map_err(anyhow::Error::msg)?.as_bytes(),
        )?;
    }
    if !ctx.quiet {
        print_summary(&report);
        print_output_paths(&args.output, &config_path, tum_path.as_deref());
    }
    if run.interrupted {
        bail!(
            "interrupted: {} of {} poses written to {} (the frames done)",
            poses.len(),
            expected_poses(args, n),
            args.output.display()
        );
    }
    Ok(())
}

/// Poses a complete run writes: one per input frame (`2N − 1` for a palindrome).
fn expected_poses(args: &Args, n: usize) -> usize {
    if args.palindrome { 2 * n - 1 } else { n }
}

/// The run's summary lines.
fn print_summary(r: &RunReport) {
    let m = &r.mean;
    println!(
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
    );
    if let Some(s) = &r.sources {
        println!(
            "pose sources: {} eight-point, {} PnP, {} fused, {} constant velocity",
            s.eight_point, s.pnp, s.fused, s.constant_velocity
        );
    }
    if let Some(l) = &r.loop_closure {
        println!(
            "loop closure: {} accepted ({} set aside by the pose graph), {} rejected, {} optimisations; odometry only: {}",
            l.accepted,
            l.rejected_by_graph,
            l.rejected,
            l.optimisations,
            l.odometry_output
                .as_deref()
                .unwrap_or(Path::new("-"))
                .display()
        );
        if let Some(d) = &l.odometry_palindrome {
            println!(
                "  odometry only: end-point error {:.3} m ({:.2} % of the distance)",
                d.end_point_error_m,
                100.0 * d.end_point_error_relative
            );
        }
    }
    if let Some(d) = &r.palindrome {
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
        println!("report: {}", output.display());
    }
    Ok(())
}

/// Reads a TOML configuration file into `T`.
fn read_config<T: serde::de::DeserializeOwned>(path: &Path) -> anyhow::Result<T> {
    let text = visnav_io::text::read_text(path)
        .with_context(|| format!("reading config {}", path.display()))?;
    toml::from_str::<T>(&text).with_context(|| format!("parsing config {}", path.display()))
}

/// Loads the stereo config: defaults, then the TOML file, then `--outlier`.
fn load_stereo_config(args: &Args) -> anyhow::Result<StereoConfig> {
    let mut config = match &args.config {
        Some(p) => read_config::<StereoConfig>(p)?,
        None => StereoConfig::default(),
    };
    if let Some(o) = args.outlier {
        config.outlier = o.into();
    }
    config.validate().context("invalid stereo configuration")?;
    Ok(config)
}

/// Loads the mono config: defaults, then the TOML file, then the command-line overrides.
fn load_mono_config(args: &Args) -> anyhow::Result<MonoRunConfig> {
    let mut config = match &args.config {
        Some(p) => read_config::<MonoRunConfig>(p)?,
        None => MonoRunConfig::default(),
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
    config.validate().context("invalid mono configuration")?;
    Ok(config)
}

/// Prints where a run wrote its poses, its configuration and (when asked for) its TUM poses.
fn print_output_paths(output: &Path, config: &Path, tum: Option<&Path>) {
    println!("poses: {}  config: {}", output.display(), config.display());
    if let Some(p) = tum {
        println!("poses with timestamps (TUM): {}", p.display());
    }
}

/// Opens the input with its camera file, if any (a ROS 2 bag with its topics).
fn open_sequence(args: &Args) -> anyhow::Result<Sequence> {
    let bag_options = args.topic.is_some() || args.right_topic.is_some();
    let seq = if bag_options || visnav_io::bag::is_bag(&args.sequence) {
        let options = visnav_io::bag::BagOptions {
            topic: args.topic.clone(),
            right_topic: args.right_topic.clone(),
            camera: args.camera.clone(),
            pair_tolerance_s: None,
        };
        visnav_io::bag::open_bag_sequence(&args.sequence, &options)
    } else {
        Sequence::open_with_camera(&args.sequence, args.camera.as_deref())
    };
    seq.with_context(|| format!("opening sequence {}", args.sequence.display()))
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
    let path = sibling(output, "tum.txt");
    let poses: Vec<Pose> = match seq.body_from_cam {
        Some(b) => poses.iter().map(|p| b * p * b.inverse()).collect(),
        None => poses.to_vec(),
    };
    visnav_io::trajectory::write_tum(&path, &poses, &seq.timestamps[..poses.len()])
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(Some(path))
}

/// The poses as an MCAP file of `PoseStamped` messages stamped with the frames' timestamps
/// (`visnav_io::bag::writer`); a palindrome run's way back has no timestamps of its own.
fn write_pose_mcap(path: &Path, seq: &Sequence, poses: &[Pose]) -> anyhow::Result<()> {
    let Some(stamps) = seq.timestamps.get(..poses.len()) else {
        bail!(
            "--output-mcap: {} poses but {} frame timestamps (a palindrome run has no timestamps for its way back)",
            poses.len(),
            seq.timestamps.len()
        );
    };
    visnav_io::bag::writer::write_pose_mcap(path, poses, stamps)
        .with_context(|| format!("writing {}", path.display()))
}

/// `poses.txt` → `poses.<suffix>` in the same directory.
fn sibling(output: &Path, suffix: &str) -> PathBuf {
    let stem = output
        .file_stem()
        .map_or_else(|| "poses".into(), |s| s.to_string_lossy().into_owned());
    output.with_file_name(format!("{stem}.{suffix}"))
}

/// `poses.txt` → `poses.config.toml` in the same directory.
fn config_path_for(output: &Path) -> PathBuf {
    sibling(output, "config.toml")
}

/// `poses.txt` → `poses.odometry.txt` in the same directory (odometry-only trajectory of a
/// `--loop-closure` run).
fn odometry_path_for(output: &Path) -> PathBuf {
    sibling(output, "odometry.txt")
}
