//! The service's overhead against the in-process pipeline on the same frames, measured in
//! interleaved pairs.
//!
//! Each round runs the same frame once in process and once through the service, in an order
//! drawn at random, so that both sides of a pair see the same state of the machine. On a shared
//! virtual machine the pipeline's own time drifts by 30 % and more between runs of a few seconds
//! (the segmentation session most of all); a benchmark that measures one side for seconds and
//! then the other, as criterion's groups do, reports that drift as overhead. The overhead here is
//! the median of the per-pair ratios, with a bootstrap 95 % interval.
//!
//! Per frame:
//! - `in process`: validation and conversion of the request, `run_pipeline`, conversion of the
//!   result — everything the service does except transport and dispatch;
//! - `unary`: one `DetectLandingSites` call over loopback (encode, HTTP/2, decode, the same
//!   conversion, dispatch to the worker pool, the answer back);
//! - `stream`: 16 frames through one `StreamLandingSites` call against 16 in-process runs, per
//!   frame;
//! - `gap`: the unary call's wall time minus the server's own `total` for that frame — what
//!   transport and hand-offs cost, whatever the pipeline's time does.
//!
//! Frames: synthetic geometry-only clouds (1.5 k and 20 k points, point classes), the last sample
//! recording frame with point classes, and — when ONNX Runtime is installed (`.ort/` or
//! `ORT_DYLIB_PATH`) — the same frame with `SEGMENTATION_MODE_MODEL`, the service's real workload
//! (decode, segmentation, classification, keep-out disks, geometry). The server runs one
//! geometry worker and one segmentation session with one thread, as the in-process side does.
//!
//! Run: `cargo bench -p landing-server --bench overhead [-- --seconds S]` (S per frame and
//! measurement, default 8).

use std::hint::black_box;
use std::time::{Duration, Instant};

use landing_eval::stats::{self, SplitMix64};
use landing_geometry::synthetic::{Scene, SceneParams};
use landing_proto::v1;
use landing_proto::v1::landing_service_client::LandingServiceClient;
use landing_server::pipeline::Pipeline;
use landing_server::{Config, convert, run_pipeline, start};
use tonic::transport::Channel;

const STREAM_FRAMES: usize = 16;

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
    let sample = landing_perception::workspace_root().join("samples/rooftops.mcap");
    let mut recorded = landing_recording::read(&sample).expect("samples/rooftops.mcap");
    let mut frame = recorded.swap_remove(recorded.len() - 1).frame;
    frame.sequence = 99;
    let point_classes = v1::SegmentationMode::PointClasses;
    let mut frames = vec![
        (
            "synthetic 1.5 k points, point classes",
            synthetic(1500, 1),
            point_classes,
        ),
        (
            "synthetic 20 k points, point classes",
            synthetic(20_000, 2),
            point_classes,
        ),
        (
            "recorded frame, point classes",
            frame.clone(),
            point_classes,
        ),
    ];
    if model_files().is_some() {
        frames.push((
            "recorded frame, model segmentation",
            frame,
            v1::SegmentationMode::Model,
        ));
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

/// The median of `values` (not empty).
fn median(values: &[f64]) -> f64 {
    stats::median(values).expect("measurements")
}

/// The median of `ratios` and a percentile-bootstrap 95 % interval of it.
fn median_with_interval(ratios: &[f64], seed: u64) -> (f64, f64, f64) {
    let (lo, hi) = stats::bootstrap_ci95(ratios, 2000, seed, median).expect("measurements");
    (median(ratios), lo, hi)
}

/// Interleaved pairs of (in process, service) wall times in seconds, plus what the second
/// closure reports on the side (the unary gap), for `budget` or at least 20 pairs.
fn pairs(
    budget: Duration,
    rng: &mut SplitMix64,
    mut local: impl FnMut(),
    mut remote: impl FnMut() -> f64,
) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let (mut a, mut b, mut side) = (Vec::new(), Vec::new(), Vec::new());
    // Warm both paths (connections, allocator, the sessions' first runs).
    for _ in 0..3 {
        local();
        remote();
    }
    let start = Instant::now();
    while start.elapsed() < budget || a.len() < 20 {
        let local_first = rng.next_u64().is_multiple_of(2);
        let mut time_local = || {
            let t = Instant::now();
            local();
            t.elapsed().as_secs_f64()
        };
        let (la, rb, s);
        if local_first {
            la = time_local();
            let t = Instant::now();
            s = remote();
            rb = t.elapsed().as_secs_f64();
        } else {
            let t = Instant::now();
            s = remote();
            rb = t.elapsed().as_secs_f64();
            la = time_local();
        }
        a.push(la);
        b.push(rb);
        side.push(s);
    }
    (a, b, side)
}

