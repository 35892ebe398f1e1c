//! The `landing.v1.LandingService` handlers: validate and convert, hand to the dispatcher, convert
//! back. No pipeline logic and no metrics here.

use std::sync::Arc;
use std::time::{Duration, Instant};

use landing_geometry::SemanticClass;
use landing_proto::v1;
use tokio::sync::{mpsc, oneshot, watch};
use tokio_stream::wrappers::ReceiverStream;
use tonic::{Request, Response, Status, Streaming};

use crate::auth::Arrived;
use crate::catalog::Catalog;
use crate::catalog::search::{SearchRequest, response};
use crate::convert;
use crate::live::LiveView;
use crate::status::{to_rpc_status, to_status};
use crate::telemetry::Rpc;
use crate::workers::{Dispatcher, Done};

mod stream;

/// The service state shared by every call.
#[derive(Debug, Clone)]
pub(crate) struct LandingService {
    pub dispatcher: Arc<Dispatcher>,
    pub stream_buffer: usize,
    pub max_request_bytes: u64,
    /// Defaults and limits of streams that fuse.
    pub fusion: landing_fusion::FusionParams,
    /// Flips to true when the server starts draining: open streams stop reading.
    pub draining: watch::Receiver<bool>,
    /// The Foxglove live view, when `server.foxglove_listen` is set.
    pub live: Option<Arc<LiveView>>,
    /// The fleet's landing-site catalog, unless `catalog.enabled` is false.
    pub catalog: Option<Catalog>,
}

impl LandingService {
    /// The live view, if a viewer is watching: only then is a frame kept to be shown.
    fn watched(&self) -> Option<Arc<LiveView>> {
        self.live.as_ref().filter(|l| l.watched()).cloned()
    }
}

/// How much earlier than the caller's deadline a frame is given up: a tenth of the timeout, at
/// most [`MAX_DEADLINE_MARGIN`]. Timers run on both sides of the call: tonic's server timer
/// starts with ours and answers CANCELLED when it fires first, and the caller's own timer
/// started before its request was sent (measured: 4-5 ms before the headers arrive for a
/// 1.4 MB frame on a loaded 2-core box). Giving up a little earlier lets the caller hear
/// DEADLINE_EXCEEDED, with the reason, from the service.
fn deadline_margin(timeout: Duration) -> Duration {
    (timeout / 10).min(MAX_DEADLINE_MARGIN)
}

const MAX_DEADLINE_MARGIN: Duration = Duration::from_millis(20);

/// The deadline a caller set with `grpc-timeout`, if any, counted from when the call's headers
/// arrived (before a large body was read), less [`deadline_margin`].
pub(crate) fn deadline_of<T>(request: &Request<T>) -> Option<Instant> {
    let value = request.metadata().get("grpc-timeout")?.to_str().ok()?;
    let (digits, unit) = value.split_at(value.len().checked_sub(1)?);
    let n: u64 = digits.parse().ok()?;
    let timeout = match unit {
        "H" => Duration::from_secs(n.saturating_mul(3600)),
        "M" => Duration::from_secs(n.saturating_mul(60)),
        "S" => Duration::from_secs(n),
        "m" => Duration::from_millis(n),
        "u" => Duration::from_micros(n),
        "n" => Duration::from_nanos(n),
        _ => return None,
    };
    let arrived = request
        .extensions()
        .get::<Arrived>()
        .map_or_else(Instant::now, |a| a.0);
    // The margin is a fraction of the timeout: never before arrival.
    arrived.checked_add(timeout - deadline_margin(timeout))
}

fn never() -> impl std::future::Future<Output = u64> + Send + 'static {
    std::future::pending()
}

fn stream_response(sequence: u64, done: Done) -> v1::StreamLandingSitesResponse {
    use v1::stream_landing_sites_response::Outcome;
    let outcome = match done {
        Done::Computed(out) => Outcome::Result(v1::FrameResult::from(&*out)),
        Done::Failed(e) => Outcome::Error(to_rpc_status(&e)),
        Done::Skipped { superseded_by } => Outcome::Skipped(v1::FrameSkipped {
            superseded_by_sequence: superseded_by,
        }),
    };
    v1::StreamLandingSitesResponse {
        sequence,
        outcome: Some(outcome),
    }
}

#[tonic::async_trait]
impl v1::landing_service_server::LandingService for LandingService {
    async fn detect_landing_sites(
        &self,
        request: Request<v1::DetectLandingSitesRequest>,
    ) -> Result<Response<v1::DetectLandingSitesResponse>, Status> {
        let deadline = deadline_of(&request);
        let mut request = request.into_inner();
        let parts = convert::request_parts(&request, &self.dispatcher.pipeline.defaults);
        let shown = self.watched().zip(request.frame.take());
        drop(request);
        // Awaited in place: if the caller goes away, tonic drops this future and the frame stops.
        match self
            .dispatcher
            .process(Rpc::Unary, parts, deadline, never(), None)
            .await
        {
            Done::Computed(out) => {
                let result = v1::FrameResult::from(&*out);
                if let Some((live, frame)) = shown {
                    live.show(
                        frame,
                        v1::StreamLandingSitesResponse {
                            sequence: result.sequence,
                            outcome: Some(v1::stream_landing_sites_response::Outcome::Result(
                                result.clone(),
                            )),
                        },
                    );
                }
                Ok(Response::new(v1::DetectLandingSitesResponse {
                    result: Some(result),
                }))
            }
            Done::Failed(e) => Err(to_status(&e)),
            Done::Skipped { .. } => Err(Status::internal("a unary frame cannot be skipped")),
        }
    }

