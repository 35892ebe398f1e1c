//! Seeded synthetic rooftop scenes for tests and benchmarks (this crate's and other crates').
//!
//! Entry point: [`Scene::generate`]. A scene is a flat (or sloped) rectangular roof at a height,
//! optionally with a courtyard opening and a second roof at another height beside it, random box
//! obstacles on the roof, ground around, and walls. Points are sampled like a top-down scan: rows
//! along y, each row left to right with jitter and z noise, then the wall points; every point has
//! its semantic class. The truth (roof outlines and obstacle boxes) comes with it.
//!
//! The generator is a local PCG so a seed gives bit-identical scenes on every run, platform and
//! dependency version.

use crate::{CloudKind, SemanticClass};

/// What to generate; `Default` is a 20 m × 20 m roof 10 m up with three obstacles, ~1500 points
/// (the paper's average frame).
#[derive(Debug, Clone, PartialEq)]
pub struct SceneParams {
    /// Approximate number of points (raster plus walls).
    pub point_count: usize,
    /// Main roof extent in x and y, metres; its corner is at the origin.
    pub roof_size_m: [f64; 2],
    /// Height of the main roof above the ground (z = 0), metres.
    pub roof_height_m: f64,
    /// Slope of the main roof, dz/dx (0 is flat). Its height is `roof_height_m` at x = 0.
    pub roof_slope: f64,
    /// Number of random box obstacles on the main roof.
    pub obstacles: usize,
    /// Range of obstacle footprint sides, metres.
    pub obstacle_side_m: [f64; 2],
    /// Range of obstacle heights above the roof, metres.
    pub obstacle_height_m: [f64; 2],
    /// Size of a rectangular opening (down to the ground) centred in the main roof, metres.
    pub courtyard_m: Option<[f64; 2]>,
    /// A second flat roof east of the main one.
    pub second_roof: Option<SecondRoof>,
    /// Width of the ground strip around the buildings, metres.
    pub ground_margin_m: f64,
    /// Sample walls (vertical faces) as well.
    pub walls: bool,
    /// Standard deviation of the z noise, metres.
    pub noise_m: f64,
}

impl Default for SceneParams {
    fn default() -> Self {
        Self {
            point_count: 1500,
            roof_size_m: [20.0, 20.0],
            roof_height_m: 10.0,
            roof_slope: 0.0,
            obstacles: 3,
            obstacle_side_m: [0.8, 3.0],
            obstacle_height_m: [0.5, 2.0],
            courtyard_m: None,
            second_roof: None,
            ground_margin_m: 4.0,
            walls: true,
            noise_m: 0.01,
        }
    }
}

impl SceneParams {
    /// A default roof sized so that `point_count` points keep a realistic density (about 3 points
    /// per square metre at 1.5 k points, denser beyond), with obstacles in proportion.
    pub fn with_points(point_count: usize) -> Self {
        let side = (20.0 * (point_count as f64 / 1500.0).powf(0.25)).max(20.0);
        Self {
            point_count,
            roof_size_m: [side, side],
            obstacles: (3.0 * (side / 20.0).powi(2)).round() as usize,
            ..Self::default()
        }
    }
}

/// A second flat roof beside the main one.
#[derive(Debug, Clone, PartialEq)]
pub struct SecondRoof {
    /// Extent in x and y, metres; its south-west corner is at (main width + gap, 0).
    pub size_m: [f64; 2],
    /// Height above the ground, metres.
    pub height_m: f64,
    /// Gap between the two buildings, metres (0: they share a wall).
    pub gap_m: f64,
}

/// A generated scene.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// x, y, z, metres: raster rows first, then walls.
    pub points: Vec<[f32; 3]>,
    /// One [`SemanticClass`] byte per point.
    pub classes: Vec<u8>,
    pub truth: SceneTruth,
    /// Mean distance between neighbouring raster points, metres.
    pub spacing_m: f64,
}

/// What the scene contains.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SceneTruth {
    /// The main roof first.
    pub roofs: Vec<RoofTruth>,
    pub obstacles: Vec<ObstacleTruth>,
}

