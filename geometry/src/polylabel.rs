//! Pole of inaccessibility: the point of a polygon (with holes) farthest from its boundary, and
//! that distance.
//!
//! Entry point: [`polylabel`]. The search of Mapbox's polylabel (Garcia-Castellanos & Lombardo's
//! idea): cover the bounding box with square cells, keep them in a priority queue ordered by the
//! best distance any point of the cell could reach (`d(centre) + half-diagonal`, because the signed
//! distance is 1-Lipschitz), split the most promising cell into four, and drop every cell that
//! cannot beat the best centre found so far by more than the precision. When the queue is empty the
//! best centre is within the precision of the optimum. Unlike the `polylabel` crate this returns
//! the distance and needs no `geo`.
//!
//! [`polylabel_avoiding`] also keeps the circle clear of keep-out [`Disk`]s: obstacles that are
//! not part of the polygon (seen by the camera but missed by the LiDAR, say). The distance is then
//! `min(signed distance to the boundary, distance to the nearest disk's rim)`, still 1-Lipschitz,
//! so the same search keeps the same precision guarantee.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use crate::bins::Bins;
use crate::{GeometryError, Polygon};

/// Parameters of [`polylabel`].
#[derive(Debug, Clone, PartialEq)]
pub struct PolylabelParams {
    /// The returned distance is at least the optimum minus this, metres (> 0).
    pub precision_m: f64,
    /// Bound on the cells examined; reaching it is an error, not a silent loss of precision.
    pub max_cells: usize,
}

impl Default for PolylabelParams {
    fn default() -> Self {
        Self {
            precision_m: crate::Params::default().polylabel_precision_m,
            max_cells: 2_000_000,
        }
    }
}

/// The pole of inaccessibility of a polygon.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pole {
    /// x, y of the centre.
    pub center: [f64; 2],
    /// Distance from `center` to the nearest edge of the shell or of a hole (the safe radius).
    pub distance: f64,
}

/// A circle that a safe circle must not overlap: centre x, y and radius, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Disk {
    pub center: [f64; 2],
    pub radius: f64,
}

/// Finds the pole of inaccessibility of `polygon` within `params.precision_m` of the optimum.
///
/// A polygon with an empty or degenerate shell gives distance 0 at the first shell vertex (or the
/// origin when there is none).
pub fn polylabel(polygon: &Polygon, params: &PolylabelParams) -> Result<Pole, GeometryError> {
    polylabel_avoiding(polygon, &[], params)
}

/// [`polylabel`] for a circle that must also stay clear of every disk of `keep_out`. The returned
/// distance is clamped at 0: a polygon that the disks cover entirely gives 0.
pub fn polylabel_avoiding(
    polygon: &Polygon,
    keep_out: &[Disk],
    params: &PolylabelParams,
) -> Result<Pole, GeometryError> {
    polylabel_in_rings(&rings(polygon), keep_out, params)
}

