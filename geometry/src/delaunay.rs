//! Our own Delaunay triangulator: a sweep-hull on flat half-edge arrays with exact predicates.
//!
//! Entry point: [`triangulate`]. The scheme is the one popularised by delaunator (Sinclair's
//! s-hull): start from a small seed triangle, add the points in order of distance from its
//! circumcentre so each lies outside the current convex hull, connect it to the hull edges it sees,
//! and restore the Delaunay property with Lawson flips. What differs from delaunator:
//!
//! - every orientation and in-circle test is `robust::orient2d`/`incircle` (exact, adaptive), so
//!   collinear and cocircular input (grids!) never makes a degenerate or flipped triangle;
//! - a point that turns out not to be strictly outside the hull (rounding in the distance order, or
//!   a duplicate) is not dropped: it is kept aside and inserted at the end by walking to its
//!   triangle and splitting it (or the edge it lies on), again followed by flips;
//! - exact duplicate positions are found and triangulated once (normally the first index; a copy
//!   of a seed point yields to the seed);
//! - every loop is bounded and reports [`GeometryError::IterationLimit`] instead of spinning.
//!
//! The output layout is [`Triangulation`]'s: counter-clockwise triangles, half-edge twins.

use crate::GeometryError;
use crate::mesh::{EMPTY, Triangulation, next_halfedge, prev_halfedge};

/// Triangulates the x/y of `points` (finite coordinates). Fewer than three distinct points, or all
/// points on one line, give an empty triangulation.
pub fn triangulate(points: &[[f64; 3]]) -> Result<Triangulation, GeometryError> {
    triangulate_deferring(points, |_| false)
}

/// [`triangulate`], with the points for which `defer` is true inserted last by point location
/// (the path rounding and duplicates take); tests use it to exercise that path on any input.
fn triangulate_deferring(
    points: &[[f64; 3]],
    defer: impl Fn(usize) -> bool,
) -> Result<Triangulation, GeometryError> {
    let n = points.len();
    if n < 3 {
        return Ok(Triangulation::default());
    }
    if n >= EMPTY as usize {
        return Err(GeometryError::InvalidParameter {
            field: "points",
            value: n.to_string(),
            reason: "at most 2^32 - 2 points",
        });
    }
    let Some((seed, center)) = seed_triangle(points) else {
        return Ok(Triangulation::default()); // all points coincide or lie on one line
    };
    let sweep = Sweep::new(points, center, seed);
    let [r0, r1, r2] = sweep.seed_ranks;
    let coords = &sweep.coords;
    let mut b = Builder::new(coords, center);
    b.seed(r0, r1, r2);
    let seeds = [
        coords[r0 as usize],
        coords[r1 as usize],
        coords[r2 as usize],
    ];
    let order = &sweep.order;
    let mut deferred = Vec::new();
    let mut k = 0;
    while k < n {
        // Points at exactly the same distance form a (usually one-long) run; exact duplicates
        // within a run are skipped here, the smallest index kept.
        let mut end = k + 1;
        while end < n && order[end].0 == order[k].0 {
            end += 1;
        }
        for r in k..end {
            let r32 = r as u32;
            if r32 == r0 || r32 == r1 || r32 == r2 {
                continue;
            }
            let p = coords[r];
            let i = order[r].1;
            let dup = seeds.contains(&p)
                || (end - k > 1 && (k..end).any(|m| order[m].1 < i && coords[m] == p));
            if dup {
                continue;
            }
            if defer(i as usize) || !b.add_outside(r32)? {
                deferred.push(r32);
            }
        }
        k = end;
    }
    for r in deferred {
        b.add_inside(r)?;
    }
    Ok(b.finish(&sweep.order))
}

