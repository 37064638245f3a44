//! Issue 53 item 7: the camera files users already have. ORB-SLAM2/3 and OpenCV settings files
//! (`%YAML:1.0`, `Camera.fx: …`, `Camera1.fx`, `Camera.bf`, `Stereo.b`, `Stereo.T_c1_c2`, the
//! pre-rectification `LEFT.*`/`RIGHT.*`) are read as camera files; they were refused with
//! "unknown field `Camera.fx`, expected one of `cam0`, `cam1`, `rate_hz`". The cameras they give
//! equal the ones visnav reads from KITTI 00's `calib.txt` and EuRoC's `sensor.yaml` files.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};

use visnav_core::Pose;
use visnav_core::distortion::Distortion;
use visnav_core::testdata::shared_data;
use visnav_io::Sequence;
use visnav_io::calibration::{RigCalibration, read_camera_file, read_euroc_sensor};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/orb_slam")
        .join(name)
}

fn read(name: &str) -> RigCalibration {
    read_camera_file(&fixture(name)).unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// Rotation angle (rad) and translation distance (m) between two poses.
fn pose_gap(a: &Pose, b: &Pose) -> (f64, f64) {
    let d = a.inverse() * b;
    (d.rotation.angle(), d.translation.vector.norm())
}

#[test]
fn kitti_settings_give_the_camera_of_kitti_00s_calib_txt() {
    let Some(kitti00) = shared_data("kitti/odometry/sequences/00") else {
        return;
    };
    let seq = Sequence::open(&kitti00).unwrap();
    let calib = visnav_io::kitti::read_odometry_calib(&kitti00.join("calib.txt")).unwrap();
    let p1 = calib.p1.unwrap();
    let kitti_baseline_m = -p1[(0, 3)] / p1[(0, 0)];

    let mono = read("kitti00-02_mono_orbslam3.yaml");
    assert_eq!(mono.left.pinhole, seq.camera);
    assert!(mono.left.distortion.is_identity());
    assert!(mono.right.is_none());
    assert_eq!(mono.rate_hz, Some(10.0));

    // ORB-SLAM2: Camera.bf = baseline × fx, exactly KITTI's -P1[0][3]
    let stereo2 = read("kitti00-02_stereo_orbslam2.yaml");
    assert_eq!(stereo2.left.pinhole, seq.camera);
    let (right, right_from_left) = stereo2.right.unwrap();
    assert_eq!(right, stereo2.left);
    assert_eq!(right_from_left.rotation.angle(), 0.0);
    let t = right_from_left.translation.vector;
    assert!(
        (t.x + kitti_baseline_m).abs() < 1e-12,
        "{t:?} vs {kitti_baseline_m}"
    );
    assert_eq!((t.y, t.z), (0.0, 0.0));

    // ORB-SLAM3: "Rectified" with Stereo.b = 0.53716 (KITTI's 0.5371657 rounded)
    let stereo3 = read("kitti00-02_stereo_orbslam3.yaml");
    assert_eq!(stereo3.left.pinhole, seq.camera);
    assert_eq!(stereo3.left.distortion, Distortion::None);
    let (_, right_from_left) = stereo3.right.unwrap();
    assert!((right_from_left.translation.vector.x + kitti_baseline_m).abs() < 1e-5);
}

#[test]
fn euroc_settings_give_the_cameras_of_its_sensor_yaml_files() {
    let Some(mav0) = shared_data("euroc/V1_01_easy_first40/mav0") else {
        return;
    };
    let (cam0, body_from_cam0) = read_euroc_sensor(&mav0.join("cam0/sensor.yaml")).unwrap();
    let (cam1, body_from_cam1) = read_euroc_sensor(&mav0.join("cam1/sensor.yaml")).unwrap();
    let cam1_from_cam0 = body_from_cam1.inverse() * body_from_cam0;

    let mono = read("euroc_mono_orbslam3.yaml");
    assert_eq!(mono.left, cam0);
    assert_eq!(mono.rate_hz, Some(20.0));

    // ORB-SLAM3: Camera2 and Stereo.T_c1_c2 (left_from_right, 15 digits)
    let stereo3 = read("euroc_stereo_orbslam3.yaml");
    assert_eq!(stereo3.left, cam0);
    let (right, right_from_left) = stereo3.right.unwrap();
    assert_eq!(right, cam1);
    let (angle, distance) = pose_gap(&right_from_left, &cam1_from_cam0);
    assert!(angle < 1e-6 && distance < 1e-6, "{angle} rad, {distance} m");

    // ORB-SLAM2: the raw cameras of LEFT.K/D, RIGHT.K/D and the extrinsics of its rectification
    // (LEFT.R, RIGHT.R, RIGHT.P), which OpenCV computed from the same calibration
    let stereo2 = read("euroc_stereo_orbslam2.yaml");
    assert_eq!(stereo2.left.pinhole, cam0.pinhole);
    assert_eq!(
        stereo2.left.distortion.coefficients()[..4],
        cam0.distortion.coefficients()[..4]
    );
    let (right, right_from_left) = stereo2.right.unwrap();
    assert_eq!(right.pinhole, cam1.pinhole);
    let (angle, distance) = pose_gap(&right_from_left, &cam1_from_cam0);
    assert!(angle < 1e-5 && distance < 1e-5, "{angle} rad, {distance} m");

    // the EuRoC sequence opened with the ORB-SLAM3 file is rectified as with its sensor.yaml
    let euroc = mav0.parent().unwrap();
    let own = Sequence::open(euroc).unwrap();
    let orb =
        Sequence::open_with_camera(euroc, Some(&fixture("euroc_stereo_orbslam3.yaml"))).unwrap();
    let (a, b) = (own.camera, orb.camera);
    assert!(
        (a.fx - b.fx).abs() < 1e-3 && (a.cx - b.cx).abs() < 1e-3,
        "{a:?} vs {b:?}"
    );
    let (ba, bb) = (own.baseline_m.unwrap(), orb.baseline_m.unwrap());
    assert!((ba - bb).abs() < 1e-6, "{ba} vs {bb}");
}

/// The settings' own checks, each error naming the file, the line and the key.
#[test]
fn bad_settings_are_errors_naming_the_file_line_and_key() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("settings.yaml");
    let stereo = std::fs::read_to_string(fixture("euroc_stereo_orbslam3.yaml")).unwrap();
    let rect = std::fs::read_to_string(fixture("kitti00-02_stereo_orbslam3.yaml")).unwrap();
    let line_of = |text: &str, key: &str| {
        1 + text
            .lines()
            .position(|l| l.starts_with(key))
            .unwrap_or_else(|| panic!("{key}"))
    };
    let cases = [
        (
            stereo.replace("Camera1.fx:", "Camera1.fxx:"),
            "Camera1.fxx",
            "unknown key",
        ),
        (
            stereo.replace("Camera1.cy: 248.375\n", ""),
            "",
            "Camera1.cy: missing",
        ),
        (
            stereo.replace("Camera.width: 752\n", ""),
            "",
            "Camera.width: missing",
        ),
        (
            stereo.replace("Camera1.p2: 1.76187114e-05\n", ""),
            "",
            "Camera1.p2: missing",
        ),
        (
            stereo.replace("Stereo.T_c1_c2:", "Stereo.T_c1_c3:"),
            "Stereo.T_c1_c3",
            "unknown key",
        ),
        (
            stereo.replace("0.999997256477797,", "0.5,"),
            "Stereo.T_c1_c2",
            "not a rotation",
        ),
        (
            stereo.replace("  rows: 4\n", "  rows: 3\n"),
            "Stereo.T_c1_c2",
            "3x4 needs 12 numbers",
        ),
        (
            stereo.replace("\"PinHole\"", "\"Fisheye\""),
            "Camera.type",
            "not supported",
        ),
        (
            stereo.replace("Camera.width: 752", "Camera.width: -752"),
            "Camera.width",
            "positive whole number",
        ),
        (
            stereo.replace("Camera1.fx: 458.654", "Camera1.fx: nan"),
            "Camera1.fx",
            "expected a number",
        ),
        (
            rect.replace("0.53716", "-0.53716"),
            "Stereo.b",
            "must be positive",
        ),
        (
            rect.replace("Stereo.b:", "Camera1.k1: 0.1\nStereo.b:"),
            "Camera1.k1",
            "no distortion",
        ),
    ];
    for (text, key, what) in cases {
        std::fs::write(&p, &text).unwrap();
        let e = read_camera_file(&p).unwrap_err().to_string();
        assert!(e.contains("settings.yaml"), "{key} {what}: {e}");
        assert!(e.contains(what), "{key} {what}: {e}");
        if !key.is_empty() {
            let line = line_of(&text, key);
            assert!(
                e.contains(&format!("settings.yaml:{line}: {key}")),
                "{key} at line {line}: {e}"
            );
        }
    }
    // Camera2 without the extrinsics, and the extrinsics without Camera2
    let no_t: String = stereo.split("Stereo.T_c1_c2").next().unwrap().to_string();
    std::fs::write(&p, &no_t).unwrap();
    let e = read_camera_file(&p).unwrap_err().to_string();
    assert!(
        e.contains("Camera2.fx") && e.contains("Stereo.T_c1_c2"),
        "{e}"
    );
    let no_camera2: String = stereo
        .lines()
        .filter(|l| !l.starts_with("Camera2."))
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(&p, &no_camera2).unwrap();
    let e = read_camera_file(&p).unwrap_err().to_string();
    assert!(e.contains("second camera is missing"), "{e}");
}

