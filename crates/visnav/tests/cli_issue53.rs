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

/// A `left/` + `right/` folder of three small frames with a Kalibr camera file whose stereo
/// translation is `-baseline` metres.
fn stereo_folder(dir: &Path, baseline: &str) {
    for side in ["left", "right"] {
        std::fs::create_dir_all(dir.join(side)).unwrap();
        for i in 0..3 {
            let img =
                visnav_core::GrayImage::from_fn(64, 32, |x, y| ((x * 7 + y * 13 + i) % 256) as f32);
            visnav_io::image_io::save_gray_png(&img, &dir.join(side).join(format!("{i}.png")))
                .unwrap();
        }
    }
    let cam = "  camera_model: pinhole\n  intrinsics: [50, 50, 32, 16]\n  distortion_model: none\n  resolution: [64, 32]\n";
    std::fs::write(
        dir.join("camera.yaml"),
        format!(
            "cam0:\n{cam}cam1:\n{cam}  T_cn_cnm1:\n  - [1, 0, 0, -{baseline}]\n  - [0, 1, 0, 0]\n  - [0, 0, 1, 0]\n  - [0, 0, 0, 1]\n"
        ),
    )
    .unwrap();
}

/// A stereo camera file whose translation is written in millimetres (a 537 m baseline) was read
/// in silence, the run's depths and trajectory 1000× too large; now a warning names the file,
/// the field, the value and the likely unit (Kalibr `T_cn_cnm1`, KITTI `P1`, ORB-SLAM
/// `Camera.bf`). A real baseline gives no warning.
#[test]
fn a_stereo_baseline_in_millimetres_is_named_with_its_field() {
    let tmp = tempfile::tempdir().unwrap();
    let folder = tmp.path().join("mm");
    stereo_folder(&folder, "537");
    let out = run_ok(visnav().args(["-q", "info"]).arg(&folder));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("camera.yaml: cam1.T_cn_cnm1: stereo baseline 537 m is impossible"),
        "{stderr}"
    );
    assert!(stderr.contains("millimetres (0.5370 m)?"), "{stderr}");
    let metres = tmp.path().join("m");
    stereo_folder(&metres, "0.537");
    let out = run_ok(visnav().args(["-q", "info"]).arg(&metres));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("impossible"), "{stderr}");

    // an ORB-SLAM2 settings file whose Camera.bf is baseline (mm) × fx
    let orb = tmp.path().join("orb.yaml");
    std::fs::write(
        &orb,
        "%YAML:1.0\nCamera.fx: 50.0\nCamera.fy: 50.0\nCamera.cx: 32.0\nCamera.cy: 16.0\nCamera.width: 64\nCamera.height: 32\nCamera.bf: 26850.0\n",
    )
    .unwrap();
    let out = run_ok(
        visnav()
            .args(["-q", "info", "--camera"])
            .arg(&orb)
            .arg(&metres),
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("orb.yaml: Camera.bf: stereo baseline 537 m"),
        "{stderr}"
    );

    // KITTI 06's calib.txt with P1 in millimetres
    let Some(kitti06) = shared_data("kitti/odometry/sequences/06") else {
        return;
    };
    let kitti = tmp.path().join("kitti");
    for cam in ["image_0", "image_1"] {
        std::fs::create_dir_all(kitti.join(cam)).unwrap();
        for i in 0..3 {
            let name = format!("{cam}/{i:06}.png");
            std::fs::copy(kitti06.join(&name), kitti.join(&name)).unwrap();
        }
    }
    let calib = std::fs::read_to_string(kitti06.join("calib.txt")).unwrap();
    assert!(calib.contains("-3.798145000000e+02"));
    std::fs::write(
        kitti.join("calib.txt"),
        calib.replace("-3.798145000000e+02", "-3.798145000000e+05"),
    )
    .unwrap();
    let out = run_ok(visnav().args(["-q", "info"]).arg(&kitti));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("calib.txt: P1 (baseline -P1[0][3]/P1[0][0]): stereo baseline"),
        "{stderr}"
    );
    assert!(stderr.contains("millimetres (0.5372 m)?"), "{stderr}");
}

