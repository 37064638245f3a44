//! Issue 53, "Bad input, round two", at the command line: a truncated JPEG is a skipped frame
//! (and `info --check` says so), numbered frames run in number order, `--threads 2000` is
//! clamped, `visnav report` says when the trajectory holds fewer poses than the run, and
//! `flow-eval` (a missing folder, `--limit 0`) and `odometry --output -` name the cause.
//! SIGTERM and SIGHUP: `cli_interrupt.rs`.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::Path;
use std::process::Stdio;
use std::time::{Duration, Instant};

use common::{run_err, run_ok, synth_sequence, visnav};
use visnav_core::testdata::shared_data;

/// `1.jpg … 10.jpg` made from the first ten KITTI 06 frames, with its camera file; `5.jpg` cut
/// to a third.
fn jpeg_folder_with_a_truncated_frame(kitti06: &Path, dir: &Path) {
    std::fs::create_dir_all(dir).unwrap();
    for i in 0..10 {
        let frame =
            visnav_io::image_io::load_gray(&kitti06.join(format!("image_0/{i:06}.png"))).unwrap();
        let jpg = dir.join(format!("{}.jpg", i + 1));
        visnav_io::image_io::save_gray_jpeg(&frame, &jpg, 90).unwrap();
    }
    let cut = dir.join("5.jpg");
    let bytes = std::fs::read(&cut).unwrap();
    std::fs::write(&cut, &bytes[..bytes.len() / 3]).unwrap();
    std::fs::write(
        dir.join("camera.yaml"),
        "cam0:\n  camera_model: pinhole\n  intrinsics: [707.0912, 707.0912, 601.8873, 183.1104]\n  distortion_model: none\n  resolution: [1226, 370]\nrate_hz: 10\n",
    )
    .unwrap();
}

/// A JPEG cut to a third decoded as a grey-filled frame called `ok`. Now it is a skipped input
/// (its own status, the predicted pose, a warning naming the file) and `info --check` fails on
/// it. The frames are named `1.jpg … 10.jpg`: the truncated `5.jpg` is the fifth frame (index
/// 4), not the sixth as in name order (1, 10, 2, 3, 4, 5, …).
#[test]
fn a_truncated_jpeg_is_a_skipped_frame_in_number_order_and_info_check_fails() {
    let Some(kitti06) = shared_data("kitti/odometry/sequences/06") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let seq = tmp.path().join("frames");
    jpeg_folder_with_a_truncated_frame(&kitti06, &seq);

    let e = run_err(visnav().args(["-q", "info", "--check"]).arg(&seq));
    assert!(e.contains("5.jpg") && e.contains("truncated JPEG"), "{e}");
    assert!(e.contains("1 of 10 frames"), "{e}");
    assert!(e.contains("first: frame 4"), "{e}");

    let out = tmp.path().join("poses.txt");
    let json = tmp.path().join("report.json");
    let run = run_ok(
        visnav()
            .args(["-q", "odometry", "--mode", "mono"])
            .arg(&seq)
            .arg("-o")
            .arg(&out)
            .arg("--json")
            .arg(&json),
    );
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(stderr.contains("truncated JPEG"), "{stderr}");
    assert_eq!(visnav_io::trajectory::read_kitti(&out).unwrap().len(), 10);
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(report["skipped_frames"], 1, "{report}");
    let frames = report["per_frame"].as_array().unwrap();
    let bad = &frames[4];
    assert_eq!(bad["status"], "skipped", "{bad}");
    let reason = bad["reason"].as_str().unwrap();
    assert!(
        reason.contains("5.jpg") && reason.contains("truncated JPEG"),
        "{reason}"
    );
}

/// `--threads 2000` on three frames ran past 60 s; now it is clamped with a warning and the run
/// takes seconds.
#[test]
fn threads_2000_is_clamped_with_a_warning_and_finishes_quickly() {
    let tmp = tempfile::tempdir().unwrap();
    let seq = tmp.path().join("seq");
    synth_sequence(&seq, 3, 160, 48);
    let start = Instant::now();
    let mut child = visnav()
        .args(["-q", "--threads", "2000", "odometry", "--mode", "mono"])
        .arg(&seq)
        .arg("-o")
        .arg(tmp.path().join("poses.txt"))
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > Duration::from_secs(60) {
            child.kill().unwrap();
            panic!("--threads 2000 on three frames still running after 60 s");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains("--threads 2000") && stderr.contains("per core"),
        "{stderr}"
    );
}

