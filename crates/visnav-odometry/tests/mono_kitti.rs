//! Monocular odometry on real KITTI frames (sequence 00), with the dense flow of `visnav-flow`.
//!
//! `kitti_00_first_frames` runs in CI on a few frames; `kitti_00_report` (ignored; run with
//! `--ignored`) runs the whole 300-frame clip with the three estimators side by side on the same
//! flow and prints the KITTI scores (lengths 100, 200 m) and timings for `docs/benchmarks.md`.
#![allow(clippy::unwrap_used)]

use std::time::Instant;

use visnav_core::Pose;
use visnav_eval::kitti::{KittiMetricConfig, kitti_score, sequence_errors};
use visnav_eval::pose_matrices;
use visnav_flow::DenseFlow;
use visnav_geometry::fundamental::Estimator;
use visnav_io::Sequence;
use visnav_io::trajectory::read_kitti;
use visnav_odometry::mono::{
    MonoConfig, MonoFlow, MonoFlowConfig, MonoFrameResult, MonoOdometry, PoseSource,
};

/// Flow cache (test tooling): `VISNAV_MONO_FLOW_CACHE=DIR` stores each frame's dense flow as a
/// little-endian binary (`width`, `height` as u64, then per pixel u, v, Yxx, Yxy, Yyy as f32 and
/// valid as u8), so that estimator variants can be re-run without recomputing the flow.
fn cached_flow(k: usize, compute: impl FnOnce() -> DenseFlow) -> DenseFlow {
    let Ok(dir) = std::env::var("VISNAV_MONO_FLOW_CACHE") else {
        return compute();
    };
    let path = std::path::Path::new(&dir).join(format!("flow_{k:06}.bin"));
    if let Ok(bytes) = std::fs::read(&path) {
        let u64_at = |o: usize| u64::from_le_bytes(bytes[o..o + 8].try_into().unwrap()) as usize;
        let (w, h) = (u64_at(0), u64_at(8));
        let n = w * h;
        let f32_at = |o: usize| f32::from_le_bytes(bytes[o..o + 4].try_into().unwrap());
        let base = 16;
        let flow = (0..n)
            .map(|i| [f32_at(base + 20 * i), f32_at(base + 20 * i + 4)])
            .collect();
        let information = (0..n)
            .map(|i| {
                [
                    f32_at(base + 20 * i + 8),
                    f32_at(base + 20 * i + 12),
                    f32_at(base + 20 * i + 16),
                ]
            })
            .collect();
        let valid = (0..n).map(|i| bytes[base + 20 * n + i] != 0).collect();
        return DenseFlow {
            width: w,
            height: h,
            flow,
            information,
            valid,
        };
    }
    let f = compute();
    let n = f.width * f.height;
    let mut out = Vec::with_capacity(16 + 21 * n);
    out.extend_from_slice(&(f.width as u64).to_le_bytes());
    out.extend_from_slice(&(f.height as u64).to_le_bytes());
    for i in 0..n {
        for v in [
            f.flow[i][0],
            f.flow[i][1],
            f.information[i][0],
            f.information[i][1],
            f.information[i][2],
        ] {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    out.extend(f.valid.iter().map(|&v| u8::from(v)));
    std::fs::write(&path, out).unwrap();
    f
}

struct KittiRun {
    /// Per estimator: the frame results.
    results: Vec<Vec<MonoFrameResult>>,
    gt: Vec<Pose>,
    flow_ms: Vec<f64>,
}

fn run_kitti(frames: usize, estimators: &[Estimator], flow: &MonoFlowConfig) -> Option<KittiRun> {
    let root = visnav_core::testdata::shared_data("kitti/odometry/sequences/00")?;
    let poses_path = visnav_core::testdata::shared_data("kitti/odometry/poses/00.txt")?;
    let seq = Sequence::open(&root).unwrap();
    let frames = frames.min(seq.len());
    let gt: Vec<Pose> = read_kitti(&poses_path).unwrap()[..frames].to_vec();
    let flow = MonoFlow::new(flow).unwrap();
    let mut pipelines: Vec<MonoOdometry> = estimators
        .iter()
        .map(|&e| {
            let mut cfg = MonoConfig::default();
            cfg.eight_point.estimator = e;
            MonoOdometry::new(seq.camera, cfg).unwrap()
        })
        .collect();
    let mut results = vec![Vec::new(); estimators.len()];
    let mut flow_ms = Vec::new();
    let mut prev = None;
    for k in 0..frames {
        let img = seq.load_left(k).unwrap();
        let dense = prev.as_ref().map(|p| {
            cached_flow(k, || {
                let t = Instant::now();
                let (f, _) = flow.compute_timed(p, &img).unwrap();
                flow_ms.push(t.elapsed().as_secs_f64() * 1e3);
                f
            })
        });
        for (vo, out) in pipelines.iter_mut().zip(&mut results) {
            let r = vo.process(&img, dense.as_ref()).unwrap();
            out.push(r);
        }
        let r = &results[0][k];
        if k > 0 {
            let gt_step = (gt[k - 1].inverse() * gt[k]).translation.vector.norm();
            eprintln!(
                "frame {k}: {:?} {:?} {:?} s={:.3} (g {:?} d {:?}) gt {gt_step:.3} | inl {}/{} pnp {}/{} | flow {:.0} ms vo {:.0} ms",
                r.status,
                r.source,
                r.scale_source,
                r.cur_from_prev.translation.vector.norm(),
                r.scale_ground_m.map(|v| (v * 1000.0).round() / 1000.0),
                r.scale_depth_m.map(|v| (v * 1000.0).round() / 1000.0),
                r.eight_point_inliers,
                r.correspondences,
                r.pnp_inliers,
                r.pnp_correspondences,
                flow_ms.last().copied().unwrap_or(0.0),
                r.timings.total_ms
            );
        }
        prev = Some(img);
    }
    Some(KittiRun {
        results,
        gt,
        flow_ms,
    })
}

#[test]
fn kitti_00_first_frames() {
    let frames = std::env::var("VISNAV_MONO_FRAMES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(4);
    let Some(run) = run_kitti(
        frames,
        &[Estimator::Mahalanobis],
        &MonoFlowConfig::default(),
    ) else {
        return;
    };
    let res = &run.results[0];
    for (k, r) in res.iter().enumerate().skip(1) {
        let gt_step = run.gt[k - 1].inverse() * run.gt[k];
        let est = r.cur_from_prev.inverse();
        let gt_len = gt_step.translation.vector.norm();
        let len_ratio = est.translation.vector.norm() / gt_len;
        let rot_err = (gt_step.rotation.inverse() * est.rotation).angle();
        let dir_err = est
            .translation
            .vector
            .normalize()
            .dot(&gt_step.translation.vector.normalize())
            .clamp(-1.0, 1.0)
            .acos();
        eprintln!(
            "frame {k}: length ratio {len_ratio:.3}, rotation error {rot_err:.5} rad, direction error {dir_err:.4} rad"
        );
        assert_ne!(r.source, PoseSource::ConstantVelocity, "frame {k}");
        assert!(rot_err < 0.01, "frame {k}: rotation error {rot_err} rad");
        assert!(
            dir_err < 0.1,
            "frame {k}: translation direction error {dir_err} rad"
        );
        // the ground fits of the first frames of 00 underestimate the scale by ~20 % (see
        // docs/benchmarks.md); later frames are within a few per cent
        assert!(
            (0.7..1.3).contains(&len_ratio),
            "frame {k}: length ratio {len_ratio}"
        );
    }
}

// Bounds of `kitti_00_clip_accuracy_with_the_downsampled_flow`, ~1.4x the figures measured with the
// 2x-downsampled flow (t_err 6.9 %, r_err 7.5 deg/100 m over 5–15 m segments, end point 1.39 m
// of 25.7 m; the first frames' ground fits underestimate the scale by ~20 %, see
// docs/benchmarks.md). A wrong flow or information scaling breaks them by far.
const T_ERR_BOUND_PERCENT: f64 = 10.0;
const R_ERR_BOUND_DEG_PER_100M: f64 = 11.0;
const END_ERROR_BOUND_FRACTION: f64 = 0.08;

/// Guards the accuracy of the speed setting of the flow (`max_width_px = 700`: flow on the
/// 2x-downsampled pair): the first 30 frames of KITTI 00 (≈ 21 m) scored by
/// the KITTI metric over short segments and by the end point, scale from the camera height only.
#[test]
fn kitti_00_clip_accuracy_with_the_downsampled_flow() {
    let frames = 30;
    let speed = MonoFlowConfig {
        max_width_px: 700,
        ..MonoFlowConfig::default()
    };
    let Some(run) = run_kitti(frames, &[Estimator::Mahalanobis], &speed) else {
        return;
    };
    let res = &run.results[0];
    assert!(
        res.iter().all(|r| r.source != PoseSource::ConstantVelocity),
        "a frame failed"
    );
    let poses: Vec<Pose> = res.iter().map(|r| r.world_from_cam).collect();
    let metric = KittiMetricConfig {
        lengths_m: vec![5.0, 10.0, 15.0],
        ..KittiMetricConfig::default()
    };
    let errors = sequence_errors(&pose_matrices(&run.gt), &pose_matrices(&poses), &metric, 0);
    let score = kitti_score(&errors, &metric.lengths_m);
    let gt_end = run.gt[frames - 1].translation.vector;
    let end_error_m = (poses[frames - 1].translation.vector - gt_end).norm();
    let travelled_m: f64 = run
        .gt
        .windows(2)
        .map(|w| (w[1].translation.vector - w[0].translation.vector).norm())
        .sum();
    eprintln!(
        "30 frames ({travelled_m:.1} m): t_err {:.3} % r_err {:.3} deg/100m ({} segments), end-point error {end_error_m:.3} m",
        score.t_err_percent, score.r_err_deg_per_100m, score.segments
    );
    assert!(score.segments > 0);
    assert!(
        score.t_err_percent < T_ERR_BOUND_PERCENT,
        "t_err {} %",
        score.t_err_percent
    );
    assert!(
        score.r_err_deg_per_100m < R_ERR_BOUND_DEG_PER_100M,
        "r_err {} deg/100m",
        score.r_err_deg_per_100m
    );
    assert!(
        end_error_m < END_ERROR_BOUND_FRACTION * travelled_m,
        "end-point error {end_error_m} m of {travelled_m} m"
    );
}

#[test]
#[ignore = "several minutes: the 300-frame KITTI clip for docs/benchmarks.md"]
fn kitti_00_report() {
    let frames = std::env::var("VISNAV_MONO_FRAMES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(300);
    let estimators = [
        Estimator::Mahalanobis,
        Estimator::Sampson,
        Estimator::Algebraic,
    ];
    let Some(run) = run_kitti(frames, &estimators, &MonoFlowConfig::default()) else {
        return;
    };
    let metric = KittiMetricConfig {
        lengths_m: vec![100.0, 200.0],
        ..KittiMetricConfig::default()
    };
    let gt = pose_matrices(&run.gt);
    for (est, res) in estimators.iter().zip(&run.results) {
        let poses: Vec<Pose> = res.iter().map(|r| r.world_from_cam).collect();
        let errors = sequence_errors(&gt, &pose_matrices(&poses), &metric, 0);
        let score = kitti_score(&errors, &metric.lengths_m);
        let mean_vo = res.iter().map(|r| r.timings.total_ms).sum::<f64>() / res.len() as f64;
        let count = |s: PoseSource| res.iter().filter(|r| r.source == s).count();
        eprintln!(
            "{est:?}: t_err {:.3} % r_err {:.3} deg/100m ({} segments); vo {mean_vo:.1} ms/frame; sources 8pt {} pnp {} fused {} cv {}",
            score.t_err_percent,
            score.r_err_deg_per_100m,
            score.segments,
            count(PoseSource::EightPoint),
            count(PoseSource::Pnp),
            count(PoseSource::Fused),
            count(PoseSource::ConstantVelocity)
        );
        let n = res.len().max(1) as f64;
        let mean = |f: fn(&MonoFrameResult) -> f64| res.iter().map(f).sum::<f64>() / n;
        eprintln!(
            "{est:?} stage means (ms): correspondences {:.1} parallax {:.1} pnp {:.1} eight-point {:.1} triangulation {:.1} scale {:.1} depth {:.1} total {:.1}",
            mean(|r| r.timings.correspondences_ms),
            mean(|r| r.timings.parallax_ms),
            mean(|r| r.timings.pnp_ms),
            mean(|r| r.timings.eight_point_ms),
            mean(|r| r.timings.triangulation_ms),
            mean(|r| r.timings.scale_ms),
            mean(|r| r.timings.depth_ms),
            mean(|r| r.timings.total_ms),
        );
        if let Ok(dir) = std::env::var("VISNAV_MONO_OUT") {
            let path = std::path::Path::new(&dir).join(format!("mono_{est:?}.txt").to_lowercase());
            visnav_io::trajectory::write_kitti(&path, &poses).unwrap();
        }
        assert!(score.t_err_percent.is_finite());
    }
    let mean_flow = run.flow_ms.iter().sum::<f64>() / run.flow_ms.len().max(1) as f64;
    eprintln!("flow {mean_flow:.0} ms/frame");
}