/// As above for the EuRoC layout: cam1's `T_BS` written in millimetres (the EuRoC sample's
/// frames linked, not copied) is named with the file and the field.
#[cfg(unix)]
#[test]
fn a_euroc_sensor_yaml_in_millimetres_is_named_with_its_field() {
    let Some(euroc) = shared_data("euroc/V1_01_easy_first40/mav0") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let mav0 = tmp.path().join("euroc/mav0");
    for cam in ["cam0", "cam1"] {
        std::fs::create_dir_all(mav0.join(cam)).unwrap();
        for f in ["data", "data.csv"] {
            std::os::unix::fs::symlink(euroc.join(cam).join(f), mav0.join(cam).join(f)).unwrap();
        }
    }
    // both cameras' T_BS translations written in millimetres
    for (cam, metres) in [
        (
            "cam0",
            ["-0.0216401454975", "-0.064676986768", "0.00981073058949"],
        ),
        (
            "cam1",
            ["-0.0198435579556", "0.0453689425024", "0.00786212447038"],
        ),
    ] {
        let text = std::fs::read_to_string(euroc.join(cam).join("sensor.yaml")).unwrap();
        let mut mm = text.clone();
        for m in metres {
            let v: f64 = m.parse().unwrap();
            mm = mm.replace(m, &format!("{}", v * 1000.0));
        }
        assert_ne!(mm, text);
        std::fs::write(mav0.join(cam).join("sensor.yaml"), mm).unwrap();
    }
    let out = run_ok(visnav().args(["-q", "info"]).arg(tmp.path().join("euroc")));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr
            .contains("cam1/sensor.yaml: T_BS (with cam0's: the stereo baseline): stereo baseline"),
        "{stderr}"
    );
    assert!(
        stderr.contains("stereo baseline 110.0778 m") && stderr.contains("millimetres (0.1101 m)"),
        "{stderr}"
    );
}

/// A TUM ground truth whose lines are out of time order was half-matched in silence by the
/// timestamp association (19 of EuRoC's 40 poses, "scoring those"); now its poses are sorted,
/// with a note naming the file and the first line out of order, and all 40 are scored. Two
/// poses at one timestamp are an error naming both lines.
#[test]
fn tum_ground_truth_out_of_time_order_is_sorted_with_a_note() {
    let Some(gt) = shared_data("euroc/V1_01_easy_first40/groundtruth_body_tum.txt") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(&gt).unwrap();
    let mut lines: Vec<&str> = text.lines().collect();
    let header = lines.remove(0);
    assert!(header.starts_with('#'));
    // the odd lines first, then the even ones
    let shuffled: Vec<&str> = std::iter::once(header)
        .chain(lines.iter().step_by(2).copied())
        .chain(lines.iter().skip(1).step_by(2).copied())
        .collect();
    let unsorted = tmp.path().join("unsorted_gt.txt");
    std::fs::write(&unsorted, shuffled.join("\n") + "\n").unwrap();
    let eval = |gt: &Path| {
        let out = run_ok(
            visnav()
                .args(["-q", "eval", "--json", "--lengths", "0.001"])
                .arg(gt)
                .arg(gt_copy(&text, tmp.path())),
        );
        let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        (json, String::from_utf8_lossy(&out.stderr).into_owned())
    };
    let (sorted, _) = eval(&gt);
    let (json, stderr) = eval(&unsorted);
    assert_eq!(json["sequences"][0]["scored_poses"], 40, "{stderr}");
    assert_eq!(json["rpe"], sorted["rpe"]);
    assert!(
        stderr.contains("unsorted_gt.txt:22: timestamps are not in time order"),
        "{stderr}"
    );
    let twice = tmp.path().join("twice.txt");
    std::fs::write(&twice, format!("{}\n{}\n", lines[0], lines[0])).unwrap();
    let e = run_err(visnav().args(["-q", "eval"]).arg(&twice).arg(&twice));
    assert!(
        e.contains("twice.txt:2: the timestamp") && e.contains("of line 1 again"),
        "{e}"
    );
}

