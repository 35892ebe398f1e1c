//! Assembles and runs the server: the landing service behind bearer-token auth, health (exempt
//! from auth), reflection, TLS, message-size limits, the metrics endpoint and graceful drain.

use std::collections::HashSet;
use std::future::Future;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context as _;
use landing_geometry::Params;
use landing_proto::v1::landing_service_server::LandingServiceServer;
use tokio::net::TcpListener;
use tokio::sync::{oneshot, watch};
use tonic::service::interceptor::InterceptedService;
use tonic::transport::server::Router;
use tonic::transport::{Certificate, Identity, Server, ServerTlsConfig};

use crate::auth::Auth;
use crate::catalog::Catalog;
use crate::config::{Config, read_tokens};
use crate::limit::RequestLimit;
use crate::live::LiveView;
use crate::pipeline::Pipeline;
use crate::segmentation;
use crate::service::LandingService;
use crate::telemetry::{Metrics, serve_metrics};
use crate::workers::Dispatcher;

/// A server started by [`start`]: its addresses and the means to stop it.
#[derive(Debug)]
pub struct RunningServer {
    /// The gRPC address (the listener's, so port 0 resolves to the real port).
    pub addr: SocketAddr,
    /// The `/metrics` address, when metrics are enabled.
    pub metrics_addr: Option<SocketAddr>,
    /// The Foxglove live view's address, when `server.foxglove_listen` is set.
    pub foxglove_addr: Option<SocketAddr>,
    shutdown: Option<oneshot::Sender<()>>,
    task: tokio::task::JoinHandle<anyhow::Result<()>>,
}

impl RunningServer {
    /// Starts the graceful shutdown (health NOT_SERVING, no new frames, in-flight frames finish
    /// within `server.shutdown_grace_s`) and waits for it.
    pub async fn shutdown(mut self) -> anyhow::Result<()> {
        if let Some(tx) = self.shutdown.take() {
            let _ = tx.send(());
        }
        self.wait().await
    }

    /// Waits until the server stops (after a shutdown).
    pub async fn wait(self) -> anyhow::Result<()> {
        self.task.await.context("the server task panicked")?
    }
}

/// Runs the server on `listener` until `shutdown` resolves, then drains gracefully.
pub async fn serve(
    config: Config,
    listener: TcpListener,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> anyhow::Result<()> {
    let running = start(config, listener).await?;
    tracing::info!(
        addr = %running.addr,
        metrics = ?running.metrics_addr,
        foxglove = ?running.foxglove_addr,
        "serving landing.v1"
    );
    let (tx, rx) = oneshot::channel::<()>();
    tokio::spawn(async move {
        shutdown.await;
        let _ = tx.send(());
    });
    let mut running = running;
    let stop = running.shutdown.take();
    tokio::select! {
        r = &mut running.task => return r.context("the server task panicked")?,
        _ = rx => {}
    }
    if let Some(stop) = stop {
        let _ = stop.send(());
    }
    running.wait().await
}

/// A future that resolves on SIGTERM or SIGINT (Ctrl-C). On Unix the handlers are installed by
/// this call, not when the future is first polled: a signal that arrives just after the server
/// announces itself must drain it, not kill the process with the default action.
pub fn shutdown_signal() -> anyhow::Result<impl Future<Output = ()> + Send + 'static> {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{SignalKind, signal};
        let mut term = signal(SignalKind::terminate()).context("install the SIGTERM handler")?;
        let mut int = signal(SignalKind::interrupt()).context("install the SIGINT handler")?;
        Ok(async move {
            tokio::select! {
                _ = int.recv() => tracing::info!("SIGINT received, draining"),
                _ = term.recv() => tracing::info!("SIGTERM received, draining"),
            }
        })
    }
    #[cfg(not(unix))]
    {
        Ok(async {
            let _ = tokio::signal::ctrl_c().await;
            tracing::info!("Ctrl-C received, draining");
        })
    }
}

