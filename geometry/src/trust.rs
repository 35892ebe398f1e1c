//! Where a dense region's own points answer for the ground, and keep-out disks are not needed.
//!
//! Keep-out disks ([`crate::ranking::KeepOut`]) stand for obstacles that the points missed: a
//! camera saw an obstacle along a ray, and no point of it made a hole in the region. Where an
//! obstacle stands that no point hit, the points leave a gap: an empty disk of radius ρ in the
//! region puts its centre in a Delaunay triangle whose vertices all lie at least ρ from it, so
//! that triangle has an edge of at least ρ√3. Where every edge of a region's triangles is short
//! (a fused map's cells, a cell or two apart), the points themselves show the ground, and an
//! obstacle the LiDAR hit is a hole of its own points. A disk that meets none of the regions'
//! long-edged triangles covers only that shown ground, and bounds no safe circle
//! ([`crate::CloudKind::keep_out_trust_edge_m`], two cells for a fused map).

use crate::bins::Bins;
use crate::polylabel::{Disk, segment_distance2};
use crate::ranking::KeepOut;
use crate::regions::Regions;
use crate::triangulation::Triangulation;

/// Most grid cells; a wider spread of points gets coarser cells.
const MAX_CELLS: f64 = 1.0e6;

/// The regions' triangles with an x/y edge longer than a limit, binned on a grid by their
/// bounding boxes.
#[derive(Debug)]
pub(crate) struct Gaps {
    origin: [f64; 2],
    /// Cells per metre.
    per_metre: f64,
    nx: usize,
    ny: usize,
    /// Each cell's triangles, indices into `triangles`.
    bins: Bins,
    triangles: Vec<[[f64; 2]; 3]>,
    /// Each triangle's box: min x, min y, max x, max y.
    boxes: Vec<[f64; 4]>,
    /// Each triangle's region (its index in the regions given to [`Gaps::new`]).
    region: Vec<u32>,
    /// Whether each of those regions still counts ([`Gaps::keep_regions`]).
    live: Vec<bool>,
}

impl Gaps {
    /// The long-edged triangles of every region of `tri` (cells of `limit`, or coarser).
    pub(crate) fn new(
        tri: &Triangulation,
        points: &[[f64; 3]],
        regions: &Regions,
        limit: f64,
    ) -> Self {
        let long = |c: &[[f64; 2]; 3]| {
            (0..3).any(|i| {
                let (a, b) = (c[i], c[(i + 1) % 3]);
                (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) > limit * limit
            })
        };
        let mut region = Vec::new();
        let mut triangles = Vec::new();
        for (r, found) in regions.regions.iter().enumerate() {
            for &t in &found.triangles {
                let v = &tri.triangles[3 * t as usize..3 * t as usize + 3];
                let corners = std::array::from_fn(|i| {
                    let p = points[v[i] as usize];
                    [p[0], p[1]]
                });
                if long(&corners) {
                    triangles.push(corners);
                    region.push(r as u32);
                }
            }
        }
        Self::binned(triangles, region, regions.regions.len(), limit)
    }

    /// Leaves out the triangles of the regions whose `keep` is false (one flag per region given
    /// to [`Gaps::new`]).
    pub(crate) fn keep_regions(&mut self, keep: &[bool]) {
        for (live, keep) in self.live.iter_mut().zip(keep) {
            *live &= keep;
        }
    }

    /// `triangles`, each of region `region[t]` of `regions`, binned on cells of `limit` (or
    /// coarser).
    fn binned(triangles: Vec<[[f64; 2]; 3]>, region: Vec<u32>, regions: usize, limit: f64) -> Self {
        let boxes: Vec<[f64; 4]> = (triangles.iter())
            .map(|c| {
                let [x, y] = [0, 1].map(|k| c.map(|p| p[k]));
                let min = |v: [f64; 3]| v[0].min(v[1]).min(v[2]);
                let max = |v: [f64; 3]| v[0].max(v[1]).max(v[2]);
                [min(x), min(y), max(x), max(y)]
            })
            .collect();
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        for b in &boxes {
            lo = [lo[0].min(b[0]), lo[1].min(b[1])];
            hi = [hi[0].max(b[2]), hi[1].max(b[3])];
        }
        let span = [hi[0] - lo[0], hi[1] - lo[1]];
        let cell = if (span[0] / limit + 1.0) * (span[1] / limit + 1.0) > MAX_CELLS {
            ((span[0] + limit) * (span[1] + limit) / MAX_CELLS).sqrt()
        } else {
            limit
        };
        // No triangle: an empty grid of one cell.
        let [nx, ny] = if triangles.is_empty() {
            [1, 1]
        } else {
            span.map(|s| (s / cell) as usize + 1)
        };
        let mut gaps = Self {
            origin: lo,
            per_metre: 1.0 / cell,
            nx,
            ny,
            bins: Bins::default(),
            triangles,
            boxes: Vec::new(),
            region,
            live: vec![true; regions],
        };
        let spans: Vec<[usize; 4]> = boxes.iter().map(|b| gaps.span(b)).collect();
        gaps.bins = Bins::new(&spans, nx, ny);
        gaps.boxes = boxes;
        gaps
    }

