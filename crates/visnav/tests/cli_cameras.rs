//! `visnav odometry` on users' own cameras: the EuRoC sample (stereo and mono, rectified on load,
//! timestamps kept in a TUM output that `visnav eval` matches by timestamp), a synthetic TUM
//! monoVO sequence (FOV lens, JPEG frames, `times.txt`), and `--camera` errors.
#![allow(clippy::unwrap_used)]

use std::path::Path;

use visnav_core::testdata::shared_data;
use visnav_io::trajectory::{read_kitti, read_tum};

mod common;
use common::{run_err, run_ok, synth_sequence, visnav};

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
    let e = run_err(
        visnav()
            .args(["odometry", "--mode", "mono"])
            .arg(&frames)
            .arg("--camera")
            .arg(&cam)
            .arg("--output")
            .arg(dir.path().join("p.txt")),
    );
    assert!(
        e.contains("cam.yaml") && e.contains("needs 4 (k1 k2 k3 k4)"),
        "{e}"
    );
}

/// Writes the frames of a `visnav synth` sequence as a TUM monoVO sequence seen through a FOV
/// lens (ω = 0.5, the synthetic camera's intrinsics): JPEG frames, `times.txt` with absolute
/// timestamps, DSO's `camera.txt` (output `none`: the same pinhole, distortion removed).
fn write_monovo_from_synth(synth: &Path, out: &Path, frames: usize, t0: f64) -> Vec<f64> {
    use nalgebra::Point2;
    use visnav_core::distortion::{CalibratedCamera, Distortion};
    let pinhole = visnav_io::Sequence::open(synth).unwrap().camera;
    let lens = CalibratedCamera {
        pinhole,
        distortion: Distortion::Fov { omega: 0.5 },
    };
    std::fs::create_dir_all(out.join("images")).unwrap();
    let mut times = String::new();
    let mut stamps = Vec::new();
    for i in 0..frames {
        let ideal =
            visnav_io::image_io::load_gray(&synth.join(format!("image_0/{i:06}.png"))).unwrap();
        let raw = visnav_core::GrayImage::from_fn(ideal.width(), ideal.height(), |u, v| {
            let x = lens.undistort_px(&Point2::new(u as f64, v as f64)).unwrap();
            ideal.bilinear_clamped(pinhole.fx * x.x + pinhole.cx, pinhole.fy * x.y + pinhole.cy)
        });
        visnav_io::image_io::save_gray_jpeg(&raw, &out.join(format!("images/{i:05}.jpg")), 95)
            .unwrap();
        let t = t0 + 0.1 * i as f64;
        times.push_str(&format!("{i:05} {t:.6} 10.0\n"));
        stamps.push(t);
    }
    std::fs::write(out.join("times.txt"), times).unwrap();
    std::fs::write(
        out.join("camera.txt"),
        format!(
            "FOV {} {} {} {} 0.5\n{} {}\nnone\n{} {}\n",
            pinhole.fx,
            pinhole.fy,
            pinhole.cx,
            pinhole.cy,
            pinhole.width,
            pinhole.height,
            pinhole.width,
            pinhole.height
        ),
    )
    .unwrap();
    stamps
}

#[test]
fn tum_monovo_mono_keeps_timestamps() {
    const FRAMES: usize = 5;
    let dir = tempfile::tempdir().unwrap();
    let synth = dir.path().join("synth");
    synth_sequence(&synth, FRAMES, 320, 96);
    let seq = dir.path().join("sequence_01");
    let stamps = write_monovo_from_synth(&synth, &seq, FRAMES, 1_383_315_339.120_7);
    let out = dir.path().join("mono.txt");
    run_ok(
        visnav()
            .args(["-q", "odometry", "--mode", "mono", "--camera-height", "1.7"])
            .arg(&seq)
            .arg("--output")
            .arg(&out),
    );
    let poses = read_kitti(&out).unwrap();
    assert_eq!(poses.len(), FRAMES);
    let tum = read_tum(&dir.path().join("mono.tum.txt")).unwrap();
    assert_eq!(tum.poses.len(), FRAMES);
    for (g, w) in tum.timestamps.unwrap().iter().zip(&stamps) {
        assert!((g - w).abs() < 1e-6, "timestamp {g} vs {w}");
    }
    // the undistorted frames give the synthetic drive: forward along +z
    let gt = read_kitti(&synth.join("poses.txt")).unwrap();
    let (est, truth) = (
        poses[FRAMES - 1].translation.vector,
        gt[FRAMES - 1].translation.vector,
    );
    assert!(
        est.z > 0.0 && (est - truth).norm() < 0.3 * truth.norm(),
        "end point {est:?} vs ground truth {truth:?}"
    );
}
