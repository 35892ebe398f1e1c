//! Ray-primitive intersection and a bounding-volume hierarchy over the primitives of a world.
//!
//! Shapes are the few a rooftop city needs: boxes turned about the vertical axis, vertical
//! cylinders and cones, and spheres. The ground is the plane `z = 0`, handled outside the tree.

use crate::math::V3;

/// Index used for "no primitive" (the ground, or a miss).
pub const NO_PRIM: u32 = u32::MAX;

/// Shortest accepted hit distance, metres; keeps shadow rays off their own surface.
const T_EPS: f32 = 1e-3;

/// One analytic shape.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Shape {
    /// A box with centre `c`, half extents `h` (in its own frame) turned by `yaw` about z;
    /// `cos`/`sin` are those of the yaw.
    Box { c: V3, h: V3, cos: f32, sin: f32 },
    /// A vertical cylinder with axis at (`cx`, `cy`) from `z0` to `z1`.
    Cylinder {
        cx: f32,
        cy: f32,
        r: f32,
        z0: f32,
        z1: f32,
    },
    /// A vertical cone: radius `r` at `z0`, apex at `z1`.
    Cone {
        cx: f32,
        cy: f32,
        r: f32,
        z0: f32,
        z1: f32,
    },
    /// A sphere.
    Sphere { c: V3, r: f32 },
}

/// Procedural surface patterns, evaluated from world coordinates at the hit point.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Texture {
    /// Low-frequency blotches.
    Plain,
    /// Fine speckle (roof gravel).
    Gravel,
    /// Sheets with seams (roofing membrane).
    Membrane,
    /// Square tiles with grout lines (roof pavers, plazas).
    Tiles,
    /// Brick courses.
    Brick,
    /// A facade with rows of windows.
    Windows,
    /// Ribbed sheet metal.
    Metal,
    /// Glass panes with mullions.
    Glass,
    /// Vertical planks.
    Wood,
    /// Leafy clumps.
    Foliage,
    /// Asphalt with lane markings (ground only).
    Asphalt,
    /// Grass.
    Grass,
}

/// Colour and pattern of a surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Material {
    /// Linear RGB albedo in `[0, 1]`.
    pub albedo: [f32; 3],
    pub texture: Texture,
    /// Salt for the pattern's noise, so that two surfaces of one material differ.
    pub salt: u32,
}

/// A shape with its classes, material and owners.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prim {
    pub shape: Shape,
    /// Class of surfaces facing up (normal z > 0.7).
    pub top_class: u8,
    /// Class of every other surface.
    pub side_class: u8,
    /// Look of surfaces facing up.
    pub material: Material,
    /// Look of every other surface.
    pub side_material: Material,
    /// Index of the building it stands on or belongs to, or [`NO_PRIM`].
    pub building: u32,
    /// Index of the rooftop asset it belongs to, or [`NO_PRIM`].
    pub asset: u32,
}

/// A rigid motion in the ground plane: a turn by `yaw` radians about the vertical through
/// `pivot`, then a shift (x, y), metres. Moves a rooftop asset's primitives as one body.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanarMotion {
    pub pivot: [f64; 2],
    pub yaw: f64,
    pub shift: [f64; 2],
}

impl PlanarMotion {
    /// Where the motion takes the point (x, y).
    pub fn apply(&self, x: f32, y: f32) -> (f32, f32) {
        let (s, c) = self.yaw.sin_cos();
        let (dx, dy) = (f64::from(x) - self.pivot[0], f64::from(y) - self.pivot[1]);
        (
            (self.pivot[0] + c * dx - s * dy + self.shift[0]) as f32,
            (self.pivot[1] + s * dx + c * dy + self.shift[1]) as f32,
        )
    }

