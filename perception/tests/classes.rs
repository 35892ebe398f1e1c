//! The class table and the projection agree with the rest of the workspace.

use landing_geometry::SemanticClass;
use landing_perception::{CameraModel, ClassMask, NUM_CLASSES, classify_points};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng, rngs::SmallRng};

#[test]
fn class_count_matches_the_shared_table() {
    assert_eq!(NUM_CLASSES, SemanticClass::COUNT);
    assert_eq!(SemanticClass::BuildingRooftop as u8, 4);
}

/// Seeded property: for random poses and points, a point's class is 0 exactly when it is behind
/// the camera or projects outside the image, and otherwise the class of the pixel it lands in.
#[test]
fn classify_points_agrees_with_project_for_random_cameras() {
    let mut rng = SmallRng::seed_from_u64(0x5eed);
    for _ in 0..200 {
        let (w, h) = (rng.random_range(8..64u32), rng.random_range(8..64u32));
        // Each pixel holds a distinct-ish class so that a wrong pixel is noticed.
        let data = (0..w * h).map(|i| (1 + i % 14) as u8).collect();
        let mask = ClassMask::new(w, h, data).unwrap();
        let axis = Vector3::new(rng.random(), rng.random(), rng.random::<f64>() + 0.1);
        let camera = CameraModel {
            pose: Isometry3::from_parts(
                Translation3::new(
                    rng.random_range(-50.0..50.0),
                    rng.random_range(-50.0..50.0),
                    rng.random_range(-50.0..50.0),
                ),
                UnitQuaternion::from_scaled_axis(axis.normalize() * rng.random_range(0.0..6.0)),
            ),
            fx: rng.random_range(20.0..200.0),
            fy: rng.random_range(20.0..200.0),
            cx: f64::from(w) / 2.0,
            cy: f64::from(h) / 2.0,
            width: w,
            height: h,
        };
        let points: Vec<[f32; 3]> = (0..200)
            .map(|_| {
                [
                    rng.random_range(-100.0..100.0),
                    rng.random_range(-100.0..100.0),
                    rng.random_range(-100.0..100.0),
                ]
            })
            .collect();
        let classes = classify_points(&points, &camera, &mask);
        for (p, &c) in points.iter().zip(&classes) {
            let pw = nalgebra::Point3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
            let expected = match camera.project(&pw) {
                Some((u, v)) if u >= 0.0 && v >= 0.0 && u < f64::from(w) && v < f64::from(h) => {
                    let (x, y) = (u.floor() as u32, v.floor() as u32);
                    // Skip points within rounding distance of a pixel border.
                    if (u - u.round()).abs() < 1e-6 || (v - v.round()).abs() < 1e-6 {
                        continue;
                    }
                    mask.get(x, y).unwrap()
                }
                _ => 0,
            };
            assert_eq!(c, expected, "point {p:?} camera {camera:?}");
        }
    }
}
