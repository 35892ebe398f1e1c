//! Obstacles that the camera sees and the LiDAR may miss, as keep-out disks on a landing plane.
//!
//! A 16-beam scan leaves metre-wide gaps between its lines at 40 m; a 0.5 m air vent between two
//! lines has no point, so the triangulated roof spans it. The class mask is dense: every pixel
//! whose class may not be landed on is an obstacle seen from the camera, somewhere along its ray.
//!
//! Where along the ray is what the footprint on a candidate landing plane depends on. The ray
//! crosses the plane *behind* an obstacle that stands above it, by the obstacle's height times
//! the tangent of the ray's incidence: from 40 m away and 20 m up, a water tank 2.5 m above the
//! roof casts its pixels 5 m past the roof under it. So each pixel block is cast as a swept
//! footprint: disks from where its ray meets the plane back towards the camera, as far as the
//! ray's height above the plane reaches the height of the obstacle. That height comes from the
//! LiDAR: the highest point near the block in the image that the mask also calls an obstacle;
//! where no such point is near (a vent between scan lines), an assumed low obstacle
//! ([`DEFAULT_OBSTACLE_HEIGHT_M`]). A pixel that sees something below the plane (the street past
//! an edge, its LiDAR points below the plane too) lands in front of it with no sweep: it marks
//! where the camera does not see landable roof at the plane's height, which is what matters.

use nalgebra::{Point3, Vector3};

use crate::{CameraModel, ClassMask};

/// Incidence below which a footprint is capped (rays almost parallel to the plane).
const MIN_COS_INCIDENCE: f64 = 0.2;

/// Side of the pixel blocks cast as one ray.
pub const BLOCK: usize = 2;

/// Height above a plane assumed for an obstacle block with no obstacle LiDAR point near it in
/// the image, metres: the low rooftop assets (air vents, ducts) the scan lines miss.
pub const DEFAULT_OBSTACLE_HEIGHT_M: f64 = 1.2;

/// Heights of obstacles above a plane are capped here, metres (a water tower's top).
const MAX_OBSTACLE_HEIGHT_M: f64 = 12.0;

/// Side of the mask cells that gather obstacle points, pixels; a block looks at the 3 × 3 cells
/// around its own.
const CELL: usize = 8;

/// At most this many disks per block and plane.
const MAX_SWEEP_DISKS: usize = 64;

/// Side of the tiles that group the obstacle blocks, blocks. A plane's footprint test runs once per
/// tile from its corner rays before any of its blocks is cast (see [`Tile::may_reach`]).
const TILE: usize = 8;

/// A newer frame replaces an older one's view of a place only from at most this fraction of the
/// older one's range to it (see [`ObstacleRays::newest_view_on_plane`]). It was 0.8 until an air
/// vent the model saw from 50 m and called roof from 45 m on was forgotten at 39 m, where a
/// circle reached it (fresh set 6278; 0.6 changed no answer on six fresh fused sets, EVALUATION.md).
pub const NEARER_VIEW: f64 = 0.6;

/// The rays of a mask's obstacle pixels, in the world frame.
#[derive(Debug, Clone)]
pub struct ObstacleRays {
    /// The camera the rays leave, for [`ObstacleRays::sees`].
    camera: CameraModel,
    origin: Point3<f64>,
    /// Unit directions, world frame.
    rays: Vec<Vector3<f64>>,
    /// For each ray, the highest LiDAR point near its block that the mask calls an obstacle.
    tops: Vec<Option<Point3<f64>>>,
    /// Angle one block spans, radians (the larger of its two sides).
    pixel_angle: f64,
    /// The tiles that hold obstacle blocks; their rays are consecutive in `rays`.
    tiles: Vec<Tile>,
}

/// `TILE × TILE` blocks of the mask: the unit directions (world frame) of the four corners of
/// its pixel rectangle, which bound the rays of all its blocks, and where its rays are.
#[derive(Debug, Clone)]
struct Tile {
    corners: [Vector3<f64>; 4],
    rays: std::ops::Range<usize>,
}

