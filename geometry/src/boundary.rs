//! Mesh to polygon: each region's boundary half-edges walked into closed rings.
//!
//! Entry point: [`region_polygons`]. A half-edge of a region is on its boundary when its opposite is
//! missing (convex hull) or lies in another triangle that is not in the region. Triangles are
//! counter-clockwise, so the region is on the left of every boundary half-edge, and following them
//! head to tail gives rings: the outer one counter-clockwise (the shell), the others clockwise
//! (holes).
//!
//! At a *pinch* vertex, where several boundary loops meet, the walk takes the outgoing boundary
//! edge met first when turning counter-clockwise from the incoming edge, i.e. the sharpest right
//! turn, through the outside. That traces the boundary of each connected piece of the outside
//! separately, so every ring stays simple: a hole touching the shell, or two holes touching, become
//! rings that touch at one vertex (valid in OGC) instead of one ring that visits the vertex twice.
//! The angular order comes from exact `orient2d` signs, never from `atan2`.

use crate::triangulation::{EMPTY, Triangulation, coord, next_halfedge};
use crate::{GeometryError, Polygon, regions::Regions};

/// Parameters of [`region_polygons`]. `Default` traces the paper's polygons: each region's own
/// boundary edges.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct BoundaryParams {
    /// Edges to midpoints: where a boundary edge `a → b` faces a triangle `b a c` of no region
    /// whose third point `c` is not a point of the region and lies within this of both `a` and
    /// `b` (x/y, metres), the ring runs `a → mid(a, c) → mid(b, c) → b` instead: the polygon ends
    /// halfway to the first point that is not part of it, not at its last point. Each such
    /// triangle is empty (Delaunay) and belongs to no region, so the polygon grows by part of
    /// it and covers no other point and no other region. 0 (the default) turns it off.
    pub midpoint_max_edge_m: f64,
}

/// One polygon per region of `regions`, in the same order.
///
/// Rings are canonical: each starts at its lexicographically smallest (x, y) vertex, holes are
/// sorted by their vertices. Every loop is bounded by the number of boundary edges.
pub fn region_polygons(
    tri: &Triangulation,
    points: &[[f64; 3]],
    regions: &Regions,
    params: &BoundaryParams,
) -> Result<Vec<Polygon>, GeometryError> {
    traced(tri, points, regions, params.midpoint_max_edge_m).map(|v| {
        v.into_iter()
            .map(|(own, grown)| grown.unwrap_or(own))
            .collect()
    })
}

/// Each region's polygon of its own points and the same polygon through midpoints
/// ([`BoundaryParams::midpoint_max_edge_m`] = `midpoint_max_edge_m`), from one walk of its
/// boundary: [`region_polygons`] without and with midpoints.
pub fn region_polygons_with_midpoints(
    tri: &Triangulation,
    points: &[[f64; 3]],
    regions: &Regions,
    midpoint_max_edge_m: f64,
) -> Result<Vec<(Polygon, Polygon)>, GeometryError> {
    traced(
        tri,
        points,
        regions,
        midpoint_max_edge_m.max(f64::MIN_POSITIVE),
    )
    .map(|v| {
        v.into_iter()
            .map(|(own, grown)| {
                let grown = grown.unwrap_or_else(|| own.clone());
                (own, grown)
            })
            .collect()
    })
}

/// Each region's polygon of its own points, and through midpoints when `midpoint_max_edge_m`
/// is positive.
fn traced(
    tri: &Triangulation,
    points: &[[f64; 3]],
    regions: &Regions,
    midpoint_max_edge_m: f64,
) -> Result<Vec<(Polygon, Option<Polygon>)>, GeometryError> {
    let mut scratch = Scratch::for_points(points.len());
    let grow = midpoint_max_edge_m > 0.0;
    if grow {
        scratch.member.resize(points.len(), false);
    }
    let edges = boundary_edges(tri, regions);
    (regions.regions.iter().zip(&edges))
        .enumerate()
        .map(|(r, (region, edges))| {
            let midpoints = grow.then_some(Midpoints {
                labels: &regions.labels,
                max_edge_m: midpoint_max_edge_m,
            });
            region_polygon(
                tri,
                points,
                (r as u32, &region.triangles),
                edges,
                midpoints,
                &mut scratch,
            )
        })
        .collect()
}

/// Each region's boundary half-edges, ascending: those whose opposite is missing or in a
/// triangle with another label. One pass over the half-edges in their order finds them for every
/// region (the labels and the regions' triangle lists agree, as [`crate::regions`] leaves them).
fn boundary_edges(tri: &Triangulation, regions: &Regions) -> Vec<Vec<u32>> {
    let labels = &regions.labels;
    let mut edges = vec![Vec::new(); regions.regions.len()];
    for (t, &label) in labels.iter().enumerate() {
        if label == EMPTY {
            continue;
        }
        for e in 3 * t..3 * t + 3 {
            let o = tri.halfedges[e];
            if o == EMPTY || labels[o as usize / 3] != label {
                edges[label as usize].push(e as u32);
            }
        }
    }
    edges
}

