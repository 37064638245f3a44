//! Issue 53, "Bad input, round two" (the `visnav-io` part): numbered frames in number order, a
//! truncated image is an error, not a grey frame, macOS `._*` resource forks in an image folder
//! are skipped, and a KITTI odometry layout of JPEG frames opens.
#![allow(clippy::unwrap_used)]

use std::path::Path;

use visnav_core::GrayImage;
use visnav_core::testdata::shared_data;
use visnav_io::image_io::{load_gray, save_gray_jpeg, save_gray_png};
use visnav_io::{IoError, Sequence};

fn img(seed: usize) -> GrayImage {
    GrayImage::from_fn(16, 8, |x, y| ((x * 7 + y * 13 + seed * 29) % 256) as f32)
}

fn camera_yaml(dir: &Path, stereo: bool) {
    let cam = "  camera_model: pinhole\n  intrinsics: [100, 100, 8, 4]\n  distortion_model: none\n  resolution: [16, 8]\n";
    let mut text = format!("cam0:\n{cam}");
    if stereo {
        text.push_str(&format!(
            "cam1:\n{cam}  T_cn_cnm1:\n  - [1, 0, 0, -0.5]\n  - [0, 1, 0, 0]\n  - [0, 0, 1, 0]\n  - [0, 0, 0, 1]\n"
        ));
    }
    std::fs::write(dir.join("camera.yaml"), text).unwrap();
}

fn names(seq: &Sequence, right: bool) -> Vec<String> {
    (0..seq.len())
        .map(|i| {
            let p = if right {
                seq.right_path(i).unwrap()
            } else {
                seq.left_path(i)
            };
            p.file_name().unwrap().to_string_lossy().into_owned()
        })
        .collect()
}

/// `image_1.jpg … image_120.jpg` was read as image_1, image_10, image_100, image_101, …
#[test]
fn a_folder_of_unpadded_numbered_images_is_read_in_number_order() {
    let dir = tempfile::tempdir().unwrap();
    for i in 1..=120 {
        save_gray_jpeg(&img(i), &dir.path().join(format!("image_{i}.jpg")), 90).unwrap();
    }
    camera_yaml(dir.path(), false);
    let seq = Sequence::open(dir.path()).unwrap();
    let expected: Vec<String> = (1..=120).map(|i| format!("image_{i}.jpg")).collect();
    assert_eq!(names(&seq, false), expected);
}

/// `left/` and `right/` with `1.png … 51.png`: both in number order, so frame 10 pairs `10.png`
/// with `10.png`.
#[test]
fn left_and_right_folders_of_unpadded_numbers_are_in_number_order() {
    let dir = tempfile::tempdir().unwrap();
    for side in ["left", "right"] {
        std::fs::create_dir_all(dir.path().join(side)).unwrap();
        for i in 1..=51 {
            save_gray_png(&img(i), &dir.path().join(side).join(format!("{i}.png"))).unwrap();
        }
    }
    camera_yaml(dir.path(), true);
    let seq = Sequence::open(dir.path()).unwrap();
    let expected: Vec<String> = (1..=51).map(|i| format!("{i}.png")).collect();
    assert_eq!(names(&seq, false), expected);
    assert_eq!(names(&seq, true), expected);
}

/// Names of two patterns have no one order: an error naming the folder, not a guess.
#[test]
fn a_folder_of_mixed_name_patterns_is_an_error_naming_the_folder() {
    let dir = tempfile::tempdir().unwrap();
    for n in ["a1.png", "a2.png", "b3.png"] {
        save_gray_png(&img(1), &dir.path().join(n)).unwrap();
    }
    camera_yaml(dir.path(), false);
    let e = Sequence::open(dir.path()).unwrap_err();
    assert!(matches!(e, IoError::Format { .. }), "{e:?}");
    let e = e.to_string();
    assert!(e.contains(&dir.path().display().to_string()), "{e}");
    assert!(e.contains("ambiguous") && e.contains("b3.png"), "{e}");
}

