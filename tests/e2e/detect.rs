//! Unary detection through the service against the in-process pipeline and the ground truth.

use landing_client::v1::SegmentationMode;

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
    ] {
        for f in [
            &scene.frames[0].frame,
            &scene.frames[SCENE_FRAMES as usize - 1].frame,
        ] {
            let got = client
                .detect_with(f.clone(), Some(mode(m)))
                .await
                .expect("detect");
            let want = in_process(server.reference(), f, &mode(m)).expect("in process");
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
