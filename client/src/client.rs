//! The connection to a server: unary detection with retries, service info, health, and streams.

use std::collections::VecDeque;
use std::pin::Pin;
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::{Duration, Instant};

use landing_proto::v1::landing_service_client::LandingServiceClient;
use landing_proto::v1::{
    DetectLandingSitesRequest, Frame, FrameResult, FusionOptions, GetServiceInfoRequest,
    OverflowPolicy, PipelineOptions, SearchLandingSitesRequest, SearchLandingSitesResponse,
    ServiceInfo, StreamLandingSitesRequest, StreamLandingSitesResponse,
};
use tokio::sync::{Semaphore, mpsc};
use tokio_stream::Stream;
use tonic::metadata::{AsciiMetadataValue, MetadataValue};
use tonic::service::Interceptor;
use tonic::service::interceptor::InterceptedService;
use tonic::transport::{Certificate, Channel, ClientTlsConfig, Endpoint, Identity};
use tonic_health::pb::health_client::HealthClient;

use crate::outcome::outcome_of;
use crate::{ClientConfig, ClientError, FrameError, RetryPolicy, StreamItem};

pub use tonic_health::ServingStatus;

type Inner = InterceptedService<Channel, Auth>;

/// Adds the bearer token to every call.
#[derive(Debug, Clone)]
pub struct Auth {
    header: Option<AsciiMetadataValue>,
}

impl Interceptor for Auth {
    fn call(
        &mut self,
        mut request: tonic::Request<()>,
    ) -> Result<tonic::Request<()>, tonic::Status> {
        if let Some(h) = &self.header {
            request.metadata_mut().insert("authorization", h.clone());
        }
        Ok(request)
    }
}

/// A connected client. Cheap to clone; clones share the connection.
#[derive(Debug, Clone)]
pub struct LandingClient {
    landing: LandingServiceClient<Inner>,
    health: HealthClient<Inner>,
    config: Arc<ClientConfig>,
}

impl LandingClient {
    /// Connects (and completes the TLS handshake) now, so an unreachable server is reported here
    /// as [`ClientError::Unreachable`].
    pub async fn connect(config: ClientConfig) -> Result<Self, ClientError> {
        let endpoint = endpoint(&config)?;
        let channel = endpoint
            .connect()
            .await
            .map_err(|e| ClientError::Unreachable {
                endpoint: config.endpoint.clone(),
                reason: error_chain(&e),
            })?;
        Self::from_channel(channel, config)
    }

    /// Wraps an existing channel (for example one made with `Endpoint::connect_lazy`).
    pub fn from_channel(channel: Channel, config: ClientConfig) -> Result<Self, ClientError> {
        let header = match &config.token {
            None => None,
            Some(t) => Some(MetadataValue::try_from(format!("Bearer {t}")).map_err(|_| {
                ClientError::InvalidConfig {
                    field: "token",
                    value: "<redacted>".into(),
                    reason: "must be printable ASCII".into(),
                }
            })?),
        };
        let auth = Auth { header };
        let landing = LandingServiceClient::with_interceptor(channel.clone(), auth.clone())
            .max_decoding_message_size(config.max_response_bytes)
            .max_encoding_message_size(usize::MAX);
        let health = HealthClient::with_interceptor(channel, auth);
        Ok(Self {
            landing,
            health,
            config: Arc::new(config),
        })
    }

    /// The configuration this client was made with.
    pub fn config(&self) -> &ClientConfig {
        &self.config
    }

    /// Detects the landing sites of one frame with the server's default options.
    pub async fn detect(&self, frame: Frame) -> Result<FrameResult, ClientError> {
        self.detect_with(frame, None).await
    }

