//! The real server over loopback gRPC: streams with a bad frame in the middle, validation details,
//! world/geodetic results, auth, health, reflection, metrics, overflow policies, admission,
//! deadlines and graceful shutdown. Results are compared with the in-process pipeline.

use std::time::Duration;

use landing_geometry::synthetic::{Scene, SceneParams};
use landing_proto::google::rpc;
use landing_proto::v1;
use landing_proto::v1::landing_service_client::LandingServiceClient;
use landing_server::pipeline::Pipeline;
use landing_server::status::{BAD_REQUEST_TYPE_URL, RETRY_INFO_TYPE_URL};
use landing_server::{Config, RunningServer, convert, run_pipeline, start};
use prost::Message as _;
use tokio_stream::wrappers::ReceiverStream;
use tonic::transport::Channel;
use tonic_types::StatusExt as _;
use v1::stream_landing_sites_response::Outcome;

fn config() -> Config {
    let mut c = Config::default();
    c.server.listen = "127.0.0.1:0".into();
    c.server.metrics_listen = "127.0.0.1:0".into();
    c.server.shutdown_grace_s = 5.0;
    c.segmentation.enabled = false;
    c.catalog.enabled = false;
    c
}

async fn start_with(config: Config) -> (RunningServer, Channel) {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let server = start(config, listener).await.unwrap();
    let channel = Channel::from_shared(format!("http://{}", server.addr))
        .unwrap()
        .connect()
        .await
        .unwrap();
    (server, channel)
}

fn client(channel: &Channel) -> LandingServiceClient<Channel> {
    LandingServiceClient::new(channel.clone()).max_decoding_message_size(64 << 20)
}

/// A generated roof as a frame with classes, numbered `sequence`.
fn scene_frame(params: &SceneParams, seed: u64, sequence: u64) -> v1::Frame {
    let scene = Scene::generate(params, seed);
    let flat: Vec<f32> = scene.points.iter().flatten().copied().collect();
    v1::Frame {
        drone_id: "drone-7".into(),
        sequence,
        point_cloud: Some(convert::packed_cloud(&flat, Some(&scene.classes))),
        ..Default::default()
    }
}

fn frame(seed: u64, sequence: u64) -> v1::Frame {
    scene_frame(&SceneParams::default(), seed, sequence)
}

/// What the in-process pipeline answers for `frame`.
fn in_process(frame: &v1::Frame) -> v1::FrameResult {
    let pipeline = Pipeline::default();
    let request = v1::DetectLandingSitesRequest {
        frame: Some(frame.clone()),
        options: None,
    };
    let (frame, options) = convert::request_parts(&request, &pipeline.defaults).unwrap();
    v1::FrameResult::from(&run_pipeline(&frame, &options, &pipeline).unwrap())
}

fn stream_request(frame: v1::Frame, policy: v1::OverflowPolicy) -> v1::StreamLandingSitesRequest {
    v1::StreamLandingSitesRequest {
        frame: Some(frame),
        options: None,
        overflow_policy: policy as i32,
        single_frame: true,
        ..Default::default()
    }
}

fn bad_request_fields(status: &rpc::Status) -> Vec<String> {
    let any = status
        .details
        .iter()
        .find(|d| d.type_url == BAD_REQUEST_TYPE_URL)
        .expect("BadRequest detail");
    rpc::BadRequest::decode(any.value.as_slice())
        .unwrap()
        .field_violations
        .into_iter()
        .map(|v| v.field)
        .collect()
}

