//! Window bundle adjustment (`visnav_odometry::ba`) on synthetic stereo tracks with exact ground
//! truth: exact recovery without noise, and with pixel noise and 20 % gross outliers a lower pose
//! error than the frame-to-frame RotROCC estimate it starts from.

#![allow(clippy::unwrap_used)] // fixtures of a fixed, valid synthetic scene

use nalgebra::{Point2, Point3, Vector3, Vector6};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use visnav_core::se3::{rotation_angle, se3_exp};
use visnav_core::{PinholeCamera, Pose, StereoCamera};
use visnav_odometry::RelativeMotion;
use visnav_odometry::ba::{BaConfig, Observation, WindowBa};
use visnav_odometry::stereo::StereoConfig;
use visnav_odometry::stereo::estimate::{Observation as F2fObservation, estimate_motion};

const FRAMES: usize = 8;

fn rig() -> StereoCamera {
    StereoCamera::new(PinholeCamera::kitti_default(), 0.54).unwrap()
}

/// `cam_from_world` of a drive: 1.2 m forward a frame, yawing 0.8° a frame.
fn truth() -> Vec<Pose> {
    (0..FRAMES)
        .map(|k| {
            let k = k as f64;
            let world_from_cam =
                se3_exp(&Vector6::new(0.05 * k, 0.0, 1.2 * k, 0.0, 0.014 * k, 0.0));
            world_from_cam.inverse()
        })
        .collect()
}

fn scene(rng: &mut ChaCha8Rng) -> Vec<Point3<f64>> {
    (0..400)
        .map(|_| {
            Point3::new(
                rng.random_range(-14.0..14.0),
                rng.random_range(-3.0..1.6),
                rng.random_range(6.0..45.0),
            )
        })
        .collect()
}

/// Noisy stereo measurements `(frame, point, left px, right u)`; `outliers` of them moved by
/// 10–40 px.
fn measure(
    poses: &[Pose],
    points: &[Point3<f64>],
    sigma: f64,
    outliers: f64,
    rng: &mut ChaCha8Rng,
) -> Vec<(usize, usize, Point2<f64>, f64)> {
    let rig = rig();
    let noise = Normal::new(0.0, sigma.max(1e-300)).unwrap();
    let mut out = Vec::new();
    for (k, t) in poses.iter().enumerate() {
        for (j, x) in points.iter().enumerate() {
            let p = t * x;
            let (Some(l), Some(r)) = (rig.left.project(&p), rig.project_right(&p)) else {
                continue;
            };
            if p.z < 1.0 || !(0.0..1241.0).contains(&l.x) || !(0.0..376.0).contains(&l.y) {
                continue;
            }
            let mut e = Vector3::from_fn(|_, _| if sigma > 0.0 { noise.sample(rng) } else { 0.0 });
            if rng.random::<f64>() < outliers {
                let sign = if rng.random::<bool>() { 1.0 } else { -1.0 };
                e += Vector3::new(
                    sign * rng.random_range(10.0..40.0),
                    rng.random_range(-20.0..20.0),
                    0.0,
                );
            }
            out.push((k, j, Point2::new(l.x + e.x, l.y + e.y), r.x + e.x + e.z));
        }
    }
    out
}

/// The frame-to-frame RotROCC trajectory (`cam_from_world`, frame 0 = truth) from the
/// measurements.
fn frame_to_frame(meas: &[(usize, usize, Point2<f64>, f64)], first: Pose) -> Vec<Pose> {
    let rig = rig();
    let config = StereoConfig::default();
    let mut poses = vec![first];
    let mut motion = Pose::identity();
    for k in 1..FRAMES {
        let obs: Vec<F2fObservation> = meas
            .iter()
            .filter(|m| m.0 == k)
            .filter_map(|&(_, j, l, ur)| {
                let prev = meas.iter().find(|m| m.0 == k - 1 && m.1 == j)?;
                let p = rig.triangulate(&prev.2, prev.2.x - prev.3)?;
                Some(F2fObservation {
                    p_in_prev: p.coords,
                    left_px: l,
                    right_px: Point2::new(ur, l.y),
                    right_row_offset_px: 0.0,
                })
            })
            .collect();
        motion = estimate_motion(
            &rig,
            &obs,
            &RelativeMotion::from_cur_from_prev(motion),
            &config,
        )
        .unwrap()
        .motion
        .cur_from_prev();
        poses.push(motion * poses[k - 1]);
    }
    poses
}

