//! Stereo VO on rendered, noise-free synthetic sequences (visnav-synth) with exact ground truth.
#![allow(clippy::unwrap_used)]

mod common;

use visnav_core::{Pose, StereoCamera};
use visnav_eval::kitti::{KittiMetricConfig, kitti_score, sequence_errors};
use visnav_odometry::RelativeMotion;
use visnav_odometry::stereo::{FailReason, FrameStatus, StereoConfig, StereoOdometry};
use visnav_synth::{KITTI_BASELINE_M, Scene, drive_trajectory, kitti_like_camera, render_stereo};

/// Renders `frames` stereo pairs along a generated drive and runs the odometry.
fn run(
    frames: usize,
    seed: u64,
    size: (u32, u32),
    config: &StereoConfig,
) -> (Vec<Pose>, Vec<Pose>, Vec<FrameStatus>) {
    let (gt, est, status, _) = run_told(frames, seed, size, config, 0.0);
    (gt, est, status)
}

/// [`run`] with the odometry told a rig whose right principal point sits `told_offset_px`
/// columns off the rendering rig's (a calibration error); also the rig's offset at the end.
fn run_told(
    frames: usize,
    seed: u64,
    (width, height): (u32, u32),
    config: &StereoConfig,
    told_offset_px: f64,
) -> (Vec<Pose>, Vec<Pose>, Vec<FrameStatus>, f64) {
    let gt = drive_trajectory(frames, seed);
    let scene = Scene::along(&gt, seed).unwrap();
    let rig = StereoCamera::new(kitti_like_camera(width, height), KITTI_BASELINE_M).unwrap();
    let told = rig.with_right_cx_offset(told_offset_px);
    let mut vo = StereoOdometry::new(told, config.clone()).unwrap();
    let mut motion = RelativeMotion::identity();
    let mut est = Vec::new();
    let mut status = Vec::new();
    for world_from_left in &gt {
        let (l, r) = render_stereo(&scene, &rig, world_from_left);
        let res = vo.process(&l.image, &r.image, &motion);
        motion = res.motion.unwrap_or(motion);
        est.push(res.world_from_cam);
        status.push(res.status);
    }
    // ground truth relative to its first frame
    let first_inv = gt[0].inverse();
    let gt: Vec<Pose> = gt.iter().map(|p| first_inv * p).collect();
    (gt, est, status, vo.rig().right_cx_offset_px)
}

/// The RotROCC frame-to-frame target (< 0.3 %) and, separately, the default pipeline with
/// persistent tracks and the window bundle adjustment, which is worse on this noise-free drive
/// with a stop and a rotation on the spot (0.4125 % against 0.2558 %,
/// docs/notes/2026-12-02-stereo-history.md).
#[test]
fn rendered_sequence_translation_error_below_0_3_percent() {
    let mut frame_to_frame = StereoConfig::default();
    frame_to_frame.window.persistent_tracks = false;
    frame_to_frame.window.bundle_adjustment = false;
    for (config, limit_percent) in [(frame_to_frame, 0.3), (StereoConfig::default(), 0.5)] {
        rendered_sequence_below(&config, limit_percent);
    }
}

fn rendered_sequence_below(config: &StereoConfig, limit_percent: f64) {
    let (gt, est, status) = run(40, 7, (620, 188), config);
    common::assert_no_fallback(&status);
    let t_err = score(&gt, &est);
    assert!(t_err < limit_percent, "t_err {t_err} %");
}

