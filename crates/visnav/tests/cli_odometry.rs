//! `visnav odometry`: end-to-end runs of the CLI on a rendered KITTI-layout sequence and on the
//! real KITTI 06 clip.
#![allow(clippy::unwrap_used)]

use std::path::Path;

use visnav_synth::drive_trajectory;

mod common;
use common::{visnav, write_stereo_sequence};

/// Writes a small rendered stereo drive in the KITTI odometry layout.
fn write_synthetic_sequence(dir: &Path, frames: usize) {
    let gt = drive_trajectory(frames, 3);
    write_stereo_sequence(dir, &gt, &gt);
}

#[test]
fn stereo_on_rendered_sequence_writes_one_pose_per_frame() {
    let tmp = tempfile::tempdir().unwrap();
    let seq = tmp.path().join("seq");
    write_synthetic_sequence(&seq, 8);
    let out = tmp.path().join("poses.txt");
    let json = tmp.path().join("report.json");
    let status = visnav()
        .args(["-q", "odometry", "--mode", "stereo"])
        .arg(&seq)
        .arg("--output")
        .arg(&out)
        .arg("--json")
        .arg(&json)
        .args(["--outlier", "re"])
        .status()
        .unwrap();
    assert!(status.success());
    let text = std::fs::read_to_string(&out).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 8);
    assert_eq!(lines[0].split_whitespace().count(), 12);
    let first: Vec<f64> = lines[0]
        .split_whitespace()
        .map(|v| v.parse().unwrap())
        .collect();
    assert_eq!(
        first,
        vec![1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0]
    );
    // the effective config sits beside the output and says which outlier mode ran
    let config = std::fs::read_to_string(tmp.path().join("poses.config.toml")).unwrap();
    assert!(config.contains("outlier = \"re\""), "{config}");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let frames = report["per_frame"].as_array().unwrap();
    assert_eq!(frames.len(), 8);
    assert_eq!(frames[0]["status"], "ok");
    assert!(
        frames[1]["detail"]["stereo"]["counts"]["circular"]
            .as_u64()
            .unwrap()
            > 20
    );
    assert!(
        frames[1]["timings"]["stereo"]["tracking_ms"]
            .as_f64()
            .unwrap()
            >= 0.0
    );
    // the effective config is itself a valid --config
    let out2 = tmp.path().join("again.txt");
    let status = visnav()
        .args(["-q", "odometry"])
        .arg(&seq)
        .arg("--output")
        .arg(&out2)
        .arg("--config")
        .arg(tmp.path().join("poses.config.toml"))
        .status()
        .unwrap();
    assert!(status.success());
    assert_eq!(std::fs::read_to_string(&out2).unwrap(), text);
}

#[test]
fn bad_inputs_fail_with_a_message() {
    let tmp = tempfile::tempdir().unwrap();
    let out = visnav()
        .args([
            "odometry",
            "--mode",
            "stereo",
            "/nonexistent/sequence",
            "--output",
        ])
        .arg(tmp.path().join("p.txt"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("sequence"));
    let bad_cfg = tmp.path().join("bad.toml");
    std::fs::write(&bad_cfg, "no_such_field = 1\n").unwrap();
    let seq = tmp.path().join("seq");
    write_synthetic_sequence(&seq, 2);
    let out = visnav()
        .args(["odometry"])
        .arg(&seq)
        .arg("--output")
        .arg(tmp.path().join("p.txt"))
        .arg("--config")
        .arg(&bad_cfg)
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("config"));
    // a stereo-only option in mono mode (mono itself is tested in cli_odometry_mono.rs)
    let out = visnav()
        .args(["odometry", "--mode", "mono", "--outlier", "re"])
        .arg(&seq)
        .arg("--output")
        .arg(tmp.path().join("p.txt"))
        .output()
        .unwrap();
    assert!(!out.status.success());
}

#[test]
fn stereo_on_kitti_06_head() {
    let Some(seq) = visnav_core::testdata::shared_data("kitti/odometry/sequences/06") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("p.txt");
    let status = visnav()
        .args(["-q", "odometry", "--mode", "stereo", "--max-frames", "6"])
        .arg(&seq)
        .arg("--output")
        .arg(&out)
        .status()
        .unwrap();
    assert!(status.success());
    let text = std::fs::read_to_string(&out).unwrap();
    assert_eq!(text.lines().count(), 6);
    // the car drives forward (+z) about 1 m a frame at the start of 06
    let last: Vec<f64> = text
        .lines()
        .last()
        .unwrap()
        .split_whitespace()
        .map(|v| v.parse().unwrap())
        .collect();
    assert!(
        last[11] > 3.0 && last[11] < 8.0,
        "z after 5 frames: {}",
        last[11]
    );
}