    /// Detects the landing sites of one frame, retrying on `UNAVAILABLE` and
    /// `RESOURCE_EXHAUSTED` as the [`RetryPolicy`] allows.
    pub async fn detect_with(
        &self,
        frame: Frame,
        options: Option<PipelineOptions>,
    ) -> Result<FrameResult, ClientError> {
        let request = DetectLandingSitesRequest {
            frame: Some(frame),
            options,
        };
        let response = self
            .with_retries(|mut client, timeout| {
                let mut req = tonic::Request::new(request.clone());
                if let Some(t) = timeout {
                    req.set_timeout(t);
                }
                async move { client.detect_landing_sites(req).await }
            })
            .await?;
        response
            .result
            .ok_or_else(|| ClientError::Protocol("DetectLandingSitesResponse had no result".into()))
    }

    /// Version, model, classes and default options of the server.
    pub async fn info(&self) -> Result<ServiceInfo, ClientError> {
        self.with_retries(|mut client, timeout| {
            let mut req = tonic::Request::new(GetServiceInfoRequest {});
            if let Some(t) = timeout {
                req.set_timeout(t);
            }
            async move { client.get_service_info(req).await }
        })
        .await
    }

    /// One page of the fleet's landing-site catalog near a place ([`crate::SiteSearch`] builds
    /// the request), retried on `UNAVAILABLE` as the [`RetryPolicy`] allows. A bad field is
    /// [`ClientError::Status`] with `INVALID_ARGUMENT` naming it; a server whose catalog is off
    /// or whose database is down answers `UNAVAILABLE`. Every site found is a candidate for a
    /// drone to confirm with its own stream, never a clearance to land.
    pub async fn search_landing_sites(
        &self,
        request: impl Into<SearchLandingSitesRequest>,
    ) -> Result<SearchLandingSitesResponse, ClientError> {
        let request = request.into();
        self.with_retries(|mut client, timeout| {
            let mut req = tonic::Request::new(request.clone());
            if let Some(t) = timeout {
                req.set_timeout(t);
            }
            async move { client.search_landing_sites(req).await }
        })
        .await
    }

    /// The `grpc.health.v1` status of `service` (`""` for the whole server).
    pub async fn health(&self, service: &str) -> Result<ServingStatus, ClientError> {
        let mut client = self.health.clone();
        let mut req = tonic::Request::new(tonic_health::pb::HealthCheckRequest {
            service: service.to_owned(),
        });
        if let Some(t) = self.config.request_timeout {
            req.set_timeout(t);
        }
        let resp = client.check(req).await.map_err(|s| self.status_error(&s))?;
        use tonic_health::pb::health_check_response::ServingStatus as Pb;
        Ok(match Pb::try_from(resp.into_inner().status) {
            Ok(Pb::Serving) => ServingStatus::Serving,
            Ok(Pb::NotServing) => ServingStatus::NotServing,
            _ => ServingStatus::Unknown,
        })
    }

    /// Opens a bidirectional stream. Frames go in through the [`FrameSender`]; answers come out
    /// of the [`ResultStream`], one per frame, in order. The sender waits when
    /// `max_in_flight` frames are unanswered (and when the server stops reading), so a fast
    /// producer cannot queue unbounded memory.
    pub fn open_stream(&self, config: StreamConfig) -> (FrameSender, ResultStream) {
        let (tx, rx) = mpsc::channel::<StreamLandingSitesRequest>(1);
        let pending = Arc::new(Mutex::new(VecDeque::new()));
        let window = Arc::new(Semaphore::new(
            config.max_in_flight.clamp(1, Semaphore::MAX_PERMITS),
        ));
        let mut client = self.landing.clone();
        let call = tokio::spawn(async move {
            client
                .stream_landing_sites(tokio_stream::wrappers::ReceiverStream::new(rx))
                .await
        });
        let sender = FrameSender {
            tx,
            pending: pending.clone(),
            window: window.clone(),
            first: true,
            reset_next: false,
            config,
        };
        let results = ResultStream {
            state: StreamState::Opening(call),
            pending,
            window,
            endpoint: self.config.endpoint.clone(),
        };
        (sender, results)
    }

