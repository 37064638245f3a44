//! The shared KITTI clips open with the expected calibration and sizes.
#![allow(clippy::unwrap_used)]

use visnav_core::testdata::shared_data;
use visnav_io::trajectory::read_trajectory;
use visnav_io::{Sequence, SequenceLayout};

#[test]
fn kitti_06_stereo_clip() {
    let Some(root) = shared_data("kitti/odometry/sequences/06") else {
        return;
    };
    let seq = Sequence::open(&root).unwrap();
    assert_eq!(seq.layout, SequenceLayout::KittiOdometry);
    assert_eq!(seq.len(), 51);
    assert!(seq.has_stereo());
    assert_eq!((seq.camera.width, seq.camera.height), (1226, 370));
    assert!((seq.baseline_m.unwrap() - 0.537).abs() < 1e-3);
    let right = seq.load_right(50).unwrap();
    assert_eq!(right.width(), 1226);
}

#[test]
fn kitti_00_mono_clip_and_poses() {
    let Some(root) = shared_data("kitti/odometry/sequences/00") else {
        return;
    };
    let seq = Sequence::open(&root).unwrap();
    assert_eq!(seq.len(), 300);
    assert_eq!((seq.camera.width, seq.camera.height), (1241, 376));
    assert!((seq.timestamps[1] - seq.timestamps[0] - 0.1).abs() < 0.01);
    let Some(poses) = shared_data("kitti/odometry/poses/00.txt") else {
        return;
    };
    let t = read_trajectory(&poses).unwrap();
    assert_eq!(t.poses.len(), 4541);
    assert!(t.timestamps.is_none());
}
