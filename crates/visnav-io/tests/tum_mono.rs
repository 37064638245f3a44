//! The TUM monoVO layout on a synthetic sequence: a texture known in normalised coordinates is
//! seen through a known FOV lens, written as JPEG with `times.txt` and DSO's `camera.txt`; the
//! opened sequence must give back the undistorted texture, the timestamps, and clear errors for
//! bad input.
#![allow(clippy::unwrap_used)]

use std::path::Path;

use nalgebra::Point2;
use visnav_core::distortion::{CalibratedCamera, Distortion};
use visnav_core::{GrayImage, PinholeCamera};
use visnav_io::image_io::save_gray_jpeg;
use visnav_io::{Sequence, SequenceLayout};

const W: u32 = 160;
const H: u32 = 120;
const OMEGA: f64 = 0.9;
/// `camera.txt` of the synthetic lens: relative intrinsics (fx = 96 px, cx = 79.5 px, …).
const CAMERA_TXT: &str = "0.6 0.8 0.5 0.5 0.9\n160 120\nnone\n160 120\n";
const T0: f64 = 1_383_315_339.120_7;

/// The scene: a smooth texture as a function of ideal normalised coordinates, shifted by
/// `frame` to make the frames differ.
fn texture(x: &Point2<f64>, frame: usize) -> f32 {
    let s = 0.02 * frame as f64;
    (128.0
        + 60.0 * ((6.0 * (x.x + s)).sin() * (5.0 * x.y).cos())
        + 30.0 * (3.0 * x.x - 4.0 * x.y).sin()) as f32
}

/// The raw camera the texture is seen through (what `CAMERA_TXT` describes).
fn raw_camera() -> CalibratedCamera {
    CalibratedCamera {
        pinhole: PinholeCamera::new(96.0, 96.0, 79.5, 59.5, W, H).unwrap(),
        distortion: Distortion::Fov { omega: OMEGA },
    }
}

/// The raw (distorted) image of frame `i`.
fn raw_frame(i: usize) -> GrayImage {
    let cam = raw_camera();
    GrayImage::from_fn(W as usize, H as usize, |u, v| {
        let x = cam.undistort_px(&Point2::new(u as f64, v as f64)).unwrap();
        texture(&x, i)
    })
}

/// Writes a monoVO sequence of `n` frames into `root`.
fn write_sequence(root: &Path, n: usize) {
    std::fs::create_dir_all(root.join("images")).unwrap();
    let mut times = String::new();
    for i in 0..n {
        save_gray_jpeg(&raw_frame(i), &root.join(format!("images/{i:05}.jpg")), 98).unwrap();
        times.push_str(&format!("{i:05} {:.6} 12.5\n", T0 + 0.05 * i as f64));
    }
    std::fs::write(root.join("times.txt"), times).unwrap();
    std::fs::write(root.join("camera.txt"), CAMERA_TXT).unwrap();
}

/// Mean absolute difference between frame `i` as loaded and the texture seen by the output
/// pinhole camera, over the interior (2 px border left out).
fn error_to_texture(seq: &Sequence, img: &GrayImage, i: usize) -> f64 {
    let (w, h) = (img.width(), img.height());
    let mut sum = 0.0;
    let mut n = 0.0;
    for v in 2..h - 2 {
        for u in 2..w - 2 {
            let x = seq.camera.normalize(&Point2::new(u as f64, v as f64));
            sum += f64::from((img.get(u, v) - texture(&x, i)).abs());
            n += 1.0;
        }
    }
    sum / n
}

#[test]
fn monovo_sequence_opens_undistorted_with_timestamps() {
    let dir = tempfile::tempdir().unwrap();
    write_sequence(dir.path(), 4);
    // DSO's photometric files are accepted and ignored
    std::fs::write(dir.path().join("pcalib.txt"), "0 1 2\n").unwrap();
    let seq = Sequence::open(dir.path()).unwrap();
    assert_eq!(seq.layout, SequenceLayout::TumMono);
    assert_eq!(seq.len(), 4);
    assert!(seq.timestamped && !seq.has_stereo());
    for (i, t) in seq.timestamps.iter().enumerate() {
        assert!((t - (T0 + 0.05 * i as f64)).abs() < 1e-6, "{t}");
    }
    // `none`: the input intrinsics (relative → pixels with DSO's half-pixel shift), undistorted
    let cam = seq.camera;
    assert_eq!((cam.fx, cam.fy, cam.cx, cam.cy), (96.0, 96.0, 79.5, 59.5));
    assert_eq!((cam.width, cam.height), (W, H));
    let img = seq.load_left(3).unwrap();
    let undistorted = error_to_texture(&seq, &img, 3);
    // the raw frame is the distorted view: far from the pinhole texture
    let raw = visnav_io::image_io::load_gray(seq.left_path(3)).unwrap();
    let distorted = error_to_texture(&seq, &raw, 3);
    assert!(
        undistorted < 1.5,
        "undistorted image off by {undistorted} grey levels"
    );
    assert!(
        distorted > 5.0 * undistorted,
        "raw {distorted} vs {undistorted}"
    );
}

