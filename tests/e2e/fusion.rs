//! Approach fusion over a real stream: answers come from the stream's map, equal to the
//! in-process fused pipeline frame by frame; the map resets on request; bad options name their
//! field; the defaults are reported; a fused frame's points and keep-out footprints take the
//! finest segmentation mask alone.

use landing_client::v1::{self, SegmentationMode};
use landing_client::{FrameOutcome, StreamConfig};
use landing_server::convert;
use landing_server::pipeline::{StreamMap, run_fused, to_world};

use crate::support::{TestServer, mode, scene, stream_with, untimed};

fn fusing(options: v1::PipelineOptions, fusion: v1::FusionOptions) -> StreamConfig {
    StreamConfig {
        max_in_flight: 4,
        ..StreamConfig::fused_with(fusion).with_options(options)
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn fused_answers_equal_the_in_process_fused_pipeline() {
    let server = TestServer::start().await;
    let frames: Vec<v1::Frame> = scene(31).frames.iter().map(|f| f.frame.clone()).collect();
    let options = mode(SegmentationMode::PointClasses);
    let items = stream_with(
        &server,
        frames.clone(),
        fusing(options.clone(), v1::FusionOptions::default()),
        None,
    )
    .await;
    assert_eq!(items.len(), frames.len());

    let defaults = landing_server::Config::default().fusion.params();
    let mut map = StreamMap::new(defaults).unwrap();
    let mut grew = false;
    for (i, (item, frame)) in items.iter().zip(&frames).enumerate() {
        assert_eq!(item.sequence, frame.sequence, "answers in order");
        let FrameOutcome::Result(got) = &item.outcome else {
            panic!("frame {i}: {:?}", item.outcome);
        };
        let request = v1::DetectLandingSitesRequest {
            frame: Some(frame.clone()),
            options: Some(options.clone()),
        };
        let (f, o) = convert::request_parts(&request, &server.reference().defaults).unwrap();
        let want = run_fused(&f, &o, server.reference(), &mut map, false).unwrap();
        assert_eq!(
            untimed(got.clone()),
            untimed(v1::FrameResult::from(&want)),
            "frame {i}"
        );
        let fusion = got
            .fusion
            .as_ref()
            .expect("a fused answer says what it fused");
        assert_eq!(fusion.frames as usize, i + 1);
        assert_eq!(fusion.points, got.point_count);
        assert!(fusion.reset_reason.is_empty());
        // Each answer says how its scan was laid onto the map, or why it was not.
        assert_ne!(
            fusion.registration.is_some(),
            !fusion.registration_skipped.is_empty(),
            "frame {i}: {fusion:?}"
        );
        if i == 0 {
            assert_eq!(fusion.registration_skipped, "nothing to register to");
        }
        grew |= i > 0 && fusion.cells as usize > frame_points(frame);
    }
    assert!(grew, "the map holds more than one frame's points");
    server.stop().await;
}

fn frame_points(frame: &v1::Frame) -> usize {
    let cloud = frame.point_cloud.as_ref().unwrap();
    cloud.data.len() / cloud.point_stride as usize
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_requested_reset_starts_the_map_over() {
    let server = TestServer::start().await;
    let frames: Vec<v1::Frame> = scene(32).frames.iter().map(|f| f.frame.clone()).collect();
    assert!(frames.len() >= 4);
    let config = fusing(mode(SegmentationMode::None), v1::FusionOptions::default());
    let items = stream_with(&server, frames, config, Some(2)).await;
    let fused: Vec<&v1::FusionSummary> = items
        .iter()
        .map(|i| i.outcome.result().and_then(|r| r.fusion.as_ref()).unwrap())
        .collect();
    let counts: Vec<u32> = fused.iter().map(|f| f.frames).collect();
    assert_eq!(&counts[..4], &[1, 2, 1, 2], "{counts:?}");
    assert_eq!(fused[2].reset_reason, "reset requested");
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_fusion_options_name_their_field_and_defaults_are_reported() {
    let server = TestServer::start().await;
    let frames: Vec<v1::Frame> = scene(33)
        .frames
        .iter()
        .take(2)
        .map(|f| f.frame.clone())
        .collect();
    let bad = v1::FusionOptions {
        cell_size_m: Some(-1.0),
        ..Default::default()
    };
    let items = stream_with(
        &server,
        frames,
        fusing(mode(SegmentationMode::None), bad),
        None,
    )
    .await;
    assert_eq!(items.len(), 2, "every frame is answered");
    for item in &items {
        let FrameOutcome::Error(e) = &item.outcome else {
            panic!("{:?}", item.outcome);
        };
        assert_eq!(e.code, tonic::Code::InvalidArgument);
        assert!(
            e.field_violations
                .iter()
                .any(|v| v.field == "fusion.cell_size_m"),
            "{e:?}"
        );
    }
    let info = server.client().await.info().await.unwrap();
    let defaults = info.default_fusion.expect("default_fusion");
    let configured = landing_server::Config::default().fusion;
    assert_eq!(defaults.cell_size_m, Some(configured.cell_size_m));
    assert_eq!(defaults.max_cells, Some(configured.max_cells));
    assert_eq!(defaults.keep_out_frames, Some(configured.keep_out_frames));
    assert_eq!(defaults.register_scans, Some(configured.register_scans));
    assert_eq!(
        defaults.max_pixel_footprint_m,
        Some(configured.max_pixel_footprint_m)
    );
    server.stop().await;
}

/// A fused stream's frames run the finest input size alone, whose classes their points take
/// (the votes of every frame that sees a cell guard them) and whose obstacles cast their
/// keep-out footprints. On a real frame the finest mask calls more points landable, never
/// fewer, and casts fewer footprints than the lone frame's every size.
#[test]
fn fused_points_take_the_finest_mask_and_keep_out_its_obstacles() {
    use landing_server::segmentation::{self, Judged};

    let server_config = crate::support::server_config();
    if !server_config.segmentation.enabled {
        eprintln!("skipped: no model or ONNX Runtime library");
        return;
    }
    let segmenter = segmentation::Segmenter::load(&server_config.segmentation).unwrap();
    let request = v1::DetectLandingSitesRequest {
        frame: Some(scene(34).frames[2].frame.clone()),
        options: Some(mode(SegmentationMode::Model)),
    };
    let defaults = landing_geometry::Params::default();
    let (frame, options) = convert::request_parts(&request, &defaults).unwrap();
    let camera = frame.image.as_ref().unwrap();
    let rgb = segmentation::decode(camera).unwrap();
    let points: Vec<[f32; 3]> = to_world(&frame.cloud)
        .iter()
        .map(|p| p.map(|v| v as f32))
        .collect();
    let landable = &options.params.landable_classes;
    let classify = |segmenter: &segmentation::Segmenter, judged| {
        let masks = segmenter.segment(&rgb, judged, landable).unwrap();
        masks.classify(camera, camera.pose, &points, landable)
    };
    let guarded = classify(&segmenter, Judged::Alone);
    let finest = classify(&segmenter, Judged::InStream);
    let is_landable = |c: &u8| landable.contains(c);
    for (i, (g, f)) in guarded.classes.iter().zip(&finest.classes).enumerate() {
        assert!(
            !is_landable(g) || is_landable(f),
            "point {i}: guard {g}, finest {f}"
        );
    }
    let count = |c: &[u8]| c.iter().filter(|c| is_landable(c)).count();
    assert!(
        count(&finest.classes) > count(&guarded.classes),
        "the finest mask alone has the higher rooftop recall: {} vs {}",
        count(&finest.classes),
        count(&guarded.classes)
    );
    // The roof the drone approaches: a plane through the lowest tenth of the scan.
    let mut heights: Vec<f64> = points.iter().map(|p| f64::from(p[2])).collect();
    heights.sort_by(f64::total_cmp);
    let roof = [0.0, 0.0, heights[heights.len() / 10]];
    let disks = |c: &segmentation::Classified| {
        c.obstacles
            .on_plane(roof, [0.0, 0.0, 1.0], [-1e4, -1e4, 1e4, 1e4])
    };
    let (alone, one) = (disks(&guarded), disks(&finest));
    assert!(!one.is_empty());
    assert!(
        one.len() < alone.len(),
        "the coarser size adds obstacles: {} vs {}",
        one.len(),
        alone.len()
    );
}

/// A fused stream's safe circles keep clear of what no camera saw finely enough to show small
/// obstacles (`max_pixel_footprint_m`): classified by the true labels, a stream answers sites
/// with the rule off and none under a limit no camera pixel meets, though the map holds the same
/// points.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn places_seen_only_coarsely_get_no_landing_circle() {
    let server = TestServer::start().await;
    let frames: Vec<v1::Frame> = scene(35)
        .frames
        .iter()
        .map(|recorded| {
            let mut f = recorded.frame.clone();
            f.class_image.clone_from(&recorded.labels);
            f
        })
        .collect();
    let mut answers = Vec::new();
    for limit in [0.0, 0.001] {
        let fusion = v1::FusionOptions {
            max_pixel_footprint_m: Some(limit),
            ..Default::default()
        };
        let options = mode(SegmentationMode::ClassImage);
        let items = stream_with(&server, frames.clone(), fusing(options, fusion), None).await;
        let results: Vec<&v1::FrameResult> = items
            .iter()
            .map(|i| i.outcome.result().expect("every frame answered"))
            .collect();
        let sites: usize = results.iter().map(|r| r.sites.len()).sum();
        let points: Vec<u32> = results.iter().map(|r| r.point_count).collect();
        answers.push((sites, points));
    }
    assert!(answers[0].0 > 0, "the rule off: sites");
    assert_eq!(answers[1].0, 0, "no pixel fine enough: no site");
    assert_eq!(answers[0].1, answers[1].1, "the same map points");
    server.stop().await;
}