/// [`polylabel_avoiding`] for the area that `rings` bound by the even-odd rule: one polygon's
/// shell and holes, or several polygons' (a region with parts cut out, say). The first ring's
/// first vertex stands in when the rings are empty or degenerate.
pub fn polylabel_in_rings(
    rings: &[&[[f64; 2]]],
    keep_out: &[Disk],
    params: &PolylabelParams,
) -> Result<Pole, GeometryError> {
    if !(params.precision_m > 0.0 && params.precision_m.is_finite()) {
        return Err(GeometryError::InvalidParameter {
            field: "polylabel_precision_m",
            value: params.precision_m.to_string(),
            reason: "must be finite and > 0",
        });
    }
    let Some(&first) = rings.first().and_then(|r| r.first()) else {
        return Ok(Pole {
            center: [0.0, 0.0],
            distance: 0.0,
        });
    };
    let field = Field {
        edges: Edges::new(rings),
        disks: DiskGrid::new(keep_out),
    };
    let (mut min, mut max) = (first, first);
    for p in rings.iter().copied().flatten() {
        min = [min[0].min(p[0]), min[1].min(p[1])];
        max = [max[0].max(p[0]), max[1].max(p[1])];
    }
    let (w, h) = (max[0] - min[0], max[1] - min[1]);
    if !(w > 0.0 && h > 0.0) {
        return Ok(Pole {
            center: first,
            distance: 0.0,
        });
    }
    // Square cells of side min(w, h), but never more than ~1024 of them to start with.
    let mut cell = w.min(h).max((w * h / 1024.0).sqrt());
    while (w / cell).ceil() * (h / cell).ceil() > 4096.0 {
        cell *= 2.0;
    }
    let half = cell / 2.0;
    let mut heap = BinaryHeap::new();
    let mut examined = 0usize;
    let mut x = min[0];
    while x < max[0] {
        let mut y = min[1];
        while y < max[1] {
            heap.push(Cell::new([x + half, y + half], half, &field));
            examined += 1;
            y += cell;
        }
        x += cell;
    }
    // Start from the better of the area centroid and the box centre.
    let mut best = Cell::new(centroid(rings[0]).unwrap_or(first), 0.0, &field);
    let mid = Cell::new([min[0] + w / 2.0, min[1] + h / 2.0], 0.0, &field);
    if mid.d > best.d {
        best = mid;
    }
    while let Some(c) = heap.pop() {
        let (center, half, max) = (c.center, c.half, c.max);
        if c.d > best.d {
            best = c;
        }
        if max - best.d <= params.precision_m {
            continue;
        }
        let q = half / 2.0;
        for (dx, dy) in [(-q, -q), (q, -q), (-q, q), (q, q)] {
            heap.push(Cell::new([center[0] + dx, center[1] + dy], q, &field));
        }
        examined += 4;
        if examined > params.max_cells {
            return Err(GeometryError::IterationLimit {
                step: "polylabel",
                limit: params.max_cells,
            });
        }
    }
    Ok(Pole {
        center: best.center,
        distance: best.d.max(0.0),
    })
}

/// Signed distance from `p` to the boundary of `polygon`: positive inside (inside the shell and
/// outside every hole), negative outside.
pub fn signed_distance(polygon: &Polygon, p: [f64; 2]) -> f64 {
    Edges::new(&rings(polygon)).signed_distance(p)
}

/// A polygon's shell and holes.
pub(crate) fn rings(polygon: &Polygon) -> Vec<&[[f64; 2]]> {
    std::iter::once(&polygon.shell)
        .chain(&polygon.holes)
        .map(Vec::as_slice)
        .collect()
}

/// What the circle must stay clear of: the polygon's boundary and the keep-out disks.
struct Field {
    edges: Edges,
    disks: Option<DiskGrid>,
}

impl Field {
    fn distance(&self, p: [f64; 2]) -> f64 {
        let d = self.edges.signed_distance(p);
        match &self.disks {
            // Only a disk nearer than the boundary can lower the distance.
            Some(grid) if d > 0.0 => grid.clearance(p, d).min(d),
            _ => d,
        }
    }
}

/// Keep-out disks bucketed on a uniform grid, for "distance to the nearest rim" queries.
struct DiskGrid {
    disks: Vec<Disk>,
    /// Disk indices per cell, row-major.
    bins: Bins,
    origin: [f64; 2],
    cell: f64,
    cols: usize,
    rows: usize,
    max_radius: f64,
}