/// One roof.
#[derive(Debug, Clone, PartialEq)]
pub struct RoofTruth {
    pub min: [f64; 2],
    pub max: [f64; 2],
    /// Height at `min[0]`, metres.
    pub height_m: f64,
    /// dz/dx.
    pub slope: f64,
    /// The opening, as (min, max).
    pub courtyard: Option<([f64; 2], [f64; 2])>,
}

impl RoofTruth {
    /// True when (x, y) is on this roof (inside the outline, outside the courtyard).
    pub fn contains(&self, x: f64, y: f64) -> bool {
        let inside =
            |lo: [f64; 2], hi: [f64; 2]| x >= lo[0] && x <= hi[0] && y >= lo[1] && y <= hi[1];
        inside(self.min, self.max) && !self.courtyard.is_some_and(|(lo, hi)| inside(lo, hi))
    }

    /// Roof height at x.
    pub fn height_at(&self, x: f64) -> f64 {
        self.height_m + self.slope * (x - self.min[0])
    }
}

/// One box obstacle standing on the main roof.
#[derive(Debug, Clone, PartialEq)]
pub struct ObstacleTruth {
    pub min: [f64; 3],
    pub max: [f64; 3],
    pub class: SemanticClass,
}

impl ObstacleTruth {
    /// True when (x, y) is inside the footprint (closed).
    pub fn contains(&self, x: f64, y: f64) -> bool {
        x >= self.min[0] && x <= self.max[0] && y >= self.min[1] && y <= self.max[1]
    }

    /// Distance from (x, y) to the footprint (0 inside).
    pub fn distance(&self, x: f64, y: f64) -> f64 {
        let dx = (self.min[0] - x).max(x - self.max[0]).max(0.0);
        let dy = (self.min[1] - y).max(y - self.max[1]).max(0.0);
        dx.hypot(dy)
    }
}

const OBSTACLE_CLASSES: [SemanticClass; 6] = [
    SemanticClass::AcUnit,
    SemanticClass::AirVents,
    SemanticClass::SmallRooftopEntrance,
    SemanticClass::Skylight,
    SemanticClass::Chimney,
    SemanticClass::WaterTower,
];

impl Scene {
    /// Generates the scene for `params` and `seed`; the same pair always gives the same scene.
    pub fn generate(params: &SceneParams, seed: u64) -> Scene {
        let mut rng = Pcg32::new(seed);
        let roofs = roofs(params);
        let obstacles = place_obstacles(params, &roofs[0], &mut rng);
        let raster = Raster::new(params, &roofs);
        let mut points = Vec::with_capacity(params.point_count + 16);
        let mut classes = Vec::with_capacity(params.point_count + 16);
        for r in 0..raster.rows {
            for c in 0..raster.cols {
                let x = raster.lo[0] + (c as f64 + 0.5 + rng.range(-0.35, 0.35)) * raster.dx;
                let y = raster.lo[1] + (r as f64 + 0.5 + rng.range(-0.35, 0.35)) * raster.dy;
                let (z, class) = surface(&roofs, &obstacles, x, y);
                let z = z + params.noise_m * rng.normal();
                points.push([x as f32, y as f32, z as f32]);
                classes.push(class as u8);
            }
        }
        if params.walls {
            let step = 3.0 * raster.spacing;
            for roof in &roofs {
                for p in wall_points(roof, step, &mut rng) {
                    points.push(p);
                    classes.push(SemanticClass::BuildingWall as u8);
                }
            }
        }
        Scene {
            points,
            classes,
            truth: SceneTruth { roofs, obstacles },
            spacing_m: raster.dx.max(raster.dy),
        }
    }

    /// Indices of the points that stand on an obstacle (not roof, ground or wall).
    pub fn obstacle_points(&self) -> impl Iterator<Item = usize> + '_ {
        self.classes.iter().enumerate().filter_map(|(i, &c)| {
            let c = SemanticClass::from_u8(c)?;
            (!matches!(
                c,
                SemanticClass::BuildingRooftop
                    | SemanticClass::Ground
                    | SemanticClass::BuildingWall
            ))
            .then_some(i)
        })
    }
}

