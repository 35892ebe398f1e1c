//! What a fused answer can tell the fleet's catalog: the ground its map resolved, and which of its
//! sites lie wholly on it ([`Evidence`]). Computed on the worker with the answer, from the map's
//! surface points, their classes and their unresolved flags (`landing_fusion::Fused`); the
//! catalog's feed (`crate::catalog`) decides from it what a stream reports.

use std::collections::{BTreeMap, HashMap};

use super::Site;
use landing_geometry::geodetic::Geodetic;

/// Side of the squares the seen area is made of, metres. A square is seen when the cameras
/// resolved the map points in it (see [`Evidence::seen`]); a metre keeps a roof's seen area to
/// tens of rectangles, and is well under the smallest safe circle worth recording.
pub const SEEN_CELL_M: f64 = 1.0;

/// Why a fused answer tells the catalog nothing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NotCatalogued {
    /// The frame carries no geodetic origin: its sites have no WGS-84 position.
    NoGeodeticOrigin,
    /// The map cannot say which ground the cameras resolved: no camera classified it, or the
    /// stream turned the resolution rule off (`max_pixel_footprint_m = 0`).
    Unresolvable,
}

/// The ground a fused answer's map resolved and which of its sites lie on it, in the world frame
/// (local ENU of `origin`).
#[derive(Debug, Clone, PartialEq)]
pub struct Evidence {
    /// The WGS-84 position of the world origin (the frame's).
    pub origin: Geodetic,
    /// The seen area: the [`SEEN_CELL_M`] squares `(i, j)` of the world grid (the square from
    /// `(i, j) * SEEN_CELL_M` to `(i + 1, j + 1) * SEEN_CELL_M`), sorted; a square is seen when a map point in it shows
    /// something other than landable ground (an obstacle is seen, whatever the resolution), or
    /// when its map points are all landable ground that a camera resolved. A square with any map
    /// point no camera classified, or classified landable but not resolved, is not seen: what the
    /// cameras could not resolve keeps its earlier verdict.
    pub seen: Vec<(i64, i64)>,
    /// Per site of the answer, in order: whether every map point within its safe circle is
    /// landable ground a camera resolved (and there is at least one).
    pub resolved: Vec<bool>,
}

/// The state of one map point, as the catalog reads it.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Point {
    /// No camera classified it, or it is landable and no view resolved it.
    Unresolved,
    /// Landable, and resolved.
    Landable,
    /// Something else: an obstacle, a wall, the ground.
    Other,
}

/// The map's surface as the answer read it: frame-local points relative to `origin`, their
/// classes and unresolved flags, and the landable classes.
pub(super) struct MapSurface<'a> {
    pub points: &'a [[f32; 3]],
    pub origin: [f64; 3],
    pub classes: Option<&'a [u8]>,
    pub unresolved: &'a [bool],
    pub landable: &'a [u8],
    /// The map marks unresolved ground (its `max_pixel_footprint_m` is above 0).
    pub resolving: bool,
}

/// The evidence of an answer with `sites` (world frame) computed from `surface`.
pub(super) fn evidence(
    geodetic_origin: Option<Geodetic>,
    surface: &MapSurface<'_>,
    sites: &[Site],
) -> Result<Evidence, NotCatalogued> {
    let origin = geodetic_origin.ok_or(NotCatalogued::NoGeodeticOrigin)?;
    let classes = match surface.classes {
        Some(c) if surface.resolving && c.len() == surface.points.len() => c,
        _ => return Err(NotCatalogued::Unresolvable),
    };
    let state = |i: usize| {
        let class = classes[i];
        if class == 0 || surface.unresolved.get(i).copied().unwrap_or(false) {
            Point::Unresolved
        } else if surface.landable.contains(&class) {
            Point::Landable
        } else {
            Point::Other
        }
    };
    let [x0, y0, _] = surface.origin;
    let world = |p: &[f32; 3]| (f64::from(p[0]) + x0, f64::from(p[1]) + y0);
    let resolved = sites
        .iter()
        .map(|s| {
            let (cx, cy, r2) = (s.center[0], s.center[1], s.safe_radius_m.powi(2));
            let mut inside = surface
                .points
                .iter()
                .enumerate()
                .filter(|(_, p)| {
                    let (x, y) = world(p);
                    (x - cx).powi(2) + (y - cy).powi(2) < r2
                })
                .peekable();
            inside.peek().is_some() && inside.all(|(i, _)| state(i) == Point::Landable)
        })
        .collect();
    // Per square: (any point seen as something else, any resolved landable, any unresolved).
    let mut squares: HashMap<(i64, i64), (bool, bool, bool)> = HashMap::new();
    for (i, p) in surface.points.iter().enumerate() {
        let (x, y) = world(p);
        let key = (
            (x / SEEN_CELL_M).floor() as i64,
            (y / SEEN_CELL_M).floor() as i64,
        );
        let square = squares.entry(key).or_default();
        match state(i) {
            Point::Other => square.0 = true,
            Point::Landable => square.1 = true,
            Point::Unresolved => square.2 = true,
        }
    }
    let mut seen: Vec<(i64, i64)> = squares
        .into_iter()
        .filter(|(_, (other, landable, unresolved))| *other || (*landable && !*unresolved))
        .map(|(key, _)| key)
        .collect();
    seen.sort_unstable();
    Ok(Evidence {
        origin,
        seen,
        resolved,
    })
}