impl ObstacleRays {
    /// The rays through the centres of the `BLOCK × BLOCK` pixel blocks of `mask` (stretched
    /// over the camera's image) that hold a pixel whose class `is_obstacle` says so. A block is
    /// one disk covering all of it: conservative, and a quarter of the rays to cast per plane.
    /// `points` (world frame) give the obstacles' heights: each point that projects onto an
    /// obstacle pixel counts for the blocks around it.
    ///
    /// `is_structure` names the obstacle classes of structures too large for a scan to miss
    /// (a building's wall, a parapet's face). A block whose obstacle pixels are all structure,
    /// with a point that the mask also calls structure among the points around it, casts
    /// nothing: the scan hit that structure, and its points, which are not landable, already
    /// end the landing region at it. Its sweep would only keep free roof clear: a pixel cannot
    /// tell a wall's foot from its top, so a far parapet's face is swept its height times the
    /// cotangent of the view's elevation onto the roof in front of it (1.2 m for a 1 m parapet
    /// seen at 40°). A structure pixel with no such point near it casts as any obstacle does.
    pub fn new(
        camera: &CameraModel,
        mask: &ClassMask,
        points: &[[f32; 3]],
        is_obstacle: impl Fn(u8) -> bool,
        is_structure: impl Fn(u8) -> bool,
    ) -> Self {
        let (w, h) = (mask.width() as usize, mask.height() as usize);
        let sx = f64::from(camera.width) / w as f64;
        let sy = f64::from(camera.height) / h as f64;

        // The highest obstacle point of every CELL × CELL cell of the mask.
        let (cells_x, cells_y) = (w.div_ceil(CELL), h.div_ceil(CELL));
        let mut highest: Vec<Option<Point3<f64>>> = vec![None; cells_x * cells_y];
        // Whether a point the mask calls structure fell in each cell.
        let mut structure = vec![false; cells_x * cells_y];
        for p in points {
            let p = Point3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
            let Some((u, v)) = camera.project(&p) else {
                continue;
            };
            let class = mask.class_at_image_point(u, v, camera.width, camera.height);
            if !is_obstacle(class) {
                continue;
            }
            // In the image (the lookup above said so): a cell of the mask.
            let (x, y) = ((u / sx) as usize, (v / sy) as usize);
            let k = (y / CELL).min(cells_y - 1) * cells_x + (x / CELL).min(cells_x - 1);
            if highest[k].is_none_or(|c| p.z > c.z) {
                highest[k] = Some(p);
            }
            structure[k] |= is_structure(class);
        }
        // The highest of the 3 × 3 cells around each cell, and whether any of them holds a
        // structure point: what every block of that cell sees.
        let near: Vec<(Option<Point3<f64>>, bool)> = (0..cells_x * cells_y)
            .map(|i| {
                let (cx, cy) = (i % cells_x, i / cells_x);
                let (mut top, mut seen): (Option<Point3<f64>>, bool) = (None, false);
                for ny in cy.saturating_sub(1)..(cy + 2).min(cells_y) {
                    for nx in cx.saturating_sub(1)..(cx + 2).min(cells_x) {
                        let k = ny * cells_x + nx;
                        seen |= structure[k];
                        if let Some(p) = highest[k]
                            && top.is_none_or(|t| p.z > t.z)
                        {
                            top = Some(p);
                        }
                    }
                }
                (top, seen)
            })
            .collect();

        let rotation = camera.pose.rotation;
        let direction = |u: f64, v: f64| {
            rotation
                * Vector3::new(
                    (u - camera.cx) / camera.fx,
                    (v - camera.cy) / camera.fy,
                    1.0,
                )
                .normalize()
        };
        let data = mask.as_slice();
        let (mut rays, mut tops, mut tiles) = (Vec::new(), Vec::new(), Vec::new());
        let side = TILE * BLOCK;
        for ty in (0..h).step_by(side) {
            for tx in (0..w).step_by(side) {
                let first = rays.len();
                let (tx1, ty1) = ((tx + side).min(w), (ty + side).min(h));
                for by in (ty..ty1).step_by(BLOCK) {
                    for bx in (tx..tx1).step_by(BLOCK) {
                        let (x1, y1) = ((bx + BLOCK).min(w), (by + BLOCK).min(h));
                        let (mut hit, mut only_structure) = (false, true);
                        for c in (by..y1).flat_map(|y| &data[y * w + bx..y * w + x1]) {
                            if is_obstacle(*c) {
                                hit = true;
                                only_structure &= is_structure(*c);
                            }
                        }
                        let (top, structure_seen) = near[(by / CELL) * cells_x + bx / CELL];
                        if !hit || (only_structure && structure_seen) {
                            continue;
                        }
                        let u = (bx + x1) as f64 / 2.0 * sx;
                        let v = (by + y1) as f64 / 2.0 * sy;
                        rays.push(direction(u, v));
                        tops.push(top);
                    }
                }
                if rays.len() > first {
                    let (u0, v0) = (tx as f64 * sx, ty as f64 * sy);
                    let (u1, v1) = (tx1 as f64 * sx, ty1 as f64 * sy);
                    tiles.push(Tile {
                        corners: [
                            direction(u0, v0),
                            direction(u1, v0),
                            direction(u1, v1),
                            direction(u0, v1),
                        ],
                        rays: first..rays.len(),
                    });
                }
            }
        }
        Self {
            camera: camera.clone(),
            origin: Point3::from(camera.pose.translation.vector),
            rays,
            tops,
            pixel_angle: BLOCK as f64 * (sx / camera.fx).max(sy / camera.fy),
            tiles,
        }
    }

