//! The kept triangulation against a fresh one after every edit of seeded random edit sequences:
//! points moved within their cells (a fusion map's means), moved farther, on the hull and inside,
//! new points inside and outside the hull, duplicate positions, and point sets rebuilt; and
//! a few points on a coarse lattice, where hull edges run through several points.

use std::collections::HashSet;

use landing_geometry::delaunay::KeptTriangulation;
use landing_geometry::synthetic::Pcg32;
use landing_geometry::{Triangulation, triangulate_points};

/// Each triangle as its vertices from the smallest (the same turn), sorted: two triangulations
/// of the same points are the same triangles exactly when these are equal.
fn canonical(t: &Triangulation) -> Vec<[u32; 3]> {
    let mut out: Vec<[u32; 3]> = t
        .triangles
        .chunks_exact(3)
        .map(|v| {
            let k = (0..3).min_by_key(|&k| v[k]).unwrap_or(0);
            [v[k], v[(k + 1) % 3], v[(k + 2) % 3]]
        })
        .collect();
    out.sort_unstable();
    out
}

/// The kept triangulation is a Delaunay triangulation of exactly `points` (each distinct
/// position a vertex) with the fresh one's triangle count, and, with `same_triangles` (no four
/// points on a circle), the fresh one's triangles.
fn check(kept: &KeptTriangulation, points: &[[f32; 3]], same_triangles: bool, what: &str) {
    let tri = kept.triangulation();
    let xy: Vec<[f64; 2]> = points
        .iter()
        .map(|p| [f64::from(p[0]), f64::from(p[1])])
        .collect();
    tri.check_invariants(&xy, true)
        .unwrap_or_else(|e| panic!("{what}: {e}"));
    let fresh = triangulate_points(points).unwrap();
    assert_eq!(tri.len(), fresh.len(), "{what}: triangle count");
    let used: HashSet<u32> = tri.triangles.iter().copied().collect();
    let positions: HashSet<[u32; 2]> = points
        .iter()
        .map(|p| [p[0], p[1]].map(|v| (v + 0.0).to_bits())) // -0.0 is 0.0
        .collect();
    if !tri.is_empty() {
        assert_eq!(
            used.len(),
            positions.len(),
            "{what}: every position a vertex"
        );
    }
    if same_triangles {
        assert_eq!(canonical(&tri), canonical(&fresh), "{what}: the triangles");
    }
}

/// A fusion map's surface in miniature: one point per occupied cell of a grid of `CELL` metres,
/// somewhere in its cell, with the cells' keys.
struct Grid {
    points: Vec<[f32; 3]>,
    cells: Vec<[i32; 2]>,
    occupied: HashSet<[i32; 2]>,
    /// Where the grid's cell (0, 0) starts.
    offset: [f64; 2],
}

const CELL: f64 = 0.15;

impl Grid {
    fn point(&self, cell: [i32; 2], at: [f64; 2]) -> [f32; 3] {
        let c = |k: usize| self.offset[k] + (f64::from(cell[k]) + at[k]) * CELL;
        [c(0) as f32, c(1) as f32, 0.0]
    }

    /// Adds `cell` with its point somewhere in it, unless it is there; returns whether added.
    fn add(&mut self, g: &mut Pcg32, cell: [i32; 2]) -> bool {
        if !self.occupied.insert(cell) {
            return false;
        }
        let p = self.point(cell, [g.unit(), g.unit()]);
        self.points.push(p);
        self.cells.push(cell);
        true
    }

    /// Moves point `i` within its cell: a little (a mean taking one more point) or anywhere.
    fn nudge(&mut self, g: &mut Pcg32, i: usize) {
        let cell = self.cells[i];
        let old = self.points[i];
        let at = |k: usize| (f64::from(old[k]) - self.offset[k]) / CELL - f64::from(cell[k]);
        let far = g.unit() < 0.2;
        let w = if far {
            1.0
        } else {
            1.0 / (2.0 + 30.0 * g.unit())
        };
        let to = [0, 1].map(|k| (at(k) * (1.0 - w) + g.unit() * w).clamp(0.0, 0.999));
        self.points[i] = self.point(cell, to);
    }
}