/// The seed triangle, counter-clockwise, and its circumcentre: the point nearest the
/// bounding-box centre, its nearest neighbour, and the point that makes the smallest circumcircle
/// with them (then no point lies inside that circle). `None` when all points coincide or lie on
/// one line.
fn seed_triangle(points: &[[f64; 3]]) -> Option<([usize; 3], [f64; 2])> {
    let xy = |p: &[f64; 3]| [p[0], p[1]];
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in points {
        lo = [lo[0].min(p[0]), lo[1].min(p[1])];
        hi = [hi[0].max(p[0]), hi[1].max(p[1])];
    }
    let mid = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
    let nearest = |to: [f64; 2], skip: usize| {
        let mut best = (f64::INFINITY, EMPTY as usize);
        for (i, p) in points.iter().enumerate() {
            let d = dist2(xy(p), to);
            if i != skip && d > 0.0 && d < best.0 {
                best = (d, i);
            }
        }
        best.1
    };
    let i0 = {
        let mut best = (f64::INFINITY, 0);
        for (i, p) in points.iter().enumerate() {
            let d = dist2(xy(p), mid);
            if d < best.0 {
                best = (d, i);
            }
        }
        best.1
    };
    let p0 = xy(&points[i0]);
    let i1 = nearest(p0, i0);
    if i1 == EMPTY as usize {
        return None;
    }
    let p1 = xy(&points[i1]);
    let mut i2 = EMPTY as usize;
    let mut best_r = f64::INFINITY;
    for (i, p) in points.iter().enumerate() {
        if i == i0 || i == i1 {
            continue;
        }
        // The exact collinearity test only for a point that would be taken: it is the costly one.
        let r = circumradius2(p0, p1, xy(p));
        if (r < best_r || i2 == EMPTY as usize) && orient(p0, p1, xy(p)) != 0.0 {
            best_r = r;
            i2 = i;
        }
    }
    if i2 == EMPTY as usize {
        return None;
    }
    let p2 = xy(&points[i2]);
    let (i1, i2) = if orient(p0, p1, p2) < 0.0 {
        (i2, i1)
    } else {
        (i1, i2)
    };
    let center = circumcenter(p0, xy(&points[i1]), xy(&points[i2]));
    let center = if center[0].is_finite() && center[1].is_finite() {
        center
    } else {
        mid
    };
    Some(([i0, i1, i2], center))
}

/// The sweep order: distance from the seed circumcentre, ties by index (deterministic). The sweep
/// works on ranks in this order, over a copy of the coordinates in this order: points that meet in
/// the sweep sit together in memory.
struct Sweep {
    /// (squared distance's bits, input index), sorted.
    order: Vec<(u64, u32)>,
    /// The x/y of `order`'s points, in that order.
    coords: Vec<[f64; 2]>,
    /// The ranks of the seed triangle's points.
    seed_ranks: [u32; 3],
}

impl Sweep {
    fn new(points: &[[f64; 3]], center: [f64; 2], seed: [usize; 3]) -> Self {
        let mut order: Vec<(u64, u32)> = points
            .iter()
            .enumerate()
            .map(|(i, p)| (dist2([p[0], p[1]], center).to_bits(), i as u32))
            .collect();
        order.sort_unstable();
        let mut seed_ranks = [0u32; 3];
        let coords = order
            .iter()
            .enumerate()
            .map(|(r, &(_, i))| {
                for (s, rank) in seed.iter().zip(&mut seed_ranks) {
                    if *s == i as usize {
                        *rank = r as u32;
                    }
                }
                let p = points[i as usize];
                [p[0], p[1]]
            })
            .collect();
        Self {
            order,
            coords,
            seed_ranks,
        }
    }
}

#[inline]
fn dist2(a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (a[0] - b[0], a[1] - b[1]);
    dx * dx + dy * dy
}

#[inline]
fn orient(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    robust::orient2d(
        robust::Coord { x: a[0], y: a[1] },
        robust::Coord { x: b[0], y: b[1] },
        robust::Coord { x: c[0], y: c[1] },
    )
}

