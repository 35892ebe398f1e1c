//! Invariant checks for results: OGC polygon validity and whole detections. Public so that other
//! crates' tests can call them on what they get back; this crate's tests call them on every result.
//! Mesh checks are [`crate::Triangulation::check_invariants`].
//!
//! Entry points: [`check_polygon`] and [`check_detection`]. Orientation and intersection questions
//! use exact `orient2d`.

use crate::bins::Bins;
use crate::boundary::{lex, ring_is_ccw};
use crate::triangulation::coord;
use crate::{Detection, GeometryError, Polygon, ring_bounds};

/// Shoelace signed area of a ring (not closed): positive when counter-clockwise.
pub fn ring_signed_area(ring: &[[f64; 2]]) -> f64 {
    let n = ring.len();
    if n < 3 {
        return 0.0;
    }
    let o = ring[0];
    let mut a = 0.0;
    for i in 1..n - 1 {
        let p = [ring[i][0] - o[0], ring[i][1] - o[1]];
        let q = [ring[i + 1][0] - o[0], ring[i + 1][1] - o[1]];
        a += p[0] * q[1] - q[0] * p[1];
    }
    a / 2.0
}

/// True when every vertex of `ring` lies on one line, exactly: a ring of distinct vertices has
/// zero area only then. The shoelace sum cannot answer this: coordinates of very different
/// magnitudes (1e-41 beside 1e-23, found by fuzzing) round a real, tiny area to 0.
fn ring_is_collinear(ring: &[[f64; 2]]) -> bool {
    let [a, b] = [ring[0], ring[1]];
    ring[2..]
        .iter()
        .all(|&p| robust::orient2d(coord(a), coord(b), coord(p)) == 0.0)
}

/// Where a point lies relative to a ring.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Location {
    Inside,
    Boundary,
    Outside,
}

/// Exact location of `p` relative to the simple ring `ring`.
pub fn locate_in_ring(ring: &[[f64; 2]], p: [f64; 2]) -> Location {
    let n = ring.len();
    let mut inside = false;
    for i in 0..n {
        let a = ring[i];
        let b = ring[(i + 1) % n];
        // An edge that does not span p's y can neither hold p nor be crossed by its ray.
        if p[1] < a[1].min(b[1]) || p[1] > a[1].max(b[1]) {
            continue;
        }
        let o = robust::orient2d(coord(a), coord(b), coord(p));
        if o == 0.0
            && p[0] >= a[0].min(b[0])
            && p[0] <= a[0].max(b[0])
            && p[1] >= a[1].min(b[1])
            && p[1] <= a[1].max(b[1])
        {
            return Location::Boundary;
        }
        if (a[1] <= p[1] && p[1] < b[1] && o > 0.0) || (b[1] <= p[1] && p[1] < a[1] && o < 0.0) {
            inside = !inside;
        }
    }
    if inside {
        Location::Inside
    } else {
        Location::Outside
    }
}

