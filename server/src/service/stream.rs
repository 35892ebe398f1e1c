//! A `StreamLandingSites` call: a [`StreamSession`] reads, validates and starts each frame
//! ([`read_frames`]), and [`write_answers`] answers them in order, one response per frame.
//!
//! Concurrency, as the tests pin it: each frame is its own task on the dispatcher, so a stream
//! can have several in flight (up to `pipeline.stream_buffer`, the BLOCK back-pressure); a fused
//! frame waits for the previous one's fusion before it takes a worker ([`FusionTurn`]); under
//! LATEST a frame not yet started is skipped once a newer one arrives; a frame that fails
//! validation is answered with its error, and never changes the map.

use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;
use std::time::Instant;

use landing_proto::v1;
use tokio::sync::{mpsc, oneshot, watch};
use tonic::{Status, Streaming};

use super::{LandingService, never, stream_response};
use crate::catalog::Feed;
use crate::convert;
use crate::live::LiveView;
use crate::telemetry::Rpc;
use crate::workers::{Done, FusionTurn, StreamFusion};

/// A stream's frame in flight: its sequence, its computation, and the frame itself when a
/// live viewer is watching (to be shown with its answer).
pub(super) type Pending = (
    u64,
    tokio::task::JoinHandle<Done>,
    Option<(Arc<LiveView>, v1::Frame)>,
);

/// Whether a stream fuses, as its first message asked.
enum Fusing {
    Off,
    On(Arc<StreamFusion>),
    /// It asked with options this server refuses; every frame is answered with the error.
    Refused(crate::Error),
}

/// A frame's wait to be skipped: resolves to the sequence of a newer frame (never under BLOCK).
type Superseded = Pin<Box<dyn Future<Output = u64> + Send>>;

/// The reader's side of one stream: what its first message decided and the fusion turn the
/// next frame waits for.
pub(super) struct StreamSession {
    service: LandingService,
    /// The caller's deadline for every frame.
    deadline: Option<Instant>,
    /// OVERFLOW_POLICY_LATEST, as the first message asked.
    latest: Option<bool>,
    /// Whether the stream fuses, as the first message asked.
    fusing: Option<Fusing>,
    /// The previous fused frame's signal: the next one fuses after it.
    previous: Option<oneshot::Receiver<()>>,
    /// Frames read so far.
    index: u64,
    /// (arrival index, sequence) of the newest frame, for LATEST.
    newest: watch::Sender<(u64, u64)>,
}

impl StreamSession {
    pub(super) fn new(service: LandingService, deadline: Option<Instant>) -> Self {
        Self {
            service,
            deadline,
            latest: None,
            fusing: None,
            previous: None,
            index: 0,
            newest: watch::channel((0, 0)).0,
        }
    }

    /// Starts one frame's computation on the dispatcher.
    fn start(&mut self, mut request: v1::StreamLandingSitesRequest) -> Pending {
        let latest = *self
            .latest
            .get_or_insert(request.overflow_policy == v1::OverflowPolicy::Latest as i32);
        let sequence = request.frame.as_ref().map_or(0, |f| f.sequence);
        self.index += 1;
        self.newest.send_replace((self.index, sequence));
        let (parts, turn) = self.convert(&request);
        let shown = self.service.watched().zip(request.frame.take());
        drop(request);
        let superseded = if latest {
            self.superseded()
        } else {
            Box::pin(never())
        };
        let dispatcher = &self.service.dispatcher;
        let job =
            tokio::spawn(dispatcher.process(Rpc::Stream, parts, self.deadline, superseded, turn));
        (sequence, job, shown)
    }

