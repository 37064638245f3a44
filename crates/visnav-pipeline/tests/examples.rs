//! The library examples run here, on their synthetic input, and their trajectories are checked
//! against the rendered ground truth (so CI runs the examples a newcomer copies).
#![allow(clippy::unwrap_used, dead_code)]

#[path = "../examples/mono.rs"]
mod mono;
#[path = "../examples/stereo.rs"]
mod stereo;

use visnav_synth::drive_trajectory;

/// Distance of the last estimated position from the truth, metres, and the path length.
fn end_error(est: &[visnav_core::Pose]) -> (f64, f64) {
    // the estimate's world is the first camera
    let truth: Vec<_> = drive_trajectory(est.len(), 2);
    let truth: Vec<_> = truth.iter().map(|p| truth[0].inverse() * p).collect();
    let length: f64 = truth
        .windows(2)
        .map(|w| (w[1].translation.vector - w[0].translation.vector).norm())
        .sum();
    let last = est.len() - 1;
    let e = (est[last].translation.vector - truth[last].translation.vector).norm();
    (e, length)
}

#[test]
fn the_mono_example_tracks_the_synthetic_drive() {
    let (camera, images, height) = mono::input(&[]).unwrap();
    let poses = mono::run(camera, images, height);
    assert_eq!(poses.len(), 12);
    // monocular: the direction of travel is tight, the scale (from the ground plane on 320x96
    // images) within 25 %
    let truth = drive_trajectory(12, 2);
    let t_true = (truth[0].inverse() * truth[11]).translation.vector;
    let t_est = poses[11].translation.vector;
    let angle_deg = t_true.angle(&t_est).to_degrees();
    let ratio = t_est.norm() / t_true.norm();
    assert!(angle_deg < 3.0, "end direction off by {angle_deg} deg");
    assert!((0.75..1.25).contains(&ratio), "end distance ratio {ratio}");
}

#[test]
fn the_stereo_example_tracks_the_synthetic_drive() {
    let (rig, pairs) = stereo::input(None).unwrap();
    let poses = stereo::run(rig, pairs);
    assert_eq!(poses.len(), 12);
    let (e, length) = end_error(&poses);
    assert!(e < 0.05 * length, "end error {e} m over {length} m");
}