/// OGC validity of a polygon with holes, in the orientation convention of [`Polygon`]:
///
/// - every ring has at least 3 distinct, finite vertices and no repeated vertex;
/// - the shell is counter-clockwise, every hole clockwise, none of zero area;
/// - every ring is simple (no two of its edges meet except neighbours at their shared vertex);
/// - rings do not cross or overlap; they may touch at single points;
/// - every hole lies inside the shell, and no hole lies inside another.
///
/// Not checked: that touching points leave the interior connected.
pub fn check_polygon(polygon: &Polygon) -> Result<(), GeometryError> {
    let bad = |reason: String| Err(GeometryError::InvalidPolygon { reason });
    let rings: Vec<&Vec<[f64; 2]>> = std::iter::once(&polygon.shell)
        .chain(polygon.holes.iter())
        .collect();
    for (r, ring) in rings.iter().enumerate() {
        let name = ring_name(r);
        if ring.len() < 3 {
            return bad(format!("{name} has {} vertices", ring.len()));
        }
        if let Some(p) = ring
            .iter()
            .find(|p| !(p[0].is_finite() && p[1].is_finite()))
        {
            return bad(format!("{name} has a non-finite vertex {p:?}"));
        }
        let mut sorted = (*ring).clone();
        sorted.sort_by(|a, b| lex(*a, *b));
        if let Some(w) = sorted.windows(2).find(|w| w[0] == w[1]) {
            return bad(format!("{name} repeats vertex {:?}", w[0]));
        }
        if ring_is_collinear(ring) {
            return bad(format!("{name} has zero area"));
        }
        let ccw = ring_is_ccw(ring);
        if r == 0 && !ccw {
            return bad("shell is not counter-clockwise".into());
        }
        if r > 0 && ccw {
            return bad(format!("{name} is not clockwise"));
        }
    }
    check_segments(&rings)?;
    let boxes: Vec<[f64; 4]> = polygon.holes.iter().map(|h| ring_bounds(h)).collect();
    for (h, hole) in polygon.holes.iter().enumerate() {
        if sample_location(hole, &polygon.shell) != Location::Inside {
            return bad(format!("hole {h} is not inside the shell"));
        }
        // A hole whose first vertex lies outside another's box is outside that hole (rings are
        // judged at their first vertex off the other's boundary).
        let p = hole[0];
        for (k, other) in polygon.holes.iter().enumerate() {
            let b = &boxes[k];
            let near = b[0] <= p[0] && p[0] <= b[2] && b[1] <= p[1] && p[1] <= b[3];
            if k != h && near && sample_location(hole, other) == Location::Inside {
                return bad(format!("hole {h} lies inside hole {k}"));
            }
        }
    }
    Ok(())
}

/// Checks a whole detection: every polygon valid, ranks 1, 2, … in order of non-increasing safe
/// radius, every centre inside its polygon at least (almost) its radius from the boundary, finite
/// values, unit normals pointing up.
pub fn check_detection(detection: &Detection) -> Result<(), GeometryError> {
    let bad = |reason: String| Err(GeometryError::InvalidPolygon { reason });
    let mut previous = f64::INFINITY;
    for (i, site) in detection.sites.iter().enumerate() {
        check_polygon(&site.polygon)?;
        if site.rank as usize != i + 1 {
            return bad(format!("site {i} has rank {}", site.rank));
        }
        if !(site.safe_radius_m >= 0.0 && site.safe_radius_m <= previous) {
            return bad(format!(
                "site {i} radius {} out of order",
                site.safe_radius_m
            ));
        }
        previous = site.safe_radius_m;
        let c = [site.center[0], site.center[1]];
        let d = site.polygon.signed_distance(c);
        if d < site.safe_radius_m - 1e-6 * (1.0 + site.safe_radius_m) {
            return bad(format!(
                "site {i} centre is {d} from the boundary, radius {}",
                site.safe_radius_m
            ));
        }
        let n = site.normal;
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        if !((len - 1.0).abs() < 1e-9 && n[2] > 0.0) {
            return bad(format!(
                "site {i} normal {n:?} is not a unit vector pointing up"
            ));
        }
        if !(site.center.iter().all(|v| v.is_finite()) && site.plane_height_m.is_finite()) {
            return bad(format!("site {i} has a non-finite centre or height"));
        }
        if (site.area_m2 - site.polygon.area()).abs() > 1e-6 * (1.0 + site.area_m2) {
            return bad(format!(
                "site {i} area {} is not its polygon's",
                site.area_m2
            ));
        }
    }
    Ok(())
}

fn ring_name(r: usize) -> String {
    if r == 0 {
        "shell".into()
    } else {
        format!("hole {}", r - 1)
    }
}

