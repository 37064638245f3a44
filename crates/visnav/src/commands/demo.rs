//! `visnav demo`: the main job on an embedded default. Renders a short synthetic stereo drive
//! with exact ground truth (`visnav synth`), runs every trajectory estimator of [`estimators`] on
//! it, scores each with the KITTI metric, ATE and RPE (`visnav-eval`), prints a table and writes
//! the trajectories, the plots and `scores.json` into the output directory:
//!
//! ```text
//! OUT/sequence/          the rendered sequence (KITTI odometry layout + flow/ and depth/)
//! OUT/trajectories/      ground_truth.txt and <estimator>.txt (KITTI format)
//! OUT/plots/             top_<estimator>.{png,svg}, errors_<estimator>.{png,svg}
//! OUT/scores.json        one entry per estimator
//! ```
//!
//! Until the odometry pipelines land, the estimators are the ground truth itself (scores zero)
//! and ground truth with simulated drift; a pipeline is added as one more [`Estimator`].

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context as _;
use nalgebra::{Translation3, UnitQuaternion, Vector3};
use serde::Serialize;
use visnav_core::Pose;
use visnav_eval::kitti::KittiMetricConfig;
use visnav_eval::{EvalConfig, TrajectoryPair, evaluate, pose_matrices};
use visnav_io::Sequence;
use visnav_io::trajectory::write_kitti;
use visnav_synth::noise::cell_random;
use visnav_synth::{KITTI_BASELINE_M, Scene, drive_trajectory, kitti_like_camera};

use super::synth::{SynthSpec, write_sequence};

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
    /// Print the scores as JSON on stdout instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// What an estimator sees: the rendered sequence (images, calibration, timestamps). The ground
/// truth is there for the reference entries only; a real pipeline must not read it.
pub(crate) struct DemoInput<'a> {
    pub sequence: &'a Sequence,
    pub ground_truth: &'a [Pose],
}

