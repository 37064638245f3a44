//! Cost of scoring a full-length KITTI sequence: the devkit metric (default lengths), ATE
//! (SE(3) + Sim(3)) and RPE, on `poses/00.txt` (4,541 poses) against a drifting copy, or on a
//! synthetic drive of the same length when the shared data is absent.
#![allow(clippy::unwrap_used)]

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use nalgebra::{UnitQuaternion, Vector3};
use visnav_eval::kitti::{KittiMetricConfig, sequence_errors};
use visnav_eval::{EvalConfig, PoseMatrix, TrajectoryPair, evaluate, pose_matrices};

fn ground_truth() -> Vec<PoseMatrix> {
    if let Ok(d) = std::env::var("VISNAV_DATA") {
        let p = std::path::Path::new(&d).join("kitti/odometry/poses/00.txt");
        if let Ok(poses) = visnav_io::trajectory::read_kitti(&p) {
            return pose_matrices(&poses);
        }
    }
    let step = UnitQuaternion::from_scaled_axis(Vector3::new(0.0, 0.002, 0.0)).to_homogeneous();
    let mut out = vec![PoseMatrix::identity()];
    for _ in 1..4541 {
        let mut s = step;
        s[(2, 3)] = 0.8;
        out.push(out[out.len() - 1] * s);
    }
    out
}

fn drifting(gt: &[PoseMatrix]) -> Vec<PoseMatrix> {
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

fn bench(c: &mut Criterion) {
    let gt = ground_truth();
    let est = drifting(&gt);
    let mut g = c.benchmark_group("eval_full_sequence");
    g.throughput(Throughput::Elements(gt.len() as u64));
    g.sample_size(20);
    g.bench_function("kitti_metric_only", |b| {
        let config = KittiMetricConfig::default();
        b.iter(|| sequence_errors(&gt, &est, &config, 0).len());
    });
    g.bench_function("evaluate_all", |b| {
        let config = EvalConfig::default();
        b.iter(|| {
            evaluate(&[TrajectoryPair::by_index(&gt, &est)], &config)
                .unwrap()
                .segments
        });
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
