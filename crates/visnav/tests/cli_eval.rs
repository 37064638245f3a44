//! `visnav eval` end to end: devkit numbers in `--json`, plots, and errors for bad files.
#![allow(clippy::unwrap_used)]

use visnav_core::testdata::shared_data;

mod common;
use common::{run_err, run_ok, visnav};

#[test]
fn eval_json_reproduces_the_devkit_and_writes_plots() {
    let Some(root) = shared_data("kitti/odometry") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    // the full ground truth: scored on the common prefix (300 frames) with a warning
    let out = run_ok(
        visnav()
            .arg("eval")
            .arg(root.join("poses/00.txt"))
            .arg(root.join("reference/viso2m_00_first300.txt"))
            .args(["--lengths", "100,200", "--json", "--plot"])
            .arg(dir.path()),
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let t = v["t_err_percent"].as_f64().unwrap();
    let r = v["r_err_deg_per_100m"].as_f64().unwrap();
    assert!(((t - 10.9855) / 10.9855).abs() < 1e-3, "{t}");
    assert!(((r - 3.2061) / 3.2061).abs() < 1e-3, "{r}");
    assert_eq!(v["segments"].as_u64(), Some(18));
    assert!(v["ate_se3_m"].as_f64().unwrap() > v["ate_sim3_m"].as_f64().unwrap());
    assert!(v["rpe"]["trans_rmse_m"].as_f64().unwrap() > 0.0);
    assert!(v["per_length"].is_array() && v["per_speed"].is_array());
    assert_eq!(v["config"]["kitti"]["lengths_m"][1].as_f64(), Some(200.0));
    assert_eq!(v["written"].as_array().unwrap().len(), 5);
    assert!(String::from_utf8_lossy(&out.stderr).contains("scoring the first 300"));
    for f in [
        "top_view.png",
        "top_view.svg",
        "errors_vs_length.png",
        "errors_vs_length.svg",
        "eval_config.json",
    ] {
        assert!(dir.path().join(f).exists(), "{f}");
    }
    // --strict turns the length mismatch into an error
    let out = visnav()
        .arg("eval")
        .arg(root.join("poses/00.txt"))
        .arg(root.join("reference/viso2m_00_first300.txt"))
        .arg("--strict")
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("strict"));
}

#[test]
fn eval_table_on_tum_files() {
    let dir = tempfile::tempdir().unwrap();
    let gt = dir.path().join("gt.tum");
    let est = dir.path().join("est.tum");
    let mut g = String::from("# t tx ty tz qx qy qz qw\n");
    let mut e = String::new();
    for i in 0..200 {
        let t = 0.1 * f64::from(i);
        g.push_str(&format!("{t:.3} 0 0 {} 0 0 0 1\n", f64::from(i)));
        e.push_str(&format!(
            "{:.3} 0 0 {} 0 0 0 1\n",
            t + 0.004,
            1.02 * f64::from(i)
        ));
    }
    std::fs::write(&gt, g).unwrap();
    std::fs::write(&est, e).unwrap();
    let out = run_ok(
        visnav()
            .args(["eval", "--lengths", "50,100", "--json"])
            .arg(&gt)
            .arg(&est),
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["sequences"][0]["association"], "Timestamp");
    let t = v["t_err_percent"].as_f64().unwrap();
    assert!(t > 2.0 && t < 2.1, "{t}");
    let out = visnav().arg("eval").arg(&gt).arg(&est).output().unwrap();
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stdout).contains("t_err [%]"));
}

#[test]
fn eval_bad_inputs_fail_with_a_message_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good.txt");
    std::fs::write(&good, "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1 1\n").unwrap();
    let missing = dir.path().join("missing_est.txt");
    let err = run_err(visnav().arg("eval").arg(&good).arg(&missing));
    assert!(
        err.contains("missing_est.txt") && err.contains("not found"),
        "{err}"
    );
    let bad = dir.path().join("bad.txt");
    std::fs::write(&bad, "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1\n").unwrap();
    let err = run_err(visnav().arg("eval").arg(&good).arg(&bad));
    assert!(err.contains("bad.txt:2"), "{err}");
    let out = visnav()
        .arg("eval")
        .arg(&good)
        .arg(&good)
        .arg(&good)
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("pairs"));
    let out = visnav()
        .args(["eval", "--lengths", "100,-5"])
        .arg(&good)
        .arg(&good)
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("lengths_m"));
}
