//! The demo scenario (`visnav demo`): a short synthetic stereo drive with exact ground truth is
//! rendered (`visnav-synth`), every trajectory estimator of [`estimators`] runs on it through
//! the streaming odometry (`visnav-pipeline`), each is scored with the KITTI metric, ATE and RPE
//! (`visnav-eval`), and the trajectories, plots and `scores.json` are written:
//!
//! ```text
//! OUT/sequence/          the rendered sequence (KITTI odometry layout + flow/ and depth/)
//! OUT/trajectories/      ground_truth.txt and <estimator>.txt (KITTI format)
//! OUT/plots/             top_<estimator>.{png,svg}, errors_<estimator>.{png,svg}
//! OUT/scores.json        one entry per estimator
//! ```
//!
//! The estimators are the ground truth itself (scores zero), two reference rows of ground truth
//! with simulated drift, and the two odometry pipelines on the rendered images. After them a
//! drive around a rendered block (small images, the last frames revisiting the first) runs the
//! monocular pipeline with and without loop closure. A pipeline that fails on a frame keeps going
//! (counted as failed); a pipeline that fails altogether is reported and skipped.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use anyhow::Context as _;
use nalgebra::{Translation3, UnitQuaternion, Vector3};
use serde::Serialize;
use visnav_core::{GrayImage, Pose, Progress};
use visnav_eval::kitti::KittiMetricConfig;
use visnav_eval::{EvalConfig, TrajectoryPair, evaluate, pose_matrices};
use visnav_io::trajectory::write_kitti;
use visnav_io::{FrameSource, InMemorySource, Sequence, Take};
use visnav_loop::{ClosureReport, LoopCloser};
use visnav_odometry::mono::MonoConfig;
use visnav_odometry::stereo::StereoConfig;
use visnav_pipeline::{Control, MemoryStore, Mode, MonoRunConfig, Odometry, run_source};
use visnav_synth::noise::cell_random;
use visnav_synth::write::{SynthSpec, SynthSummary, write_sequence};
use visnav_synth::{
    KITTI_BASELINE_M, Scene, block_loop_trajectory, drive_trajectory, kitti_like_camera,
    render_view,
};

/// What the demo renders and runs.
#[derive(Debug, Clone)]
pub struct DemoSettings {
    /// Output directory.
    pub output: PathBuf,
    /// Frames of the rendered drive (10 Hz).
    pub frames: usize,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Seed of the scene and the drive.
    pub seed: u64,
    /// Frames the monocular pipeline runs on (a prefix of the drive); `None`: every frame.
    pub mono_frames: Option<usize>,
    /// Frames of the loop-closure drive (0 skips it).
    pub loop_frames: usize,
}

impl DemoSettings {
    /// Checks the ranges.
    ///
    /// # Errors
    /// A message naming the setting out of range.
    pub fn validate(&self) -> anyhow::Result<()> {
        if !(5..=2000).contains(&self.frames) {
            anyhow::bail!("--frames must be within 5..=2000, got {}", self.frames);
        }
        if let Some(m) = self.mono_frames
            && !(3..=self.frames).contains(&m)
        {
            anyhow::bail!(
                "--mono-frames must be within 3..=--frames ({}), got {m}",
                self.frames
            );
        }
        if self.loop_frames != 0 && !(60..=1000).contains(&self.loop_frames) {
            anyhow::bail!(
                "--loop-frames must be 0 (skip) or within 60..=1000, got {}",
                self.loop_frames
            );
        }
        if !(16..=4096).contains(&self.width) || !(16..=4096).contains(&self.height) {
            anyhow::bail!(
                "--width/--height must be within 16..=4096 pixels, got {}x{}",
                self.width,
                self.height
            );
        }
        Ok(())
    }
}

/// Image size of the loop-closure drive (`visnav_synth::block_loop_trajectory`), pixels; small,
/// with 2x2 supersampling, to keep the demo short.
pub const LOOP_SIZE_PX: (u32, u32) = (320, 96);

