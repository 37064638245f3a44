//! `visnav odometry --mode mono`: end-to-end runs of the CLI on a small sequence rendered by
//! `visnav synth` (320x96, 8 frames, ground truth in `poses.txt`).
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};

use visnav_core::Pose;
use visnav_io::trajectory::read_kitti;

mod common;
use common::{run_ok, synth_sequence, visnav};

const FRAMES: usize = 8;

/// Renders the test sequence into `dir/seq` and returns its path.
fn synth(dir: &Path) -> PathBuf {
    let seq = dir.join("seq");
    synth_sequence(&seq, FRAMES, 320, 96);
    seq
}

/// Runs mono odometry on `seq` with `extra` arguments; returns the poses and the JSON report.
fn run_mono(dir: &Path, seq: &Path, extra: &[&str]) -> (Vec<Pose>, serde_json::Value) {
    let out = dir.join("poses.txt");
    let json = dir.join("report.json");
    run_ok(
        visnav()
            .args(["-q", "odometry", "--mode", "mono"])
            .arg(seq)
            .arg("--output")
            .arg(&out)
            .arg("--json")
            .arg(&json)
            .args(extra),
    );
    let report = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    (read_kitti(&out).unwrap(), report)
}

fn position(p: &Pose) -> nalgebra::Vector3<f64> {
    p.translation.vector
}

#[test]
fn mono_writes_one_forward_pose_per_frame_and_a_full_report() {
    let tmp = tempfile::tempdir().unwrap();
    let seq = synth(tmp.path());
    let depth_dir = tmp.path().join("depth");
    let flow_dir = tmp.path().join("flow");
    let (poses, report) = run_mono(
        tmp.path(),
        &seq,
        &[
            "--camera-height",
            "1.7",
            "--save-depth",
            depth_dir.to_str().unwrap(),
            "--save-flow",
            flow_dir.to_str().unwrap(),
        ],
    );
    assert_eq!(poses.len(), FRAMES);
    assert!(
        (poses[0].to_homogeneous() - Pose::identity().to_homogeneous()).norm() < 1e-12,
        "frame 0 must be the identity"
    );

    // motion roughly forward along +z, with about the true length (the scale comes from the
    // camera height alone)
    let gt = read_kitti(&seq.join("poses.txt")).unwrap();
    let (est_end, gt_end) = (position(&poses[FRAMES - 1]), position(&gt[FRAMES - 1]));
    assert!(est_end.z > 0.0, "end point {est_end:?}");
    assert!(
        est_end.z > 2.0 * est_end.y.abs(),
        "end point {est_end:?} not forward"
    );
    let err = (est_end - gt_end).norm() / gt_end.norm();
    assert!(
        err < 0.3,
        "end point {est_end:?} vs ground truth {gt_end:?} ({err:.2} relative)"
    );

    // the report
    assert_eq!(report["mode"], "mono");
    assert_eq!(report["frames"], FRAMES);
    assert!(report["palindrome"].is_null());
    assert!(report["config"]["mono"]["scale"]["camera_height_m"].as_f64() == Some(1.7));
    assert!(report["config"]["mono"]["flow"]["flow"].is_object());
    assert!(report["mean"]["flow_ms"].as_f64().unwrap() > 0.0);
    let frames = report["per_frame"].as_array().unwrap();
    assert_eq!(frames.len(), FRAMES);
    assert_eq!(frames[0]["detail"]["mono"]["source"], "initial");
    for (k, f) in frames.iter().enumerate().skip(1) {
        assert_eq!(f["index"], k);
        assert!(
            ["ok", "low_parallax"].contains(&f["status"].as_str().unwrap()),
            "frame {k}: {f}"
        );
        let m = &f["detail"]["mono"];
        let source = m["source"].as_str().unwrap();
        assert!(
            ["eight_point", "pnp", "fused"].contains(&source),
            "frame {k}: {source}"
        );
        assert!(m["scale_source"].is_string());
        assert!(m["eight_point_inliers"].as_u64().is_some());
        assert!(m["pnp_inliers"].as_u64().is_some());
        assert!(f["timings"]["flow"]["total_ms"].as_f64().unwrap() > 0.0);
        assert!(f["timings"]["mono"]["eight_point_ms"].as_f64().is_some());
    }
    assert!(
        frames
            .iter()
            .any(|f| f["detail"]["mono"]["eight_point_inliers"].as_u64().unwrap() > 100)
    );

    // effective config beside the output, and it parses back as a config file
    let config = tmp.path().join("poses.config.toml");
    let text = std::fs::read_to_string(&config).unwrap();
    assert!(
        text.contains("[mono") && text.contains("[mono.flow"),
        "{text}"
    );
    let again = tmp.path().join("again");
    std::fs::create_dir_all(&again).unwrap();
    let (p2, _) = run_mono(
        &again,
        &seq,
        &["--config", config.to_str().unwrap(), "--max-frames", "3"],
    );
    assert_eq!(p2.len(), 3);

    // saved flow and depth
    let flo = visnav_io::flo::read_flo(&flow_dir.join("000000_000001.flo")).unwrap();
    assert_eq!((flo.width, flo.height), (320, 96));
    let info = visnav_io::pfm::read_pfm(&flow_dir.join("000006_000007.info.pfm")).unwrap();
    assert_eq!(info.channels, 3);
    let depth = visnav_io::pfm::read_pfm(&depth_dir.join("000007.pfm")).unwrap();
    assert_eq!(depth.channels, 1);
    let known: Vec<f32> = depth
        .data
        .iter()
        .copied()
        .filter(|d| d.is_finite())
        .collect();
    assert!(known.len() > 10);
    assert!(known.iter().all(|&d| d > 0.0));
}

