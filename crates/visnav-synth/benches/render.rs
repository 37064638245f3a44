//! Rendering throughput: one frame of the default city at several image sizes (3x3
//! supersampling), and the ground-truth flow of a pair.
#![allow(clippy::unwrap_used)]

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use visnav_synth::{Scene, drive_trajectory, flow_between, kitti_like_camera, render_view};

fn bench_render(c: &mut Criterion) {
    let poses = drive_trajectory(20, 1);
    let scene = Scene::along(&poses, 1).unwrap();
    let mut group = c.benchmark_group("render_view");
    group.sample_size(10);
    for (w, h) in [(320u32, 96u32), (620, 188), (1241, 376)] {
        let cam = kitti_like_camera(w, h);
        group.throughput(Throughput::Elements(u64::from(w) * u64::from(h)));
        group.bench_function(format!("{w}x{h}"), |b| {
            b.iter(|| render_view(&scene, &cam, &poses[10]));
        });
    }
    group.finish();
    let cam = kitti_like_camera(1241, 376);
    let a = render_view(&scene, &cam, &poses[10]);
    let b = render_view(&scene, &cam, &poses[11]);
    c.bench_function("flow_between/1241x376", |bench| {
        bench.iter(|| flow_between(&scene, &cam, &poses[10], &a, &poses[11], &b));
    });
}

criterion_group!(benches, bench_render);
criterion_main!(benches);