/// Where a region's edges run to midpoints ([`BoundaryParams::midpoint_max_edge_m`]).
struct Midpoints<'a> {
    /// Every triangle's region, or [`EMPTY`].
    labels: &'a [u32],
    max_edge_m: f64,
}

/// A vertex of a ring: a point of the mesh, or the midpoint of two.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Vertex {
    Point(u32),
    Mid(u32, u32),
}

impl Midpoints<'_> {
    /// The third point of the triangle that boundary half-edge `e` faces, when the ring detours
    /// through it: the triangle is in no region, its third point is not a `member` of this
    /// region, and that point is within `max_edge_m` of both ends of `e`.
    fn third(
        &self,
        tri: &Triangulation,
        points: &[[f64; 3]],
        member: &[bool],
        e: usize,
    ) -> Option<u32> {
        let o = tri.halfedges[e];
        if o == EMPTY || self.labels[o as usize / 3] != EMPTY {
            return None;
        }
        let c = tri.triangles[next_halfedge(next_halfedge(o as usize))];
        if member[c as usize] {
            return None;
        }
        let near = |v: u32| {
            let (p, q) = (points[v as usize], points[c as usize]);
            (p[0] - q[0]).hypot(p[1] - q[1]) <= self.max_edge_m
        };
        let (a, b) = (tri.triangles[e], tri.triangles[next_halfedge(e)]);
        (near(a) && near(b)).then_some(c)
    }
}

/// Buffers reused across regions.
#[derive(Default)]
struct Scratch {
    /// Per point: index (into `edges`) of the first outgoing boundary edge, or `EMPTY`.
    head: Vec<u32>,
    /// Per boundary edge: the next outgoing boundary edge from the same point, or `EMPTY`.
    chain: Vec<u32>,
    /// Boundary half-edges of the current region, ascending.
    edges: Vec<u32>,
    used: Vec<bool>,
    /// Per point: whether it is a vertex of the current region (only when growing to midpoints).
    member: Vec<bool>,
}

/// Closed rings of x/y points (not repeating the first at the end).
pub type Rings = Vec<Vec<[f64; 2]>>;

/// For each region of `regions` (same order), the rings that bound the part of it made of the
/// triangles `keep` accepts, or `None` when it accepts them all (the region's polygon bounds that
/// part). The part may fall apart, so there can be several counter-clockwise rings, each with
/// its clockwise holes; an empty list means no triangle is left. Rings are traced as
/// [`region_polygons`] traces them.
pub fn region_parts(
    tri: &Triangulation,
    points: &[[f64; 3]],
    regions: &Regions,
    keep: impl Fn(u32) -> bool,
) -> Result<Vec<Option<Rings>>, GeometryError> {
    let mut scratch = Scratch::for_points(points.len());
    regions
        .regions
        .iter()
        .enumerate()
        .map(|(r, region)| {
            if region.triangles.iter().all(|&t| keep(t)) {
                return Ok(None);
            }
            let inside = |t: usize| regions.labels[t] == r as u32 && keep(t as u32);
            let kept = region.triangles.iter().copied().filter(|&t| keep(t));
            let edges = edges_leaving(tri, kept, inside);
            let loops = boundary_loops(tri, points, &edges, &mut scratch)?;
            Ok(Some(
                loops
                    .iter()
                    .map(|l| ring_of(tri, points, l, None, &scratch))
                    .collect(),
            ))
        })
        .collect()
}

impl Scratch {
    fn for_points(n: usize) -> Self {
        Self {
            head: vec![EMPTY; n],
            ..Self::default()
        }
    }
}

/// The polygon of region `label` with `triangles` and boundary half-edges `edges` (ascending),
/// and through midpoints where `midpoints` says so.
fn region_polygon(
    tri: &Triangulation,
    points: &[[f64; 3]],
    (label, triangles): (u32, &[u32]),
    edges: &[u32],
    midpoints: Option<Midpoints<'_>>,
    s: &mut Scratch,
) -> Result<(Polygon, Option<Polygon>), GeometryError> {
    let loops = boundary_loops(tri, points, edges, s)?;
    let own = polygon_of(
        loops
            .iter()
            .map(|l| ring_of(tri, points, l, None, s))
            .collect(),
        label,
    )?;
    let Some(midpoints) = midpoints else {
        return Ok((own, None));
    };
    let mark = |member: &mut [bool], on: bool| {
        for &t in triangles {
            for &v in &tri.triangles[3 * t as usize..3 * t as usize + 3] {
                member[v as usize] = on;
            }
        }
    };
    mark(&mut s.member, true);
    let rings = loops
        .iter()
        .map(|l| ring_of(tri, points, l, Some(&midpoints), s))
        .collect();
    mark(&mut s.member, false);
    Ok((own, Some(polygon_of(rings, label)?)))
}

