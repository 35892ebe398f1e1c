//! 2-D Delaunay triangulation of the points' x/y, as flat half-edge arrays.
//!
//! Entry point: [`triangulate`]. The result, [`Triangulation`], uses the layout of delaunator:
//! triangle `t` is `triangles[3t..3t+3]` (point indices, counter-clockwise), half-edge `e` runs from
//! `triangles[e]` to `triangles[next(e)]`, and `halfedges[e]` is the opposite half-edge in the
//! neighbouring triangle or [`EMPTY`] on the convex hull. Adjacency is therefore free.
//!
//! Our own sweep-hull ([`crate::delaunay`]) produces it, with exact predicates; it triangulates a
//! duplicated position once and gives no triangles for collinear input. The tests and benchmarks
//! cross-check it with spade's triangulation (`tests/support/spade.rs`, given to
//! [`crate::detect`] through [`crate::Cloud::with_triangulation`]) and put it beside delaunator's,
//! the sweep Polylidar3D uses (`tests/delaunator.rs`: the same triangles on the bench clouds;
//! `benches/triangulation.rs`).

use crate::GeometryError;
pub(crate) use crate::mesh::coord;
pub use crate::mesh::{EMPTY, Triangulation, next_halfedge, prev_halfedge};

/// Triangulates the x/y of `points` (z is ignored) with our sweep-hull ([`crate::delaunay`]).
/// Coordinates must be finite (checked by [`crate::detect`]). Fewer than three distinct points or
/// collinear input give an empty result.
pub fn triangulate(points: &[[f64; 3]]) -> Result<Triangulation, GeometryError> {
    crate::delaunay::triangulate(points)
}
