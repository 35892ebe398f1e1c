//! `/metrics` from the start: every metric with its help text and type before any frame, the
//! frame counters at 0 for every call and outcome, and `landing_build_info` naming the version
//! and the model the server reports.

use landing_client::v1::SegmentationMode;
use landing_server::telemetry::scrape;

use crate::support::{TestServer, mode, scene, server_config};

/// Every metric and its Prometheus type.
const METRICS: [(&str, &str); 21] = [
    ("landing_frames_total", "counter"),
    ("landing_frame_seconds", "histogram"),
    ("landing_stage_seconds", "histogram"),
    ("landing_queue_depth", "gauge"),
    ("landing_queue_bytes", "gauge"),
    ("landing_in_flight", "gauge"),
    ("landing_streams_open", "gauge"),
    ("landing_fusion_maps_open", "gauge"),
    ("landing_fusion_map_bytes", "gauge"),
    ("landing_live_view_frames_total", "counter"),
    ("landing_live_view_dropped_total", "counter"),
    ("landing_build_info", "gauge"),
    ("landing_catalog_frames_total", "counter"),
    ("landing_catalog_writes_total", "counter"),
    ("landing_catalog_write_failures_total", "counter"),
    ("landing_catalog_dropped_total", "counter"),
    ("landing_catalog_site_changes_total", "counter"),
    ("landing_catalog_queue_depth", "gauge"),
    ("landing_catalog_sites", "gauge"),
    ("landing_catalog_connected", "gauge"),
    ("landing_catalog_query_seconds", "histogram"),
];
const RPCS: [&str; 2] = ["unary", "stream"];
const OUTCOMES: [&str; 8] = [
    "ok",
    "invalid",
    "overloaded",
    "deadline_exceeded",
    "cancelled",
    "skipped",
    "unavailable",
    "failed",
];

/// The value of the series written exactly as `series` (name and labels), if present.
fn value(text: &str, series: &str) -> Option<f64> {
    text.lines()
        .find_map(|l| l.strip_prefix(series)?.strip_prefix(' '))
        .map(|v| v.trim().parse().expect("a number"))
}

fn frames_total(rpc: &str, outcome: &str) -> String {
    format!("landing_frames_total{{rpc=\"{rpc}\",outcome=\"{outcome}\"}}")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_metric_is_there_before_the_first_frame() {
    let mut config = server_config();
    config.server.metrics_listen = "127.0.0.1:0".into();
    let server = TestServer::with_config(config).await;
    let addr = server.metrics_addr().expect("metrics enabled");
    let before = scrape(addr).await.expect("scrape");

    for (name, kind) in METRICS {
        assert!(
            before
                .lines()
                .any(|l| l.starts_with(&format!("# HELP {name} ")) && l.len() > name.len() + 10),
            "no help text for {name}:\n{before}"
        );
        assert!(
            before.lines().any(|l| l == format!("# TYPE {name} {kind}")),
            "no `# TYPE {name} {kind}`:\n{before}"
        );
    }
    for rpc in RPCS {
        for outcome in OUTCOMES {
            assert_eq!(
                value(&before, &frames_total(rpc, outcome)),
                Some(0.0),
                "{rpc}/{outcome}:\n{before}"
            );
        }
        let count = format!("landing_frame_seconds_count{{rpc=\"{rpc}\"}}");
        assert_eq!(value(&before, &count), Some(0.0), "{count}:\n{before}");
    }
    let triangulation = "landing_stage_seconds_count{stage=\"triangulation\"}";
    assert_eq!(value(&before, triangulation), Some(0.0), "{before}");
    for gauge in [
        "landing_queue_depth",
        "landing_queue_bytes",
        "landing_in_flight",
        "landing_streams_open",
    ] {
        assert_eq!(value(&before, gauge), Some(0.0), "{gauge}:\n{before}");
    }

    // The build info names the version and the model that GetServiceInfo reports.
    let client = server.client().await;
    let info = client.info().await.expect("service info");
    let model_sha256 = info.model.map(|m| m.sha256).unwrap_or_default();
    assert_eq!(model_sha256.is_empty(), !server.config.segmentation.enabled);
    let build_info = format!(
        "landing_build_info{{version=\"{}\",model_sha256=\"{model_sha256}\"}}",
        info.version
    );
    assert_eq!(
        value(&before, &build_info),
        Some(1.0),
        "{build_info}:\n{before}"
    );
    assert_eq!(info.version, env!("CARGO_PKG_VERSION"));

    // A frame moves its own counter and no other.
    let frame = scene(31).frames[0].frame.clone();
    client
        .detect_with(frame, Some(mode(SegmentationMode::None)))
        .await
        .expect("a frame");
    let after = scrape(addr).await.expect("scrape");
    for rpc in RPCS {
        for outcome in OUTCOMES {
            let want = if (rpc, outcome) == ("unary", "ok") {
                1.0
            } else {
                0.0
            };
            assert_eq!(
                value(&after, &frames_total(rpc, outcome)),
                Some(want),
                "{rpc}/{outcome}:\n{after}"
            );
        }
    }
    server.stop().await;
}
