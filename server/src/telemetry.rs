//! Logs (tracing, pretty or JSON) and metrics (Prometheus, one recorder per server, served on its
//! own port). Every metric is counted here, through [`Metrics`], from the dispatch layer.
//!
//! Every metric is registered with its help text when the server starts, so the first scrape,
//! before any frame, already shows them all: the counters at 0 for every label value known at
//! start ([`Rpc::ALL`] × [`Outcome::ALL`]), the gauges at 0, the histograms empty, and
//! `landing_build_info` (always 1) with the version and the model's SHA-256.

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use metrics_exporter_prometheus::{PrometheusBuilder, PrometheusHandle, PrometheusRecorder};
use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};
use tokio::net::TcpListener;
use tracing_subscriber::EnvFilter;

use crate::Error;
use crate::config::LogConfig;

/// Installs the global tracing subscriber (once per process; later calls are no-ops).
/// `RUST_LOG` overrides `log.filter`.
pub fn init_tracing(log: &LogConfig) -> Result<(), Error> {
    let filter = match std::env::var("RUST_LOG") {
        Ok(f) if !f.is_empty() => {
            EnvFilter::try_new(&f).map_err(|e| Error::config("RUST_LOG", e.to_string()))?
        }
        _ => EnvFilter::try_new(&log.filter)
            .map_err(|e| Error::config("log.filter", e.to_string()))?,
    };
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr);
    // A second install (several servers in one test process) keeps the first subscriber.
    let _ = match log.format {
        crate::config::LogFormat::Json => builder.json().try_init(),
        crate::config::LogFormat::Pretty => builder.try_init(),
    };
    Ok(())
}

/// The call a frame came in on, as counted in `landing_frames_total{rpc}`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rpc {
    /// `DetectLandingSites`.
    Unary,
    /// `StreamLandingSites`.
    Stream,
}

impl Rpc {
    /// Every call, so that each has its series from the start.
    pub const ALL: [Self; 2] = [Self::Unary, Self::Stream];

    /// The label value.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Unary => "unary",
            Self::Stream => "stream",
        }
    }
}

/// How one frame ended, as counted in `landing_frames_total{outcome}`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    Ok,
    Invalid,
    Overloaded,
    DeadlineExceeded,
    Cancelled,
    Skipped,
    Unavailable,
    Failed,
}

impl Outcome {
    /// Every outcome, so that each has its series from the start.
    pub const ALL: [Self; 8] = [
        Self::Ok,
        Self::Invalid,
        Self::Overloaded,
        Self::DeadlineExceeded,
        Self::Cancelled,
        Self::Skipped,
        Self::Unavailable,
        Self::Failed,
    ];

    /// The label value.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Ok => "ok",
            Self::Invalid => "invalid",
            Self::Overloaded => "overloaded",
            Self::DeadlineExceeded => "deadline_exceeded",
            Self::Cancelled => "cancelled",
            Self::Skipped => "skipped",
            Self::Unavailable => "unavailable",
            Self::Failed => "failed",
        }
    }

    /// The outcome of a frame that failed with `error`.
    pub fn of(error: &Error) -> Self {
        match crate::status::code_of(error) {
            tonic::Code::InvalidArgument | tonic::Code::FailedPrecondition => Self::Invalid,
            tonic::Code::ResourceExhausted => Self::Overloaded,
            tonic::Code::DeadlineExceeded => Self::DeadlineExceeded,
            tonic::Code::Cancelled => Self::Cancelled,
            tonic::Code::Unavailable => Self::Unavailable,
            _ => Self::Failed,
        }
    }
}

/// This server's metrics: a Prometheus recorder of its own (so several servers can run in one
/// process) and the handle that renders it.
#[derive(Clone)]
pub struct Metrics {
    recorder: Arc<PrometheusRecorder>,
    handle: PrometheusHandle,
}

impl std::fmt::Debug for Metrics {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Metrics")
    }
}

/// Histogram buckets for latencies, seconds.
const LATENCY_BUCKETS: [f64; 14] = [
    0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0,
];

impl Metrics {
    /// A fresh recorder with every metric registered: described, counters and gauges at 0,
    /// histograms empty, and `landing_build_info` naming this build and `model_sha256` (the
    /// SHA-256 of the loaded model file, as `GetServiceInfo` reports it; "" without a model).
    pub fn new(model_sha256: &str) -> Self {
        let recorder = PrometheusBuilder::new()
            .set_buckets(&LATENCY_BUCKETS)
            .map(PrometheusBuilder::build_recorder)
            .unwrap_or_else(|_| PrometheusBuilder::new().build_recorder());
        let handle = recorder.handle();
        let metrics = Self {
            recorder: Arc::new(recorder),
            handle,
        };
        metrics.describe();
        metrics.register(model_sha256);
        metrics
    }