/// A region's rings as a polygon: the counter-clockwise one its shell, the others its holes,
/// sorted by their vertices.
fn polygon_of(rings: Rings, label: u32) -> Result<Polygon, GeometryError> {
    let mut shell = None;
    let mut holes = Vec::new();
    for ring in rings {
        if ring_is_ccw(&ring) {
            if shell.is_some() {
                return Err(GeometryError::InvalidMesh {
                    reason: format!("region {label} has two counter-clockwise boundary rings"),
                });
            }
            shell = Some(ring);
        } else {
            holes.push(ring);
        }
    }
    let shell = shell.ok_or_else(|| GeometryError::InvalidMesh {
        reason: format!("region {label} has no counter-clockwise boundary ring"),
    })?;
    holes.sort_by(|a, b| {
        a.iter()
            .flatten()
            .zip(b.iter().flatten())
            .map(|(x, y)| x.total_cmp(y))
            .find(|o| o.is_ne())
            .unwrap_or(a.len().cmp(&b.len()))
    });
    Ok(Polygon { shell, holes })
}

/// The half-edges of `triangles` whose opposite is missing or in a triangle that `inside`
/// does not count as one of them, ascending.
fn edges_leaving(
    tri: &Triangulation,
    triangles: impl Iterator<Item = u32>,
    inside: impl Fn(usize) -> bool,
) -> Vec<u32> {
    let mut edges = Vec::new();
    for t in triangles {
        for e in 3 * t as usize..3 * t as usize + 3 {
            let o = tri.halfedges[e];
            if o == EMPTY || !inside(o as usize / 3) {
                edges.push(e as u32);
            }
        }
    }
    edges.sort_unstable();
    edges
}

/// The loops of boundary half-edges `edges` (ascending), walked head to tail.
fn boundary_loops(
    tri: &Triangulation,
    points: &[[f64; 3]],
    edges: &[u32],
    s: &mut Scratch,
) -> Result<Vec<Vec<u32>>, GeometryError> {
    s.edges.clear();
    s.edges.extend_from_slice(edges);
    let m = s.edges.len();
    s.chain.clear();
    s.chain.resize(m, EMPTY);
    s.used.clear();
    s.used.resize(m, false);
    // Build the per-point lists in reverse so each list is in ascending edge order.
    for i in (0..m).rev() {
        let v = tri.triangles[s.edges[i] as usize] as usize;
        s.chain[i] = s.head[v];
        s.head[v] = i as u32;
    }
    let result = trace_loops(tri, points, s);
    for &e in &s.edges {
        s.head[tri.triangles[e as usize] as usize] = EMPTY;
    }
    result
}

/// The ring of coordinates of a loop of boundary half-edges, detouring through midpoints where
/// `midpoints` says so, rotated to start at its smallest vertex.
fn ring_of(
    tri: &Triangulation,
    points: &[[f64; 3]],
    edges: &[u32],
    midpoints: Option<&Midpoints<'_>>,
    s: &Scratch,
) -> Vec<[f64; 2]> {
    // Two detour triangles that share the edge a–c around a meet at its midpoint: the ring would
    // run mid(a, c) → a → mid(a, c), a spike with no area, so a and the repeated midpoint go.
    let spike = |m: Vertex, a: Vertex, n: Vertex| {
        matches!(a, Vertex::Point(_)) && matches!(m, Vertex::Mid(..)) && m == n
    };
    let mut ring: Vec<Vertex> = Vec::with_capacity(edges.len());
    let push = |ring: &mut Vec<Vertex>, v: Vertex| {
        let n = ring.len();
        if n >= 2 && spike(ring[n - 2], ring[n - 1], v) {
            ring.pop();
        } else {
            ring.push(v);
        }
    };
    for &e in edges {
        let e = e as usize;
        let a = tri.triangles[e];
        push(&mut ring, Vertex::Point(a));
        if let Some(c) = midpoints.and_then(|m| m.third(tri, points, &s.member, e)) {
            let b = tri.triangles[next_halfedge(e)];
            push(&mut ring, Vertex::Mid(a.min(c), a.max(c)));
            push(&mut ring, Vertex::Mid(b.min(c), b.max(c)));
        }
    }
    // The same where the ring closes: a spike across its end, or across its start.
    let mut start = 0;
    while ring.len() - start > 3 {
        let n = ring.len();
        if spike(ring[n - 2], ring[n - 1], ring[start]) {
            ring.truncate(n - 2);
        } else if spike(ring[n - 1], ring[start], ring[start + 1]) {
            start += 2;
        } else {
            break;
        }
    }
    let xy = |v: u32| {
        let p = points[v as usize];
        [p[0], p[1]]
    };
    let mut ring: Vec<[f64; 2]> = ring[start..]
        .iter()
        .map(|v| match *v {
            Vertex::Point(a) => xy(a),
            Vertex::Mid(a, c) => {
                let (p, q) = (xy(a), xy(c));
                [(p[0] + q[0]) / 2.0, (p[1] + q[1]) / 2.0]
            }
        })
        .collect();
    let min = (0..ring.len())
        .min_by(|&i, &j| lex(ring[i], ring[j]))
        .unwrap_or(0);
    ring.rotate_left(min);
    ring
}