/// Location of `ring` relative to `other`, judged at a vertex (or, if all lie on `other`'s boundary,
/// an edge midpoint) of `ring` that is not on `other`'s boundary. Rings must not cross.
fn sample_location(ring: &[[f64; 2]], other: &[[f64; 2]]) -> Location {
    for &p in ring {
        let l = locate_in_ring(other, p);
        if l != Location::Boundary {
            return l;
        }
    }
    let n = ring.len();
    for i in 0..n {
        let (a, b) = (ring[i], ring[(i + 1) % n]);
        let l = locate_in_ring(other, [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0]);
        if l != Location::Boundary {
            return l;
        }
    }
    Location::Boundary
}

/// One edge: ring index, edge index within the ring, endpoints.
#[derive(Clone, Copy)]
struct Seg {
    ring: usize,
    index: usize,
    a: [f64; 2],
    b: [f64; 2],
}

/// Simplicity of each ring and no crossing or overlap between rings, with a uniform grid so that
/// large polygons stay near-linear: cells about two edges long, as a ring's edges lie along a
/// curve (a grid of one cell per edge would put about √n edges in each cell the ring crosses),
/// and at most 16 cells an edge.
fn check_segments(rings: &[&Vec<[f64; 2]>]) -> Result<(), GeometryError> {
    let mut segs = Vec::new();
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    let mut length = 0.0;
    for (r, ring) in rings.iter().enumerate() {
        let n = ring.len();
        for i in 0..n {
            let (a, b) = (ring[i], ring[(i + 1) % n]);
            lo = [lo[0].min(a[0]), lo[1].min(a[1])];
            hi = [hi[0].max(a[0]), hi[1].max(a[1])];
            length += (b[0] - a[0]).abs().max((b[1] - a[1]).abs());
            segs.push(Seg {
                ring: r,
                index: i,
                a,
                b,
            });
        }
    }
    let lens: Vec<usize> = rings.iter().map(|r| r.len()).collect();
    let span = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(1e-9);
    let by_length = span * segs.len() as f64 / (2.0 * length);
    let by_count = 4.0 * (segs.len() as f64).sqrt();
    // NaN (no length) gives 1 cell.
    let cells_per_side = (by_length.min(by_count).ceil() as usize).clamp(1, 1024);
    let cell = span / cells_per_side as f64;
    let index = |v: f64, o: f64| (((v - o) / cell) as usize).min(cells_per_side - 1);
    // Each edge's box of cells (first and last column, first and last row), then the edges of
    // each cell.
    let boxes: Vec<[usize; 4]> = (segs.iter())
        .map(|s| {
            [
                index(s.a[0].min(s.b[0]), lo[0]),
                index(s.a[0].max(s.b[0]), lo[0]),
                index(s.a[1].min(s.b[1]), lo[1]),
                index(s.a[1].max(s.b[1]), lo[1]),
            ]
        })
        .collect();
    let grid = Bins::new(&boxes, cells_per_side, cells_per_side);
    for y in 0..cells_per_side {
        for x in 0..cells_per_side {
            let c = y * cells_per_side + x;
            let cell = grid.run(c, c);
            for (i, &p) in cell.iter().enumerate() {
                for &q in &cell[i + 1..] {
                    // A pair is checked once, in the first cell (row by row) that both edges'
                    // boxes share: the corner of the two boxes' overlap.
                    let (bp, bq) = (&boxes[p as usize], &boxes[q as usize]);
                    if x != bp[0].max(bq[0]) || y != bp[2].max(bq[2]) {
                        continue;
                    }
                    let (p, q) = if p < q { (p, q) } else { (q, p) };
                    let (s, t) = (&segs[p as usize], &segs[q as usize]);
                    // Edges whose boxes are apart can neither cross, overlap nor touch.
                    let apart = |k: usize| {
                        s.a[k].max(s.b[k]) < t.a[k].min(t.b[k])
                            || t.a[k].max(t.b[k]) < s.a[k].min(s.b[k])
                    };
                    if !(apart(0) || apart(1)) {
                        check_pair(s, t, &lens)?;
                    }
                }
            }
        }
    }
    Ok(())
}

