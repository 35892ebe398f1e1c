//! Unary detection through the service against the in-process pipeline and the ground truth.

use landing_client::v1::{self, SegmentationMode};
use landing_client::{ImageData, RigidTransform, camera_image, unpack_point_cloud};

use crate::support::{SCENE_FRAMES, TestServer, in_process, mode, scene, untimed};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn unary_detect_equals_in_process_pipeline() {
    let server = TestServer::start().await;
    let client = server.client().await;
    let scene = scene(11);
    for m in [
        SegmentationMode::None,
        SegmentationMode::PointClasses,
        SegmentationMode::Unspecified,
        SegmentationMode::ClassImage,
    ] {
        for recorded in [&scene.frames[0], &scene.frames[SCENE_FRAMES as usize - 1]] {
            let mut f = recorded.frame.clone();
            if m == SegmentationMode::ClassImage {
                f.class_image.clone_from(&recorded.labels);
            }
            let got = client
                .detect_with(f.clone(), Some(mode(m)))
                .await
                .expect("detect");
            let want = in_process(server.reference(), &f, &mode(m)).expect("in process");
            assert_eq!(
                untimed(got),
                untimed(want),
                "mode {m:?}, frame {}",
                f.sequence
            );
        }
    }
    server.stop().await;
}

/// Point-in-polygon by ray crossing, for the truth's roof outline.
fn inside(ring: &[[f64; 2]], p: [f64; 2]) -> bool {
    let mut inside = false;
    for i in 0..ring.len() {
        let (a, b) = (ring[i], ring[(i + 1) % ring.len()]);
        if (a[1] > p[1]) != (b[1] > p[1])
            && p[0] < a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0])
        {
            inside = !inside;
        }
    }
    inside
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn true_classes_put_the_best_site_on_the_approached_roof() {
    let server = TestServer::start().await;
    let client = server.client().await;
    let scene = scene(11);
    // The last frame of an approach is the closest to the roof.
    let last = scene.frames.last().expect("frames");
    let truth = last.truth.as_ref().expect("ground truth");
    let roof = truth.roofs.first().expect("the target roof is in view");
    let result = client
        .detect_with(
            last.frame.clone(),
            Some(mode(SegmentationMode::PointClasses)),
        )
        .await
        .expect("detect");
    let best = result
        .sites
        .first()
        .expect("at least one site on a visible roof");
    let c = best.center.expect("centre");
    let outline: Vec<[f64; 2]> = roof
        .outline
        .as_ref()
        .expect("outline")
        .points
        .iter()
        .map(|p| [p.x, p.y])
        .collect();
    assert!(
        inside(&outline, [c.x, c.y]),
        "best site centre {c:?} is off the target roof"
    );
    assert!(
        (c.z - roof.height_m).abs() < 0.5,
        "centre height {} vs roof {}",
        c.z,
        roof.height_m
    );
    // The returned radius cannot beat the truth by more than the polylabel precision and noise.
    assert!(
        best.safe_radius_m <= roof.best_safe_radius_m + 1.0,
        "radius {} > true best {}",
        best.safe_radius_m,
        roof.best_safe_radius_m
    );
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_geodetic_origin_gives_sites_latitude_and_longitude() {
    let server = TestServer::start().await;
    let client = server.client().await;
    let mut frame = scene(11).frames.last().expect("frames").frame.clone();
    frame.geodetic_origin = Some(landing_client::v1::GeodeticPoint {
        latitude_deg: 40.7128,
        longitude_deg: -74.006,
        altitude_m: 10.0,
    });
    let result = client
        .detect_with(frame, Some(mode(SegmentationMode::PointClasses)))
        .await
        .expect("detect");
    assert!(!result.sites.is_empty());
    for s in &result.sites {
        let g = s.center_geodetic.expect("geodetic centre");
        // The scene spans a few hundred metres: well within 0.05 degrees of the origin.
        assert!(
            (g.latitude_deg - 40.7128).abs() < 0.05 && (g.longitude_deg + 74.006).abs() < 0.05,
            "{g:?}"
        );
    }
    server.stop().await;
}

/// The frame's true label image as raw mono8 pixels, with its width and height.
fn true_labels(frame: &landing_recording::RecordedFrame) -> (v1::CameraImage, Vec<u8>, u32, u32) {
    let labels = frame.labels.clone().expect("the simulator records labels");
    let Some(v1::camera_image::Image::Compressed(png)) = &labels.image else {
        panic!("labels are a PNG")
    };
    let gray = image::load_from_memory(&png.data)
        .expect("label PNG")
        .into_luma8();
    let (w, h) = gray.dimensions();
    (labels, gray.into_raw(), w, h)
}

/// `labels` with other pixels, as raw mono8.
fn with_pixels(
    labels: &v1::CameraImage,
    width: u32,
    height: u32,
    data: Vec<u8>,
) -> v1::CameraImage {
    let pose = labels.pose.expect("pose");
    let calibration = labels.calibration.expect("calibration");
    camera_image(
        ImageData::Mono8 {
            width,
            height,
            data,
        },
        pose,
        calibration,
    )
    .expect("class image")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_class_image_classifies_the_points_and_keeps_safe_circles_off_its_obstacles() {
    let server = TestServer::start().await;
    let client = server.client().await;
    let scene = scene(11);
    let last = scene.frames.last().expect("frames");
    let (labels, pixels, w, h) = true_labels(last);

    // The true labels as the frame's class image: UNSPECIFIED picks them, and the service answers
    // what the in-process pipeline does.
    let mut frame = last.frame.clone();
    frame.class_image = Some(labels.clone());
    let truth = client
        .detect_with(frame.clone(), Some(mode(SegmentationMode::Unspecified)))
        .await
        .expect("detect");
    assert_eq!(truth.segmentation_mode, SegmentationMode::ClassImage as i32);
    let want = in_process(
        server.reference(),
        &frame,
        &mode(SegmentationMode::ClassImage),
    )
    .expect("in process");
    assert_eq!(untimed(truth.clone()), untimed(want));
    let best = truth.sites.first().expect("a site on the approached roof");
    let c = best.center.expect("centre");

    // Paint an AC unit (class 8) where the camera sees the best site's centre, only on pixels
    // that no LiDAR point projects to (nor their neighbours): every point keeps its class, so
    // only the keep-out disks of the painted pixels can move the safe circles off that spot.
    let image = frame.image.as_ref().expect("image");
    let k = image.calibration.expect("calibration");
    let camera = RigidTransform::from_pose(&image.pose.expect("pose")).inverse();
    let pixel = |p: [f64; 3]| {
        let p = camera.apply(p);
        (k.fx * p[0] / p[2] + k.cx, k.fy * p[1] / p[2] + k.cy)
    };
    let cloud = frame.point_cloud.as_ref().expect("cloud");
    let mut near_a_point = vec![false; pixels.len()];
    for p in unpack_point_cloud(cloud)
        .expect("cloud")
        .to_world(cloud.pose.as_ref())
    {
        let (u, v) = pixel(p);
        for (du, dv) in (-1..=1).flat_map(|a| (-1..=1).map(move |b| (a, b))) {
            let (x, y) = ((u.floor() as i64) + du, (v.floor() as i64) + dv);
            if (0..i64::from(w)).contains(&x) && (0..i64::from(h)).contains(&y) {
                near_a_point[(y * i64::from(w) + x) as usize] = true;
            }
        }
    }
    let (u, v) = pixel([c.x, c.y, c.z]);
    let mut painted = pixels.clone();
    let mut changed = 0;
    for y in 0..h {
        for x in 0..w {
            let (dx, dy) = (f64::from(x) + 0.5 - u, f64::from(y) + 0.5 - v);
            let i = (y * w + x) as usize;
            if dx * dx + dy * dy <= 16.0 && !near_a_point[i] {
                painted[i] = 8;
                changed += 1;
            }
        }
    }
    assert!(changed > 20, "the centre is in view ({u:.1}, {v:.1})");
    frame.class_image = Some(with_pixels(&labels, w, h, painted));
    let avoided = client
        .detect_with(frame.clone(), Some(mode(SegmentationMode::ClassImage)))
        .await
        .expect("detect");
    assert_eq!(avoided.triangle_count, truth.triangle_count);
    for s in &avoided.sites {
        let d = s.center.expect("centre");
        let dist = ((d.x - c.x).powi(2) + (d.y - c.y).powi(2)).sqrt();
        assert!(
            dist >= s.safe_radius_m - 0.5,
            "site {} (radius {:.2}) covers the painted obstacle {dist:.2} m from its centre",
            s.rank,
            s.safe_radius_m
        );
    }

    // A class image that sees no rooftop leaves no point that may form a landing plane.
    frame.class_image = Some(with_pixels(&labels, w, h, vec![2; pixels.len()]));
    let ground = client
        .detect_with(frame, Some(mode(SegmentationMode::ClassImage)))
        .await
        .expect("detect");
    assert!(ground.sites.is_empty(), "{:?}", ground.sites);
    server.stop().await;
}