#[test]
fn crop_full_explicit_and_kalibr_cameras() {
    let dir = tempfile::tempdir().unwrap();
    write_sequence(dir.path(), 2);
    let cam_txt = dir.path().join("camera.txt");
    for (line3, size) in [
        ("crop", (128, 96)),
        ("full", (160, 120)),
        ("0.6 0.8 0.5 0.5 0", (120, 90)),
        ("70.0 70.0 60.0 45.0 0", (120, 90)),
    ] {
        std::fs::write(
            &cam_txt,
            format!(
                "0.6 0.8 0.5 0.5 0.9\n160 120\n{line3}\n{} {}\n",
                size.0, size.1
            ),
        )
        .unwrap();
        let seq = Sequence::open(dir.path()).unwrap();
        assert_eq!((seq.camera.width, seq.camera.height), size, "{line3}");
        let img = seq.load_left(1).unwrap();
        assert_eq!(
            (img.width(), img.height()),
            (size.0 as usize, size.1 as usize)
        );
        if line3 != "full" {
            let e = error_to_texture(&seq, &img, 1);
            assert!(e < 2.0, "{line3}: off by {e} grey levels");
        }
    }
    let seq = Sequence::open(dir.path()).unwrap();
    assert_eq!((seq.camera.fx, seq.camera.cx), (70.0, 60.0));
    // `crop` sees less than `full` (larger focal lengths)
    std::fs::write(&cam_txt, "0.6 0.8 0.5 0.5 0.9\n160 120\ncrop\n160 120\n").unwrap();
    let crop = Sequence::open(dir.path()).unwrap().camera;
    std::fs::write(&cam_txt, "0.6 0.8 0.5 0.5 0.9\n160 120\nfull\n160 120\n").unwrap();
    let full = Sequence::open(dir.path()).unwrap().camera;
    assert!(crop.fx > full.fx && crop.fy > full.fy, "{crop:?} {full:?}");
    // --camera with a Kalibr-style file: the same lens, undistorted by visnav's alpha = 0 rule
    let yaml = dir.path().join("lens.yaml");
    std::fs::write(
        &yaml,
        "cam0:\n  camera_model: pinhole\n  intrinsics: [96.0, 96.0, 79.5, 59.5]\n  distortion_model: fov\n  distortion_coeffs: [0.9]\n  resolution: [160, 120]\n",
    )
    .unwrap();
    let seq = Sequence::open_with_camera(dir.path(), Some(&yaml)).unwrap();
    assert_eq!(seq.layout, SequenceLayout::TumMono);
    let e = error_to_texture(&seq, &seq.load_left(0).unwrap(), 0);
    assert!(e < 2.0, "Kalibr fov: off by {e} grey levels");
}

#[test]
fn bad_monovo_input_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    write_sequence(root, 3);
    let open_err = || Sequence::open(root).unwrap_err().to_string();
    // malformed camera.txt lines name the file and the line
    for (text, what) in [
        ("0.6 0.8 0.5\n160 120\nnone\n160 120\n", "camera.txt:1:"),
        (
            "0.6 0.8 0.5 0.5 0.9\n160x120\nnone\n160 120\n",
            "camera.txt:2:",
        ),
        (
            "0.6 0.8 0.5 0.5 0.9\n160 120\nrectify\n160 120\n",
            "camera.txt:3:",
        ),
        (
            "0.6 0.8 0.5 0.5 0.9\n160 120\nnone\n",
            "camera.txt:4: missing line",
        ),
    ] {
        std::fs::write(root.join("camera.txt"), text).unwrap();
        let e = open_err();
        assert!(e.contains(what), "{what}: {e}");
    }
    // a calibration for another size names the calibration and the image
    std::fs::write(
        root.join("camera.txt"),
        "0.6 0.8 0.5 0.5 0.9\n320 240\nnone\n320 240\n",
    )
    .unwrap();
    let e = open_err();
    assert!(
        e.contains("camera.txt") && e.contains("320x240") && e.contains("00000.jpg"),
        "{e}"
    );
    std::fs::write(root.join("camera.txt"), CAMERA_TXT).unwrap();
    // a later frame of another size is an error when it is loaded
    save_gray_jpeg(
        &GrayImage::new(80, 60, 100.0),
        &root.join("images/00002.jpg"),
        90,
    )
    .unwrap();
    let seq = Sequence::open(root).unwrap();
    let e = seq.load_left(2).unwrap_err().to_string();
    assert!(e.contains("00002.jpg") && e.contains("80x60"), "{e}");
    // an id of times.txt without its image
    std::fs::remove_file(root.join("images/00001.jpg")).unwrap();
    let e = open_err();
    assert!(
        e.contains("times.txt:2") && e.contains("'00001'") && e.contains("00001.jpg"),
        "{e}"
    );
    // a malformed times.txt line
    std::fs::write(root.join("times.txt"), "00000 1383315339.12 12.5\n00001\n").unwrap();
    let e = open_err();
    assert!(
        e.contains("times.txt:2") && e.contains("expected 'id timestamp"),
        "{e}"
    );
    // a JPEG that does not decode names the file
    std::fs::write(root.join("times.txt"), format!("00000 {T0}\n")).unwrap();
    std::fs::write(root.join("images/00000.jpg"), b"not a jpeg").unwrap();
    let e = open_err();
    assert!(
        e.contains("00000.jpg") && e.contains("cannot decode"),
        "{e}"
    );
    // the zipped download must be unzipped first
    std::fs::remove_dir_all(root.join("images")).unwrap();
    let e = open_err();
    assert!(e.contains("images") && e.contains("not found"), "{e}");
    std::fs::write(root.join("images.zip"), b"PK").unwrap();
    let e = open_err();
    assert!(e.contains("images.zip") && e.contains("unzip"), "{e}");
}