fn seconds(d: &Option<prost_types::Duration>) -> f64 {
    d.as_ref()
        .map_or(0.0, |d| d.seconds as f64 + f64::from(d.nanos) * 1e-9)
}

fn main() {
    let budget = std::env::args()
        .skip_while(|a| a != "--seconds")
        .nth(1)
        .map_or(8.0, |s| s.parse::<f64>().expect("--seconds takes a number"));
    let budget = Duration::from_secs_f64(budget);
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let mut config = Config::default();
    config.catalog.enabled = false;
    match model_files() {
        Some((model, ort)) => {
            config.segmentation.model_path = model;
            config.segmentation.ort_library = ort;
        }
        None => {
            eprintln!("ONNX Runtime or the model is missing: the model frame is left out");
            config.segmentation.enabled = false;
        }
    }
    config.server.metrics_listen = String::new();
    config.pipeline.geometry_workers = 1;
    config.pipeline.stream_buffer = STREAM_FRAMES as u32;
    let (server, channel) = runtime.block_on(async {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let server = start(config.clone(), listener).await.unwrap();
        let channel = Channel::from_shared(format!("http://{}", server.addr))
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
    let mut rng = SplitMix64(2026);

    println!(
        "| frame | in process | unary | unary overhead (95 % CI) | gap | stream, per frame | \
         in process ×{STREAM_FRAMES}, per frame | stream overhead (95 % CI) | pairs |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for (name, frame, mode) in frames() {
        let request = v1::DetectLandingSitesRequest {
            frame: Some(frame.clone()),
            options: Some(options(mode)),
        };
        let in_process = || {
            let (f, o) = convert::request_parts(&request, &pipeline.defaults).unwrap();
            black_box(v1::FrameResult::from(
                &run_pipeline(&f, &o, &pipeline).unwrap(),
            ));
        };
        let unary = || {
            let mut client = client.clone();
            let t = Instant::now();
            let response = runtime
                .block_on(client.detect_landing_sites(request.clone()))
                .unwrap()
                .into_inner();
            let wall = t.elapsed().as_secs_f64();
            let total = response.result.and_then(|r| r.timings).map(|t| t.total);
            wall - seconds(&total.flatten())
        };
        let (a, b, gaps) = pairs(budget, &mut rng, in_process, unary);

        let batch: Vec<v1::StreamLandingSitesRequest> = (0..STREAM_FRAMES as u64)
            .map(|i| v1::StreamLandingSitesRequest {
                frame: Some(v1::Frame {
                    sequence: i,
                    ..frame.clone()
                }),
                options: Some(options(mode)),
                overflow_policy: v1::OverflowPolicy::Block as i32,
                single_frame: true,
                ..Default::default()
            })
            .collect();
        let in_process_batch = || {
            for _ in 0..STREAM_FRAMES {
                in_process();
            }
        };
        let stream = || {
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
                assert_eq!(n, STREAM_FRAMES);
            });
            0.0
        };
        let (c, d, _) = pairs(budget, &mut rng, in_process_batch, stream);

        let ratios = |x: &[f64], y: &[f64]| -> Vec<f64> {
            x.iter().zip(y).map(|(x, y)| y / x - 1.0).collect()
        };
        let (u, u_lo, u_hi) = median_with_interval(&ratios(&a, &b), 1);
        let (s, s_lo, s_hi) = median_with_interval(&ratios(&c, &d), 2);
        let ms = |v: &[f64]| median(v) * 1e3;
        let per_frame = |v: &[f64]| median(v) * 1e3 / STREAM_FRAMES as f64;
        let pct = |x: f64| format!("{:+.1} %", x * 100.0);
        println!(
            "| {name} | {:.2} ms | {:.2} ms | {} ({} … {}) | {:.2} ms | {:.2} ms | {:.2} ms | {} ({} … {}) | {} + {} |",
            ms(&a),
            ms(&b),
            pct(u),
            pct(u_lo),
            pct(u_hi),
            ms(&gaps),
            per_frame(&d),
            per_frame(&c),
            pct(s),
            pct(s_lo),
            pct(s_hi),
            a.len(),
            c.len(),
        );
    }
    runtime.block_on(server.shutdown()).unwrap();
}