/// The loop-closure part of the demo report.
#[derive(Debug, Clone, Serialize)]
pub struct LoopDriveReport {
    pub frames: usize,
    pub width: u32,
    pub height: u32,
    pub path_length_m: f64,
    /// The frame where the loop closes: the last candidate-search frame (every 10 frames).
    pub closing_frame: usize,
    /// Distance of the estimated position from the true one at `closing_frame`, odometry only,
    /// metres.
    pub end_drift_odometry_m: f64,
    /// The same after loop closure, metres.
    pub end_drift_loop_closure_m: f64,
    /// The last frame of the drive (the closing frame with the default 91 frames; frames after
    /// the closing frame add the odometry's own drift again).
    pub final_frame: usize,
    /// Distance of the estimated position from the true one at `final_frame`, odometry only,
    /// metres.
    pub final_drift_odometry_m: f64,
    /// The same after loop closure, metres.
    pub final_drift_loop_closure_m: f64,
    pub closures_accepted: usize,
    pub closures_rejected: usize,
    pub render_s: f64,
    pub run_s: f64,
}

/// The trajectories of the loop drive, without and with loop closure.
struct LoopRun {
    odometry: Vec<Pose>,
    corrected: Vec<Pose>,
    closures: Vec<ClosureReport>,
}

/// Renders the loop drive and runs the monocular pipeline with loop closure on it.
pub fn run_loop_drive(frames: usize, seed: u64) -> anyhow::Result<LoopDriveReport> {
    let gt = block_loop_trajectory(frames);
    let scene = Scene::along(&gt, seed)
        .context("laying out the loop scene")?
        .with_supersampling(2);
    let camera = kitti_like_camera(LOOP_SIZE_PX.0, LOOP_SIZE_PX.1);
    let t = Instant::now();
    let images: Vec<GrayImage> = gt
        .iter()
        .map(|p| render_view(&scene, &camera, p).image)
        .collect();
    let render_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let config = MonoRunConfig {
        mono: mono_config(scene.config().ground_depth_m),
        ..MonoRunConfig::default()
    };
    let mut vo = Odometry::mono(camera, &config)?
        .pipelined(true)
        .with_loop_closure(camera, &config, Box::new(MemoryStore::default()))?;
    run_source(&mut vo, Arc::new(InMemorySource::mono(images)), |_, _| {
        Control::Continue
    });
    let run = LoopRun {
        odometry: vo.trajectory().to_vec(),
        corrected: vo.corrected_trajectory(),
        closures: vo
            .loop_closer()
            .map(LoopCloser::closures)
            .unwrap_or_default(),
    };
    let closing_frame = (frames - 1) / 10 * 10;
    let final_frame = frames - 1;
    let drift =
        |poses: &[Pose], k: usize| (poses[k].translation.vector - gt[k].translation.vector).norm();
    let end = |poses: &[Pose]| drift(poses, closing_frame);
    let accepted = run.closures.iter().filter(|c| c.accepted).count();
    Ok(LoopDriveReport {
        frames,
        width: camera.width,
        height: camera.height,
        path_length_m: visnav_eval::path_length_m(&gt),
        closing_frame,
        end_drift_odometry_m: end(&run.odometry),
        end_drift_loop_closure_m: end(&run.corrected),
        final_frame,
        final_drift_odometry_m: drift(&run.odometry, final_frame),
        final_drift_loop_closure_m: drift(&run.corrected, final_frame),
        closures_accepted: accepted,
        closures_rejected: run.closures.len() - accepted,
        render_s,
        run_s: t.elapsed().as_secs_f64(),
    })
}

/// What an estimator sees: the rendered sequence (images, calibration, timestamps). The ground
/// truth is there for the reference entries only; a real pipeline must not read it.
pub struct DemoInput<'a> {
    pub sequence: &'a Sequence,
    pub ground_truth: &'a [Pose],
    /// Height of the camera above the ground plane, metres: part of the rig's calibration (the
    /// renderer's `SceneConfig::ground_depth_m`), which a monocular pipeline may use for scale.
    pub camera_height_m: f64,
    /// Frames the monocular pipeline runs on (a prefix, at most the sequence length).
    pub mono_frames: usize,
    /// Where the estimators report their progress.
    pub progress: &'a dyn Progress,
}

