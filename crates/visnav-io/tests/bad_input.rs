//! Bad input gives a clear error naming what is wrong, never a panic.
#![allow(clippy::unwrap_used)]

use std::path::Path;

use visnav_core::GrayImage;
use visnav_io::image_io::save_gray_png;
use visnav_io::trajectory::{read_kitti, read_trajectory};
use visnav_io::{IoError, Sequence};

const CALIB: &str = "P0: 718.856 0 607.1928 0 0 718.856 185.2157 0 0 0 1 0
P1: 718.856 0 607.1928 -386.1448 0 718.856 185.2157 0 0 0 1 0
";

fn img(w: usize, h: usize) -> GrayImage {
    GrayImage::from_fn(w, h, |x, y| ((x + 3 * y) % 256) as f32)
}

/// An odometry sequence with `n` stereo frames of 16x8.
fn make_odometry(root: &Path, n: usize) {
    for cam in ["image_0", "image_1"] {
        std::fs::create_dir_all(root.join(cam)).unwrap();
        for i in 0..n {
            save_gray_png(&img(16, 8), &root.join(cam).join(format!("{i:06}.png"))).unwrap();
        }
    }
    std::fs::write(root.join("calib.txt"), CALIB).unwrap();
    let times: String = (0..n).map(|i| format!("{:e}\n", 0.1 * i as f64)).collect();
    std::fs::write(root.join("times.txt"), times).unwrap();
}

#[test]
fn a_good_sequence_opens() {
    let dir = tempfile::tempdir().unwrap();
    make_odometry(dir.path(), 3);
    let seq = Sequence::open(dir.path()).unwrap();
    assert_eq!(seq.len(), 3);
    assert!(seq.has_stereo());
    assert!((seq.baseline_m.unwrap() - 386.1448 / 718.856).abs() < 1e-12);
}

/// `P1`'s principal point column enters the rig (a disparity offset, not dropped silently);
/// a `P1` whose rows or focal lengths differ from `P0`'s is no rectified pair: an error naming
/// the file.
#[test]
fn the_right_principal_point_reaches_the_rig_and_unrectified_p1_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    make_odometry(dir.path(), 2);
    let calib = dir.path().join("calib.txt");
    let p1 = |fx: &str, cx: &str, cy: &str| {
        format!(
            "P0: 718.856 0 607.1928 0 0 718.856 185.2157 0 0 0 1 0\nP1: {fx} 0 {cx} -386.1448 0 {fx} {cy} 0 0 0 1 0\n"
        )
    };
    std::fs::write(&calib, p1("718.856", "609.1928", "185.2157")).unwrap();
    let seq = Sequence::open(dir.path()).unwrap();
    let rig = seq.stereo_camera().unwrap();
    assert!((rig.right_cx_offset_px - 2.0).abs() < 1e-9, "{rig:?}");
    // a point 10 m ahead: its disparity is f b / z minus the offset
    let p = nalgebra::Point3::new(0.0, 0.0, 10.0);
    let (l, r) = (
        rig.left.project(&p).unwrap(),
        rig.project_right(&p).unwrap(),
    );
    assert!((rig.depth_from_disparity(l.x - r.x).unwrap() - 10.0).abs() < 1e-9);
    for (text, what) in [
        (p1("718.856", "607.1928", "190.0"), "not aligned"),
        (p1("700.0", "607.1928", "185.2157"), "focal lengths"),
    ] {
        std::fs::write(&calib, text).unwrap();
        let msg = Sequence::open(dir.path()).unwrap_err().to_string();
        assert!(msg.contains("calib.txt") && msg.contains(what), "{msg}");
    }
}

#[test]
fn missing_directory() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("sequences/99");
    let e = Sequence::open(&missing).unwrap_err();
    assert!(matches!(e, IoError::NotFound { .. }));
    let msg = e.to_string();
    assert!(
        msg.contains("sequences/99") && msg.contains("not found"),
        "{msg}"
    );
}

#[test]
fn directory_that_is_no_sequence() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("readme.txt"), "hello").unwrap();
    let msg = Sequence::open(dir.path()).unwrap_err().to_string();
    assert!(msg.contains("KITTI sequence"), "{msg}");
}

#[test]
fn missing_calib() {
    let dir = tempfile::tempdir().unwrap();
    make_odometry(dir.path(), 2);
    std::fs::remove_file(dir.path().join("calib.txt")).unwrap();
    let msg = Sequence::open(dir.path()).unwrap_err().to_string();
    assert!(
        msg.contains("calib.txt") && msg.contains("not found"),
        "{msg}"
    );
}

