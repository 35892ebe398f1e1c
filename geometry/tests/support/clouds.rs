//! The seeded clouds the triangulation bench and its tests share: the synthetic roof of
//! `SceneParams::with_points(n)`, seed 1 (as the pipeline bench), widened to f64 as `detect` does.
//! Included with `#[path]`.

use landing_geometry::synthetic::{Scene, SceneParams};

/// The sizes the issue names, with their labels.
pub const SIZES: [(usize, &str); 4] = [
    (1_500, "1.5k"),
    (20_000, "20k"),
    (100_000, "100k"),
    (1_000_000, "1M"),
];

/// The scene of about `n` points and its points in f64.
pub fn cloud(n: usize) -> (Scene, Vec<[f64; 3]>) {
    let s = Scene::generate(&SceneParams::with_points(n), 1);
    let p = s.points.iter().map(|p| p.map(f64::from)).collect();
    (s, p)
}

/// The x/y of `points` as delaunator takes them.
pub fn delaunator_points(points: &[[f64; 3]]) -> Vec<delaunator::Point> {
    points
        .iter()
        .map(|p| delaunator::Point { x: p[0], y: p[1] })
        .collect()
}