    fn with<T>(&self, f: impl FnOnce() -> T) -> T {
        metrics::with_local_recorder(&*self.recorder, f)
    }

    fn describe(&self) {
        self.with(|| {
            metrics::describe_counter!(
                "landing_frames_total",
                "Frames answered, by RPC and outcome."
            );
            metrics::describe_histogram!(
                "landing_stage_seconds",
                metrics::Unit::Seconds,
                "Time per pipeline stage."
            );
            metrics::describe_histogram!(
                "landing_frame_seconds",
                metrics::Unit::Seconds,
                "Time from receipt to answer."
            );
            metrics::describe_gauge!(
                "landing_queue_depth",
                "Frames admitted and not yet finished."
            );
            metrics::describe_gauge!(
                "landing_queue_bytes",
                metrics::Unit::Bytes,
                "Memory the admitted, unfinished frames hold (against pipeline.max_queued_bytes)."
            );
            metrics::describe_gauge!("landing_in_flight", "Frames being computed on a worker.");
            metrics::describe_gauge!("landing_streams_open", "Open detection streams.");
            metrics::describe_gauge!(
                "landing_fusion_maps_open",
                "Fusion maps held: one per open stream that fuses."
            );
            metrics::describe_gauge!(
                "landing_fusion_map_bytes",
                metrics::Unit::Bytes,
                "Memory the open fusion maps hold (cells and kept obstacle rays)."
            );
            metrics::describe_counter!(
                "landing_live_view_frames_total",
                "Frames published to the Foxglove live view (server.foxglove_listen)."
            );
            metrics::describe_counter!(
                "landing_live_view_dropped_total",
                "Frames the live view dropped, oldest first, because its viewers fell behind."
            );
            describe_catalog();
            metrics::describe_gauge!(
                "landing_build_info",
                "Always 1; the labels name the server version and the SHA-256 of the segmentation model file (\"\" without a model)."
            );
        });
    }

    /// Creates every series whose labels are known at start, so that a scrape before the first
    /// frame shows each metric (and dashboards and absent-series alerts see 0, not nothing).
    fn register(&self, model_sha256: &str) {
        self.with(|| {
            for rpc in Rpc::ALL {
                for outcome in Outcome::ALL {
                    metrics::counter!("landing_frames_total", "rpc" => rpc.as_str(), "outcome" => outcome.as_str())
                        .absolute(0);
                }
                // Registered, not recorded: an empty histogram.
                let _ = metrics::histogram!("landing_frame_seconds", "rpc" => rpc.as_str());
            }
            for stage in crate::pipeline::STAGES.iter().filter(|s| **s != "total") {
                let _ = metrics::histogram!("landing_stage_seconds", "stage" => *stage);
            }
            for gauge in [
                "landing_queue_depth",
                "landing_queue_bytes",
                "landing_in_flight",
                "landing_streams_open",
                "landing_fusion_maps_open",
                "landing_fusion_map_bytes",
            ] {
                metrics::gauge!(gauge).set(0.0);
            }
            for counter in [
                "landing_live_view_frames_total",
                "landing_live_view_dropped_total",
            ] {
                metrics::counter!(counter).absolute(0);
            }
            register_catalog();
            metrics::gauge!(
                "landing_build_info",
                "version" => env!("CARGO_PKG_VERSION"),
                "model_sha256" => model_sha256.to_owned()
            )
            .set(1.0);
        });
    }

    /// Counts a finished frame.
    pub fn frame(&self, rpc: Rpc, outcome: Outcome, total: Duration) {
        let rpc = rpc.as_str();
        self.with(|| {
            metrics::counter!("landing_frames_total", "rpc" => rpc, "outcome" => outcome.as_str())
                .increment(1);
            metrics::histogram!("landing_frame_seconds", "rpc" => rpc).record(total.as_secs_f64());
        });
    }

    /// Records the stage timings of a computed frame.
    pub fn stages(&self, t: &crate::pipeline::StageTimings) {
        self.with(|| {
            // `total` is its own histogram; the stages are the steps inside it.
            for (stage, d) in t.named().filter(|(name, _)| *name != "total") {
                metrics::histogram!("landing_stage_seconds", "stage" => stage)
                    .record(d.as_secs_f64());
            }
        });
    }