#[test]
fn mono_corrupted_frame_still_yields_one_pose_per_frame() {
    let tmp = tempfile::tempdir().unwrap();
    let seq = synth(tmp.path());
    std::fs::write(seq.join("image_0/000004.png"), b"not a png").unwrap();
    let (poses, report) = run_mono(tmp.path(), &seq, &[]);
    assert_eq!(poses.len(), FRAMES);
    let frames = report["per_frame"].as_array().unwrap();
    assert_eq!(report["skipped_frames"], 1);
    assert_eq!(report["failed_frames"], 0);
    let bad = &frames[4];
    assert_eq!(bad["status"], "skipped");
    assert_eq!(bad["detail"], "none");
    let error = bad["reason"].as_str().unwrap();
    assert!(error.contains("000004.png"), "{error}");
    // the prediction continues the motion, and the frames after it are estimated again
    let step = |k: usize| (position(&poses[k]) - position(&poses[k - 1])).norm();
    assert!(step(4) > 0.5 * step(3) && step(4) < 2.0 * step(3));
    for f in &frames[5..] {
        assert!(
            ["ok", "low_parallax"].contains(&f["status"].as_str().unwrap()),
            "{f}"
        );
    }
    assert!(position(&poses[FRAMES - 1]).z > position(&poses[3]).z);
}

#[test]
fn mono_palindrome_returns_near_the_start() {
    let tmp = tempfile::tempdir().unwrap();
    let seq = synth(tmp.path());
    let (poses, report) = run_mono(tmp.path(), &seq, &["--palindrome"]);
    assert_eq!(poses.len(), 2 * FRAMES - 1);
    let drift = &report["palindrome"];
    let travelled = drift["distance_travelled_m"].as_f64().unwrap();
    let end_point = drift["end_point_error_m"].as_f64().unwrap();
    assert!(travelled > 4.0, "{drift}");
    // the end point is near the start, relative to the distance travelled
    assert!(
        (position(&poses[2 * FRAMES - 2]) - position(&poses[0])).norm() < 0.15 * travelled,
        "{drift}"
    );
    assert!(
        (end_point / travelled - drift["end_point_error_relative"].as_f64().unwrap()).abs() < 1e-9
    );
    let ratio = drift["scale_drift_ratio"].as_f64().unwrap();
    assert!((0.7..1.4).contains(&ratio), "{drift}");
    // the turning frame appears once: steps 7 and 8 are frames 7 and 6
    let frames = report["per_frame"].as_array().unwrap();
    assert_eq!(frames[FRAMES - 1]["index"], FRAMES - 1);
    assert_eq!(frames[FRAMES]["index"], FRAMES - 2);
    assert_eq!(frames[2 * FRAMES - 2]["index"], 0);
}

#[test]
fn mode_specific_options_are_rejected_in_the_other_mode() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("p.txt");
    let run = |mode: &str, extra: &[&str]| {
        visnav()
            .args(["-q", "odometry", "--mode", mode])
            .arg(tmp.path())
            .arg("--output")
            .arg(&out)
            .args(extra)
            .output()
            .unwrap()
    };
    let o = run("stereo", &["--palindrome"]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--palindrome"));
    let o = run("mono", &["--outlier", "re"]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--outlier"));
    assert!(!out.exists());
}

/// `--preset realtime` runs the fast flow (the written configuration says so) and keeps the
/// output's shape: one forward pose per frame, no frame refused on the rendered drive.
#[test]
fn the_realtime_preset_runs_the_fast_flow() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let seq = synth(d);
    let (poses, report) = run_mono(d, &seq, &["--preset", "realtime"]);
    assert_eq!(poses.len(), FRAMES);
    assert_eq!(
        report["config"]["mono"]["flow"]["method"], "fast",
        "{}",
        report["config"]
    );
    assert_eq!(report["failed_frames"], 0);
    let last = position(&poses[FRAMES - 1]);
    assert!(last.z > 1.0, "the drive goes forward: {last:?}");
    let (_, paper) = run_mono(d, &seq, &[]);
    assert_eq!(paper["config"]["mono"]["flow"]["method"], "paper");
}