/// One seeded sequence: a patch of cells, then `steps` edits of moves and new cells (growing
/// the patch and, now and then, far outside it), checked after each.
fn edit_sequence(
    seed: u64,
    offset: [f64; 2],
    steps: usize,
) -> landing_geometry::delaunay::KeptStats {
    let mut g = Pcg32::new(seed);
    let mut grid = Grid {
        points: Vec::new(),
        cells: Vec::new(),
        occupied: HashSet::new(),
        offset,
    };
    let side = 20 + (g.next_u32() % 20) as i32;
    for _ in 0..side * side / 2 {
        let cell = [
            (g.next_u32() % side as u32) as i32,
            (g.next_u32() % side as u32) as i32,
        ];
        grid.add(&mut g, cell);
    }
    let mut kept = KeptTriangulation::new();
    kept.update(&grid.points, &[]).unwrap();
    check(&kept, &grid.points, true, &format!("seed {seed}, start"));
    for step in 0..steps {
        let mut changed = Vec::new();
        let n = grid.points.len();
        for _ in 0..(g.next_u32() as usize % (n / 8 + 1)) {
            let i = g.next_u32() as usize % n;
            grid.nudge(&mut g, i);
            changed.push(i as u32);
        }
        let grow = g.next_u32() % 40;
        for _ in 0..grow {
            let from = grid.cells[g.next_u32() as usize % grid.cells.len()];
            let d = [(g.next_u32() % 5) as i32 - 2, (g.next_u32() % 5) as i32 - 2];
            grid.add(&mut g, [from[0] + d[0], from[1] + d[1]]);
        }
        if step % 7 == 3 {
            let far = [
                side + 5 + (g.next_u32() % 10) as i32,
                (g.next_u32() % 60) as i32 - 20,
            ];
            grid.add(&mut g, far);
        }
        kept.update(&grid.points, &changed).unwrap();
        check(
            &kept,
            &grid.points,
            true,
            &format!("seed {seed}, step {step}"),
        );
    }
    kept.stats()
}

#[test]
fn kept_triangulation_is_the_fresh_one_after_random_edits() {
    let mut total = landing_geometry::delaunay::KeptStats::default();
    for seed in 0..12u64 {
        // Map-local coordinates: near 0, and a map hundreds of metres across.
        let offset = [[0.0, 0.0], [-3.7, 2.1], [412.3, -377.9]][seed as usize % 3];
        let stats = edit_sequence(seed, offset, 30);
        total.repaired += stats.repaired;
        total.rebuilt += stats.rebuilt;
        total.moved += stats.moved;
        total.inserted += stats.inserted;
        total.reinserted += stats.reinserted;
    }
    // Most updates must take the kept path, or the test would only check the rebuild.
    eprintln!("{total:?}");
    assert!(total.repaired > 3 * total.rebuilt, "{total:?}");
    assert!(total.moved > 1000 && total.inserted > 1000, "{total:?}");
    assert!(total.reinserted > 100, "{total:?}");
}

#[test]
fn lattice_points_with_cocircular_fours_stay_delaunay() {
    // Points on an exact lattice: every unit square is four points on one circle, so only the
    // triangle count and the Delaunay property can be compared. Moves between lattice points.
    let mut g = Pcg32::new(77);
    let mut points: Vec<[f32; 3]> = (0..400)
        .map(|i| [(i % 20) as f32, (i / 20) as f32, 0.0])
        .collect();
    let mut kept = KeptTriangulation::new();
    kept.update(&points, &[]).unwrap();
    check(&kept, &points, false, "lattice");
    for step in 0..40 {
        let mut changed = Vec::new();
        for _ in 0..10 {
            let i = g.next_u32() as usize % points.len();
            // Half a unit off and back: onto edges' midpoints and cocircular again.
            let d = if step % 2 == 0 { 0.5 } else { 0.0 };
            points[i] = [(i % 20) as f32 + d, (i / 20) as f32, 0.0];
            changed.push(i as u32);
        }
        for k in 0..3 {
            points.push([20.0 + k as f32, step as f32 % 20.0, 0.0]);
        }
        kept.update(&points, &changed).unwrap();
        check(&kept, &points, false, &format!("lattice, step {step}"));
    }
}

#[test]
fn duplicates_hull_moves_and_fewer_points_rebuild() {
    let mut g = Pcg32::new(5);
    let mut points: Vec<[f32; 3]> = (0..300)
        .map(|_| [g.range(0.0, 10.0) as f32, g.range(0.0, 10.0) as f32, 0.0])
        .collect();
    let mut kept = KeptTriangulation::new();
    kept.update(&points, &[]).unwrap();
    // A new point on an existing one: triangulated once, as the fresh triangulation does.
    points.push(points[17]);
    kept.update(&points, &[]).unwrap();
    check(&kept, &points, true, "duplicate");
    // It moves off: now both are vertices.
    let last = points.len() - 1;
    points[last][0] += 0.01;
    kept.update(&points, &[last as u32]).unwrap();
    check(&kept, &points, true, "duplicate moved off");
    // Every point moved far (hull points among them, triangles folding over).
    for p in &mut points {
        p[0] = 10.0 - p[0];
        p[1] *= 1.5;
    }
    let all: Vec<u32> = (0..points.len() as u32).collect();
    kept.update(&points, &all).unwrap();
    check(&kept, &points, true, "mirrored");
    points.truncate(100);
    kept.update(&points, &[]).unwrap();
    check(&kept, &points, true, "fewer points");
    // Collinear, then a triangle again.
    let line: Vec<[f32; 3]> = (0..5).map(|i| [i as f32, 2.0 * i as f32, 0.0]).collect();
    kept.update(&line, &[]).unwrap();
    assert!(kept.triangulation().is_empty());
    let mut more = line.clone();
    more.push([0.0, 5.0, 0.0]);
    kept.update(&more, &[]).unwrap();
    check(&kept, &more, false, "off the line");
}

