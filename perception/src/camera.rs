//! The pinhole camera and the projection of world points into a class mask.

use nalgebra::{Isometry3, Point3};

use crate::{ClassMask, PerceptionError};

/// A pinhole camera: pose `T_world_camera` in the optical convention (x right, y down, z forward)
/// and intrinsics, `u = fx·x/z + cx`, `v = fy·y/z + cy`, for an image of `width × height` pixels.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraModel {
    /// `T_world_camera`: maps camera-frame coordinates to world coordinates.
    pub pose: Isometry3<f64>,
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
}

impl CameraModel {
    /// Checks that the intrinsics are finite and positive where they must be, and that the pose
    /// is finite. Errors name the field.
    pub fn validate(&self) -> Result<(), PerceptionError> {
        for (field, value) in [("fx", self.fx), ("fy", self.fy)] {
            if !(value.is_finite() && value > 0.0) {
                return Err(PerceptionError::invalid_input(
                    field,
                    value,
                    "must be finite and > 0",
                ));
            }
        }
        for (field, value) in [("cx", self.cx), ("cy", self.cy)] {
            if !value.is_finite() {
                return Err(PerceptionError::invalid_input(
                    field,
                    value,
                    "must be finite",
                ));
            }
        }
        for (field, value) in [("width", self.width), ("height", self.height)] {
            if value == 0 {
                return Err(PerceptionError::invalid_input(field, value, "must be > 0"));
            }
        }
        let t = &self.pose.translation.vector;
        let q = self.pose.rotation.quaternion();
        if !(t.iter().all(|v| v.is_finite()) && q.coords.iter().all(|v| v.is_finite())) {
            return Err(PerceptionError::invalid_input(
                "pose",
                format!("{:?}", self.pose),
                "must be finite",
            ));
        }
        Ok(())
    }

    /// How finely a mask of `mask_width × mask_height` pixels, stretched over this camera's
    /// image, sees a world point: the longer side, metres, of the patch that one mask pixel
    /// covers on level ground (constant world z) through the point; `None` when the camera does
    /// not see the point ([`CameraModel::sees`]). Across the ray the patch is the range times the
    /// pixel's angle; along the ground it stretches by one over the sine of the ray's elevation,
    /// so a grazing view is coarse however near.
    ///
    /// ```
    /// # use landing_perception::CameraModel;
    /// # use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
    /// // 20 m above the ground looking straight down, f = 100 px: 0.2 m an image pixel right
    /// // below, 0.4 m a pixel of a mask of half the image's size.
    /// let down = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
    /// let camera = CameraModel {
    ///     pose: Isometry3::from_parts(Translation3::new(0.0, 0.0, 20.0), down),
    ///     fx: 100.0, fy: 100.0, cx: 50.0, cy: 40.0, width: 100, height: 80,
    /// };
    /// let footprint = |p| camera.footprint_on_level_ground(&p, 50, 40);
    /// assert!((footprint(Point3::new(0.0, 0.0, 0.0)).unwrap() - 0.4).abs() < 1e-9);
    /// // 5 m to the side: 1.03 times as far, and stretched by 1.03 along the ground.
    /// let side = footprint(Point3::new(5.0, 0.0, 0.0)).unwrap();
    /// assert!((side - 0.4 * (1.0 + 0.25 * 0.25)).abs() < 1e-9);
    /// // Outside the image.
    /// assert_eq!(footprint(Point3::new(20.0, 0.0, 0.0)), None);
    /// ```
    pub fn footprint_on_level_ground(
        &self,
        point: &Point3<f64>,
        mask_width: u32,
        mask_height: u32,
    ) -> Option<f64> {
        if !self.sees(point) {
            return None;
        }
        // The angle one mask pixel spans, the larger of its two sides.
        let angle = (f64::from(self.width) / (self.fx * f64::from(mask_width.max(1))))
            .max(f64::from(self.height) / (self.fy * f64::from(mask_height.max(1))));
        // range × angle / sin(elevation), with sin(elevation) = |dz| / range.
        let d = point - self.pose.translation.vector;
        let footprint = d.coords.norm_squared() * angle / d.z.abs();
        footprint.is_finite().then_some(footprint)
    }