/// Height and class of the top surface at (x, y).
fn surface(
    roofs: &[RoofTruth],
    obstacles: &[ObstacleTruth],
    x: f64,
    y: f64,
) -> (f64, SemanticClass) {
    let mut best: Option<(f64, SemanticClass)> = None;
    for o in obstacles {
        if o.contains(x, y) && best.is_none_or(|b| o.max[2] > b.0) {
            best = Some((o.max[2], o.class));
        }
    }
    if let Some(b) = best {
        return b;
    }
    for r in roofs {
        if r.contains(x, y) {
            return (r.height_at(x), SemanticClass::BuildingRooftop);
        }
    }
    (0.0, SemanticClass::Ground)
}

/// The main roof (with its courtyard) and the second roof, if any.
fn roofs(params: &SceneParams) -> Vec<RoofTruth> {
    let [w, h] = params.roof_size_m;
    let mut roofs = vec![RoofTruth {
        min: [0.0, 0.0],
        max: [w, h],
        height_m: params.roof_height_m,
        slope: params.roof_slope,
        courtyard: params.courtyard_m.map(|[cw, ch]| {
            (
                [(w - cw) / 2.0, (h - ch) / 2.0],
                [(w + cw) / 2.0, (h + ch) / 2.0],
            )
        }),
    }];
    if let Some(s) = &params.second_roof {
        let x0 = w + s.gap_m;
        roofs.push(RoofTruth {
            min: [x0, 0.0],
            max: [x0 + s.size_m[0], s.size_m[1]],
            height_m: s.height_m,
            slope: 0.0,
            courtyard: None,
        });
    }
    roofs
}

/// Up to `params.obstacles` boxes standing on the `main` roof, each at least 0.5 m inside its
/// edge and off its courtyard (a bounded number of tries).
fn place_obstacles(params: &SceneParams, main: &RoofTruth, rng: &mut Pcg32) -> Vec<ObstacleTruth> {
    let [w, h] = params.roof_size_m;
    let mut obstacles = Vec::new();
    let mut tries = 0;
    while obstacles.len() < params.obstacles && tries < 100 * (params.obstacles + 1) {
        tries += 1;
        let sx = rng.range(params.obstacle_side_m[0], params.obstacle_side_m[1]);
        let sy = rng.range(params.obstacle_side_m[0], params.obstacle_side_m[1]);
        if sx + 1.0 >= w || sy + 1.0 >= h {
            continue;
        }
        let x0 = rng.range(0.5, w - 0.5 - sx);
        let y0 = rng.range(0.5, h - 0.5 - sy);
        let corners = [[x0, y0], [x0 + sx, y0], [x0, y0 + sy], [x0 + sx, y0 + sy]];
        if !corners.iter().all(|c| main.contains(c[0], c[1])) {
            continue;
        }
        let base = main.height_at(x0);
        let top = base + rng.range(params.obstacle_height_m[0], params.obstacle_height_m[1]);
        let class = OBSTACLE_CLASSES[obstacles.len() % OBSTACLE_CLASSES.len()];
        obstacles.push(ObstacleTruth {
            min: [x0, y0, base],
            max: [x0 + sx, y0 + sy, top],
            class,
        });
    }
    obstacles
}

/// The jittered raster the surfaces are sampled on: everything with the ground margin, at the
/// spacing that gives about `params.point_count` points with the walls.
struct Raster {
    lo: [f64; 2],
    cols: usize,
    rows: usize,
    dx: f64,
    dy: f64,
    spacing: f64,
}

