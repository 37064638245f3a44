//! The streaming odometry's one failure policy, on rendered drives with exact ground truth: a
//! frame with missing images gets the constant-velocity prediction and a `Skipped` status, the
//! next frame is matched against the last accepted image, every pushed frame gets exactly one
//! result; the pipelined mode gives the same poses as the synchronous one; the run report
//! round-trips through its JSON.
#![allow(clippy::unwrap_used)]

use visnav_core::{GrayImage, PinholeCamera, StereoCamera};
use visnav_odometry::stereo::StereoConfig;
use visnav_pipeline::report::{FrameRecord, RunReport};
use visnav_pipeline::{FrameInput, FrameResult, MonoRunConfig, Odometry, RunConfig, Status};
use visnav_synth::{
    KITTI_BASELINE_M, Scene, drive_trajectory, kitti_like_camera, render_stereo, render_view,
};

const FRAMES: usize = 9;
const MISSING: usize = 4;

fn mono_drive() -> (PinholeCamera, Vec<GrayImage>, MonoRunConfig) {
    let truth = drive_trajectory(FRAMES, 3);
    let scene = Scene::along(&truth, 3).unwrap();
    let camera = kitti_like_camera(320, 96);
    let images = truth
        .iter()
        .map(|p| render_view(&scene, &camera, p).image)
        .collect();
    let mut config = MonoRunConfig::default();
    config.mono.scale.camera_height_m = scene.config().ground_depth_m;
    let s = f64::from(camera.width) / 1241.0;
    config.mono.parallax.min_flow_p75_px *= s;
    config.mono.parallax.min_klt_median_px *= s;
    (camera, images, config)
}

/// Pushes the drive with frame `MISSING` missing; collects every result.
fn run_mono(pipelined: bool) -> Vec<FrameResult> {
    let (camera, images, config) = mono_drive();
    let mut vo = Odometry::mono(camera, &config)
        .unwrap()
        .pipelined(pipelined);
    let mut out = Vec::new();
    for (i, image) in images.into_iter().enumerate() {
        let input = if i == MISSING {
            FrameInput::missing("frame 4 dropped", Some(0.4))
        } else {
            FrameInput::mono(image, Some(i as f64 * 0.1))
        };
        out.extend(vo.push(input));
    }
    out.extend(vo.finish());
    assert_eq!(vo.trajectory().len(), FRAMES);
    out
}

#[test]
fn a_missing_mono_frame_is_predicted_and_the_next_is_matched_against_the_last_accepted() {
    let r = run_mono(false);
    assert_eq!(r.len(), FRAMES);
    for (k, f) in r.iter().enumerate() {
        assert_eq!(f.position, k);
        assert!(
            f.world_from_cam
                .translation
                .vector
                .iter()
                .all(|v| v.is_finite())
        );
        // world_from_cur = world_from_prev · prev_from_cur, for every frame
        if k > 0 {
            let chained = r[k - 1].world_from_cam * f.prev_from_cur;
            assert!(
                (chained.to_homogeneous() - f.world_from_cam.to_homogeneous())
                    .abs()
                    .max()
                    < 1e-9
            );
        }
    }
    assert!(matches!(&r[MISSING].status, Status::Skipped { reason } if reason.contains("dropped")));
    assert_eq!(r[MISSING].timestamp_s, Some(0.4));
    // constant velocity: the skipped step repeats the motion before it
    let (a, b) = (r[MISSING - 1].prev_from_cur, r[MISSING].prev_from_cur);
    let d = (a.to_homogeneous() - b.to_homogeneous()).abs().max();
    assert!(d < 1e-9, "{d} {a:?} {b:?}");
    assert_eq!(r[MISSING + 1].reference_position, Some(MISSING - 1));
    for f in r.iter().filter(|f| f.position != MISSING) {
        assert!(
            !f.status.is_predicted(),
            "frame {}: {:?}",
            f.position,
            f.status
        );
    }
}

#[test]
fn the_pipelined_mode_gives_the_same_poses_as_the_synchronous_one() {
    let sync = run_mono(false);
    let piped = run_mono(true);
    assert_eq!(sync.len(), piped.len());
    for (a, b) in sync.iter().zip(&piped) {
        assert_eq!(a.world_from_cam, b.world_from_cam, "frame {}", a.position);
        assert_eq!(a.status, b.status);
    }
}

