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

/// A newer frame replaces an older one's view of a place only from at most this fraction of the
/// older one's range to it (see [`ObstacleRays::newest_view_on_plane`]).
pub const NEARER_VIEW: f64 = 0.8;

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
}

impl ObstacleRays {
    /// The rays through the centres of the `BLOCK × BLOCK` pixel blocks of `mask` (stretched
    /// over the camera's image) that hold a pixel whose class `is_obstacle` says so. A block is
    /// one disk covering all of it: conservative, and a quarter of the rays to cast per plane.
    /// `points` (world frame) give the obstacles' heights: each point that projects onto an
    /// obstacle pixel counts for the blocks around it.
    pub fn new(
        camera: &CameraModel,
        mask: &ClassMask,
        points: &[[f32; 3]],
        is_obstacle: impl Fn(u8) -> bool,
    ) -> Self {
        let (w, h) = (mask.width() as usize, mask.height() as usize);
        let sx = f64::from(camera.width) / w as f64;
        let sy = f64::from(camera.height) / h as f64;

        // The highest obstacle point of every CELL × CELL cell of the mask.
        let (cells_x, cells_y) = (w.div_ceil(CELL), h.div_ceil(CELL));
        let mut highest: Vec<Option<Point3<f64>>> = vec![None; cells_x * cells_y];
        for p in points {
            let p = Point3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
            let Some((u, v)) = camera.project(&p) else {
                continue;
            };
            if !is_obstacle(mask.class_at_image_point(u, v, camera.width, camera.height)) {
                continue;
            }
            // In the image (the lookup above said so): a cell of the mask.
            let (x, y) = ((u / sx) as usize, (v / sy) as usize);
            let cell =
                &mut highest[(y / CELL).min(cells_y - 1) * cells_x + (x / CELL).min(cells_x - 1)];
            if cell.is_none_or(|c| p.z > c.z) {
                *cell = Some(p);
            }
        }
        // The highest of the 3 × 3 cells around each cell: what every block of that cell sees.
        let near: Vec<Option<Point3<f64>>> = (0..cells_x * cells_y)
            .map(|i| {
                let (cx, cy) = (i % cells_x, i / cells_x);
                let mut top: Option<Point3<f64>> = None;
                for ny in cy.saturating_sub(1)..(cy + 2).min(cells_y) {
                    for nx in cx.saturating_sub(1)..(cx + 2).min(cells_x) {
                        if let Some(p) = highest[ny * cells_x + nx]
                            && top.is_none_or(|t| p.z > t.z)
                        {
                            top = Some(p);
                        }
                    }
                }
                top
            })
            .collect();

        let rotation = camera.pose.rotation;
        let data = mask.as_slice();
        let (mut rays, mut tops) = (Vec::new(), Vec::new());
        for by in (0..h).step_by(BLOCK) {
            for bx in (0..w).step_by(BLOCK) {
                let (x1, y1) = ((bx + BLOCK).min(w), (by + BLOCK).min(h));
                let hit = (by..y1).any(|y| (bx..x1).any(|x| is_obstacle(data[y * w + x])));
                if !hit {
                    continue;
                }
                let u = (bx + x1) as f64 / 2.0 * sx;
                let v = (by + y1) as f64 / 2.0 * sy;
                let d = Vector3::new(
                    (u - camera.cx) / camera.fx,
                    (v - camera.cy) / camera.fy,
                    1.0,
                );
                rays.push(rotation * d.normalize());
                tops.push(near[(by / CELL) * cells_x + bx / CELL]);
            }
        }
        Self {
            camera: camera.clone(),
            origin: Point3::from(camera.pose.translation.vector),
            rays,
            tops,
            pixel_angle: BLOCK as f64 * (sx / camera.fx).max(sy / camera.fy),
        }
    }

