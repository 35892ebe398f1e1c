//! Bad input: a clear error naming the field (or, for a message over `server.max_request_bytes`,
//! the limit), and nothing else lost.

use std::time::Duration;

use landing_client::v1::{
    DetectLandingSitesRequest, Frame, PipelineOptions, SegmentationMode, StreamLandingSitesRequest,
};
use landing_client::{
    ClientError, FrameBuilder, FrameOutcome, ImageData, LandingClient, PointCloudBuilder,
    StreamConfig, camera_image, intrinsics_from_fov, pose,
};
use landing_geometry::synthetic::{Scene, SceneParams};
use prost::Message as _;

use crate::support::{TestServer, check_frames, mode, scene, server_config};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_bad_frame_mid_stream_is_refused_by_field_and_the_stream_goes_on() {
    let server = TestServer::start().await;
    let mut frames: Vec<Frame> = scene(31).frames.iter().map(|f| f.frame.clone()).collect();
    frames[2].point_cloud.as_mut().expect("cloud").point_stride = 0;
    let items = check_frames(&server, &frames, mode(SegmentationMode::None)).await;
    let FrameOutcome::Error(e) = &items[2].outcome else {
        panic!("frame 2: {:?}", items[2].outcome)
    };
    assert_eq!(e.code, tonic::Code::InvalidArgument);
    assert!(
        e.fields().contains(&"frame.point_cloud.point_stride"),
        "{e}"
    );
    for i in items.iter().skip(3) {
        assert!(
            matches!(i.outcome, FrameOutcome::Result(_)),
            "frame {} after the bad one",
            i.sequence
        );
    }
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn unary_errors_name_the_field() {
    let server = TestServer::start().await;
    let client = server.client().await;
    let frame = scene(31).frames[0].frame.clone();

    let options = PipelineOptions {
        min_normal_dot: Some(1.5),
        ..Default::default()
    };
    let err = client
        .detect_with(frame.clone(), Some(options))
        .await
        .unwrap_err();
    let ClientError::Status(e) = &err else {
        panic!("{err}")
    };
    assert_eq!(e.code, tonic::Code::InvalidArgument);
    assert!(e.fields().contains(&"options.min_normal_dot"), "{e}");

    let mut no_cloud = frame;
    no_cloud.point_cloud = None;
    let err = client.detect(no_cloud).await.unwrap_err();
    let ClientError::Status(e) = &err else {
        panic!("{err}")
    };
    assert_eq!(e.code, tonic::Code::InvalidArgument);
    assert!(e.fields().contains(&"frame.point_cloud"), "{e}");
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_deadline_that_passes_during_the_computation_is_deadline_exceeded() {
    let server = TestServer::start().await;
    let mut config = server.client_config();
    config.request_timeout = Some(Duration::from_millis(150));
    let client = LandingClient::connect(config).await.expect("connect");
    // A message that arrives well within the deadline (≈ 2.6 MB, a few ms on loopback) but
    // takes about twice the deadline to compute on an idle 2-core box: an 8192×8192 grey PNG
    // (≈ 200 KiB compressed, 192 MiB decoded, ≈ 0.14 s; every image is decoded, whatever the
    // mode) and 200 k points (≈ 0.15 s of geometry). The handler runs, so it, not tonic's own
    // timer (CANCELLED), answers.
    let (width, height) = (8192, 8192);
    let mut png = Vec::new();
    image::RgbImage::from_pixel(width, height, image::Rgb([128, 128, 128]))
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .expect("encode the PNG");
    let scene = Scene::generate(&SceneParams::with_points(100_000), 5);
    let cloud = PointCloudBuilder::new(&scene.points)
        .build()
        .expect("cloud");
    let camera = camera_image(
        ImageData::Png(png),
        pose([0.0, 0.0, 40.0], [1.0, 0.0, 0.0, 0.0]),
        intrinsics_from_fov(width, height, 70.0),
    )
    .expect("camera image");
    let frame = FrameBuilder::new(1, cloud).image(camera).build();
    let outcome = client
        .detect_with(frame, Some(mode(SegmentationMode::None)))
        .await;
    let Err(ClientError::Status(e)) = &outcome else {
        panic!(
            "expected a status, got {:?}",
            outcome.map(|r| r.timings).map_err(|e| e.to_string())
        )
    };
    // Not CANCELLED (tonic's own timers): the service gives up first and says why (and, should
    // the client's timer still fire first, the SDK reports that as DEADLINE_EXCEEDED too).
    assert_eq!(e.code, tonic::Code::DeadlineExceeded, "{e}");
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn class_image_errors_name_the_field() {
    let server = TestServer::start().await;
    let client = server.client().await;
    let recorded = &scene(31).frames[0];
    let labels = recorded.labels.clone().expect("labels");
    let frame = recorded.frame.clone();
    let fields = |err: ClientError| match err {
        ClientError::Status(e) => {
            assert_eq!(e.code, tonic::Code::InvalidArgument, "{e}");
            e.fields().iter().map(|f| f.to_string()).collect::<Vec<_>>()
        }
        other => panic!("{other}"),
    };
    let class_mode = Some(mode(SegmentationMode::ClassImage));

    // Asked for, but not sent.
    let err = client
        .detect_with(frame.clone(), class_mode.clone())
        .await
        .unwrap_err();
    assert_eq!(fields(err), ["frame.class_image"]);

    // A JPEG would change the class numbers.
    let mut jpeg = labels.clone();
    if let Some(landing_client::v1::camera_image::Image::Compressed(c)) = &mut jpeg.image {
        c.format = "jpeg".into();
    }
    let mut f = frame.clone();
    f.class_image = Some(jpeg);
    let err = client.detect_with(f, class_mode.clone()).await.unwrap_err();
    assert_eq!(fields(err), ["frame.class_image.compressed.format"]);

    // A number that is no class, found when the pixels are read.
    let k = labels.calibration.expect("calibration");
    let mut pixels = vec![4u8; (k.width * k.height) as usize];
    pixels[7] = 99;
    let bad = camera_image(
        ImageData::Mono8 {
            width: k.width,
            height: k.height,
            data: pixels,
        },
        labels.pose.expect("pose"),
        k,
    )
    .expect("layout is fine");
    let mut f = frame.clone();
    f.class_image = Some(bad);
    let err = client.detect_with(f, class_mode.clone()).await.unwrap_err();
    let ClientError::Status(e) = &err else {
        panic!("{err}")
    };
    assert_eq!(e.fields(), ["frame.class_image.raw.data"]);
    assert!(e.to_string().contains("99 at pixel (7, 0)"), "{e}");

    // The colour camera image is no class image.
    let mut f = frame;
    f.class_image = f.image.clone();
    let err = client.detect_with(f, class_mode).await.unwrap_err();
    let got = fields(err);
    assert!(
        got == ["frame.class_image.compressed.data"],
        "an RGB PNG is refused by its pixels: {got:?}"
    );
    server.stop().await;
}

/// A server whose `server.max_request_bytes` is twice the size of scene 31's frames (at least
/// the 1 MiB the config allows), and that limit.
async fn small_limit_server() -> (TestServer, u64) {
    let frame = &scene(31).frames[0].frame;
    let limit = (2 * frame.encoded_len() as u64).max(1 << 20);
    let mut config = server_config();
    config.server.max_request_bytes = limit;
    (TestServer::with_config(config).await, limit)
}

/// `frame` with its `drone_id` padded so that `request(frame)` encodes to exactly `len` bytes.
fn padded_to<M: prost::Message>(frame: &Frame, len: usize, request: impl Fn(Frame) -> M) -> Frame {
    let mut padded = frame.clone();
    for _ in 0..8 {
        let n = request(padded.clone()).encoded_len();
        if n == len {
            return padded;
        }
        // Length prefixes grow and shrink with the padding, so this may take a few rounds.
        let pad = (padded.drone_id.len() + len)
            .checked_sub(n)
            .expect("room to pad");
        padded.drone_id = "p".repeat(pad);
    }
    panic!("cannot pad to {len} bytes")
}

fn too_large_message(bytes: usize, limit: u64) -> String {
    format!("request of {bytes} bytes exceeds server.max_request_bytes = {limit}")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_unary_request_over_max_request_bytes_is_resource_exhausted_naming_the_limit() {
    let (server, limit) = small_limit_server().await;
    let client = server.client().await;
    let frame = scene(31).frames[0].frame.clone();
    let unary = |frame| DetectLandingSitesRequest {
        frame: Some(frame),
        options: None,
    };

    // One byte over: refused before it is read, whatever is in it.
    let over = limit as usize + 1;
    let err = client
        .detect(padded_to(&frame, over, unary))
        .await
        .unwrap_err();
    let ClientError::Status(e) = &err else {
        panic!("{err}")
    };
    assert_eq!(e.code, tonic::Code::ResourceExhausted, "{e}");
    assert_eq!(e.message, too_large_message(over, limit));
    assert!(
        e.retry_delay.is_none(),
        "a retry would be refused the same way: {e}"
    );

    // At the limit: read and validated (its padded drone_id is too long).
    let err = client
        .detect(padded_to(&frame, limit as usize, unary))
        .await
        .unwrap_err();
    let ClientError::Status(e) = &err else {
        panic!("{err}")
    };
    assert_eq!(e.code, tonic::Code::InvalidArgument, "{e}");
    assert!(e.fields().contains(&"frame.drone_id"), "{e}");

    // The connection still serves normal frames.
    client.detect(frame).await.expect("a frame under the limit");
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stream_message_over_max_request_bytes_ends_the_stream_with_resource_exhausted() {
    let (server, limit) = small_limit_server().await;
    let client = server.client().await;
    let frames: Vec<Frame> = scene(31).frames.iter().map(|f| f.frame.clone()).collect();
    let options = mode(SegmentationMode::None);
    // How the SDK sends every frame after the first.
    let later = |frame| StreamLandingSitesRequest {
        frame: Some(frame),
        options: Some(options.clone()),
        ..Default::default()
    };
    let over = limit as usize + 1;
    let big = padded_to(&frames[2], over, later);
    let (mut tx, mut rx) = client.open_stream(StreamConfig {
        options: Some(options.clone()),
        max_in_flight: 4,
        ..StreamConfig::single_frame()
    });
    for frame in [frames[0].clone(), frames[1].clone(), big] {
        // The server may end the stream before the big frame is handed over.
        if tx.send(frame).await.is_err() {
            break;
        }
    }
    tx.finish();
    let mut answered = Vec::new();
    let broken = loop {
        match rx.next().await.expect("the stream ends with an error") {
            Ok(item) => answered.push(item),
            Err(e) => break e,
        }
    };
    assert!(rx.next().await.is_none());
    // The frames before the big one are answered, in order, then the stream ends.
    let sequences: Vec<u64> = answered.iter().map(|i| i.sequence).collect();
    assert_eq!(sequences, [frames[0].sequence, frames[1].sequence]);
    for item in &answered {
        assert!(matches!(item.outcome, FrameOutcome::Result(_)), "{item:?}");
    }
    let ClientError::StreamBroken {
        unanswered,
        status: Some(e),
    } = &broken
    else {
        panic!("{broken}")
    };
    assert_eq!(unanswered, &[frames[2].sequence]);
    assert_eq!(e.code, tonic::Code::ResourceExhausted, "{e}");
    assert_eq!(e.message, too_large_message(over, limit));
    server.stop().await;
}
