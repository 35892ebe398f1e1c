//! The dispatch layer between handlers and the pipeline: admission control, the geometry worker
//! pool (`spawn_blocking` gated by a semaphore sized to the cores), deadlines, skipping under the
//! LATEST policy, and every metric.

use std::future::Future;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use tokio::sync::Semaphore;
use tracing::Instrument as _;

use crate::Error;
use crate::pipeline::{
    Frame, FrameOptions, FrameOutput, Pipeline, StreamMap, run_fused, run_pipeline,
};
use crate::telemetry::{Metrics, Outcome, Rpc};

/// How a frame ended.
#[derive(Debug)]
pub(crate) enum Done {
    Computed(Box<FrameOutput>),
    Failed(Error),
    /// Dropped unprocessed under OVERFLOW_POLICY_LATEST: a newer frame arrived.
    Skipped {
        superseded_by: u64,
    },
}

/// A fused stream's frame: the stream's map, the turn that follows the previous frame's fusion
/// (frames of one stream are fused in arrival order, one at a time), and the signal for the
/// next frame, sent when this one's computation ends (dropped, whatever the outcome).
#[derive(Debug)]
pub(crate) struct FusionTurn {
    pub stream: Arc<StreamFusion>,
    pub after: Option<tokio::sync::oneshot::Receiver<()>>,
    pub done: tokio::sync::oneshot::Sender<()>,
    /// The frame asked for the map to start over.
    pub reset: bool,
}

/// A fusing stream's map, shared by its frames' jobs: on the gauges from [`StreamFusion::open`]
/// until the last holder (the reader at the stream's end, or the last frame still computing)
/// drops it.
#[derive(Debug)]
pub(crate) struct StreamFusion {
    map: std::sync::Mutex<StreamMap>,
    /// What the map held after its latest frame, as counted on the memory gauge.
    bytes: AtomicUsize,
    metrics: Metrics,
}

impl StreamFusion {
    pub fn open(map: StreamMap, metrics: &Metrics) -> Arc<Self> {
        metrics.fusion_maps(1.0);
        Arc::new(Self {
            map: std::sync::Mutex::new(map),
            bytes: AtomicUsize::new(0),
            metrics: metrics.clone(),
        })
    }
}

impl Drop for StreamFusion {
    fn drop(&mut self) {
        let bytes = self.bytes.load(Ordering::Relaxed);
        self.metrics.fusion_bytes(-(bytes as f64));
        self.metrics.fusion_maps(-1.0);
    }
}

/// Shared by every handler of one server.
#[derive(Debug)]
pub(crate) struct Dispatcher {
    pub pipeline: Arc<Pipeline>,
    admission: Arc<Semaphore>,
    workers: Arc<Semaphore>,
    capacity: usize,
    worker_count: usize,
    in_flight: AtomicUsize,
    /// Moving average of the compute time of a frame, microseconds (for RetryInfo).
    average_us: AtomicU64,
    draining: AtomicBool,
    pub metrics: Metrics,
}

impl Dispatcher {
    pub fn new(pipeline: Pipeline, capacity: usize, workers: usize, metrics: Metrics) -> Self {
        Self {
            pipeline: Arc::new(pipeline),
            admission: Arc::new(Semaphore::new(capacity)),
            workers: Arc::new(Semaphore::new(workers)),
            capacity,
            worker_count: workers,
            in_flight: AtomicUsize::new(0),
            average_us: AtomicU64::new(50_000),
            draining: AtomicBool::new(false),
            metrics,
        }
    }

    /// From now on new frames are refused with UNAVAILABLE; admitted ones finish.
    pub fn drain(&self) {
        self.draining.store(true, Ordering::SeqCst);
    }

    pub fn is_draining(&self) -> bool {
        self.draining.load(Ordering::SeqCst)
    }

    /// Frames admitted and not finished.
    pub fn queued(&self) -> usize {
        self.capacity - self.admission.available_permits()
    }

    fn retry_after(&self) -> Duration {
        // Roughly the time the queue ahead needs to clear a slot.
        let average = self.average_us.load(Ordering::Relaxed);
        let us = average.saturating_mul(self.capacity as u64) / self.worker_count.max(1) as u64;
        Duration::from_micros(us.clamp(10_000, 5_000_000))
    }

    fn gauges(&self) {
        self.metrics
            .queue(self.queued(), self.in_flight.load(Ordering::Relaxed));
    }

