//! Stereo VO on the real KITTI 06 clip (51 stereo pairs, about 60 m), scored with the KITTI devkit
//! metric over lengths 10, 20, 30, 40, 50 m against libviso2's reference scores on the same clip
//! (t_err 1.0251 %, r_err 2.8211 deg/100 m).
#![allow(clippy::unwrap_used)]

use visnav_core::Pose;
use visnav_eval::kitti::{KittiMetricConfig, kitti_score, sequence_errors};
use visnav_io::Sequence;
use visnav_io::trajectory::read_kitti;
use visnav_odometry::RelativeMotion;
use visnav_odometry::stereo::{FrameStatus, StereoConfig, StereoOdometry};

#[test]
fn kitti_06_beats_libviso2() {
    let Some(seq_dir) = visnav_core::testdata::shared_data("kitti/odometry/sequences/06") else {
        return;
    };
    let Some(gt_path) = visnav_core::testdata::shared_data("kitti/odometry/poses/06.txt") else {
        return;
    };
    let seq = Sequence::open(&seq_dir).unwrap();
    let rig = seq.stereo_camera().unwrap();
    let mut vo = StereoOdometry::new(rig, StereoConfig::default()).unwrap();
    let mut motion = RelativeMotion::identity();
    let mut est: Vec<Pose> = Vec::new();
    for i in 0..seq.len() {
        let (l, r) = (seq.load_left(i).unwrap(), seq.load_right(i).unwrap());
        let res = vo.process(&l, &r, &motion);
        motion = res.motion.unwrap_or(motion);
        assert!(
            !matches!(res.status, FrameStatus::Fallback(_)),
            "frame {i}: {:?}",
            res.status
        );
        est.push(res.world_from_cam);
    }
    let gt = read_kitti(&gt_path).unwrap();
    let gt: Vec<_> = gt[..est.len()].iter().map(Pose::to_homogeneous).collect();
    let est: Vec<_> = est.iter().map(Pose::to_homogeneous).collect();
    let cfg = KittiMetricConfig {
        lengths_m: vec![10.0, 20.0, 30.0, 40.0, 50.0],
        ..KittiMetricConfig::default()
    };
    let errors = sequence_errors(&gt, &est, &cfg, 6);
    let score = kitti_score(&errors, &cfg.lengths_m);
    eprintln!(
        "KITTI 06 clip: t_err {:.4} %  r_err {:.4} deg/100m  ({} segments)",
        score.t_err_percent, score.r_err_deg_per_100m, score.segments
    );
    assert_eq!(score.segments, 15);
    assert!(
        score.t_err_percent < 1.0251,
        "t_err {}",
        score.t_err_percent
    );
    assert!(
        score.r_err_deg_per_100m < 2.8211,
        "r_err {}",
        score.r_err_deg_per_100m
    );
}