impl Raster {
    fn new(params: &SceneParams, roofs: &[RoofTruth]) -> Self {
        let [w, h] = params.roof_size_m;
        let m = params.ground_margin_m;
        let (mut lo, mut hi) = ([-m, -m], [w + m, h + m]);
        for r in roofs {
            hi = [hi[0].max(r.max[0] + m), hi[1].max(r.max[1] + m)];
            lo = [lo[0].min(r.min[0] - m), lo[1].min(r.min[1] - m)];
        }
        let area = (hi[0] - lo[0]) * (hi[1] - lo[1]);
        let wall_area: f64 = if params.walls {
            roofs.iter().map(wall_area).sum()
        } else {
            0.0
        };
        // Walls are sampled three times sparser than the raster (a scan sees them at a glancing
        // angle).
        let n = params.point_count.max(4) as f64;
        let spacing = ((area + wall_area / 9.0) / n).sqrt();
        let cols = ((hi[0] - lo[0]) / spacing).round().max(2.0) as usize;
        let rows = ((hi[1] - lo[1]) / spacing).round().max(2.0) as usize;
        let (dx, dy) = ((hi[0] - lo[0]) / cols as f64, (hi[1] - lo[1]) / rows as f64);
        Self {
            lo,
            cols,
            rows,
            dx,
            dy,
            spacing,
        }
    }
}

/// The area of a roof's walls: its outline and its courtyard's, up to its height.
fn wall_area(r: &RoofTruth) -> f64 {
    let mut p = 2.0 * (r.max[0] - r.min[0] + r.max[1] - r.min[1]);
    if let Some((a, b)) = r.courtyard {
        p += 2.0 * (b[0] - a[0] + b[1] - a[1]);
    }
    p * r.height_m.max(0.0)
}

/// Points on the walls of `roof` (outside and around its courtyard), about `step` apart, just
/// off the wall outward.
fn wall_points(roof: &RoofTruth, step: f64, rng: &mut Pcg32) -> Vec<[f32; 3]> {
    let mut points = Vec::new();
    let mut outlines = vec![(roof.min, roof.max, 1.0)];
    if let Some((a, b)) = roof.courtyard {
        outlines.push((a, b, -1.0));
    }
    for (a, b, outward) in outlines {
        let corners = [[a[0], a[1]], [b[0], a[1]], [b[0], b[1]], [a[0], b[1]]];
        for k in 0..4 {
            let (p, q) = (corners[k], corners[(k + 1) % 4]);
            let len = ((q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2)).sqrt();
            // Outward normal of a counter-clockwise edge is (dy, -dx).
            let nrm = [
                (q[1] - p[1]) / len * outward,
                -(q[0] - p[0]) / len * outward,
            ];
            let along = (len / step).floor() as usize;
            for i in 0..along {
                let t = (i as f64 + rng.range(0.1, 0.9)) / along as f64;
                let off = rng.range(0.01, 0.05);
                let x = p[0] + t * (q[0] - p[0]) + off * nrm[0];
                let y = p[1] + t * (q[1] - p[1]) + off * nrm[1];
                let top = roof.height_at(x.clamp(roof.min[0], roof.max[0]));
                let levels = (top / step).floor() as usize;
                for j in 0..levels {
                    let z = (j as f64 + rng.range(0.1, 0.9)) * step;
                    let jitter = rng.range(-0.3, 0.3) * step;
                    let x = x + jitter * (q[0] - p[0]) / len;
                    let y = y + jitter * (q[1] - p[1]) / len;
                    points.push([x as f32, y as f32, z as f32]);
                }
            }
        }
    }
    points
}

/// PCG-XSH-RR 32: small, fast, and fixed forever (unlike a library's default generator).
#[derive(Debug, Clone)]
pub struct Pcg32 {
    state: u64,
}

impl Pcg32 {
    const MUL: u64 = 6364136223846793005;
    const INC: u64 = 1442695040888963407;

    /// A generator for `seed`.
    pub fn new(seed: u64) -> Self {
        let mut g = Self { state: 0 };
        g.next_u32();
        g.state = g.state.wrapping_add(seed);
        g.next_u32();
        g
    }