/// `robust::incircle`'s sign: positive when `d` is inside the circle through the counter-clockwise
/// `a`, `b`, `c`. A floating-point filter inlined here, because it runs once per flip candidate;
/// uncertain cases go to the exact adaptive version, so the sign is always exact.
///
/// The filter is Shewchuk's with a cheaper bound: his error bound is `(10 + 96u) u` (u = 2^-53)
/// times the permanent `Σ (|bdx·cdy| + |cdx·bdy|)·alift`, and since `|x·y| ≤ (x² + y²) / 2` the
/// permanent is at most `alift·blift + blift·clift + clift·alift` (products of terms already
/// computed); the rounding of both sides moves that by under 12u relatively, so `11u` times it
/// bounds the error too. It is looser only for nearly degenerate triangles, which then take the
/// exact path.
#[inline(always)]
fn incircle(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> f64 {
    const ERRBOUND: f64 = 11.0 * (f64::EPSILON / 2.0);
    let (adx, ady) = (a[0] - d[0], a[1] - d[1]);
    let (bdx, bdy) = (b[0] - d[0], b[1] - d[1]);
    let (cdx, cdy) = (c[0] - d[0], c[1] - d[1]);
    let alift = adx * adx + ady * ady;
    let blift = bdx * bdx + bdy * bdy;
    let clift = cdx * cdx + cdy * cdy;
    let det = alift * (bdx * cdy - cdx * bdy)
        + blift * (cdx * ady - adx * cdy)
        + clift * (adx * bdy - bdx * ady);
    let errbound = ERRBOUND * (alift * blift + blift * clift + clift * alift);
    if det > errbound || -det > errbound {
        return det;
    }
    let k = |p: [f64; 2]| robust::Coord { x: p[0], y: p[1] };
    robust::incircle(k(a), k(b), k(c), k(d))
}

#[inline]
fn circumradius2(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    let cc = circumcenter(a, b, c);
    let r = dist2(cc, a);
    if r.is_finite() { r } else { f64::INFINITY }
}

fn circumcenter(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> [f64; 2] {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let (ex, ey) = (c[0] - a[0], c[1] - a[1]);
    let bl = dx * dx + dy * dy;
    let cl = ex * ex + ey * ey;
    let d = 0.5 / (dx * ey - dy * ex);
    [
        a[0] + (ey * bl - dy * cl) * d,
        a[1] + (dx * cl - ex * bl) * d,
    ]
}

/// The growing triangulation and its convex hull.
struct Builder<'a> {
    /// Coordinates in sweep order; the builder's point numbers are ranks in this order.
    points: &'a [[f64; 2]],
    triangles: Vec<u32>,
    halfedges: Vec<u32>,
    /// Counter-clockwise hull as a linked list over point indices; `next[v] == v` marks a point
    /// that has left the hull.
    hull_next: Vec<u32>,
    hull_prev: Vec<u32>,
    /// Half-edge of the hull edge `v → hull_next[v]`.
    hull_tri: Vec<u32>,
    /// Hull points bucketed by pseudo-angle around `center`, to start the visibility search near
    /// the new point.
    hash: Vec<u32>,
    /// Each hull point's bucket in `hash`, kept from when it joined the hull.
    hull_key: Vec<u32>,
    center: [f64; 2],
    stack: Vec<u32>,
    /// Budget of flips left (Lawson flips terminate; this only guards against bugs).
    flips_left: usize,
    flip_budget: usize,
}

impl<'a> Builder<'a> {
    fn new(points: &'a [[f64; 2]], center: [f64; 2]) -> Self {
        let n = points.len();
        let hash_size = ((n as f64).sqrt().ceil() as usize).max(1);
        let flip_budget = 64 * n + 1024;
        Self {
            points,
            triangles: Vec::with_capacity(6 * n),
            halfedges: Vec::with_capacity(6 * n),
            hull_next: vec![EMPTY; n],
            hull_prev: vec![EMPTY; n],
            hull_tri: vec![EMPTY; n],
            hash: vec![EMPTY; hash_size],
            hull_key: vec![0; n],
            center,
            stack: Vec::with_capacity(64),
            flips_left: flip_budget,
            flip_budget,
        }
    }

    /// The triangulation in input indices (`order` maps ranks to them).
    fn finish(self, order: &[(u64, u32)]) -> Triangulation {
        let mut triangles = self.triangles;
        for v in &mut triangles {
            *v = order[*v as usize].1;
        }
        triangles.shrink_to_fit();
        let mut halfedges = self.halfedges;
        halfedges.shrink_to_fit();
        Triangulation {
            triangles,
            halfedges,
        }
    }

    #[inline]
    fn xy(&self, i: u32) -> [f64; 2] {
        self.points[i as usize]
    }

    fn hash_key(&self, p: [f64; 2]) -> usize {
        let (dx, dy) = (p[0] - self.center[0], p[1] - self.center[1]);
        let q = dx / (dx.abs() + dy.abs());
        let a = if dy > 0.0 { 3.0 - q } else { 1.0 + q } / 4.0;
        let size = self.hash.len();
        // `a` is in [0, 1] (NaN for the centre itself), so truncation is the floor (NaN gives 0)
        // and only a == 1 reaches `size`; no libm call, no integer division on the hot path.
        let k = (a * size as f64) as usize;
        if k < size { k } else { k % size }
    }

    /// Point `v`, which has just joined the hull, becomes the hint of its bucket `key`.
    #[inline]
    fn hash_point(&mut self, v: u32, key: usize) {
        self.hash[key] = v;
        self.hull_key[v as usize] = key as u32;
    }

    fn seed(&mut self, i0: u32, i1: u32, i2: u32) {
        for (v, next, prev) in [(i0, i1, i2), (i1, i2, i0), (i2, i0, i1)] {
            self.hull_next[v as usize] = next;
            self.hull_prev[v as usize] = prev;
            self.hash_point(v, self.hash_key(self.xy(v)));
        }
        let t = self.add_triangle(i0, i1, i2, EMPTY, EMPTY, EMPTY);
        self.hull_tri[i0 as usize] = t;
        self.hull_tri[i1 as usize] = t + 1;
        self.hull_tri[i2 as usize] = t + 2;
    }

    /// Adds triangle (a, b, c), linking its half-edges to `ha`, `hb`, `hc`; returns its first
    /// half-edge.
    #[inline(always)]
    fn add_triangle(&mut self, a: u32, b: u32, c: u32, ha: u32, hb: u32, hc: u32) -> u32 {
        let t = self.triangles.len() as u32;
        self.triangles.extend_from_slice(&[a, b, c]);
        self.halfedges.extend_from_slice(&[EMPTY; 3]);
        self.link(t, ha);
        self.link(t + 1, hb);
        self.link(t + 2, hc);
        t
    }

    #[inline]
    fn link(&mut self, a: u32, b: u32) {
        self.halfedges[a as usize] = b;
        if b != EMPTY {
            self.halfedges[b as usize] = a;
        }
    }

    /// Adds point `i` if it lies strictly outside the current hull; returns false (and changes
    /// nothing) if it does not.
    fn add_outside(&mut self, i: u32) -> Result<bool, GeometryError> {
        let p = self.xy(i);
        let key = self.hash_key(p);
        let Some((mut e, start)) = self.first_visible_edge(p, key)? else {
            return Ok(false);
        };
        let n0 = self.hull_next[e as usize];
        let t = self.add_triangle(e, i, n0, EMPTY, EMPTY, self.hull_tri[e as usize]);
        self.hull_tri[i as usize] = t + 1;
        self.hull_tri[e as usize] = t;
        self.legalize(t + 2)?;
        let n = self.wrap_forward(i, n0, p)?;
        // Hull edges before the first, which are only possible when the first edge tried was
        // visible.
        if e == start {
            e = self.wrap_backward(i, e, p)?;
        }
        self.hull_prev[i as usize] = e;
        self.hull_next[i as usize] = n;
        self.hull_next[e as usize] = i;
        self.hull_prev[n as usize] = i;
        self.hash_point(i, key);
        self.hash[self.hull_key[e as usize] as usize] = e;
        Ok(true)
    }

    /// The first hull edge `e → next(e)` that sees `p`, walking from a hull point near `p` in
    /// the angular hash, and the hull point the walk started at; `None` when no edge sees it (the
    /// point is inside or on the hull).
    fn first_visible_edge(
        &self,
        p: [f64; 2],
        key: usize,
    ) -> Result<Option<(u32, u32)>, GeometryError> {
        let mut start = self.hull_point_near(key);
        if start == EMPTY {
            return Err(GeometryError::InvalidMesh {
                reason: "sweep hull lost its points".into(),
            });
        }
        start = self.hull_prev[start as usize];
        let mut e = start;
        let mut guard = 0usize;
        loop {
            let q = self.hull_next[e as usize];
            if orient(self.xy(e), self.xy(q), p) < 0.0 {
                return Ok(Some((e, start)));
            }
            e = q;
            guard += 1;
            if e == start {
                return Ok(None);
            }
            if guard > self.points.len() {
                return Err(GeometryError::IterationLimit {
                    step: "hull walk",
                    limit: guard,
                });
            }
        }
    }

    /// The first point still on the hull in the angular hash from bucket `key` on, or [`EMPTY`].
    fn hull_point_near(&self, key: usize) -> u32 {
        let size = self.hash.len();
        let mut k = key;
        for _ in 0..size {
            let s = self.hash[k];
            if s != EMPTY && self.hull_next[s as usize] != s {
                return s;
            }
            k += 1;
            if k == size {
                k = 0;
            }
        }
        EMPTY
    }

    /// Adds the triangles of point `i` with the hull edges from `n` on that see it (`p`), and
    /// takes their points off the hull; returns the first hull point that does not see it.
    fn wrap_forward(&mut self, i: u32, mut n: u32, p: [f64; 2]) -> Result<u32, GeometryError> {
        loop {
            let q = self.hull_next[n as usize];
            if orient(self.xy(n), self.xy(q), p) >= 0.0 {
                return Ok(n);
            }
            let t = self.add_triangle(
                n,
                i,
                q,
                self.hull_tri[i as usize],
                EMPTY,
                self.hull_tri[n as usize],
            );
            self.hull_tri[i as usize] = t + 1;
            self.legalize(t + 2)?;
            self.hull_next[n as usize] = n;
            n = q;
        }
    }

    /// Adds the triangles of point `i` with the hull edges before `e` that see it (`p`), and
    /// takes their points off the hull; returns the last hull point before them.
    fn wrap_backward(&mut self, i: u32, mut e: u32, p: [f64; 2]) -> Result<u32, GeometryError> {
        loop {
            let q = self.hull_prev[e as usize];
            if orient(self.xy(q), self.xy(e), p) >= 0.0 {
                return Ok(e);
            }
            let t = self.add_triangle(
                q,
                i,
                e,
                EMPTY,
                self.hull_tri[e as usize],
                self.hull_tri[q as usize],
            );
            self.hull_tri[q as usize] = t;
            self.legalize(t + 2)?;
            self.hull_next[e as usize] = e;
            e = q;
        }
    }

    /// Adds point `i`, which lies inside or on the hull: walk to its triangle, split it (or the edge
    /// the point is on), flip. A point equal to an existing vertex is skipped.
    fn add_inside(&mut self, i: u32) -> Result<(), GeometryError> {
        let p = self.xy(i);
        // Start from the hull edge nearest in angle: late points lie near the hull.
        let s = self.hull_point_near(self.hash_key(p));
        let start = if s == EMPTY {
            0
        } else {
            self.hull_tri[s as usize]
        };
        let mut t = start as usize / 3;
        let limit = self.triangles.len() + 16;
        let mut steps = 0usize;
        'walk: loop {
            steps += 1;
            if steps > limit {
                return Err(GeometryError::IterationLimit {
                    step: "point location",
                    limit,
                });
            }
            for e in 3 * t..3 * t + 3 {
                let (a, b) = (self.triangles[e], self.triangles[next_halfedge(e)]);
                if orient(self.xy(a), self.xy(b), p) < 0.0 {
                    let o = self.halfedges[e];
                    if o == EMPTY {
                        // Outside the hull after all (only for points deferred on purpose).
                        return if self.add_outside(i)? {
                            Ok(())
                        } else {
                            Err(GeometryError::InvalidMesh {
                                reason: format!("point {i} is neither inside nor outside the hull"),
                            })
                        };
                    }
                    t = o as usize / 3;
                    continue 'walk;
                }
            }
            break;
        }
        let v = [
            self.triangles[3 * t],
            self.triangles[3 * t + 1],
            self.triangles[3 * t + 2],
        ];
        if v.iter().any(|&v| self.xy(v) == p) {
            return Ok(()); // duplicate
        }
        let on_edge = (0..3).find(|&k| orient(self.xy(v[k]), self.xy(v[(k + 1) % 3]), p) == 0.0);
        match on_edge {
            None => self.split_triangle(t, i),
            Some(k) => self.split_edge(3 * t + k, i),
        }
    }

    fn split_triangle(&mut self, t: usize, p: u32) -> Result<(), GeometryError> {
        let (e0, e1, e2) = (3 * t, 3 * t + 1, 3 * t + 2);
        let [v0, v1, v2] = [self.triangles[e0], self.triangles[e1], self.triangles[e2]];
        let (h1, h2) = (self.halfedges[e1], self.halfedges[e2]);
        // t becomes (v0, v1, p); two new triangles (v1, v2, p) and (v2, v0, p).
        self.triangles[e2] = p;
        self.halfedges[e1] = EMPTY;
        self.halfedges[e2] = EMPTY;
        let t1 = self.add_triangle(v1, v2, p, h1, EMPTY, e1 as u32);
        let t2 = self.add_triangle(v2, v0, p, h2, e2 as u32, t1 + 1);
        self.fix_hull(v1, t1);
        self.fix_hull(v2, t2);
        self.legalize(e0 as u32)?;
        self.legalize(t1)?;
        self.legalize(t2)
    }

    fn split_edge(&mut self, e: usize, p: u32) -> Result<(), GeometryError> {
        let (en, ep) = (next_halfedge(e), prev_halfedge(e));
        let [v0, v1, v2] = [self.triangles[e], self.triangles[en], self.triangles[ep]];
        let (h_en, h_ep) = (self.halfedges[en], self.halfedges[ep]);
        let b = self.halfedges[e];
        // Triangle of e becomes (v1, v2, p) in place; a new (v2, v0, p).
        self.triangles[e] = v1;
        self.triangles[en] = v2;
        self.triangles[ep] = p;
        self.halfedges[e] = EMPTY;
        self.halfedges[en] = EMPTY;
        self.halfedges[ep] = EMPTY;
        self.link(e as u32, h_en);
        self.fix_hull(v1, e as u32);
        let t1 = self.add_triangle(v2, v0, p, h_ep, EMPTY, en as u32);
        self.fix_hull(v2, t1);
        if b == EMPTY {
            // A hull edge: v0 → p and p → v1 are now on the hull.
            self.hull_tri[v0 as usize] = t1 + 1;
            self.hull_tri[p as usize] = ep as u32;
            self.hull_next[v0 as usize] = p;
            self.hull_prev[p as usize] = v0;
            self.hull_next[p as usize] = v1;
            self.hull_prev[v1 as usize] = p;
            self.hash_point(p, self.hash_key(self.xy(p)));
            self.legalize(e as u32)?;
            return self.legalize(t1);
        }
        let b = b as usize;
        let (bn, bp) = (next_halfedge(b), prev_halfedge(b));
        let v3 = self.triangles[bp];
        let (h_bn, h_bp) = (self.halfedges[bn], self.halfedges[bp]);
        // Triangle of b, (v1, v0, v3), becomes (v0, v3, p) in place; a new (v3, v1, p).
        self.triangles[b] = v0;
        self.triangles[bn] = v3;
        self.triangles[bp] = p;
        self.halfedges[b] = EMPTY;
        self.halfedges[bn] = EMPTY;
        self.halfedges[bp] = EMPTY;
        self.link(b as u32, h_bn);
        self.fix_hull(v0, b as u32);
        self.link(bp as u32, t1 + 1);
        let t2 = self.add_triangle(v3, v1, p, h_bp, ep as u32, bn as u32);
        self.fix_hull(v3, t2);
        self.legalize(e as u32)?;
        self.legalize(t1)?;
        self.legalize(b as u32)?;
        self.legalize(t2)
    }

    /// Half-edge `e` (from `v`) may have become the home of a hull edge.
    #[inline]
    fn fix_hull(&mut self, v: u32, e: u32) {
        if self.halfedges[e as usize] == EMPTY {
            self.hull_tri[v as usize] = e;
        }
    }

    /// Lawson flips from half-edge `a`, whose triangle's third point is the newly added one.
    fn legalize(&mut self, a: u32) -> Result<(), GeometryError> {
        let flipped = legalize(
            Mesh {
                points: self.points,
                triangles: &mut self.triangles,
                halfedges: &mut self.halfedges,
                hull_tri: &mut self.hull_tri,
            },
            &mut self.stack,
            a,
            self.flips_left,
        );
        match flipped {
            Some(flips) => {
                self.flips_left -= flips;
                Ok(())
            }
            None => Err(GeometryError::IterationLimit {
                step: "Delaunay flips",
                limit: self.flip_budget,
            }),
        }
    }
}

