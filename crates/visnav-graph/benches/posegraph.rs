//! Solve time of the public pose graphs (sphere2500, parking-garage) with the default
//! configuration (chordal initialisation, pairwise-consistency preselection, Levenberg–Marquardt).
//! Needs `VISNAV_DATA`.
#![allow(clippy::unwrap_used)]

use criterion::{Criterion, criterion_group, criterion_main};
use visnav_graph::{GraphConfig, read_g2o, solve};

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("posegraph");
    group.sample_size(10);
    for name in ["sphere2500.g2o", "parking-garage.g2o"] {
        let Some(path) = visnav_core::testdata::shared_data(&format!("posegraph/{name}")) else {
            continue;
        };
        let graph = read_g2o(&path).unwrap();
        let config = GraphConfig::default();
        group.bench_function(name, |b| b.iter(|| solve(&graph, &config).unwrap()));
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