#[test]
fn bad_input_is_an_error_naming_it() {
    let mut kept = KeptTriangulation::new();
    let points = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let e = kept.update(&points, &[3]).unwrap_err();
    assert!(e.to_string().contains("changed"), "{e}");
    let bad = [[0.0, 0.0, 0.0], [f32::NAN, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let e = kept.update(&bad, &[]).unwrap_err();
    assert!(e.to_string().contains("point 1"), "{e}");
}

#[test]
fn hull_points_and_folding_moves_are_taken_out_and_inserted_again() {
    let mut g = Pcg32::new(9);
    let mut points: Vec<[f32; 3]> = (0..200)
        .map(|_| [g.range(0.0, 10.0) as f32, g.range(0.0, 10.0) as f32, 0.0])
        .collect();
    // Corners: hull points for sure.
    points.extend([
        [-1.0, -1.0, 0.0],
        [11.0, -1.0, 0.0],
        [11.0, 11.0, 0.0],
        [-1.0, 11.0, 0.0],
    ]);
    let mut kept = KeptTriangulation::new();
    kept.update(&points, &[]).unwrap();
    points[200] = [-1.5, -0.5, 0.0]; // outward
    points[202] = [9.0, 9.0, 0.0]; // far inward: off the hull
    points[5] = [5.0, 5.0, 0.0];
    points[6] = [0.1, 9.9, 0.0];
    kept.update(&points, &[200, 202, 5, 6]).unwrap();
    check(&kept, &points, true, "hull moves");
    let stats = kept.stats();
    assert_eq!((stats.rebuilt, stats.repaired), (1, 1), "{stats:?}");
    assert!(stats.reinserted >= 2, "{stats:?}");
}

#[test]
fn a_point_leaving_a_straight_hull_edge_opposite_a_hull_corner_rebuilds() {
    // Found by the `stream` fuzz target: points 1-5 on one line (the hull's long edge), point 0
    // the hull's third corner. Point 3 moves inward off the line: taken out, the hull would
    // run 2 → 0 → 4 with 0 on it twice.
    let mut points = vec![
        [-0.45, -7.05, 0.0],
        [0.55, -9.05, 0.0],
        [0.55, -8.05, 0.0],
        [0.55, -7.05, 0.0],
        [0.55, -6.05, 0.0],
        [0.55, 8.95, 0.0],
    ];
    let mut kept = KeptTriangulation::new();
    kept.update(&points, &[]).unwrap();
    check(&kept, &points, false, "the fan");
    points[3] = [0.547_573_45, -7.000_799_7, 0.0];
    points.push([-2.440_293_8, -7.246_800_4, 0.0]);
    kept.update(&points, &[3, 6]).unwrap();
    check(&kept, &points, false, "moved off the line");
}

#[test]
fn few_points_on_a_coarse_lattice_stay_delaunay_through_random_edits() {
    // Many points collinear with hull edges and four on a circle: points on a 6 × 6 lattice,
    // moved to other lattice points, nudged a little off them, or added, a few at a time.
    let mut repaired = 0;
    let mut reinserted = 0;
    for seed in 0..4000u64 {
        let mut g = Pcg32::new(1000 + seed);
        let lattice = |g: &mut Pcg32| -> [f32; 3] {
            [(g.next_u32() % 6) as f32, (g.next_u32() % 6) as f32, 0.0]
        };
        let mut points: Vec<[f32; 3]> =
            (0..3 + g.next_u32() % 6).map(|_| lattice(&mut g)).collect();
        let mut kept = KeptTriangulation::new();
        kept.update(&points, &[]).unwrap();
        check(&kept, &points, false, &format!("seed {seed}, start"));
        for step in 0..12 {
            let mut changed = Vec::new();
            for _ in 0..1 + g.next_u32() % 3 {
                let i = g.next_u32() as usize % points.len();
                points[i] = match g.next_u32() % 3 {
                    0 => lattice(&mut g),
                    1 => {
                        let [x, y, z] = points[i];
                        [
                            x + g.range(-0.1, 0.1) as f32,
                            y + g.range(-0.1, 0.1) as f32,
                            z,
                        ]
                    }
                    _ => {
                        let [x, y, z] = points[i];
                        [x.round(), y.round(), z]
                    }
                };
                changed.push(i as u32);
            }
            for _ in 0..g.next_u32() % 3 {
                points.push(lattice(&mut g));
            }
            kept.update(&points, &changed).unwrap();
            check(&kept, &points, false, &format!("seed {seed}, step {step}"));
        }
        repaired += kept.stats().repaired;
        reinserted += kept.stats().reinserted;
    }
    // Duplicate positions rebuild; the rest must take the kept path.
    eprintln!("repaired {repaired}, points reinserted {reinserted}");
    assert!(
        repaired > 10_000 && reinserted > 10_000,
        "{repaired} {reinserted}"
    );
}