/// The arrays [`legalize`] changes, borrowed apart from the builder.
struct Mesh<'a> {
    points: &'a [[f64; 2]],
    triangles: &'a mut [u32],
    halfedges: &'a mut [u32],
    hull_tri: &'a mut [u32],
}

/// Lawson flips from half-edge `a`, whose triangle's third point is the newly added one; returns
/// the number of flips, or `None` past `budget`. After a flip the same half-edge is checked again
/// (it has a new neighbour) before the one the flip exposed on the other side, which waits on the
/// stack: delaunator's order.
///
/// A free function over separately borrowed slices rather than a method: the compiler may then
/// assume the arrays do not overlap and keep their addresses and lengths in registers across the
/// stores of a flip.
fn legalize(m: Mesh<'_>, stack: &mut Vec<u32>, a: u32, budget: usize) -> Option<usize> {
    let Mesh {
        points,
        triangles,
        halfedges,
        hull_tri,
    } = m;
    let xy = |v: u32| points[v as usize];
    stack.clear();
    let mut flips = 0;
    let mut a = a as usize;
    loop {
        let b = halfedges[a];
        let (al, ar) = (next_halfedge(a), prev_halfedge(a));
        let illegal = b != EMPTY && {
            let bl = prev_halfedge(b as usize);
            let [p0, pr, pl, p1] = [triangles[ar], triangles[a], triangles[al], triangles[bl]];
            incircle(xy(pr), xy(pl), xy(p0), xy(p1)) > 0.0
        };
        if !illegal {
            match stack.pop() {
                Some(next) => {
                    a = next as usize;
                    continue;
                }
                None => return Some(flips),
            }
        }
        if flips == budget {
            return None;
        }
        flips += 1;
        let b = b as usize;
        let (bl, br) = (prev_halfedge(b), next_halfedge(b));
        let (p0, p1) = (triangles[ar], triangles[bl]);
        triangles[a] = p1;
        triangles[b] = p0;
        let hbl = halfedges[bl];
        let har = halfedges[ar];
        halfedges[a] = hbl;
        if hbl == EMPTY {
            hull_tri[p1 as usize] = a as u32;
        } else {
            halfedges[hbl as usize] = a as u32;
        }
        halfedges[b] = har;
        if har == EMPTY {
            hull_tri[p0 as usize] = b as u32;
        } else {
            halfedges[har as usize] = b as u32;
        }
        halfedges[ar] = bl as u32;
        halfedges[bl] = ar as u32;
        stack.push(br as u32);
    }
}

