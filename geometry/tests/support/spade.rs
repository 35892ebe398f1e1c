//! spade's Delaunay triangulation in our flat half-edge layout, to cross-check ours in tests and
//! benchmarks (spade is a dev-dependency only). Included with `#[path]` by the geometry's tests,
//! benchmarks and `delaunay`'s unit tests; the including module has `Triangulation` and `EMPTY`
//! (`landing_geometry::triangulation`) in scope.

use super::{EMPTY, Triangulation};

/// A spade vertex that remembers its input index.
#[derive(Debug, Clone, Copy)]
struct IndexedPoint {
    position: spade::Point2<f64>,
    index: u32,
}

impl spade::HasPosition for IndexedPoint {
    type Scalar = f64;
    fn position(&self) -> spade::Point2<f64> {
        self.position
    }
}

/// spade's `DelaunayTriangulation::bulk_load` of the x/y of `points`, converted to flat arrays.
/// Which of several duplicated positions survives is spade's choice. Panics where spade refuses
/// the points (non-finite coordinates) or there are 2^32 or more.
pub fn triangulate_spade(points: &[[f64; 3]]) -> Triangulation {
    use spade::Triangulation as _;
    if points.len() < 3 {
        return Triangulation::default();
    }
    let count = u32::try_from(points.len()).expect("fewer than 2^32 points");
    let vertices: Vec<IndexedPoint> = (0..count)
        .map(|i| {
            let p = points[i as usize];
            IndexedPoint {
                position: spade::Point2::new(p[0], p[1]),
                index: i,
            }
        })
        .collect();
    let dt = spade::DelaunayTriangulation::<IndexedPoint>::bulk_load(vertices)
        .expect("spade takes the points");
    // Inner faces have fixed indices 1..=num_inner_faces (0 is the outer face).
    let faces = dt.num_inner_faces();
    let mut triangles = Vec::with_capacity(3 * faces);
    let mut halfedges = vec![EMPTY; 3 * faces];
    for face in dt.inner_faces() {
        for v in face.vertices() {
            triangles.push(v.data().index);
        }
    }
    for face in dt.inner_faces() {
        let t = face.fix().index() - 1;
        // face.vertices()[i] is the origin of face.adjacent_edges()[i].
        for (i, edge) in face.adjacent_edges().iter().enumerate() {
            if let Some(other) = edge.rev().face().as_inner() {
                let ot = other.fix().index() - 1;
                let from = edge.to().data().index;
                let j = (0..3)
                    .find(|&j| triangles[3 * ot + j] == from)
                    .expect("spade face adjacency");
                halfedges[3 * t + i] = (3 * ot + j) as u32;
            }
        }
    }
    Triangulation {
        triangles,
        halfedges,
    }
}