    /// Bytes the rays hold on the heap (a fused stream keeps several frames' rays).
    pub fn heap_bytes(&self) -> usize {
        self.rays.capacity() * std::mem::size_of::<Vector3<f64>>()
            + self.tops.capacity() * std::mem::size_of::<Option<Point3<f64>>>()
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
        self.cast(point, normal, bounds, |_| true, &mut out);
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
    pub fn newest_view_on_plane(
        frames: &[&ObstacleRays],
        point: [f64; 3],
        normal: [f64; 3],
        bounds: [f64; 4],
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
                &mut out,
            );
        }
        out
    }

    /// [`ObstacleRays::on_plane`] for the blocks whose obstacle base `keep` accepts, into `out`.
    fn cast(
        &self,
        point: [f64; 3],
        normal: [f64; 3],
        bounds: [f64; 4],
        keep: impl Fn(&Point3<f64>) -> bool,
        out: &mut Vec<([f64; 2], f64)>,
    ) {
        let point = Point3::from(point);
        let mut n = Vector3::from(normal);
        // Heights are measured on the camera's side of the plane.
        let camera_height = n.dot(&(self.origin - point));
        if camera_height < 0.0 {
            n = -n;
        }
        let camera_height = camera_height.abs();
        let half_diagonal = self.pixel_angle * std::f64::consts::FRAC_1_SQRT_2;
        let within = |c: &Point3<f64>, r: f64| {
            c.x + r >= bounds[0]
                && c.y + r >= bounds[1]
                && c.x - r <= bounds[2]
                && c.y - r <= bounds[3]
        };
        for (ray, top) in self.rays.iter().zip(&self.tops) {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::tests::nadir_camera_at;

    #[test]
    fn a_much_nearer_camera_that_sees_a_place_decides_it() {
        let roof = (
            [0.0, 0.0, 5.0],
            [0.0, 0.0, 1.0],
            [-100.0, -100.0, 100.0, 100.0],
        );
        let cast = |frames: &[&ObstacleRays]| {
            ObstacleRays::newest_view_on_plane(frames, roof.0, roof.1, roof.2)
        };
        // From 20 m, one obstacle block; it lands near (1.65, 2.85) on the roof.
        let mut data = vec![4u8; 100 * 80];
        data[21 * 100 + 61] = 7;
        let far = ObstacleRays::new(
            &nadir_camera_at(20.0),
            &ClassMask::new(100, 80, data).unwrap(),
            &[],
            |c| c != 4,
        );
        let clear = ClassMask::new(100, 80, vec![4u8; 100 * 80]).unwrap();
        // From 15 m above the same place the roof is clear; from 30 m east it is out of view.
        let near = ObstacleRays::new(&nadir_camera_at(15.0), &clear, &[], |c| c != 4);
        let mut elsewhere = nadir_camera_at(15.0);
        elsewhere.pose.translation.vector.x = 30.0;
        let elsewhere = ObstacleRays::new(&elsewhere, &clear, &[], |c| c != 4);

        let alone = far.on_plane(roof.0, roof.1, roof.2);
        assert!(!alone.is_empty());
        assert_eq!(cast(&[&far]), alone);
        // A newer view of the same place replaces it; a newer view elsewhere does not.
        assert!(cast(&[&far, &near]).is_empty());
        assert_eq!(cast(&[&far, &elsewhere]), alone);
        // Order is time: the far frame as the newest keeps its block.
        assert_eq!(cast(&[&near, &far]), alone);
        // A newer view from about the same range adds to the older one instead of replacing it.
        let mut beside = nadir_camera_at(20.0);
        beside.pose.translation.vector.x = 0.5;
        let beside = ObstacleRays::new(&beside, &clear, &[], |c| c != 4);
        assert_eq!(cast(&[&far, &beside]), alone);
        let under = Point3::new(1.65, 2.85, 5.0);
        assert!(near.sees(&under) && !elsewhere.sees(&under));
    }

    #[test]
    fn obstacle_pixels_land_where_the_camera_sees_them() {
        let camera = nadir_camera_at(20.0);
        // A 100×80 mask: one obstacle pixel (class 7) at mask (61, 21), in the 2×2 block
        // (60..62, 20..22) centred on image (61, 21).
        let mut data = vec![4u8; 100 * 80];
        data[21 * 100 + 61] = 7;
        let mask = ClassMask::new(100, 80, data).unwrap();
        let rays = ObstacleRays::new(&camera, &mask, &[], |c| c != 4);
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
            let rays = ObstacleRays::new(&camera, &blob_mask(), points, |c| c != 4);
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
        let rays = ObstacleRays::new(&camera, &blob_mask(), &[tank_top], |c| c != 4);
        let flipped = rays.on_plane(plane.0, [0.0, 0.0, -1.0], plane.2);
        assert_eq!(flipped, with_height);
        // A point below the plane (the street seen past an edge, here at image (86.4, 40) too)
        // sweeps nothing back: one disk per block.
        let below = footprint(&[[6.92, 0.0, 1.0]]);
        assert_eq!(below.len(), rays.len());
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
        let rays = ObstacleRays::new(&camera, &mask, &points, |c| c != 4);
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