    /// Whether a world point is in front of the camera and inside its image.
    pub fn sees(&self, point: &Point3<f64>) -> bool {
        let (w, h) = (f64::from(self.width), f64::from(self.height));
        self.project(point)
            .is_some_and(|(u, v)| (0.0..w).contains(&u) && (0.0..h).contains(&v))
    }

    /// The pixel coordinates `(u, v)` of a world point, or `None` when it is not in front of the
    /// camera (`z <= 0` in the camera frame). The result may lie outside the image.
    pub fn project(&self, point_world: &Point3<f64>) -> Option<(f64, f64)> {
        let p = self.pose.inverse_transform_point(point_world);
        (p.z > 0.0).then(|| (self.fx * p.x / p.z + self.cx, self.fy * p.y / p.z + self.cy))
    }
}

/// The class of every world point as seen in `mask`: each point is moved into the camera frame,
/// projected with the intrinsics, and looked up in the mask stretched over the camera's image.
/// Points behind the camera, outside the image, or not finite get `0` (unknown).
pub fn classify_points(
    points_world: &[[f32; 3]],
    camera: &CameraModel,
    mask: &ClassMask,
) -> Vec<u8> {
    // One matrix product per point: world → camera is the inverse pose.
    let world_to_camera = camera.pose.inverse().to_homogeneous();
    let r = world_to_camera.fixed_view::<3, 3>(0, 0);
    let t = world_to_camera.fixed_view::<3, 1>(0, 3);
    points_world
        .iter()
        .map(|p| {
            let pw = nalgebra::Vector3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
            let pc = r * pw + t;
            // NaN fails this test too, so non-finite points come out unknown.
            if pc.z.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
                return 0;
            }
            let u = camera.fx * pc.x / pc.z + camera.cx;
            let v = camera.fy * pc.y / pc.z + camera.cy;
            mask.class_at_image_point(u, v, camera.width, camera.height)
        })
        .collect()
}

#[cfg(test)]
pub(crate) mod tests {
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    use super::*;

    /// A camera 10 m up looking straight down.
    fn nadir_camera() -> CameraModel {
        nadir_camera_at(10.0)
    }

    /// A camera `height` m up looking straight down, 100×80 pixels, f = 100 px: camera z =
    /// world -z, camera x = world x, camera y = world -y.
    pub(crate) fn nadir_camera_at(height: f64) -> CameraModel {
        let rotation = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
        CameraModel {
            pose: Isometry3::from_parts(Translation3::new(0.0, 0.0, height), rotation),
            fx: 100.0,
            fy: 100.0,
            cx: 50.0,
            cy: 40.0,
            width: 100,
            height: 80,
        }
    }

    #[test]
    fn nadir_projection_matches_the_formula() {
        let cam = nadir_camera();
        let (u, v) = cam.project(&Point3::new(1.0, 2.0, 0.0)).unwrap();
        // Camera frame: x = 1, y = -2, z = 10.
        assert!((u - 60.0).abs() < 1e-9, "{u}");
        assert!((v - 20.0).abs() < 1e-9, "{v}");
        assert!(cam.project(&Point3::new(0.0, 0.0, 11.0)).is_none());
    }

    #[test]
    fn classify_points_uses_quadrants_and_rejects_outside() {
        let cam = nadir_camera();
        // 2x2 mask: top-left 1, top-right 2, bottom-left 3, bottom-right 4.
        let mask = ClassMask::new(2, 2, vec![1, 2, 3, 4]).unwrap();
        let points = [
            [-1.0, 1.0, 0.0],  // u 40, v 30: top-left
            [1.0, 1.0, 0.0],   // u 60, v 30: top-right
            [-1.0, -1.0, 0.0], // bottom-left
            [1.0, -1.0, 0.0],  // bottom-right
            [0.0, 0.0, 20.0],  // behind the camera
            [100.0, 0.0, 0.0], // far outside the image
            [f32::NAN, 0.0, 0.0],
        ];
        assert_eq!(
            classify_points(&points, &cam, &mask),
            vec![1, 2, 3, 4, 0, 0, 0]
        );
    }

    #[test]
    fn validate_names_the_field() {
        let mut cam = nadir_camera();
        cam.fy = 0.0;
        assert!(cam.validate().unwrap_err().to_string().contains("fy"));
        let mut cam = nadir_camera();
        cam.height = 0;
        assert!(cam.validate().unwrap_err().to_string().contains("height"));
        assert!(nadir_camera().validate().is_ok());
    }
}
