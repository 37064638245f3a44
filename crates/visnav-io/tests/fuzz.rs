//! Property-based fuzzing of every parser of `visnav-io` (issue 21; the harness and its
//! properties: `fuzz_harness`): no panic, no hang, allocation bounded by the input, a result or
//! an error naming the file (and a line that exists), and a BOM + CRLF copy read as the original.
//!
//! Seeds are the real files of `VISNAV_DATA` when it is set (KITTI `calib.txt`, `times.txt`,
//! ground-truth poses, EuRoC `data.csv` and `sensor.yaml`), the ORB-SLAM settings fixtures, plus
//! small embedded samples of every format, so that the suite also runs without the data.
//!
//! Case counts: `VISNAV_FUZZ_CASES` cases per parser (default 48: the whole suite takes a few
//! seconds in a test build). A long campaign:
//! `VISNAV_FUZZ_CASES=100000 cargo test -p visnav-io --test fuzz`.
#![allow(clippy::unwrap_used)]

mod fuzz_harness;

use std::path::Path;

use fuzz_harness::{campaign, outcome, seeds};

const CALIB: &str = "P0: 718.856 0 607.1928 0 0 718.856 185.2157 0 0 0 1 0
P1: 718.856 0 607.1928 -386.1448 0 718.856 185.2157 0 0 0 1 0
P2: 718.856 0 607.1928 45.38225 0 718.856 185.2157 -0.1130887 0 0 1 0.003779761
P3: 718.856 0 607.1928 -337.2877 0 718.856 185.2157 2.369057 0 0 1 0.004915215
Tr: 4.276802385584e-04 -9.999672484946e-01 -8.084491683471e-03 -1.198459927713e-02 -7.210626507497e-03 8.081198471645e-03 -9.999413164504e-01 -5.403984729748e-02 9.999738645903e-01 4.859485810390e-04 -7.206933692422e-03 -2.921968648686e-01
";

const RAW_CALIB: &str = "calib_time: 09-Jan-2012 13:57:47
corner_dist: 9.950000e-02
S_rect_00: 1.242000e+03 3.750000e+02
P_rect_00: 7.215377e+02 0.000000e+00 6.095593e+02 0.000000e+00 0.000000e+00 7.215377e+02 1.728540e+02 0.000000e+00 0.000000e+00 0.000000e+00 1.000000e+00 0.000000e+00
P_rect_01: 7.215377e+02 0.000000e+00 6.095593e+02 -3.875744e+02 0.000000e+00 7.215377e+02 1.728540e+02 0.000000e+00 0.000000e+00 0.000000e+00 1.000000e+00 0.000000e+00
";

const KITTI_POSES: &str = "1.000000e+00 9.043680e-12 2.326809e-11 5.551115e-17 9.043683e-12 1.000000e+00 2.392370e-10 3.330669e-16 2.326810e-11 2.392370e-10 9.999999e-01 -4.440892e-16
9.999978e-01 5.272628e-04 -2.066935e-03 -4.690294e-02 -5.296506e-04 9.999992e-01 -1.154865e-03 -2.839928e-02 2.066324e-03 1.155958e-03 9.999971e-01 8.586941e-01
9.999910e-01 1.048972e-03 -4.131348e-03 -9.374345e-02 -1.058514e-03 9.999968e-01 -2.308104e-03 -5.676064e-02 4.128913e-03 2.312456e-03 9.999887e-01 1.716275e+00
";

const TUM: &str = "# timestamp tx ty tz qx qy qz qw
1305031102.175304 1.3405 0.6266 1.6575 0.6574 0.6126 -0.2949 -0.3248
1305031102.211214 1.3303 0.6256 1.6464 0.6579 0.6161 -0.2932 -0.3189
1305031102.243211 1.3160 0.6254 1.6302 0.6609 0.6199 -0.2893 -0.3086
";

const EUROC_GT: &str = "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], v_RS_R_x [m s^-1]
1403715273262142976,0.878612,2.142470,0.947262,0.060514,-0.828314,-0.058630,-0.553837,0.009474
1403715273267142912,0.878590,2.142512,0.947287,0.060501,-0.828297,-0.058663,-0.553862,0.009542
";

