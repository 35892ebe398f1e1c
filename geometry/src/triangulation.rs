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

/// Marks a hull half-edge (no opposite) or an absent index.
pub const EMPTY: u32 = u32::MAX;

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

/// A triangulation as flat half-edge arrays (see the module doc).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Triangulation {
    /// Three point indices per triangle, counter-clockwise.
    pub triangles: Vec<u32>,
    /// Opposite half-edge of each half-edge, or [`EMPTY`].
    pub halfedges: Vec<u32>,
}

/// The next half-edge in the same triangle.
#[inline]
pub fn next_halfedge(e: usize) -> usize {
    if e % 3 == 2 { e - 2 } else { e + 1 }
}

/// The previous half-edge in the same triangle.
#[inline]
pub fn prev_halfedge(e: usize) -> usize {
    if e.is_multiple_of(3) { e + 2 } else { e - 1 }
}

impl Triangulation {
    /// Number of triangles.
    pub fn len(&self) -> usize {
        self.triangles.len() / 3
    }

    /// True when there are no triangles.
    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// Checks the structure and, with `check_delaunay`, the empty-circumcircle property with exact
    /// predicates (O(n) per triangle pair across each edge: cheap, it is the local criterion, which
    /// for a triangulation is equivalent to the global one).
    ///
    /// Structure: lengths, indices in range, every triangle strictly counter-clockwise, `halfedges`
    /// an involution joining half-edges with swapped endpoints, Euler's formula for a triangulated
    /// convex hull (`T = 2V - h - 2`, with `h` the hull edges) over the points that are used.
    pub fn check_invariants(
        &self,
        points: &[[f64; 2]],
        check_delaunay: bool,
    ) -> Result<(), GeometryError> {
        let bad = |reason: String| Err(GeometryError::InvalidMesh { reason });
        let n = self.triangles.len();
        if !n.is_multiple_of(3) || self.halfedges.len() != n {
            return bad(format!(
                "{} triangle indices, {} half-edges",
                n,
                self.halfedges.len()
            ));
        }
        let mut used = vec![false; points.len()];
        for (e, &v) in self.triangles.iter().enumerate() {
            let Some(u) = used.get_mut(v as usize) else {
                return bad(format!("half-edge {e} uses point {v} of {}", points.len()));
            };
            *u = true;
        }
        let p = |e: usize| coord(points[self.triangles[e] as usize]);
        let mut hull_edges = 0usize;
        for t in 0..self.len() {
            let o = robust::orient2d(p(3 * t), p(3 * t + 1), p(3 * t + 2));
            if o <= 0.0 {
                return bad(format!(
                    "triangle {t} is not counter-clockwise (orient2d = {o})"
                ));
            }
        }
        for e in 0..n {
            let o = self.halfedges[e];
            if o == EMPTY {
                hull_edges += 1;
                continue;
            }
            let o = o as usize;
            if o >= n || self.halfedges[o] as usize != e || o / 3 == e / 3 {
                return bad(format!(
                    "half-edge {e} has opposite {o}, which does not point back"
                ));
            }
            if self.triangles[e] != self.triangles[next_halfedge(o)]
                || self.triangles[o] != self.triangles[next_halfedge(e)]
            {
                return bad(format!(
                    "half-edges {e} and {o} do not share their endpoints"
                ));
            }
            if check_delaunay && e < o {
                // The vertex of the neighbour opposite the shared edge must not lie strictly inside
                // this triangle's circumcircle.
                let q = p(prev_halfedge(o));
                let ic = robust::incircle(p(e), p(next_halfedge(e)), p(prev_halfedge(e)), q);
                if ic > 0.0 {
                    return bad(format!(
                        "edge {e}-{o} is not locally Delaunay (incircle = {ic})"
                    ));
                }
            }
        }
        let vertices = used.iter().filter(|&&u| u).count();
        if n > 0 && self.len() + hull_edges + 2 != 2 * vertices {
            return bad(format!(
                "Euler: {} triangles, {vertices} vertices, {hull_edges} hull edges",
                self.len()
            ));
        }
        Ok(())
    }
}

/// The point as a `robust` coordinate.
#[inline]
pub(crate) fn coord(p: [f64; 2]) -> robust::Coord<f64> {
    robust::Coord { x: p[0], y: p[1] }
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