    /// Bytes the rays hold on the heap (a fused stream keeps several frames' rays).
    pub fn heap_bytes(&self) -> usize {
        self.rays.capacity() * std::mem::size_of::<Vector3<f64>>()
            + self.tops.capacity() * std::mem::size_of::<Option<Point3<f64>>>()
            + self.tiles.capacity() * std::mem::size_of::<Tile>()
    }

    /// Number of obstacle blocks.
    pub fn len(&self) -> usize {
        self.rays.len()
    }

    /// True when no block holds an obstacle.
    pub fn is_empty(&self) -> bool {
        self.rays.is_empty()
    }

    /// The footprints of the obstacle blocks on the plane through `point` with unit `normal`,
    /// as disks `(x, y, radius)` that reach into `bounds` (`[min x, min y, max x, max y]`). Each
    /// block gives the disk where its ray crosses the plane (half a block diagonal at that
    /// range, stretched by the incidence) and, for an obstacle standing above the plane, more
    /// disks of that radius, one radius apart, back along the ray's ground track to below the
    /// point where the ray is as high above the plane as the obstacle. Rays that never reach
    /// the plane (parallel, or crossing it behind the camera) give nothing.
    pub fn on_plane(
        &self,
        point: [f64; 3],
        normal: [f64; 3],
        bounds: [f64; 4],
    ) -> Vec<([f64; 2], f64)> {
        let mut out = Vec::new();
        self.cast(point, normal, bounds, |_| true, &|_| true, &mut out);
        out
    }

    /// Whether `point` (world frame) is in front of this frame's camera and inside its image.
    pub fn sees(&self, point: &Point3<f64>) -> bool {
        self.camera.sees(point)
    }

    /// The footprints of several frames' obstacle blocks on one plane (as
    /// [`ObstacleRays::on_plane`]), `frames` oldest first, where a nearer view decides: a block of
    /// an older frame counts unless a newer frame's camera sees the place its obstacle stands
    /// (where its ray is the obstacle's height above the plane) from at most [`NEARER_VIEW`] of
    /// the older camera's range. A much nearer view replaces what a far one saw (its pixels are
    /// finer, and the far frame's false obstacles would shrink every circle); views from about
    /// the same range add up, so one frame's miss is not the last word; and what has left the
    /// newest camera's view is still kept clear of as the last cameras that saw it saw it.
    ///
    /// A caller that needs only some of the disks says so with `wanted`: where it refuses a box
    /// (`[min x, min y, max x, max y]`), the tiles and blocks whose disks all lie within that box
    /// are not cast. What is cast is as above.
    pub fn newest_view_on_plane(
        frames: &[&ObstacleRays],
        point: [f64; 3],
        normal: [f64; 3],
        bounds: [f64; 4],
        wanted: &dyn Fn(&[f64; 4]) -> bool,
    ) -> Vec<([f64; 2], f64)> {
        let mut out = Vec::new();
        for (i, rays) in frames.iter().enumerate() {
            let newer = &frames[i + 1..];
            rays.cast(
                point,
                normal,
                bounds,
                |base| {
                    let range = (base - rays.origin).norm();
                    !newer
                        .iter()
                        .any(|n| (base - n.origin).norm() <= NEARER_VIEW * range && n.sees(base))
                },
                wanted,
                &mut out,
            );
        }
        out
    }

    /// [`ObstacleRays::on_plane`] for the blocks whose obstacle base `keep` accepts, into `out`,
    /// but for those whose disks all lie in a box `wanted` refuses. Tiles whose blocks cannot
    /// reach `bounds` (or only in a refused box) are skipped whole ([`Tile::may_reach`]); the
    /// disks are those of casting every block.
    fn cast(
        &self,
        point: [f64; 3],
        normal: [f64; 3],
        bounds: [f64; 4],
        keep: impl Fn(&Point3<f64>) -> bool,
        wanted: &dyn Fn(&[f64; 4]) -> bool,
        out: &mut Vec<([f64; 2], f64)>,
    ) {
        let plane = self.plane(point, normal, bounds);
        for tile in &self.tiles {
            if tile.may_reach(&plane, wanted) {
                self.cast_rays(tile.rays.clone(), &plane, &keep, wanted, out);
            }
        }
    }

    /// What casting onto the plane through `point` with unit `normal` needs, the normal turned
    /// to the camera's side (heights are measured on that side).
    fn plane(&self, point: [f64; 3], normal: [f64; 3], bounds: [f64; 4]) -> Plane {
        let point = Point3::from(point);
        let mut normal = Vector3::from(normal);
        let camera_height = normal.dot(&(self.origin - point));
        if camera_height < 0.0 {
            normal = -normal;
        }
        Plane {
            point,
            normal,
            origin: self.origin,
            camera_height: camera_height.abs(),
            half_diagonal: self.pixel_angle * std::f64::consts::FRAC_1_SQRT_2,
            bounds,
        }
    }

