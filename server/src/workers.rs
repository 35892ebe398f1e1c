//! The dispatch layer between handlers and the pipeline: admission control, the geometry worker
//! pool (`spawn_blocking` gated by a semaphore sized to the cores), deadlines, skipping under the
//! LATEST policy, and every metric.

use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use tokio::sync::{OwnedSemaphorePermit, Semaphore};
use tracing::Instrument as _;

use crate::Error;
use crate::error::Capacity;
use crate::frame::{CameraImage, ImagePixels};
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

impl StreamFusion {
    /// Computes `frame` from the stream's map (its fusion turn has come), and counts what the
    /// map holds after it on the memory gauge.
    fn fuse(
        &self,
        frame: &Frame,
        options: &FrameOptions,
        pipeline: &Pipeline,
        reset: bool,
    ) -> Result<FrameOutput, Error> {
        let mut map = self.map.lock().unwrap_or_else(|e| e.into_inner());
        let out = run_fused(frame, options, pipeline, &mut map, reset);
        let bytes = map_bytes(&map);
        drop(map);
        let before = self.bytes.swap(bytes, Ordering::Relaxed);
        self.metrics.fusion_bytes(bytes as f64 - before as f64);
        out
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
    /// `pipeline.max_queued_bytes` in KiB permits: the memory admitted frames hold.
    memory: Arc<Semaphore>,
    memory_kib: u32,
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
    /// `capacity` frames and `max_queued_bytes` of them admitted at a time, computed by
    /// `workers` at a time.
    pub fn new(
        pipeline: Pipeline,
        capacity: usize,
        max_queued_bytes: u64,
        workers: usize,
        metrics: Metrics,
    ) -> Self {
        let memory_kib = u32::try_from(max_queued_bytes / 1024).unwrap_or(u32::MAX);
        Self {
            pipeline: Arc::new(pipeline),
            admission: Arc::new(Semaphore::new(capacity)),
            memory: Arc::new(Semaphore::new(memory_kib as usize)),
            memory_kib,
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
        let kib = self.memory_kib as usize - self.memory.available_permits();
        self.metrics.queue(
            self.queued(),
            kib * 1024,
            self.in_flight.load(Ordering::Relaxed),
        );
    }

    /// Admits a frame against both limits, or says which one it met.
    fn admit(&self, frame: &Frame) -> Result<Admitted, Error> {
        let overloaded = |capacity| Error::Overloaded {
            capacity,
            retry_after: self.retry_after(),
        };
        let frames = self
            .admission
            .clone()
            .try_acquire_owned()
            .map_err(|_| overloaded(Capacity::Frames(self.capacity)))?;
        // A frame larger than the whole budget takes all of it: it waits for an empty queue.
        let kib = u32::try_from(held_bytes(frame).div_ceil(1024))
            .unwrap_or(u32::MAX)
            .clamp(1, self.memory_kib);
        let memory = self
            .memory
            .clone()
            .try_acquire_many_owned(kib)
            .map_err(|_| overloaded(Capacity::Bytes(u64::from(self.memory_kib) * 1024)))?;
        Ok(Admitted {
            _frames: frames,
            _memory: memory,
        })
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
            Ok((frame, _)) => self.admit(frame).map(Some),
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
        admission: Option<Admitted>,
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
        let after = fusion.as_mut().and_then(|f| f.after.take());
        let worker = match self.take_worker(after, superseded, expired.as_mut()).await {
            Ok(worker) => worker,
            Err(done) => return done,
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
            compute_frame(&frame, &options, &pipeline, fusion)
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

    /// Waits for the frame's fusion turn (`after`, the previous frame's fusion), then for a
    /// worker; or says how the frame ended while it waited (skipped, expired).
    ///
    /// A fused frame waits for its turn before it takes a worker, so that a stream never holds a
    /// worker while it waits for itself. A frame skipped or expired while it waits is not fused:
    /// fusing it needs its segmentation, the very work skipping saves, and its points without
    /// classes would add geometry no class vouches for.
    async fn take_worker(
        &self,
        after: Option<tokio::sync::oneshot::Receiver<()>>,
        mut superseded: Pin<&mut impl Future<Output = u64>>,
        mut expired: Pin<&mut impl Future<Output = ()>>,
    ) -> Result<OwnedSemaphorePermit, Done> {
        if let Some(after) = after {
            tokio::select! {
                biased;
                _ = after => {}
                by = &mut superseded => return Err(Done::Skipped { superseded_by: by }),
                () = &mut expired => return Err(Done::Failed(Error::DeadlineExceeded)),
            }
        }
        tokio::select! {
            biased;
            permit = self.workers.clone().acquire_owned() => permit.map_err(|_| {
                Done::Failed(Error::Internal("the worker pool is closed".into()))
            }),
            by = &mut superseded => Err(Done::Skipped { superseded_by: by }),
            () = &mut expired => Err(Done::Failed(Error::DeadlineExceeded)),
        }
    }
}

/// One frame's computation on a worker: judged alone, or from its stream's map, after which
/// the stream's next frame may fuse.
fn compute_frame(
    frame: &Frame,
    options: &FrameOptions,
    pipeline: &Pipeline,
    fusion: Option<FusionTurn>,
) -> Result<FrameOutput, Error> {
    let Some(FusionTurn {
        stream,
        done,
        reset,
        ..
    }) = fusion
    else {
        return run_pipeline(frame, options, pipeline);
    };
    let out = stream.fuse(frame, options, pipeline, reset);
    // The next frame of the stream may fuse.
    drop(done);
    out
}

/// A frame's place in the queue: one of `pipeline.queue_capacity` and its share of
/// `pipeline.max_queued_bytes`, given back when dropped.
#[derive(Debug)]
pub(crate) struct Admitted {
    _frames: OwnedSemaphorePermit,
    _memory: OwnedSemaphorePermit,
}

/// The memory a validated frame holds while queued: its points (f64), classes, the image bytes
/// as received and its strings. Decoded pixels exist only while a worker computes it.
fn held_bytes(frame: &Frame) -> usize {
    let cloud = &frame.cloud;
    let image = |i: &Option<CameraImage>| {
        i.as_ref().map_or(0, |i| match &i.pixels {
            ImagePixels::Encoded { data, .. }
            | ImagePixels::Rgb8 { data, .. }
            | ImagePixels::Mono8 { data, .. } => data.len(),
        })
    };
    std::mem::size_of::<Frame>()
        + cloud.points.len() * std::mem::size_of::<[f64; 3]>()
        + cloud.classes.as_ref().map_or(0, Vec::len)
        + image(&frame.image)
        + image(&frame.class_image)
        + frame.drone_id.len()
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

#[cfg(test)]
mod tests {
    use nalgebra::Isometry3;

    use super::*;
    use crate::frame::Cloud;

    /// A frame whose points hold about `kib` KiB.
    fn frame_of(kib: usize) -> (Frame, FrameOptions) {
        let points = vec![[0.0; 3]; kib * 1024 / 24];
        let frame = Frame {
            drone_id: "d1".into(),
            sequence: 1,
            timestamp: None,
            cloud: Cloud {
                points,
                classes: None,
                pose: Isometry3::identity(),
            },
            image: None,
            class_image: None,
            geodetic_origin: None,
        };
        (frame, FrameOptions::default())
    }

    fn dispatcher(capacity: usize, max_queued_bytes: u64) -> Arc<Dispatcher> {
        let pipeline = Pipeline::geometry_only(Default::default());
        Arc::new(Dispatcher::new(
            pipeline,
            capacity,
            max_queued_bytes,
            1,
            Metrics::new(""),
        ))
    }

    /// Admits (admission happens when `process` is called, not when its future runs).
    fn admit(d: &Arc<Dispatcher>, kib: usize) -> impl Future<Output = Done> {
        d.process(
            Rpc::Stream,
            Ok(frame_of(kib)),
            None,
            std::future::pending(),
            None,
        )
    }

    fn refusal(done: Done) -> Capacity {
        match done {
            Done::Failed(Error::Overloaded { capacity, .. }) => capacity,
            other => panic!("expected an overload refusal, got {other:?}"),
        }
    }

    #[tokio::test]
    async fn admission_counts_frames_and_their_memory() {
        let d = dispatcher(64, 1 << 20);
        let first = admit(&d, 600);
        assert_eq!(d.queued(), 1);
        // 600 KiB are held; another 600 do not fit in 1 MiB, 300 do.
        let second = admit(&d, 600);
        assert_eq!(refusal(second.await), Capacity::Bytes(1 << 20));
        let third = admit(&d, 300);
        assert_eq!(d.queued(), 2);
        // Finishing a frame gives its memory back.
        drop(first);
        let fourth = admit(&d, 600);
        assert_eq!(d.queued(), 2);
        drop((third, fourth));
        assert_eq!(d.queued(), 0);
        assert_eq!(d.memory.available_permits(), 1024);
    }

    #[tokio::test]
    async fn a_frame_larger_than_the_budget_waits_for_an_empty_queue() {
        let d = dispatcher(64, 1 << 20);
        let small = admit(&d, 10);
        assert_eq!(refusal(admit(&d, 4096).await), Capacity::Bytes(1 << 20));
        drop(small);
        let big = admit(&d, 4096);
        assert_eq!(d.queued(), 1, "admitted alone");
        assert_eq!(refusal(admit(&d, 1).await), Capacity::Bytes(1 << 20));
        drop(big);
    }

    #[tokio::test]
    async fn the_frame_limit_still_applies() {
        let d = dispatcher(1, 1 << 30);
        let _first = admit(&d, 1);
        assert_eq!(refusal(admit(&d, 1).await), Capacity::Frames(1));
    }
}