fn check_pair(s: &Seg, t: &Seg, lens: &[usize]) -> Result<(), GeometryError> {
    let bad = |reason: String| Err(GeometryError::InvalidPolygon { reason });
    let (a, b, c, d) = (coord(s.a), coord(s.b), coord(t.a), coord(t.b));
    let o1 = robust::orient2d(a, b, c);
    let o2 = robust::orient2d(a, b, d);
    let o3 = robust::orient2d(c, d, a);
    let o4 = robust::orient2d(c, d, b);
    let what = || {
        format!(
            "edge {} of {} and edge {} of {}",
            s.index,
            ring_name(s.ring),
            t.index,
            ring_name(t.ring)
        )
    };
    if o1 * o2 < 0.0 && o3 * o4 < 0.0 {
        return bad(format!("{} cross", what()));
    }
    let collinear = o1 == 0.0 && o2 == 0.0;
    if collinear {
        // Overlap of more than a point along the common line?
        let axis = if (s.a[0] - s.b[0]).abs() >= (s.a[1] - s.b[1]).abs() {
            0
        } else {
            1
        };
        let (s0, s1) = (s.a[axis].min(s.b[axis]), s.a[axis].max(s.b[axis]));
        let (t0, t1) = (t.a[axis].min(t.b[axis]), t.a[axis].max(t.b[axis]));
        if s0.max(t0) < s1.min(t1) {
            return bad(format!("{} overlap", what()));
        }
    }
    let touch = |o: f64, p: [f64; 2], u: [f64; 2], v: [f64; 2]| {
        o == 0.0
            && p[0] >= u[0].min(v[0])
            && p[0] <= u[0].max(v[0])
            && p[1] >= u[1].min(v[1])
            && p[1] <= u[1].max(v[1])
    };
    let meet = touch(o1, t.a, s.a, s.b)
        || touch(o2, t.b, s.a, s.b)
        || touch(o3, s.a, t.a, t.b)
        || touch(o4, s.b, t.a, t.b);
    if s.ring == t.ring && meet {
        let n = lens[s.ring];
        let adjacent = (s.index + 1) % n == t.index || (t.index + 1) % n == s.index;
        if !adjacent {
            return bad(format!("{} touch: the ring is not simple", what()));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(x0: f64, y0: f64, s: f64) -> Vec<[f64; 2]> {
        vec![[x0, y0], [x0 + s, y0], [x0 + s, y0 + s], [x0, y0 + s]]
    }
    fn cw(mut r: Vec<[f64; 2]>) -> Vec<[f64; 2]> {
        r.reverse();
        r
    }

    #[test]
    fn a_square_with_a_hole_is_valid() {
        let p = Polygon {
            shell: square(0.0, 0.0, 10.0),
            holes: vec![cw(square(2.0, 2.0, 2.0))],
        };
        check_polygon(&p).unwrap();
        assert_eq!(p.area(), 96.0);
    }

    #[test]
    fn holes_may_touch_the_shell_and_each_other_at_a_point() {
        let touching_shell = vec![[0.0, 5.0], [2.0, 6.0], [2.0, 4.0]];
        let p = Polygon {
            shell: square(0.0, 0.0, 10.0),
            holes: vec![touching_shell],
        };
        check_polygon(&p).unwrap();
        let p = Polygon {
            shell: square(0.0, 0.0, 10.0),
            holes: vec![cw(square(2.0, 2.0, 2.0)), cw(square(4.0, 4.0, 2.0))],
        };
        check_polygon(&p).unwrap();
    }

    #[test]
    fn invalid_polygons_are_caught() {
        let cases: Vec<(&str, Polygon)> = vec![
            (
                "clockwise shell",
                Polygon {
                    shell: cw(square(0.0, 0.0, 1.0)),
                    holes: vec![],
                },
            ),
            (
                "two points",
                Polygon {
                    shell: vec![[0.0, 0.0], [1.0, 0.0]],
                    holes: vec![],
                },
            ),
            (
                "bow tie",
                Polygon {
                    shell: vec![[0.0, 0.0], [1.0, 1.0], [1.0, 0.0], [0.0, 1.0]],
                    holes: vec![],
                },
            ),
            (
                "ring through a vertex twice",
                Polygon {
                    shell: vec![
                        [0.0, 0.0],
                        [2.0, 0.0],
                        [1.0, 1.0],
                        [2.0, 2.0],
                        [0.0, 2.0],
                        [1.0, 1.0],
                    ],
                    holes: vec![],
                },
            ),
            (
                // A vertex on another edge, where the two edges' boxes only touch.
                "ring touching its own edge",
                Polygon {
                    shell: vec![[0.0, 0.0], [6.0, 0.0], [6.0, 4.0], [3.0, 0.0], [0.0, 4.0]],
                    holes: vec![],
                },
            ),
            (
                "counter-clockwise hole",
                Polygon {
                    shell: square(0.0, 0.0, 10.0),
                    holes: vec![square(2.0, 2.0, 2.0)],
                },
            ),
            (
                "hole outside",
                Polygon {
                    shell: square(0.0, 0.0, 10.0),
                    holes: vec![cw(square(20.0, 2.0, 2.0))],
                },
            ),
            (
                "hole crossing the shell",
                Polygon {
                    shell: square(0.0, 0.0, 10.0),
                    holes: vec![cw(square(9.0, 2.0, 2.0))],
                },
            ),
            (
                "nested holes",
                Polygon {
                    shell: square(0.0, 0.0, 10.0),
                    holes: vec![cw(square(1.0, 1.0, 6.0)), cw(square(2.0, 2.0, 1.0))],
                },
            ),
            (
                "overlapping holes",
                Polygon {
                    shell: square(0.0, 0.0, 10.0),
                    holes: vec![cw(square(1.0, 1.0, 3.0)), cw(square(2.0, 2.0, 3.0))],
                },
            ),
            (
                "collinear hole",
                Polygon {
                    shell: square(0.0, 0.0, 10.0),
                    holes: vec![vec![[1.0, 1.0], [3.0, 3.0], [2.0, 2.0]]],
                },
            ),
            (
                "NaN",
                Polygon {
                    shell: vec![[0.0, 0.0], [1.0, f64::NAN], [0.0, 1.0]],
                    holes: vec![],
                },
            ),
        ];
        for (name, p) in cases {
            assert!(check_polygon(&p).is_err(), "{name} passed");
        }
    }

    #[test]
    fn a_tiny_hole_of_mixed_magnitudes_is_valid() {
        // Exact area about 1e-31 m²; the shoelace sum rounds it to 0 (the `detect` fuzz find).
        let hole = vec![
            [-2.7296960214249913e-23, 1.1094379637199836e-8],
            [2.263517409423877e-41, 3.073364496231079e-8],
            [0.0, 4.17230836546878e-8],
            [2.274307407599178e-41, 3.073364496231079e-8],
        ];
        assert_eq!(ring_signed_area(&hole), 0.0);
        let p = Polygon {
            shell: square(-1.0, -1.0, 2.0),
            holes: vec![hole],
        };
        check_polygon(&p).expect("a valid polygon");
    }

    #[test]
    fn locate_is_exact_on_edges() {
        let s = square(0.0, 0.0, 1.0);
        assert_eq!(locate_in_ring(&s, [0.5, 0.0]), Location::Boundary);
        assert_eq!(locate_in_ring(&s, [1.0, 1.0]), Location::Boundary);
        assert_eq!(locate_in_ring(&s, [0.5, 0.5]), Location::Inside);
        assert_eq!(locate_in_ring(&s, [1.5, 0.5]), Location::Outside);
        assert_eq!(locate_in_ring(&s, [0.5, 1e-300]), Location::Inside);
    }
}