/// A rig calibrated 1 px off in the right principal point (every depth wrong by a share that
/// grows with the depth): the window adjustment's estimate of the offset brings the drive back
/// (a 1 px error here is what a rectification without zero disparity, or a misread `P1`, gives).
#[test]
fn the_window_estimates_a_miscalibrated_disparity_offset() {
    let mut estimating = StereoConfig::default();
    estimating.window.ba.estimate_right_cx_offset = true;
    let (gt, est, status, _) = run_told(40, 7, (620, 188), &StereoConfig::default(), 1.0);
    common::assert_no_fallback(&status);
    let t_told = score(&gt, &est);
    let (gt, est, status, offset) = run_told(40, 7, (620, 188), &estimating, 1.0);
    common::assert_no_fallback(&status);
    let t_estimated = score(&gt, &est);
    eprintln!(
        "told 1 px off: t_err {t_told:.4} %; estimated: {t_estimated:.4} %, offset {offset:.4} px"
    );
    assert!(
        offset.abs() < 0.1,
        "the offset ends near the true 0: {offset}"
    );
    // the first frames, before the running mean has settled, keep some of the error
    assert!(t_told > 5.0 * t_estimated, "{t_told} {t_estimated}");
}

/// The KITTI t_err (%) of a drive, lengths 5–20 m.
fn score(gt: &[Pose], est: &[Pose]) -> f64 {
    let cfg = KittiMetricConfig {
        lengths_m: vec![5.0, 10.0, 15.0, 20.0],
        step_frames: 2,
        frame_period_s: 0.1,
    };
    let gt_m: Vec<_> = gt.iter().map(Pose::to_homogeneous).collect();
    let est_m: Vec<_> = est.iter().map(Pose::to_homogeneous).collect();
    let errors = sequence_errors(&gt_m, &est_m, &cfg, 0);
    assert!(!errors.is_empty());
    let score = kitti_score(&errors, &cfg.lengths_m);
    eprintln!(
        "synthetic: t_err {:.4} %  r_err {:.4} deg/100m over {} segments",
        score.t_err_percent,
        score.r_err_deg_per_100m,
        errors.len()
    );
    score.t_err_percent
}

#[test]
fn failed_frames_get_the_constant_velocity_prediction() {
    let gt = drive_trajectory(4, 11);
    let scene = Scene::along(&gt, 11).unwrap();
    let rig = StereoCamera::new(kitti_like_camera(480, 144), KITTI_BASELINE_M).unwrap();
    let mut vo = StereoOdometry::new(rig, StereoConfig::default()).unwrap();
    let views: Vec<_> = gt.iter().map(|p| render_stereo(&scene, &rig, p)).collect();
    let r0 = vo.process(
        &views[0].0.image,
        &views[0].1.image,
        &RelativeMotion::identity(),
    );
    assert_eq!(r0.status, FrameStatus::First);
    assert_eq!(r0.motion, None);
    let r1 = vo.process(
        &views[1].0.image,
        &views[1].1.image,
        &RelativeMotion::identity(),
    );
    assert!(
        matches!(r1.status, FrameStatus::Ok | FrameStatus::LowSpeed),
        "{:?}",
        r1.status
    );
    // an untextured pair: nothing can be tracked
    let flat = visnav_core::GrayImage::new(480, 144, 90.0);
    // the driver's constant-velocity model: the motion the odometry returned
    let motion = r1.motion.expect("an estimate");
    let r2 = vo.process(&flat, &flat, &motion);
    assert_eq!(r2.motion, None);
    assert!(
        matches!(
            r2.status,
            FrameStatus::Fallback(FailReason::TooFewTracks { .. })
        ),
        "{:?}",
        r2.status
    );
    let predicted = r1.world_from_cam * r1.prev_from_cur;
    assert!((r2.world_from_cam.translation.vector - predicted.translation.vector).norm() < 1e-9);
    // a pair of the wrong size
    let small = visnav_core::GrayImage::new(10, 10, 0.0);
    let r3 = vo.process(&small, &small, &motion);
    assert!(matches!(
        r3.status,
        FrameStatus::Fallback(FailReason::ImageSize { .. })
    ));
    // and the pipeline recovers on good frames (first one re-initialises)
    let r4 = vo.process(&views[2].0.image, &views[2].1.image, &motion);
    assert!(matches!(
        r4.status,
        FrameStatus::Fallback(FailReason::NoPreviousFeatures)
    ));
    let r5 = vo.process(&views[3].0.image, &views[3].1.image, &motion);
    assert!(
        matches!(r5.status, FrameStatus::Ok | FrameStatus::LowSpeed),
        "{:?}",
        r5.status
    );
}