    /// The shape moved: centres and axes turn and shift, sizes and heights stay.
    pub fn shape(&self, shape: Shape) -> Shape {
        match shape {
            Shape::Box { c, h, cos, sin } => {
                let (x, y) = self.apply(c.x, c.y);
                let yaw = f64::from(sin).atan2(f64::from(cos)) + self.yaw;
                Shape::Box {
                    c: V3::new(x, y, c.z),
                    h,
                    cos: yaw.cos() as f32,
                    sin: yaw.sin() as f32,
                }
            }
            Shape::Cylinder { cx, cy, r, z0, z1 } => {
                let (cx, cy) = self.apply(cx, cy);
                Shape::Cylinder { cx, cy, r, z0, z1 }
            }
            Shape::Cone { cx, cy, r, z0, z1 } => {
                let (cx, cy) = self.apply(cx, cy);
                Shape::Cone { cx, cy, r, z0, z1 }
            }
            Shape::Sphere { c, r } => {
                let (x, y) = self.apply(c.x, c.y);
                Shape::Sphere {
                    c: V3::new(x, y, c.z),
                    r,
                }
            }
        }
    }
}

impl Prim {
    /// The class of the surface with outward normal `n`.
    pub fn class_for_normal(&self, n: V3) -> u8 {
        if n.z > 0.7 {
            self.top_class
        } else {
            self.side_class
        }
    }

    /// Axis-aligned bounds, padded by 1 mm so that grazing hits at rims are not culled.
    pub fn bounds(&self) -> (V3, V3) {
        let pad = V3::new(1e-3, 1e-3, 1e-3);
        let (lo, hi) = self.tight_bounds();
        (lo - pad, hi + pad)
    }

    fn tight_bounds(&self) -> (V3, V3) {
        match self.shape {
            Shape::Box { c, h, cos, sin } => {
                let ex = cos.abs() * h.x + sin.abs() * h.y;
                let ey = sin.abs() * h.x + cos.abs() * h.y;
                let e = V3::new(ex, ey, h.z);
                (c - e, c + e)
            }
            Shape::Cylinder { cx, cy, r, z0, z1 } | Shape::Cone { cx, cy, r, z0, z1 } => {
                (V3::new(cx - r, cy - r, z0), V3::new(cx + r, cy + r, z1))
            }
            Shape::Sphere { c, r } => (c - V3::new(r, r, r), c + V3::new(r, r, r)),
        }
    }
}

/// A ray hit: distance, outward unit normal and the primitive ([`NO_PRIM`] for the ground).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    pub t: f32,
    pub normal: V3,
    pub prim: u32,
}

/// A ray with its precomputed reciprocal direction.
#[derive(Debug, Clone, Copy)]
pub struct Ray {
    pub o: V3,
    pub d: V3,
    inv: V3,
}

impl Ray {
    /// A ray from `o` along unit direction `d`.
    pub fn new(o: V3, d: V3) -> Self {
        let inv = V3::new(1.0 / d.x, 1.0 / d.y, 1.0 / d.z);
        Self { o, d, inv }
    }

    pub fn at(&self, t: f32) -> V3 {
        self.o + self.d * t
    }
}

/// Distance and normal of the nearest hit of `ray` with `shape` in `(T_EPS, t_max)`.
pub fn intersect_shape(shape: &Shape, ray: &Ray, t_max: f32) -> Option<(f32, V3)> {
    match *shape {
        Shape::Box { c, h, cos, sin } => intersect_box(c, h, cos, sin, ray, t_max),
        Shape::Cylinder { cx, cy, r, z0, z1 } => intersect_cylinder(cx, cy, r, z0, z1, ray, t_max),
        Shape::Cone { cx, cy, r, z0, z1 } => intersect_cone(cx, cy, r, z0, z1, ray, t_max),
        Shape::Sphere { c, r } => intersect_sphere(c, r, ray, t_max),
    }
}

/// Where a ray enters and leaves a box, from the slab test: the distance, the axis of the face
/// and the sign of that face's outward normal, all in the box frame.
struct SlabSpan {
    t0: f32,
    axis0: usize,
    sign0: f32,
    t1: f32,
    axis1: usize,
    sign1: f32,
}

