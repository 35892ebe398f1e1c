//! Obstacles that the camera sees and the LiDAR may miss, as keep-out disks on a landing plane.
//!
//! A 16-beam scan leaves metre-wide gaps between its lines at 40 m; a 0.5 m air vent between two
//! lines has no point, so the triangulated roof spans it. The class mask is dense: every pixel
//! whose class may not be landed on is an obstacle seen from the camera. Its ray crosses a
//! candidate landing plane at one point; the pixel's footprint there, a disk, must stay outside
//! the safe circle. A pixel that sees something above the plane (a tall obstacle) lands behind it
//! on the plane, one that sees something below (the street past an edge) lands before it: both
//! mark places where the camera does not see landable roof at the plane's height, which is what
//! matters.

use nalgebra::{Point3, Vector3};

use crate::{CameraModel, ClassMask};

/// Incidence below which a footprint is capped (rays almost parallel to the plane).
const MIN_COS_INCIDENCE: f64 = 0.2;

/// Side of the pixel blocks cast as one ray.
pub const BLOCK: usize = 2;

/// The rays of a mask's obstacle pixels, in the world frame.
#[derive(Debug, Clone)]
pub struct ObstacleRays {
    origin: Point3<f64>,
    /// Unit directions, world frame.
    rays: Vec<Vector3<f64>>,
    /// Angle one block spans, radians (the larger of its two sides).
    pixel_angle: f64,
}

impl ObstacleRays {
    /// The rays through the centres of the `BLOCK × BLOCK` pixel blocks of `mask` (stretched
    /// over the camera's image) that hold a pixel whose class `is_obstacle` says so. A block is
    /// one disk covering all of it: conservative, and a quarter of the rays to cast per plane.
    pub fn new(camera: &CameraModel, mask: &ClassMask, is_obstacle: impl Fn(u8) -> bool) -> Self {
        let (w, h) = (mask.width() as usize, mask.height() as usize);
        let sx = f64::from(camera.width) / w as f64;
        let sy = f64::from(camera.height) / h as f64;
        let rotation = camera.pose.rotation;
        let data = mask.as_slice();
        let mut rays = Vec::new();
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
            }
        }
        Self {
            origin: Point3::from(camera.pose.translation.vector),
            rays,
            pixel_angle: BLOCK as f64 * (sx / camera.fx).max(sy / camera.fy),
        }
    }

    /// Number of obstacle blocks.
    pub fn len(&self) -> usize {
        self.rays.len()
    }

    /// True when no block holds an obstacle.
    pub fn is_empty(&self) -> bool {
        self.rays.is_empty()
    }

    /// Where the rays cross the plane through `point` with unit `normal`: `(x, y, radius)` of
    /// each block's footprint (a disk around it, half a block diagonal at that range, stretched
    /// by the incidence), for the footprints that reach into `bounds` (`[min x, min y, max x,
    /// max y]`). Rays that never reach the plane (parallel, or crossing it behind the camera)
    /// give nothing.
    pub fn on_plane(
        &self,
        point: [f64; 3],
        normal: [f64; 3],
        bounds: [f64; 4],
    ) -> Vec<([f64; 2], f64)> {
        let n = Vector3::from(normal);
        let to_plane = n.dot(&(Point3::from(point) - self.origin));
        let half_diagonal = self.pixel_angle * std::f64::consts::FRAC_1_SQRT_2;
        let mut out = Vec::new();
        for ray in &self.rays {
            let along = n.dot(ray);
            if along.abs() < 1e-9 {
                continue;
            }
            let t = to_plane / along;
            if !(t > 0.0 && t.is_finite()) {
                continue;
            }
            let hit = self.origin + ray * t;
            let radius = t * half_diagonal / along.abs().max(MIN_COS_INCIDENCE);
            if hit.x + radius < bounds[0]
                || hit.y + radius < bounds[1]
                || hit.x - radius > bounds[2]
                || hit.y - radius > bounds[3]
            {
                continue;
            }
            out.push(([hit.x, hit.y], radius));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::tests::nadir_camera_at;

    #[test]
    fn obstacle_pixels_land_where_the_camera_sees_them() {
        let camera = nadir_camera_at(20.0);
        // A 100×80 mask: one obstacle pixel (class 7) at mask (61, 21), in the 2×2 block
        // (60..62, 20..22) centred on image (61, 21).
        let mut data = vec![4u8; 100 * 80];
        data[21 * 100 + 61] = 7;
        let mask = ClassMask::new(100, 80, data).unwrap();
        let rays = ObstacleRays::new(&camera, &mask, |c| c != 4);
        assert_eq!(rays.len(), 1);
        // On the roof 5 m up, 15 m below the camera: image (61, 21) is camera (0.11, -0.19) · 15.
        let disks = rays.on_plane(
            [0.0, 0.0, 5.0],
            [0.0, 0.0, 1.0],
            [-100.0, -100.0, 100.0, 100.0],
        );
        assert_eq!(disks.len(), 1);
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
}