    /// Casts the blocks `rays` (indices into `self.rays`) onto `plane`, into `out`.
    fn cast_rays(
        &self,
        rays: std::ops::Range<usize>,
        plane: &Plane,
        keep: impl Fn(&Point3<f64>) -> bool,
        wanted: &dyn Fn(&[f64; 4]) -> bool,
        out: &mut Vec<([f64; 2], f64)>,
    ) {
        let Plane {
            point,
            normal: n,
            camera_height,
            half_diagonal,
            bounds,
            ..
        } = *plane;
        let within = |c: &Point3<f64>, r: f64| {
            c.x + r >= bounds[0]
                && c.y + r >= bounds[1]
                && c.x - r <= bounds[2]
                && c.y - r <= bounds[3]
        };
        for (ray, top) in self.rays[rays.clone()].iter().zip(&self.tops[rays]) {
            // The ray descends towards the plane: cos of its incidence.
            let cos = -n.dot(ray);
            if cos < 1e-9 {
                continue;
            }
            let t = camera_height / cos;
            if !t.is_finite() {
                continue;
            }
            let hit = self.origin + ray * t;
            let radius = t * half_diagonal / cos.max(MIN_COS_INCIDENCE);
            let height = top
                .map_or(DEFAULT_OBSTACLE_HEIGHT_M, |top| n.dot(&(top - point)))
                .clamp(0.0, MAX_OBSTACLE_HEIGHT_M.min(camera_height));
            // Where the ray is `height` above the plane, dropped onto the plane.
            let under = self.origin + ray * (t - height / cos) - n * height;
            // Most obstacle pixels (streets, walls, other roofs) sweep nowhere near the region:
            // skip them on the bounding box of the whole sweep.
            let lo = hit.coords.inf(&under.coords);
            let hi = hit.coords.sup(&under.coords);
            if hi.x + radius < bounds[0]
                || hi.y + radius < bounds[1]
                || lo.x - radius > bounds[2]
                || lo.y - radius > bounds[3]
            {
                continue;
            }
            // Rounding: a disk's centre may land a hair outside the sweep's box.
            let slack = radius * (1.0 + 1e-9) + 1e-6 * (1.0 + hit.x.abs() + hit.y.abs());
            if !is_wanted(
                [lo.x - slack, lo.y - slack, hi.x + slack, hi.y + slack],
                wanted,
            ) {
                continue;
            }
            if !keep(&under) {
                continue;
            }
            let sweep = under - hit;
            let steps = ((sweep.norm() / radius).ceil() as usize).min(MAX_SWEEP_DISKS);
            for k in 0..=steps {
                let c = if steps == 0 {
                    hit
                } else {
                    hit + sweep * (k as f64 / steps as f64)
                };
                if within(&c, radius) {
                    out.push(([c.x, c.y], radius));
                }
            }
        }
    }
}

/// A plane to cast onto (see [`ObstacleRays::plane`]).
#[derive(Debug, Clone, Copy)]
struct Plane {
    point: Point3<f64>,
    /// Unit, on the camera's side.
    normal: Vector3<f64>,
    /// The camera's centre.
    origin: Point3<f64>,
    camera_height: f64,
    /// Half the diagonal of a block, radians.
    half_diagonal: f64,
    /// `[min x, min y, max x, max y]` the disks must reach into.
    bounds: [f64; 4],
}

