//! Issue 21 end to end: `--quiet` keeps warnings, errors do not repeat their cause, bad inputs of
//! `eval`, `flow`, `flow-eval` and `synth` are clear errors instead of wrong numbers or hangs.
#![allow(clippy::unwrap_used)]

use std::path::Path;

mod common;
use common::{run_err, run_ok, visnav};

/// A straight 30-pose KITTI trajectory along z, `scale` times the identity rotation block.
fn kitti_line(n: usize, scale: f64) -> String {
    (0..n)
        .map(|i| format!("{scale} 0 0 0 0 {scale} 0 0 0 0 {scale} {}\n", i as f64))
        .collect()
}

#[test]
fn quiet_keeps_warnings() {
    let dir = tempfile::tempdir().unwrap();
    let gt = dir.path().join("gt.txt");
    let est = dir.path().join("est.txt");
    std::fs::write(&gt, kitti_line(30, 1.0)).unwrap();
    std::fs::write(&est, kitti_line(20, 1.0)).unwrap();
    let out = run_ok(visnav().args(["--quiet", "eval"]).arg(&gt).arg(&est));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("scoring the first 20"), "{stderr}");
    // progress and tables stay silent
    assert!(out.stdout.is_empty());
}

#[test]
fn a_directory_given_as_a_trajectory_is_named_once() {
    let dir = tempfile::tempdir().unwrap();
    let e = run_err(visnav().arg("eval").arg(dir.path()).arg(dir.path()));
    assert!(e.contains("is a directory"), "{e}");
    assert!(!e.contains("os error 21"), "{e}");
}

#[test]
fn eval_rejects_rotation_blocks_that_are_not_rotations() {
    let dir = tempfile::tempdir().unwrap();
    let gt = dir.path().join("gt.txt");
    let est = dir.path().join("est.txt");
    std::fs::write(&gt, kitti_line(30, 1.0)).unwrap();
    for scale in [2.0, 0.0] {
        std::fs::write(&est, kitti_line(30, scale)).unwrap();
        let e = run_err(visnav().arg("eval").arg(&gt).arg(&est));
        assert!(
            e.contains("est.txt:1") && e.contains("not a rotation"),
            "{e}"
        );
    }
    let mut huge = kitti_line(30, 1.0);
    huge.push_str("1 0 0 1e308 0 1 0 0 0 0 1 1.7e308\n");
    std::fs::write(&est, huge).unwrap();
    let e = run_err(
        visnav()
            .arg("eval")
            .arg(&gt)
            .arg(&est)
            .arg("--plot")
            .arg(dir.path().join("p")),
    );
    assert!(e.contains("est.txt:31"), "{e}");
}

/// A flow-eval KITTI layout with two pairs of 48x32 images and ground truth `gt` written by
/// `write_gt(path, index)`.
fn kitti_flow_layout(root: &Path, write_gt: impl Fn(&Path, u32)) {
    let img_dir = root.join("training/image_0");
    let gt_dir = root.join("training/flow_occ");
    std::fs::create_dir_all(&img_dir).unwrap();
    std::fs::create_dir_all(&gt_dir).unwrap();
    for k in 0..2 {
        for (suffix, shift) in [("10", 0), ("11", 1)] {
            let img = image::GrayImage::from_fn(48, 32, |x, y| {
                image::Luma([((x + shift + k) * 37 % 251 + y * 13 % 97) as u8])
            });
            img.save(img_dir.join(format!("{k:06}_{suffix}.png")))
                .unwrap();
        }
        write_gt(&gt_dir.join(format!("{k:06}_10.png")), k);
    }
}

fn gt16(path: &Path, valid: u16) {
    let img = image::ImageBuffer::<image::Rgb<u16>, Vec<u16>>::from_pixel(
        48,
        32,
        image::Rgb([32768 + 64, 32768, valid]),
    );
    image::DynamicImage::ImageRgb16(img).save(path).unwrap();
}