/// Validates `config`, loads the model, binds the metrics listener and starts serving on
/// `listener` in the background.
pub async fn start(config: Config, listener: TcpListener) -> anyhow::Result<RunningServer> {
    config.validate()?;
    let addr = listener
        .local_addr()
        .context("read the listener's address")?;
    let pipeline = load_pipeline(&config)?;
    let (model_sha256, model_id) = model_identity(&pipeline);
    let metrics = Metrics::new(&model_sha256);
    let catalog = Catalog::start(&config.catalog, model_id, metrics.clone())?;
    let metrics_listener = match config.metrics_addr()? {
        Some(a) => Some(
            TcpListener::bind(a)
                .await
                .with_context(|| format!("bind server.metrics_listen {a}"))?,
        ),
        None => None,
    };
    let metrics_addr = metrics_listener
        .as_ref()
        .map(TcpListener::local_addr)
        .transpose()?;
    let live = match config.foxglove_addr()? {
        Some(a) => Some(Arc::new(LiveView::start(a, metrics.clone()).await?)),
        None => None,
    };
    let foxglove_addr = live.as_ref().map(|l| l.addr);
    let tls = tls_config(&config)?;
    let tokens = token_set(&config)?;

    let dispatcher = Arc::new(Dispatcher::new(
        pipeline,
        config.pipeline.queue_capacity as usize,
        config.pipeline.max_queued_bytes,
        config.pipeline.workers(),
        metrics.clone(),
    ));
    let (drain_tx, drain_rx) = watch::channel(false);
    let service = LandingService {
        dispatcher: dispatcher.clone(),
        stream_buffer: config.pipeline.stream_buffer as usize,
        max_request_bytes: config.server.max_request_bytes,
        fusion: config.fusion.params(),
        draining: drain_rx,
        live: live.clone(),
        catalog: catalog.clone(),
    };
    let (health_reporter, router) = router(&config, service, tokens, tls).await?;

    let (metrics_stop_tx, metrics_stop_rx) = oneshot::channel::<()>();
    if let Some(l) = metrics_listener {
        tokio::spawn(serve_metrics(l, metrics, async {
            let _ = metrics_stop_rx.await;
        }));
    }
    let (stop_tx, stop_rx) = oneshot::channel::<()>();
    let serving = Serving {
        router,
        incoming: tonic::transport::server::TcpIncoming::from(listener).with_nodelay(Some(true)),
        stopping: Stopping {
            health_reporter,
            dispatcher,
            drain: drain_tx,
            metrics_stop: metrics_stop_tx,
            live,
            catalog,
            grace: Duration::from_secs_f64(config.server.shutdown_grace_s),
        },
    };
    let task = tokio::spawn(serving.run(stop_rx));
    Ok(RunningServer {
        addr,
        metrics_addr,
        foxglove_addr,
        shutdown: Some(stop_tx),
        task,
    })
}

/// The loaded model's SHA-256 (for `landing_build_info`) and the short id the catalog records
/// with each site (`name@sha256[..12]`); empty without a model.
fn model_identity(pipeline: &Pipeline) -> (String, String) {
    let Some(segmenter) = &pipeline.segmenter else {
        return Default::default();
    };
    let m = segmenter.model_info();
    let id = format!("{}@{}", m.name, m.sha256.get(..12).unwrap_or(&m.sha256));
    (m.sha256, id)
}

/// The bearer tokens `auth.tokens_file` lists, or `None` (no auth) when it is not set.
fn token_set(config: &Config) -> anyhow::Result<Option<Arc<HashSet<String>>>> {
    if config.auth.tokens_file.as_os_str().is_empty() {
        return Ok(None);
    }
    let tokens = read_tokens(&config.auth.tokens_file)?;
    Ok(Some(Arc::new(tokens.into_iter().collect())))
}

/// Everything served, behind auth where it applies, with the health service reporting
/// `landing.v1` as serving.
async fn router(
    config: &Config,
    service: LandingService,
    tokens: Option<Arc<HashSet<String>>>,
    tls: Option<ServerTlsConfig>,
) -> anyhow::Result<(tonic_health::server::HealthReporter, Router)> {
    let max = usize::try_from(config.server.max_request_bytes).unwrap_or(usize::MAX);
    let landing = LandingServiceServer::new(service)
        .max_decoding_message_size(max)
        .max_encoding_message_size(max);
    let auth = Auth { tokens };
    let landing = InterceptedService::new(landing, auth.clone());
    // Refuses an oversized message with RESOURCE_EXHAUSTED naming the limit, before tonic's
    // own check (the same limit) would answer OUT_OF_RANGE.
    let landing = RequestLimit::new(landing, config.server.max_request_bytes);

    let (health_reporter, health) = tonic_health::server::health_reporter();
    health_reporter
        .set_serving::<LandingServiceServer<LandingService>>()
        .await;
    // Both reflection versions: v1 for current tools, v1alpha for the stock Python client
    // (grpcio-reflection) and older tools, which know no other.
    let reflection_v1 = reflection()
        .build_v1()
        .context("build the reflection service (v1)")?;
    let reflection_v1alpha = reflection()
        .build_v1alpha()
        .context("build the reflection service (v1alpha)")?;
    let reflection_v1 = InterceptedService::new(reflection_v1, auth.clone());
    let reflection_v1alpha = InterceptedService::new(reflection_v1alpha, auth);

    // Frames are hundreds of KiB to MiBs: HTTP/2's default 64 KiB windows would cost a round trip
    // per window of every frame.
    let window = u32::try_from(config.server.max_request_bytes.min(8 << 20)).unwrap_or(8 << 20);
    let mut builder = Server::builder()
        .initial_stream_window_size(window)
        .initial_connection_window_size(window.saturating_mul(4))
        .tcp_nodelay(true);
    if let Some(tls) = tls {
        builder = builder.tls_config(tls).context("configure TLS")?;
    }
    let router = builder
        .add_service(health)
        .add_service(reflection_v1)
        .add_service(reflection_v1alpha)
        .add_service(landing);
    Ok((health_reporter, router))
}

/// A started server's parts, for its background task: serve until stopped, then drain.
struct Serving {
    router: Router,
    incoming: tonic::transport::server::TcpIncoming,
    stopping: Stopping,
}