/// Follows the boundary edges in `s.edges` into loops of half-edges.
fn trace_loops(
    tri: &Triangulation,
    points: &[[f64; 3]],
    s: &mut Scratch,
) -> Result<Vec<Vec<u32>>, GeometryError> {
    let m = s.edges.len();
    let xy = |v: u32| {
        let p = points[v as usize];
        [p[0], p[1]]
    };
    let mut loops = Vec::new();
    let mut steps = 0usize;
    for start in 0..m {
        if s.used[start] {
            continue;
        }
        let mut edges = Vec::new();
        let mut cur = start;
        loop {
            steps += 1;
            if steps > m {
                return Err(GeometryError::IterationLimit {
                    step: "boundary walk",
                    limit: m,
                });
            }
            s.used[cur] = true;
            let e = s.edges[cur] as usize;
            let a = tri.triangles[e];
            let b = tri.triangles[next_halfedge(e)];
            edges.push(e as u32);
            // Candidates: the unused outgoing boundary edges at b, and the ring's first edge.
            let mut best = EMPTY;
            let mut c = s.head[b as usize];
            let mut guard = 0usize;
            while c != EMPTY {
                guard += 1;
                if guard > m {
                    return Err(GeometryError::IterationLimit {
                        step: "pinch vertex",
                        limit: m,
                    });
                }
                let ci = c as usize;
                if !s.used[ci] || ci == start {
                    if best == EMPTY {
                        best = c;
                    } else {
                        let pa = xy(a);
                        let pb = xy(b);
                        let x = xy(tri.triangles[next_halfedge(s.edges[best as usize] as usize)]);
                        let y = xy(tri.triangles[next_halfedge(s.edges[ci] as usize)]);
                        if ccw_before(pb, pa, y, x) {
                            best = c;
                        }
                    }
                }
                c = s.chain[ci];
            }
            if best == EMPTY {
                return Err(GeometryError::InvalidMesh {
                    reason: format!("boundary walk stuck at point {b}"),
                });
            }
            if best as usize == start {
                break;
            }
            cur = best as usize;
        }
        loops.push(edges);
    }
    Ok(loops)
}

/// Lexicographic order of points.
pub(crate) fn lex(a: [f64; 2], b: [f64; 2]) -> std::cmp::Ordering {
    a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1]))
}

/// True when, turning counter-clockwise around `o` from the ray towards `r`, direction `x` comes
/// strictly before direction `y`. Angles are taken in (0, 2π]; exact.
fn ccw_before(o: [f64; 2], r: [f64; 2], x: [f64; 2], y: [f64; 2]) -> bool {
    let half = |p: [f64; 2]| {
        let s = robust::orient2d(coord(o), coord(r), coord(p));
        if s > 0.0 {
            0
        } else if s < 0.0 {
            1
        } else {
            // On the line: straight back (angle π) ends the first half, along the ray (angle 2π)
            // ends the second.
            let along = (p[0] - o[0]) * (r[0] - o[0]) + (p[1] - o[1]) * (r[1] - o[1]) > 0.0;
            if along { 2 } else { 0 }
        }
    };
    let (hx, hy) = (half(x), half(y));
    if hx != hy {
        return hx < hy;
    }
    if hx == 2 {
        return false;
    }
    robust::orient2d(coord(o), coord(x), coord(y)) > 0.0
}

/// Orientation of a simple ring, exact: the turn at its lexicographically smallest vertex.
pub(crate) fn ring_is_ccw(ring: &[[f64; 2]]) -> bool {
    let n = ring.len();
    if n < 3 {
        return false;
    }
    let i = (0..n).min_by(|&i, &j| lex(ring[i], ring[j])).unwrap_or(0);
    let prev = ring[(i + n - 1) % n];
    let next = ring[(i + 1) % n];
    robust::orient2d(coord(prev), coord(ring[i]), coord(next)) > 0.0
}