/// The ground truth's text as the estimate (a copy, so that only the ground truth is shuffled).
fn gt_copy(text: &str, dir: &Path) -> std::path::PathBuf {
    let p = dir.join("estimate.txt");
    std::fs::write(&p, text).unwrap();
    p
}

/// A symbolic link loop where an input is read was "not found" (a folder's `camera.yaml`, the
/// flow's image, a report's run directory) or ignored in silence (KITTI `times.txt`: 10 Hz
/// assumed); now each is named as a symlink loop.
#[cfg(unix)]
#[test]
fn a_symlink_loop_is_named_as_one() {
    use std::os::unix::fs::symlink;
    let tmp = tempfile::tempdir().unwrap();
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    symlink(&b, &a).unwrap();
    symlink(&a, &b).unwrap();
    let is_loop = |e: &str, name: &str| {
        assert!(
            e.contains(name) && e.contains("symlink loop"),
            "{name}: {e}"
        );
    };

    let folder = tmp.path().join("folder");
    stereo_folder(&folder, "0.5");
    std::fs::remove_file(folder.join("camera.yaml")).unwrap();
    symlink(&a, folder.join("camera.yaml")).unwrap();
    is_loop(
        &run_err(visnav().args(["-q", "info"]).arg(&folder)),
        "camera.yaml",
    );
    is_loop(
        &run_err(
            visnav()
                .args(["-q", "info", "--camera"])
                .arg(&a)
                .arg(&folder),
        ),
        "a",
    );

    let seq = tmp.path().join("seq");
    synth_sequence(&seq, 3, 160, 48);
    std::fs::remove_file(seq.join("times.txt")).unwrap();
    symlink(&a, seq.join("times.txt")).unwrap();
    is_loop(
        &run_err(visnav().args(["-q", "info"]).arg(&seq)),
        "times.txt",
    );

    is_loop(
        &run_err(visnav().args(["-q", "report"]).arg(&a)),
        "run directory",
    );
    is_loop(
        &run_err(
            visnav()
                .args(["-q", "flow"])
                .arg(&a)
                .arg(&a)
                .arg("-o")
                .arg(tmp.path().join("x.flo")),
        ),
        "a",
    );
    is_loop(
        &run_err(
            visnav()
                .args(["-q", "odometry", "--mode", "mono"])
                .arg(&a)
                .arg("-o")
                .arg(tmp.path().join("p.txt")),
        ),
        "a",
    );
}

