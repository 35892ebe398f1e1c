//! Our triangulation against delaunator's on the triangulation bench's clouds (1.5 k to 1 M
//! points): the same triangles.
//!
//! These clouds are in general position but for a few exact duplicates (f32 rounding: none at
//! 1.5 k to 100 k, 9 at 1 M): both triangulators keep one copy of a duplicated position (ours the
//! smallest index, delaunator the first in its sort), so each vertex is compared as the smallest
//! index at its position, and the test asks for the same set of triangles, not only the same count.
//! Collinear, cocircular and duplicate-heavy input is not compared with delaunator: its in-circle
//! test is plain floating point and it skips near-duplicates within 2ε (absolute) only when they
//! meet in its sort, so there it may keep a non-Delaunay edge or a point ours merges; spade (exact
//! predicates) is the reference for those (tests/triangulation.rs).

use landing_geometry::triangulation::{EMPTY, Triangulation, triangulate};

#[path = "support/clouds.rs"]
mod clouds;

/// Each triangle as its sorted triple of canonical vertices, sorted: the triangulation as a set.
fn triangle_set(triangles: impl Iterator<Item = usize>, canonical: &[usize]) -> Vec<[usize; 3]> {
    let flat: Vec<usize> = triangles.map(|v| canonical[v]).collect();
    let mut set: Vec<[usize; 3]> = flat
        .chunks_exact(3)
        .map(|t| {
            let mut t = [t[0], t[1], t[2]];
            t.sort_unstable();
            t
        })
        .collect();
    set.sort_unstable();
    set
}

/// For each point, the smallest index at its x/y position.
fn canonical_indices(points: &[[f64; 3]]) -> Vec<usize> {
    let mut by_position: Vec<((u64, u64), usize)> = points
        .iter()
        .enumerate()
        .map(|(i, p)| (((p[0] + 0.0).to_bits(), (p[1] + 0.0).to_bits()), i))
        .collect();
    by_position.sort_unstable();
    let mut canonical: Vec<usize> = (0..points.len()).collect();
    for w in 1..by_position.len() {
        if by_position[w].0 == by_position[w - 1].0 {
            canonical[by_position[w].1] = canonical[by_position[w - 1].1];
        }
    }
    canonical
}

fn hull_edges(t: &Triangulation) -> usize {
    t.halfedges.iter().filter(|&&h| h == EMPTY).count()
}

#[test]
fn same_triangles_as_delaunator_on_the_bench_clouds() {
    for (n, label) in clouds::SIZES {
        let (_, pts) = clouds::cloud(n);
        let canonical = canonical_indices(&pts);
        let duplicates = (0..pts.len()).filter(|&i| canonical[i] != i).count();
        assert!(
            duplicates * 10_000 < pts.len(),
            "{label}: {duplicates} duplicates"
        );
        let ours = triangulate(&pts).unwrap();
        let theirs = delaunator::triangulate(&clouds::delaunator_points(&pts));
        assert_eq!(ours.len(), theirs.len(), "{label}: triangle counts");
        assert_eq!(
            hull_edges(&ours),
            theirs.hull.len(),
            "{label}: hull lengths"
        );
        assert_eq!(
            triangle_set(ours.triangles.iter().map(|&v| v as usize), &canonical),
            triangle_set(theirs.triangles.iter().copied(), &canonical),
            "{label}: triangles"
        );
    }
}