/// A run directory whose `poses.txt` holds 2 of the run's 4 frames: the report said "Every
/// frame after the first was estimated"; now the page and a warning say the trajectory is cut.
#[test]
fn report_says_when_the_trajectory_holds_fewer_poses_than_the_run() {
    let tmp = tempfile::tempdir().unwrap();
    let seq = tmp.path().join("seq");
    synth_sequence(&seq, 4, 320, 96);
    let run_dir = tmp.path().join("run");
    let poses = run_dir.join("poses.txt");
    run_ok(
        visnav()
            .args(["-q", "odometry", "--mode", "mono"])
            .arg(&seq)
            .arg("-o")
            .arg(&poses)
            .arg("--report"),
    );
    let text = std::fs::read_to_string(&poses).unwrap();
    let two: String = text.lines().take(2).map(|l| format!("{l}\n")).collect();
    std::fs::write(&poses, two).unwrap();
    let out = run_ok(visnav().args(["-q", "report"]).arg(&run_dir));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("holds 2 poses") && stderr.contains("4 frames"),
        "{stderr}"
    );
    assert!(stderr.contains("the trajectory is cut"), "{stderr}");
    let page = std::fs::read_to_string(run_dir.join("report.html")).unwrap();
    assert!(page.contains("the trajectory is cut: frames 2 to 3"));
    assert!(!page.contains("Every frame after the first was estimated (status ok)"));
}

/// `visnav flow-eval` on a folder that does not exist said "no Middlebury … layout found"; now
/// it says the folder was not found and names it.
#[test]
fn flow_eval_on_a_missing_folder_says_it_was_not_found() {
    let tmp = tempfile::tempdir().unwrap();
    let missing = tmp.path().join("no-such-benchmark");
    let e = run_err(visnav().args(["-q", "flow-eval"]).arg(&missing));
    assert!(
        e.contains("no-such-benchmark") && e.contains("not found"),
        "{e}"
    );
    assert!(!e.contains("layout found"), "{e}");
}

/// `visnav flow-eval DIR --limit 0` evaluated no pair and blamed the dataset ("no image pairs
/// with ground truth"); now `--limit 0` is refused by name.
#[test]
fn flow_eval_limit_0_is_refused_by_name() {
    let tmp = tempfile::tempdir().unwrap();
    // a Middlebury layout (its pairs do not matter: the option is refused before they are read)
    std::fs::create_dir_all(tmp.path().join("other-data")).unwrap();
    let e = run_err(
        visnav()
            .args(["-q", "flow-eval", "--limit", "0"])
            .arg(tmp.path()),
    );
    assert!(e.contains("--limit must be at least 1"), "{e}");
}

/// `visnav odometry … --output -` wrote a file called `-` (and `-.config.toml`); now it is
/// refused before the run with the option named (as are `--json -` and `--output-mcap -`).
#[test]
fn odometry_output_dash_is_refused_by_name() {
    let tmp = tempfile::tempdir().unwrap();
    let seq = tmp.path().join("seq");
    synth_sequence(&seq, 3, 160, 48);
    let e = run_err(
        visnav()
            .current_dir(tmp.path())
            .args(["-q", "odometry", "--mode", "mono"])
            .arg(&seq)
            .args(["--output", "-"]),
    );
    assert!(
        e.contains("--output -") && e.contains("standard output is not supported"),
        "{e}"
    );
    assert!(!tmp.path().join("-").exists());
    let e = run_err(
        visnav()
            .current_dir(tmp.path())
            .args(["-q", "odometry", "--mode", "mono"])
            .arg(&seq)
            .arg("-o")
            .arg(tmp.path().join("poses.txt"))
            .args(["--json", "-"]),
    );
    assert!(e.contains("--json -"), "{e}");
    assert!(!tmp.path().join("poses.txt").exists());
}