const G2O: &str = "# a comment
VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1
VERTEX_SE3:QUAT 1 1.5 0.25 -0.125 0 0 0.0998334 0.995004
VERTEX_SE3:QUAT 2 3 0.5 -0.25 0 0 0.198669 0.980067
EDGE_SE3:QUAT 0 1 1.5 0.25 -0.125 0 0 0.0998334 0.995004 100 0 0 0 0 0 100 0 0 0 0 100 0 0 0 400 0 0 400 0 400
EDGE_SE3:QUAT 1 2 1.5 0.25 -0.125 0 0 0.0998334 0.995004 100 1 0 0 0 0 100 0 0 0 0 100 0 0 0 400 0 0 400 0 -400
FIX 0
";

const DATA_CSV: &str = "#timestamp [ns],filename
1403715273262142976,1403715273262142976.png
1403715273312143104,1403715273312143104.png
1403715273362142976,1403715273362142976.png
";

const RGB_TXT: &str = "# color images
# timestamp filename
1305031102.175304 rgb/1305031102.175304.png
1305031102.211214 rgb/1305031102.211214.png
";

const TIMES: &str = "0.000000e+00\n1.036224e-01\n2.072448e-01\n3.108673e-01\n";

const RAW_TIMES: &str = "2011-09-26 13:02:25.964389445
2011-09-26 13:02:26.067700756
2011-09-26 13:02:26.171153311
";

const CAMERA_YAML: &str = "cam0:
  camera_model: pinhole
  intrinsics: [458.654, 457.296, 367.215, 248.375]
  distortion_model: radtan
  distortion_coeffs: [-0.2834, 0.0740, 0.00019, 1.76e-05]
  resolution: [752, 480]
cam1:
  camera_model: pinhole
  intrinsics: [457.587, 456.134, 379.999, 255.238]
  distortion_model: radtan
  distortion_coeffs: [-0.2837, 0.0745, -0.0001, -3.6e-05]
  resolution: [752, 480]
  T_cn_cnm1:
  - [0.99999, 0.00231, 0.00037, -0.11007]
  - [-0.00231, 0.99996, 0.00857, 0.00040]
  - [-0.00035, -0.00857, 0.99996, -0.00085]
  - [0.0, 0.0, 0.0, 1.0]
rate_hz: 20
";

const CAMERA_TOML: &str = "rate_hz = 20
[cam0]
camera_model = \"pinhole\"
intrinsics = [458.654, 457.296, 367.215, 248.375]
distortion_model = \"equidistant\"
distortion_coeffs = [0.1, -0.01, 0.001, 0.0001]
resolution = [752, 480]
";

const SENSOR_YAML: &str = "%YAML:1.0
sensor_type: camera
T_BS:
  cols: 4
  rows: 4
  data: [0.0148655429818, -0.999880929698, 0.00414029679422, -0.0216401454975,
         0.999557249008, 0.0149672133247, 0.025715529948, -0.064676986768,
        -0.0257744366974, 0.00375618835797, 0.999660727178, 0.00981073058949,
         0.0, 0.0, 0.0, 1.0]
rate_hz: 20
resolution: [752, 480]
camera_model: pinhole
intrinsics: [458.654, 457.296, 367.215, 248.375] #fu, fv, cu, cv
distortion_model: radial-tangential
distortion_coefficients: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]
";

const DSO_CAMERA: &[&str] = &[
    "0.535185 0.669236 0.493176 0.500151 0.897966\n640 480\ncrop\n640 480\n",
    "Pinhole 458.654 457.296 367.215 248.375 0\n752 480\n0.4 0.53 0.5 0.5 0\n640 480\n",
];

const MONO_TIMES: &str =
    "00000 1399381444.705361 20.0\n00001 1399381444.740360 20.0\n00002 1399381444.775360\n";

#[test]
fn fuzz_kitti_calib() {
    let s = seeds(&[CALIB], &[("kitti/odometry/sequences/00/calib.txt", 10)]);
    campaign(
        "calib.txt",
        "calib.txt",
        |p| outcome(visnav_io::kitti::read_odometry_calib(p), |_| 60),
        &s,
        true,
    );
    let s = seeds(&[RAW_CALIB], &[]);
    campaign(
        "calib_cam_to_cam.txt",
        "calib_cam_to_cam.txt",
        |p| outcome(visnav_io::kitti::raw::read_raw_calib(p), |_| 24),
        &s,
        true,
    );
}

