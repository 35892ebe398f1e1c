//! The whole pipeline and each step on seeded synthetic roofs of 1.5 k to 1 M points, next to the
//! bare triangulators (ours and spade) on the same points.
//!
//! `cargo bench -p landing-geometry --bench pipeline` (add a filter such as `100k` to narrow it).
//! Before the criterion runs, each size prints the per-step split of `detect`'s own timings
//! (median of a few runs) to stderr.

use std::hint::black_box;
use std::time::Duration;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use landing_geometry::boundary::{BoundaryParams, region_polygons};
use landing_geometry::filter::{FilterParams, filter_triangles};
use landing_geometry::ranking::{RankingParams, rank_sites};
use landing_geometry::regions::{RegionParams, extract_regions};
use landing_geometry::synthetic::{Scene, SceneParams};
use landing_geometry::triangulation::{EMPTY, Triangulation, triangulate};
use landing_geometry::{Cloud, CloudKind, Disk, KeepClear, Params, StepTimings, detect};

#[path = "../tests/support/spade.rs"]
mod spade;

const SIZES: [(usize, &str); 4] = [
    (1_500, "1.5k"),
    (10_000, "10k"),
    (100_000, "100k"),
    (1_000_000, "1M"),
];

fn scene(n: usize) -> (Scene, Vec<[f64; 3]>) {
    let s = Scene::generate(&SceneParams::with_points(n), 1);
    let p = s
        .points
        .iter()
        .map(|p| [f64::from(p[0]), f64::from(p[1]), f64::from(p[2])])
        .collect();
    (s, p)
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

/// Nanoseconds this thread has spent on a CPU (Linux schedstat), if readable. On a shared box the
/// wall clock also counts the time other processes held the core; this does not.
fn on_cpu_ns() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    s.split_whitespace().next()?.parse().ok()
}

/// Median per-step split of `detect` over a few runs, printed once per size, with the mean on-CPU
/// time of a batch of runs lasting at least a second (schedstat advances in scheduler ticks).
fn print_split(label: &str, s: &Scene) {
    let runs = if s.points.len() > 500_000 { 5 } else { 21 };
    let all: Vec<StepTimings> = (0..runs)
        .map(|_| {
            detect(&Cloud::new(&s.points, Some(&s.classes)), &Params::default())
                .unwrap()
                .timings
        })
        .collect();
    let batch = (1.0 / all[0].total().as_secs_f64().max(1e-6)).ceil() as usize;
    let before = on_cpu_ns();
    for _ in 0..batch {
        black_box(detect(&Cloud::new(&s.points, Some(&s.classes)), &Params::default()).unwrap());
    }
    let cpu_ms = match (before, on_cpu_ns()) {
        (Some(a), Some(b)) => (b - a) as f64 / 1e6 / batch as f64,
        _ => f64::NAN,
    };
    let median = |f: &dyn Fn(&StepTimings) -> Duration| {
        let mut v: Vec<Duration> = all.iter().map(f).collect();
        v.sort();
        ms(v[v.len() / 2])
    };
    let tri = median(&|t| t.triangulation);
    let filter = median(&|t| t.triangle_filter);
    let planes = median(&|t| t.plane_extraction);
    let polygons = median(&|t| t.polygon_extraction);
    let label_ms = median(&|t| t.polylabel);
    let total = median(&|t| t.total());
    let rest = filter + planes + polygons + label_ms;
    let d = detect(&Cloud::new(&s.points, Some(&s.classes)), &Params::default()).unwrap();
    eprintln!(
        "split {label:>5} ({} points, {} triangles, {} sites): total {total:.3} ms wall \
         ({cpu_ms:.3} ms on-CPU) = triangulation {tri:.3} + filter {filter:.3} + planes \
         {planes:.3} + polygons {polygons:.3} + polylabel {label_ms:.3}; non-triangulation = \
         {:.0}% of triangulation",
        s.points.len(),
        d.triangle_count,
        d.sites.len(),
        100.0 * rest / tri
    );
}

