//! KITTI raw drive layout opened through `Sequence::open`, on small generated directories.
#![allow(clippy::unwrap_used)]

use std::path::Path;

use visnav_core::GrayImage;
use visnav_io::image_io::save_gray_png;
use visnav_io::{Sequence, SequenceLayout};

const CALIB: &str = "calib_time: 09-Jan-2012 13:57:47
corner_dist: 9.950000e-02
S_00: 1.392000e+03 5.120000e+02
K_00: 9.842439e+02 0.000000e+00 6.900000e+02 0.000000e+00 9.808141e+02 2.331966e+02 0.000000e+00 0.000000e+00 1.000000e+00
S_rect_00: 1.242000e+03 3.750000e+02
P_rect_00: 7.215377e+02 0.000000e+00 6.095593e+02 0.000000e+00 0.000000e+00 7.215377e+02 1.728540e+02 0.000000e+00 0.000000e+00 0.000000e+00 1.000000e+00 0.000000e+00
P_rect_01: 7.215377e+02 0.000000e+00 6.095593e+02 -3.875744e+02 0.000000e+00 7.215377e+02 1.728540e+02 0.000000e+00 0.000000e+00 0.000000e+00 1.000000e+00 0.000000e+00
";

fn frame(i: usize, w: usize, h: usize) -> GrayImage {
    GrayImage::from_fn(w, h, |x, y| ((x * 7 + y * 13 + i * 29) % 256) as f32)
}

/// Writes a raw drive `<date>/<date>_drive_0001_sync` with `n` frames of `w`x`h`.
fn make_raw_drive(base: &Path, n: usize, stereo: bool) -> std::path::PathBuf {
    let date = base.join("2011_09_26");
    let drive = date.join("2011_09_26_drive_0001_sync");
    std::fs::create_dir_all(&drive).unwrap();
    std::fs::write(date.join("calib_cam_to_cam.txt"), CALIB).unwrap();
    let cams: &[&str] = if stereo {
        &["image_00", "image_01"]
    } else {
        &["image_00"]
    };
    for cam in cams {
        let data = drive.join(cam).join("data");
        std::fs::create_dir_all(&data).unwrap();
        let mut stamps = String::new();
        for i in 0..n {
            save_gray_png(&frame(i, 24, 10), &data.join(format!("{i:010}.png"))).unwrap();
            stamps.push_str(&format!(
                "2011-09-26 13:02:{:012.9}\n",
                25.0 + 0.1037 * i as f64
            ));
        }
        std::fs::write(drive.join(cam).join("timestamps.txt"), stamps).unwrap();
    }
    drive
}

#[test]
fn raw_stereo_drive_opens_with_rectified_calibration() {
    let dir = tempfile::tempdir().unwrap();
    let drive = make_raw_drive(dir.path(), 4, true);
    let seq = Sequence::open(&drive).unwrap();
    assert_eq!(seq.layout, SequenceLayout::KittiRaw);
    assert_eq!(seq.len(), 4);
    assert!(seq.has_stereo());
    assert!((seq.camera.fx - 721.5377).abs() < 1e-9);
    assert!((seq.camera.cy - 172.854).abs() < 1e-9);
    assert_eq!((seq.camera.width, seq.camera.height), (24, 10));
    let b = seq.baseline_m.unwrap();
    assert!((b - 387.5744 / 721.5377).abs() < 1e-12, "{b}");
    assert!((seq.timestamps[0]).abs() < 1e-12);
    assert!((seq.timestamps[3] - 3.0 * 0.1037).abs() < 1e-6);
    assert_eq!(seq.load_left(2).unwrap(), frame(2, 24, 10));
    assert_eq!(seq.load_right(3).unwrap(), frame(3, 24, 10));
    assert!(seq.left_path(1).ends_with("image_00/data/0000000001.png"));
}

#[test]
fn raw_mono_drive_has_no_stereo() {
    let dir = tempfile::tempdir().unwrap();
    let drive = make_raw_drive(dir.path(), 2, false);
    let seq = Sequence::open(&drive).unwrap();
    assert!(!seq.has_stereo());
    assert!(seq.load_right(0).is_err());
}

#[test]
fn raw_drive_errors() {
    let dir = tempfile::tempdir().unwrap();
    let drive = make_raw_drive(dir.path(), 2, true);
    // missing calibration beside the drive
    let calib = drive.parent().unwrap().join("calib_cam_to_cam.txt");
    std::fs::remove_file(&calib).unwrap();
    let e = Sequence::open(&drive).unwrap_err().to_string();
    assert!(e.contains("calib_cam_to_cam.txt"), "{e}");
    // calibration without P_rect_00
    std::fs::write(&calib, "calib_time: 09-Jan-2012 13:57:47\n").unwrap();
    let e = Sequence::open(&drive).unwrap_err().to_string();
    assert!(e.contains("P_rect_00"), "{e}");
    // malformed P_rect_01
    std::fs::write(&calib, CALIB.replace("-3.875744e+02", "x")).unwrap();
    let e = Sequence::open(&drive).unwrap_err().to_string();
    assert!(e.contains("calib_cam_to_cam.txt:7"), "{e}");
    // malformed timestamp
    std::fs::write(&calib, CALIB).unwrap();
    std::fs::write(drive.join("image_00/timestamps.txt"), "yesterday\n").unwrap();
    let e = Sequence::open(&drive).unwrap_err().to_string();
    assert!(e.contains("timestamps.txt:1"), "{e}");
    // different numbers of left and right frames
    std::fs::remove_file(drive.join("image_00/timestamps.txt")).unwrap();
    std::fs::remove_file(drive.join("image_01/data/0000000001.png")).unwrap();
    let e = Sequence::open(&drive).unwrap_err().to_string();
    assert!(e.contains("1 right images but 2 left images"), "{e}");
    // empty left folder
    std::fs::remove_dir_all(drive.join("image_01")).unwrap();
    for f in std::fs::read_dir(drive.join("image_00/data")).unwrap() {
        std::fs::remove_file(f.unwrap().path()).unwrap();
    }
    let e = Sequence::open(&drive).unwrap_err().to_string();
    assert!(e.contains("no frames"), "{e}");
}