#[test]
fn malformed_calib_line() {
    let dir = tempfile::tempdir().unwrap();
    make_odometry(dir.path(), 2);
    std::fs::write(
        dir.path().join("calib.txt"),
        "P0: 718.856 0 607.1928 0 0 718.856 185.2157 0 0 0 1 0\nP1: 718.856 0 607.1928\n",
    )
    .unwrap();
    let msg = Sequence::open(dir.path()).unwrap_err().to_string();
    assert!(
        msg.contains("calib.txt:2") && msg.contains("expected 12 numbers"),
        "{msg}"
    );
    std::fs::write(dir.path().join("calib.txt"), "this is not a calibration\n").unwrap();
    let msg = Sequence::open(dir.path()).unwrap_err().to_string();
    assert!(msg.contains("calib.txt:1") && msg.contains("KEY"), "{msg}");
}

#[test]
fn malformed_times_line() {
    let dir = tempfile::tempdir().unwrap();
    make_odometry(dir.path(), 2);
    std::fs::write(dir.path().join("times.txt"), "0.0\nabc\n").unwrap();
    let msg = Sequence::open(dir.path()).unwrap_err().to_string();
    assert!(msg.contains("times.txt:2"), "{msg}");
}

#[test]
fn malformed_pose_line_names_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("poses.txt");
    std::fs::write(
        &p,
        "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0.5 0 1 0 0 0 0 1 0\n1 0 0 1 0 1 0 zero 0 0 1 0\n",
    )
    .unwrap();
    let msg = read_kitti(&p).unwrap_err().to_string();
    assert!(
        msg.contains("poses.txt:3") && msg.contains("'zero'"),
        "{msg}"
    );
    let msg = read_trajectory(&p).unwrap_err().to_string();
    assert!(msg.contains("poses.txt:3"), "{msg}");
    let msg = read_trajectory(&dir.path().join("nope.txt"))
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("nope.txt") && msg.contains("not found"),
        "{msg}"
    );
}

#[test]
fn unreadable_png() {
    let dir = tempfile::tempdir().unwrap();
    make_odometry(dir.path(), 3);
    let bad = dir.path().join("image_0/000001.png");
    std::fs::write(&bad, b"\x89PNG but truncated").unwrap();
    let seq = Sequence::open(dir.path()).unwrap();
    assert!(seq.load_left(0).is_ok());
    let e = seq.load_left(1).unwrap_err();
    assert!(matches!(e, IoError::Image { .. }));
    assert!(e.to_string().contains("000001.png"), "{e}");
    // an unreadable first frame fails at open time, naming the file
    let first = dir.path().join("image_0/000000.png");
    std::fs::write(&first, b"").unwrap();
    let msg = Sequence::open(dir.path()).unwrap_err().to_string();
    assert!(msg.contains("000000.png"), "{msg}");
}

#[test]
fn frames_of_different_sizes() {
    let dir = tempfile::tempdir().unwrap();
    make_odometry(dir.path(), 3);
    save_gray_png(&img(20, 8), &dir.path().join("image_1/000002.png")).unwrap();
    let seq = Sequence::open(dir.path()).unwrap();
    assert!(seq.load_right(1).is_ok());
    let e = seq.load_right(2).unwrap_err();
    let msg = e.to_string();
    assert!(matches!(
        e,
        IoError::SizeMismatch {
            got_w: 20,
            expected_w: 16,
            ..
        }
    ));
    assert!(
        msg.contains("000002.png") && msg.contains("20x8") && msg.contains("16x8"),
        "{msg}"
    );
}

#[test]
fn empty_sequence() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(dir.path().join("image_0")).unwrap();
    std::fs::write(dir.path().join("calib.txt"), CALIB).unwrap();
    let e = Sequence::open(dir.path()).unwrap_err();
    assert!(matches!(e, IoError::EmptySequence { .. }), "{e}");
    assert!(e.to_string().contains("no frames"));
}

#[test]
fn more_frames_than_timestamps() {
    let dir = tempfile::tempdir().unwrap();
    make_odometry(dir.path(), 3);
    std::fs::write(dir.path().join("times.txt"), "0.0\n0.1\n").unwrap();
    let msg = Sequence::open(dir.path()).unwrap_err().to_string();
    assert!(msg.contains("2 timestamps for 3 frames"), "{msg}");
}