/// The slab test of a ray (`o`, `d`) in the box frame against half extents `h`; `None` when it
/// misses.
#[inline]
fn slab_span(o: V3, d: V3, h: V3) -> Option<SlabSpan> {
    let mut span = SlabSpan {
        t0: f32::NEG_INFINITY,
        axis0: 0,
        sign0: 0.0,
        t1: f32::INFINITY,
        axis1: 0,
        sign1: 0.0,
    };
    for i in 0..3 {
        let (oi, di, hi) = (o.axis(i), d.axis(i), h.axis(i));
        if di.abs() < 1e-12 {
            if oi.abs() > hi {
                return None;
            }
            continue;
        }
        let inv = 1.0 / di;
        let mut ta = (-hi - oi) * inv;
        let mut tb = (hi - oi) * inv;
        let mut s = -1.0;
        if ta > tb {
            std::mem::swap(&mut ta, &mut tb);
            s = 1.0;
        }
        if ta > span.t0 {
            span.t0 = ta;
            span.axis0 = i;
            span.sign0 = s;
        }
        if tb < span.t1 {
            span.t1 = tb;
            span.axis1 = i;
            span.sign1 = -s;
        }
        if span.t0 > span.t1 {
            return None;
        }
    }
    Some(span)
}

/// [`intersect_shape`] for a box with centre `c`, half extents `h`, turned by the yaw whose
/// cosine and sine are `cos` and `sin`.
#[inline]
fn intersect_box(c: V3, h: V3, cos: f32, sin: f32, ray: &Ray, t_max: f32) -> Option<(f32, V3)> {
    let p = ray.o - c;
    // Into the box frame: rotate by -yaw.
    let o = V3::new(cos * p.x + sin * p.y, -sin * p.x + cos * p.y, p.z);
    let d = V3::new(
        cos * ray.d.x + sin * ray.d.y,
        -sin * ray.d.x + cos * ray.d.y,
        ray.d.z,
    );
    let span = slab_span(o, d, h)?;
    let (t, axis, sign) = if span.t0 > T_EPS {
        (span.t0, span.axis0, span.sign0)
    } else if span.t1 > T_EPS {
        // Inside the box: the exit face, normal facing the ray.
        (span.t1, span.axis1, -span.sign1)
    } else {
        return None;
    };
    if t >= t_max {
        return None;
    }
    let nl = match axis {
        0 => V3::new(sign, 0.0, 0.0),
        1 => V3::new(0.0, sign, 0.0),
        _ => V3::new(0.0, 0.0, sign),
    };
    let n = V3::new(cos * nl.x - sin * nl.y, sin * nl.x + cos * nl.y, nl.z);
    Some((t, n))
}

/// [`intersect_shape`] for a vertical cylinder of radius `r` with axis at (`cx`, `cy`) from
/// `z0` to `z1`: the side, then the caps.
#[inline]
fn intersect_cylinder(
    cx: f32,
    cy: f32,
    r: f32,
    z0: f32,
    z1: f32,
    ray: &Ray,
    t_max: f32,
) -> Option<(f32, V3)> {
    let mut best: Option<(f32, V3)> = None;
    let mut t_lim = t_max;
    let (px, py) = (ray.o.x - cx, ray.o.y - cy);
    let a = ray.d.x * ray.d.x + ray.d.y * ray.d.y;
    if a > 1e-12 {
        let b = px * ray.d.x + py * ray.d.y;
        let cc = px * px + py * py - r * r;
        let disc = b * b - a * cc;
        if disc >= 0.0 {
            let sq = disc.sqrt();
            for t in [(-b - sq) / a, (-b + sq) / a] {
                if t > T_EPS && t < t_lim {
                    let z = ray.o.z + t * ray.d.z;
                    if z >= z0 && z <= z1 {
                        let n = V3::new(px + t * ray.d.x, py + t * ray.d.y, 0.0) * (1.0 / r);
                        best = Some((t, n));
                        t_lim = t;
                        break;
                    }
                }
            }
        }
    }
    if ray.d.z.abs() > 1e-12 {
        for (zc, nz) in [(z1, 1.0f32), (z0, -1.0f32)] {
            let t = (zc - ray.o.z) / ray.d.z;
            if t > T_EPS && t < t_lim {
                let x = px + t * ray.d.x;
                let y = py + t * ray.d.y;
                if x * x + y * y <= r * r {
                    best = Some((t, V3::new(0.0, 0.0, nz)));
                    t_lim = t;
                }
            }
        }
    }
    best
}