/// The window problem started from `poses`, each point from its first measurement.
fn window(
    poses: &[Pose],
    meas: &[(usize, usize, Point2<f64>, f64)],
    n_points: usize,
    sigma: f64,
) -> WindowBa {
    let rig = rig();
    let mut points_w = vec![Point3::origin(); n_points];
    let mut seen = vec![false; n_points];
    for &(k, j, l, ur) in meas {
        if !seen[j]
            && let Some(p) = rig.triangulate(&l, l.x - ur)
        {
            points_w[j] = poses[k].inverse() * p;
            seen[j] = true;
        }
    }
    let observations = meas
        .iter()
        .filter(|m| seen[m.1])
        .map(|&(frame, point, left_px, right_u)| Observation {
            frame,
            point,
            left_px,
            right_u_px: Some(right_u),
            sigma_px: sigma.max(0.5),
            right_sigma_px: sigma.max(0.5),
        })
        .collect();
    WindowBa {
        rig,
        cam_from_world: poses.to_vec(),
        points_w,
        observations,
    }
}

/// Mean translation (m) and rotation (deg) error of `world_from_cam` against the truth.
fn errors(est: &[Pose], truth: &[Pose]) -> (f64, f64) {
    let n = est.len() as f64;
    let (mut t, mut r) = (0.0, 0.0);
    for (a, b) in est.iter().zip(truth) {
        let d = b * a.inverse();
        t += (a.inverse().translation.vector - b.inverse().translation.vector).norm();
        r += rotation_angle(&d).to_degrees();
    }
    (t / n, r / n)
}

#[test]
fn noise_free_tracks_give_the_exact_poses() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let truth = truth();
    let points = scene(&mut rng);
    let meas = measure(&truth, &points, 0.0, 0.0, &mut rng);
    // start 0.2 m and ~1° off on every free frame
    let start: Vec<Pose> = truth
        .iter()
        .enumerate()
        .map(|(k, t)| {
            if k == 0 {
                *t
            } else {
                se3_exp(&Vector6::new(0.2, -0.1, 0.15, 0.01, -0.015, 0.008)) * t
            }
        })
        .collect();
    let mut ba = window(&start, &meas, points.len(), 0.0);
    let report = ba
        .solve(&BaConfig {
            max_iterations: 30,
            ..BaConfig::default()
        })
        .unwrap();
    let (t, r) = errors(&ba.cam_from_world, &truth);
    assert!(t < 1e-6 && r < 1e-6, "{t} m {r} deg, {report:?}");
    assert!(
        report.final_cost < 1e-12 * report.initial_cost.max(1.0),
        "{report:?}"
    );
}

#[test]
fn with_noise_and_outliers_it_beats_frame_to_frame() {
    let mut worse = Vec::new();
    for seed in 0..4 {
        let mut rng = ChaCha8Rng::seed_from_u64(10 + seed);
        let truth = truth();
        let points = scene(&mut rng);
        let meas = measure(&truth, &points, 0.5, 0.2, &mut rng);
        let f2f = frame_to_frame(&meas, truth[0]);
        let mut ba = window(&f2f, &meas, points.len(), 0.5);
        let report = ba.solve(&BaConfig::default()).unwrap();
        let (t0, r0) = errors(&f2f, &truth);
        let (t1, r1) = errors(&ba.cam_from_world, &truth);
        eprintln!(
            "seed {seed}: frame-to-frame {t0:.4} m {r0:.4} deg, BA {t1:.4} m {r1:.4} deg, {report:?}"
        );
        assert!(report.final_cost < report.initial_cost);
        // the dropped outliers are the moved measurements: about 20 % of them
        assert!(report.outliers > 0, "the outliers are found: {report:?}");
        if !(t1 < t0 && r1 < r0) {
            worse.push((seed, t0, t1, r0, r1));
        }
    }
    assert!(
        worse.is_empty(),
        "BA not better than frame-to-frame: {worse:?}"
    );
}

#[test]
fn bad_windows_are_errors() {
    let mut ba = WindowBa {
        rig: rig(),
        cam_from_world: vec![Pose::identity(); 2],
        points_w: vec![Point3::new(0.0, 0.0, 10.0)],
        observations: vec![Observation {
            frame: 5,
            point: 0,
            left_px: Point2::new(600.0, 180.0),
            right_u_px: None,
            sigma_px: 1.0,
            right_sigma_px: 1.0,
        }],
    };
    assert!(ba.solve(&BaConfig::default()).is_err());
    ba.observations.clear();
    assert!(ba.solve(&BaConfig::default()).is_err());
}

