//! After frames dropped by a live stream's frame policy, the monocular constant-velocity
//! prediction spans the true time step (issue 55 item 2); without drops it stays the paper's
//! one-motion-a-frame model, pose for pose.
#![allow(clippy::unwrap_used)]

use visnav_core::Pose;
use visnav_pipeline::{FrameInput, MonoRunConfig, Odometry, Preset};
use visnav_synth::{Scene, drive_trajectory, kitti_like_camera, render_view};

/// The rotation angle of a pose, radians.
fn angle(p: &Pose) -> f64 {
    p.rotation.angle()
}

/// Three rendered frames 0.1 s apart, then a frame without images at `t_s` after `dropped`
/// dropped frames: its `prev_from_cur` and the last estimated one.
fn predicted_after(dropped: usize, t_s: f64) -> (Pose, Pose) {
    let gt = drive_trajectory(12, 3);
    let scene = Scene::along(&gt, 3).unwrap();
    let camera = kitti_like_camera(320, 96);
    let config = MonoRunConfig::of_preset(Preset::Realtime);
    let mut vo = Odometry::mono(camera, &config).unwrap();
    let mut last = Pose::identity();
    for (k, pose) in gt.iter().take(3).enumerate() {
        let image = render_view(&scene, &camera, pose).image;
        let r = vo.process(FrameInput::mono(image, Some(0.1 * k as f64)));
        let r = r.last().unwrap();
        assert!(!r.status.is_predicted(), "frame {k}: {:?}", r.status);
        last = r.prev_from_cur;
    }
    let mut gap = FrameInput::missing("dropped", Some(t_s));
    gap.dropped_before = dropped;
    let r = vo.process(gap);
    (r.last().unwrap().prev_from_cur, last)
}

#[test]
fn the_prediction_after_dropped_frames_spans_the_true_time_step() {
    // 3 frames dropped: 0.4 s since the frame before, the last motion spanned 0.1 s
    let (predicted, last) = predicted_after(3, 0.6);
    let ratio = predicted.translation.vector.norm() / last.translation.vector.norm();
    assert!((ratio - 4.0).abs() < 1e-9, "translation x{ratio}");
    let turn = angle(&predicted) / angle(&last);
    assert!((turn - 4.0).abs() < 1e-6, "rotation x{turn}");
    // no drop (a recording): the last motion (to rounding: the trajectory's step is
    // `world_from_prev⁻¹ · world_from_cur`), whatever the timestamps say
    let (predicted, last) = predicted_after(0, 0.6);
    let d = predicted.inverse() * last;
    assert!(
        d.translation.vector.norm() < 1e-12 && angle(&d) < 1e-12,
        "{d:?}"
    );
}