impl DiskGrid {
    fn new(disks: &[Disk]) -> Option<Self> {
        let disks: Vec<Disk> = disks
            .iter()
            .copied()
            .filter(|d| {
                d.center.iter().all(|c| c.is_finite()) && d.radius.is_finite() && d.radius >= 0.0
            })
            .collect();
        if disks.is_empty() {
            return None;
        }
        let (mut min, mut max) = (disks[0].center, disks[0].center);
        let mut max_radius = 0.0f64;
        for d in &disks {
            min = [min[0].min(d.center[0]), min[1].min(d.center[1])];
            max = [max[0].max(d.center[0]), max[1].max(d.center[1])];
            max_radius = max_radius.max(d.radius);
        }
        // About two disks per cell.
        let (w, h) = (max[0] - min[0], max[1] - min[1]);
        let cell = ((w * h * 2.0 / disks.len() as f64).sqrt())
            .max(w.max(h) / 1024.0)
            .max(1e-3);
        let cols = (w / cell) as usize + 1;
        let rows = (h / cell) as usize + 1;
        let spans: Vec<[usize; 4]> = (disks.iter())
            .map(|d| {
                let c = (((d.center[0] - min[0]) / cell) as usize).min(cols - 1);
                let r = (((d.center[1] - min[1]) / cell) as usize).min(rows - 1);
                [c, c, r, r]
            })
            .collect();
        let bins = Bins::new(&spans, cols, rows);
        Some(Self {
            disks,
            bins,
            origin: min,
            cell,
            cols,
            rows,
            max_radius,
        })
    }

    /// `min(limit, distance from p to the nearest disk's rim)` (negative inside a disk): rings of
    /// cells around p's cell, stopping once no farther ring can beat the best found or `limit`.
    fn clearance(&self, p: [f64; 2], limit: f64) -> f64 {
        let cx = (p[0] - self.origin[0]) / self.cell;
        let cy = (p[1] - self.origin[1]) / self.cell;
        // Clamped, the cast truncates as the floor would (no libm call); NaN gives 0.
        let clamp = |v: f64, n: usize| v.clamp(0.0, (n - 1) as f64) as usize;
        let (ci, cj) = (clamp(cx, self.cols), clamp(cy, self.rows));
        // Distance from p to the grid's box: no disk centre is nearer.
        let far = [
            self.origin[0] + self.cols as f64 * self.cell,
            self.origin[1] + self.rows as f64 * self.cell,
        ];
        let gx = (self.origin[0] - p[0]).max(p[0] - far[0]).max(0.0);
        let gy = (self.origin[1] - p[1]).max(p[1] - far[1]).max(0.0);
        // Inside the box (the usual case) no libm call.
        let gap = if gx == 0.0 || gy == 0.0 {
            gx + gy
        } else {
            gx.hypot(gy)
        };
        let mut best = limit;
        for k in 0..self.cols.max(self.rows) {
            // Every cell of ring k is at least (k - 1) cells away from p, and no nearer than the box.
            if ((k as f64 - 1.0) * self.cell).max(gap) - self.max_radius >= best {
                break;
            }
            if k == 0 {
                best = self.nearest_rim(p, cj * self.cols + ci, best);
                continue;
            }
            // Ring k: its top and bottom rows whole, then its two columns between them.
            let (i0, i1) = (ci.saturating_sub(k), (ci + k).min(self.cols - 1));
            let rows = [cj.checked_sub(k), Some(cj + k).filter(|&j| j < self.rows)];
            for j in rows.into_iter().flatten() {
                for i in i0..=i1 {
                    best = self.nearest_rim(p, j * self.cols + i, best);
                }
            }
            let (j0, j1) = (cj.saturating_sub(k - 1), (cj + k - 1).min(self.rows - 1));
            let columns = [ci.checked_sub(k), Some(ci + k).filter(|&i| i < self.cols)];
            for i in columns.into_iter().flatten() {
                for j in j0..=j1 {
                    best = self.nearest_rim(p, j * self.cols + i, best);
                }
            }
        }
        best
    }

    /// `min(best, distance from p to the nearest rim of cell c's disks)`.
    fn nearest_rim(&self, p: [f64; 2], c: usize, mut best: f64) -> f64 {
        for &d in self.bins.run(c, c) {
            let disk = &self.disks[d as usize];
            let dist = (p[0] - disk.center[0]).hypot(p[1] - disk.center[1]);
            best = best.min(dist - disk.radius);
        }
        best
    }
}

/// All edges of all rings as flat segments (ax, ay, bx, by), in chunks of consecutive edges with
/// bounding boxes, so a query skips the chunks that cannot hold the nearest edge or a crossing.
struct Edges {
    segs: Vec<[f64; 4]>,
    /// (first segment, end, [min x, min y, max x, max y]) per chunk.
    chunks: Vec<(usize, usize, [f64; 4])>,
}