    /// The frame converted, and its fusion turn when the stream fuses. The first message
    /// decides whether the stream fuses (unless it asks for `single_frame`), and with what map.
    fn convert(
        &mut self,
        request: &v1::StreamLandingSitesRequest,
    ) -> (
        Result<(crate::pipeline::Frame, crate::pipeline::FrameOptions), crate::Error>,
        Option<FusionTurn>,
    ) {
        let dispatcher = &self.service.dispatcher;
        let defaults = &self.service.fusion;
        let fusing = self.fusing.get_or_insert_with(|| {
            match (request.single_frame, request.fusion.as_ref()) {
                (true, None) => Fusing::Off,
                (true, Some(_)) => Fusing::Refused(crate::Error::invalid(
                    "fusion",
                    "fusion options on a stream that asks for single_frame would not be applied",
                )),
                (false, asked) => {
                    match convert::fusion_map(
                        asked.unwrap_or(&v1::FusionOptions::default()),
                        defaults,
                    ) {
                        Ok(map) => Fusing::On(StreamFusion::open(map, &dispatcher.metrics)),
                        Err(e) => Fusing::Refused(e),
                    }
                }
            }
        });
        let parts = || convert::stream_parts(request, &dispatcher.pipeline.defaults);
        match fusing {
            Fusing::Off => (parts(), None),
            Fusing::Refused(e) => (Err(e.clone()), None),
            Fusing::On(stream) => {
                let (done, next) = oneshot::channel();
                let turn = FusionTurn {
                    stream: stream.clone(),
                    after: self.previous.replace(next),
                    done,
                    reset: request.reset_fusion,
                };
                (parts(), Some(turn))
            }
        }
    }

    /// Resolves to the sequence of the first frame that arrives after this one.
    fn superseded(&self) -> Superseded {
        let mut rx = self.newest.subscribe();
        let mine = self.index;
        Box::pin(async move {
            match rx.wait_for(|(i, _)| *i > mine).await.map(|v| v.1) {
                Ok(sequence) => sequence,
                Err(_) => std::future::pending().await,
            }
        })
    }
}

/// Reads the stream's messages and starts each frame, until the input ends, breaks (its error
/// goes to `broken`), the writer stops (`cancel`) or the server drains.
pub(super) async fn read_frames(
    mut session: StreamSession,
    mut inbound: Streaming<v1::StreamLandingSitesRequest>,
    mut cancel: watch::Receiver<bool>,
    pending: mpsc::Sender<Pending>,
    broken: oneshot::Sender<Status>,
) {
    let mut draining = session.service.draining.clone();
    loop {
        if *draining.borrow() {
            break;
        }
        let message = tokio::select! {
            m = inbound.message() => m,
            changed = draining.changed() => {
                if changed.is_err() {
                    break;
                }
                continue;
            }
            _ = cancel.changed() => break,
        };
        let request = match message {
            Ok(Some(r)) => r,
            Ok(None) => break,
            Err(status) => {
                tracing::debug!(%status, "stream input ended with an error");
                let _ = broken.send(status);
                break;
            }
        };
        if pending.send(session.start(request)).await.is_err() {
            break;
        }
    }
}

/// Answers the frames in order, one response per frame, then the input's error if it broke;
/// when the caller goes away, aborts what is left and tells the reader (`cancel`). Each computed
/// answer goes to the catalog's `feed`, which reports the stream's last one when dropped here.
pub(super) async fn write_answers(
    mut pending: mpsc::Receiver<Pending>,
    out: mpsc::Sender<Result<v1::StreamLandingSitesResponse, Status>>,
    broken: oneshot::Receiver<Status>,
    cancel: watch::Sender<bool>,
    mut feed: Option<Feed>,
) {
    let mut broken = broken;
    while let Some((sequence, mut job, shown)) = pending.recv().await {
        let done = tokio::select! {
            joined = &mut job => match joined {
                Ok(done) => done,
                Err(e) => Done::Failed(crate::Error::Internal(format!("frame task failed: {e}"))),
            },
            () = out.closed() => {
                job.abort();
                break;
            }
        };
        if let (Some(feed), Done::Computed(computed)) = (&mut feed, &done) {
            feed.answered(computed);
        }
        let response = stream_response(sequence, done);
        if let Some((live, frame)) = shown {
            live.show(frame, response.clone());
        }
        if out.send(Ok(response)).await.is_err() {
            break;
        }
    }
    // The reader sent its error, if any, before it let go of its end of `pending`.
    if let Ok(status) = broken.try_recv() {
        let _ = out.send(Err(status)).await;
    }
    let _ = cancel.send(true);
    pending.close();
    while let Ok((_, job, _)) = pending.try_recv() {
        job.abort();
    }
}
