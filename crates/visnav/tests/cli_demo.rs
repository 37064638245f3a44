//! `visnav demo` renders, scores and plots: the ground truth scores zero, the simulated
//! drifts score what they were built with, and the stereo and monocular pipelines run on the
//! rendered drive (default 620x188 size, 50 frames; mono on the first 12 frames to keep the test
//! short) with a bounded KITTI translation error.
#![allow(clippy::unwrap_used)]

mod common;
use common::{run_err, run_ok, visnav};

#[test]
fn demo_scores_references_as_built_and_pipelines_within_bounds() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo");
    let output = run_ok(
        visnav()
            .args(["demo", "--json", "--mono-frames", "12", "--output"])
            .arg(&out),
    );
    let report: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    let saved: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("scores.json")).unwrap()).unwrap();
    assert_eq!(report, saved);
    let scores = report["scores"].as_array().unwrap();
    let score = |name: &str| scores.iter().find(|s| s["name"] == name).unwrap().clone();
    let gt = score("ground_truth");
    assert!(gt["segments"].as_u64().unwrap() > 0);
    assert!(gt["t_err_percent"].as_f64().unwrap().abs() < 1e-9);
    // the devkit's acos((trace - 1) / 2) resolves angles only to ~1e-8 rad
    assert!(gt["r_err_deg_per_100m"].as_f64().unwrap().abs() < 1e-4);
    assert!(gt["ate_se3_m"].as_f64().unwrap() < 1e-9);
    // every step 3 % too long: t_err is 3 % of chord / segment length (chord <= the segment's
    // ground-truth path, which exceeds the nominal length by less than one step); no rotation
    let scale = score("scale_drift");
    let t = scale["t_err_percent"].as_f64().unwrap();
    assert!((2.0..3.5).contains(&t), "{t}");
    assert!(scale["r_err_deg_per_100m"].as_f64().unwrap() < 1e-4);
    assert!(scale["ate_sim3_m"].as_f64().unwrap() < 1e-6);
    // yaw drift of 0.1 deg a metre = 10 deg/100 m, plus noise
    let yaw = score("yaw_drift_noise");
    let r = yaw["r_err_deg_per_100m"].as_f64().unwrap();
    assert!((7.0..13.0).contains(&r), "{r}");
    for s in scores {
        assert_eq!(s["failed_frames"].as_u64(), Some(0), "{s}");
    }
    assert!(report["failures"].as_array().unwrap().is_empty());
    // stereo VO (RotROCC) on all 50 frames: measured 0.21 % (release); bound 2 %
    let stereo = score("stereo_vo");
    assert_eq!(stereo["frames"].as_u64(), Some(50));
    assert!(stereo["segments"].as_u64().unwrap() > 0);
    let t = stereo["t_err_percent"].as_f64().unwrap();
    assert!(t < 2.0, "stereo t_err {t} %");
    // mono VO on the first 12 frames: measured 7.0 % (scale from the ground plane ~6 % short);
    // bound 10 %
    let mono = score("mono_vo");
    assert_eq!(mono["frames"].as_u64(), Some(12));
    assert!(mono["segments"].as_u64().unwrap() > 0);
    let t = mono["t_err_percent"].as_f64().unwrap();
    assert!(t < 10.0, "mono t_err {t} %");
    let mono_lines = std::fs::read_to_string(out.join("trajectories/mono_vo.txt"))
        .unwrap()
        .lines()
        .count();
    assert_eq!(mono_lines, 12);
    // the loop-closure drive (default 91 frames: its last frame closes the loop)
    let lp = &report["loop_drive"];
    assert_eq!(lp["frames"].as_u64(), Some(91));
    assert_eq!(lp["final_frame"], lp["closing_frame"]);
    let before = lp["final_drift_odometry_m"].as_f64().unwrap();
    let after = lp["final_drift_loop_closure_m"].as_f64().unwrap();
    assert!(after * 5.0 <= before, "loop drive {before} m -> {after} m");
    for f in [
        "sequence/calib.txt",
        "sequence/image_1/000039.png",
        "sequence/flow/000038.flo",
        "trajectories/ground_truth.txt",
        "trajectories/scale_drift.txt",
        "plots/top_scale_drift.png",
        "plots/top_scale_drift.svg",
        "trajectories/stereo_vo.txt",
        "trajectories/mono_vo.txt",
        "plots/top_stereo_vo.png",
        "plots/errors_stereo_vo.svg",
        "plots/top_mono_vo.png",
    ] {
        assert!(out.join(f).exists(), "{f} missing");
    }
}

#[test]
fn demo_rejects_bad_arguments() {
    let dir = tempfile::tempdir().unwrap();
    let err = run_err(
        visnav()
            .args(["demo", "--frames", "1", "--output"])
            .arg(dir.path().join("demo")),
    );
    assert!(err.contains("--frames"));
}

#[test]
fn demo_rejects_mono_frames_beyond_frames() {
    let dir = tempfile::tempdir().unwrap();
    let err = run_err(
        visnav()
            .args(["demo", "--frames", "10", "--mono-frames", "11", "--output"])
            .arg(dir.path().join("demo")),
    );
    assert!(err.contains("--mono-frames"));
}