    /// Sets the queue gauges: frames admitted, the memory they hold, frames computing.
    pub fn queue(&self, depth: usize, bytes: usize, in_flight: usize) {
        self.with(|| {
            metrics::gauge!("landing_queue_depth").set(depth as f64);
            metrics::gauge!("landing_queue_bytes").set(bytes as f64);
            metrics::gauge!("landing_in_flight").set(in_flight as f64);
        });
    }

    /// Adds `delta` to the open-streams gauge.
    pub fn streams(&self, delta: f64) {
        self.with(|| metrics::gauge!("landing_streams_open").increment(delta));
    }

    /// Moves the open fusion map count by `delta`.
    pub fn fusion_maps(&self, delta: f64) {
        self.with(|| metrics::gauge!("landing_fusion_maps_open").increment(delta));
    }

    /// Moves the fusion maps' memory by `delta` bytes.
    pub fn fusion_bytes(&self, delta: f64) {
        self.with(|| metrics::gauge!("landing_fusion_map_bytes").increment(delta));
    }

    /// Counts a frame the live view published.
    pub fn live_view_published(&self) {
        self.with(|| metrics::counter!("landing_live_view_frames_total").increment(1));
    }

    /// Counts a frame the live view dropped because its viewers fell behind.
    pub fn live_view_dropped(&self) {
        self.with(|| metrics::counter!("landing_live_view_dropped_total").increment(1));
    }

    /// Counts a fused frame by what it gave the catalog (`catalogued`, `no_geodetic_origin`,
    /// `unresolvable`).
    pub fn catalog_frame(&self, outcome: &'static str) {
        self.with(|| {
            metrics::counter!("landing_catalog_frames_total", "outcome" => outcome).increment(1);
        });
    }

    /// Sets the catalog's write-queue depth.
    pub fn catalog_queue(&self, depth: usize) {
        self.with(|| metrics::gauge!("landing_catalog_queue_depth").set(depth as f64));
    }

    /// Counts observations dropped unwritten (the queue was full, or the store refused them).
    pub fn catalog_dropped(&self, observations: usize) {
        self.with(|| {
            metrics::counter!("landing_catalog_dropped_total").increment(observations as u64);
        });
    }

    /// Counts a batch written and what it did to the stored sites.
    pub fn catalog_written(&self, report: &landing_catalog::ApplyReport) {
        self.with(|| {
            metrics::counter!("landing_catalog_writes_total").increment(report.observations);
            for (change, n) in [
                ("inserted", report.inserted),
                ("updated", report.updated),
                ("withdrawn", report.withdrawn),
                ("merged", report.merged),
                ("dropped_stale", report.dropped_stale),
            ] {
                metrics::counter!("landing_catalog_site_changes_total", "change" => change)
                    .increment(n);
            }
        });
    }

    /// Counts a write (or an attempt to open the store) that failed.
    pub fn catalog_write_failed(&self) {
        self.with(|| metrics::counter!("landing_catalog_write_failures_total").increment(1));
    }

    /// Sets the stored-records gauges and whether the store is open.
    pub fn catalog_sites(&self, counts: &landing_catalog::Counts) {
        self.with(|| {
            metrics::gauge!("landing_catalog_sites", "kind" => "site").set(counts.confirmed as f64);
            metrics::gauge!("landing_catalog_sites", "kind" => "candidate")
                .set(counts.candidates as f64);
        });
    }

    /// Sets whether the catalog's store is open.
    pub fn catalog_connected(&self, connected: bool) {
        self.with(|| {
            metrics::gauge!("landing_catalog_connected").set(f64::from(u8::from(connected)))
        });
    }

    /// Records one search's time in the store.
    pub fn catalog_query(&self, took: Duration) {
        self.with(|| {
            metrics::histogram!("landing_catalog_query_seconds").record(took.as_secs_f64())
        });
    }

    /// The Prometheus text exposition of every metric.
    pub fn render(&self) -> String {
        self.handle.run_upkeep();
        self.handle.render()
    }
}

