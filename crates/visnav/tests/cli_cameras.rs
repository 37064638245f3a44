//! `visnav odometry` on users' own cameras: the EuRoC sample (stereo and mono, rectified on load,
//! timestamps kept in a TUM output that `visnav eval` matches by timestamp), and `--camera` errors.
#![allow(clippy::unwrap_used)]

use std::path::Path;
use std::process::Command;

use visnav_core::testdata::shared_data;
use visnav_io::trajectory::{read_kitti, read_tum};

fn visnav() -> Command {
    Command::new(env!("CARGO_BIN_EXE_visnav"))
}

/// The first `n` image timestamps of the EuRoC sample, seconds.
fn euroc_timestamps(root: &Path, n: usize) -> Vec<f64> {
    let csv = std::fs::read_to_string(root.join("mav0/cam0/data.csv")).unwrap();
    csv.lines()
        .filter(|l| !l.starts_with('#'))
        .take(n)
        .map(|l| l.split(',').next().unwrap().parse::<u64>().unwrap() as f64 * 1e-9)
        .collect()
}

/// Runs odometry and checks one pose per frame in both outputs, with the image timestamps, and
/// that `visnav eval` matches the TUM output to the ground truth by timestamp.
fn run_and_check(root: &Path, mode: &str, frames: usize) {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join(format!("{mode}.txt"));
    let run = visnav()
        .args(["-q", "odometry", "--mode", mode, "--max-frames"])
        .arg(frames.to_string())
        .arg(root)
        .arg("--output")
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{mode}: {}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert_eq!(read_kitti(&out).unwrap().len(), frames);
    let tum_path = dir.path().join(format!("{mode}.tum.txt"));
    let tum = read_tum(&tum_path).unwrap();
    assert_eq!(tum.poses.len(), frames);
    let want = euroc_timestamps(root, frames);
    let got = tum.timestamps.unwrap();
    for (g, w) in got.iter().zip(&want) {
        assert!((g - w).abs() < 1e-6, "timestamp {g} vs {w}");
    }
    // the drone barely moves in these frames: the estimate must stay within 0.5 m of the start
    let far = tum
        .poses
        .iter()
        .map(|p| p.translation.vector.norm())
        .fold(0.0, f64::max);
    assert!(far < 0.5, "{mode}: {far} m from the start");
    let eval = visnav()
        .args(["eval", "--json", "--lengths", "0.01"])
        .arg(root.join("groundtruth_body_tum.txt"))
        .arg(&tum_path)
        .output()
        .unwrap();
    assert!(
        eval.status.success(),
        "eval: {}",
        String::from_utf8_lossy(&eval.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&eval.stdout).unwrap();
    assert_eq!(v["sequences"][0]["association"], "Timestamp", "{v}");
    // the same ground truth as EuRoC's own CSV (`state_groundtruth_estimate0/data.csv`: ns stamps,
    // scalar-first quaternion, 17 columns) scores the estimate identically
    let gt = read_tum(&root.join("groundtruth_body_tum.txt")).unwrap();
    let mut csv = String::from(
        "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], v_RS_R_z [m s^-1], b_w_RS_S_x [rad s^-1], b_w_RS_S_y [rad s^-1], b_w_RS_S_z [rad s^-1], b_a_RS_S_x [m s^-2], b_a_RS_S_y [m s^-2], b_a_RS_S_z [m s^-2]\n",
    );
    for (p, t) in gt.poses.iter().zip(gt.timestamps.as_deref().unwrap()) {
        let (tr, q) = (p.translation.vector, p.rotation.quaternion());
        csv.push_str(&format!(
            "{},{},{},{},{},{},{},{},0,0,0,0,0,0,0,0,0\n",
            (t * 1e9).round() as u64,
            tr.x,
            tr.y,
            tr.z,
            q.w,
            q.i,
            q.j,
            q.k
        ));
    }
    let csv_path = dir.path().join("data.csv");
    std::fs::write(&csv_path, csv).unwrap();
    let eval_csv = visnav()
        .args(["eval", "--json", "--lengths", "0.01"])
        .arg(&csv_path)
        .arg(&tum_path)
        .output()
        .unwrap();
    assert!(
        eval_csv.status.success(),
        "eval (EuRoC CSV): {}",
        String::from_utf8_lossy(&eval_csv.stderr)
    );
    let w: serde_json::Value = serde_json::from_slice(&eval_csv.stdout).unwrap();
    assert_eq!(w["sequences"][0]["association"], "Timestamp", "{w}");
    assert_eq!(
        v["sequences"][0]["scored_poses"], w["sequences"][0]["scored_poses"],
        "{v}\n{w}"
    );
    match (v["ate_se3_m"].as_f64(), w["ate_se3_m"].as_f64()) {
        (Some(a), Some(b)) => {
            assert!(
                (a - b).abs() < 1e-6,
                "ATE with TUM ground truth {a} vs EuRoC CSV {b}"
            );
        }
        (a, b) => assert_eq!(a, b, "ATE with TUM vs EuRoC CSV ground truth"),
    }
}

#[test]
fn euroc_sample_stereo_and_mono_keep_timestamps() {
    let Some(root) = shared_data("euroc/V1_01_easy_first40") else {
        return;
    };
    run_and_check(&root, "stereo", 40);
    // mono: dense flow takes about 2 s a pair, so only the first frames
    run_and_check(&root, "mono", 4);
}

#[test]
fn camera_file_errors_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let frames = dir.path().join("frames");
    std::fs::create_dir_all(&frames).unwrap();
    let img = visnav_core::GrayImage::from_fn(32, 24, |x, y| (x * 7 + y * 3) as f32);
    visnav_io::image_io::save_gray_png(&img, &frames.join("0000.png")).unwrap();
    let cam = dir.path().join("cam.yaml");
    std::fs::write(
        &cam,
        "cam0:\n  camera_model: pinhole\n  intrinsics: [30.0, 30.0, 15.5, 11.5]\n  distortion_model: equidistant\n  distortion_coeffs: [0.01, 0.0]\n  resolution: [32, 24]\n",
    )
    .unwrap();
    let out = visnav()
        .args(["odometry", "--mode", "mono"])
        .arg(&frames)
        .arg("--camera")
        .arg(&cam)
        .arg("--output")
        .arg(dir.path().join("p.txt"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(
        e.contains("cam.yaml") && e.contains("needs 4 (k1 k2 k3 k4)"),
        "{e}"
    );
}