    /// Streams `frames` and yields one item per frame, in order. Frames are pulled from the input
    /// only as fast as the window of [`StreamConfig::max_in_flight`] allows.
    pub fn stream<S>(&self, frames: S, config: StreamConfig) -> ResultStream
    where
        S: Stream<Item = Frame> + Send + 'static,
    {
        let (mut sender, results) = self.open_stream(config);
        tokio::spawn(async move {
            use tokio_stream::StreamExt;
            let mut frames = std::pin::pin!(frames);
            while let Some(frame) = frames.next().await {
                if sender.send(frame).await.is_err() {
                    break;
                }
            }
        });
        results
    }

    async fn with_retries<T, F, Fut>(&self, mut call: F) -> Result<T, ClientError>
    where
        F: FnMut(LandingServiceClient<Inner>, Option<Duration>) -> Fut,
        Fut: Future<Output = Result<tonic::Response<T>, tonic::Status>>,
    {
        let policy = &self.config.retry;
        let started = Instant::now();
        let mut attempt = 0u32;
        loop {
            attempt += 1;
            let sent = Instant::now();
            match call(self.landing.clone(), self.config.request_timeout).await {
                Ok(r) => return Ok(r.into_inner()),
                Err(status) => {
                    let status = own_deadline(status, self.config.request_timeout, sent.elapsed());
                    let error = FrameError::from_status(&status);
                    if !RetryPolicy::is_retryable(error.code, error.retry_delay) {
                        return Err(self.status_error(&status));
                    }
                    if attempt >= policy.max_attempts.max(1) {
                        if attempt == 1 {
                            return Err(self.status_error(&status));
                        }
                        return Err(ClientError::RetriesExhausted {
                            attempts: attempt,
                            elapsed: started.elapsed(),
                            last: Box::new(error),
                        });
                    }
                    let wait = policy.backoff(attempt, error.retry_delay, jitter());
                    tokio::time::sleep(wait).await;
                }
            }
        }
    }

    fn status_error(&self, status: &tonic::Status) -> ClientError {
        status_to_error(&self.config.endpoint, status)
    }
}

/// A transport failure (no HTTP/2 answer at all) becomes `Unreachable`; an answer, `Status`.
fn status_to_error(endpoint: &str, status: &tonic::Status) -> ClientError {
    use std::error::Error;
    if status.code() == tonic::Code::Unavailable
        && status
            .source()
            .is_some_and(|s| s.downcast_ref::<tonic::transport::Error>().is_some())
    {
        return ClientError::Unreachable {
            endpoint: endpoint.to_owned(),
            reason: error_chain(status),
        };
    }
    ClientError::Status(Box::new(FrameError::from_status(status)))
}

fn error_chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut cur = e.source();
    while let Some(c) = cur {
        let msg = c.to_string();
        if !s.contains(&msg) {
            s.push_str(": ");
            s.push_str(&msg);
        }
        cur = c.source();
    }
    s
}

/// A cheap jitter source in `[0, 1)`; quality does not matter, only that clients differ.
fn jitter() -> f64 {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.subsec_nanos())
        .unwrap_or(0);
    let mut x = nanos as u64 ^ 0x9E37_79B9_7F4A_7C15;
    x ^= x >> 33;
    x = x.wrapping_mul(0xff51_afd7_ed55_8ccd);
    x ^= x >> 33;
    (x >> 11) as f64 / (1u64 << 53) as f64
}