/// The catalog's metrics' help texts (inside [`Metrics::describe`]'s recorder).
fn describe_catalog() {
    metrics::describe_counter!(
        "landing_catalog_frames_total",
        "Fused frames by what they gave the landing-site catalog: catalogued, no_geodetic_origin (answered, not catalogued), unresolvable (no camera classes, or max_pixel_footprint_m = 0)."
    );
    metrics::describe_counter!(
        "landing_catalog_writes_total",
        "Observations written to the catalog."
    );
    metrics::describe_counter!(
        "landing_catalog_write_failures_total",
        "Catalog writes (and attempts to open its store) that failed; they are retried."
    );
    metrics::describe_counter!(
        "landing_catalog_dropped_total",
        "Observations dropped unwritten, oldest first: the write queue was full (catalog.queue_capacity), or the store refused them."
    );
    metrics::describe_counter!(
        "landing_catalog_site_changes_total",
        "What written observations did to stored sites: inserted, updated, withdrawn, merged, dropped_stale."
    );
    metrics::describe_gauge!(
        "landing_catalog_queue_depth",
        "Observations waiting to be written."
    );
    metrics::describe_gauge!(
        "landing_catalog_sites",
        "Records in the catalog, by kind (site, candidate)."
    );
    metrics::describe_gauge!(
        "landing_catalog_connected",
        "1 when the catalog's store is open, 0 while it is off or being retried."
    );
    metrics::describe_histogram!(
        "landing_catalog_query_seconds",
        metrics::Unit::Seconds,
        "Time SearchLandingSites spends in the catalog's store."
    );
}

/// The catalog's series, at 0 (inside [`Metrics::register`]'s recorder).
fn register_catalog() {
    for outcome in ["catalogued", "no_geodetic_origin", "unresolvable"] {
        metrics::counter!("landing_catalog_frames_total", "outcome" => outcome).absolute(0);
    }
    for change in [
        "inserted",
        "updated",
        "withdrawn",
        "merged",
        "dropped_stale",
    ] {
        metrics::counter!("landing_catalog_site_changes_total", "change" => change).absolute(0);
    }
    for counter in [
        "landing_catalog_writes_total",
        "landing_catalog_write_failures_total",
        "landing_catalog_dropped_total",
    ] {
        metrics::counter!(counter).absolute(0);
    }
    for kind in ["site", "candidate"] {
        metrics::gauge!("landing_catalog_sites", "kind" => kind).set(0.0);
    }
    metrics::gauge!("landing_catalog_queue_depth").set(0.0);
    metrics::gauge!("landing_catalog_connected").set(0.0);
    let _ = metrics::histogram!("landing_catalog_query_seconds");
}

impl Default for Metrics {
    /// The metrics of a server without a model.
    fn default() -> Self {
        Self::new("")
    }
}

/// Serves `GET /metrics` (Prometheus text format) on `listener` until `shutdown` resolves.
/// A deliberately tiny HTTP/1.1 responder: one request per connection.
pub async fn serve_metrics(
    listener: TcpListener,
    metrics: Metrics,
    shutdown: impl std::future::Future<Output = ()>,
) {
    tokio::pin!(shutdown);
    loop {
        let accepted = tokio::select! {
            _ = &mut shutdown => return,
            a = listener.accept() => a,
        };
        let Ok((mut socket, _)) = accepted else {
            continue;
        };
        let metrics = metrics.clone();
        tokio::spawn(async move {
            let mut buf = Vec::with_capacity(1024);
            let mut chunk = [0u8; 1024];
            // Read the request head, bounded in size and time.
            let read = tokio::time::timeout(Duration::from_secs(5), async {
                while !buf.windows(4).any(|w| w == b"\r\n\r\n") && buf.len() < 16 * 1024 {
                    match socket.read(&mut chunk).await {
                        Ok(0) | Err(_) => break,
                        Ok(n) => buf.extend_from_slice(&chunk[..n]),
                    }
                }
            })
            .await;
            if read.is_err() {
                return;
            }
            let head = String::from_utf8_lossy(&buf);
            let mut words = head.split_whitespace();
            let (method, path) = (words.next().unwrap_or(""), words.next().unwrap_or(""));
            let (status, body) =
                if method == "GET" && (path == "/metrics" || path.starts_with("/metrics?")) {
                    ("200 OK", metrics.render())
                } else {
                    (
                        "404 Not Found",
                        "only GET /metrics is served here\n".to_owned(),
                    )
                };
            let response = format!(
                "HTTP/1.1 {status}\r\ncontent-type: text/plain; version=0.0.4\r\ncontent-length: {}\r\n\
                 connection: close\r\n\r\n{body}",
                body.len()
            );
            let _ = socket.write_all(response.as_bytes()).await;
            let _ = socket.shutdown().await;
        });
    }
}

/// Fetches `http://addr/metrics` (used by tests and the `check` tooling).
pub async fn scrape(addr: SocketAddr) -> std::io::Result<String> {
    let mut socket = tokio::net::TcpStream::connect(addr).await?;
    socket
        .write_all(b"GET /metrics HTTP/1.1\r\nhost: localhost\r\n\r\n")
        .await?;
    let mut out = String::new();
    socket.read_to_string(&mut out).await?;
    Ok(out
        .split_once("\r\n\r\n")
        .map_or(out.clone(), |(_, body)| body.to_owned()))
}