    /// The first and last column and the first and last row of the cells that the box (min x,
    /// min y, max x, max y) touches; parts of the box beyond the grid go to its border cells.
    /// Boxes and disks are placed by the same monotone rule, so overlapping ones share a cell.
    fn span(&self, b: &[f64; 4]) -> [usize; 4] {
        let at = |v: f64, k: usize| {
            // Negative and NaN go to 0 (the cast saturates, and truncates as the floor would
            // at or above 0: no libm call), beyond the grid to its last cell.
            let n = [self.nx, self.ny][k];
            (((v - self.origin[k]) * self.per_metre) as usize).min(n - 1)
        };
        [at(b[0], 0), at(b[2], 0), at(b[1], 1), at(b[3], 1)]
    }

    /// False only when no disk lying within the box (min x, min y, max x, max y) can meet a
    /// long-edged triangle ([`Gaps::touches`]): no triangle is binned in the cells the box
    /// covers, which hold every cell such a disk's own box covers. A box with a non-finite side
    /// may hold anything.
    pub(crate) fn may_touch(&self, b: &[f64; 4]) -> bool {
        if !b.iter().all(|v| v.is_finite()) {
            return true;
        }
        if self.triangles.is_empty() {
            return false;
        }
        let [x0, x1, y0, y1] = self.span(b);
        (y0..=y1).any(|row| !(self.bins.run(row * self.nx + x0, row * self.nx + x1)).is_empty())
    }

    /// Whether the disk meets one of the long-edged triangles of a region that still counts. A
    /// disk with a non-finite coordinate always counts.
    pub(crate) fn touches(&self, d: &Disk) -> bool {
        if !(d.center.iter().all(|c| c.is_finite()) && d.radius.is_finite()) {
            return true;
        }
        if self.triangles.is_empty() {
            return false;
        }
        let [x, y] = d.center;
        let reach = [x - d.radius, y - d.radius, x + d.radius, y + d.radius];
        let [x0, x1, y0, y1] = self.span(&reach);
        // Cells are stored row by row, so one row's run of cells is one run of `bins`, often
        // empty: most disks lie where no triangle is long.
        (y0..=y1).any(|row| {
            let run = self.bins.run(row * self.nx + x0, row * self.nx + x1);
            run.iter().any(|&t| {
                let b = &self.boxes[t as usize];
                // Most of a cell's triangles lie apart from the disk's box.
                b[0] <= reach[2]
                    && reach[0] <= b[2]
                    && b[1] <= reach[3]
                    && reach[1] <= b[3]
                    && self.live[self.region[t as usize] as usize]
                    && meets(&self.triangles[t as usize], d)
            })
        })
    }
}

/// Whether the closed disk and the closed triangle share a point.
fn meets(t: &[[f64; 2]; 3], d: &Disk) -> bool {
    let p = d.center;
    let cross =
        |a: [f64; 2], b: [f64; 2]| (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]);
    let s = [cross(t[0], t[1]), cross(t[1], t[2]), cross(t[2], t[0])];
    if s.iter().all(|&v| v >= 0.0) || s.iter().all(|&v| v <= 0.0) {
        return true;
    }
    let r2 = d.radius * d.radius;
    (0..3).any(|i| {
        let (a, b) = (t[i], t[(i + 1) % 3]);
        segment_distance2(p, a[0], a[1], b[0], b[1]) <= r2
    })
}

/// The disks of `inner` that meet a long-edged triangle of `gaps`.
pub(crate) struct OverGaps<'a> {
    pub inner: &'a dyn KeepOut,
    pub gaps: &'a Gaps,
}

