//! The KITTI metric reproduces the official devkit's scores on the shared reference
//! trajectories, and agrees with an independent straightforward implementation on the full
//! length of sequence 00.
#![allow(clippy::unwrap_used)]

use std::path::Path;

use nalgebra::{Matrix4, UnitQuaternion, Vector3};
use visnav_core::testdata::shared_data;
use visnav_eval::kitti::KittiMetricConfig;
use visnav_eval::{EvalConfig, PoseMatrix, TrajectoryPair, evaluate, pose_matrices};
use visnav_io::trajectory::{read_kitti, read_kitti_matrices};

/// The matrices of a KITTI file exactly as written, as the devkit reads them.
fn read_devkit(path: &Path) -> Vec<PoseMatrix> {
    read_kitti_matrices(path)
        .unwrap()
        .iter()
        .map(|m| m.insert_fixed_rows::<1>(3, 0.0))
        .map(|mut m| {
            m[(3, 3)] = 1.0;
            m
        })
        .collect()
}

fn config(lengths_m: &[f64]) -> EvalConfig {
    EvalConfig {
        kitti: KittiMetricConfig {
            lengths_m: lengths_m.to_vec(),
            ..KittiMetricConfig::default()
        },
        ..EvalConfig::default()
    }
}

fn rel_close(got: f64, want: f64, tol: f64) -> bool {
    ((got - want) / want).abs() < tol
}

/// Scores `reference/<est>` against the first lines of `poses/<seq>.txt`.
fn check_reference(est: &str, seq: &str, lengths: &[f64], t_err: f64, r_err: f64, segments: usize) {
    let Some(root) = shared_data("kitti/odometry") else {
        return;
    };
    let est = read_devkit(&root.join("reference").join(est));
    let gt = read_devkit(&root.join(format!("poses/{seq}.txt")));
    let gt = &gt[..est.len()];
    let r = evaluate(&[TrajectoryPair::by_index(gt, &est)], &config(lengths)).unwrap();
    assert_eq!(r.segments, segments);
    assert!(
        rel_close(r.t_err_percent, t_err, 1e-3),
        "t_err {} vs devkit {t_err}",
        r.t_err_percent
    );
    assert!(
        rel_close(r.r_err_deg_per_100m, r_err, 1e-3),
        "r_err {} vs devkit {r_err}",
        r.r_err_deg_per_100m
    );
    eprintln!(
        "{}: t_err {:.4} % (devkit {t_err}), r_err {:.4} deg/100m (devkit {r_err}), {} segments, ATE se3 {:.3} m sim3 {:.3} m",
        root.display(),
        r.t_err_percent,
        r.r_err_deg_per_100m,
        r.segments,
        r.ate_se3_m.unwrap(),
        r.ate_sim3_m.unwrap()
    );
}

#[test]
fn devkit_viso2_mono_00_first300() {
    check_reference(
        "viso2m_00_first300.txt",
        "00",
        &[100.0, 200.0],
        10.9855,
        3.2061,
        18,
    );
}

#[test]
fn devkit_opencv_mono_gtscale_00_first300() {
    check_reference(
        "opencv_mono_gtscale_00_first300.txt",
        "00",
        &[100.0, 200.0],
        1.3956,
        1.5991,
        18,
    );
}

#[test]
fn devkit_viso2_stereo_06_first51() {
    check_reference(
        "viso2s_06_first51.txt",
        "06",
        &[10.0, 20.0, 30.0, 40.0, 50.0],
        1.0251,
        2.8211,
        15,
    );
}

#[test]
fn several_pairs_pool_all_segments() {
    let Some(root) = shared_data("kitti/odometry") else {
        return;
    };
    let gt = read_devkit(&root.join("poses/00.txt"));
    let a = read_devkit(&root.join("reference/viso2m_00_first300.txt"));
    let b = read_devkit(&root.join("reference/opencv_mono_gtscale_00_first300.txt"));
    let pairs = [
        TrajectoryPair::by_index(&gt[..300], &a),
        TrajectoryPair::by_index(&gt[..300], &b),
    ];
    let r = evaluate(&pairs, &config(&[100.0, 200.0])).unwrap();
    assert_eq!(r.segments, 36);
    // equal segment counts: the pooled mean is the mean of the two scores
    assert!(
        rel_close(r.t_err_percent, 0.5 * (10.9855 + 1.3956), 1e-3),
        "{}",
        r.t_err_percent
    );
    assert!(rel_close(
        r.r_err_deg_per_100m,
        0.5 * (3.2061 + 1.5991),
        1e-3
    ));
    assert_eq!(r.sequences.len(), 2);
    assert_eq!(r.per_length.iter().map(|b| b.segments).sum::<usize>(), 36);
}

