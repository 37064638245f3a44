//! Users' own cameras: EuRoC (real sample), TUM RGB-D, image folders and video with camera
//! files; undistortion / rectification on load and calibration errors that name the file.
#![allow(clippy::unwrap_used)]

use std::path::Path;

use visnav_core::GrayImage;
use visnav_core::testdata::shared_data;
use visnav_io::image_io::save_gray_png;
use visnav_io::{Sequence, SequenceLayout};

/// The vertical shift (and its horizontal partner) that best aligns `right` to `left` by
/// normalised cross-correlation over the image centre: `left(u, v) ≈ right(u - dx, v - dy)`.
fn best_shift(left: &GrayImage, right: &GrayImage) -> (i64, i64) {
    let (w, h) = (left.width() as i64, left.height() as i64);
    let mut best = (f64::MIN, 0, 0);
    for dy in -12..=12 {
        for dx in 0..=60 {
            let (mut sl, mut sr, mut sll, mut srr, mut slr, mut n) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
            for v in (h / 4..3 * h / 4).step_by(2) {
                for u in (w / 4..3 * w / 4).step_by(2) {
                    let a = f64::from(left.get(u as usize, v as usize));
                    let b = f64::from(right.get((u - dx) as usize, (v - dy) as usize));
                    sl += a;
                    sr += b;
                    sll += a * a;
                    srr += b * b;
                    slr += a * b;
                    n += 1.0;
                }
            }
            let cov = slr / n - sl * sr / (n * n);
            let ncc = cov / ((sll / n - (sl / n).powi(2)) * (srr / n - (sr / n).powi(2))).sqrt();
            if ncc > best.0 {
                best = (ncc, dx, dy);
            }
        }
    }
    (best.1, best.2)
}

#[test]
fn euroc_sample_opens_rectified_with_timestamps() {
    let Some(root) = shared_data("euroc/V1_01_easy_first40") else {
        return;
    };
    let seq = Sequence::open(&root).unwrap();
    assert_eq!(seq.layout, SequenceLayout::Euroc);
    assert_eq!(seq.len(), 40);
    assert!(seq.has_stereo() && seq.timestamped);
    assert_eq!((seq.camera.width, seq.camera.height), (752, 480));
    // EuRoC's stereo baseline is about 11 cm
    let b = seq.baseline_m.unwrap();
    assert!((b - 0.110).abs() < 0.002, "baseline {b} m");
    // data.csv nanoseconds → seconds, 20 Hz
    assert!((seq.timestamps[0] - 1_403_715_273.262_143).abs() < 1e-5);
    assert!((seq.timestamps[39] - seq.timestamps[0] - 39.0 * 0.05).abs() < 1e-3);
    // the cam0 → body transform is known
    assert!(seq.body_from_cam.is_some());
    // raw images are offset vertically by several pixels (cy 248 vs 255); rectified rows agree
    let raw_l = visnav_io::image_io::load_gray(seq.left_path(0)).unwrap();
    let raw_r = visnav_io::image_io::load_gray(seq.right_path(0).unwrap()).unwrap();
    let (l, r) = (seq.load_left(0).unwrap(), seq.load_right(0).unwrap());
    let (_, dy_raw) = best_shift(&raw_l, &raw_r);
    let (dx, dy) = best_shift(&l, &r);
    assert!(dy_raw.abs() >= 3, "raw vertical offset {dy_raw}");
    assert!(dy.abs() <= 1 && dx > 0, "rectified shift ({dx}, {dy})");
}

fn write_frames(dir: &Path, n: usize, w: usize, h: usize) {
    std::fs::create_dir_all(dir).unwrap();
    for i in 0..n {
        let img = GrayImage::from_fn(w, h, |x, y| ((x * 3 + y * 5 + i * 7) % 256) as f32);
        save_gray_png(&img, &dir.join(format!("{i:04}.png"))).unwrap();
    }
}

const CAMERA_YAML: &str = "cam0:\n  camera_model: pinhole\n  intrinsics: [60.0, 60.0, 31.5, 23.5]\n  distortion_model: radtan\n  distortion_coeffs: [-0.1, 0.01, 0.0, 0.0]\n  resolution: [64, 48]\n";

