//! `visnav demo` renders, scores and plots: the ground truth scores zero, the simulated
//! drifts score what they were built with.
#![allow(clippy::unwrap_used)]

use std::process::Command;

#[test]
fn demo_scores_ground_truth_zero_and_drift_as_built() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo");
    let output = Command::new(env!("CARGO_BIN_EXE_visnav"))
        .args([
            "demo", "--json", "--frames", "40", "--width", "96", "--height", "32", "--output",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
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
    for f in [
        "sequence/calib.txt",
        "sequence/image_1/000039.png",
        "sequence/flow/000038.flo",
        "trajectories/ground_truth.txt",
        "trajectories/scale_drift.txt",
        "plots/top_scale_drift.png",
        "plots/top_scale_drift.svg",
    ] {
        assert!(out.join(f).exists(), "{f} missing");
    }
}

#[test]
fn demo_rejects_bad_arguments() {
    let dir = tempfile::tempdir().unwrap();
    let output = Command::new(env!("CARGO_BIN_EXE_visnav"))
        .args(["demo", "--frames", "1", "--output"])
        .arg(dir.path().join("demo"))
        .output()
        .unwrap();
    assert!(!output.status.success());
    assert!(String::from_utf8_lossy(&output.stderr).contains("--frames"));
}