#[test]
fn stereo_frames_without_a_pair_are_skipped_and_still_get_a_pose() {
    let truth = drive_trajectory(FRAMES, 2);
    let scene = Scene::along(&truth, 2).unwrap().with_supersampling(2);
    let rig = StereoCamera::new(kitti_like_camera(640, 192), KITTI_BASELINE_M).unwrap();
    let mut vo = Odometry::stereo(rig, StereoConfig::default()).unwrap();
    let mut results = Vec::new();
    for (i, p) in truth.iter().enumerate() {
        let (l, r) = render_stereo(&scene, &rig, p);
        let input = match i {
            3 => FrameInput::missing("unreadable", None),
            6 => FrameInput::mono(l.image, None),
            _ => FrameInput::stereo(l.image, r.image, None),
        };
        results.extend(vo.process(input));
    }
    assert_eq!(results.len(), FRAMES);
    assert!(matches!(&results[3].status, Status::Skipped { reason } if reason == "unreadable"));
    assert!(
        matches!(&results[6].status, Status::Skipped { reason } if reason.contains("no right image"))
    );
    // the frame after a skip has nothing to track from: a fallback, then estimates again
    assert!(matches!(results[4].status, Status::Fallback { .. }));
    assert!(!results[5].status.is_predicted());
    // frame 8 restarts from frame 7 with the prediction of the rotation on the spot while the
    // car pulls away: the tracks do not agree on one motion (issue 21: it used to be accepted
    // with status ok although no track was consistent with it). Accepted, it must be right;
    // else it is the documented fallback.
    let step = truth[7].inverse() * truth[8];
    let err_m = (results[8].prev_from_cur.translation.vector - step.translation.vector).norm();
    eprintln!("frame 8: {:?}, step error {err_m:.3} m", results[8].status);
    if results[8].status.is_predicted() {
        let status = format!("{:?}", results[8].status);
        assert!(status.contains("InconsistentMotion"), "{status}");
    } else {
        assert!(err_m < 0.2, "frame 8 accepted {err_m:.3} m off the truth");
    }
    // before the first skip the poses follow the truth; every pose chains onto the one before
    for k in 0..3 {
        let t = (truth[0].inverse() * truth[k]).translation.vector;
        let err = (results[k].world_from_cam.translation.vector - t).norm();
        assert!(err < 0.05, "frame {k}: {err} m from the truth");
    }
    for k in 1..FRAMES {
        let chained = results[k - 1].world_from_cam * results[k].prev_from_cur;
        let d = (chained.to_homogeneous() - results[k].world_from_cam.to_homogeneous())
            .abs()
            .max();
        assert!(d < 1e-9, "frame {k}");
    }
    // the report of the run round-trips through its JSON, and counts what happened
    let records: Vec<FrameRecord> = results
        .iter()
        .map(|r| FrameRecord::new(r, r.position, 0.0, 0.0))
        .collect();
    let report = RunReport::new(
        "memory".into(),
        RunConfig::Stereo(Box::default()),
        FRAMES,
        records,
        1.0,
    );
    assert_eq!(report.skipped_frames, 2);
    let failed = 2 + usize::from(results[8].status.is_predicted());
    assert_eq!(report.failed_frames, failed);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.json");
    std::fs::write(&path, report.to_json().unwrap()).unwrap();
    assert_eq!(RunReport::read(&path).unwrap(), report);
}

/// Issue 21: on rendered stop-and-go drives RotROCC used to accept wrong motions with status
/// ok (seed 7: 1.46 m and 1.86 m for true steps of 0.82 m and 0.12 m while braking, 3.46 m for
/// 1.16 m later; seed 0: 1.90 m for 1.06 m). The rank-based phases always keep some subset of
/// the tracks, and the pass with more rotation inliers was kept even when its motion explained a
/// handful of tracks. Now a motion must be consistent with most tracks (else another pass, else
/// a fallback with `InconsistentMotion`), so every accepted step is close to the truth.
#[test]
fn stereo_stop_and_go_accepts_no_inconsistent_motion() {
    let rig = StereoCamera::new(kitti_like_camera(640, 192), KITTI_BASELINE_M).unwrap();
    for seed in [0_u64, 1, 7] {
        let truth = drive_trajectory(12, seed);
        let scene = Scene::along(&truth, seed).unwrap().with_supersampling(2);
        let mut vo = Odometry::stereo(rig, StereoConfig::default()).unwrap();
        let mut results = Vec::new();
        for p in &truth {
            let (l, r) = render_stereo(&scene, &rig, p);
            results.extend(vo.process(FrameInput::stereo(l.image, r.image, None)));
        }
        assert_eq!(
            results.len(),
            truth.len(),
            "seed {seed}: one pose per frame"
        );
        for (k, r) in results.iter().enumerate().skip(1) {
            let true_step = truth[k - 1].inverse() * truth[k];
            let err_m = (r.prev_from_cur.translation.vector - true_step.translation.vector).norm();
            eprintln!(
                "seed {seed} frame {k}: true step {:.3} m, estimated {:.3} m, error {err_m:.3} m, {:?}",
                true_step.translation.vector.norm(),
                r.prev_from_cur.translation.vector.norm(),
                r.status
            );
            if r.status.is_predicted() {
                let reason = format!("{:?}", r.status);
                assert!(
                    reason.contains("InconsistentMotion"),
                    "seed {seed} frame {k}: unexpected fallback {reason}"
                );
            } else {
                // a fifth of the ~1 m steps; the accepted wrong steps were 0.6-2.3 m off
                assert!(
                    err_m < 0.2,
                    "seed {seed} frame {k}: accepted a step {err_m:.3} m off the truth ({:?})",
                    r.status
                );
            }
        }
    }
}