impl Tile {
    /// False only when no disk of any of the tile's blocks can reach the plane's bounds.
    ///
    /// Every block's ray lies in the cone of the four corner rays, and each disk centre is a
    /// point of its ray between the plane and `MAX_OBSTACLE_HEIGHT_M` (at most the camera's
    /// height) above it, dropped onto the plane. That part of the cone is a convex solid whose
    /// vertices are the corner rays at those two heights, and the drop onto the plane is affine,
    /// so the centres lie in the box of the eight dropped vertices. A disk's radius,
    /// `camera height × half diagonal / (cos × max(cos, MIN_COS_INCIDENCE))`, is largest where
    /// the incidence's cos is least; that cos (the angle to the downward normal) has convex
    /// upper level sets, so its least value over the cone is at a corner. A tile with a corner
    /// at or past the plane's horizon is not tested. Nor is it skipped when the disks' box is
    /// not finite; else it is when `wanted` refuses that box.
    fn may_reach(&self, plane: &Plane, wanted: &dyn Fn(&[f64; 4]) -> bool) -> bool {
        let Plane {
            normal: n,
            origin,
            camera_height,
            half_diagonal,
            bounds,
            ..
        } = *plane;
        let top = MAX_OBSTACLE_HEIGHT_M.min(camera_height);
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        let mut least_cos = f64::INFINITY;
        for ray in &self.corners {
            let cos = -n.dot(ray);
            if cos.is_nan() || cos < 1e-9 {
                return true;
            }
            least_cos = least_cos.min(cos);
            let on_plane = origin + ray * (camera_height / cos);
            let dropped = origin + ray * ((camera_height - top) / cos) - n * top;
            for c in [on_plane, dropped] {
                lo = [lo[0].min(c.x), lo[1].min(c.y)];
                hi = [hi[0].max(c.x), hi[1].max(c.y)];
            }
        }
        let radius = camera_height * half_diagonal / (least_cos * least_cos.max(MIN_COS_INCIDENCE));
        // Rounding: the blocks' own arithmetic may land a hair outside the box.
        let slack = radius * (1.0 + 1e-9) + 1e-6 * (1.0 + origin.x.abs() + origin.y.abs());
        if !slack.is_finite() {
            return true;
        }
        let reach = [lo[0] - slack, lo[1] - slack, hi[0] + slack, hi[1] + slack];
        reach[2] >= bounds[0]
            && reach[3] >= bounds[1]
            && reach[0] <= bounds[2]
            && reach[1] <= bounds[3]
            && is_wanted(reach, wanted)
    }
}