/// Streams `requests` and collects every response.
async fn stream_all(
    channel: &Channel,
    requests: Vec<v1::StreamLandingSitesRequest>,
) -> Vec<v1::StreamLandingSitesResponse> {
    let responses = client(channel)
        .stream_landing_sites(tokio_stream::iter(requests))
        .await
        .unwrap()
        .into_inner();
    let mut out = Vec::new();
    let mut responses = responses;
    while let Some(r) = responses.message().await.unwrap() {
        out.push(r);
    }
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stream_with_a_bad_frame_in_the_middle_goes_on() {
    let (server, channel) = start_with(config()).await;
    let frames: Vec<v1::Frame> = (1..=5).map(|i| frame(i, i * 10)).collect();
    let mut requests: Vec<_> = frames
        .iter()
        .cloned()
        .map(|f| stream_request(f, v1::OverflowPolicy::Block))
        .collect();
    // Frame 3: a NaN coordinate in the first point.
    let bad = requests[2]
        .frame
        .as_mut()
        .unwrap()
        .point_cloud
        .as_mut()
        .unwrap();
    let mut data = bad.data.to_vec();
    data[0..4].copy_from_slice(&f32::NAN.to_le_bytes());
    bad.data = data.into();

    let responses = stream_all(&channel, requests).await;
    let sequences: Vec<u64> = responses.iter().map(|r| r.sequence).collect();
    assert_eq!(sequences, vec![10, 20, 30, 40, 50]);
    for (i, response) in responses.iter().enumerate() {
        match response.outcome.as_ref().unwrap() {
            Outcome::Error(status) => {
                assert_eq!(i, 2, "only frame 3 is bad: {status:?}");
                assert_eq!(status.code, tonic::Code::InvalidArgument as i32);
                assert_eq!(bad_request_fields(status), vec!["frame.point_cloud.data"]);
                assert!(status.message.contains("point 0"), "{}", status.message);
            }
            Outcome::Result(result) => {
                assert_ne!(i, 2);
                let expected = in_process(&frames[i]);
                assert!(!result.sites.is_empty());
                assert_eq!(
                    result.sites, expected.sites,
                    "frame {i} differs from the in-process pipeline"
                );
                assert_eq!(result.drone_id, "drone-7");
                assert_eq!(
                    result.segmentation_mode,
                    v1::SegmentationMode::PointClasses as i32
                );
                let t = result.timings.as_ref().unwrap();
                assert!(t.queue.is_some() && t.triangulation.is_some() && t.total.is_some());
            }
            Outcome::Skipped(s) => panic!("BLOCK never skips: {s:?}"),
        }
    }
    server.shutdown().await.unwrap();
}

/// Streams fuse unless their first message asks for `single_frame`; asking for both is refused
/// on every frame, naming `fusion`.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn streams_fuse_unless_the_first_message_asks_for_single_frames() {
    let (server, channel) = start_with(config()).await;
    let requests = |single_frame: bool, fusion: Option<v1::FusionOptions>| -> Vec<_> {
        (1..=3)
            .map(|i| v1::StreamLandingSitesRequest {
                single_frame: single_frame && i == 1,
                fusion: fusion.filter(|_| i == 1),
                ..stream_request(frame(7, i), v1::OverflowPolicy::Block)
            })
            .collect()
    };
    let results = |responses: Vec<v1::StreamLandingSitesResponse>| -> Vec<v1::FrameResult> {
        assert_eq!(responses.len(), 3, "one answer per frame");
        responses
            .into_iter()
            .map(|r| match r.outcome {
                Some(Outcome::Result(result)) => result,
                other => panic!("{other:?}"),
            })
            .collect()
    };

    let fused = results(stream_all(&channel, requests(false, None)).await);
    let frames: Vec<u32> = fused
        .iter()
        .map(|r| r.fusion.as_ref().unwrap().frames)
        .collect();
    assert_eq!(
        frames,
        vec![1, 2, 3],
        "a stream with no fusion options is fused"
    );
    let single = results(stream_all(&channel, requests(true, None)).await);
    assert!(single.iter().all(|r| r.fusion.is_none()));
    assert_eq!(single[0].sites, in_process(&frame(7, 1)).sites);

    let both = stream_all(&channel, requests(true, Some(v1::FusionOptions::default()))).await;
    assert_eq!(both.len(), 3, "every frame is answered");
    for response in &both {
        let Some(Outcome::Error(status)) = &response.outcome else {
            panic!("{response:?}");
        };
        assert_eq!(status.code, tonic::Code::InvalidArgument as i32);
        assert_eq!(bad_request_fields(status), vec!["fusion"]);
    }
    server.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn unary_results_are_in_world_and_geodetic_coordinates() {
    let (server, channel) = start_with(config()).await;
    let mut f = frame(3, 1);
    // The LiDAR sits 100 m east and 200 m north of the world origin, turned 90° about z.
    let h = std::f64::consts::FRAC_1_SQRT_2;
    f.point_cloud.as_mut().unwrap().pose = Some(v1::Pose {
        position: Some(v1::Vector3 {
            x: 100.0,
            y: 200.0,
            z: 0.0,
        }),
        orientation: Some(v1::Quaternion {
            x: 0.0,
            y: 0.0,
            z: h,
            w: h,
        }),
    });
    f.geodetic_origin = Some(v1::GeodeticPoint {
        latitude_deg: 40.7128,
        longitude_deg: -74.006,
        altitude_m: 10.0,
    });
    let result = client(&channel)
        .detect_landing_sites(v1::DetectLandingSitesRequest {
            frame: Some(f),
            options: None,
        })
        .await
        .unwrap()
        .into_inner()
        .result
        .unwrap();
    let best = &result.sites[0];
    let c = best.center.as_ref().unwrap();
    // Roof x in [0, 20] maps to world y in [200, 220]; roof y in [0, 20] to world x in [80, 100].
    assert!(
        (80.0..=100.0).contains(&c.x) && (200.0..=220.0).contains(&c.y),
        "{c:?}"
    );
    assert!((c.z - 10.0).abs() < 0.2, "{c:?}");
    let g = best.center_geodetic.as_ref().unwrap();
    // ~200 m north and ~90 m east of the origin.
    assert!((g.latitude_deg - 40.7128 - 0.0019).abs() < 0.0003, "{g:?}");
    assert!((g.longitude_deg + 74.006 - 0.00107).abs() < 0.0003, "{g:?}");
    let shell = &best
        .polygon
        .as_ref()
        .unwrap()
        .shell
        .as_ref()
        .unwrap()
        .points;
    assert!(
        shell
            .iter()
            .all(|p| (79.0..=101.0).contains(&p.x) && (199.0..=221.0).contains(&p.y))
    );
    server.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn unary_validation_names_every_bad_field() {
    let (server, channel) = start_with(config()).await;
    let mut f = frame(1, 1);
    f.point_cloud.as_mut().unwrap().point_stride = 11;
    let options = v1::PipelineOptions {
        min_normal_dot: Some(2.0),
        ..Default::default()
    };
    let status = client(&channel)
        .detect_landing_sites(v1::DetectLandingSitesRequest {
            frame: Some(f),
            options: Some(options),
        })
        .await
        .unwrap_err();
    assert_eq!(status.code(), tonic::Code::InvalidArgument);
    let details = status.get_error_details();
    let fields: Vec<&str> = details
        .bad_request()
        .unwrap()
        .field_violations
        .iter()
        .map(|v| v.field.as_str())
        .collect();
    assert!(fields.contains(&"options.min_normal_dot"), "{fields:?}");
    assert!(
        fields.iter().any(|f| f.starts_with("frame.point_cloud.")),
        "{fields:?}"
    );

    // MODEL mode on a server without a model.
    let options = v1::PipelineOptions {
        segmentation_mode: v1::SegmentationMode::Model as i32,
        ..Default::default()
    };
    let status = client(&channel)
        .detect_landing_sites(v1::DetectLandingSitesRequest {
            frame: Some(frame(1, 1)),
            options: Some(options),
        })
        .await
        .unwrap_err();
    assert_eq!(status.code(), tonic::Code::InvalidArgument, "{status:?}");
    assert_eq!(
        status
            .get_error_details()
            .bad_request()
            .unwrap()
            .field_violations[0]
            .field,
        "frame.image"
    );
    server.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn frames_larger_than_four_mebibytes_are_accepted() {
    let (server, channel) = start_with(config()).await;
    let mut f = frame(2, 1);
    // Pad every point to 4 KiB: 1.5 k points make a ~6 MiB message.
    let pc = f.point_cloud.as_mut().unwrap();
    let stride = pc.point_stride as usize;
    let padded: Vec<u8> = pc
        .data
        .chunks_exact(stride)
        .flat_map(|p| {
            p.iter()
                .copied()
                .chain(std::iter::repeat_n(0u8, 4096 - stride))
        })
        .collect();
    pc.data = padded.into();
    pc.point_stride = 4096;
    assert!(f.encoded_len() > 4 << 20);
    let result = client(&channel)
        .detect_landing_sites(v1::DetectLandingSitesRequest {
            frame: Some(f),
            options: None,
        })
        .await
        .unwrap()
        .into_inner();
    assert!(!result.result.unwrap().sites.is_empty());
    server.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn health_reflection_service_info_and_metrics() {
    let (server, channel) = start_with(config()).await;
    let mut health = tonic_health::pb::health_client::HealthClient::new(channel.clone());
    let serving = health
        .check(tonic_health::pb::HealthCheckRequest {
            service: "landing.v1.LandingService".into(),
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(
        serving.status,
        tonic_health::pb::health_check_response::ServingStatus::Serving as i32
    );

    use tonic_reflection::pb::v1::server_reflection_client::ServerReflectionClient;
    use tonic_reflection::pb::v1::server_reflection_request::MessageRequest;
    use tonic_reflection::pb::v1::server_reflection_response::MessageResponse;
    let request = tonic_reflection::pb::v1::ServerReflectionRequest {
        host: String::new(),
        message_request: Some(MessageRequest::ListServices(String::new())),
    };
    let mut replies = ServerReflectionClient::new(channel.clone())
        .server_reflection_info(tokio_stream::iter(vec![request]))
        .await
        .unwrap()
        .into_inner();
    let reply = replies.message().await.unwrap().unwrap();
    let Some(MessageResponse::ListServicesResponse(list)) = reply.message_response else {
        panic!("{reply:?}")
    };
    let names: Vec<String> = list.service.into_iter().map(|s| s.name).collect();
    assert!(
        names.contains(&"landing.v1.LandingService".to_owned()),
        "{names:?}"
    );

    let info = client(&channel)
        .get_service_info(v1::GetServiceInfoRequest {})
        .await
        .unwrap()
        .into_inner();
    assert_eq!(info.classes.len(), 15);
    assert_eq!(info.classes[4].name, "building rooftop");
    assert_eq!(info.default_options.unwrap().max_triangle_edge_m, Some(4.0));
    assert_eq!(info.max_request_bytes, 64 << 20);
    assert!(info.model.is_none());

    client(&channel)
        .detect_landing_sites(v1::DetectLandingSitesRequest {
            frame: Some(frame(1, 1)),
            options: None,
        })
        .await
        .unwrap();
    let text = landing_server::telemetry::scrape(server.metrics_addr.unwrap())
        .await
        .unwrap();
    assert!(
        text.contains("landing_frames_total{rpc=\"unary\",outcome=\"ok\"} 1"),
        "{text}"
    );
    assert!(
        text.contains("landing_stage_seconds_bucket{stage=\"triangulation\""),
        "{text}"
    );
    assert!(text.contains("landing_queue_depth"), "{text}");
    server.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bearer_tokens_guard_everything_but_health() {
    let dir = std::env::temp_dir().join(format!("landing-auth-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let tokens = dir.join("tokens");
    std::fs::write(&tokens, "# fleet tokens\ns3cret\n").unwrap();
    let mut c = config();
    c.auth.tokens_file = tokens;
    let (server, channel) = start_with(c).await;

    let status = client(&channel)
        .get_service_info(v1::GetServiceInfoRequest {})
        .await
        .unwrap_err();
    assert_eq!(status.code(), tonic::Code::Unauthenticated);
    let mut wrong = tonic::Request::new(v1::GetServiceInfoRequest {});
    wrong
        .metadata_mut()
        .insert("authorization", "Bearer nope".parse().unwrap());
    assert_eq!(
        client(&channel)
            .get_service_info(wrong)
            .await
            .unwrap_err()
            .code(),
        tonic::Code::Unauthenticated
    );
    let mut right = tonic::Request::new(v1::GetServiceInfoRequest {});
    right
        .metadata_mut()
        .insert("authorization", "Bearer s3cret".parse().unwrap());
    client(&channel).get_service_info(right).await.unwrap();

    let mut health = tonic_health::pb::health_client::HealthClient::new(channel.clone());
    health
        .check(tonic_health::pb::HealthCheckRequest {
            service: String::new(),
        })
        .await
        .unwrap();
    server.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn latest_policy_skips_stale_frames_and_answers_every_one() {
    let mut c = config();
    c.pipeline.geometry_workers = 1;
    c.pipeline.stream_buffer = 16;
    let (server, channel) = start_with(c).await;
    // Big frames so that they queue up behind the single worker.
    let params = SceneParams::with_points(40_000);
    let frames: Vec<_> = (1..=6).map(|i| scene_frame(&params, i, i)).collect();
    let requests = frames
        .into_iter()
        .map(|f| stream_request(f, v1::OverflowPolicy::Latest))
        .collect();
    let responses = stream_all(&channel, requests).await;
    assert_eq!(
        responses.iter().map(|r| r.sequence).collect::<Vec<_>>(),
        vec![1, 2, 3, 4, 5, 6]
    );
    let skipped: Vec<_> = responses
        .iter()
        .filter_map(|r| match r.outcome.as_ref().unwrap() {
            Outcome::Skipped(s) => Some((r.sequence, s.superseded_by_sequence)),
            _ => None,
        })
        .collect();
    assert!(!skipped.is_empty(), "nothing skipped: {responses:?}");
    assert!(skipped.iter().all(|(seq, by)| by > seq), "{skipped:?}");
    // The newest frame is never skipped.
    assert!(matches!(responses[5].outcome, Some(Outcome::Result(_))));
    server.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn beyond_capacity_frames_get_resource_exhausted_with_retry_info() {
    let mut c = config();
    c.pipeline.geometry_workers = 1;
    c.pipeline.queue_capacity = 1;
    c.pipeline.stream_buffer = 8;
    let (server, channel) = start_with(c).await;
    let params = SceneParams::with_points(40_000);
    let requests = (1..=4)
        .map(|i| stream_request(scene_frame(&params, i, i), v1::OverflowPolicy::Block))
        .collect();
    let responses = stream_all(&channel, requests).await;
    assert_eq!(responses.len(), 4, "every frame is answered");
    assert!(matches!(responses[0].outcome, Some(Outcome::Result(_))));
    let exhausted: Vec<_> = responses
        .iter()
        .filter_map(|r| match r.outcome.as_ref().unwrap() {
            Outcome::Error(s) if s.code == tonic::Code::ResourceExhausted as i32 => Some(s),
            _ => None,
        })
        .collect();
    assert!(!exhausted.is_empty(), "{responses:?}");
    for s in exhausted {
        let any = s
            .details
            .iter()
            .find(|d| d.type_url == RETRY_INFO_TYPE_URL)
            .expect("RetryInfo");
        let info = rpc::RetryInfo::decode(any.value.as_slice()).unwrap();
        assert!(info.retry_delay.is_some());
    }
    server.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn frames_past_the_stream_deadline_are_not_computed() {
    let (server, channel) = start_with(config()).await;
    let (tx, rx) = tokio::sync::mpsc::channel(4);
    let mut request = tonic::Request::new(ReceiverStream::new(rx));
    request.set_timeout(Duration::from_millis(100));
    let mut responses = client(&channel)
        .stream_landing_sites(request)
        .await
        .unwrap()
        .into_inner();
    tokio::time::sleep(Duration::from_millis(200)).await;
    tx.send(stream_request(frame(1, 1), v1::OverflowPolicy::Block))
        .await
        .unwrap();
    drop(tx);
    let response = responses.message().await.unwrap().unwrap();
    match response.outcome.unwrap() {
        Outcome::Error(s) => assert_eq!(s.code, tonic::Code::DeadlineExceeded as i32, "{s:?}"),
        other => panic!("expected DEADLINE_EXCEEDED, got {other:?}"),
    }
    server.shutdown().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn shutdown_drains_open_streams_and_stops_serving() {
    let (server, channel) = start_with(config()).await;
    let (tx, rx) = tokio::sync::mpsc::channel(4);
    let mut responses = client(&channel)
        .stream_landing_sites(ReceiverStream::new(rx))
        .await
        .unwrap()
        .into_inner();
    tx.send(stream_request(frame(1, 1), v1::OverflowPolicy::Block))
        .await
        .unwrap();
    let first = responses.message().await.unwrap().unwrap();
    assert!(matches!(first.outcome, Some(Outcome::Result(_))));
    let addr = server.addr;
    // The client keeps its side open; the drain must end the stream by itself.
    let stopped = tokio::time::timeout(Duration::from_secs(4), server.shutdown()).await;
    assert!(
        stopped.is_ok(),
        "shutdown did not finish within the grace period"
    );
    stopped.unwrap().unwrap();
    assert!(
        responses
            .message()
            .await
            .map(|m| m.is_none())
            .unwrap_or(true)
    );
    assert!(
        tokio::net::TcpStream::connect(addr).await.is_err(),
        "still accepting connections"
    );
    drop(tx);
}

fn workspace() -> std::path::PathBuf {
    std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn recorded_frames_with_the_model_match_the_in_process_pipeline() {
    // Needs the ONNX Runtime library (scripts/setup-ort.sh) and the shipped model.
    let mut c = config();
    c.segmentation.enabled = true;
    c.segmentation.model_path = workspace().join("models/rooftop-segmentation.onnx");
    let segmenter = landing_server::segmentation::Segmenter::load(&c.segmentation).unwrap();
    let (server, channel) = start_with(c).await;
    let info = client(&channel)
        .get_service_info(v1::GetServiceInfoRequest {})
        .await
        .unwrap()
        .into_inner();
    let model = info.model.expect("the model is reported");
    assert_eq!(model.sha256.len(), 64);
    assert_eq!(model.execution_provider, "cpu");

    let recorded = landing_recording::read(&workspace().join("samples/rooftops.mcap")).unwrap();
    let frames: Vec<v1::Frame> = recorded.into_iter().take(4).map(|r| r.frame).collect();
    let options = v1::PipelineOptions {
        segmentation_mode: v1::SegmentationMode::Model as i32,
        ..Default::default()
    };
    let requests = frames
        .iter()
        .map(|f| v1::StreamLandingSitesRequest {
            frame: Some(f.clone()),
            options: Some(options.clone()),
            overflow_policy: v1::OverflowPolicy::Block as i32,
            single_frame: true,
            ..Default::default()
        })
        .collect();
    let responses = stream_all(&channel, requests).await;

    let pipeline = Pipeline {
        segmenter: Some(std::sync::Arc::new(segmenter)),
        ..Pipeline::default()
    };
    for (frame, response) in frames.iter().zip(&responses) {
        assert_eq!(response.sequence, frame.sequence);
        let Some(Outcome::Result(result)) = &response.outcome else {
            panic!("{response:?}")
        };
        assert_eq!(result.segmentation_mode, v1::SegmentationMode::Model as i32);
        let t = result.timings.as_ref().unwrap();
        assert!(t.decode.is_some() && t.segmentation.is_some() && t.classification.is_some());
        let request = v1::DetectLandingSitesRequest {
            frame: Some(frame.clone()),
            options: Some(options.clone()),
        };
        let (f, o) = convert::request_parts(&request, &pipeline.defaults).unwrap();
        let expected = v1::FrameResult::from(&run_pipeline(&f, &o, &pipeline).unwrap());
        assert_eq!(result.sites, expected.sites);
        assert_eq!(result.point_count, expected.point_count);
    }

    // An image that does not decode is the caller's error, named.
    let mut broken = frames[0].clone();
    if let Some(v1::camera_image::Image::Compressed(c)) =
        broken.image.as_mut().unwrap().image.as_mut()
    {
        c.data.truncate(40);
    }
    let status = client(&channel)
        .detect_landing_sites(v1::DetectLandingSitesRequest {
            frame: Some(broken),
            options: None,
        })
        .await
        .unwrap_err();
    assert_eq!(status.code(), tonic::Code::InvalidArgument, "{status:?}");
    let details = status.get_error_details();
    assert_eq!(
        details.bad_request().unwrap().field_violations[0].field,
        "frame.image.compressed.data"
    );
    server.shutdown().await.unwrap();
}
