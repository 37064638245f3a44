//! Criterion benchmarks of the stereo odometry: the whole `process` call per frame and its
//! stages, on the KITTI 06 clip when `VISNAV_DATA` is set (else on a rendered sequence).
//! Images are decoded outside the timed loop; PNG decoding is measured separately.
#![allow(clippy::unwrap_used)]

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use nalgebra::Point2;
use visnav_core::{GrayImage, StereoCamera};
use visnav_image::{CornerConfig, KltConfig, Pyramid, detect_corners, track};
use visnav_odometry::RelativeMotion;
use visnav_odometry::stereo::{StereoConfig, StereoOdometry};

fn frames() -> (StereoCamera, Vec<(GrayImage, GrayImage)>) {
    if let Some(dir) = std::env::var_os("VISNAV_DATA")
        .map(|d| std::path::PathBuf::from(d).join("kitti/odometry/sequences/06"))
        .filter(|p| p.exists())
    {
        let seq = visnav_io::Sequence::open(&dir).unwrap();
        let n = seq.len().min(11);
        let f = (0..n)
            .map(|i| (seq.load_left(i).unwrap(), seq.load_right(i).unwrap()))
            .collect();
        return (seq.stereo_camera().unwrap(), f);
    }
    let gt = visnav_synth::drive_trajectory(11, 1);
    let scene = visnav_synth::Scene::along(&gt, 1).unwrap();
    let rig = StereoCamera::new(
        visnav_synth::kitti_like_camera(1241, 376),
        visnav_synth::KITTI_BASELINE_M,
    )
    .unwrap();
    let f = gt
        .iter()
        .map(|p| {
            let (l, r) = visnav_synth::render_stereo(&scene, &rig, p);
            (l.image, r.image)
        })
        .collect();
    (rig, f)
}

fn bench(c: &mut Criterion) {
    let (rig, frames) = frames();
    let mut g = c.benchmark_group("stereo");
    g.sample_size(10);
    g.throughput(Throughput::Elements(frames.len() as u64));
    g.bench_function("process_sequence", |b| {
        b.iter(|| {
            let mut vo = StereoOdometry::new(rig, StereoConfig::default()).unwrap();
            let mut motion = RelativeMotion::identity();
            for (l, r) in &frames {
                let res = std::hint::black_box(vo.process(l, r, &motion));
                motion = res.motion.unwrap_or(motion);
            }
        });
    });
    g.throughput(Throughput::Elements(1));
    let cfg = StereoConfig::default();
    let (l0, r0) = &frames[0];
    let (l1, _) = &frames[1];
    g.bench_function("pyramid_pair", |b| {
        b.iter(|| {
            rayon::join(
                || Pyramid::build(l0, cfg.klt.levels),
                || Pyramid::build(r0, cfg.klt.levels),
            )
        });
    });
    let corners_cfg: CornerConfig = cfg.corners.clone();
    g.bench_function("corners", |b| b.iter(|| detect_corners(l0, &corners_cfg)));
    let p0 = Pyramid::build(l0, cfg.klt.levels);
    let p1 = Pyramid::build(l1, cfg.klt.levels);
    let pts: Vec<Point2<f64>> = detect_corners(l0, &corners_cfg)
        .iter()
        .map(|c| c.px)
        .collect();
    let klt: KltConfig = cfg.klt.clone();
    g.bench_function("klt_one_pass", |b| {
        b.iter(|| track(&p0, &p1, &pts, None, &klt).unwrap());
    });
    g.finish();

    let mut d = c.benchmark_group("decode");
    d.sample_size(10);
    if let Some(dir) = std::env::var_os("VISNAV_DATA")
        .map(|d| std::path::PathBuf::from(d).join("kitti/odometry/sequences/06"))
        .filter(|p| p.exists())
    {
        let seq = visnav_io::Sequence::open(&dir).unwrap();
        d.bench_function("png_pair", |b| {
            b.iter(|| (seq.load_left(0).unwrap(), seq.load_right(0).unwrap()));
        });
    }
    d.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