/// spade's triangulation, to cross-check ours.
#[cfg(test)]
#[path = "../tests/support/spade.rs"]
mod spade_support;

#[cfg(test)]
mod tests {
    use super::spade_support::triangulate_spade;
    use super::*;
    use crate::synthetic::Pcg32;

    fn check_deferring(points: &[[f64; 3]], defer: impl Fn(usize) -> bool, what: &str) {
        let ours = triangulate_deferring(points, defer).unwrap_or_else(|e| panic!("{what}: {e}"));
        let xy: Vec<[f64; 2]> = points.iter().map(|p| [p[0], p[1]]).collect();
        ours.check_invariants(&xy, true)
            .unwrap_or_else(|e| panic!("{what}: {e}"));
        let spade = triangulate_spade(points);
        assert_eq!(ours.len(), spade.len(), "{what}");
    }

    #[test]
    fn deferred_points_are_inserted_by_location() {
        for seed in 0..20u64 {
            let mut g = Pcg32::new(seed);
            let random: Vec<[f64; 3]> = (0..800)
                .map(|_| [g.range(0.0, 10.0), g.range(0.0, 10.0), 0.0])
                .collect();
            check_deferring(&random, |i| i % 3 == seed as usize % 3, "random");
            // Lattice points: many land exactly on edges (split_edge), some on the hull.
            let lattice: Vec<[f64; 3]> = (0..600)
                .map(|_| [g.range(0.0, 8.0).round(), g.range(0.0, 8.0).round(), 0.0])
                .collect();
            check_deferring(&lattice, |i| i % 2 == 0, "lattice");
            // Everything deferred but the seed: the sweep and the location path meet all cases.
            check_deferring(&lattice, |_| true, "lattice, all deferred");
        }
    }

