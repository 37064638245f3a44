//! Benchmarks of the two-view solvers: guided RANSAC + eight-point refinement (three estimators)
//! over n correspondences, the refinement alone, P3P, PnP RANSAC and dense triangulation.
#![allow(clippy::unwrap_used)]

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use nalgebra::{Matrix2, Point3, Vector2, Vector3, Vector6};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use visnav_core::se3::se3_exp;
use visnav_core::{PinholeCamera, Pose};
use visnav_geometry::Correspondence;
use visnav_geometry::fundamental::{
    EightPointConfig, Estimator, eight_point, estimate_fundamental,
};
use visnav_geometry::pnp::{PnpConfig, PnpCorrespondence, p3p, solve_pnp};
use visnav_geometry::triangulation::triangulate;

fn scene(n: usize, seed: u64) -> (Pose, Vec<Correspondence>) {
    let cam = PinholeCamera::kitti_default();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let pose = se3_exp(&Vector6::new(0.02, -0.01, -0.9, 0.002, 0.02, -0.001));
    let mut data = Vec::with_capacity(n);
    while data.len() < n {
        let p = Point3::new(
            rng.random_range(-20.0..20.0),
            rng.random_range(-4.0..1.65),
            rng.random_range(4.0..60.0),
        );
        let (Some(a), Some(b)) = (cam.project(&p), cam.project(&(pose * p))) else {
            continue;
        };
        if !cam.contains(&a, 0.0) || !cam.contains(&b, 0.0) {
            continue;
        }
        let outlier = data.len() % 10 == 0;
        let noise = if outlier {
            Vector2::new(rng.random_range(-30.0..30.0), rng.random_range(-30.0..30.0))
        } else {
            Vector2::new(rng.random_range(-0.5..0.5), rng.random_range(-0.5..0.5))
        };
        data.push(Correspondence {
            p1_px: a,
            p2_px: b + noise,
            information: Matrix2::new(4.0, 1.0, 1.0, 2.0),
        });
    }
    (pose, data)
}

fn bench_fundamental(c: &mut Criterion) {
    let mut g = c.benchmark_group("fundamental_ransac");
    for n in [1000usize, 4000] {
        let (_, data) = scene(n, 1);
        g.throughput(Throughput::Elements(n as u64));
        for est in [
            Estimator::Algebraic,
            Estimator::Sampson,
            Estimator::Mahalanobis,
        ] {
            let cfg = EightPointConfig {
                estimator: est,
                ..EightPointConfig::default()
            };
            g.bench_with_input(BenchmarkId::new(format!("{est:?}"), n), &data, |b, d| {
                b.iter(|| {
                    let mut rng = ChaCha8Rng::seed_from_u64(7);
                    black_box(estimate_fundamental(d, &cfg, &mut rng))
                });
            });
        }
    }
    g.finish();
    let mut g = c.benchmark_group("eight_point_refine");
    let (_, data) = scene(4000, 2);
    let refs: Vec<&Correspondence> = data.iter().filter(|c| c.p1_px.x > -1.0).collect();
    g.throughput(Throughput::Elements(refs.len() as u64));
    for est in [
        Estimator::Algebraic,
        Estimator::Sampson,
        Estimator::Mahalanobis,
    ] {
        g.bench_function(format!("{est:?}/4000"), |b| {
            b.iter(|| black_box(eight_point(&refs, est, 10, 1e-10)));
        });
    }
    g.finish();
}

fn bench_pnp_and_triangulation(c: &mut Criterion) {
    let cam = PinholeCamera::kitti_default();
    let (pose, data) = scene(3000, 3);
    let mut g = c.benchmark_group("pnp");
    let bearings = [
        Vector3::new(0.1, 0.05, 1.0),
        Vector3::new(-0.2, 0.1, 1.0),
        Vector3::new(0.05, -0.15, 1.0),
    ];
    let pts = [
        Point3::new(1.0, 0.5, 10.0),
        Point3::new(-4.0, 2.0, 20.0),
        Point3::new(0.4, -1.2, 8.0),
    ];
    g.bench_function("p3p", |b| b.iter(|| black_box(p3p(&bearings, &pts))));
    let pnp_data: Vec<PnpCorrespondence> = data
        .iter()
        .filter_map(|c| {
            let t = triangulate(&cam, &pose, c)?;
            Some(PnpCorrespondence {
                p_in_world: t.p_in_cam1,
                p_px: c.p2_px,
                information: c.information,
            })
        })
        .collect();
    g.throughput(Throughput::Elements(pnp_data.len() as u64));
    g.bench_function("pnp_ransac_refine/3000", |b| {
        b.iter(|| {
            let mut rng = ChaCha8Rng::seed_from_u64(9);
            black_box(solve_pnp(&cam, &pnp_data, &PnpConfig::default(), &mut rng))
        });
    });
    g.finish();
    let mut g = c.benchmark_group("triangulation");
    g.throughput(Throughput::Elements(data.len() as u64));
    g.bench_function("triangulate/3000", |b| {
        b.iter(|| {
            black_box(
                data.iter()
                    .filter_map(|c| triangulate(&cam, &pose, c))
                    .count(),
            )
        });
    });
    g.finish();
}

criterion_group!(benches, bench_fundamental, bench_pnp_and_triangulation);
criterion_main!(benches);
