//! Where `detect`'s time goes on the benchmark's seeded roofs: each step's wall time over many
//! runs (median and quartiles), and per run the time of everything after the triangulation over
//! the triangulation's.
//!
//! `cargo run --release -p landing-geometry --example step_split -- 100k 1M` (sizes: 1.5k, 20k,
//! 100k, 1M; `--runs N` to change the number of runs, 41 below 1 M points and 15 at 1 M).

use std::time::Duration;

use landing_geometry::synthetic::{Scene, SceneParams};
use landing_geometry::{Cloud, Params, StepTimings, detect};

fn size(label: &str) -> Option<usize> {
    match label {
        "1.5k" => Some(1_500),
        "20k" => Some(20_000),
        "100k" => Some(100_000),
        "1M" => Some(1_000_000),
        _ => None,
    }
}

/// Median and quartiles of `v`, in milliseconds.
fn spread(mut v: Vec<f64>) -> String {
    v.sort_by(f64::total_cmp);
    let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
    format!("{:.3} [{:.3}–{:.3}]", at(0.5), at(0.25), at(0.75))
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

fn report(label: &str, n: usize, runs: Option<usize>) {
    let scene = Scene::generate(&SceneParams::with_points(n), 1);
    let cloud = Cloud::new(&scene.points, Some(&scene.classes));
    let runs = runs.unwrap_or(if n >= 1_000_000 { 15 } else { 41 });
    let params = Params::default();
    let all: Vec<StepTimings> = (0..=runs)
        .map(|_| detect(&cloud, &params).expect("detect").timings)
        .skip(1) // warm-up
        .collect();
    let rest = |t: &StepTimings| t.total() - t.triangulation;
    let step = |f: fn(&StepTimings) -> Duration| spread(all.iter().map(|t| ms(f(t))).collect());
    println!("{label} ({runs} runs), ms, median [quartiles]:");
    println!("  triangulation      {}", step(|t| t.triangulation));
    println!("  filter             {}", step(|t| t.triangle_filter));
    println!("  plane extraction   {}", step(|t| t.plane_extraction));
    println!("  polygons           {}", step(|t| t.polygon_extraction));
    println!("  polylabel, ranking {}", step(|t| t.polylabel));
    println!(
        "  after triangulation {}",
        spread(all.iter().map(|t| ms(rest(t))).collect())
    );
    let ratios = all
        .iter()
        .map(|t| 100.0 * rest(t).as_secs_f64() / t.triangulation.as_secs_f64())
        .collect();
    println!("  after ÷ triangulation, per run, % {}", spread(ratios));
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let runs = (args.iter().position(|a| a == "--runs"))
        .and_then(|i| args.get(i + 1))
        .and_then(|r| r.parse().ok());
    for label in &args {
        if let Some(n) = size(label) {
            report(label, n, runs);
        }
    }
}