/// An output file the user made read-only was replaced by the atomic write's rename (which
/// needs only the folder's permission), after the whole run; now the run is refused before it
/// starts, naming the file, and the file is kept. `visnav batch` checks its outputs likewise.
#[test]
fn a_read_only_output_file_is_refused_before_the_run() {
    let tmp = tempfile::tempdir().unwrap();
    let seq = tmp.path().join("seq");
    synth_sequence(&seq, 3, 160, 48);
    let read_only = |p: &Path| {
        let mut perms = std::fs::metadata(p).unwrap().permissions();
        perms.set_readonly(true);
        std::fs::set_permissions(p, perms).unwrap();
    };
    let poses = tmp.path().join("poses.txt");
    std::fs::write(&poses, "kept\n").unwrap();
    read_only(&poses);
    let e = run_err(
        visnav()
            .args(["-q", "odometry", "--mode", "mono"])
            .arg(&seq)
            .arg("-o")
            .arg(&poses),
    );
    assert!(e.contains("poses.txt") && e.contains("read-only"), "{e}");
    assert_eq!(std::fs::read_to_string(&poses).unwrap(), "kept\n");
    // refused before the run: no journal, no configuration
    assert!(!tmp.path().join("poses.txt.partial").exists());
    assert!(!tmp.path().join("poses.config.toml").exists());

    let json = tmp.path().join("report.json");
    std::fs::write(&json, "{}\n").unwrap();
    read_only(&json);
    let e = run_err(
        visnav()
            .args(["-q", "odometry", "--mode", "mono"])
            .arg(&seq)
            .arg("-o")
            .arg(tmp.path().join("other.txt"))
            .arg("--json")
            .arg(&json),
    );
    assert!(e.contains("--json") && e.contains("read-only"), "{e}");
    assert!(!tmp.path().join("other.txt").exists());

    let out = tmp.path().join("run");
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("poses.txt"), "kept\n").unwrap();
    read_only(&out.join("poses.txt"));
    let manifest = tmp.path().join("runs.jsonl");
    std::fs::write(
        &manifest,
        "{\"sequence\": \"seq\", \"mode\": \"mono\", \"output\": \"run\"}\n",
    )
    .unwrap();
    let e = run_err(
        visnav()
            .args(["-q", "batch"])
            .arg(&manifest)
            .args(["--index", "0"]),
    );
    assert!(e.contains("poses.txt") && e.contains("read-only"), "{e}");
    assert_eq!(
        std::fs::read_to_string(out.join("poses.txt")).unwrap(),
        "kept\n"
    );
    assert!(!out.join("report.json").exists());

    // `visnav flow`: a read-only `--information` file is refused before the flow is computed
    // (before, the flow was computed and `-o` written, then the information refused)
    let information = tmp.path().join("pair.pfm");
    std::fs::write(&information, "kept\n").unwrap();
    read_only(&information);
    let flo = tmp.path().join("pair.flo");
    let pictures = tmp.path().join("pictures");
    let e = run_err(
        visnav()
            .args(["-q", "flow", "--method", "fast"])
            .arg(seq.join("image_0/000000.png"))
            .arg(seq.join("image_0/000001.png"))
            .arg("-o")
            .arg(&flo)
            .arg("--information")
            .arg(&information)
            .arg("--visualize")
            .arg(&pictures),
    );
    assert!(e.contains("pair.pfm") && e.contains("read-only"), "{e}");
    assert_eq!(std::fs::read_to_string(&information).unwrap(), "kept\n");
    assert!(!flo.exists() && !pictures.exists());
}

/// Issue 53 item 7, end to end: KITTI 06's frames as a `left/` + `right/` folder with an ORB-SLAM2
/// settings file (the `KITTI04-12.yaml` form: `Camera.fx …`, `Camera.bf` = baseline × fx) give
/// the stereo trajectory of the KITTI layout byte for byte; before, the file was refused
/// ("unknown field `Camera.fx`").
#[test]
fn kitti_06_with_an_orb_slam2_settings_file_gives_the_kitti_trajectory() {
    let Some(kitti06) = shared_data("kitti/odometry/sequences/06") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let folder = tmp.path().join("k06");
    for (cam, side) in [("image_0", "left"), ("image_1", "right")] {
        std::fs::create_dir_all(folder.join(side)).unwrap();
        for i in 0..10 {
            let name = format!("{i:06}.png");
            std::fs::copy(kitti06.join(cam).join(&name), folder.join(side).join(&name)).unwrap();
        }
    }
    std::fs::write(
        folder.join("camera.yaml"),
        "%YAML:1.0\n\n# Camera calibration and distortion parameters (OpenCV)\nCamera.type: \"PinHole\"\nCamera.fx: 707.0912\nCamera.fy: 707.0912\nCamera.cx: 601.8873\nCamera.cy: 183.1104\n\nCamera.k1: 0.0\nCamera.k2: 0.0\nCamera.p1: 0.0\nCamera.p2: 0.0\n\nCamera.width: 1226\nCamera.height: 370\n\n# Camera frames per second\nCamera.fps: 10.0\n\n# stereo baseline times fx\nCamera.bf: 379.8145\n\nThDepth: 35.0\nORBextractor.nFeatures: 2000\nViewer.PointSize:2\n",
    )
    .unwrap();
    let (a, b) = (tmp.path().join("folder.txt"), tmp.path().join("kitti.txt"));
    for (input, out) in [(&folder, &a), (&kitti06, &b)] {
        run_ok(
            visnav()
                .args(["-q", "odometry", "--mode", "stereo", "--max-frames", "10"])
                .arg(input)
                .arg("-o")
                .arg(out),
        );
    }
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
}
