//! `visnav posegraph` end to end: a synthetic loop drive written as g2o, optimised by the CLI;
//! the JSON report, the output graph and the error message for a malformed file are checked.
#![allow(clippy::unwrap_used)]

use visnav_graph::synthetic::{LoopDriveConfig, ate_and_extent, loop_drive};

mod common;
use common::{run_err, run_ok, visnav};

#[test]
fn optimises_a_synthetic_loop_and_reports_json() {
    let dir = tempfile::tempdir().unwrap();
    let synth = loop_drive(&LoopDriveConfig::default());
    let input = dir.path().join("loop.g2o");
    let output = dir.path().join("loop-opt.g2o");
    visnav_graph::write_g2o(&input, &synth.graph).unwrap();
    let out = run_ok(
        visnav()
            .args(["--quiet", "posegraph"])
            .arg(&input)
            .arg("--output")
            .arg(&output)
            .args(["--json", "--max-iterations", "50"]),
    );
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let before = report["objective_before"]["gtsam_error"].as_f64().unwrap();
    let after = report["objective_after"]["gtsam_error"].as_f64().unwrap();
    let chi2 = report["objective_after"]["chi2"].as_f64().unwrap();
    assert!(after < 0.01 * before, "{after} vs {before}");
    assert!((chi2 - 2.0 * after).abs() < 1e-9 * chi2.max(1.0));
    assert!(report["iterations"].as_u64().unwrap() >= 1);
    assert_eq!(report["vertices"].as_u64().unwrap(), 200);
    assert!(report["timing"]["solve_ms"].as_f64().unwrap() > 0.0);

    // The written graph holds the optimised poses: its objective is the reported one and the
    // trajectory is closer to the truth than the odometry.
    let optimised = visnav_graph::read_g2o(&output).unwrap();
    assert_eq!(optimised.edges.len(), synth.graph.edges.len());
    let reread = optimised.objective().gtsam_error;
    assert!(
        (reread - after).abs() <= 1e-9 * after.max(1.0),
        "{reread} vs {after}"
    );
    let (ate_odo, _) = ate_and_extent(&synth.graph.poses(), &synth.ground_truth);
    let (ate_opt, _) = ate_and_extent(&optimised.poses(), &synth.ground_truth);
    assert!(ate_opt < 0.5 * ate_odo);
    assert!(output.with_extension("config.toml").exists());
}

#[test]
fn reports_file_and_line_of_a_malformed_graph() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("bad.g2o");
    std::fs::write(
        &input,
        "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\nVERTEX_SE3:QUAT 1 0 0 0 0 0 0\n",
    )
    .unwrap();
    let stderr = run_err(
        visnav()
            .arg("posegraph")
            .arg(&input)
            .arg("--output")
            .arg(dir.path().join("out.g2o")),
    );
    assert!(stderr.contains("bad.g2o:2:"), "{stderr}");
    assert!(stderr.contains("expected 8 fields"), "{stderr}");
}