#[test]
fn fuzz_times() {
    let s = seeds(&[TIMES], &[("kitti/odometry/sequences/06/times.txt", 60)]);
    campaign(
        "times.txt",
        "times.txt",
        |p| outcome(visnav_io::kitti::read_times(p), Vec::len),
        &s,
        true,
    );
    let s = seeds(&[RAW_TIMES], &[]);
    campaign(
        "raw timestamps.txt",
        "timestamps.txt",
        |p| outcome(visnav_io::kitti::raw::read_raw_timestamps(p), Vec::len),
        &s,
        true,
    );
    let s = seeds(&[MONO_TIMES], &[]);
    campaign(
        "monoVO times.txt",
        "times.txt",
        |p| outcome(visnav_io::tum_mono::read_frame_times(p), Vec::len),
        &s,
        true,
    );
}

#[test]
fn fuzz_trajectories() {
    let traj = |p: &Path| {
        outcome(visnav_io::trajectory::read_trajectory(p), |t| {
            t.poses.len() * 7
        })
    };
    let s = seeds(&[KITTI_POSES], &[("kitti/odometry/poses/00.txt", 40)]);
    campaign("KITTI trajectory", "poses.txt", traj, &s, true);
    campaign(
        "KITTI matrices",
        "poses.txt",
        |p| {
            outcome(visnav_io::trajectory::read_kitti_matrices(p), |m| {
                m.len() * 12
            })
        },
        &s,
        true,
    );
    let s = seeds(&[TUM], &[]);
    campaign("TUM trajectory", "traj.tum", traj, &s, true);
    let s = seeds(&[EUROC_GT], &[]);
    campaign("EuRoC ground truth", "data.csv", traj, &s, true);
}

#[test]
fn fuzz_frame_lists() {
    let s = seeds(
        &[DATA_CSV],
        &[("euroc/V1_01_easy_first40/mav0/cam0/data.csv", 41)],
    );
    campaign(
        "EuRoC data.csv",
        "data.csv",
        |p| outcome(visnav_io::layouts::read_euroc_csv(p), Vec::len),
        &s,
        true,
    );
    let s = seeds(&[RGB_TXT], &[]);
    campaign(
        "TUM rgb.txt",
        "rgb.txt",
        |p| outcome(visnav_io::layouts::read_tum_list(p), Vec::len),
        &s,
        true,
    );
}

#[test]
fn fuzz_g2o() {
    let s = seeds(&[G2O], &[("posegraph/tinyGrid3D.g2o", 40)]);
    campaign(
        "g2o",
        "graph.g2o",
        |p| {
            outcome(visnav_io::g2o::read_g2o(p), |g| {
                g.vertices.len() * 8 + g.edges.len() * 30
            })
        },
        &s,
        true,
    );
}

#[test]
fn fuzz_camera_files() {
    let s = seeds(&[CAMERA_YAML], &[]);
    campaign(
        "Kalibr camera.yaml",
        "camera.yaml",
        |p| outcome(visnav_io::calibration::read_camera_file(p), |_| 40),
        &s,
        true,
    );
    let s = seeds(&[CAMERA_TOML], &[]);
    campaign(
        "camera.toml",
        "camera.toml",
        |p| outcome(visnav_io::calibration::read_camera_file(p), |_| 40),
        &s,
        true,
    );
    let s = seeds(
        &[SENSOR_YAML],
        &[("euroc/V1_01_easy_first40/mav0/cam0/sensor.yaml", 40)],
    );
    campaign(
        "EuRoC sensor.yaml",
        "sensor.yaml",
        |p| outcome(visnav_io::calibration::read_euroc_sensor(p), |_| 40),
        &s,
        true,
    );
    // ORB-SLAM2/3 and OpenCV settings files (issue 53): the six fixtures (monocular, Camera.bf,
    // Stereo.b, Camera2 + Stereo.T_c1_c2, the pre-rectification LEFT/RIGHT matrices)
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/orb_slam");
    let mut s: Vec<Vec<u8>> = std::fs::read_dir(&fixtures)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "yaml"))
        .map(|p| std::fs::read(p).unwrap())
        .collect();
    s.sort();
    assert_eq!(s.len(), 6);
    campaign(
        "ORB-SLAM settings",
        "settings.yaml",
        |p| outcome(visnav_io::calibration::read_camera_file(p), |_| 40),
        &s,
        true,
    );
    let s = seeds(DSO_CAMERA, &[]);
    campaign(
        "monoVO camera.txt",
        "camera.txt",
        |p| outcome(visnav_io::tum_mono::read_dso_camera(p), |_| 20),
        &s,
        true,
    );
}