/// One trajectory estimator run by the demo.
pub(crate) struct Estimator {
    /// Short name (file names, table rows).
    pub name: &'static str,
    /// One line for the table.
    pub description: &'static str,
    /// Produces one `world_from_cam` pose per frame.
    pub run: fn(&DemoInput<'_>) -> anyhow::Result<Vec<Pose>>,
}

/// The estimators the demo runs, in table order. Add a pipeline here.
pub(crate) fn estimators() -> Vec<Estimator> {
    vec![
        Estimator {
            name: "ground_truth",
            description: "the ground truth itself (must score zero)",
            run: |input| {
                Ok(input
                    .ground_truth
                    .iter()
                    .take(input.sequence.len())
                    .copied()
                    .collect())
            },
        },
        Estimator {
            name: "scale_drift",
            description: "ground truth with every step 3 % too long (simulated)",
            run: |input| Ok(perturb(input.ground_truth, 1.03, 0.0, 0.0, 0.0, 0)),
        },
        Estimator {
            name: "yaw_drift_noise",
            description: "ground truth with yaw drift 1 deg/10 m and per-frame noise (simulated)",
            run: |input| {
                Ok(perturb(
                    input.ground_truth,
                    1.0,
                    0.1f64.to_radians(),
                    0.01,
                    0.05f64.to_radians(),
                    7,
                ))
            },
        },
    ]
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
struct DemoScore {
    name: &'static str,
    description: &'static str,
    t_err_percent: f64,
    r_err_deg_per_100m: f64,
    segments: usize,
    ate_se3_m: Option<f64>,
    ate_sim3_m: Option<f64>,
    rpe_trans_rmse_m: Option<f64>,
    rpe_rot_rmse_deg: Option<f64>,
    ms_per_frame: f64,
}

#[derive(Debug, Serialize)]
struct DemoReport {
    output: PathBuf,
    frames: usize,
    width: u32,
    height: u32,
    path_length_m: f64,
    lengths_m: Vec<f64>,
    render_s: f64,
    render_ms_per_frame: f64,
    scores: Vec<DemoScore>,
    total_s: f64,
}

/// Runs the subcommand.
///
/// # Errors
/// Bad arguments, a file that cannot be written, or an estimator or scoring failure.
pub fn run(args: &Args, ctx: &super::Context) -> anyhow::Result<()> {
    let start = Instant::now();
    if !(5..=2000).contains(&args.frames) {
        anyhow::bail!("--frames must be within 5..=2000, got {}", args.frames);
    }
    if !(16..=4096).contains(&args.width) || !(16..=4096).contains(&args.height) {
        anyhow::bail!(
            "--width/--height must be within 16..=4096 pixels, got {}x{}",
            args.width,
            args.height
        );
    }
    let out = &args.output;
    let poses = drive_trajectory(args.frames, args.seed);
    let scene = Scene::along(&poses, args.seed).context("laying out the demo scene")?;
    let spec = SynthSpec {
        scene,
        camera: kitti_like_camera(args.width, args.height),
        baseline_m: Some(KITTI_BASELINE_M),
        poses,
        trajectory_source: format!("generated drive (seed {})", args.seed),
    };
    if !ctx.quiet {
        eprintln!(
            "rendering {} stereo frames at {}x{} into {}",
            args.frames,
            args.width,
            args.height,
            out.join("sequence").display()
        );
    }
    let synth = write_sequence(&spec, &out.join("sequence"), ctx.quiet)?;
    let sequence = Sequence::open(&out.join("sequence"))?;
    let gt = &spec.poses;
    let gt_m = pose_matrices(gt);
    let lengths_m = demo_lengths(synth.path_length_m);
    let config = EvalConfig {
        kitti: KittiMetricConfig {
            lengths_m: lengths_m.clone(),
            ..KittiMetricConfig::default()
        },
        ..EvalConfig::default()
    };
    let traj_dir = out.join("trajectories");
    let plot_dir = out.join("plots");
    for d in [&traj_dir, &plot_dir] {
        std::fs::create_dir_all(d).with_context(|| format!("creating {}", d.display()))?;
    }
    write_kitti(&traj_dir.join("ground_truth.txt"), gt)?;
    let input = DemoInput {
        sequence: &sequence,
        ground_truth: gt,
    };
    let mut scores = Vec::new();
    for est in estimators() {
        let t0 = Instant::now();
        let poses = (est.run)(&input).with_context(|| format!("estimator '{}'", est.name))?;
        let ms_per_frame = 1e3 * t0.elapsed().as_secs_f64() / sequence.len().max(1) as f64;
        anyhow::ensure!(
            poses.len() == gt.len(),
            "estimator '{}' returned {} poses for {} frames",
            est.name,
            poses.len(),
            gt.len()
        );
        write_kitti(&traj_dir.join(format!("{}.txt", est.name)), &poses)?;
        let est_m = pose_matrices(&poses);
        let report = evaluate(&[TrajectoryPair::by_index(&gt_m, &est_m)], &config)
            .with_context(|| format!("scoring '{}'", est.name))?;
        write_plots(&plot_dir, est.name, &gt_m, &est_m, &report)?;
        scores.push(DemoScore {
            name: est.name,
            description: est.description,
            t_err_percent: report.t_err_percent,
            r_err_deg_per_100m: report.r_err_deg_per_100m,
            segments: report.segments,
            ate_se3_m: report.ate_se3_m,
            ate_sim3_m: report.ate_sim3_m,
            rpe_trans_rmse_m: report.rpe.map(|r| r.trans_rmse_m),
            rpe_rot_rmse_deg: report.rpe.map(|r| r.rot_rmse_deg),
            ms_per_frame,
        });
    }
    let report = DemoReport {
        output: out.clone(),
        frames: synth.frames,
        width: synth.width,
        height: synth.height,
        path_length_m: synth.path_length_m,
        lengths_m,
        render_s: synth.total_s,
        render_ms_per_frame: synth.render_ms_per_frame,
        scores,
        total_s: start.elapsed().as_secs_f64(),
    };
    let json = serde_json::to_string_pretty(&report)?;
    visnav_io::trajectory::write_atomically(&out.join("scores.json"), json.as_bytes())?;
    if args.json {
        println!("{json}");
    } else if !ctx.quiet {
        print_table(&report);
    }
    Ok(())
}

/// Segment lengths for a short drive: multiples of 5 m below 90 % of the path (at most five),
/// or half the path when it is shorter than 5.6 m.
fn demo_lengths(path_length_m: f64) -> Vec<f64> {
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
        "{:<18} {:>9} {:>13} {:>5} {:>10} {:>10} {:>10} {:>9}",
        "estimator",
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
            "{:<18} {:>9.4} {:>13.4} {:>5} {:>10} {:>10} {:>10} {:>9.2}",
            s.name,
            s.t_err_percent,
            s.r_err_deg_per_100m,
            s.segments,
            opt(s.ate_se3_m, 4),
            opt(s.ate_sim3_m, 4),
            opt(s.rpe_trans_rmse_m, 4),
            s.ms_per_frame
        );
    }
    println!(
        "trajectories, plots and scores.json in {} ({:.1} s in all)",
        r.output.display(),
        r.total_s
    );
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
}