    /// The next 32 random bits.
    pub fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old.wrapping_mul(Self::MUL).wrapping_add(Self::INC);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        xorshifted.rotate_right((old >> 59) as u32)
    }

    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        let hi = u64::from(self.next_u32()) << 21;
        let lo = u64::from(self.next_u32() >> 11);
        ((hi | lo) as f64) / (1u64 << 53) as f64
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }

    /// Approximately standard normal (Irwin-Hall with 4 terms, bounded at ±3.5).
    pub fn normal(&mut self) -> f64 {
        let s: f64 = (0..4).map(|_| self.unit()).sum();
        (s - 2.0) * 3.0f64.sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scenes_are_reproducible_and_sized() {
        let p = SceneParams::default();
        let a = Scene::generate(&p, 3);
        let b = Scene::generate(&p, 3);
        assert_eq!(a, b);
        assert_ne!(a.points, Scene::generate(&p, 4).points);
        let n = a.points.len() as f64;
        assert!((n - 1500.0).abs() < 300.0, "{n}");
        assert_eq!(a.truth.obstacles.len(), 3);
        assert!(a.obstacle_points().count() > 0);
    }

    #[test]
    fn with_points_scales() {
        for n in [1_500usize, 10_000, 100_000] {
            let s = Scene::generate(&SceneParams::with_points(n), 1);
            let k = s.points.len() as f64;
            assert!((k / n as f64 - 1.0).abs() < 0.2, "{n}: {k}");
        }
    }
}

/// What the `detect` fuzz target (`fuzz/fuzz_targets/detect.rs`) makes of its bytes, so that its
/// finds replay in this crate's tests: 8 bytes pick parameters within the ranges the API
/// accepts, then 13 bytes a point (f32 x, y, z; a class), at most `max_points` points; points
/// with a non-finite coordinate or one beyond 1e7 m are skipped, as the service refuses them.
/// `None` without the 8 parameter bytes. The classes are used when the 7th byte is odd, and the
/// first 8 points also stand for keep-out disks (radius from the class byte, up to 2 m) when its
/// second bit is set. The cloud is a [`CloudKind::FusedMap`] when the 8th byte is odd, of cells
/// from 0.025 to 2.5 m (its top six bits), a [`CloudKind::Scan`] otherwise.
pub fn fuzz_detect_input(data: &[u8], max_points: usize) -> Option<DetectInput> {
    let (head, body) = data.split_first_chunk::<8>()?;
    let unit = |b: u8| f64::from(b) / 255.0;
    let with_disks = head[6] & 2 == 2;
    let params = crate::Params {
        max_triangle_edge_m: 0.05 + unit(head[0]) * 20.0,
        min_normal_dot: unit(head[1]) * 0.999,
        max_triangle_height_m: unit(head[2]) * 2.0,
        polylabel_precision_m: 0.01 + unit(head[3]) * 2.0,
        min_region_triangles: usize::from(head[4] % 16),
        max_sites: usize::from(head[5] % 8) + 1,
        ..crate::Params::default()
    };
    let kind = if head[7] & 1 == 1 {
        CloudKind::FusedMap {
            cell_size_m: 0.025 + f64::from(head[7] >> 2) / 63.0 * 2.475,
        }
    } else {
        CloudKind::Scan
    };
    let mut points = Vec::new();
    let mut classes = Vec::new();
    let mut disks = Vec::new();
    for chunk in body.chunks_exact(13).take(max_points) {
        let v = |i: usize| f32::from_le_bytes([chunk[i], chunk[i + 1], chunk[i + 2], chunk[i + 3]]);
        let p = [v(0), v(4), v(8)];
        if p.iter().all(|c| c.is_finite() && c.abs() <= 1.0e7) {
            points.push(p);
            classes.push(chunk[12] % 15);
            if with_disks && disks.len() < 8 {
                disks.push(crate::Disk {
                    center: [f64::from(p[0]), f64::from(p[1])],
                    radius: unit(chunk[12]) * 2.0,
                });
            }
        }
    }
    Some(DetectInput {
        points,
        disks,
        classes: (head[6] & 1 == 1).then_some(classes),
        kind,
        params,
    })
}

/// The arguments of one [`crate::detect`] call.
#[derive(Debug, Clone, PartialEq)]
pub struct DetectInput {
    pub points: Vec<[f32; 3]>,
    /// Keep-out disks for every plane ([`crate::Cloud::keep_clear`]), when not empty.
    pub disks: Vec<crate::Disk>,
    pub classes: Option<Vec<u8>>,
    pub kind: CloudKind,
    pub params: crate::Params,
}