/// What an estimator returns.
pub struct EstimatorRun {
    /// One `world_from_cam` pose per processed frame: frames `0..poses.len()` of the sequence
    /// (a prefix when the pipeline runs on fewer frames).
    pub poses: Vec<Pose>,
    /// Frames whose pose is a fallback (constant-velocity prediction, failed flow or image).
    pub failed_frames: usize,
    /// Wall time spent estimating (waiting for decoded images excluded), seconds; `None`: use
    /// the wall time.
    pub compute_s: Option<f64>,
    /// Time spent in dense optical flow (mono; on its own thread, overlapping `compute_s`),
    /// seconds.
    pub flow_s: Option<f64>,
}

impl EstimatorRun {
    /// A reference entry: poses computed without images.
    fn reference(poses: Vec<Pose>) -> Self {
        Self {
            poses,
            failed_frames: 0,
            compute_s: None,
            flow_s: None,
        }
    }
}

/// One trajectory estimator run by the demo.
pub struct Estimator {
    /// Short name (file names, table rows).
    pub name: &'static str,
    /// One line for the table.
    pub description: &'static str,
    /// Produces one `world_from_cam` pose per processed frame.
    pub run: fn(&DemoInput<'_>) -> anyhow::Result<EstimatorRun>,
}

/// The estimators the demo runs, in table order. Add a pipeline here.
pub fn estimators() -> Vec<Estimator> {
    vec![
        Estimator {
            name: "ground_truth",
            description: "the ground truth itself (must score zero)",
            run: |input| {
                Ok(EstimatorRun::reference(
                    input
                        .ground_truth
                        .iter()
                        .take(input.sequence.len())
                        .copied()
                        .collect(),
                ))
            },
        },
        Estimator {
            name: "scale_drift",
            description: "ground truth with every step 3 % too long (simulated)",
            run: |input| {
                Ok(EstimatorRun::reference(perturb(
                    input.ground_truth,
                    1.03,
                    0.0,
                    0.0,
                    0.0,
                    0,
                )))
            },
        },
        Estimator {
            name: "yaw_drift_noise",
            description: "ground truth with yaw drift 1 deg/10 m and per-frame noise (simulated)",
            run: |input| {
                Ok(EstimatorRun::reference(perturb(
                    input.ground_truth,
                    1.0,
                    0.1f64.to_radians(),
                    0.01,
                    0.05f64.to_radians(),
                    7,
                )))
            },
        },
        Estimator {
            name: "stereo_vo",
            description: "stereo VO: RotROCC, default config, DNRE outlier rejection",
            run: run_stereo_vo,
        },
        Estimator {
            name: "mono_vo",
            description: "mono VO: dense flow + Mahalanobis eight-point, scale from camera height",
            run: run_mono_vo,
        },
    ]
}

/// Stereo odometry (RotROCC, default [`StereoConfig`]) on every rendered stereo pair, through
/// the library's streaming odometry (an unreadable frame gets the constant-velocity prediction).
fn run_stereo_vo(input: &DemoInput<'_>) -> anyhow::Result<EstimatorRun> {
    let seq = input.sequence;
    let rig = seq
        .stereo_camera()
        .context("the rendered sequence has no stereo rig")?;
    let vo = Odometry::stereo(rig, StereoConfig::default())?;
    Ok(drive(
        vo,
        Arc::new(seq.clone()),
        "stereo_vo",
        input.progress,
    ))
}

/// Drives `vo` over `source`, reporting progress; one pose per frame.
fn drive(
    mut vo: Odometry,
    source: Arc<dyn FrameSource>,
    name: &str,
    progress: &dyn Progress,
) -> EstimatorRun {
    let total = source.len() as u64;
    let mut done = 0;
    let (mut failed_frames, mut wait_ms, mut flow_ms) = (0, 0.0, 0.0);
    let start = Instant::now();
    run_source(&mut vo, source, |r, waited_ms| {
        failed_frames += usize::from(r.status.is_predicted());
        wait_ms += waited_ms;
        done += 1;
        progress.step(name, done, total);
        flow_ms += r.timings.flow.map_or(0.0, |f| f.total_ms);
        Control::Continue
    });
    // wall time without waiting for decoded images (the flow thread overlaps the odometry)
    let compute_s = start.elapsed().as_secs_f64() - wait_ms / 1e3;
    EstimatorRun {
        poses: vo.trajectory().to_vec(),
        failed_frames,
        compute_s: Some(compute_s),
        flow_s: (vo.mode() == Mode::Mono).then_some(flow_ms / 1e3),
    }
}

/// The monocular pipeline's configuration for the demo: the paper's defaults (Mahalanobis
/// eight-point; the parallax thresholds, given for KITTI's 1241-px width, scale to the image
/// width by themselves) and the renderer's camera height.
fn mono_config(camera_height_m: f64) -> MonoConfig {
    let mut cfg = MonoConfig::default();
    cfg.scale.camera_height_m = camera_height_m;
    cfg
}

/// Monocular odometry on the first `input.mono_frames` left images (dense flow from the last
/// accepted image, `FlowConfig::odometry`, then the monocular odometry) through the library's
/// streaming odometry, flow pipelined with the odometry.
fn run_mono_vo(input: &DemoInput<'_>) -> anyhow::Result<EstimatorRun> {
    let seq = input.sequence;
    let n = input.mono_frames.min(seq.len());
    let config = MonoRunConfig {
        mono: mono_config(input.camera_height_m),
        ..MonoRunConfig::default()
    };
    let vo = Odometry::mono(seq.camera, &config)?.pipelined(true);
    Ok(drive(
        vo,
        Arc::new(Take::new(seq.clone(), n)),
        "mono_vo",
        input.progress,
    ))
}

/// Re-integrates the relative motions of `gt` with a scale factor on every step, a yaw bias
/// per metre travelled (radians), and uniform noise of the given amplitude on every step
/// (translation metres, rotation radians), seeded.
fn perturb(
    gt: &[Pose],
    scale: f64,
    yaw_per_m_rad: f64,
    noise_m: f64,
    noise_rad: f64,
    seed: u32,
) -> Vec<Pose> {
    let mut out = Vec::with_capacity(gt.len());
    let Some(first) = gt.first() else {
        return out;
    };
    out.push(*first);
    let mut est = *first;
    for (i, w) in gt.windows(2).enumerate() {
        let rel = w[0].inverse() * w[1];
        let step_m = rel.translation.vector.norm();
        let u = |k: i64| f64::from(cell_random(i as i64, k, seed)) * 2.0 - 1.0;
        let t = rel.translation.vector * scale
            + noise_m * Vector3::new(u(0), u(1), u(2)) * step_m.min(1.0);
        let drift = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), yaw_per_m_rad * step_m)
            * UnitQuaternion::from_scaled_axis(
                noise_rad * step_m.min(1.0) * Vector3::new(u(3), u(4), u(5)),
            );
        est *= Pose::from_parts(Translation3::from(t), drift * rel.rotation);
        out.push(est);
    }
    out
}