impl KeepOut for OverGaps<'_> {
    fn disks_on_plane(&self, point: [f64; 3], normal: [f64; 3], bounds: [f64; 4]) -> Vec<Disk> {
        // Disks where no long-edged triangle is near are not even cast.
        let wanted = |b: &[f64; 4]| self.gaps.may_touch(b);
        let mut disks = (self.inner).wanted_disks_on_plane(point, normal, bounds, &wanted);
        disks.retain(|d| self.gaps.touches(d));
        disks
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_disk_meets_a_triangle_it_overlaps_or_holds_and_no_other() {
        let t = [[0.0, 0.0], [4.0, 0.0], [0.0, 3.0]];
        let disk = |x: f64, y: f64, r: f64| Disk {
            center: [x, y],
            radius: r,
        };
        // Inside, holding the triangle, over an edge, touching a corner.
        assert!(meets(&t, &disk(1.0, 1.0, 0.1)));
        assert!(meets(&t, &disk(1.0, 1.0, 10.0)));
        assert!(meets(&t, &disk(2.0, -0.5, 0.6)));
        assert!(meets(&t, &disk(-0.3, -0.4, 0.5)));
        // Near but apart: below the base, past the hypotenuse, off a corner.
        assert!(!meets(&t, &disk(2.0, -0.5, 0.4)));
        assert!(!meets(&t, &disk(3.0, 3.0, 1.0)));
        assert!(!meets(&t, &disk(-0.3, -0.4, 0.49)));
        // Either orientation.
        let cw = [t[0], t[2], t[1]];
        assert!(meets(&cw, &disk(1.0, 1.0, 0.1)));
        assert!(!meets(&cw, &disk(3.0, 3.0, 1.0)));
    }

    #[test]
    fn the_grid_finds_exactly_the_disks_that_meet_a_triangle() {
        // Seeded random triangles of every size, far from the origin, and disks of every size,
        // some beyond the grid: the binned search answers as a scan of every triangle does, and
        // a box the grid says no disk in it can touch holds none that does.
        let mut rng = crate::synthetic::Pcg32::new(43);
        let mut u = |lo: f64, hi: f64| lo + (hi - lo) * rng.unit();
        let origin = [5.0e5, -3.0e6];
        // Boxes refused and not.
        let mut refused = [0, 0];
        for round in 0..40 {
            let limit = u(0.1, 2.0);
            let triangles: Vec<[[f64; 2]; 3]> = (0..round * 3)
                .map(|_| {
                    let (cx, cy, size) = (u(0.0, 40.0), u(0.0, 40.0), u(0.05, 12.0));
                    std::array::from_fn(|_| {
                        [
                            origin[0] + cx + u(-size, size),
                            origin[1] + cy + u(-size, size),
                        ]
                    })
                })
                .collect();
            // Three regions, the last one left out.
            let region: Vec<u32> = (0..triangles.len() as u32).map(|t| t % 3).collect();
            let mut gaps = Gaps::binned(triangles.clone(), region.clone(), 3, limit);
            gaps.keep_regions(&[true, true, false]);
            let (mut met, mut missed) = (0, 0);
            for _ in 0..400 {
                let d = Disk {
                    center: [origin[0] + u(-10.0, 50.0), origin[1] + u(-10.0, 50.0)],
                    radius: u(0.0, 6.0),
                };
                let scan = (triangles.iter().zip(&region)).any(|(t, &r)| r != 2 && meets(t, &d));
                assert_eq!(gaps.touches(&d), scan, "round {round}, {d:?}");
                if scan { met += 1 } else { missed += 1 }
            }
            assert!(
                round < 4 || (met > 0 && missed > 0),
                "round {round}: {met} met, {missed} missed"
            );
            // A box it refuses holds no disk that touches: boxes of every size, each with disks
            // inside it (on its corners and edges too).
            for _ in 0..100 {
                let (x, y) = (origin[0] + u(-10.0, 50.0), origin[1] + u(-10.0, 50.0));
                let b = [x, y, x + u(0.0, 8.0), y + u(0.0, 8.0)];
                if gaps.may_touch(&b) {
                    refused[1] += 1;
                    continue;
                }
                refused[0] += 1;
                for _ in 0..20 {
                    let radius = u(0.0, 0.5 * (b[2] - b[0]).min(b[3] - b[1]));
                    let at = |lo: f64, hi: f64, k: f64| lo + radius + (hi - lo - 2.0 * radius) * k;
                    let [kx, ky] =
                        [0, 1].map(|_| [0.0, 1.0, u(0.0, 1.0)][(u(0.0, 3.0) as usize).min(2)]);
                    let d = Disk {
                        center: [at(b[0], b[2], kx), at(b[1], b[3], ky)],
                        radius,
                    };
                    assert!(!gaps.touches(&d), "round {round}, {b:?}, {d:?}");
                }
            }
        }
        assert!(refused[0] > 100 && refused[1] > 100, "{refused:?}");
    }
}
