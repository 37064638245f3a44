//! Regression tests of issue 21: inputs that panicked, lost frames, gave silently wrong results
//! or misleading messages. Each test fails on the code before the fix.
#![allow(clippy::unwrap_used)]

use std::path::Path;

use visnav_core::GrayImage;
use visnav_core::testdata::shared_data;
use visnav_io::image_io::save_gray_png;
use visnav_io::kitti::{read_odometry_calib, read_times};
use visnav_io::pfm::read_pfm;
use visnav_io::trajectory::{read_kitti_matrices, read_trajectory};
use visnav_io::{IoError, Sequence};

const CALIB: &str = "P0: 718.856 0 607.1928 0 0 718.856 185.2157 0 0 0 1 0
P1: 718.856 0 607.1928 -386.1448 0 718.856 185.2157 0 0 0 1 0
";

/// A gray 16x8 image whose content encodes `k` (so that which file was loaded can be told).
fn img(k: usize) -> GrayImage {
    GrayImage::from_fn(16, 8, |x, y| ((x + 3 * y + 20 * k) % 256) as f32)
}

/// An odometry sequence with stereo frames of the given numbers.
fn make_odometry(root: &Path, numbers: &[usize], times: usize) {
    for (cam, base) in [("image_0", 0), ("image_1", 100)] {
        std::fs::create_dir_all(root.join(cam)).unwrap();
        for &i in numbers {
            save_gray_png(&img(base + i), &root.join(cam).join(format!("{i:06}.png"))).unwrap();
        }
    }
    std::fs::write(root.join("calib.txt"), CALIB).unwrap();
    let t: String = (0..times)
        .map(|i| format!("{:e}\n", 0.1 * i as f64))
        .collect();
    std::fs::write(root.join("times.txt"), t).unwrap();
}

#[test]
fn pfm_with_huge_width_is_an_error_not_an_overflow_panic() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("a.pfm");
    let mut bytes = b"PF\n18446744073709551615 3\n-1.0\n".to_vec();
    bytes.extend_from_slice(&[0u8; 64]);
    std::fs::write(&p, &bytes).unwrap();
    let e = read_pfm(&p).unwrap_err().to_string();
    assert!(e.contains("a.pfm") && e.contains("truncated"), "{e}");
    std::fs::write(&p, b"Pf\n4294967296 4294967296\n-1.0\n\0\0\0\0").unwrap();
    assert!(read_pfm(&p).is_err());
}

#[test]
fn pfm_with_scale_zero_is_an_error_not_big_endian() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("a.pfm");
    let mut bytes = b"Pf\n1 1\n0.0\n".to_vec();
    bytes.extend_from_slice(&1.5f32.to_le_bytes());
    std::fs::write(&p, &bytes).unwrap();
    let e = read_pfm(&p).unwrap_err().to_string();
    assert!(e.contains("byte order"), "{e}");
    for scale in ["-0", "nan", "inf"] {
        let mut bytes = format!("Pf\n1 1\n{scale}\n").into_bytes();
        bytes.extend_from_slice(&1.5f32.to_le_bytes());
        std::fs::write(&p, &bytes).unwrap();
        assert!(read_pfm(&p).is_err(), "scale {scale}");
    }
}

#[test]
fn utf8_byte_order_mark_is_accepted_by_the_text_parsers() {
    let dir = tempfile::tempdir().unwrap();
    let bom = "\u{feff}";
    let calib = dir.path().join("calib.txt");
    std::fs::write(&calib, format!("{bom}{CALIB}")).unwrap();
    assert!(read_odometry_calib(&calib).unwrap().p1.is_some());
    let times = dir.path().join("times.txt");
    std::fs::write(&times, format!("{bom}1.0\r\n1.1\r\n")).unwrap();
    assert_eq!(read_times(&times).unwrap(), vec![1.0, 1.1]);
    let kitti = dir.path().join("poses.txt");
    std::fs::write(&kitti, format!("{bom}1 0 0 0 0 1 0 0 0 0 1 0\r\n")).unwrap();
    assert_eq!(read_trajectory(&kitti).unwrap().poses.len(), 1);
    let tum = dir.path().join("tum.txt");
    std::fs::write(&tum, format!("{bom}1.0 1 2 3 0 0 0 1\n")).unwrap();
    assert_eq!(read_trajectory(&tum).unwrap().poses.len(), 1);
    let cam = dir.path().join("camera.yaml");
    std::fs::write(
        &cam,
        format!(
            "{bom}cam0:\n  camera_model: pinhole\n  intrinsics: [100, 100, 8, 4]\n  distortion_model: none\n  resolution: [16, 8]\n"
        ),
    )
    .unwrap();
    visnav_io::calibration::read_camera_file(&cam).unwrap();
    let dso = dir.path().join("camera.txt");
    std::fs::write(&dso, format!("{bom}100 100 8 4 0\n16 8\ncrop\n16 8\n")).unwrap();
    visnav_io::tum_mono::read_dso_camera(&dso).unwrap();
}