// ---------------------------------------------------------------------------------------------
// An independent straightforward implementation of the same definition: raw 4x4 matrices, general
// matrix inverses, f64 path lengths.

fn read_raw_matrices(path: &Path) -> Vec<Matrix4<f64>> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|t| t.parse().unwrap()).collect();
            let mut m = Matrix4::identity();
            for r in 0..3 {
                for c in 0..4 {
                    m[(r, c)] = v[4 * r + c];
                }
            }
            m
        })
        .collect()
}

/// Returns (mean t_err ratio, mean r_err rad/m, segments). Path lengths are accumulated in
/// `float` as the devkit's `trajectoryDistances` does (with `f64` sums a few of the 3,283 segments of
/// sequence 00 end one frame differently, which moves the mean by ~3e-6 relative).
fn straightforward_kitti(
    gt: &[Matrix4<f64>],
    est: &[Matrix4<f64>],
    lengths: &[f64],
) -> (f64, f64, usize) {
    let mut dist = vec![0.0f32; gt.len()];
    for i in 1..gt.len() {
        let d = gt[i].fixed_view::<3, 1>(0, 3) - gt[i - 1].fixed_view::<3, 1>(0, 3);
        dist[i] = dist[i - 1] + d.cast::<f32>().norm();
    }
    let (mut t_sum, mut r_sum, mut n) = (0.0, 0.0, 0usize);
    let mut first = 0;
    while first < gt.len() {
        for &len in lengths {
            let Some(last) = (first..gt.len()).find(|&i| dist[i] > dist[first] + len as f32) else {
                continue;
            };
            let gt_delta = gt[first].try_inverse().unwrap() * gt[last];
            let est_delta = est[first].try_inverse().unwrap() * est[last];
            let e = est_delta.try_inverse().unwrap() * gt_delta;
            let c = 0.5 * (e[(0, 0)] + e[(1, 1)] + e[(2, 2)] - 1.0);
            r_sum += c.clamp(-1.0, 1.0).acos() / len;
            t_sum += e.fixed_view::<3, 1>(0, 3).norm() / len;
            n += 1;
        }
        first += 10;
    }
    (t_sum / n as f64, r_sum / n as f64, n)
}

/// A drifting copy: every relative motion's translation scaled by 1.5 % and followed by a small
/// rotation.
fn drifting_copy(gt: &[PoseMatrix]) -> Vec<PoseMatrix> {
    let drift = UnitQuaternion::from_scaled_axis(Vector3::new(2e-4, 6e-4, -1e-4)).to_homogeneous();
    let mut est = vec![gt[0]];
    for w in gt.windows(2) {
        let mut rel = w[0].try_inverse().unwrap() * w[1];
        for r in 0..3 {
            rel[(r, 3)] *= 1.015;
        }
        est.push(est[est.len() - 1] * rel * drift);
    }
    est
}

#[test]
fn full_length_00_matches_independent_implementation() {
    let Some(path) = shared_data("kitti/odometry/poses/00.txt") else {
        return;
    };
    let gt = read_devkit(&path);
    let est = drifting_copy(&gt);
    let r = evaluate(
        &[TrajectoryPair::by_index(&gt, &est)],
        &EvalConfig::default(),
    )
    .unwrap();
    let gt_raw = read_raw_matrices(&path);
    let (t, rr, n) = straightforward_kitti(&gt_raw, &est, &visnav_eval::kitti::DEVKIT_LENGTHS_M);
    assert_eq!(r.segments, n);
    let t_percent = 100.0 * t;
    let r_deg = rr.to_degrees() * 100.0;
    assert!(
        rel_close(r.t_err_percent, t_percent, 1e-6),
        "{} vs {t_percent}",
        r.t_err_percent
    );
    assert!(
        rel_close(r.r_err_deg_per_100m, r_deg, 1e-6),
        "{} vs {r_deg}",
        r.r_err_deg_per_100m
    );
    assert!(
        r.t_err_percent > 1.0,
        "drift must show: {}",
        r.t_err_percent
    );
    // the devkit's per-length bins cover every segment
    assert_eq!(r.per_length.len(), 8);
    assert_eq!(r.per_length.iter().map(|b| b.segments).sum::<usize>(), n);
    eprintln!(
        "00 drifting copy: {} segments, t_err {:.6} % (independent {t_percent:.6}), r_err {:.6} deg/100m (independent {r_deg:.6})",
        r.segments, r.t_err_percent, r.r_err_deg_per_100m
    );
}

