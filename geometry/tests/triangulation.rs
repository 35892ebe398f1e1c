//! The triangulators against each other and against the Delaunay invariants, on random, grid
//! (many cocircular points), collinear and duplicate-heavy input.

use landing_geometry::synthetic::Pcg32;
use landing_geometry::triangulation::{EMPTY, Triangulation, triangulate};

#[path = "support/spade.rs"]
mod spade;

fn run(points: &[[f64; 3]]) -> Triangulation {
    triangulate(points).unwrap()
}

fn xy(points: &[[f64; 3]]) -> Vec<[f64; 2]> {
    points.iter().map(|p| [p[0], p[1]]).collect()
}

/// Number of distinct x/y positions.
fn distinct(points: &[[f64; 3]]) -> usize {
    let mut v: Vec<(u64, u64)> = points
        .iter()
        .map(|p| ((p[0] + 0.0).to_bits(), (p[1] + 0.0).to_bits()))
        .collect();
    v.sort_unstable();
    v.dedup();
    v.len()
}

/// Checks ours fully (structure, Delaunay, every distinct point used) and compares the triangle
/// count with spade's.
fn check(points: &[[f64; 3]], what: &str) -> Triangulation {
    let ours = run(points);
    ours.check_invariants(&xy(points), true)
        .unwrap_or_else(|e| panic!("{what}: {e}"));
    let spade = spade::triangulate_spade(points);
    spade
        .check_invariants(&xy(points), true)
        .unwrap_or_else(|e| panic!("{what} (spade): {e}"));
    assert_eq!(
        ours.len(),
        spade.len(),
        "{what}: triangle counts differ from spade"
    );
    if !ours.is_empty() {
        let mut used = vec![false; points.len()];
        for &v in &ours.triangles {
            used[v as usize] = true;
        }
        assert_eq!(
            used.iter().filter(|&&u| u).count(),
            distinct(points),
            "{what}: points left out"
        );
    }
    ours
}

fn random(n: usize, seed: u64, scale: f64) -> Vec<[f64; 3]> {
    let mut g = Pcg32::new(seed);
    (0..n)
        .map(|_| [g.range(-scale, scale), g.range(-scale, scale), g.unit()])
        .collect()
}

#[test]
fn random_points_match_spade() {
    for seed in 0..40 {
        let n = 3 + (seed as usize * 37) % 2000;
        check(
            &random(n, seed, 100.0),
            &format!("random n={n} seed={seed}"),
        );
    }
}

#[test]
fn f32_rounded_points_far_from_the_origin() {
    // LiDAR clouds arrive as f32 in a world frame: coarse, many near-collinear triples.
    let mut g = Pcg32::new(9);
    let pts: Vec<[f64; 3]> = (0..3000)
        .map(|_| {
            let x = (500_000.0 + g.range(0.0, 50.0)) as f32;
            let y = (4_000_000.0 + g.range(0.0, 50.0)) as f32;
            [f64::from(x), f64::from(y), 0.0]
        })
        .collect();
    check(&pts, "f32 far from origin");
}

#[test]
fn grids_with_many_cocircular_points() {
    for (nx, ny) in [(2, 2), (3, 3), (10, 7), (40, 40), (1, 50), (100, 3)] {
        let mut pts = Vec::new();
        for y in 0..ny {
            for x in 0..nx {
                pts.push([f64::from(x), f64::from(y), 0.0]);
            }
        }
        let t = check(&pts, &format!("grid {nx}x{ny}"));
        if nx > 1 && ny > 1 {
            assert_eq!(t.len(), 2 * (nx as usize - 1) * (ny as usize - 1));
        } else {
            assert!(t.is_empty());
        }
    }
    // A scrambled grid, so the sweep meets points in an unhelpful order.
    let mut pts = Vec::new();
    for i in 0..900u32 {
        let j = (i * 577) % 900;
        pts.push([f64::from(j % 30) * 0.25, f64::from(j / 30) * 0.25, 0.0]);
    }
    check(&pts, "scrambled grid");
}

#[test]
fn points_on_circles() {
    let mut pts = Vec::new();
    for ring in 1..6 {
        for k in 0..24 {
            let a = f64::from(k) * std::f64::consts::TAU / 24.0;
            let r = f64::from(ring);
            pts.push([r * a.cos(), r * a.sin(), 0.0]);
        }
    }
    pts.push([0.0, 0.0, 0.0]);
    check(&pts, "concentric circles");
}

#[test]
fn degenerate_inputs() {
    assert!(run(&[]).is_empty());
    assert!(run(&[[0.0, 0.0, 0.0]]).is_empty());
    assert!(run(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]).is_empty());
    let collinear: Vec<[f64; 3]> = (0..100)
        .map(|i| [f64::from(i), 2.0 * f64::from(i), 0.0])
        .collect();
    assert!(check(&collinear, "collinear").is_empty());
    let same = vec![[3.0, 4.0, 0.0]; 50];
    assert!(check(&same, "all duplicates").is_empty());
    let two_spots: Vec<[f64; 3]> = (0..50)
        .map(|i| {
            if i % 2 == 0 {
                [0.0, 0.0, 0.0]
            } else {
                [1.0, 1.0, 0.0]
            }
        })
        .collect();
    assert!(check(&two_spots, "two spots").is_empty());
    // Collinear plus one point off the line: a fan.
    let mut fan = collinear.clone();
    fan.push([0.0, 10.0, 0.0]);
    assert_eq!(check(&fan, "fan").len(), 99);
}

#[test]
fn duplicate_heavy_input() {
    for seed in 0..10 {
        let base = random(200, seed, 10.0);
        let mut g = Pcg32::new(seed + 100);
        let pts: Vec<[f64; 3]> = (0..2000)
            .map(|_| base[(g.next_u32() % 200) as usize])
            .collect();
        check(&pts, &format!("duplicates seed {seed}"));
        // Also snapped to a coarse lattice: duplicates, collinear and cocircular at once.
        let snapped: Vec<[f64; 3]> = random(1500, seed, 5.0)
            .iter()
            .map(|p| [p[0].round(), p[1].round(), 0.0])
            .collect();
        check(&snapped, &format!("snapped seed {seed}"));
    }
}

#[test]
fn scan_like_rows() {
    // Rows of a scan: many points share a y, duplicates at the row ends.
    let mut pts = Vec::new();
    for r in 0..60 {
        for c in 0..80 {
            pts.push([
                f64::from(c) * 0.1 + f64::from(r % 2) * 0.05,
                f64::from(r) * 0.2,
                0.0,
            ]);
        }
        pts.push([7.9, f64::from(r) * 0.2, 0.0]);
    }
    check(&pts, "scan rows");
}