/// Scores of one estimator.
#[derive(Debug, Clone, Serialize)]
pub struct DemoScore {
    pub name: &'static str,
    pub description: &'static str,
    /// Frames run and scored: a prefix `0..frames` of the drive.
    pub frames: usize,
    /// Frames whose pose is a fallback (see [`EstimatorRun::failed_frames`]).
    pub failed_frames: usize,
    /// Segment lengths of the KITTI metric, metres (shorter for a prefix run).
    pub lengths_m: Vec<f64>,
    pub t_err_percent: f64,
    pub r_err_deg_per_100m: f64,
    pub segments: usize,
    pub ate_se3_m: Option<f64>,
    pub ate_sim3_m: Option<f64>,
    pub rpe_trans_rmse_m: Option<f64>,
    pub rpe_rot_rmse_deg: Option<f64>,
    /// Estimation time per frame (image decoding excluded for the pipelines), milliseconds.
    pub ms_per_frame: f64,
    /// The dense optical flow (mono), milliseconds a frame; it runs on its own thread while
    /// the previous frame's odometry runs, so it overlaps `ms_per_frame`.
    pub flow_ms_per_frame: Option<f64>,
}

/// An estimator that failed altogether (reported, not fatal).
#[derive(Debug, Clone, Serialize)]
pub struct DemoFailure {
    pub name: &'static str,
    pub error: String,
}