#[test]
fn ground_truth_scores_zero_and_one_percent_scale_scores_one_percent() {
    let Some(path) = shared_data("kitti/odometry/poses/00.txt") else {
        return;
    };
    // as read by visnav (rotations re-orthonormalised)
    let gt = pose_matrices(&read_kitti(&path).unwrap());
    let r = evaluate(
        &[TrajectoryPair::by_index(&gt, &gt)],
        &EvalConfig::default(),
    )
    .unwrap();
    assert!(r.segments > 3000, "{}", r.segments);
    // `inv(X) X` is the identity to rounding: acos(1 - 1e-16) is 1.5e-8 rad
    assert!(r.t_err_percent < 1e-9, "{}", r.t_err_percent);
    assert!(r.r_err_deg_per_100m < 1e-6, "{}", r.r_err_deg_per_100m);
    assert!(r.ate_se3_m.unwrap() < 1e-9 && r.ate_sim3_m.unwrap() < 1e-9);
    assert!(r.rpe.unwrap().trans_rmse_m < 1e-9);
    let scaled: Vec<PoseMatrix> = gt
        .iter()
        .map(|m| {
            let mut m = *m;
            for r in 0..3 {
                m[(r, 3)] *= 1.01;
            }
            m
        })
        .collect();
    let r = evaluate(
        &[TrajectoryPair::by_index(&gt, &scaled)],
        &EvalConfig::default(),
    )
    .unwrap();
    // a global 1 % scale error: |t(E)| = 1 % of the segment's chord |t_last - t_first|, so the
    // score is 1 % times the mean chord/length ratio (below 1 on a winding drive)
    let expected: f64 = r
        .segment_errors
        .iter()
        .map(|e| {
            let chord = gt[e.last_frame].fixed_view::<3, 1>(0, 3)
                - gt[e.first_frame].fixed_view::<3, 1>(0, 3);
            chord.norm() / e.length_m
        })
        .sum::<f64>()
        / r.segments as f64;
    assert!(
        rel_close(r.t_err_percent, expected, 1e-9),
        "{} vs {expected}",
        r.t_err_percent
    );
    assert!(expected > 0.5 && expected < 1.01, "{expected}");
    assert!(r.r_err_deg_per_100m < 1e-6);
    // Sim(3) alignment removes the scale entirely, SE(3) cannot
    assert!(r.ate_sim3_m.unwrap() < 1e-6, "{:?}", r.ate_sim3_m);
    assert!(r.ate_se3_m.unwrap() > 1.0);
    let s = r.sequences[0].ate_sim3.unwrap().alignment.scale;
    assert!((s - 1.0 / 1.01).abs() < 1e-9, "{s}");
    eprintln!(
        "00 scaled by 1 %: t_err {:.4} %, ATE se3 {:.3} m, sim3 {:.2e} m",
        r.t_err_percent,
        r.ate_se3_m.unwrap(),
        r.ate_sim3_m.unwrap()
    );
}

#[test]
fn one_percent_scale_on_a_straight_drive_scores_one_percent() {
    // 0.1 m a frame for 1,000 m: a segment of L metres spans L + 0.1 m of ground truth
    let gt: Vec<PoseMatrix> = (0..10_001)
        .map(|i| {
            let mut m = PoseMatrix::identity();
            m[(2, 3)] = 0.1 * f64::from(i);
            m
        })
        .collect();
    let est: Vec<PoseMatrix> = gt
        .iter()
        .map(|m| {
            let mut m = *m;
            m[(2, 3)] *= 1.01;
            m
        })
        .collect();
    let r = evaluate(
        &[TrajectoryPair::by_index(&gt, &est)],
        &EvalConfig::default(),
    )
    .unwrap();
    assert!(r.segments > 1000);
    assert!((r.t_err_percent - 1.0).abs() < 2e-3, "{}", r.t_err_percent);
    assert!(r.r_err_deg_per_100m.abs() < 1e-9);
    assert_eq!(r.per_length.len(), 8);
}