fn endpoint(config: &ClientConfig) -> Result<Endpoint, ClientError> {
    let bad = |reason: String| ClientError::InvalidConfig {
        field: "endpoint",
        value: config.endpoint.clone(),
        reason,
    };
    let https = config.endpoint.starts_with("https://");
    if !https && !config.endpoint.starts_with("http://") {
        return Err(bad("must start with http:// or https://".into()));
    }
    let mut ep = Endpoint::from_shared(config.endpoint.clone())
        .map_err(|e| bad(e.to_string()))?
        .connect_timeout(config.connect_timeout)
        .tcp_nodelay(true);
    match (&config.tls, https) {
        (Some(tls), true) => {
            let mut t = ClientTlsConfig::new();
            match &tls.ca_cert_pem {
                Some(ca) => t = t.ca_certificate(Certificate::from_pem(ca)),
                None => {
                    return Err(ClientError::InvalidConfig {
                        field: "ca_cert",
                        value: String::new(),
                        reason:
                            "an https:// endpoint needs the CA certificate that signed the server's"
                                .into(),
                    });
                }
            }
            match (&tls.client_cert_pem, &tls.client_key_pem) {
                (Some(c), Some(k)) => t = t.identity(Identity::from_pem(c, k)),
                (None, None) => {}
                _ => {
                    return Err(ClientError::InvalidConfig {
                        field: "client_cert",
                        value: String::new(),
                        reason: "client certificate and client key must be given together".into(),
                    });
                }
            }
            if let Some(d) = &tls.domain_name {
                t = t.domain_name(d.clone());
            }
            ep = ep.tls_config(t).map_err(|e| bad(error_chain(&e)))?;
        }
        (None, true) => {
            return Err(ClientError::InvalidConfig {
                field: "ca_cert",
                value: String::new(),
                reason: "an https:// endpoint needs the CA certificate that signed the server's"
                    .into(),
            });
        }
        (Some(_), false) => {
            return Err(bad(
                "TLS settings were given for a plain http:// endpoint; use https://".into(),
            ));
        }
        (None, false) => {}
    }
    Ok(ep)
}

/// How a stream's frames are answered.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StreamMode {
    /// Approach fusion (the default): each answer comes from the server's map of the stream's
    /// frames so far, with these options (unset fields take the server's defaults,
    /// `ServiceInfo.default_fusion`). The map lives in the server process that holds the
    /// stream: when the stream breaks and the drone reconnects, possibly to another replica
    /// after a drain, fusion starts over from the next frame. A fused answer's polygons end
    /// halfway between the map's last landable points and the first points that are not; each
    /// safe circle stays within the landable points, so it may lie farther from its polygon's
    /// edge than its radius.
    Fused(FusionOptions),
    /// Every frame judged alone, as [`LandingClient::detect`] judges it (the paper's
    /// single-frame method).
    SingleFrame,
}

/// Settings of one stream.
#[derive(Debug, Clone)]
pub struct StreamConfig {
    /// What the server does when frames come faster than it processes them.
    pub overflow_policy: OverflowPolicy,
    /// Pipeline options sent with every frame.
    pub options: Option<PipelineOptions>,
    /// At most this many frames are sent and unanswered at once.
    pub max_in_flight: usize,
    /// Fused (the default) or single frames; sent with the first frame.
    pub mode: StreamMode,
}

impl Default for StreamConfig {
    fn default() -> Self {
        Self::fused()
    }
}

impl StreamConfig {
    /// A fused stream with the server's fusion defaults (`ServiceInfo.default_fusion`): each
    /// answer comes from the map of the stream's frames so far (the `Default`).
    pub fn fused() -> Self {
        Self::fused_with(FusionOptions::default())
    }

    /// A fused stream with these fusion options (unset fields take the server's defaults).
    pub fn fused_with(fusion: FusionOptions) -> Self {
        Self {
            overflow_policy: OverflowPolicy::Block,
            options: None,
            max_in_flight: 16,
            mode: StreamMode::Fused(fusion),
        }
    }

    /// A stream whose every frame is judged alone, as [`LandingClient::detect`] judges it.
    pub fn single_frame() -> Self {
        Self {
            mode: StreamMode::SingleFrame,
            ..Self::fused()
        }
    }

    /// The same stream with these pipeline options sent with every frame.
    pub fn with_options(mut self, options: PipelineOptions) -> Self {
        self.options = Some(options);
        self
    }

    /// The same stream with this overflow policy.
    pub fn with_overflow_policy(mut self, policy: OverflowPolicy) -> Self {
        self.overflow_policy = policy;
        self
    }
}

type Pending = Arc<Mutex<VecDeque<(u64, Instant)>>>;