/// The demo's results (`scores.json`).
#[derive(Debug, Serialize)]
pub struct DemoReport {
    pub output: PathBuf,
    pub frames: usize,
    pub width: u32,
    pub height: u32,
    pub path_length_m: f64,
    pub lengths_m: Vec<f64>,
    pub render_s: f64,
    pub render_ms_per_frame: f64,
    pub scores: Vec<DemoScore>,
    pub loop_drive: Option<LoopDriveReport>,
    pub failures: Vec<DemoFailure>,
    pub total_s: f64,
}

/// Runs the demo (see the crate docs) into `settings.output`; progress goes to `progress`.
///
/// # Errors
/// Invalid settings, a file that cannot be written, or a scoring failure. An estimator that
/// fails altogether is not an error: it is listed in [`DemoReport::failures`].
pub fn run_demo(settings: &DemoSettings, progress: &dyn Progress) -> anyhow::Result<DemoReport> {
    let start = Instant::now();
    settings.validate()?;
    let out = &settings.output;
    let poses = drive_trajectory(settings.frames, settings.seed);
    let scene = Scene::along(&poses, settings.seed).context("laying out the demo scene")?;
    let spec = SynthSpec {
        scene,
        camera: kitti_like_camera(settings.width, settings.height),
        baseline_m: Some(KITTI_BASELINE_M),
        poses,
        trajectory_source: format!("generated drive (seed {})", settings.seed),
        frame_interval_s: 0.1,
    };
    log::info!(
        "rendering {} stereo frames at {}x{} into {}",
        settings.frames,
        settings.width,
        settings.height,
        out.join("sequence").display()
    );
    let synth = write_sequence(&spec, &out.join("sequence"), progress)?;
    let sequence = Sequence::open(&out.join("sequence"))?;
    let input = DemoInput {
        sequence: &sequence,
        ground_truth: &spec.poses,
        camera_height_m: spec.scene.config().ground_depth_m,
        mono_frames: settings
            .mono_frames
            .unwrap_or(settings.frames)
            .min(sequence.len()),
        progress,
    };
    let (scores, mut failures) = run_estimators(&input, &synth, out)?;
    let loop_drive = if settings.loop_frames == 0 {
        None
    } else {
        log::info!(
            "loop-closure drive: {} frames around a block at {}x{}",
            settings.loop_frames,
            LOOP_SIZE_PX.0,
            LOOP_SIZE_PX.1
        );
        match run_loop_drive(settings.loop_frames, settings.seed) {
            Ok(r) => Some(r),
            Err(e) => {
                log::error!("loop-closure drive failed: {e:#}");
                failures.push(DemoFailure {
                    name: "mono_vo_loop_closure",
                    error: format!("{e:#}"),
                });
                None
            }
        }
    };
    let report = DemoReport {
        output: out.clone(),
        frames: synth.frames,
        width: synth.width,
        height: synth.height,
        path_length_m: synth.path_length_m,
        lengths_m: demo_lengths(synth.path_length_m),
        render_s: synth.total_s,
        render_ms_per_frame: synth.render_ms_per_frame,
        scores,
        loop_drive,
        failures,
        total_s: start.elapsed().as_secs_f64(),
    };
    let json = serde_json::to_string_pretty(&report)?;
    visnav_io::atomic::write_atomic(&out.join("scores.json"), json.as_bytes())?;
    Ok(report)
}