    /// `x` moved by `k` units in the last place.
    fn ulps(x: f64, k: i64) -> f64 {
        if x == 0.0 {
            return f64::from_bits(k.unsigned_abs()) * if k < 0 { -1.0 } else { 1.0 };
        }
        f64::from_bits((x.to_bits() as i64 + k * x.signum() as i64) as u64)
    }

    /// The plain floating-point in-circle determinant (delaunator's test, no filter).
    fn incircle_naive(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> f64 {
        let (adx, ady) = (a[0] - d[0], a[1] - d[1]);
        let (bdx, bdy) = (b[0] - d[0], b[1] - d[1]);
        let (cdx, cdy) = (c[0] - d[0], c[1] - d[1]);
        (adx * adx + ady * ady) * (bdx * cdy - cdx * bdy)
            + (bdx * bdx + bdy * bdy) * (cdx * ady - adx * cdy)
            + (cdx * cdx + cdy * cdy) * (adx * bdy - bdx * ady)
    }

    #[test]
    fn incircle_filter_gives_the_exact_sign() {
        // Points a few ulps off a triangle's circumcircle (the filter's hard case), at scales and
        // origins from millimetres to a UTM world frame, and plain random ones.
        let k = |p: [f64; 2]| robust::Coord { x: p[0], y: p[1] };
        let mut g = Pcg32::new(43);
        let mut naive_wrong = 0;
        for case in 0..200_000 {
            let scale = [1e-3, 1.0, 30.0, 1e3][case % 4];
            let origin = [[0.0, 0.0], [512_345.0, 4_123_456.0]][(case / 4) % 2];
            let mut pt = || {
                [
                    origin[0] + g.range(-scale, scale),
                    origin[1] + g.range(-scale, scale),
                ]
            };
            let (a, b, c) = (pt(), pt(), pt());
            let (a, b) = match orient(a, b, c) {
                0.0 => continue,
                o if o < 0.0 => (b, a),
                _ => (a, b),
            };
            let d = if case % 8 < 6 {
                let o = circumcenter(a, b, c);
                let r = dist2(o, a).sqrt();
                let t = g.range(0.0, std::f64::consts::TAU);
                let j = i64::from(g.next_u32() % 9) - 4;
                [ulps(o[0] + r * t.cos(), j), ulps(o[1] + r * t.sin(), -j)]
            } else {
                pt()
            };
            let ours = incircle(a, b, c, d);
            let exact = robust::incircle(k(a), k(b), k(c), k(d));
            assert_eq!(
                ours.partial_cmp(&0.0),
                exact.partial_cmp(&0.0),
                "incircle({a:?}, {b:?}, {c:?}, {d:?}): {ours} against exact {exact}"
            );
            if incircle_naive(a, b, c, d).partial_cmp(&0.0) != exact.partial_cmp(&0.0) {
                naive_wrong += 1;
            }
        }
        // Cases where plain floating point gets the sign wrong are the ones the filter must send
        // to the exact path: there must be many for this test to mean something.
        assert!(naive_wrong > 10_000, "only {naive_wrong} hard cases");
    }

    #[test]
    fn grid_with_all_points_deferred() {
        let mut pts = Vec::new();
        for y in 0..25 {
            for x in 0..25 {
                pts.push([f64::from(x), f64::from(y), 0.0]);
            }
        }
        check_deferring(&pts, |_| true, "grid");
        check_deferring(&pts, |i| i % 7 != 0, "grid, most deferred");
    }
}
