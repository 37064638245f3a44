//! A small drone's indoor flight from the command line (issue 54): `visnav synth --flight`
//! renders a low flight over a floor mat through a distorted lens into an image folder with a
//! `camera.yaml`, and `visnav odometry --mode mono --aerial --camera-height --ground-normal`
//! flies it as a user with a real drone would.
#![allow(clippy::unwrap_used)]

use std::path::Path;

use visnav_io::Sequence;
use visnav_io::trajectory::read_kitti;

mod common;
use common::{run_err, run_ok, visnav};

/// The short flight of CI: takeoff from 0.1 m to 1.5 m in 2 s, a hover, then (with enough
/// frames) a 1 m leg and a 90° turn on the spot; 2 renders of motion blur to keep it fast.
const SHORT_FLIGHT: &str = "[indoor]\ncruise_height_m = 1.5\nheight_change_m = 0.5\n\
    climb_speed_mps = 0.7\nleg_m = 1.0\nhover_s = 0.5\nland = false\nblur_samples = 2\n";

/// 240x136: the takeoff's scale is within 3 % there (2026-12-02; 320x180: 3 %, 160x90: 12 %).
fn render(dir: &Path, name: &str, frames: usize) -> std::path::PathBuf {
    let file = dir.join("flight.toml");
    std::fs::write(&file, SHORT_FLIGHT).unwrap();
    let out = dir.join(name);
    run_ok(
        visnav()
            .args(["-q", "synth", "--flight"])
            .arg(&file)
            .arg("--out")
            .arg(&out)
            .args(["--frames", &frames.to_string()])
            .args(["--width", "240", "--height", "136"]),
    );
    out
}

fn fly(seq: &Path, est: &Path) {
    run_ok(
        visnav()
            .args(["-q", "odometry", "--mode", "mono", "--aerial"])
            .args(["--camera-height", "0.1"])
            .args(["--ground-normal", "0,0,1"])
            .arg(seq)
            .arg("-o")
            .arg(est),
    );
}

/// The rendered folder is what a drone's user has: JPEG images and a camera file with the lens's
/// distortion, which the reader takes (and undistorts with); the ground truth starts on the floor.
#[test]
fn synth_writes_an_indoor_flight_as_a_calibrated_image_folder() {
    let dir = tempfile::tempdir().unwrap();
    let seq = render(dir.path(), "indoor", 3);
    let calib = visnav_io::calibration::read_camera_file(&seq.join("camera.yaml")).unwrap();
    assert_eq!(calib.left.distortion.coefficients()[..2], [0.19, -0.56]);
    assert_eq!(
        (calib.left.pinhole.width, calib.left.pinhole.height),
        (240, 136)
    );
    let opened = Sequence::open(&seq).unwrap();
    assert_eq!(opened.len(), 3);
    assert!((opened.timestamps[1] - opened.timestamps[0] - 0.1).abs() < 1e-9);
    assert!(seq.join("000002.jpg").is_file());
    let heights = std::fs::read_to_string(seq.join("heights.txt")).unwrap();
    assert!(heights.starts_with("0.100000000\n"), "{heights}");
    // a lens the reader cannot invert at the corners is refused when rendering, naming it
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "[indoor.camera]\nfocal_px = 400.0\n").unwrap();
    let e = run_err(
        visnav()
            .args(["synth", "--flight"])
            .arg(&bad)
            .arg("--out")
            .arg(dir.path().join("x")),
    );
    assert!(e.contains("focal_px"), "{e}");
}

/// The takeoff from 0.1 m to 1.5 m: every frame gets a pose and the metric scale comes from the
/// height at the first frame, `--camera-height 0.1`: the climb comes out within 10 % of its
/// 1.4 m (measured 2026-12-02: 2.8 % short; a height read as 1 m makes it 10 times too long).
#[test]
fn a_takeoff_keeps_the_metric_scale_from_the_first_height() {
    let dir = tempfile::tempdir().unwrap();
    let frames = 22;
    let seq = render(dir.path(), "takeoff", frames);
    let est = dir.path().join("est.txt");
    fly(&seq, &est);
    let est = read_kitti(&est).unwrap();
    let gt = read_kitti(&seq.join("poses.txt")).unwrap();
    assert_eq!(est.len(), frames);
    let climb = |p: &[visnav_core::Pose]| {
        (p[frames - 1].translation.vector - p[0].translation.vector).norm()
    };
    let (climb_est, climb_gt) = (climb(&est), climb(&gt));
    assert!((climb_gt - 1.4).abs() < 0.05, "{climb_gt}");
    assert!(
        (climb_est / climb_gt - 1.0).abs() < 0.1,
        "climbed {climb_est:.3} m of {climb_gt:.3} m"
    );
}

/// A leg flown sideways over the floor after the hover keeps its length within 10 %. Without the
/// ground's normal held (`--ground-normal`) PnP and the homography take the small sideways step
/// over a plane for a pitch (their flows differ only in perspective) and the 1.03 m leg came
/// out 0.53 m (2026-12-03); with it, 0.975 of its length.
#[test]
fn a_leg_over_the_floor_is_flown_at_its_length() {
    let dir = tempfile::tempdir().unwrap();
    let frames = 50;
    let seq = render(dir.path(), "leg", frames);
    let est = dir.path().join("est.txt");
    fly(&seq, &est);
    let est = read_kitti(&est).unwrap();
    let gt = read_kitti(&seq.join("poses.txt")).unwrap();
    // the leg: from the end of the hover after the takeoff to the end of the sequence
    let leg = |p: &[visnav_core::Pose]| {
        (p[frames - 1].translation.vector - p[25].translation.vector).norm()
    };
    let (leg_est, leg_gt) = (leg(&est), leg(&gt));
    assert!(
        (leg_est / leg_gt - 1.0).abs() < 0.1,
        "flew {leg_est:.3} m of {leg_gt:.3} m"
    );
}