/// Runs and scores every estimator; writes their trajectories and plots.
fn run_estimators(
    input: &DemoInput<'_>,
    synth: &SynthSummary,
    out: &Path,
) -> anyhow::Result<(Vec<DemoScore>, Vec<DemoFailure>)> {
    let traj_dir = out.join("trajectories");
    let plot_dir = out.join("plots");
    for d in [&traj_dir, &plot_dir] {
        std::fs::create_dir_all(d).with_context(|| format!("creating {}", d.display()))?;
    }
    let gt = input.ground_truth;
    write_kitti(&traj_dir.join("ground_truth.txt"), gt)?;
    let mut scores = Vec::new();
    let mut failures = Vec::new();
    for est in estimators() {
        let t0 = Instant::now();
        let run = match (est.run)(input) {
            Ok(run) => run,
            Err(e) => {
                // one broken pipeline must not take the others down
                log::error!("estimator '{}' failed: {e:#}", est.name);
                failures.push(DemoFailure {
                    name: est.name,
                    error: format!("{e:#}"),
                });
                continue;
            }
        };
        let wall_s = t0.elapsed().as_secs_f64();
        let n = run.poses.len();
        if !(2..=gt.len()).contains(&n) {
            log::error!("estimator '{}' returned {n} poses", est.name);
            failures.push(DemoFailure {
                name: est.name,
                error: format!("returned {n} poses for {} frames", gt.len()),
            });
            continue;
        }
        write_kitti(&traj_dir.join(format!("{}.txt", est.name)), &run.poses)?;
        scores.push(score(&est, &run, wall_s, gt, synth, &plot_dir)?);
    }
    Ok((scores, failures))
}

/// The scores of one estimator's run (a prefix run against the same prefix of the ground truth,
/// with segment lengths fitted to its shorter path), with its plots.
fn score(
    est: &Estimator,
    run: &EstimatorRun,
    wall_s: f64,
    gt: &[Pose],
    synth: &SynthSummary,
    plot_dir: &Path,
) -> anyhow::Result<DemoScore> {
    let n = run.poses.len();
    let lengths_m = if n == gt.len() {
        demo_lengths(synth.path_length_m)
    } else {
        demo_lengths(visnav_eval::path_length_m(&gt[..n]))
    };
    let config = EvalConfig {
        kitti: KittiMetricConfig {
            lengths_m: lengths_m.clone(),
            ..KittiMetricConfig::default()
        },
        ..EvalConfig::default()
    };
    let gt_m = pose_matrices(&gt[..n]);
    let est_m = pose_matrices(&run.poses);
    let report = evaluate(&[TrajectoryPair::by_index(&gt_m, &est_m)], &config)
        .with_context(|| format!("scoring '{}'", est.name))?;
    write_plots(plot_dir, est.name, &gt_m, &est_m, &report)?;
    Ok(DemoScore {
        name: est.name,
        description: est.description,
        frames: n,
        failed_frames: run.failed_frames,
        lengths_m,
        t_err_percent: report.t_err_percent,
        r_err_deg_per_100m: report.r_err_deg_per_100m,
        segments: report.segments,
        ate_se3_m: report.ate_se3_m,
        ate_sim3_m: report.ate_sim3_m,
        rpe_trans_rmse_m: report.rpe.map(|r| r.trans_rmse_m),
        rpe_rot_rmse_deg: report.rpe.map(|r| r.rot_rmse_deg),
        ms_per_frame: 1e3 * run.compute_s.unwrap_or(wall_s) / n as f64,
        flow_ms_per_frame: run.flow_s.map(|f| 1e3 * f / n as f64),
    })
}

/// Segment lengths for a short drive: multiples of 5 m below 90 % of the path (at most five),
/// or half the path when it is shorter than 5.6 m.
pub fn demo_lengths(path_length_m: f64) -> Vec<f64> {
    let step = if path_length_m > 60.0 { 10.0 } else { 5.0 };
    let lengths: Vec<f64> = (1..=5)
        .map(|k| step * f64::from(k))
        .filter(|l| *l < 0.9 * path_length_m)
        .collect();
    if lengths.is_empty() {
        vec![(0.5 * path_length_m).max(0.1)]
    } else {
        lengths
    }
}