/// A KannalaBrandt8 (fisheye) settings file is an equidistant camera, also a stereo one in the
/// shape of ORB-SLAM3's `Examples/Stereo/TUM-VI.yaml` (with its `overlapping` columns);
/// ORB-SLAM2's `bFishEye` flag is refused by name.
#[test]
fn fisheye_settings() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("tumvi.yaml");
    let text = "%YAML:1.0\nCamera.type: \"KannalaBrandt8\"\nCamera1.fx: 190.978\nCamera1.fy: 190.973\nCamera1.cx: 254.932\nCamera1.cy: 256.897\nCamera1.k1: 0.00348\nCamera1.k2: 0.00071\nCamera1.k3: -0.00203\nCamera1.k4: 0.00021\nCamera.width: 512\nCamera.height: 512\nCamera.fps: 20\n";
    std::fs::write(&p, text).unwrap();
    let calib = read_camera_file(&p).unwrap();
    assert_eq!(
        calib.left.distortion,
        Distortion::Equidistant {
            k1: 0.00348,
            k2: 0.00071,
            k3: -0.00203,
            k4: 0.00021
        }
    );
    let stereo = format!(
        "{text}Camera2.fx: 190.442\nCamera2.fy: 190.434\nCamera2.cx: 252.599\nCamera2.cy: 254.917\nCamera2.k1: 0.00340\nCamera2.k2: 0.00177\nCamera2.k3: -0.00266\nCamera2.k4: 0.00033\nStereo.T_c1_c2: !!opencv-matrix\n  rows: 4\n  cols: 4\n  dt: f\n  data: [ 0.999999445773493,   0.000791687752817,   0.000694034010224,   0.101063427414194,\n            -0.000823363992158,   0.998899461915674,   0.046895490788700,   0.001946204678584,\n            -0.000656143613644,  -0.046896036240590,   0.998899560146304,   0.001015350132563,\n            0.0,0.0,0.0,1.0]\nCamera.overlappingBegin: 0\nCamera.overlappingEnd: 511\nCamera2.overlappingBegin: 0\nCamera2.overlappingEnd: 511\nStereo.ThDepth: 40.0\n"
    );
    std::fs::write(&p, &stereo).unwrap();
    let calib = read_camera_file(&p).unwrap();
    let (right, right_from_left) = calib.right.unwrap();
    assert!(matches!(right.distortion, Distortion::Equidistant { .. }));
    // T_c1_c2 is left_from_right: the right camera sits 0.101 m along the left one's x
    let left_from_right = right_from_left.inverse();
    assert!((left_from_right.translation.vector.x - 0.101_063_427_414_194).abs() < 1e-12);
    std::fs::write(&p, text.replace("Camera1.k4: 0.00021\n", "")).unwrap();
    let e = read_camera_file(&p).unwrap_err().to_string();
    assert!(e.contains("Camera1.k4: missing"), "{e}");
    let orb2 = std::fs::read_to_string(fixture("kitti00-02_stereo_orbslam2.yaml")).unwrap();
    std::fs::write(&p, orb2.replace("bFishEye: 0", "bFishEye: 1")).unwrap();
    let e = read_camera_file(&p).unwrap_err().to_string();
    assert!(
        e.contains("Camera.bFishEye") && e.contains("KannalaBrandt8"),
        "{e}"
    );
}
