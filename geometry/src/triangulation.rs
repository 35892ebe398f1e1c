//! 2-D Delaunay triangulation of the points' x/y, as flat half-edge arrays.
//!
//! Entry point: [`triangulate`]. The result, [`Triangulation`], uses the layout of delaunator:
//! triangle `t` is `triangles[3t..3t+3]` (point indices, counter-clockwise), half-edge `e` runs from
//! `triangles[e]` to `triangles[next(e)]`, and `halfedges[e]` is the opposite half-edge in the
//! neighbouring triangle or [`EMPTY`] on the convex hull. Adjacency is therefore free.
//!
//! Two triangulators produce it: our own sweep-hull ([`crate::delaunay`], the default, the faster
//! one) and spade's (kept for cross-checks). Both use exact predicates; both triangulate a
//! duplicated position once and give no triangles for collinear input.

use crate::GeometryError;
pub(crate) use crate::mesh::coord;
pub use crate::mesh::{EMPTY, Triangulation, next_halfedge, prev_halfedge};

/// Which implementation triangulates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Triangulator {
    /// Our sweep-hull on flat arrays ([`crate::delaunay`]).
    #[default]
    SweepHull,
    /// spade's `DelaunayTriangulation::bulk_load`, converted to flat arrays.
    Spade,
}

/// Configuration of [`triangulate`].
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct TriangulationConfig {
    pub triangulator: Triangulator,
}

/// Triangulates the x/y of `points` (z is ignored). Coordinates must be finite (checked by
/// [`crate::detect`]). Fewer than three distinct points or collinear input give an empty result.
pub fn triangulate(
    points: &[[f64; 3]],
    config: &TriangulationConfig,
) -> Result<Triangulation, GeometryError> {
    match config.triangulator {
        Triangulator::SweepHull => crate::delaunay::triangulate(points),
        Triangulator::Spade => triangulate_spade(points),
    }
}

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

fn triangulate_spade(points: &[[f64; 3]]) -> Result<Triangulation, GeometryError> {
    use spade::Triangulation as _;
    if points.len() < 3 {
        return Ok(Triangulation::default());
    }
    let index_limit = u32::try_from(points.len()).map_err(|_| GeometryError::InvalidParameter {
        field: "points",
        value: points.len().to_string(),
        reason: "at most 2^32 - 1 points",
    })?;
    // Which of several duplicated positions survives is spade's choice.
    let vertices: Vec<IndexedPoint> = (0..index_limit)
        .map(|i| {
            let p = points[i as usize];
            IndexedPoint {
                position: spade::Point2::new(p[0], p[1]),
                index: i,
            }
        })
        .collect();
    let dt = spade::DelaunayTriangulation::<IndexedPoint>::bulk_load(vertices).map_err(|e| {
        GeometryError::InvalidMesh {
            reason: format!("spade rejected the points: {e:?}"),
        }
    })?;
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
                    .ok_or_else(|| GeometryError::InvalidMesh {
                        reason: "spade face adjacency".into(),
                    })?;
                halfedges[3 * t + i] = (3 * ot + j) as u32;
            }
        }
    }
    Ok(Triangulation {
        triangles,
        halfedges,
    })
}