fn write_plots(
    dir: &Path,
    name: &str,
    gt: &[visnav_eval::PoseMatrix],
    est: &[visnav_eval::PoseMatrix],
    report: &visnav_eval::EvalReport,
) -> anyhow::Result<()> {
    visnav_eval::plot::plot_top_view(dir, &format!("top_{name}"), gt, est, name)
        .with_context(|| format!("top-view plot of '{name}'"))?;
    if !report.per_length.is_empty() {
        visnav_eval::plot::plot_errors_vs_length(
            dir,
            &format!("errors_{name}"),
            &report.per_length,
            name,
        )
        .with_context(|| format!("error plot of '{name}'"))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn perturbation_scales_positions() {
        let gt = drive_trajectory(30, 1);
        let est = perturb(&gt, 1.03, 0.0, 0.0, 0.0, 0);
        for (g, e) in gt.iter().zip(&est) {
            let d = e.translation.vector - 1.03 * g.translation.vector;
            assert!(d.norm() < 1e-9);
            assert!(g.rotation.angle_to(&e.rotation) < 1e-9);
        }
        assert_eq!(demo_lengths(27.0), vec![5.0, 10.0, 15.0, 20.0]);
        assert_eq!(demo_lengths(2.0), vec![1.0]);
    }

    /// Renders a short drive, overwrites frame `broken` (both cameras) with bytes that are no
    /// PNG, and opens it.
    fn broken_sequence(dir: &Path, frames: usize, broken: usize) -> (Sequence, Vec<Pose>, f64) {
        let poses = drive_trajectory(frames, 5);
        let scene = Scene::along(&poses, 5).unwrap().with_supersampling(1);
        let height_m = scene.config().ground_depth_m;
        let spec = SynthSpec {
            scene,
            camera: kitti_like_camera(320, 96),
            baseline_m: Some(KITTI_BASELINE_M),
            poses: poses.clone(),
            trajectory_source: "test".into(),
            frame_interval_s: 0.1,
        };
        write_sequence(&spec, dir, &visnav_core::NoProgress).unwrap();
        for cam in ["image_0", "image_1"] {
            std::fs::write(dir.join(cam).join(format!("{broken:06}.png")), b"not a png").unwrap();
        }
        (Sequence::open(dir).unwrap(), poses, height_m)
    }

    /// Regression: an undecodable frame must not abort a pipeline; it is counted as failed and
    /// the pipeline still returns one pose per frame.
    #[test]
    fn pipelines_survive_an_undecodable_frame() {
        let dir = tempfile::tempdir().unwrap();
        let (seq, gt, camera_height_m) = broken_sequence(dir.path(), 7, 3);
        let input = DemoInput {
            sequence: &seq,
            ground_truth: &gt,
            camera_height_m,
            mono_frames: 7,
            progress: &visnav_core::NoProgress,
        };
        for run in [run_stereo_vo(&input).unwrap(), run_mono_vo(&input).unwrap()] {
            assert_eq!(run.poses.len(), 7);
            assert!(run.failed_frames >= 1);
            assert!(run.failed_frames < 7);
            assert!(
                run.poses
                    .iter()
                    .all(|p| p.translation.vector.iter().all(|v| v.is_finite()))
            );
        }
    }

    #[test]
    fn path_length_sums_steps() {
        let poses: Vec<Pose> = (0..4)
            .map(|k| {
                Pose::from_parts(
                    Translation3::new(0.0, 0.0, 2.0 * f64::from(k)),
                    UnitQuaternion::identity(),
                )
            })
            .collect();
        assert!((visnav_eval::path_length_m(&poses) - 6.0).abs() < 1e-12);
        assert!(visnav_eval::path_length_m(&poses[..1]).abs() < 1e-12);
    }

    #[test]
    fn mono_config_scales_parallax_thresholds_to_the_width() {
        let full = MonoConfig::default();
        let cfg = mono_config(1.65);
        assert!((cfg.scale.camera_height_m - 1.65).abs() < 1e-12);
        let scaled = cfg.parallax.for_width(620);
        let r = scaled.min_klt_median_px / full.parallax.min_klt_median_px;
        assert!((r - 620.0 / 1241.0).abs() < 1e-12);
        let r = scaled.min_flow_p75_px / full.parallax.min_flow_p75_px;
        assert!((r - 620.0 / 1241.0).abs() < 1e-12);
        // scaled once only, and the translational parallax not at all
        assert_eq!(scaled.for_width(620), scaled);
        assert_eq!(
            scaled.min_translational_parallax_px,
            full.parallax.min_translational_parallax_px
        );
        let same = full.parallax.for_width(1241);
        assert_eq!(same.min_flow_p75_px, full.parallax.min_flow_p75_px);
        assert!(cfg.validate().is_ok());
    }
}
