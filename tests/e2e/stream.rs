//! Streams: results equal the in-process pipeline's, one per frame, in order; LATEST skips;
//! the client's window bounds frames in flight; `StreamConfig::fused()` fuses, and only it.

use landing_client::v1::{OverflowPolicy, SegmentationMode};
use landing_client::{FrameOutcome, StreamConfig};

use crate::support::{TestServer, check, mode, scene, stream_with};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stream_equals_in_process_pipeline_geometry_only() {
    let server = TestServer::start().await;
    let items = check(&server, 21, mode(SegmentationMode::None)).await;
    assert!(
        items
            .iter()
            .all(|i| matches!(i.outcome, FrameOutcome::Result(_)))
    );
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stream_equals_in_process_pipeline_with_true_classes() {
    let server = TestServer::start().await;
    let items = check(&server, 22, mode(SegmentationMode::PointClasses)).await;
    let sites: usize = items
        .iter()
        .filter_map(|i| i.outcome.result())
        .map(|r| r.sites.len())
        .sum();
    assert!(sites > 0, "an approach to a roof finds landing sites");
    server.stop().await;
}

/// With the model installed this compares the model's classes end to end; without it, both the
/// service and the in-process pipeline refuse MODEL frames with the same code.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stream_equals_in_process_pipeline_with_the_model() {
    let server = TestServer::start().await;
    check(&server, 23, mode(SegmentationMode::Model)).await;
    server.stop().await;
}

/// Fusion is asked for in one line and is then done: every answer of a `fused()` stream comes
/// from the map of the frames so far; a `single_frame()` stream's answers carry no map.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_fused_config_fuses_every_frame_and_a_single_frame_config_none() {
    let server = TestServer::start().await;
    let frames: Vec<_> = scene(31)
        .frames
        .iter()
        .take(3)
        .map(|f| f.frame.clone())
        .collect();
    let options = mode(SegmentationMode::None);
    let fused = stream_with(
        &server,
        frames.clone(),
        StreamConfig::fused().with_options(options.clone()),
        None,
    )
    .await;
    let fused_frames: Vec<u32> = fused
        .iter()
        .map(|i| {
            let r = i.outcome.result().expect("every frame answered");
            r.fusion.as_ref().expect("a fused answer").frames
        })
        .collect();
    assert_eq!(fused_frames, [1, 2, 3]);
    let alone = stream_with(
        &server,
        frames,
        StreamConfig::single_frame().with_options(options),
        None,
    )
    .await;
    assert_eq!(alone.len(), 3);
    for item in &alone {
        let r = item.outcome.result().expect("every frame answered");
        assert!(r.fusion.is_none(), "{:?}", r.fusion);
    }
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn latest_policy_answers_every_frame_exactly_once() {
    let server = TestServer::start().await;
    let client = server.client().await;
    let frames: Vec<_> = scene(24).frames.iter().map(|f| f.frame.clone()).collect();
    let n = frames.len();
    let (mut tx, mut rx) = client.open_stream(StreamConfig {
        overflow_policy: OverflowPolicy::Latest,
        options: Some(mode(SegmentationMode::None)),
        max_in_flight: n,
        ..StreamConfig::single_frame()
    });
    for f in frames {
        tx.send(f).await.expect("send");
    }
    tx.finish();
    let mut seen = Vec::new();
    while let Some(item) = rx.next().await {
        let item = item.expect("answer");
        if let FrameOutcome::Skipped { superseded_by } = item.outcome {
            assert!(
                superseded_by > item.sequence,
                "skipped {} for older {superseded_by}",
                item.sequence
            );
        }
        seen.push(item);
    }
    let seqs: Vec<u64> = seen.iter().map(|i| i.sequence).collect();
    assert_eq!(
        seqs,
        (0..n as u64).collect::<Vec<_>>(),
        "every frame once, in order"
    );
    assert!(
        matches!(
            seen.last().map(|i| &i.outcome),
            Some(FrameOutcome::Result(_))
        ),
        "the newest frame is processed"
    );
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_client_window_bounds_frames_in_flight() {
    let server = TestServer::start().await;
    let client = server.client().await;
    let frames: Vec<_> = scene(21).frames.iter().map(|f| f.frame.clone()).collect();
    let n = frames.len();
    let (mut tx, mut rx) = client.open_stream(StreamConfig {
        options: Some(mode(SegmentationMode::None)),
        max_in_flight: 2,
        ..StreamConfig::single_frame()
    });
    let sender = tokio::spawn(async move {
        let mut most = 0;
        for f in frames {
            tx.send(f).await.expect("send");
            most = most.max(tx.in_flight());
        }
        most
    });
    let mut answered = 0;
    while let Some(item) = rx.next().await {
        item.expect("answer");
        answered += 1;
    }
    let most = sender.await.expect("sender");
    assert!(most <= 2, "{most} frames in flight with a window of 2");
    assert_eq!(answered, n);
    server.stop().await;
}
