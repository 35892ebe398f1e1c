//! Point classification on simulated frames: LiDAR points of the simulator's scanner, projected
//! into the camera's class mask, against the class of the surface each point hit.

mod common;

use landing_perception::{CameraModel, ClassMask, classify_points};
use landing_sim::camera::{CameraConfig, Intrinsics, render};
use landing_sim::flight::{ViewConfig, lidar_pose, view_of};
use landing_sim::lidar::{LidarConfig, LidarPoint, scan};
use landing_sim::{World, WorldConfig};
use rand::SeedableRng;
use rand::rngs::SmallRng;

struct Frame {
    camera: CameraModel,
    labels: ClassMask,
    image: image::RgbImage,
    points: Vec<LidarPoint>,
}

/// A seeded Manhattan world, a view of one of its roofs, the camera render and the LiDAR scan.
fn frame(seed: u64) -> Frame {
    let world = World::generate(seed, &WorldConfig::default()).unwrap();
    let mut rng = SmallRng::seed_from_u64(seed);
    let building = (seed as usize * 7) % world.buildings.len();
    let view = view_of(&world, building, &ViewConfig::default(), &mut rng);
    let intrinsics = Intrinsics::from_hfov(256, 192, 70.0).unwrap();
    let rendered = render(
        &world,
        &intrinsics,
        &view.camera,
        &CameraConfig::default(),
        seed,
    );
    let points = scan(
        &world,
        &lidar_pose(&view.camera),
        &LidarConfig::default(),
        seed,
    )
    .unwrap();
    Frame {
        camera: CameraModel {
            pose: view.camera,
            fx: intrinsics.fx,
            fy: intrinsics.fy,
            cx: intrinsics.cx,
            cy: intrinsics.cy,
            width: intrinsics.width,
            height: intrinsics.height,
        },
        labels: ClassMask::new(rendered.width, rendered.height, rendered.labels).unwrap(),
        image: image::RgbImage::from_raw(rendered.width, rendered.height, rendered.rgb).unwrap(),
        points,
    }
}

/// Whether the pixel a point projects to has the same label in its whole 5×5 neighbourhood.
fn away_from_edges(frame: &Frame, point: &LidarPoint) -> bool {
    let p = nalgebra::Point3::new(point.world[0], point.world[1], point.world[2]);
    let Some((u, v)) = frame.camera.project(&p) else {
        return false;
    };
    let (x, y) = (u.floor() as i64, v.floor() as i64);
    let (w, h) = (
        i64::from(frame.labels.width()),
        i64::from(frame.labels.height()),
    );
    if x < 2 || y < 2 || x >= w - 2 || y >= h - 2 {
        return false;
    }
    let centre = frame.labels.get(x as u32, y as u32);
    (-2..=2)
        .all(|dy| (-2..=2).all(|dx| frame.labels.get((x + dx) as u32, (y + dy) as u32) == centre))
}

fn world_points(points: &[LidarPoint]) -> Vec<[f32; 3]> {
    points
        .iter()
        .map(|p| [p.world[0] as f32, p.world[1] as f32, p.world[2] as f32])
        .collect()
}

#[test]
fn ground_truth_labels_classify_points_away_from_edges() {
    let (mut agree, mut total) = (0usize, 0usize);
    for seed in [3u64, 11, 29] {
        let frame = frame(seed);
        let classes = classify_points(&world_points(&frame.points), &frame.camera, &frame.labels);
        for (point, &class) in frame.points.iter().zip(&classes) {
            if away_from_edges(&frame, point) {
                total += 1;
                agree += usize::from(class == point.class);
            }
        }
    }
    let rate = agree as f64 / total as f64;
    eprintln!(
        "ground-truth mask: {agree} of {total} points agree ({:.2} %)",
        rate * 100.0
    );
    assert!(total > 2_000, "only {total} points in view away from edges");
    assert!(rate >= 0.99, "agreement {rate:.4} < 0.99");
}

#[test]
fn model_mask_classifies_rooftop_points() {
    let seg = common::segmenter();
    let rooftop = 4u8;
    let (mut agree, mut total, mut predicted_rooftop, mut predicted_rooftop_right) = (0, 0, 0, 0);
    for seed in [3u64, 11, 29] {
        let frame = frame(seed);
        let mask = seg.segment(&frame.image).unwrap();
        let classes = classify_points(&world_points(&frame.points), &frame.camera, &mask);
        for (point, &class) in frame.points.iter().zip(&classes) {
            if !away_from_edges(&frame, point) {
                continue;
            }
            if point.class == rooftop {
                total += 1;
                agree += usize::from(class == rooftop);
            }
            if class == rooftop {
                predicted_rooftop += 1;
                predicted_rooftop_right += usize::from(point.class == rooftop);
            }
        }
    }
    let recall = agree as f64 / total as f64;
    let precision = predicted_rooftop_right as f64 / predicted_rooftop as f64;
    eprintln!(
        "model mask, rooftop points away from edges: recall {:.2} % ({agree} of {total}), \
         precision {:.2} % ({predicted_rooftop_right} of {predicted_rooftop})",
        recall * 100.0,
        precision * 100.0
    );
    assert!(total > 1_000, "only {total} rooftop points");
    assert!(recall >= 0.90, "rooftop recall {recall:.3} < 0.90");
    assert!(precision >= 0.90, "rooftop precision {precision:.3} < 0.90");
}