#[test]
fn right_images_are_paired_by_file_name_not_sort_position() {
    let dir = tempfile::tempdir().unwrap();
    make_odometry(dir.path(), &[0, 1, 2], 3);
    // rename one right image: by position it would pair with the wrong left frame
    let r = dir.path().join("image_1");
    std::fs::rename(r.join("000001.png"), r.join("000009.png")).unwrap();
    let e = Sequence::open(dir.path()).unwrap_err().to_string();
    assert!(e.contains("000001.png") && e.contains("file name"), "{e}");
    std::fs::rename(r.join("000009.png"), r.join("000001.png")).unwrap();
    let seq = Sequence::open(dir.path()).unwrap();
    for i in 0..3 {
        let l = seq.left_path(i).file_name().unwrap().to_owned();
        assert_eq!(seq.right_path(i).unwrap().file_name().unwrap(), l);
        assert_eq!(seq.load_right(i).unwrap(), img(100 + i));
    }
}

#[test]
fn a_gap_in_the_frame_numbering_keeps_each_frames_timestamp() {
    let dir = tempfile::tempdir().unwrap();
    // frames 0, 1, 3, 4 (2 missing), times.txt for 0..5
    make_odometry(dir.path(), &[0, 1, 3, 4], 5);
    let seq = Sequence::open(dir.path()).unwrap();
    assert_eq!(seq.len(), 4);
    let want = [0.0, 0.1, 0.3, 0.4];
    for (t, w) in seq.timestamps.iter().zip(want) {
        assert!((t - w).abs() < 1e-12, "{:?}", seq.timestamps);
    }
    // a times.txt too short for the numbers is an error, not cut to fit
    std::fs::write(dir.path().join("times.txt"), "0\n0.1\n0.2\n").unwrap();
    let e = Sequence::open(dir.path()).unwrap_err().to_string();
    assert!(e.contains("times.txt") && e.contains("with gaps"), "{e}");
}

#[test]
fn frames_numbered_without_padding_are_in_numeric_order() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(dir.path().join("image_0")).unwrap();
    for i in [8, 9, 10, 11] {
        save_gray_png(&img(i), &dir.path().join(format!("image_0/{i}.png"))).unwrap();
    }
    std::fs::write(dir.path().join("calib.txt"), CALIB).unwrap();
    let seq = Sequence::open(dir.path()).unwrap();
    let names: Vec<_> = (0..4)
        .map(|i| {
            seq.left_path(i)
                .file_name()
                .unwrap()
                .to_string_lossy()
                .into_owned()
        })
        .collect();
    assert_eq!(names, ["8.png", "9.png", "10.png", "11.png"]);
}

#[test]
fn a_duplicated_calibration_key_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("calib.txt");
    std::fs::write(
        &p,
        format!("{CALIB}P0: 359.428 0 303.596 0 0 359.428 92.6 0 0 0 1 0\n"),
    )
    .unwrap();
    let e = read_odometry_calib(&p).unwrap_err().to_string();
    assert!(e.contains("calib.txt:3") && e.contains("twice"), "{e}");
}

#[test]
fn trajectory_rotation_blocks_must_be_rotations() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("est.txt");
    for bad in [
        "2 0 0 0 0 2 0 0 0 0 2 0",
        "0 0 0 0 0 0 0 0 0 0 0 0",
        "-1 0 0 0 0 1 0 0 0 0 1 0",
    ] {
        std::fs::write(&p, format!("1 0 0 0 0 1 0 0 0 0 1 0\n{bad}\n")).unwrap();
        let e = read_kitti_matrices(&p).unwrap_err().to_string();
        assert!(
            e.contains("est.txt:2") && e.contains("not a rotation"),
            "{e}"
        );
    }
    // written with 6 significant digits, a rotation stays a rotation
    std::fs::write(
        &p,
        "9.999976e-01 5.206060e-04 -2.125020e-03 -4.690294e-02 -5.206180e-04 9.999999e-01 2.090000e-07 -2.839928e-02 2.125017e-03 1.085286e-06 9.999977e-01 8.586941e-01\n",
    )
    .unwrap();
    assert_eq!(read_kitti_matrices(&p).unwrap().len(), 1);
}