/// Whether the disks lying in `reach` (`[min x, min y, max x, max y]`) are to be cast: a box
/// with a non-finite side always is, else as `wanted` says.
fn is_wanted(reach: [f64; 4], wanted: &dyn Fn(&[f64; 4]) -> bool) -> bool {
    !reach.iter().all(|v| v.is_finite()) || wanted(&reach)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::tests::nadir_camera_at;

    /// Skipping the tiles that cannot reach a plane's bounds gives exactly the disks of casting
    /// every block, on random cameras, masks, obstacle heights, planes and boxes, near the
    /// origin and a thousand kilometres from it; and skipping what a caller does not want loses
    /// none it does.
    #[test]
    fn skipping_tiles_loses_no_disk() {
        use nalgebra::{Isometry3, Translation3, UnitQuaternion};
        use rand::{Rng, SeedableRng, rngs::SmallRng};
        let mut rng = SmallRng::seed_from_u64(7);
        let (mut skipped, mut disks, mut left_out) = (0usize, 0usize, 0usize);
        for case in 0..400 {
            let far = if case % 2 == 0 { 0.0 } else { 1e6 };
            let mut camera = nadir_camera_at(rng.random_range(5.0..60.0));
            // Tilted by up to 80 degrees about a random horizontal axis, turned about z.
            let axis = Vector3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                0.0,
            );
            let tilt =
                UnitQuaternion::from_scaled_axis(axis.normalize() * rng.random_range(0.0..1.4))
                    * UnitQuaternion::from_euler_angles(0.0, 0.0, rng.random_range(0.0..6.3));
            camera.pose = Isometry3::from_parts(
                Translation3::new(
                    far + rng.random_range(-20.0..20.0),
                    rng.random_range(-20.0..20.0),
                    camera.pose.translation.z,
                ),
                tilt * camera.pose.rotation,
            );
            let (w, h) = (
                rng.random_range(3..=100usize),
                rng.random_range(3..=80usize),
            );
            let density = rng.random_range(0.01..0.5);
            let data: Vec<u8> = (0..w * h)
                .map(|_| if rng.random_bool(density) { 11 } else { 4 })
                .collect();
            // Obstacle tops for some blocks: points in the view's rough direction (single
            // precision, so only near the origin).
            let tops = if far == 0.0 {
                rng.random_range(0..50)
            } else {
                0
            };
            let points: Vec<[f32; 3]> = (0..tops)
                .map(|_| {
                    let p = camera.pose
                        * Point3::new(
                            rng.random_range(-15.0..15.0),
                            rng.random_range(-15.0..15.0),
                            rng.random_range(1.0..60.0),
                        );
                    [p.x as f32, p.y as f32, p.z as f32]
                })
                .collect();
            let rays = ObstacleRays::new(
                &camera,
                &ClassMask::new(w as u32, h as u32, data).unwrap(),
                &points,
                |c| c != 4,
                |_| false,
            );
            for _ in 0..5 {
                let normal = Vector3::new(
                    rng.random_range(-0.3..0.3),
                    rng.random_range(-0.3..0.3),
                    if rng.random_bool(0.2) { -1.0 } else { 1.0 },
                )
                .normalize();
                let point = [
                    far + rng.random_range(-30.0..30.0),
                    rng.random_range(-30.0..30.0),
                    rng.random_range(-5.0..70.0),
                ];
                let (x, y) = (
                    point[0] + rng.random_range(-30.0..30.0),
                    point[1] + rng.random_range(-30.0..30.0),
                );
                let (dx, dy) = (rng.random_range(0.0..20.0), rng.random_range(0.0..20.0));
                let bounds = [x, y, x + dx, y + dy];
                let mut all = Vec::new();
                let plane = rays.plane(point, normal.into(), bounds);
                rays.cast_rays(0..rays.len(), &plane, |_| true, &|_| true, &mut all);
                assert_eq!(
                    rays.on_plane(point, normal.into(), bounds),
                    all,
                    "case {case}"
                );
                // Wanted only where they meet a box: every disk whose own box meets it is still
                // there, in order, and nothing that casting every block does not give.
                let (x, y) = (
                    x + rng.random_range(-10.0..10.0),
                    y + rng.random_range(-10.0..10.0),
                );
                let near = [
                    x,
                    y,
                    x + rng.random_range(0.0..8.0),
                    y + rng.random_range(0.0..8.0),
                ];
                let meets = |b: &[f64; 4]| {
                    b[0] <= near[2] && near[0] <= b[2] && b[1] <= near[3] && near[1] <= b[3]
                };
                let disk_meets =
                    |(c, r): &&([f64; 2], f64)| meets(&[c[0] - r, c[1] - r, c[0] + r, c[1] + r]);
                let wanted = ObstacleRays::newest_view_on_plane(
                    &[&rays],
                    point,
                    normal.into(),
                    bounds,
                    &meets,
                );
                let mut rest = all.iter();
                assert!(
                    wanted.iter().all(|d| rest.any(|a| a == d)),
                    "case {case}: not cast"
                );
                assert_eq!(
                    wanted.iter().filter(disk_meets).collect::<Vec<_>>(),
                    all.iter().filter(disk_meets).collect::<Vec<_>>(),
                    "case {case}"
                );
                left_out += all.len() - wanted.len();
                skipped += (rays.tiles.iter())
                    .filter(|t| !t.may_reach(&plane, &|_| true))
                    .count();
                disks += all.len();
            }
        }
        // The test must exercise both sides: tiles skipped, and disks that reach; disks left
        // out where not wanted.
        assert!(
            skipped > 1000 && disks > 1000 && left_out > 1000,
            "{skipped} tiles skipped, {disks} disks, {left_out} not wanted"
        );
    }

    #[test]
    fn a_much_nearer_camera_that_sees_a_place_decides_it() {
        let roof = (
            [0.0, 0.0, 5.0],
            [0.0, 0.0, 1.0],
            [-100.0, -100.0, 100.0, 100.0],
        );
        let cast = |frames: &[&ObstacleRays]| {
            ObstacleRays::newest_view_on_plane(frames, roof.0, roof.1, roof.2, &|_| true)
        };
        // From 20 m, one obstacle block; it lands near (1.65, 2.85) on the roof.
        let mut data = vec![4u8; 100 * 80];
        data[21 * 100 + 61] = 7;
        let far = ObstacleRays::new(
            &nadir_camera_at(20.0),
            &ClassMask::new(100, 80, data).unwrap(),
            &[],
            |c| c != 4,
            |_| false,
        );
        let clear = ClassMask::new(100, 80, vec![4u8; 100 * 80]).unwrap();
        // From 12 m above the same place (about half the range) the roof is clear; from 30 m
        // east it is out of view; from 15 m (two thirds of the range) it is not much nearer.
        let near = ObstacleRays::new(&nadir_camera_at(12.0), &clear, &[], |c| c != 4, |_| false);
        let nearish = ObstacleRays::new(&nadir_camera_at(15.0), &clear, &[], |c| c != 4, |_| false);
        let mut elsewhere = nadir_camera_at(12.0);
        elsewhere.pose.translation.vector.x = 30.0;
        let elsewhere = ObstacleRays::new(&elsewhere, &clear, &[], |c| c != 4, |_| false);

        let alone = far.on_plane(roof.0, roof.1, roof.2);
        assert!(!alone.is_empty());
        assert_eq!(cast(&[&far]), alone);
        // A newer view of the same place replaces it; a newer view elsewhere does not.
        assert!(cast(&[&far, &near]).is_empty());
        assert_eq!(cast(&[&far, &nearish]), alone);
        assert_eq!(cast(&[&far, &elsewhere]), alone);
        // Order is time: the far frame as the newest keeps its block.
        assert_eq!(cast(&[&near, &far]), alone);
        // A newer view from about the same range adds to the older one instead of replacing it.
        let mut beside = nadir_camera_at(20.0);
        beside.pose.translation.vector.x = 0.5;
        let beside = ObstacleRays::new(&beside, &clear, &[], |c| c != 4, |_| false);
        assert_eq!(cast(&[&far, &beside]), alone);
        // Where the obstacle stands (its ray 1.2 m above the roof), which the near camera sees.
        let under = Point3::new(1.5, 2.6, 5.0);
        assert!(near.sees(&under) && nearish.sees(&under) && !elsewhere.sees(&under));
    }

    #[test]
    fn obstacle_pixels_land_where_the_camera_sees_them() {
        let camera = nadir_camera_at(20.0);
        // A 100×80 mask: one obstacle pixel (class 7) at mask (61, 21), in the 2×2 block
        // (60..62, 20..22) centred on image (61, 21).
        let mut data = vec![4u8; 100 * 80];
        data[21 * 100 + 61] = 7;
        let mask = ClassMask::new(100, 80, data).unwrap();
        let rays = ObstacleRays::new(&camera, &mask, &[], |c| c != 4, |_| false);
        assert_eq!(rays.len(), 1);
        // On the roof 5 m up, 15 m below the camera: image (61, 21) is camera (0.11, -0.19) · 15.
        let disks = rays.on_plane(
            [0.0, 0.0, 5.0],
            [0.0, 0.0, 1.0],
            [-100.0, -100.0, 100.0, 100.0],
        );
        // No LiDAR point near: the obstacle is taken as DEFAULT_OBSTACLE_HEIGHT_M (1.2 m) tall,
        // a sweep of 1.2 m × tan(incidence) = 1.2 × 0.22 = 0.26 m, between one and two radii:
        // the crossing and two more disks.
        assert_eq!(disks.len(), 3);
        let ([x, y], r) = disks[0];
        assert!(
            (x - 1.65).abs() < 1e-9 && (y - 2.85).abs() < 1e-9,
            "{x} {y}"
        );
        // One block spans 2 image pixels = 0.02 rad, 0.3 m at 15 m depth; half its diagonal,
        // times |d|² = 1 + 0.11² + 0.19² (range along the ray, then the slant onto the plane).
        let expected = 0.3 * std::f64::consts::FRAC_1_SQRT_2 * (1.0 + 0.11 * 0.11 + 0.19 * 0.19);
        assert!((r - expected).abs() < 1e-9, "{r} vs {expected}");
        // The projected point lies in the pixel: projecting it back gives image (61, 21).
        let (u, v) = camera.project(&Point3::new(x, y, 5.0)).unwrap();
        assert!((u - 61.0).abs() < 1e-9 && (v - 21.0).abs() < 1e-9);
        // The last disk is under the ray where it is 1.2 m above the roof (13.8 m deep), the
        // middle one half-way.
        let depth = 15.0 - DEFAULT_OBSTACLE_HEIGHT_M;
        let ([x2, y2], r2) = disks[2];
        assert!((x2 - 1.65 * depth / 15.0).abs() < 1e-9 && (y2 - 2.85 * depth / 15.0).abs() < 1e-9);
        assert_eq!(r2, r);
        let ([x1, _], _) = disks[1];
        assert!((x1 - (x + x2) / 2.0).abs() < 1e-9);
        // Outside the bounds: left out. Above the camera: never reached.
        assert!(
            rays.on_plane([0.0, 0.0, 5.0], [0.0, 0.0, 1.0], [10.0, 10.0, 20.0, 20.0])
                .is_empty()
        );
        assert!(
            rays.on_plane([0.0, 0.0, 25.0], [0.0, 0.0, 1.0], [-1e3, -1e3, 1e3, 1e3])
                .is_empty()
        );
    }

    /// A 5 × 5 pixel obstacle blob around image (86, 40) over a rooftop mask of the 100×80
    /// nadir camera 20 m up.
    fn blob_mask() -> ClassMask {
        let mut data = vec![4u8; 100 * 80];
        for y in 38..43 {
            for x in 84..89 {
                data[y * 100 + x] = 11;
            }
        }
        ClassMask::new(100, 80, data).unwrap()
    }

    fn covered(disks: &[([f64; 2], f64)], x: f64, y: f64) -> bool {
        disks
            .iter()
            .any(|([cx, cy], r)| (cx - x).hypot(cy - y) <= *r)
    }

    #[test]
    fn a_tall_obstacle_is_swept_back_to_its_footprint() {
        let camera = nadir_camera_at(20.0);
        // A water tank whose top, 4 m above the roof at z = 5, stands over (4, 0): it projects
        // to image (86.4, 40), in the blob. Its pixels' rays cross the roof 1.45 m further out.
        let tank_top = [4.0f32, 0.0, 9.0];
        let roof = [[0.0f32, 0.0, 5.0], [-3.0, 2.0, 5.0]];
        let plane = ([0.0, 0.0, 5.0], [0.0, 0.0, 1.0], [-50.0, -50.0, 50.0, 50.0]);
        let footprint = |points: &[[f32; 3]]| {
            let rays = ObstacleRays::new(&camera, &blob_mask(), points, |c| c != 4, |_| false);
            rays.on_plane(plane.0, plane.1, plane.2)
        };
        let with_height = footprint(&[roof[0], tank_top, roof[1]]);
        assert!(covered(&with_height, 4.0, 0.0), "{with_height:?}");
        assert!(covered(&with_height, 5.45, 0.0));
        // Without the LiDAR point the tank is taken as a low obstacle: its footprint is missed.
        let assumed_low = footprint(&roof);
        assert!(!covered(&assumed_low, 4.0, 0.0));
        assert!(covered(&assumed_low, 5.45, 0.0));
        // The normal's sign does not matter.
        let rays = ObstacleRays::new(&camera, &blob_mask(), &[tank_top], |c| c != 4, |_| false);
        let flipped = rays.on_plane(plane.0, [0.0, 0.0, -1.0], plane.2);
        assert_eq!(flipped, with_height);
        // A point below the plane (the street seen past an edge, here at image (86.4, 40) too)
        // sweeps nothing back: one disk per block.
        let below = footprint(&[[6.92, 0.0, 1.0]]);
        assert_eq!(below.len(), rays.len());
    }

    #[test]
    fn a_structure_the_scan_hit_casts_nothing() {
        let camera = nadir_camera_at(20.0);
        // A wall (class 3) one block wide, mask rows 30..50 at columns 70..72: ten blocks.
        let wall = |vent_at: Option<usize>| {
            let mut data = vec![4u8; 100 * 80];
            for y in 30..50 {
                for x in 70..72 {
                    data[y * 100 + x] = 3;
                }
            }
            if let Some(y) = vent_at {
                data[y * 100 + 71] = 7;
            }
            ClassMask::new(100, 80, data).unwrap()
        };
        // A LiDAR point on the wall, 1 m above the roof at z = 5: image (71, 40), mask cell
        // (8, 5). Its 3 × 3 cells hold every block of the wall but the first (rows 30..32).
        let on_wall = [[2.94f32, 0.0, 6.0]];
        // A point on the roof beside it, which the mask does not call structure.
        let on_roof = [[1.5f32, 0.0, 5.0]];
        let is_wall = |c: u8| c == 3;
        let blocks = |mask: &ClassMask, points: &[[f32; 3]], structure: &dyn Fn(u8) -> bool| {
            ObstacleRays::new(&camera, mask, points, |c| c != 4, structure).len()
        };
        assert_eq!(blocks(&wall(None), &on_wall, &is_wall), 1);
        // Without the point, or with the roof's, nothing says the scan hit the wall.
        assert_eq!(blocks(&wall(None), &[], &is_wall), 10);
        assert_eq!(blocks(&wall(None), &on_roof, &is_wall), 10);
        // Without structure classes every obstacle block casts.
        assert_eq!(blocks(&wall(None), &on_wall, &|_| false), 10);
        // A block that also holds another obstacle (an air vent before the wall) casts.
        assert_eq!(blocks(&wall(Some(41)), &on_wall, &is_wall), 2);
    }

    #[test]
    fn bounds_only_leave_out_disks_that_miss_them() {
        // Seeded obstacles all over the image, some with tall LiDAR points: the disks returned
        // for any bounds are exactly those of the unbounded footprint that reach into them.
        let camera = nadir_camera_at(20.0);
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move |n: u64| {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1);
            (state >> 33) % n
        };
        let mut data = vec![4u8; 100 * 80];
        for _ in 0..300 {
            data[next(8000) as usize] = 7 + next(5) as u8;
        }
        let mask = ClassMask::new(100, 80, data).unwrap();
        let points: Vec<[f32; 3]> = (0..60)
            .map(|_| {
                let (x, y) = (next(40) as f32 - 20.0, next(30) as f32 - 15.0);
                [x, y, 5.0 + next(8) as f32]
            })
            .collect();
        let rays = ObstacleRays::new(&camera, &mask, &points, |c| c != 4, |_| false);
        let everything = [-1e6, -1e6, 1e6, 1e6];
        let all = rays.on_plane([0.0, 0.0, 5.0], [0.0, 0.0, 1.0], everything);
        assert!(all.len() > rays.len(), "some blocks sweep");
        for _ in 0..50 {
            let (x, y) = (next(40) as f64 - 20.0, next(30) as f64 - 15.0);
            let b = [x, y, x + next(10) as f64, y + next(10) as f64];
            let reaching: Vec<_> = all
                .iter()
                .copied()
                .filter(|([cx, cy], r)| {
                    cx + r >= b[0] && cy + r >= b[1] && cx - r <= b[2] && cy - r <= b[3]
                })
                .collect();
            assert_eq!(rays.on_plane([0.0, 0.0, 5.0], [0.0, 0.0, 1.0], b), reaching);
        }
    }
}
