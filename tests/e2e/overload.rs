//! Overload: RESOURCE_EXHAUSTED with RetryInfo, no frame unanswered, unary retries succeed.

use std::sync::Arc;
use std::time::Duration;

use landing_cli::loadtest::{LoadTestConfig, run_load_test};
use landing_client::v1::SegmentationMode;
use landing_client::{FrameOutcome, LandingClient, RetryPolicy, StreamConfig};

use crate::support::{TestServer, mode, scene, server_config};

/// One worker and room for one frame: anything more is refused.
async fn tiny_server() -> TestServer {
    let mut config = server_config();
    config.pipeline.geometry_workers = 1;
    config.pipeline.queue_capacity = 1;
    TestServer::with_config(config).await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn overload_is_resource_exhausted_with_retry_info_and_every_frame_answered() {
    let server = tiny_server().await;
    let client = server.client().await;
    let frames: Vec<_> = scene(41).frames.iter().map(|f| f.frame.clone()).collect();
    let n = frames.len();
    let (mut tx, mut rx) = client.open_stream(StreamConfig {
        options: Some(mode(SegmentationMode::None)),
        max_in_flight: n,
        ..StreamConfig::single_frame()
    });
    for f in frames {
        tx.send(f).await.expect("send");
    }
    tx.finish();
    let mut items = Vec::new();
    while let Some(item) = rx.next().await {
        items.push(item.expect("answer"));
    }
    assert_eq!(items.len(), n, "no frame goes unanswered");
    let refused: Vec<_> = items.iter().filter_map(|i| i.outcome.error()).collect();
    assert!(!refused.is_empty(), "{n} frames at once into a queue of 1");
    for e in &refused {
        assert_eq!(e.code, tonic::Code::ResourceExhausted, "{e}");
        assert!(
            e.retry_delay.is_some(),
            "RESOURCE_EXHAUSTED carries RetryInfo: {e}"
        );
    }
    assert!(
        matches!(items[0].outcome, FrameOutcome::Result(_)),
        "the first frame is admitted"
    );
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn concurrent_streams_under_overload_get_exactly_one_answer_per_frame() {
    let server = tiny_server().await;
    let client = server.client().await;
    let frames: Vec<_> = scene(41).frames.iter().map(|f| f.frame.clone()).collect();
    let config = LoadTestConfig {
        streams: 4,
        rate_hz: None,
        duration: Duration::from_secs(3),
        stream: StreamConfig {
            options: Some(mode(SegmentationMode::None)),
            max_in_flight: 3,
            ..StreamConfig::single_frame()
        },
    };
    let report = run_load_test(&client, Arc::new(frames), &config, None)
        .await
        .expect("load test");
    assert!(report.exactly_once(), "{report:?}");
    assert!(
        report.sent > 0 && report.outcomes.get("ok").copied().unwrap_or(0) > 0,
        "{report:?}"
    );
    assert!(
        report
            .outcomes
            .get("resource_exhausted")
            .copied()
            .unwrap_or(0)
            > 0,
        "{report:?}"
    );
    assert_eq!(
        report.failed(),
        report.outcomes["resource_exhausted"],
        "only overload refusals: {report:?}"
    );
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn unary_calls_retry_through_overload() {
    let server = tiny_server().await;
    let mut config = server.client_config();
    config.retry = RetryPolicy {
        max_attempts: 40,
        ..RetryPolicy::default()
    };
    let client = LandingClient::connect(config).await.expect("connect");
    let frame = scene(41).frames[0].frame.clone();
    let calls: Vec<_> = (0..4)
        .map(|_| {
            let (client, frame) = (client.clone(), frame.clone());
            tokio::spawn(async move {
                client
                    .detect_with(frame, Some(mode(SegmentationMode::None)))
                    .await
            })
        })
        .collect();
    for c in calls {
        c.await
            .expect("task")
            .expect("every call succeeds after backing off");
    }
    server.stop().await;
}
