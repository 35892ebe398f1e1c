//! The service's overhead against the in-process pipeline on the same frames.
//!
//! `in_process`: `run_pipeline` on an already converted frame (the baseline).
//! `unary_loopback`: one `DetectLandingSites` call over loopback gRPC (encode, HTTP/2, decode,
//! validation, conversion, dispatch to the worker pool, result conversion).
//! `stream_loopback`: 16 frames through one `StreamLandingSites` call, per-batch time.
//! The server runs one geometry worker so that per-frame times compare like with like.
//!
//! Frames: synthetic geometry-only clouds (1.5 k and 20 k points, point classes), the last sample
//! recording frame with point classes, and — when ONNX Runtime is installed (`.ort/` or
//! `ORT_DYLIB_PATH`) — the same frame with `SEGMENTATION_MODE_MODEL`, the service's real
//! workload (decode, segmentation, classification, keep-out, geometry).
//!
//! Run: `cargo bench -p landing-server --bench overhead`.

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use landing_geometry::synthetic::{Scene, SceneParams};
use landing_proto::v1;
use landing_proto::v1::landing_service_client::LandingServiceClient;
use landing_server::pipeline::Pipeline;
use landing_server::{Config, convert, run_pipeline, start};

fn frames() -> Vec<(&'static str, v1::Frame, v1::SegmentationMode)> {
    let synthetic = |points: usize, seed: u64| {
        let scene = Scene::generate(&SceneParams::with_points(points), seed);
        let flat: Vec<f32> = scene.points.iter().flatten().copied().collect();
        v1::Frame {
            sequence: seed,
            point_cloud: Some(convert::packed_cloud(&flat, Some(&scene.classes))),
            ..Default::default()
        }
    };
    let sample =
        std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../samples/rooftops.mcap");
    let mut recorded =
        landing_sim::recording::read_recording(&sample).expect("samples/rooftops.mcap");
    let mut frame = recorded.swap_remove(recorded.len() - 1).frame;
    frame.sequence = 99;
    let point_classes = v1::SegmentationMode::PointClasses;
    let mut frames = vec![
        ("synthetic_1500", synthetic(1500, 1), point_classes),
        ("synthetic_20000", synthetic(20_000, 2), point_classes),
        ("recorded_frame", frame.clone(), point_classes),
    ];
    if model_files().is_some() {
        frames.push(("recorded_frame_model", frame, v1::SegmentationMode::Model));
    }
    frames
}

/// The shipped model and the ONNX Runtime library, when both are installed (found as the
/// server finds them).
fn model_files() -> Option<(std::path::PathBuf, std::path::PathBuf)> {
    let model = landing_perception::workspace_root().join(landing_perception::DEFAULT_MODEL_PATH);
    let ort = landing_perception::resolve_ort_library(None).ok()?;
    model.is_file().then_some((model, ort))
}

fn options(mode: v1::SegmentationMode) -> v1::PipelineOptions {
    v1::PipelineOptions {
        segmentation_mode: mode as i32,
        ..Default::default()
    }
}

fn bench(c: &mut Criterion) {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let mut config = Config::default();
    match model_files() {
        Some((model, ort)) => {
            config.segmentation.model_path = model;
            config.segmentation.ort_library = ort;
        }
        None => config.segmentation.enabled = false,
    }
    config.server.metrics_listen = String::new();
    config.pipeline.geometry_workers = 1;
    config.pipeline.stream_buffer = 16;
    let (server, channel) = runtime.block_on(async {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let server = start(config.clone(), listener).await.unwrap();
        let channel = tonic::transport::Channel::from_shared(format!("http://{}", server.addr))
            .unwrap()
            .connect()
            .await
            .unwrap();
        (server, channel)
    });
    let client = LandingServiceClient::new(channel).max_decoding_message_size(64 << 20);
    // In process: the same pipeline as the server's, the same model loaded once more.
    let mut pipeline = Pipeline::default();
    if config.segmentation.enabled {
        let segmenter = landing_server::segmentation::Segmenter::load(&config.segmentation)
            .expect("load the model");
        pipeline.segmenter = Some(std::sync::Arc::new(segmenter));
    }

    let mut group = c.benchmark_group("overhead");
    for (name, frame, mode) in frames() {
        let request = v1::DetectLandingSitesRequest {
            frame: Some(frame.clone()),
            options: Some(options(mode)),
        };
        let (f, o) = convert::request_parts(&request, &pipeline.defaults).unwrap();
        group.throughput(Throughput::Elements(1));
        group.bench_with_input(BenchmarkId::new("in_process", name), &(), |b, ()| {
            b.iter(|| black_box(run_pipeline(&f, &o, &pipeline).unwrap()))
        });
        group.bench_with_input(
            BenchmarkId::new("in_process_with_conversion", name),
            &(),
            |b, ()| {
                b.iter(|| {
                    let (f, o) = convert::request_parts(&request, &pipeline.defaults).unwrap();
                    black_box(v1::FrameResult::from(
                        &run_pipeline(&f, &o, &pipeline).unwrap(),
                    ))
                })
            },
        );
        group.bench_with_input(BenchmarkId::new("unary_loopback", name), &(), |b, ()| {
            b.iter(|| {
                let mut client = client.clone();
                runtime.block_on(async {
                    black_box(client.detect_landing_sites(request.clone()).await.unwrap())
                })
            })
        });
        let batch: Vec<v1::StreamLandingSitesRequest> = (0..16)
            .map(|i| {
                let mut f = frame.clone();
                f.sequence = i;
                v1::StreamLandingSitesRequest {
                    frame: Some(f),
                    options: Some(options(mode)),
                    overflow_policy: v1::OverflowPolicy::Block as i32,
                }
            })
            .collect();
        group.throughput(Throughput::Elements(16));
        group.bench_with_input(
            BenchmarkId::new("stream_loopback_16", name),
            &(),
            |b, ()| {
                b.iter(|| {
                    let mut client = client.clone();
                    runtime.block_on(async {
                        let mut responses = client
                            .stream_landing_sites(tokio_stream::iter(batch.clone()))
                            .await
                            .unwrap()
                            .into_inner();
                        let mut n = 0;
                        while let Some(r) = responses.message().await.unwrap() {
                            assert!(matches!(
                                r.outcome,
                                Some(v1::stream_landing_sites_response::Outcome::Result(_))
                            ));
                            n += 1;
                        }
                        assert_eq!(n, 16);
                    })
                })
            },
        );
        group.bench_with_input(BenchmarkId::new("in_process_16", name), &(), |b, ()| {
            b.iter(|| {
                for _ in 0..16 {
                    black_box(run_pipeline(&f, &o, &pipeline).unwrap());
                }
            })
        });
    }
    group.finish();
    runtime.block_on(server.shutdown()).unwrap();
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(30).measurement_time(std::time::Duration::from_secs(4));
    targets = bench
}
criterion_main!(benches);