#[test]
fn image_folder_with_camera_file() {
    let dir = tempfile::tempdir().unwrap();
    write_frames(dir.path(), 3, 64, 48);
    // no camera file: a clear error
    let e = Sequence::open(dir.path()).unwrap_err().to_string();
    assert!(e.contains("camera file"), "{e}");
    std::fs::write(dir.path().join("camera.yaml"), CAMERA_YAML).unwrap();
    let seq = Sequence::open(dir.path()).unwrap();
    assert_eq!(seq.layout, SequenceLayout::ImageFolder);
    assert_eq!(seq.len(), 3);
    assert!(!seq.has_stereo() && !seq.timestamped);
    // barrel distortion, alpha = 0: the undistorted edge midpoints lie further out than the raw
    // ones (x_d = x (1 + k1 r²), k1 < 0), so the focal length shrinks a little (0.525 → 0.541)
    assert!(
        seq.camera.fx > 57.0 && seq.camera.fx < 59.5,
        "{}",
        seq.camera.fx
    );
    let img = seq.load_left(2).unwrap();
    assert_eq!((img.width(), img.height()), (64, 48));
    // --camera overrides, and a size mismatch names the calibration and the image
    let other = dir.path().join("other.toml");
    std::fs::write(
        &other,
        "[cam0]\ncamera_model = \"pinhole\"\nintrinsics = [60.0, 60.0, 31.5, 23.5]\ndistortion_model = \"none\"\nresolution = [640, 480]\n",
    )
    .unwrap();
    let e = Sequence::open_with_camera(dir.path(), Some(&other))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("other.toml") && e.contains("640x480") && e.contains("0000.png"),
        "{e}"
    );
}

#[test]
fn tum_rgbd_layout_keeps_timestamps() {
    let dir = tempfile::tempdir().unwrap();
    write_frames(&dir.path().join("rgb"), 3, 64, 48);
    std::fs::write(
        dir.path().join("rgb.txt"),
        "# color images\n# timestamp filename\n1305031102.175304 rgb/0000.png\n1305031102.211214 rgb/0001.png\n1305031102.243211 rgb/0002.png\n",
    )
    .unwrap();
    let cam = dir.path().join("freiburg1.yaml");
    std::fs::write(&cam, CAMERA_YAML).unwrap();
    let e = Sequence::open(dir.path()).unwrap_err().to_string();
    assert!(e.contains("camera file"), "{e}");
    let seq = Sequence::open_with_camera(dir.path(), Some(&cam)).unwrap();
    assert_eq!(seq.layout, SequenceLayout::TumRgbd);
    assert!(seq.timestamped);
    assert_eq!(
        seq.timestamps,
        vec![
            1_305_031_102.175_304,
            1_305_031_102.211_214,
            1_305_031_102.243_211
        ]
    );
    assert_eq!(seq.load_left(1).unwrap().width(), 64);
    std::fs::write(dir.path().join("rgb.txt"), "1305031102.175304\n").unwrap();
    let e = Sequence::open_with_camera(dir.path(), Some(&cam))
        .unwrap_err()
        .to_string();
    assert!(e.contains("rgb.txt:1"), "{e}");
}

#[test]
fn euroc_calibration_errors_name_the_file() {
    let Some(root) = shared_data("euroc/V1_01_easy_first40") else {
        return;
    };
    // a copy of the layout with 2 frames and an edited sensor.yaml
    let dir = tempfile::tempdir().unwrap();
    let mav0 = dir.path().join("mav0");
    for cam in ["cam0", "cam1"] {
        let src = root.join("mav0").join(cam);
        std::fs::create_dir_all(mav0.join(cam).join("data")).unwrap();
        let csv = std::fs::read_to_string(src.join("data.csv")).unwrap();
        let lines: Vec<&str> = csv.lines().take(3).collect();
        std::fs::write(mav0.join(cam).join("data.csv"), lines.join("\n")).unwrap();
        for l in &lines[1..] {
            let name = l.split(',').nth(1).unwrap();
            std::fs::copy(
                src.join("data").join(name),
                mav0.join(cam).join("data").join(name),
            )
            .unwrap();
        }
        std::fs::copy(src.join("sensor.yaml"), mav0.join(cam).join("sensor.yaml")).unwrap();
    }
    let seq = Sequence::open(dir.path()).unwrap();
    assert_eq!(seq.len(), 2);
    let sensor1 = mav0.join("cam1").join("sensor.yaml");
    let original = std::fs::read_to_string(&sensor1).unwrap();
    for (edit, what) in [
        (
            original.replace("resolution: [752, 480]", "resolution: [640, 480]"),
            "640x480",
        ),
        (
            original.replace("distortion_coefficients:", "#"),
            "missing field `distortion_coefficients`",
        ),
        (
            original.replace(
                "[-0.28368365,  0.07451284, -0.00010473, -3.55590700e-05]",
                "[-0.28368365]",
            ),
            "needs 4 or 5",
        ),
    ] {
        std::fs::write(&sensor1, &edit).unwrap();
        let e = Sequence::open(dir.path()).unwrap_err().to_string();
        assert!(
            e.contains("cam1/sensor.yaml") && e.contains(what),
            "{what}: {e}"
        );
    }
}