/// [`intersect_shape`] for a vertical cone of base radius `r` at `z0` with its apex at `z1`,
/// axis at (`cx`, `cy`): the mantle, then the base.
#[inline]
fn intersect_cone(
    cx: f32,
    cy: f32,
    r: f32,
    z0: f32,
    z1: f32,
    ray: &Ray,
    t_max: f32,
) -> Option<(f32, V3)> {
    let mut best: Option<(f32, V3)> = None;
    let mut t_lim = t_max;
    let k = r / (z1 - z0);
    let k2 = k * k;
    let (px, py) = (ray.o.x - cx, ray.o.y - cy);
    let zr = z1 - ray.o.z;
    let dz = -ray.d.z;
    let a = ray.d.x * ray.d.x + ray.d.y * ray.d.y - k2 * dz * dz;
    let b = 2.0 * (px * ray.d.x + py * ray.d.y - k2 * zr * dz);
    let c = px * px + py * py - k2 * zr * zr;
    for t in quadratic_roots(a, b, c) {
        if t > T_EPS && t < t_lim {
            let z = ray.o.z + t * ray.d.z;
            if z >= z0 && z <= z1 {
                let x = px + t * ray.d.x;
                let y = py + t * ray.d.y;
                let n = V3::new(x, y, k2 * (z1 - z)).normalized();
                best = Some((t, n));
                t_lim = t;
                break;
            }
        }
    }
    if ray.d.z.abs() > 1e-12 {
        let t = (z0 - ray.o.z) / ray.d.z;
        if t > T_EPS && t < t_lim {
            let x = px + t * ray.d.x;
            let y = py + t * ray.d.y;
            if x * x + y * y <= r * r {
                best = Some((t, V3::new(0.0, 0.0, -1.0)));
            }
        }
    }
    best
}

/// The real roots of `a t² + b t + c = 0` in increasing order, padded with infinity (the one
/// root of the linear equation when `a` is about zero).
#[inline]
fn quadratic_roots(a: f32, b: f32, c: f32) -> [f32; 2] {
    let mut roots = [f32::INFINITY; 2];
    if a.abs() > 1e-9 {
        let disc = b * b - 4.0 * a * c;
        if disc >= 0.0 {
            let sq = disc.sqrt();
            let (r0, r1) = ((-b - sq) / (2.0 * a), (-b + sq) / (2.0 * a));
            roots = if r0 < r1 { [r0, r1] } else { [r1, r0] };
        }
    } else if b.abs() > 1e-12 {
        roots[0] = -c / b;
    }
    roots
}

/// [`intersect_shape`] for a sphere with centre `c` and radius `r`.
#[inline]
fn intersect_sphere(c: V3, r: f32, ray: &Ray, t_max: f32) -> Option<(f32, V3)> {
    let p = ray.o - c;
    let b = p.dot(ray.d);
    let cc = p.dot(p) - r * r;
    let disc = b * b - cc;
    if disc < 0.0 {
        return None;
    }
    let sq = disc.sqrt();
    for t in [-b - sq, -b + sq] {
        if t > T_EPS && t < t_max {
            return Some((t, (p + ray.d * t) * (1.0 / r)));
        }
    }
    None
}

#[derive(Debug, Clone, Copy)]
struct Node {
    min: V3,
    max: V3,
    /// Internal: index of the left child (the right one follows it). Leaf: first primitive.
    first: u32,
    /// 0 for an internal node, else the number of primitives of the leaf.
    count: u32,
}