/// A KITTI odometry folder of zero-padded names keeps exactly its order.
#[test]
fn zero_padded_kitti_frames_keep_their_order() {
    let Some(seq_dir) = shared_data("kitti/odometry/sequences/06") else {
        return;
    };
    let seq = Sequence::open(&seq_dir).unwrap();
    let mut sorted: Vec<String> = std::fs::read_dir(seq_dir.join("image_0"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".png"))
        .collect();
    sorted.sort();
    assert_eq!(names(&seq, false), sorted);
    assert_eq!(names(&seq, true), sorted);
}

/// A JPEG cut to a third decoded as a grey-filled frame without an error; now it is an error
/// naming the file. A PNG cut to a third (or with a broken checksum) was and is an error.
#[test]
fn a_truncated_kitti_png_or_jpeg_is_an_error_not_a_grey_frame() {
    let Some(seq_dir) = shared_data("kitti/odometry/sequences/06") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let png = std::fs::read(seq_dir.join("image_0/000000.png")).unwrap();
    let cut_png = dir.path().join("cut.png");
    std::fs::write(&cut_png, &png[..png.len() / 3]).unwrap();
    let e = load_gray(&cut_png).unwrap_err();
    assert!(matches!(e, IoError::Image { .. }), "{e:?}");
    assert!(e.to_string().contains("cut.png"), "{e}");
    // a flipped byte in the middle of the image data: the checksum no longer matches
    let mut crc = png.clone();
    let mid = png.len() / 2;
    crc[mid] ^= 0x55;
    let bad_crc = dir.path().join("crc.png");
    std::fs::write(&bad_crc, &crc).unwrap();
    assert!(load_gray(&bad_crc).is_err());

    let frame = load_gray(&seq_dir.join("image_0/000000.png")).unwrap();
    let jpg = dir.path().join("whole.jpg");
    save_gray_jpeg(&frame, &jpg, 90).unwrap();
    let whole = std::fs::read(&jpg).unwrap();
    assert_eq!(load_gray(&jpg).unwrap().width(), frame.width());
    // trailing bytes after the end-of-image marker are allowed (some cameras pad)
    let padded = dir.path().join("padded.jpg");
    std::fs::write(&padded, [&whole[..], &[0u8; 64][..]].concat()).unwrap();
    assert_eq!(load_gray(&padded).unwrap(), load_gray(&jpg).unwrap());
    for (name, len) in [
        ("third.jpg", whole.len() / 3),
        ("almost.jpg", whole.len() - 2),
        ("header.jpg", 300),
    ] {
        let cut = dir.path().join(name);
        std::fs::write(&cut, &whole[..len]).unwrap();
        let e = load_gray(&cut).unwrap_err().to_string();
        assert!(e.contains(name) && e.contains("truncated JPEG"), "{e}");
    }
}

/// An AppleDouble resource fork as macOS writes it beside a file on a FAT, exFAT or SMB volume
/// (or into a tar/zip): `._<name>`, a few hundred bytes that are not an image.
const APPLE_DOUBLE: &[u8] = b"\x00\x05\x16\x07\x00\x02\x00\x00Mac OS X        \x00\x02";

/// The first `n` frames of KITTI 06 (both cameras, its calibration and the first `n` times) as
/// a KITTI odometry layout in `dir`, each frame written by `write` (`(image, path without
/// extension)`).
fn kitti_copy(kitti06: &Path, dir: &Path, n: usize, write: impl Fn(&GrayImage, &Path)) {
    for cam in ["image_0", "image_1"] {
        std::fs::create_dir_all(dir.join(cam)).unwrap();
        for i in 0..n {
            let frame = load_gray(&kitti06.join(format!("{cam}/{i:06}.png"))).unwrap();
            write(&frame, &dir.join(format!("{cam}/{i:06}")));
        }
    }
    std::fs::copy(kitti06.join("calib.txt"), dir.join("calib.txt")).unwrap();
    let times: String = std::fs::read_to_string(kitti06.join("times.txt"))
        .unwrap()
        .lines()
        .take(n)
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(dir.join("times.txt"), times).unwrap();
}