#[test]
#[cfg(feature = "video")]
fn video_with_camera_file() {
    // CI runs scripts/setup.sh, which installs ffmpeg: a missing ffmpeg fails this test
    let dir = tempfile::tempdir().unwrap();
    let (w, h, n) = (64usize, 48usize, 5usize);
    let mut raw = Vec::with_capacity(w * h * n);
    for i in 0..n {
        for y in 0..h {
            for x in 0..w {
                raw.push(((x * 3 + y * 5 + i * 7) % 256) as u8);
            }
        }
    }
    let raw_path = dir.path().join("frames.gray");
    std::fs::write(&raw_path, &raw).unwrap();
    let video = dir.path().join("clip.mkv");
    let status = std::process::Command::new("ffmpeg")
        .args([
            "-v", "error", "-nostdin", "-f", "rawvideo", "-pix_fmt", "gray", "-s", "64x48",
        ])
        .args(["-r", "25", "-i"])
        .arg(&raw_path)
        .args(["-c:v", "ffv1"])
        .arg(&video)
        .status()
        .expect("ffmpeg must be installed (scripts/setup.sh)");
    assert!(status.success());
    let cam = dir.path().join("camera.yaml");
    std::fs::write(
        &cam,
        CAMERA_YAML.replace("[-0.1, 0.01, 0.0, 0.0]", "[0.0, 0.0, 0.0, 0.0]"),
    )
    .unwrap();
    let e = Sequence::open(&video).unwrap_err().to_string();
    assert!(e.contains("clip.mkv") && e.contains("--camera"), "{e}");
    let seq = Sequence::open_with_camera(&video, Some(&cam)).unwrap();
    assert_eq!(seq.layout, SequenceLayout::Video);
    assert_eq!(seq.len(), n);
    assert!((seq.timestamps[4] - 4.0 / 25.0).abs() < 1e-9);
    // lossless codec, zero distortion: frames come back exactly, in any order
    for i in [3, 0, 4] {
        let img = seq.load_left(i).unwrap();
        for (k, &v) in img.data().iter().enumerate() {
            assert_eq!(v, f32::from(raw[i * w * h + k]), "frame {i} pixel {k}");
        }
    }
    // a calibration for another size is an error naming both files
    std::fs::write(&cam, CAMERA_YAML.replace("[64, 48]", "[320, 240]")).unwrap();
    let e = Sequence::open_with_camera(&video, Some(&cam))
        .unwrap_err()
        .to_string();
    assert!(e.contains("camera.yaml") && e.contains("clip.mkv"), "{e}");
    // a file that is no video: a text file says so before ffprobe is asked (issue 21)
    let e = Sequence::open_with_camera(&cam, Some(&cam))
        .unwrap_err()
        .to_string();
    assert!(e.contains("camera.yaml") && e.contains("text file"), "{e}");
    let bin = dir.path().join("noise.bin");
    std::fs::write(&bin, [0u8, 1, 2, 255, 0, 7]).unwrap();
    let e = Sequence::open_with_camera(&bin, Some(&cam))
        .unwrap_err()
        .to_string();
    assert!(e.contains("ffprobe"), "{e}");
}

/// A streamed H.264 video with B-frames (packets out of presentation order) and keyframes
/// every 25 frames: any access order (backwards, jumps, repeats) gives the frames of one
/// sequential decoding, and the timestamps are the presentation times.
#[test]
#[cfg(feature = "video")]
fn streamed_video_random_access_equals_sequential() {
    let dir = tempfile::tempdir().unwrap();
    let video = dir.path().join("clip.mp4");
    let status = std::process::Command::new("ffmpeg")
        .args(["-v", "error", "-nostdin", "-f", "lavfi", "-i"])
        .args([
            "testsrc=size=64x48:rate=20",
            "-frames:v",
            "100",
            "-pix_fmt",
            "gray",
        ])
        .args(["-c:v", "libx264", "-g", "25", "-bf", "2"])
        .arg(&video)
        .status()
        .expect("ffmpeg must be installed (scripts/setup.sh)");
    assert!(status.success());
    let cam = dir.path().join("camera.yaml");
    std::fs::write(
        &cam,
        CAMERA_YAML.replace("[-0.1, 0.01, 0.0, 0.0]", "[0.0, 0.0, 0.0, 0.0]"),
    )
    .unwrap();
    let seq = Sequence::open_with_camera(&video, Some(&cam)).unwrap();
    assert_eq!(seq.len(), 100);
    assert!((seq.timestamps[99] - 99.0 / 20.0).abs() < 1e-6);
    let sequential: Vec<_> = (0..100).map(|i| seq.load_left(i).unwrap()).collect();
    // distinct frames (the test pattern moves), so a wrong index cannot pass
    assert_ne!(sequential[10], sequential[11]);
    let reopened = Sequence::open_with_camera(&video, Some(&cam)).unwrap();
    let order: Vec<usize> = (0..100)
        .rev()
        .chain([7, 63, 62, 99, 0, 50, 50, 26, 24])
        .collect();
    for i in order {
        assert_eq!(reopened.load_left(i).unwrap(), sequential[i], "frame {i}");
    }
    assert!(reopened.load_left(100).is_err());
}