    type StreamLandingSitesStream = ReceiverStream<Result<v1::StreamLandingSitesResponse, Status>>;

    async fn stream_landing_sites(
        &self,
        request: Request<Streaming<v1::StreamLandingSitesRequest>>,
    ) -> Result<Response<Self::StreamLandingSitesStream>, Status> {
        let session = stream::StreamSession::new(self.clone(), deadline_of(&request));
        let (out_tx, out_rx) = mpsc::channel(self.stream_buffer);
        // Frames in flight for this stream, in arrival order; its bound is the BLOCK back-pressure.
        let (pending_tx, pending_rx) = mpsc::channel(self.stream_buffer);
        let (cancel_tx, cancel_rx) = watch::channel(false);
        // Why the input ended, when it broke (a message over `server.max_request_bytes`, one
        // that does not decode): the stream's final status, after every frame before it is
        // answered.
        let (broken_tx, broken_rx) = oneshot::channel();
        let inbound = request.into_inner();
        let dispatcher = self.dispatcher.clone();
        dispatcher.metrics.streams(1.0);
        let feed = self.catalog.as_ref().map(Catalog::feed);
        tokio::spawn(stream::read_frames(
            session, inbound, cancel_rx, pending_tx, broken_tx,
        ));
        tokio::spawn(async move {
            stream::write_answers(pending_rx, out_tx, broken_rx, cancel_tx, feed).await;
            dispatcher.metrics.streams(-1.0);
        });
        Ok(Response::new(ReceiverStream::new(out_rx)))
    }

    async fn get_service_info(
        &self,
        _request: Request<v1::GetServiceInfoRequest>,
    ) -> Result<Response<v1::ServiceInfo>, Status> {
        let pipeline = &self.dispatcher.pipeline;
        let classes = SemanticClass::ALL
            .iter()
            .map(|&c| v1::ClassInfo {
                class: c as i32,
                name: c.name().to_owned(),
            })
            .collect();
        Ok(Response::new(v1::ServiceInfo {
            version: env!("CARGO_PKG_VERSION").to_owned(),
            model: pipeline.segmenter.as_ref().map(|s| s.model_info()),
            classes,
            default_options: Some(convert::default_options(&pipeline.defaults)),
            max_request_bytes: self.max_request_bytes,
            default_fusion: Some(convert::default_fusion(&self.fusion)),
        }))
    }

    async fn search_landing_sites(
        &self,
        request: Request<v1::SearchLandingSitesRequest>,
    ) -> Result<Response<v1::SearchLandingSitesResponse>, Status> {
        let Some(catalog) = self.catalog.clone() else {
            let off = crate::Error::CatalogUnavailable("catalog.enabled is false here".into());
            return Err(to_status(&off));
        };
        let query = landing_catalog::SearchQuery::try_from(SearchRequest {
            request: request.get_ref(),
            default_max_age: catalog.max_age(),
        })
        .map_err(|e| to_status(&e))?;
        let page = catalog.search(query).await.map_err(|e| to_status(&e))?;
        Ok(Response::new(response(page)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grpc_timeout_header_becomes_a_deadline_from_arrival() {
        let mut r = Request::new(());
        assert!(deadline_of(&r).is_none());
        let arrived = Instant::now() - Duration::from_millis(100);
        r.extensions_mut().insert(Arrived(arrived));
        r.metadata_mut()
            .insert("grpc-timeout", "250m".parse().unwrap());
        let d = deadline_of(&r).unwrap().duration_since(arrived);
        // A tenth of the timeout early, at most 20 ms.
        assert_eq!(d, Duration::from_millis(250 - 20));
        r.metadata_mut()
            .insert("grpc-timeout", "150m".parse().unwrap());
        assert_eq!(
            deadline_of(&r).unwrap(),
            arrived + Duration::from_millis(150 - 15)
        );
        r.metadata_mut()
            .insert("grpc-timeout", "3S".parse().unwrap());
        assert_eq!(
            deadline_of(&r).unwrap(),
            arrived + Duration::from_secs(3) - MAX_DEADLINE_MARGIN
        );
        r.metadata_mut()
            .insert("grpc-timeout", "1u".parse().unwrap());
        assert_eq!(
            deadline_of(&r).unwrap(),
            arrived + Duration::from_nanos(900),
            "never before arrival"
        );
        r.metadata_mut()
            .insert("grpc-timeout", "7x".parse().unwrap());
        assert!(deadline_of(&r).is_none());
    }
}
