//! Our triangulation beside delaunator (the sweep Polylidar3D's C++ uses, with its inexact
//! in-circle test) and spade (exact, incremental) on the same seeded clouds of 1.5 k to 1 M points.
//!
//! `cargo bench -p landing-geometry --bench triangulation -- --measurement-time 5 --warm-up-time 2`
//! (add a filter such as `1.5k` or `ours` to narrow it). Each triangulator takes the points in its
//! own input layout, made outside the timed loop: ours `[f64; 3]` (z ignored), delaunator its
//! `Point`, spade its vertices (built inside, as `triangulate_spade` must). spade is left out at
//! 1 M (about a second a run).

use std::hint::black_box;
use std::time::Duration;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use landing_geometry::triangulation::{EMPTY, Triangulation, triangulate};

#[path = "../tests/support/spade.rs"]
mod spade;

#[path = "../tests/support/clouds.rs"]
mod clouds;

fn benches(c: &mut Criterion) {
    for (n, label) in clouds::SIZES {
        let (_, pts) = clouds::cloud(n);
        let dpts = clouds::delaunator_points(&pts);
        let mut g = c.benchmark_group(format!("triangulation/{label}"));
        if n >= 100_000 {
            g.sample_size(10);
        }
        g.bench_function(BenchmarkId::new("ours", label), |b| {
            b.iter(|| triangulate(black_box(&pts)).unwrap())
        });
        g.bench_function(BenchmarkId::new("delaunator", label), |b| {
            b.iter(|| delaunator::triangulate(black_box(&dpts)))
        });
        if n <= 100_000 {
            g.bench_function(BenchmarkId::new("spade", label), |b| {
                b.iter(|| spade::triangulate_spade(black_box(&pts)))
            });
        }
        g.finish();
    }
}

criterion_group! {
    name = triangulation;
    config = Criterion::default().warm_up_time(Duration::from_secs(2));
    targets = benches
}
criterion_main!(triangulation);