#[test]
fn flow_eval_refuses_missing_eight_bit_and_empty_ground_truth() {
    // one of the two flow_occ files missing: an error naming it, not one pair scored of two
    let dir = tempfile::tempdir().unwrap();
    kitti_flow_layout(dir.path(), |p, k| {
        if k == 0 {
            gt16(p, 1);
        }
    });
    let e = run_err(
        visnav()
            .arg("flow-eval")
            .arg(dir.path())
            .args(["--kitti-gt", "occ"]),
    );
    assert!(
        e.contains("000001_10.png") && e.contains("no ground truth"),
        "{e}"
    );
    // 8-bit ground truth: an error, not decoded as 16-bit
    let dir = tempfile::tempdir().unwrap();
    kitti_flow_layout(dir.path(), |p, _| {
        image::RgbImage::from_pixel(48, 32, image::Rgb([128, 128, 1]))
            .save(p)
            .unwrap();
    });
    let e = run_err(
        visnav()
            .arg("flow-eval")
            .arg(dir.path())
            .args(["--kitti-gt", "occ"]),
    );
    assert!(e.contains("16-bit"), "{e}");
    // no valid pixel anywhere: an error, not a mean EPE of -0.000
    let dir = tempfile::tempdir().unwrap();
    kitti_flow_layout(dir.path(), |p, _| gt16(p, 0));
    let e = run_err(
        visnav()
            .arg("flow-eval")
            .arg(dir.path())
            .args(["--kitti-gt", "occ"]),
    );
    assert!(e.contains("no pair has a valid ground-truth pixel"), "{e}");
}

#[test]
fn flow_fundamental_takes_negative_numbers_and_refuses_nan() {
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("a.png");
    let b = dir.path().join("b.png");
    for (p, s) in [(&a, 0), (&b, 1)] {
        image::GrayImage::from_fn(64, 48, |x, y| {
            image::Luma([((x + s) * 29 % 251 + y * 7 % 53) as u8])
        })
        .save(p)
        .unwrap();
    }
    let out = dir.path().join("f.flo");
    let f = [
        "0", "-1e-6", "0.003", "1e-6", "0", "-0.3", "-0.003", "0.29", "1",
    ];
    run_ok(
        visnav()
            .args(["-q", "flow"])
            .arg(&a)
            .arg(&b)
            .arg("-o")
            .arg(&out)
            .arg("--fundamental")
            .args(f),
    );
    assert!(out.is_file());
    let mut nan = f;
    nan[2] = "NaN";
    let e = run_err(
        visnav()
            .args(["-q", "flow"])
            .arg(&a)
            .arg(&b)
            .arg("-o")
            .arg(&out)
            .arg("--fundamental")
            .args(nan),
    );
    assert!(e.contains("--fundamental") && e.contains("number 3"), "{e}");
}

#[test]
fn synth_along_a_pose_far_away_is_an_error_not_a_hang() {
    let dir = tempfile::tempdir().unwrap();
    let traj = dir.path().join("traj.txt");
    let mut text = kitti_line(3, 1.0);
    text.push_str("1 0 0 0 0 1 0 0 0 0 1 1e8\n");
    std::fs::write(&traj, text).unwrap();
    let e = run_err(
        visnav()
            .args(["-q", "synth", "--out"])
            .arg(dir.path().join("out"))
            .arg("--trajectory")
            .arg(&traj),
    );
    assert!(e.contains("pose 3") && e.contains("limit"), "{e}");
}

/// `report.json` stored the sequence path as typed (relative), so `visnav report` run from
/// another directory lost the gallery: it is stored absolute.
#[test]
fn the_run_report_stores_an_absolute_sequence_path() {
    let dir = tempfile::tempdir().unwrap();
    common::synth_sequence(&dir.path().join("seq"), 4, 160, 48);
    std::fs::create_dir(dir.path().join("run")).unwrap();
    run_ok(
        visnav()
            .current_dir(dir.path())
            .args(["-q", "odometry", "--mode", "mono", "seq"])
            .args(["-o", "run/poses.txt", "--json", "run/report.json"]),
    );
    let text = std::fs::read_to_string(dir.path().join("run/report.json")).unwrap();
    let report: serde_json::Value = serde_json::from_str(&text).unwrap();
    let stored = Path::new(report["sequence"].as_str().unwrap());
    assert!(stored.is_absolute(), "{stored:?}");
    assert_eq!(
        stored.canonicalize().unwrap(),
        dir.path().join("seq").canonicalize().unwrap()
    );
}