#[test]
fn trajectory_coordinates_of_1e308_are_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("est.txt");
    std::fs::write(&p, "1 0 0 1e308 0 1 0 0 0 0 1 -1e308\n").unwrap();
    let e = read_trajectory(&p).unwrap_err().to_string();
    assert!(
        e.contains("est.txt:1") && e.contains("from the origin"),
        "{e}"
    );
    std::fs::write(&p, "0.0 1.7e308 0 0 0 0 0 1\n").unwrap();
    let e = read_trajectory(&p).unwrap_err().to_string();
    assert!(
        e.contains("est.txt:1") && e.contains("from the origin"),
        "{e}"
    );
    std::fs::write(&p, "0.0 1 0 0 1e308 1e308 0 1\n").unwrap();
    let e = read_trajectory(&p).unwrap_err().to_string();
    assert!(e.contains("est.txt:1") && e.contains("quaternion"), "{e}");
}

#[test]
fn a_text_file_given_as_the_sequence_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("notes.txt");
    std::fs::write(&p, "these are not frames\n").unwrap();
    let e = Sequence::open(&p).unwrap_err();
    assert!(!matches!(e, IoError::NotFound { .. }), "{e}");
    assert!(e.to_string().contains("text file"), "{e}");
}

#[cfg(unix)]
#[test]
fn a_symlink_loop_given_as_the_sequence_is_not_reported_as_missing() {
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("a");
    let b = dir.path().join("b");
    std::os::unix::fs::symlink(&b, &a).unwrap();
    std::os::unix::fs::symlink(&a, &b).unwrap();
    let e = Sequence::open(&a).unwrap_err().to_string();
    assert!(
        e.contains("symlink loop") || e.contains("symbolic link"),
        "{e}"
    );
    let e = read_trajectory(&a).unwrap_err().to_string();
    assert!(
        e.contains("symlink loop") || e.contains("symbolic link"),
        "{e}"
    );
}

#[test]
fn a_directory_given_as_a_file_says_so_once() {
    let dir = tempfile::tempdir().unwrap();
    let e = read_trajectory(dir.path()).unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("is a directory"), "{msg}");
    // the message carries no source that an error chain would print a second time
    assert!(std::error::Error::source(&e).is_none(), "{msg}");
}

/// The shared EuRoC sample in a temporary copy whose `data.csv` files can be edited (the image
/// folders are symlinked).
#[cfg(unix)]
fn euroc_copy(dst: &Path) -> Option<()> {
    let src = shared_data("euroc/V1_01_easy_first40")?;
    for cam in ["cam0", "cam1"] {
        let d = dst.join("mav0").join(cam);
        std::fs::create_dir_all(&d).unwrap();
        let s = src.join("mav0").join(cam);
        std::os::unix::fs::symlink(s.join("data"), d.join("data")).unwrap();
        for f in ["data.csv", "sensor.yaml"] {
            std::fs::copy(s.join(f), d.join(f)).unwrap();
        }
    }
    Some(())
}

#[cfg(unix)]
#[test]
fn euroc_rows_out_of_order_keep_every_left_frame() {
    let dir = tempfile::tempdir().unwrap();
    if euroc_copy(dir.path()).is_none() {
        return;
    }
    let csv = dir.path().join("mav0/cam0/data.csv");
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines: Vec<&str> = text.lines().collect();
    lines.swap(5, 6);
    std::fs::write(&csv, lines.join("\n")).unwrap();
    let seq = Sequence::open(dir.path()).unwrap();
    assert_eq!(seq.len(), 40);
    assert!(seq.timestamps.windows(2).all(|w| w[1] > w[0]));
    for i in 0..seq.len() {
        assert_eq!(
            seq.left_path(i).file_name(),
            seq.right_path(i).unwrap().file_name()
        );
    }
}