/// The sending half of a stream. Dropping it (or calling [`FrameSender::finish`]) ends the
/// request stream; the server then answers the frames in flight and closes.
#[derive(Debug)]
pub struct FrameSender {
    tx: mpsc::Sender<StreamLandingSitesRequest>,
    pending: Pending,
    window: Arc<Semaphore>,
    first: bool,
    /// The next frame asks for the fusion map to start over.
    reset_next: bool,
    config: StreamConfig,
}

impl FrameSender {
    /// Sends one frame with the stream's options. Waits while the window is full. Cancel-safe:
    /// a send abandoned while waiting leaves nothing in flight.
    pub async fn send(&mut self, frame: Frame) -> Result<(), ClientError> {
        let options = self.config.options.clone();
        self.send_with(frame, options).await
    }

    /// Sends one frame with its own options.
    pub async fn send_with(
        &mut self,
        frame: Frame,
        options: Option<PipelineOptions>,
    ) -> Result<(), ClientError> {
        let seq = frame.sequence;
        // Both waits are cancel-safe: nothing is recorded until the frame is handed over.
        let permit = self
            .window
            .acquire()
            .await
            .map_err(|_| ClientError::StreamClosed(seq))?;
        let slot = self
            .tx
            .reserve()
            .await
            .map_err(|_| ClientError::StreamClosed(seq))?;
        {
            let mut pending = self.pending.lock().unwrap_or_else(|e| e.into_inner());
            if pending.iter().any(|(s, _)| *s == seq) {
                return Err(ClientError::DuplicateSequence(seq));
            }
            pending.push_back((seq, Instant::now()));
        }
        permit.forget();
        let (overflow_policy, fusion, single_frame) = match (self.first, self.config.mode) {
            (false, _) => (0, None, false),
            (true, StreamMode::Fused(fusion)) => {
                (self.config.overflow_policy as i32, Some(fusion), false)
            }
            (true, StreamMode::SingleFrame) => (self.config.overflow_policy as i32, None, true),
        };
        self.first = false;
        slot.send(StreamLandingSitesRequest {
            frame: Some(frame),
            options,
            overflow_policy,
            fusion,
            reset_fusion: std::mem::take(&mut self.reset_next),
            single_frame,
        });
        Ok(())
    }

    /// Asks the server to start the stream's fusion map over at the next frame sent.
    pub fn reset_fusion(&mut self) {
        self.reset_next = true;
    }

    /// Frames sent and not yet answered.
    pub fn in_flight(&self) -> usize {
        self.pending.lock().unwrap_or_else(|e| e.into_inner()).len()
    }

    /// Ends the request stream.
    pub fn finish(self) {}
}

enum StreamState {
    Opening(
        tokio::task::JoinHandle<
            Result<tonic::Response<tonic::Streaming<StreamLandingSitesResponse>>, tonic::Status>,
        >,
    ),
    Open(Box<tonic::Streaming<StreamLandingSitesResponse>>),
    Done,
}

/// The answers of a stream, one per frame. Ends with `Ok` items only when every sent frame was
/// answered; otherwise the last item is a [`ClientError::StreamBroken`] listing the frames that
/// got no answer (they were not re-sent: the caller decides).
pub struct ResultStream {
    state: StreamState,
    pending: Pending,
    window: Arc<Semaphore>,
    endpoint: String,
}

impl std::fmt::Debug for ResultStream {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ResultStream")
            .field("endpoint", &self.endpoint)
            .finish_non_exhaustive()
    }
}

impl ResultStream {
    /// The next answer; `None` once the stream is over.
    pub async fn next(&mut self) -> Option<Result<StreamItem, ClientError>> {
        std::future::poll_fn(|cx| Pin::new(&mut *self).poll_next(cx)).await
    }

    fn broken(
        &mut self,
        status: Option<&tonic::Status>,
    ) -> Option<Result<StreamItem, ClientError>> {
        self.state = StreamState::Done;
        self.window.close();
        let unanswered: Vec<u64> = self
            .pending
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .drain(..)
            .map(|(s, _)| s)
            .collect();
        match status {
            None if unanswered.is_empty() => None,
            None => Some(Err(ClientError::StreamBroken {
                unanswered,
                status: None,
            })),
            Some(s) => {
                let e = status_to_error(&self.endpoint, s);
                match e {
                    ClientError::Unreachable { .. } if unanswered.is_empty() => Some(Err(e)),
                    _ => Some(Err(ClientError::StreamBroken {
                        unanswered,
                        status: Some(Box::new(FrameError::from_status(s))),
                    })),
                }
            }
        }
    }