    /// Processes one frame from validation result to outcome, counting it once.
    ///
    /// `parts` is the conversion of the request (its error, if validation failed); `deadline` the
    /// caller's; `superseded` resolves to the sequence of a newer frame when this one may be
    /// skipped before it starts (never resolves under BLOCK). Dropping the returned future before
    /// it finishes stops the frame unless its computation has already started. With `fusion`,
    /// the frame waits for its turn before a worker, and is computed from the stream's map.
    pub fn process(
        self: &Arc<Self>,
        rpc: Rpc,
        parts: Result<(Frame, FrameOptions), Error>,
        deadline: Option<Instant>,
        superseded: impl Future<Output = u64> + Send + 'static,
        fusion: Option<FusionTurn>,
    ) -> impl Future<Output = Done> + Send + 'static {
        let received = Instant::now();
        // Admission happens now, in arrival order, not when the future is first polled.
        let admitted = match &parts {
            Err(_) => Ok(None),
            Ok(_) if self.is_draining() => Err(Error::ShuttingDown),
            Ok(_) => match self.admission.clone().try_acquire_owned() {
                Ok(permit) => Ok(Some(permit)),
                Err(_) => Err(Error::Overloaded {
                    capacity: self.capacity,
                    retry_after: self.retry_after(),
                }),
            },
        };
        self.gauges();
        let this = self.clone();
        let sequence = parts.as_ref().map_or(0, |(f, _)| f.sequence);
        let span = tracing::info_span!(
            "frame",
            rpc = rpc.as_str(),
            sequence,
            outcome = tracing::field::Empty
        );
        async move {
            let done = match (parts, admitted) {
                (Err(e), _) | (Ok(_), Err(e)) => Done::Failed(e),
                (Ok((frame, options)), Ok(permit)) => {
                    let when = When { received, deadline };
                    this.compute(frame, options, permit, when, superseded, fusion)
                        .await
                }
            };
            let outcome = match &done {
                Done::Computed(out) => {
                    this.metrics.stages(&out.timings);
                    Outcome::Ok
                }
                Done::Failed(e) => Outcome::of(e),
                Done::Skipped { .. } => Outcome::Skipped,
            };
            tracing::Span::current().record("outcome", outcome.as_str());
            if let Done::Failed(e) = &done {
                tracing::debug!(error = %e, "frame failed");
            }
            this.metrics.frame(rpc, outcome, received.elapsed());
            this.gauges();
            done
        }
        .instrument(span)
    }

    async fn compute(
        self: &Arc<Self>,
        frame: Frame,
        options: FrameOptions,
        admission: Option<tokio::sync::OwnedSemaphorePermit>,
        when: When,
        superseded: impl Future<Output = u64>,
        mut fusion: Option<FusionTurn>,
    ) -> Done {
        let When { received, deadline } = when;
        let expired = async {
            match deadline {
                Some(d) => tokio::time::sleep_until(tokio::time::Instant::from_std(d)).await,
                None => std::future::pending().await,
            }
        };
        tokio::pin!(expired);
        tokio::pin!(superseded);
        // A fused frame waits for the previous one's fusion before it takes a worker, so that a
        // stream never holds a worker while it waits for itself. A frame skipped or expired
        // while it waits is not fused: fusing it needs its segmentation, the very work skipping
        // saves, and its points without classes would add geometry no class vouches for.
        if let Some(after) = fusion.as_mut().and_then(|f| f.after.take()) {
            tokio::select! {
                biased;
                _ = after => {}
                by = &mut superseded => return Done::Skipped { superseded_by: by },
                () = &mut expired => return Done::Failed(Error::DeadlineExceeded),
            }
        }
        let worker = tokio::select! {
            biased;
            permit = self.workers.clone().acquire_owned() => match permit {
                Ok(p) => p,
                Err(_) => return Done::Failed(Error::Internal("the worker pool is closed".into())),
            },
            by = &mut superseded => return Done::Skipped { superseded_by: by },
            () = &mut expired => return Done::Failed(Error::DeadlineExceeded),
        };
        if deadline.is_some_and(|d| Instant::now() >= d) {
            return Done::Failed(Error::DeadlineExceeded);
        }
        let queue = received.elapsed();
        let in_flight = InFlight::enter(&self.in_flight);
        self.gauges();
        let pipeline = self.pipeline.clone();
        let started = Instant::now();
        // The permits travel with the blocking job: capacity stays accounted for even when the
        // caller goes away while the job runs.
        let job = tokio::task::spawn_blocking(move || {
            let _permits = (admission, worker);
            let Some(turn) = fusion else {
                return run_pipeline(&frame, &options, &pipeline);
            };
            let FusionTurn {
                stream,
                done,
                reset,
                ..
            } = turn;
            let mut map = stream.map.lock().unwrap_or_else(|e| e.into_inner());
            let out = run_fused(&frame, &options, &pipeline, &mut map, reset);
            let bytes = map_bytes(&map);
            drop(map);
            let before = stream.bytes.swap(bytes, Ordering::Relaxed);
            stream.metrics.fusion_bytes(bytes as f64 - before as f64);
            // The next frame of the stream may fuse.
            drop(done);
            out
        });
        // A frame that outlives the caller's deadline is answered DEADLINE_EXCEEDED at once; its
        // computation cannot be interrupted and finishes in the background, keeping its permits.
        let result = tokio::select! {
            biased;
            joined = job => joined,
            () = &mut expired => return Done::Failed(Error::DeadlineExceeded),
        };
        drop(in_flight);
        let spent = started.elapsed().as_micros() as u64;
        let old = self.average_us.load(Ordering::Relaxed);
        self.average_us
            .store((old * 7 + spent) / 8, Ordering::Relaxed);
        match result {
            Ok(Ok(mut out)) => {
                out.timings.queue = Some(queue);
                out.timings.total = Some(received.elapsed());
                Done::Computed(Box::new(out))
            }
            Ok(Err(e)) => Done::Failed(e),
            Err(join) => Done::Failed(Error::Internal(format!("pipeline worker failed: {join}"))),
        }
    }
}

/// When a frame arrived and when its caller gives up on it.
struct When {
    received: Instant,
    deadline: Option<Instant>,
}

/// Bytes a stream's map holds: its cells and its kept obstacle rays.
pub(crate) fn map_bytes(map: &StreamMap) -> usize {
    map.cell_bytes() + map.keep_outs().map(|rays| rays.heap_bytes()).sum::<usize>()
}

/// Counts a frame as in flight while alive, also when its future is dropped mid-way.
struct InFlight<'a>(&'a AtomicUsize);

impl<'a> InFlight<'a> {
    fn enter(counter: &'a AtomicUsize) -> Self {
        counter.fetch_add(1, Ordering::Relaxed);
        Self(counter)
    }
}

impl Drop for InFlight<'_> {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::Relaxed);
    }
}