fn benches(c: &mut Criterion) {
    for (n, label) in SIZES {
        let (s, pts) = scene(n);
        print_split(label, &s);
        let mut g = c.benchmark_group(format!("geometry/{label}"));
        if n >= 100_000 {
            g.sample_size(10).warm_up_time(Duration::from_secs(1));
        }
        g.measurement_time(Duration::from_secs(if n >= 1_000_000 { 20 } else { 5 }));
        g.bench_function(BenchmarkId::new("detect", label), |b| {
            b.iter(|| {
                detect(
                    &Cloud::new(black_box(&s.points), Some(&s.classes)),
                    &Params::default(),
                )
                .unwrap()
            })
        });
        g.bench_function(BenchmarkId::new("triangulate_ours", label), |b| {
            b.iter(|| triangulate(black_box(&pts)).unwrap())
        });
        g.bench_function(BenchmarkId::new("triangulate_spade", label), |b| {
            b.iter(|| spade::triangulate_spade(black_box(&pts)))
        });
        // The steps after triangulation, each on the previous step's output.
        let params = Params::default();
        let tri = triangulate(&pts).unwrap();
        let filter = FilterParams::from(&params);
        g.bench_function(BenchmarkId::new("step_filter", label), |b| {
            b.iter(|| filter_triangles(black_box(&tri), &pts, Some(&s.classes), &filter))
        });
        let keep = filter_triangles(&tri, &pts, Some(&s.classes), &filter);
        let region_params = RegionParams {
            min_triangles: params.min_region_triangles,
        };
        g.bench_function(BenchmarkId::new("step_regions", label), |b| {
            b.iter(|| extract_regions(black_box(&tri), &pts, keep.clone(), &region_params).unwrap())
        });
        let regions = extract_regions(&tri, &pts, keep, &region_params).unwrap();
        g.bench_function(BenchmarkId::new("step_polygons", label), |b| {
            b.iter(|| {
                region_polygons(black_box(&tri), &pts, &regions, &BoundaryParams::default())
                    .unwrap()
            })
        });
        // A fused map's polygons end at midpoints (the service's limit: two 0.15 m cells).
        let midpoints = BoundaryParams {
            midpoint_max_edge_m: 0.3,
        };
        g.bench_function(BenchmarkId::new("step_polygons_midpoints", label), |b| {
            b.iter(|| region_polygons(black_box(&tri), &pts, &regions, &midpoints).unwrap())
        });
        let polygons = region_polygons(&tri, &pts, &regions, &BoundaryParams::default()).unwrap();
        let ranking = RankingParams::from(&params);
        g.bench_function(BenchmarkId::new("step_polylabel_rank", label), |b| {
            b.iter(|| {
                rank_sites(black_box(&regions), polygons.clone(), None, &ranking, None).unwrap()
            })
        });
        // Keep-out disks of 0.2 m at every 50th point: every one bounding the circles (a scan), or
        // only those over the regions' long-edged triangles (a fused map of cells one point
        // spacing wide, whose pinholes are closed and polygons end at midpoints too).
        let disks: Vec<Disk> = s
            .points
            .iter()
            .step_by(50)
            .map(|p| Disk {
                center: [f64::from(p[0]), f64::from(p[1])],
                radius: 0.2,
            })
            .collect();
        let keep_out = |_: [f64; 3], _: [f64; 3], _: [f64; 4]| disks.clone();
        for (name, kind) in [
            ("detect_keep_out", CloudKind::Scan),
            (
                "detect_keep_out_fused",
                CloudKind::FusedMap {
                    cell_size_m: s.spacing_m,
                },
            ),
        ] {
            let keep_clear = KeepClear {
                disks: Some(&keep_out),
                points: None,
            };
            let cloud = Cloud::new(&s.points, Some(&s.classes))
                .with_keep_clear(keep_clear)
                .with_kind(kind);
            g.bench_function(BenchmarkId::new(name, label), |b| {
                b.iter(|| detect(black_box(&cloud), &params).unwrap())
            });
        }
        g.finish();
    }
}

criterion_group!(pipeline, benches);
criterion_main!(pipeline);