/// A small `.flo` file.
fn flo_seed() -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("a.flo");
    let mut f = visnav_io::flo::FlowField::zeros(5, 3);
    f.set(1, 2, 1.5, -2.5);
    f.set(4, 0, 1e10, 0.0);
    visnav_io::flo::write_flo(&p, &f).unwrap();
    std::fs::read(p).unwrap()
}

/// Small PFM files, one and three channels, both byte orders.
fn pfm_seeds() -> Vec<Vec<u8>> {
    let dir = tempfile::tempdir().unwrap();
    let mut out = Vec::new();
    for channels in [1, 3] {
        let p = dir.path().join("a.pfm");
        let img = visnav_io::pfm::PfmImage {
            width: 4,
            height: 3,
            channels,
            data: (0..12 * channels).map(|i| i as f32 * 0.25 - 1.0).collect(),
        };
        visnav_io::pfm::write_pfm(&p, &img).unwrap();
        out.push(std::fs::read(&p).unwrap());
    }
    let mut big_endian = b"Pf\n2 1\n1.0\n".to_vec();
    big_endian.extend_from_slice(&1.5f32.to_be_bytes());
    big_endian.extend_from_slice(&(-3.0f32).to_be_bytes());
    out.push(big_endian);
    out
}

/// A small 16-bit KITTI flow PNG.
fn kitti_flow_seed() -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("000000_10.png");
    let img = image::ImageBuffer::<image::Rgb<u16>, Vec<u16>>::from_fn(6, 4, |x, y| {
        let x = u16::try_from(x).unwrap();
        let y = u16::try_from(y).unwrap();
        image::Rgb([32768 + 64 * x, 32768 - 32 * y, (x + y) % 2])
    });
    image::DynamicImage::ImageRgb16(img).save(&p).unwrap();
    std::fs::read(p).unwrap()
}

#[test]
fn fuzz_binary_formats() {
    campaign(
        ".flo",
        "flow.flo",
        |p| outcome(visnav_io::flo::read_flo(p), |f| 4 * f.uv.len()),
        &[flo_seed()],
        false,
    );
    campaign(
        "PFM",
        "info.pfm",
        |p| outcome(visnav_io::pfm::read_pfm(p), |i| 4 * i.data.len()),
        &pfm_seeds(),
        false,
    );
    campaign(
        "KITTI flow PNG",
        "000000_10.png",
        |p| {
            outcome(
                visnav_io::kitti_flow::read_kitti_flow_png(p),
                |(f, known)| {
                    // a PNG compresses: bounded by the decoder's limits, not the file size
                    (f.uv.len() + known.len()).min(64)
                },
            )
        },
        &[kitti_flow_seed()],
        false,
    );
}

/// Header extremes of the binary formats, which byte flips rarely reach: every one is a clean
/// error or a correct result, without a huge allocation.
#[test]
fn binary_headers_with_extreme_sizes() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("x.pfm");
    let sizes = [
        "0",
        "-1",
        "1",
        "3",
        "4294967296",
        "18446744073709551615",
        "1e308",
        "nan",
        "99999999999999999999",
    ];
    let scales = [
        "0", "-0", "nan", "inf", "-inf", "-1", "1", "1e-320", "-1e308",
    ];
    for w in sizes {
        for h in sizes {
            for s in scales {
                let mut bytes = format!("PF\n{w} {h}\n{s}\n").into_bytes();
                bytes.extend_from_slice(&[0u8; 36]);
                std::fs::write(&p, &bytes).unwrap();
                if let Ok(img) = visnav_io::pfm::read_pfm(&p) {
                    assert!(img.data.len() * 4 <= bytes.len(), "{w} {h} {s}");
                }
            }
        }
    }
    let p = dir.path().join("x.flo");
    for (w, h) in [
        (i32::MAX, i32::MAX),
        (-1, 1),
        (0, 0),
        (100_000, 100_000),
        (1, 3),
    ] {
        let mut bytes = 202_021.25f32.to_le_bytes().to_vec();
        bytes.extend_from_slice(&w.to_le_bytes());
        bytes.extend_from_slice(&h.to_le_bytes());
        bytes.extend_from_slice(&[0u8; 24]);
        std::fs::write(&p, &bytes).unwrap();
        let r = visnav_io::flo::read_flo(&p);
        assert_eq!(r.is_ok(), (w, h) == (1, 3), "{w}x{h}");
    }
}