/// Edges per chunk: small enough to prune well, large enough to keep the chunk loop cheap.
const CHUNK: usize = 16;

impl Edges {
    fn new(rings: &[&[[f64; 2]]]) -> Self {
        let mut segs = Vec::new();
        let mut chunks = Vec::new();
        for ring in rings {
            let n = ring.len();
            let mut start = segs.len();
            for i in 0..n {
                let a = ring[i];
                let b = ring[(i + 1) % n];
                segs.push([a[0], a[1], b[0], b[1]]);
                if segs.len() - start == CHUNK || i + 1 == n {
                    let mut bb = [
                        f64::INFINITY,
                        f64::INFINITY,
                        f64::NEG_INFINITY,
                        f64::NEG_INFINITY,
                    ];
                    for s in &segs[start..] {
                        bb = [
                            bb[0].min(s[0]).min(s[2]),
                            bb[1].min(s[1]).min(s[3]),
                            bb[2].max(s[0]).max(s[2]),
                            bb[3].max(s[1]).max(s[3]),
                        ];
                    }
                    chunks.push((start, segs.len(), bb));
                    start = segs.len();
                }
            }
        }
        Self { segs, chunks }
    }

    fn signed_distance(&self, p: [f64; 2]) -> f64 {
        let mut inside = false;
        let mut d2 = f64::INFINITY;
        for &(start, end, bb) in &self.chunks {
            // A ray towards +x can only cross the chunk if p.y is within its y-range and the chunk
            // reaches right of p.
            let may_cross = p[1] >= bb[1] && p[1] <= bb[3] && p[0] <= bb[2];
            let dx = (bb[0] - p[0]).max(p[0] - bb[2]).max(0.0);
            let dy = (bb[1] - p[1]).max(p[1] - bb[3]).max(0.0);
            let may_be_nearer = dx * dx + dy * dy < d2;
            if !(may_cross || may_be_nearer) {
                continue;
            }
            for &[ax, ay, bx, by] in &self.segs[start..end] {
                // Even-odd ray cast over all rings: inside the shell and outside the holes.
                if may_cross
                    && (ay > p[1]) != (by > p[1])
                    && p[0] < (bx - ax) * (p[1] - ay) / (by - ay) + ax
                {
                    inside = !inside;
                }
                if may_be_nearer {
                    d2 = d2.min(segment_distance2(p, ax, ay, bx, by));
                }
            }
        }
        let d = d2.sqrt();
        if inside { d } else { -d }
    }
}