    fn answer(&mut self, response: StreamLandingSitesResponse) -> Result<StreamItem, ClientError> {
        let (sequence, outcome) = outcome_of(response);
        let sent = {
            let mut pending = self.pending.lock().unwrap_or_else(|e| e.into_inner());
            match pending.iter().position(|(s, _)| *s == sequence) {
                Some(i) => pending.remove(i).map(|(_, t)| t),
                None => None,
            }
        };
        let Some(sent) = sent else {
            return Err(ClientError::Protocol(format!(
                "answer for frame {sequence}, which is not in flight"
            )));
        };
        self.window.add_permits(1);
        Ok(StreamItem {
            sequence,
            outcome,
            latency: sent.elapsed(),
        })
    }
}

impl Stream for ResultStream {
    type Item = Result<StreamItem, ClientError>;

    fn poll_next(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Option<Self::Item>> {
        loop {
            match &mut self.state {
                StreamState::Done => return Poll::Ready(None),
                StreamState::Opening(call) => match Pin::new(call).poll(cx) {
                    Poll::Pending => return Poll::Pending,
                    Poll::Ready(Ok(Ok(response))) => {
                        self.state = StreamState::Open(Box::new(response.into_inner()));
                    }
                    Poll::Ready(Ok(Err(status))) => return Poll::Ready(self.broken(Some(&status))),
                    Poll::Ready(Err(join)) => {
                        self.state = StreamState::Done;
                        return Poll::Ready(Some(Err(ClientError::Protocol(format!(
                            "stream task failed: {join}"
                        )))));
                    }
                },
                StreamState::Open(streaming) => {
                    return match Pin::new(streaming).poll_next(cx) {
                        Poll::Pending => Poll::Pending,
                        Poll::Ready(Some(Ok(response))) => Poll::Ready(Some(self.answer(response))),
                        Poll::Ready(Some(Err(status))) => Poll::Ready(self.broken(Some(&status))),
                        Poll::Ready(None) => Poll::Ready(self.broken(None)),
                    };
                }
            }
        }
    }
}

/// tonic's own `grpc-timeout` timer answers CANCELLED ("Timeout expired") when it fires before
/// the service's DEADLINE_EXCEEDED arrives; for the caller both mean that the deadline passed,
/// which gRPC calls DEADLINE_EXCEEDED.
fn own_deadline(
    status: tonic::Status,
    timeout: Option<Duration>,
    elapsed: Duration,
) -> tonic::Status {
    match timeout {
        Some(timeout) if status.code() == tonic::Code::Cancelled && elapsed >= timeout => {
            tonic::Status::deadline_exceeded(format!(
                "no answer within the request timeout of {timeout:?} ({})",
                status.message()
            ))
        }
        _ => status,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cancel_by_the_clients_own_timer_is_deadline_exceeded() {
        let timeout = Some(Duration::from_millis(150));
        let timer = || tonic::Status::cancelled("Timeout expired");
        let late = own_deadline(timer(), timeout, Duration::from_millis(151));
        assert_eq!(late.code(), tonic::Code::DeadlineExceeded);
        assert!(late.message().contains("150ms"), "{}", late.message());
        // Cancelled early (the caller or the server went away), or without a timeout: as is.
        let early = own_deadline(timer(), timeout, Duration::from_millis(20));
        assert_eq!(early.code(), tonic::Code::Cancelled);
        let untimed = own_deadline(timer(), None, Duration::from_secs(9));
        assert_eq!(untimed.code(), tonic::Code::Cancelled);
        let other = own_deadline(
            tonic::Status::internal("x"),
            timeout,
            Duration::from_secs(1),
        );
        assert_eq!(other.code(), tonic::Code::Internal);
    }
}