#[cfg(unix)]
#[test]
fn euroc_missing_right_row_keeps_the_left_frame_and_its_right_image_is_a_per_frame_error() {
    let dir = tempfile::tempdir().unwrap();
    if euroc_copy(dir.path()).is_none() {
        return;
    }
    let csv = dir.path().join("mav0/cam1/data.csv");
    let text = std::fs::read_to_string(&csv).unwrap();
    let lines: Vec<&str> = text
        .lines()
        .filter(|l| !l.starts_with("1403715273412"))
        .collect();
    assert_eq!(lines.len(), 40);
    std::fs::write(&csv, lines.join("\n")).unwrap();
    // the row is gone but the image is there: paired by its name (same timestamp)
    let seq = Sequence::open(dir.path()).unwrap();
    let k = (0..seq.len())
        .find(|&i| seq.left_path(i).to_string_lossy().contains("1403715273412"))
        .unwrap();
    assert_eq!(seq.len(), 40, "one frame per left row");
    assert!(seq.load_right(k).is_ok());
    // the image is gone too (cam1/data rebuilt as links to every image but that one): the
    // frame stays, its right image is an error naming the file
    let missing = seq.right_path(k).unwrap().file_name().unwrap().to_owned();
    let data = dir.path().join("mav0/cam1/data");
    let shared = std::fs::read_link(&data).unwrap();
    std::fs::remove_file(&data).unwrap(); // the link, not the shared data
    std::fs::create_dir(&data).unwrap();
    for e in std::fs::read_dir(&shared).unwrap() {
        let e = e.unwrap();
        if e.file_name() != missing {
            std::os::unix::fs::symlink(e.path(), data.join(e.file_name())).unwrap();
        }
    }
    let seq = Sequence::open(dir.path()).unwrap();
    assert_eq!(seq.len(), 40);
    let e = seq.load_right(k).unwrap_err().to_string();
    assert!(e.contains("1403715273412"), "{e}");
    assert!(seq.load_right(k + 1).is_ok());
}

/// Found by `tests/fuzz.rs`: a year of 2^32 in a raw `timestamps.txt` overflowed the seconds.
#[test]
fn raw_timestamp_with_a_huge_year_is_an_error_not_an_overflow() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("timestamps.txt");
    std::fs::write(&p, "4294967296-09-26 13:02:25.964389445\n").unwrap();
    let e = visnav_io::kitti::raw::read_raw_timestamps(&p)
        .unwrap_err()
        .to_string();
    assert!(e.contains("timestamps.txt:1"), "{e}");
}

/// Issue 21: a malformed row of `cam0/data.csv` or `cam1/data.csv` is an error naming the file
/// and the row's line, whichever camera it is in (before: an extra field became part of the
/// image name and failed later as a missing image without a line, a repeated timestamp named no
/// line).
#[cfg(unix)]
#[test]
fn euroc_malformed_rows_name_the_data_csv_line() {
    // (what the row becomes, what the message must say)
    type Mutate = dyn Fn(&str) -> String;
    let cases: [(&Mutate, &str); 5] = [
        (
            &|_| "12x4,frame.png".to_string(),
            "'12x4' is not a timestamp",
        ),
        (
            &|_| "1403715273262142976".to_string(),
            "'timestamp_ns,filename'",
        ),
        (&|row| format!("{row},extra"), "expected 2 fields"),
        (
            &|row| format!("{},", row.split(',').next().unwrap()),
            "file name",
        ),
        (&|_| "-5,frame.png".to_string(), "'-5' is not a timestamp"),
    ];
    for cam in ["cam0", "cam1"] {
        for (k, (mutate, expected)) in cases.iter().enumerate() {
            let dir = tempfile::tempdir().unwrap();
            if euroc_copy(dir.path()).is_none() {
                return;
            }
            let csv = dir.path().join("mav0").join(cam).join("data.csv");
            let text = std::fs::read_to_string(&csv).unwrap();
            let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
            // line 8 of the file (the header is line 1)
            lines[7] = mutate(&lines[7]);
            std::fs::write(&csv, lines.join("\n")).unwrap();
            let e = Sequence::open(dir.path()).unwrap_err();
            let msg = e.to_string();
            assert!(
                matches!(e, IoError::Parse { line: 8, .. }),
                "{cam} case {k}: {msg}"
            );
            assert!(
                msg.contains(&format!("{cam}/data.csv:8:")) && msg.contains(expected),
                "{cam} case {k}: {msg}"
            );
        }
        // a repeated timestamp names the second row's line and the first's
        let dir = tempfile::tempdir().unwrap();
        euroc_copy(dir.path()).unwrap();
        let csv = dir.path().join("mav0").join(cam).join("data.csv");
        let text = std::fs::read_to_string(&csv).unwrap();
        let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
        let t = lines[3].split(',').next().unwrap().to_string();
        lines[9] = format!("{t},copy.png");
        std::fs::write(&csv, lines.join("\n")).unwrap();
        let msg = Sequence::open(dir.path()).unwrap_err().to_string();
        assert!(
            msg.contains(&format!("{cam}/data.csv:10:")) && msg.contains("of line 4"),
            "{cam} duplicate: {msg}"
        );
    }
}