/// The squared distance from `p` to the segment `a`-`b`.
#[inline]
pub(crate) fn segment_distance2(p: [f64; 2], ax: f64, ay: f64, bx: f64, by: f64) -> f64 {
    let (dx, dy) = (bx - ax, by - ay);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 {
        (((p[0] - ax) * dx + (p[1] - ay) * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let (ex, ey) = (ax + t * dx - p[0], ay + t * dy - p[1]);
    ex * ex + ey * ey
}

/// Area centroid of a ring, if its area is not zero.
fn centroid(ring: &[[f64; 2]]) -> Option<[f64; 2]> {
    let n = ring.len();
    let o = ring[0];
    let (mut a, mut cx, mut cy) = (0.0, 0.0, 0.0);
    for i in 0..n {
        let p = [ring[i][0] - o[0], ring[i][1] - o[1]];
        let q = [ring[(i + 1) % n][0] - o[0], ring[(i + 1) % n][1] - o[1]];
        let f = p[0] * q[1] - q[0] * p[1];
        a += f;
        cx += (p[0] + q[0]) * f;
        cy += (p[1] + q[1]) * f;
    }
    (a != 0.0).then(|| [o[0] + cx / (3.0 * a), o[1] + cy / (3.0 * a)])
}

/// A square cell of the search.
struct Cell {
    center: [f64; 2],
    half: f64,
    /// Signed distance of the centre.
    d: f64,
    /// Upper bound of the signed distance anywhere in the cell.
    max: f64,
}

impl Cell {
    fn new(center: [f64; 2], half: f64, field: &Field) -> Self {
        let d = field.distance(center);
        Self {
            center,
            half,
            d,
            max: d + half * std::f64::consts::SQRT_2,
        }
    }
}

impl PartialEq for Cell {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for Cell {}
impl PartialOrd for Cell {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Cell {
    fn cmp(&self, other: &Self) -> Ordering {
        self.max
            .total_cmp(&other.max)
            .then(other.center[0].total_cmp(&self.center[0]))
            .then(other.center[1].total_cmp(&self.center[1]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(x0: f64, y0: f64, s: f64) -> Vec<[f64; 2]> {
        vec![[x0, y0], [x0 + s, y0], [x0 + s, y0 + s], [x0, y0 + s]]
    }

    #[test]
    fn the_disk_grid_finds_the_nearest_rim_as_a_scan_of_every_disk_does() {
        // Seeded disks far from the origin, queries inside, beside and far outside their box,
        // limits small and large: the ring search returns exactly the scan's minimum.
        let mut rng = crate::synthetic::Pcg32::new(7);
        let mut u = |lo: f64, hi: f64| lo + (hi - lo) * rng.unit();
        let origin = [-2.0e6, 4.0e5];
        for round in 1..60 {
            let disks: Vec<Disk> = (0..round * 2)
                .map(|_| Disk {
                    center: [origin[0] + u(0.0, 30.0), origin[1] + u(0.0, 12.0)],
                    radius: u(0.0, 2.5),
                })
                .collect();
            let grid = DiskGrid::new(&disks).expect("finite disks");
            for _ in 0..200 {
                let p = [origin[0] + u(-40.0, 70.0), origin[1] + u(-40.0, 50.0)];
                let limit = u(0.0, 80.0);
                let scan = (disks.iter())
                    .map(|d| (p[0] - d.center[0]).hypot(p[1] - d.center[1]) - d.radius)
                    .fold(limit, f64::min);
                assert_eq!(
                    grid.clearance(p, limit),
                    scan,
                    "round {round}, {p:?}, {limit}"
                );
            }
        }
    }

    #[test]
    fn square_pole_is_its_centre() {
        let p = Polygon {
            shell: square(0.0, 0.0, 10.0),
            holes: vec![],
        };
        let pole = polylabel(
            &p,
            &PolylabelParams {
                precision_m: 0.01,
                ..Default::default()
            },
        )
        .unwrap();
        assert!((pole.distance - 5.0).abs() <= 0.01, "{pole:?}");
        assert!((pole.center[0] - 5.0).abs() < 0.1 && (pole.center[1] - 5.0).abs() < 0.1);
    }

    #[test]
    fn a_central_hole_pushes_the_pole_aside() {
        let mut hole = square(4.0, 4.0, 2.0);
        hole.reverse();
        let p = Polygon {
            shell: square(0.0, 0.0, 10.0),
            holes: vec![hole],
        };
        let pole = polylabel(
            &p,
            &PolylabelParams {
                precision_m: 0.01,
                ..Default::default()
            },
        )
        .unwrap();
        // Best is in a corner region: distance to the nearest of two outer edges and the hole.
        assert!(p.signed_distance(pole.center) >= pole.distance - 1e-9);
        assert!(pole.distance > 2.0 && pole.distance < 2.5, "{pole:?}");
        assert!(p.signed_distance([5.0, 5.0]) < 0.0);
    }

    #[test]
    fn degenerate_polygons_give_zero() {
        let pole = polylabel(&Polygon::default(), &PolylabelParams::default()).unwrap();
        assert_eq!(pole.distance, 0.0);
        let line = Polygon {
            shell: vec![[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]],
            holes: vec![],
        };
        assert_eq!(
            polylabel(&line, &PolylabelParams::default())
                .unwrap()
                .distance,
            0.0
        );
    }

    #[test]
    fn bad_precision_is_an_error() {
        let p = Polygon {
            shell: square(0.0, 0.0, 1.0),
            holes: vec![],
        };
        let r = polylabel(
            &p,
            &PolylabelParams {
                precision_m: 0.0,
                ..Default::default()
            },
        );
        assert!(matches!(r, Err(GeometryError::InvalidParameter { .. })));
    }

    #[test]
    fn a_keep_out_disk_pushes_the_pole_aside() {
        let p = Polygon {
            shell: square(0.0, 0.0, 10.0),
            holes: vec![],
        };
        let params = PolylabelParams {
            precision_m: 0.01,
            ..Default::default()
        };
        let disk = Disk {
            center: [5.0, 5.0],
            radius: 1.0,
        };
        let pole = polylabel_avoiding(&p, &[disk], &params).unwrap();
        let clear = (pole.center[0] - 5.0).hypot(pole.center[1] - 5.0) - 1.0;
        assert!(clear >= pole.distance - 1e-9, "{pole:?}");
        assert!(p.signed_distance(pole.center) >= pole.distance - 1e-9);
        // The best circle sits in a corner, touching two sides and the disk:
        // r = (5 - r)·√2 - 1  =>  r = (5√2 - 1) / (1 + √2).
        let optimum = (5.0 * std::f64::consts::SQRT_2 - 1.0) / (1.0 + std::f64::consts::SQRT_2);
        assert!(
            (pole.distance - optimum).abs() <= 0.01 + 1e-9,
            "{pole:?} vs {optimum}"
        );
        // Disks outside the polygon change nothing.
        let far = Disk {
            center: [30.0, 30.0],
            radius: 2.0,
        };
        assert_eq!(
            polylabel_avoiding(&p, &[far], &params).unwrap(),
            polylabel(&p, &params).unwrap()
        );
        // A disk over everything leaves no safe point.
        let cover = Disk {
            center: [5.0, 5.0],
            radius: 8.0,
        };
        assert_eq!(
            polylabel_avoiding(&p, &[cover], &params).unwrap().distance,
            0.0
        );
    }

    /// Random polygons and random disks: the circle is clear of the boundary and of every disk,
    /// and no point of a fine lattice does better by more than the precision.
    #[test]
    fn circles_avoiding_random_disks_are_clear_and_near_optimal() {
        let mut rng = crate::synthetic::Pcg32::new(7);
        let precision = 0.05;
        for case in 0..40 {
            let size = rng.range(4.0, 20.0);
            let mut hole = square(size * 0.3, size * 0.4, size * 0.2);
            hole.reverse();
            let p = Polygon {
                shell: square(0.0, 0.0, size),
                holes: if case % 2 == 0 { vec![hole] } else { vec![] },
            };
            let n = 1 + (rng.next_u32() % 300) as usize;
            let disks: Vec<Disk> = (0..n)
                .map(|_| Disk {
                    center: [rng.range(-1.0, size + 1.0), rng.range(-1.0, size + 1.0)],
                    radius: rng.range(0.0, 0.3),
                })
                .collect();
            let params = PolylabelParams {
                precision_m: precision,
                ..Default::default()
            };
            let pole = polylabel_avoiding(&p, &disks, &params).unwrap();
            let clearance = |q: [f64; 2]| {
                disks
                    .iter()
                    .map(|d| (q[0] - d.center[0]).hypot(q[1] - d.center[1]) - d.radius)
                    .fold(p.signed_distance(q), f64::min)
            };
            assert!(
                clearance(pole.center) >= pole.distance - 1e-9,
                "case {case}: {pole:?} is not clear"
            );
            let steps = 120;
            let mut best = f64::NEG_INFINITY;
            for i in 0..=steps {
                for j in 0..=steps {
                    let q = [
                        size * i as f64 / steps as f64,
                        size * j as f64 / steps as f64,
                    ];
                    best = best.max(clearance(q));
                }
            }
            assert!(
                best <= pole.distance + precision + 1e-9,
                "case {case}: lattice finds {best}, polylabel {}",
                pole.distance
            );
        }
    }
}