/// A bounding-volume hierarchy over primitives, plus the ground plane `z = 0`.
#[derive(Debug, Clone)]
pub struct Bvh {
    nodes: Vec<Node>,
    /// Primitives in leaf order, so that a leaf's primitives are contiguous.
    prims: Vec<Prim>,
}

const LEAF_SIZE: usize = 2;

/// Surface area of a box.
fn area(lo: V3, hi: V3) -> f32 {
    let e = (hi - lo).max(V3::default());
    2.0 * (e.x * e.y + e.y * e.z + e.z * e.x)
}

const BINS: usize = 16;

/// Binned surface-area-heuristic split of `idx`: reorders it and returns the split position, or
/// `None` when a leaf is cheaper (only for small sets) . Falls back to a median split when all
/// centroids coincide.
fn sah_split(
    idx: &mut [u32],
    bounds: &[(V3, V3)],
    centroids: &[V3],
    clo: V3,
    chi: V3,
) -> Option<usize> {
    let n = idx.len();
    let mut best = (f32::INFINITY, 0usize, 0usize);
    for axis in 0..3 {
        let Some(bins) = Bins::along(axis, clo, chi) else {
            continue;
        };
        let (cost, k) = bins.cheapest_split(idx, bounds, centroids);
        if cost < best.0 {
            best = (cost, axis, k);
        }
    }
    if !best.0.is_finite() {
        // Identical centroids: split by count.
        return Some(n / 2);
    }
    let (node_lo, node_hi) = union_bounds(idx, bounds);
    let leaf_cost = area(node_lo, node_hi) * n as f32;
    if n <= 4 && best.0 / 1.0 + area(node_lo, node_hi) * 0.5 >= leaf_cost {
        return None;
    }
    let (_, axis, k) = best;
    let bins = Bins::along(axis, clo, chi).expect("the split axis has an extent");
    let mut left = 0usize;
    for j in 0..n {
        if bins.of(centroids[idx[j] as usize]) <= k {
            idx.swap(left, j);
            left += 1;
        }
    }
    Some(left)
}

/// The bounding box of the primitives `idx`.
fn union_bounds(idx: &[u32], bounds: &[(V3, V3)]) -> (V3, V3) {
    let mut lo = V3::new(f32::INFINITY, f32::INFINITY, f32::INFINITY);
    let mut hi = -lo;
    for &i in idx {
        lo = lo.min(bounds[i as usize].0);
        hi = hi.max(bounds[i as usize].1);
    }
    (lo, hi)
}

/// `BINS` equal bins of the centroid range along one axis.
struct Bins {
    axis: usize,
    start: f32,
    scale: f32,
}

impl Bins {
    /// The bins over `clo..chi` along `axis`, or `None` when the centroids do not spread on it.
    fn along(axis: usize, clo: V3, chi: V3) -> Option<Self> {
        let (a, b) = (clo.axis(axis), chi.axis(axis));
        if b - a <= 1e-6 {
            return None;
        }
        Some(Self {
            axis,
            start: a,
            scale: BINS as f32 / (b - a),
        })
    }

    /// The bin of a centroid.
    fn of(&self, centroid: V3) -> usize {
        (((centroid.axis(self.axis) - self.start) * self.scale) as usize).min(BINS - 1)
    }

