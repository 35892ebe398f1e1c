//! The triangle mesh as flat half-edge arrays, in delaunator's layout (see [`crate::triangulation`]
//! for the layout and the triangulators that fill it), with its invariant check.

use crate::GeometryError;

/// Marks a hull half-edge (no opposite) or an absent index.
pub const EMPTY: u32 = u32::MAX;

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