/// macOS `._000001.png` resource forks (and `.DS_Store`) in an image folder tripped the
/// frame-order rule ("named after different patterns"); now they are skipped (with a note) and
/// the frames keep their order: a folder of unpadded numbers, and a KITTI layout of zero-padded
/// names (exactly its order).
#[test]
fn macos_resource_forks_in_image_folders_are_skipped() {
    let dir = tempfile::tempdir().unwrap();
    for i in 1..=12 {
        save_gray_png(&img(i), &dir.path().join(format!("{i}.png"))).unwrap();
    }
    for junk in ["._1.png", "._10.png", ".DS_Store"] {
        std::fs::write(dir.path().join(junk), APPLE_DOUBLE).unwrap();
    }
    camera_yaml(dir.path(), false);
    let seq = Sequence::open(dir.path()).unwrap();
    let expected: Vec<String> = (1..=12).map(|i| format!("{i}.png")).collect();
    assert_eq!(names(&seq, false), expected);

    let Some(kitti06) = shared_data("kitti/odometry/sequences/06") else {
        return;
    };
    let kitti = tempfile::tempdir().unwrap();
    kitti_copy(&kitti06, kitti.path(), 12, |frame, p| {
        save_gray_png(frame, &p.with_extension("png")).unwrap();
    });
    for cam in ["image_0", "image_1"] {
        for junk in ["._000000.png", "._000011.png", ".DS_Store"] {
            std::fs::write(kitti.path().join(cam).join(junk), APPLE_DOUBLE).unwrap();
        }
    }
    std::fs::write(kitti.path().join("._calib.txt"), APPLE_DOUBLE).unwrap();
    let seq = Sequence::open(kitti.path()).unwrap();
    let expected: Vec<String> = (0..12).map(|i| format!("{i:06}.png")).collect();
    assert_eq!(names(&seq, false), expected);
    assert_eq!(names(&seq, true), expected);
}

/// A KITTI odometry layout (`image_0/`, `image_1/`, `calib.txt`, `times.txt`) whose frames are
/// JPEG said "sequence has no frames"; now its frames are read as an image folder's are.
#[test]
fn a_kitti_odometry_layout_of_jpeg_frames_opens() {
    let Some(kitti06) = shared_data("kitti/odometry/sequences/06") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    kitti_copy(&kitti06, dir.path(), 5, |frame, p| {
        save_gray_jpeg(frame, &p.with_extension("jpg"), 95).unwrap();
    });
    let seq = Sequence::open(dir.path()).unwrap();
    assert!(seq.has_stereo());
    let expected: Vec<String> = (0..5).map(|i| format!("{i:06}.jpg")).collect();
    assert_eq!(names(&seq, false), expected);
    assert_eq!(names(&seq, true), expected);
    let png = load_gray(&kitti06.join("image_0/000003.png")).unwrap();
    let jpg = load_gray(seq.left_path(3)).unwrap();
    assert_eq!((jpg.width(), jpg.height()), (png.width(), png.height()));
}

/// Issue 53's fuzz campaign: a KITTI calibration without its left camera's line was an error
/// at "line 0" (`calib.txt:0: no 'P0:' line`), a line no file has; now it names the file alone.
#[test]
fn a_calibration_without_its_left_camera_names_no_line_0() {
    let dir = tempfile::tempdir().unwrap();
    let calib = dir.path().join("calib.txt");
    std::fs::write(
        &calib,
        "P1: 718.856 0 607.1928 -386.1448 0 718.856 185.2157 0 0 0 1 0\n",
    )
    .unwrap();
    let e = visnav_io::kitti::read_odometry_calib(&calib).unwrap_err();
    assert!(matches!(e, IoError::Format { .. }), "{e:?}");
    let e = e.to_string();
    assert!(e.contains("calib.txt: no 'P0:' line"), "{e}");
    let raw = dir.path().join("calib_cam_to_cam.txt");
    std::fs::write(&raw, "calib_time: 09-Jan-2012 13:57:47\n").unwrap();
    let e = visnav_io::kitti::raw::read_raw_calib(&raw).unwrap_err();
    assert!(matches!(e, IoError::Format { .. }), "{e:?}");
    assert!(
        e.to_string()
            .contains("calib_cam_to_cam.txt: no 'P_rect_00:' line"),
        "{e}"
    );
}
