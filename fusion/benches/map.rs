//! The fusion map's own cost per frame at the size an approach reaches (~40 scans of a roof),
//! beside the geometry on the points it answers with and the bare triangulation of those points.
//!
//! `cargo bench -p landing-fusion --bench map`

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use landing_fusion::{FusionMap, FusionParams, Scan, View};
use landing_geometry::triangulation::triangulate;
use landing_geometry::{Cloud, Params, detect};

const ROOFTOP: u8 = 4;
const AIR_VENT: u8 = 10;
const SENSOR: [f64; 3] = [15.0, -20.0, 40.0];

/// A seeded scan: 1,660 points (the simulator's 16-beam scan) spread over a 30 × 30 m roof 20 m up
/// with a 2 × 2 × 1.2 m vent, and a little range noise.
fn scan(seed: u64) -> (Vec<[f64; 3]>, Vec<u8>) {
    let mut state = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
    let mut next = move || {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    (0..1_660)
        .map(|_| {
            let (x, y) = (next() * 30.0, next() * 30.0);
            let vent = (14.0..16.0).contains(&x) && (14.0..16.0).contains(&y);
            let z = if vent { 21.2 } else { 20.0 } + (next() - 0.5) * 0.04;
            ([x, y, z], if vent { AIR_VENT } else { ROOFTOP })
        })
        .unzip()
}

/// A far camera at the sensor, 0.02 rad a pixel, seeing the whole roof but never finely enough
/// ([`FusionParams::max_pixel_footprint_m`]): every insertion then looks at every cell, the most work
/// the resolution rule can cost.
fn far_view(p: &[f64; 3]) -> Option<f64> {
    let d = [p[0] - SENSOR[0], p[1] - SENSOR[1], p[2] - SENSOR[2]];
    let range2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
    (d[2] < 0.0).then(|| range2 * 0.02 / -d[2])
}

fn map_of(scans: u64, view: Option<View<'_>>) -> FusionMap<()> {
    let mut map = FusionMap::new(FusionParams::default()).unwrap();
    for i in 0..scans {
        let (points, classes) = scan(i);
        map.insert(Scan {
            time_s: i as f64 * 0.1,
            sensor: SENSOR,
            points: &points,
            classes: Some(&classes),
            view,
            ..Scan::new("drone")
        });
    }
    map
}

fn bench(c: &mut Criterion) {
    let map = map_of(40, None);
    let (next, next_classes) = scan(40);
    let landable = |class| class == ROOFTOP;
    let fused = map.fused([[f64::NEG_INFINITY; 2], [f64::INFINITY; 2]], landable);
    let points: Vec<[f32; 3]> = fused.points.iter().map(|p| p.map(|v| v as f32)).collect();
    let wide: Vec<[f64; 3]> = fused.points.clone();
    eprintln!(
        "map of 40 scans: {} cells, {} points answered",
        map.cells(),
        points.len()
    );

    let mut g = c.benchmark_group("fusion");
    g.bench_function("register", |b| {
        b.iter(|| black_box(map.register(black_box(&next), SENSOR)))
    });
    let views = [
        ("insert", None),
        (
            "insert with a camera view that resolves no cell",
            Some(View(&far_view)),
        ),
    ];
    for (name, view) in views {
        g.bench_function(name, |b| {
            b.iter_batched(
                || map_of(40, view),
                |mut m| {
                    m.insert(Scan {
                        time_s: 4.0,
                        sensor: SENSOR,
                        points: &next,
                        classes: Some(&next_classes),
                        view,
                        ..Scan::new("drone")
                    })
                },
                criterion::BatchSize::LargeInput,
            )
        });
    }
    g.bench_function("fused", |b| {
        b.iter(|| black_box(map.fused([[f64::NEG_INFINITY; 2], [f64::INFINITY; 2]], landable)))
    });
    g.bench_function("detect on the fused points", |b| {
        b.iter(|| {
            black_box(detect(
                &Cloud::new(&points, fused.classes.as_deref()),
                &Params::default(),
            ))
        })
    });
    g.bench_function("triangulation alone", |b| {
        b.iter(|| black_box(triangulate(&wide)))
    });
    // A fused frame's surface and triangulation, after the 41st scan is placed: read and
    // triangulated afresh (what a frame did before), and kept from the 40th and repaired.
    let placed_next = || {
        let mut m = map_of(40, None);
        let _ = m.meshed_surface();
        m.place(&Scan {
            time_s: 4.0,
            sensor: SENSOR,
            points: &next,
            ..Scan::new("drone")
        });
        m
    };
    g.bench_function("surface and its triangulation afresh", |b| {
        b.iter_batched(
            placed_next,
            |m| {
                let surface = m.surface([[f64::NEG_INFINITY; 2], [f64::INFINITY; 2]]);
                let local: Vec<[f32; 3]> =
                    surface.points.iter().map(|p| p.map(|v| v as f32)).collect();
                black_box(landing_geometry::triangulate_points(&local))
            },
            criterion::BatchSize::LargeInput,
        )
    });
    g.bench_function("surface and its triangulation kept", |b| {
        b.iter_batched(
            placed_next,
            |mut m| black_box(m.meshed_surface()),
            criterion::BatchSize::LargeInput,
        )
    });
    g.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = bench
}
criterion_main!(benches);
