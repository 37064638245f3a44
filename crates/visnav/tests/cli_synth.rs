//! `visnav synth` writes a KITTI odometry directory that `Sequence::open` reads back, with
//! ground truth that matches the library.
#![allow(clippy::unwrap_used)]

use visnav_io::Sequence;
use visnav_io::flo::read_flo;
use visnav_io::pfm::read_pfm;
use visnav_io::trajectory::read_kitti;
use visnav_synth::{Scene, drive_trajectory, flow_between, kitti_like_camera, render_view};

mod common;
use common::{run_err, run_ok, visnav};

#[test]
fn synth_writes_a_readable_stereo_sequence() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("seq");
    let status = visnav()
        .args(["--quiet", "synth", "--out"])
        .arg(&out)
        .args([
            "--frames", "5", "--stereo", "--width", "160", "--height", "48", "--seed", "3",
        ])
        .status()
        .unwrap();
    assert!(status.success());
    let seq = Sequence::open(&out).unwrap();
    assert_eq!(seq.len(), 5);
    assert!(seq.has_stereo());
    assert!((seq.baseline_m.unwrap() - 0.537).abs() < 1e-9);
    let cam = kitti_like_camera(160, 48);
    assert_eq!((seq.camera.width, seq.camera.height), (160, 48));
    assert!((seq.camera.fx - cam.fx).abs() < 1e-9 && (seq.camera.cy - cam.cy).abs() < 1e-9);
    assert!((seq.timestamps[4] - 0.4).abs() < 1e-9);
    let left = seq.load_left(2).unwrap();
    let right = seq.load_right(2).unwrap();
    assert_eq!((left.width(), left.height()), (160, 48));
    assert_ne!(left, right);
    // ground truth: the generated drive, one flow field per consecutive pair, depth per frame
    let poses = read_kitti(&out.join("poses.txt")).unwrap();
    let expected = drive_trajectory(5, 3);
    assert_eq!(poses.len(), 5);
    for (p, q) in poses.iter().zip(&expected) {
        assert!((p.to_homogeneous() - q.to_homogeneous()).norm() < 1e-8);
    }
    for i in 0..4 {
        let flow = read_flo(&out.join(format!("flow/{i:06}.flo"))).unwrap();
        assert_eq!((flow.width, flow.height), (160, 48));
        let known = (0..160 * 48)
            .filter(|k| flow.is_known(k % 160, k / 160))
            .count();
        assert!(known > 160 * 48 / 2, "{known}");
    }
    assert!(!out.join("flow/000004.flo").exists());
    let depth = read_pfm(&out.join("depth/000004.pfm")).unwrap();
    assert_eq!((depth.width, depth.height, depth.channels), (160, 48, 1));
    // bottom-centre pixel sees the road 1.65 m below the camera
    assert!(depth.data[47 * 160 + 80] > 1.0 && depth.data[47 * 160 + 80] < 10.0);
    assert!(out.join("synth.json").exists());
    // the files hold exactly what the library renders
    let scene = Scene::along(&expected, 3).unwrap();
    let v3 = render_view(&scene, &cam, &expected[3]);
    let v4 = render_view(&scene, &cam, &expected[4]);
    assert_eq!(depth.data, v4.depth_m);
    let gt = flow_between(&scene, &cam, &expected[3], &v3, &expected[4], &v4);
    assert_eq!(
        read_flo(&out.join("flow/000003.flo")).unwrap(),
        gt.masked_flow()
    );
    let png = seq.load_left(4).unwrap();
    let max_diff = png
        .data()
        .iter()
        .zip(v4.image.data())
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(
        max_diff <= 0.5 + 1e-3,
        "PNG differs from the render by {max_diff}"
    );
}

#[test]
fn synth_follows_a_kitti_trajectory_file() {
    let dir = tempfile::tempdir().unwrap();
    let traj = dir.path().join("poses.txt");
    std::fs::write(
        &traj,
        "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0.1 0 1 0 0 0 0 1 0.9\n1 0 0 0.2 0 1 0 0 0 0 1 1.8\n",
    )
    .unwrap();
    let out = dir.path().join("seq");
    let output = run_ok(
        visnav()
            .args(["synth", "--json", "--out"])
            .arg(&out)
            .arg("--trajectory")
            .arg(&traj)
            .args(["--width", "64", "--height", "20", "--supersampling", "1"]),
    );
    let summary: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    assert_eq!(summary["frames"], 3);
    assert!((summary["path_length_m"].as_f64().unwrap() - 2.0 * 0.1f64.hypot(0.9)).abs() < 1e-9);
    let seq = Sequence::open(&out).unwrap();
    assert_eq!(seq.len(), 3);
    assert!(!seq.has_stereo());
    let poses = read_kitti(&out.join("poses.txt")).unwrap();
    assert!((poses[2].translation.vector.z - 1.8).abs() < 1e-9);
}

#[test]
fn synth_reports_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("nope.txt");
    let err = run_err(
        visnav()
            .args(["synth", "--out"])
            .arg(dir.path().join("seq"))
            .arg("--trajectory")
            .arg(&missing),
    );
    assert!(err.contains("nope.txt"), "{err}");
    let bad = dir.path().join("bad.txt");
    std::fs::write(&bad, "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0\n").unwrap();
    let err = run_err(
        visnav()
            .args(["synth", "--out"])
            .arg(dir.path().join("seq"))
            .arg("--trajectory")
            .arg(&bad),
    );
    assert!(err.contains("bad.txt") && err.contains('2'), "{err}");
    for args in [
        ["--frames", "0"],
        ["--width", "0"],
        ["--supersampling", "9"],
    ] {
        let output = visnav()
            .args(["synth", "--out"])
            .arg(dir.path().join("seq"))
            .args(args)
            .output()
            .unwrap();
        assert!(!output.status.success(), "{args:?}");
        assert!(!String::from_utf8_lossy(&output.stderr).contains("panicked"));
    }
}

#[test]
fn synth_renders_along_a_real_kitti_ground_truth() {
    let Some(poses_path) = visnav_core::testdata::shared_data("kitti/odometry/poses/00.txt") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("seq");
    let status = visnav()
        .args(["--quiet", "synth", "--out"])
        .arg(&out)
        .arg("--trajectory")
        .arg(&poses_path)
        .args([
            "--frames",
            "4",
            "--width",
            "96",
            "--height",
            "32",
            "--supersampling",
            "1",
        ])
        .status()
        .unwrap();
    assert!(status.success());
    let seq = Sequence::open(&out).unwrap();
    assert_eq!(seq.len(), 4);
    let written = read_kitti(&out.join("poses.txt")).unwrap();
    let original = read_kitti(&poses_path).unwrap();
    for (w, o) in written.iter().zip(&original) {
        assert!((w.to_homogeneous() - o.to_homogeneous()).norm() < 1e-6);
    }
    // the car drives forward ~0.9 m a frame: the flow fields are mostly known
    let flow = read_flo(&out.join("flow/000000.flo")).unwrap();
    let known = (0..96 * 32)
        .filter(|k| flow.is_known(k % 96, k / 96))
        .count();
    assert!(known > 96 * 32 / 2, "{known}");
}