/// [`SEEN_CELL_M`] grid squares merged into disjoint rectangles `[min_x, min_y, max_x, max_y]`,
/// world metres: runs along each row, and runs that repeat on the next row grown into them.
pub fn rectangles(squares: impl Iterator<Item = (i64, i64)>) -> Vec<[f64; 4]> {
    let mut rows: BTreeMap<i64, Vec<i64>> = BTreeMap::new();
    for (i, j) in squares {
        rows.entry(j).or_default().push(i);
    }
    // Open rectangles: (first column, last column) -> first row, and the last row they reach.
    let mut open: HashMap<(i64, i64), (i64, i64)> = HashMap::new();
    let mut out = Vec::new();
    let close = |(i0, i1): (i64, i64), (j0, j1): (i64, i64), out: &mut Vec<[f64; 4]>| {
        out.push([
            i0 as f64 * SEEN_CELL_M,
            j0 as f64 * SEEN_CELL_M,
            (i1 + 1) as f64 * SEEN_CELL_M,
            (j1 + 1) as f64 * SEEN_CELL_M,
        ]);
    };
    for (j, mut columns) in rows {
        columns.sort_unstable();
        let mut runs: Vec<(i64, i64)> = Vec::new();
        for i in columns {
            match runs.last_mut() {
                Some(run) if run.1 + 1 == i => run.1 = i,
                _ => runs.push((i, i)),
            }
        }
        let mut next = HashMap::with_capacity(runs.len());
        for run in runs {
            let rows = match open.remove(&run) {
                Some((j0, j1)) if j1 + 1 == j => (j0, j),
                Some(stale) => {
                    close(run, stale, &mut out);
                    (j, j)
                }
                None => (j, j),
            };
            next.insert(run, rows);
        }
        for (run, rows) in open.drain() {
            close(run, rows, &mut out);
        }
        open = next;
    }
    for (run, rows) in open {
        close(run, rows, &mut out);
    }
    out.sort_by(|a, b| a[1].total_cmp(&b[1]).then(a[0].total_cmp(&b[0])));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn squares_merge_into_disjoint_rectangles_that_cover_them() {
        // An L: a 3 x 2 block and a column above its left edge, and a lone square apart.
        let squares = [
            (0, 0),
            (1, 0),
            (2, 0),
            (0, 1),
            (1, 1),
            (2, 1),
            (0, 2),
            (0, 3),
            (5, 5),
        ];
        let r = rectangles(squares.into_iter());
        let area: f64 = r.iter().map(|b| (b[2] - b[0]) * (b[3] - b[1])).sum();
        assert_eq!(area, squares.len() as f64 * SEEN_CELL_M * SEEN_CELL_M);
        assert_eq!(r.len(), 3, "{r:?}");
        for (i, j) in squares {
            let (x, y) = (i as f64 + 0.5, j as f64 + 0.5);
            assert!(
                r.iter()
                    .any(|b| b[0] < x && x < b[2] && b[1] < y && y < b[3]),
                "({i}, {j}) in {r:?}"
            );
        }
    }

    fn site(center: [f64; 3], safe_radius_m: f64) -> Site {
        Site {
            rank: 1,
            shell: vec![],
            holes: vec![],
            plane_height_m: center[2],
            center,
            center_geodetic: None,
            safe_radius_m,
            area_m2: 0.0,
            normal: [0.0, 0.0, 1.0],
            point_count: 0,
            triangle_count: 0,
        }
    }

    #[test]
    fn only_circles_on_resolved_landable_ground_are_resolved() {
        // A 10 m x 10 m roof of points every 0.5 m, relative to (100, 200, 0); the column at
        // x = 104.5 is unresolved, the point at (101, 201) is an obstacle.
        let mut points = Vec::new();
        let mut unresolved = Vec::new();
        let mut classes = Vec::new();
        for i in 0..20 {
            for j in 0..20 {
                let (x, y) = (i as f32 * 0.5, j as f32 * 0.5);
                points.push([x, y, 10.0]);
                unresolved.push(i == 9);
                classes.push(if (i, j) == (2, 2) { 7 } else { 4 });
            }
        }
        let surface = MapSurface {
            points: &points,
            origin: [100.0, 200.0, 0.0],
            classes: Some(&classes),
            unresolved: &unresolved,
            landable: &[4],
            resolving: true,
        };
        let origin = Geodetic {
            latitude_deg: 40.0,
            longitude_deg: -74.0,
            altitude_m: 0.0,
        };
        let sites = [
            site([107.5, 207.5, 10.0], 1.5), // clear
            site([104.0, 205.0, 10.0], 1.0), // reaches the unresolved column
            site([101.0, 201.0, 10.0], 0.6), // on the obstacle
            site([150.0, 250.0, 10.0], 1.0), // off the map: nothing seen there
        ];
        let e = evidence(Some(origin), &surface, &sites).unwrap();
        assert_eq!(e.resolved, vec![true, false, false, false]);
        let seen = |x: f64, y: f64| {
            e.seen
                .binary_search(&(
                    (x / SEEN_CELL_M).floor() as i64,
                    (y / SEEN_CELL_M).floor() as i64,
                ))
                .is_ok()
        };
        assert!(
            seen(107.5, 207.5) && seen(101.2, 201.2),
            "resolved and obstacle"
        );
        assert!(!seen(104.7, 205.0), "the unresolved column");
        assert!(!seen(150.0, 250.0));
        assert_eq!(
            evidence(None, &surface, &sites).unwrap_err(),
            NotCatalogued::NoGeodeticOrigin
        );
        let off = MapSurface {
            resolving: false,
            ..surface
        };
        assert_eq!(
            evidence(Some(origin), &off, &sites).unwrap_err(),
            NotCatalogued::Unresolvable
        );
    }
}