    /// The cheapest split between bins `..=k` and `k + 1..`, as (cost, k), that leaves
    /// primitives on both sides; an infinite cost when every such split puts all of them on one
    /// side.
    fn cheapest_split(&self, idx: &[u32], bounds: &[(V3, V3)], centroids: &[V3]) -> (f32, usize) {
        let n = idx.len();
        let empty = (
            V3::new(f32::INFINITY, f32::INFINITY, f32::INFINITY),
            V3::new(f32::NEG_INFINITY, f32::NEG_INFINITY, f32::NEG_INFINITY),
        );
        let mut bins = [(empty, 0usize); BINS];
        for &i in idx {
            let k = self.of(centroids[i as usize]);
            let (lo, hi) = bounds[i as usize];
            bins[k].0 = (bins[k].0.0.min(lo), bins[k].0.1.max(hi));
            bins[k].1 += 1;
        }
        let mut right_cost = [0.0f32; BINS];
        let mut acc = empty;
        let mut cnt = 0usize;
        for k in (1..BINS).rev() {
            acc = (acc.0.min(bins[k].0.0), acc.1.max(bins[k].0.1));
            cnt += bins[k].1;
            right_cost[k] = if cnt > 0 {
                area(acc.0, acc.1) * cnt as f32
            } else {
                0.0
            };
        }
        let mut best = (f32::INFINITY, 0usize);
        let mut acc = empty;
        let mut cnt = 0usize;
        for k in 0..BINS - 1 {
            acc = (acc.0.min(bins[k].0.0), acc.1.max(bins[k].0.1));
            cnt += bins[k].1;
            if cnt == 0 || cnt == n {
                continue;
            }
            let cost = area(acc.0, acc.1) * cnt as f32 + right_cost[k + 1];
            if cost < best.0 {
                best = (cost, k);
            }
        }
        best
    }
}

impl Bvh {
    /// Builds the tree (binned surface-area heuristic).
    pub fn build(prims: Vec<Prim>) -> Self {
        let bounds: Vec<(V3, V3)> = prims.iter().map(Prim::bounds).collect();
        let centroids: Vec<V3> = bounds.iter().map(|(a, b)| (*a + *b) * 0.5).collect();
        let mut order: Vec<u32> = (0..prims.len() as u32).collect();
        let mut nodes = Vec::with_capacity(prims.len() * 2 + 1);
        nodes.push(Node {
            min: V3::default(),
            max: V3::default(),
            first: 0,
            count: 0,
        });
        if prims.is_empty() {
            nodes[0].min = V3::new(1.0, 1.0, 1.0);
            nodes[0].max = V3::new(-1.0, -1.0, -1.0);
            return Self { nodes, prims };
        }
        // Explicit stack of (node, start, end) keeps deep trees off the call stack.
        let mut stack = vec![(0usize, 0usize, order.len())];
        while let Some((ni, start, end)) = stack.pop() {
            let mut lo = V3::new(f32::INFINITY, f32::INFINITY, f32::INFINITY);
            let mut hi = -lo;
            let mut clo = lo;
            let mut chi = hi;
            for &i in &order[start..end] {
                let (a, b) = bounds[i as usize];
                lo = lo.min(a);
                hi = hi.max(b);
                clo = clo.min(centroids[i as usize]);
                chi = chi.max(centroids[i as usize]);
            }
            nodes[ni].min = lo;
            nodes[ni].max = hi;
            let n = end - start;
            if n <= LEAF_SIZE {
                nodes[ni].first = start as u32;
                nodes[ni].count = n as u32;
                continue;
            }
            let Some(mid) = sah_split(&mut order[start..end], &bounds, &centroids, clo, chi) else {
                nodes[ni].first = start as u32;
                nodes[ni].count = n as u32;
                continue;
            };
            let mid = start + mid;
            let left = nodes.len();
            nodes.push(Node {
                min: lo,
                max: hi,
                first: 0,
                count: 0,
            });
            nodes.push(Node {
                min: lo,
                max: hi,
                first: 0,
                count: 0,
            });
            nodes[ni].first = left as u32;
            nodes[ni].count = 0;
            stack.push((left + 1, mid, end));
            stack.push((left, start, mid));
        }
        let prims = order.iter().map(|&i| prims[i as usize]).collect();
        Self { nodes, prims }
    }

    /// The primitives, in the tree's order ([`Hit::prim`] indexes this).
    pub fn prims(&self) -> &[Prim] {
        &self.prims
    }