/// What the server stops when it drains or fails.
struct Stopping {
    health_reporter: tonic_health::server::HealthReporter,
    dispatcher: Arc<Dispatcher>,
    /// Tells open streams to stop reading.
    drain: watch::Sender<bool>,
    metrics_stop: oneshot::Sender<()>,
    live: Option<Arc<LiveView>>,
    catalog: Option<Catalog>,
    grace: Duration,
}

impl Serving {
    /// Serves until `stop` (or the server fails), then drains: health NOT_SERVING, no new
    /// frames, open streams stop reading, and in-flight frames get `grace` to finish.
    async fn run(self, stop: oneshot::Receiver<()>) -> anyhow::Result<()> {
        let Self {
            router,
            incoming,
            stopping,
        } = self;
        let (tonic_stop_tx, tonic_stop_rx) = oneshot::channel::<()>();
        let server = router.serve_with_incoming_shutdown(incoming, async {
            let _ = tonic_stop_rx.await;
        });
        tokio::pin!(server);
        tokio::select! {
            r = &mut server => {
                stopping.side_services().await;
                return r.context("the gRPC server failed");
            }
            _ = stop => {}
        }
        stopping.refuse_new_frames().await;
        let _ = tonic_stop_tx.send(());
        let result = match tokio::time::timeout(stopping.grace, &mut server).await {
            Ok(r) => r.context("the gRPC server failed"),
            Err(_) => {
                tracing::warn!(
                    queued = stopping.dispatcher.queued(),
                    "grace period over; closing with frames unfinished"
                );
                Ok(())
            }
        };
        stopping.side_services().await;
        tracing::info!("stopped");
        result
    }
}

impl Stopping {
    /// Health goes NOT_SERVING, the dispatcher refuses new frames and open streams stop
    /// reading.
    async fn refuse_new_frames(&self) {
        tracing::info!(
            grace_s = self.grace.as_secs_f64(),
            queued = self.dispatcher.queued(),
            "draining"
        );
        self.health_reporter
            .set_not_serving::<LandingServiceServer<LandingService>>()
            .await;
        self.health_reporter
            .set_service_status("", tonic_health::ServingStatus::NotServing)
            .await;
        self.dispatcher.drain();
        let _ = self.drain.send(true);
    }

    /// Stops the metrics endpoint and the live view, and writes what the catalog has queued
    /// (the streams have ended: their last observations are in).
    async fn side_services(self) {
        let _ = self.metrics_stop.send(());
        if let Some(live) = &self.live {
            live.stop().await;
        }
        if let Some(catalog) = &self.catalog {
            catalog.stop(CATALOG_STOP).await;
        }
    }
}

/// How long the catalog's writer gets to write what is queued when the server stops.
const CATALOG_STOP: Duration = Duration::from_secs(10);

/// A reflection builder describing everything served: the landing API, health and both
/// reflection versions (each version lists the other too, since both are served).
fn reflection() -> tonic_reflection::server::Builder<'static> {
    tonic_reflection::server::Builder::configure()
        .register_encoded_file_descriptor_set(landing_proto::FILE_DESCRIPTOR_SET)
        .register_encoded_file_descriptor_set(tonic_health::pb::FILE_DESCRIPTOR_SET)
        .register_encoded_file_descriptor_set(tonic_reflection::pb::v1::FILE_DESCRIPTOR_SET)
        .register_encoded_file_descriptor_set(tonic_reflection::pb::v1alpha::FILE_DESCRIPTOR_SET)
        .include_reflection_service(false)
}

/// The pipeline the config asks for: default parameters and, when enabled, the model.
fn load_pipeline(config: &Config) -> anyhow::Result<Pipeline> {
    let mut pipeline = Pipeline::geometry_only(Params::default());
    pipeline.catalogue = config.catalog.enabled;
    if config.segmentation.enabled {
        let segmenter = segmentation::Segmenter::load(&config.segmentation).with_context(|| {
            format!(
                "load segmentation.model_path {}",
                config.segmentation.model_path.display()
            )
        })?;
        tracing::info!(model = %segmenter.describe(), "segmentation model loaded");
        pipeline.segmenter = Some(Arc::new(segmenter));
    }
    Ok(pipeline)
}

fn tls_config(config: &Config) -> anyhow::Result<Option<ServerTlsConfig>> {
    let t = &config.tls;
    if t.cert_path.as_os_str().is_empty() {
        return Ok(None);
    }
    let read = |key: &str, path: &std::path::Path| {
        std::fs::read(path).with_context(|| format!("read {key} {}", path.display()))
    };
    let identity = Identity::from_pem(
        read("tls.cert_path", &t.cert_path)?,
        read("tls.key_path", &t.key_path)?,
    );
    let mut tls = ServerTlsConfig::new().identity(identity);
    if !t.client_ca_path.as_os_str().is_empty() {
        tls = tls.client_ca_root(Certificate::from_pem(read(
            "tls.client_ca_path",
            &t.client_ca_path,
        )?));
    }
    Ok(Some(tls))
}