#[test]
fn a_point_behind_a_camera_costs_and_is_an_outlier() {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let truth = truth();
    let points = scene(&mut rng);
    let meas = measure(&truth, &points, 0.0, 0.0, &mut rng);
    let mut ba = window(&truth, &meas, points.len(), 0.0);
    let all = vec![true; ba.observations.len()];
    let config = BaConfig::default();
    assert!(ba.cost(&config, &all) < 1e-12);
    // one observed point moved behind every camera of the window
    let j = ba.observations[0].point;
    let seen = ba.observations.iter().filter(|o| o.point == j).count();
    ba.points_w[j] = truth[0].inverse() * Point3::new(0.5, 0.2, -8.0);
    let behind = ba.cost(&config, &all);
    // each of its observations costs as an outlier at the threshold (it cost nothing before)
    let at_threshold = 0.5 * visnav_odometry::ba::huber_rho(config.outlier_chi2, config.huber_px);
    assert!(
        (behind - seen as f64 * at_threshold).abs() < 1e-9 * behind,
        "{behind} for {seen} observations"
    );
    let report = ba.solve(&config).unwrap();
    assert!(
        report.outliers >= seen,
        "{report:?}, {seen} observations behind"
    );
    let (t, r) = errors(&ba.cam_from_world, &truth);
    assert!(t < 1e-6 && r < 1e-6, "{t} m {r} deg");
}

/// Measurements of a rig whose right principal point sits `offset_px` columns right of the
/// left one's (a right column `offset_px` larger than the calibrated rig predicts).
fn with_right_offset(
    meas: &[(usize, usize, Point2<f64>, f64)],
    offset_px: f64,
) -> Vec<(usize, usize, Point2<f64>, f64)> {
    meas.iter()
        .map(|&(k, j, l, ur)| (k, j, l, ur + offset_px))
        .collect()
}

#[test]
fn the_window_measures_the_rigs_disparity_offset() {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let truth = truth();
    let points = scene(&mut rng);
    let exact = with_right_offset(&measure(&truth, &points, 0.0, 0.0, &mut rng), 0.2);
    let config = BaConfig {
        max_iterations: 30,
        estimate_right_cx_offset: true,
        ..BaConfig::default()
    };
    // noise-free: the offset, the poses and the points exactly
    let mut ba = window(&truth, &exact, points.len(), 0.0);
    ba.solve(&config).unwrap();
    let (t, r) = errors(&ba.cam_from_world, &truth);
    assert!(
        (ba.rig.right_cx_offset_px - 0.2).abs() < 1e-6,
        "{}",
        ba.rig.right_cx_offset_px
    );
    assert!(t < 1e-6 && r < 1e-6, "{t} m {r} deg");
    // the offset ignored: the trajectory is stretched (far points pushed away)
    let mut ignored = window(&truth, &exact, points.len(), 0.0);
    ignored
        .solve(&BaConfig {
            estimate_right_cx_offset: false,
            ..config
        })
        .unwrap();
    let (t_ignored, _) = errors(&ignored.cam_from_world, &truth);
    // 0.5 px noise and 20 % outliers, from the frame-to-frame estimate: within 0.05 px
    let noisy = with_right_offset(&measure(&truth, &points, 0.5, 0.2, &mut rng), 0.2);
    let f2f = frame_to_frame(&noisy, truth[0]);
    let mut ba = window(&f2f, &noisy, points.len(), 0.5);
    ba.solve(&BaConfig {
        estimate_right_cx_offset: true,
        ..BaConfig::default()
    })
    .unwrap();
    let (t_noisy, _) = errors(&ba.cam_from_world, &truth);
    eprintln!(
        "offset 0.2 px: estimated {:.4} (noisy); pose error exact {t:.2e} m, offset ignored {t_ignored:.4} m, noisy {t_noisy:.4} m",
        ba.rig.right_cx_offset_px
    );
    assert!(
        (ba.rig.right_cx_offset_px - 0.2).abs() < 0.05,
        "{}",
        ba.rig.right_cx_offset_px
    );
    assert!(
        t_ignored > 1e-3,
        "an offset of 0.2 px moves the poses: {t_ignored}"
    );
}