    fn slab(node: &Node, ray: &Ray, t_max: f32) -> Option<f32> {
        let tx0 = (node.min.x - ray.o.x) * ray.inv.x;
        let tx1 = (node.max.x - ray.o.x) * ray.inv.x;
        let ty0 = (node.min.y - ray.o.y) * ray.inv.y;
        let ty1 = (node.max.y - ray.o.y) * ray.inv.y;
        let tz0 = (node.min.z - ray.o.z) * ray.inv.z;
        let tz1 = (node.max.z - ray.o.z) * ray.inv.z;
        let tmin = tx0.min(tx1).max(ty0.min(ty1)).max(tz0.min(tz1)).max(0.0);
        let tmax = tx0.max(tx1).min(ty0.max(ty1)).min(tz0.max(tz1)).min(t_max);
        (tmin <= tmax).then_some(tmin)
    }

    /// The nearest hit of `ray` with a primitive or the ground before `t_max`.
    pub fn intersect(&self, ray: &Ray, t_max: f32) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        let mut t_best = t_max;
        if ray.d.z < -1e-9 {
            let t = -ray.o.z / ray.d.z;
            if t > T_EPS && t < t_best {
                t_best = t;
                best = Some(Hit {
                    t,
                    normal: V3::new(0.0, 0.0, 1.0),
                    prim: NO_PRIM,
                });
            }
        }
        let mut stack = [0u32; 64];
        let mut sp = 0usize;
        if Self::slab(&self.nodes[0], ray, t_best).is_some() {
            stack[0] = 0;
            sp = 1;
        }
        while sp > 0 {
            sp -= 1;
            let node = &self.nodes[stack[sp] as usize];
            if node.count > 0 {
                let first = node.first as usize;
                for (k, p) in self.prims[first..first + node.count as usize]
                    .iter()
                    .enumerate()
                {
                    if let Some((t, n)) = intersect_shape(&p.shape, ray, t_best) {
                        t_best = t;
                        best = Some(Hit {
                            t,
                            normal: n,
                            prim: (first + k) as u32,
                        });
                    }
                }
                continue;
            }
            let l = node.first as usize;
            let tl = Self::slab(&self.nodes[l], ray, t_best);
            let tr = Self::slab(&self.nodes[l + 1], ray, t_best);
            match (tl, tr) {
                (Some(a), Some(b)) => {
                    // Push the farther child first so the nearer one is visited next.
                    let (near, far) = if a <= b { (l, l + 1) } else { (l + 1, l) };
                    if sp + 2 <= stack.len() {
                        stack[sp] = far as u32;
                        stack[sp + 1] = near as u32;
                        sp += 2;
                    }
                }
                (Some(_), None) => {
                    stack[sp] = l as u32;
                    sp += 1;
                }
                (None, Some(_)) => {
                    stack[sp] = (l + 1) as u32;
                    sp += 1;
                }
                (None, None) => {}
            }
        }
        best
    }

    /// Whether anything (the ground excluded) blocks `ray` before `t_max`.
    pub fn occluded(&self, ray: &Ray, t_max: f32) -> bool {
        let mut stack = [0u32; 64];
        let mut sp = 0usize;
        if Self::slab(&self.nodes[0], ray, t_max).is_some() {
            sp = 1;
        }
        while sp > 0 {
            sp -= 1;
            let node = &self.nodes[stack[sp] as usize];
            if node.count > 0 {
                let first = node.first as usize;
                for p in &self.prims[first..first + node.count as usize] {
                    if intersect_shape(&p.shape, ray, t_max).is_some() {
                        return true;
                    }
                }
                continue;
            }
            let l = node.first as usize;
            for c in [l, l + 1] {
                if sp < stack.len() && Self::slab(&self.nodes[c], ray, t_max).is_some() {
                    stack[sp] = c as u32;
                    sp += 1;
                }
            }
        }
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn prim(shape: Shape) -> Prim {
        Prim {
            shape,
            top_class: 4,
            side_class: 3,
            material: Material {
                albedo: [0.5; 3],
                texture: Texture::Plain,
                salt: 0,
            },
            side_material: Material {
                albedo: [0.5; 3],
                texture: Texture::Plain,
                salt: 0,
            },
            building: 0,
            asset: NO_PRIM,
        }
    }

    #[test]
    fn box_turned_45_degrees_is_hit_at_its_corner() {
        let (s, c) = std::f32::consts::FRAC_PI_4.sin_cos();
        let shape = Shape::Box {
            c: V3::new(0.0, 0.0, 0.0),
            h: V3::new(1.0, 1.0, 1.0),
            cos: c,
            sin: s,
        };
        let ray = Ray::new(V3::new(-5.0, 0.0, 0.0), V3::new(1.0, 0.0, 0.0));
        let (t, n) = intersect_shape(&shape, &ray, 100.0).expect("hit");
        assert!((t - (5.0 - 2f32.sqrt())).abs() < 1e-4, "t = {t}");
        assert!(n.x < 0.0);
    }

    #[test]
    fn cylinder_cone_sphere_hits_from_above() {
        let down = V3::new(0.0, 0.0, -1.0);
        let ray = Ray::new(V3::new(0.2, 0.0, 10.0), down);
        let cyl = Shape::Cylinder {
            cx: 0.0,
            cy: 0.0,
            r: 1.0,
            z0: 0.0,
            z1: 2.0,
        };
        assert_eq!(intersect_shape(&cyl, &ray, 100.0).map(|h| h.0), Some(8.0));
        let cone = Shape::Cone {
            cx: 0.0,
            cy: 0.0,
            r: 1.0,
            z0: 0.0,
            z1: 2.0,
        };
        let (t, n) = intersect_shape(&cone, &ray, 100.0).expect("cone hit");
        // Radius 0.2 is reached at z = 2 - 0.2 * 2 = 1.6.
        assert!((t - 8.4).abs() < 1e-4, "t = {t}");
        assert!(n.z > 0.0 && n.x > 0.0);
        let sph = Shape::Sphere {
            c: V3::new(0.0, 0.0, 0.0),
            r: 1.0,
        };
        let (t, _) = intersect_shape(&sph, &ray, 100.0).expect("sphere hit");
        assert!((t - (10.0 - (1.0f32 - 0.04).sqrt())).abs() < 1e-4);
    }

    #[test]
    fn bvh_matches_brute_force() {
        let mut prims = Vec::new();
        for i in 0..40 {
            let x = (i % 7) as f32 * 3.0;
            let y = (i / 7) as f32 * 3.0;
            let shape = match i % 4 {
                0 => Shape::Box {
                    c: V3::new(x, y, 1.0),
                    h: V3::new(1.0, 0.5, 1.0),
                    cos: 0.8,
                    sin: 0.6,
                },
                1 => Shape::Cylinder {
                    cx: x,
                    cy: y,
                    r: 0.7,
                    z0: 0.0,
                    z1: 2.0 + i as f32 * 0.1,
                },
                2 => Shape::Cone {
                    cx: x,
                    cy: y,
                    r: 1.0,
                    z0: 0.5,
                    z1: 3.0,
                },
                _ => Shape::Sphere {
                    c: V3::new(x, y, 1.5),
                    r: 0.9,
                },
            };
            prims.push(prim(shape));
        }
        let bvh = Bvh::build(prims.clone());
        for k in 0..500 {
            let a = k as f32 * 0.37;
            let o = V3::new(
                8.0 + 20.0 * a.cos(),
                8.0 + 20.0 * a.sin(),
                6.0 + (k % 5) as f32,
            );
            let target = V3::new((k % 23) as f32, (k % 17) as f32, 0.5);
            let ray = Ray::new(o, (target - o).normalized());
            let mut best = f32::INFINITY;
            if ray.d.z < 0.0 {
                best = -ray.o.z / ray.d.z;
            }
            for p in &prims {
                if let Some((t, _)) = intersect_shape(&p.shape, &ray, best) {
                    best = t;
                }
            }
            let got = bvh
                .intersect(&ray, f32::INFINITY)
                .map_or(f32::INFINITY, |h| h.t);
            assert_eq!(got, best, "ray {k}");
        }
    }
}
